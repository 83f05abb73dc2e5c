"""The tasks hersd knows by name: one table for the config check, the env factory and the
report (order and titles).

A task is a gymnasium-robotics goal-conditioned env; ``cycles_per_epoch`` is the paper's
epoch size for it (50 cycles; FetchReach 10, as in the reference HER code). The Fetch tasks
are the paper's; the Hand tasks go beyond it. ``task=custom task.env_id=<id>`` runs any other
goal-conditioned env (its run directories and reports are named by its env id).
"""

from __future__ import annotations

from typing import NamedTuple


class Task(NamedTuple):
    name: str  # short name used in configs, run directories and reports
    env_id: str  # gymnasium-robotics environment id
    title: str  # name shown in figures and tables
    cycles_per_epoch: int  # the paper's rollout+update cycles per epoch


TASKS: dict[str, Task] = {task.name: task for task in (  # in the paper's order
    Task("reach", "FetchReach-v4", "FetchReach", 10),
    Task("push", "FetchPush-v4", "FetchPush", 50),
    Task("pick_and_place", "FetchPickAndPlace-v4", "FetchPickAndPlace", 50),
    Task("slide", "FetchSlide-v4", "FetchSlide", 50),
    Task("hand_reach", "HandReach-v3", "HandReach", 50),
    Task("hand_block", "HandManipulateBlockRotateXYZ-v1", "HandManipulateBlockRotateXYZ", 50),
)}
CUSTOM = "custom"  # task=custom task.env_id=<any goal-conditioned env id>
CUSTOM_CYCLES_PER_EPOCH = 50


def task_rank(name: str) -> tuple[int, str]:
    """Sort key: the tasks of :data:`TASKS` in their order, any other task after them alphabetically."""
    names = list(TASKS)
    return (names.index(name) if name in TASKS else len(names), name)


def task_title(name: str) -> str:
    """``FetchPush`` for ``push``; an unknown task's name in title case."""
    return TASKS[name].title if name in TASKS else name.replace("_", " ").title()
