"""Goal-conditioned gymnasium-robotics envs (Fetch, Hand, the mazes and any other), without wrappers.

The training loop runs exactly T = the registered ``max_episode_steps`` steps per episode
itself and ignores ``terminated``, so the TimeLimit and checker wrappers are only overhead;
the unwrapped env still computes rewards and success as the registered one does. Ignoring
``terminated`` is exact for Fetch and Hand (they never terminate) and for the mazes as
registered (``continuing_task=True``: they never terminate either; ``reset_target=False``:
the goal stays put when reached, and the loop records each step's desired goal anyway).

What hersd reads from an env (:func:`env_spec`): the observation, goal and action sizes from
its spaces, T from its registration, the action bound, the success radius and the reward's
range (:mod:`hersd.engine.envs.goal_envs`, by family), and each step's success from its info
(``is_success``, or ``success`` for the mazes: :func:`step_success`; an env that reports
neither is refused before the run starts, :func:`check_success_reported`). Rewards of
relabelled transitions are recomputed in one call by the family's rule
(:func:`hersd.engine.envs.goal_envs.vectorised_reward`).
"""

from __future__ import annotations

import contextlib
import io
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from hersd.contract.config import TaskConfig
from hersd.contract.errors import ConfigError
from hersd.engine.envs.goal_envs import GOAL_KEYS, is_goal_env, reward_family, reward_range, success_radius

# gymnasium-robotics prints a notice about the Adroit envs' rewards at import; it does not
# concern the Fetch tasks and would otherwise open every run's output.
with contextlib.redirect_stderr(io.StringIO()):
    import gymnasium_robotics

gym.register_envs(gymnasium_robotics)

# The info keys that report a step's success: gymnasium-robotics' GoalEnv convention (Fetch, Hand),
# and the mazes' (PointMaze, AntMaze v4 and later).
SUCCESS_KEYS = ("is_success", "success")
ROBOT_FAMILIES = ("fetch", "hand_reach", "hand_manipulate")  # their step info always has is_success


class EnvSpec(NamedTuple):
    """What a task's env gives the run: observation, goal and action dimensions, horizon T, max
    action, success radius (NaN if the env states none) and the (lowest, highest) reward."""

    obs_dim: int
    goal_dim: int
    action_dim: int
    horizon: int
    max_action: float
    distance_threshold: float
    reward_range: tuple[float, float]


def make_env(task: TaskConfig, **make_kwargs: Any) -> Any:
    """One unwrapped goal env; ``task.distance_threshold`` (if set) replaces the success radius;
    ``make_kwargs`` go to ``gym.make`` (e.g. ``render_mode="rgb_array"``, :mod:`hersd.engine.render`).
    An unknown env id, an env that is not goal-conditioned or has no registered episode length,
    or a distance_threshold for an env without one (the mazes' radius is fixed) raises
    ConfigError (one line)."""
    try:
        made = gym.make(task.env_id, **make_kwargs)
    except gym.error.Error as err:
        raise ConfigError(f"task.env_id={task.env_id!r}: {' '.join(str(err).split())[:200]}; goal-conditioned envs "
                          f"include: {', '.join(goal_env_ids()[:12])}, ...") from None
    env = made.unwrapped
    if not is_goal_env(env):
        env.close()
        raise ConfigError(f"task.env_id={task.env_id!r} is not goal-conditioned (needs a dict observation with "
                          f"{', '.join(GOAL_KEYS)} and compute_reward); e.g. {', '.join(goal_env_ids()[:6])}")
    env.max_episode_steps = made.spec.max_episode_steps  # the id made: also an unversioned or module:id one
    if env.max_episode_steps is None:
        env.close()
        raise ConfigError(f"task.env_id={task.env_id!r} is registered without max_episode_steps: hersd runs episodes "
                          "of that many steps; register it with one")
    if task.distance_threshold is not None:
        if not hasattr(env, "distance_threshold"):
            env.close()
            raise ConfigError(f"task.distance_threshold: task.env_id={task.env_id!r} has no distance_threshold to "
                              f"replace (its success radius is fixed, {success_radius(env)}); leave it null")
        env.distance_threshold = float(task.distance_threshold)
    return env


def goal_env_ids() -> list[str]:
    """Registered gymnasium-robotics ids of sparse-reward Fetch and Hand envs (for error messages)."""
    return sorted(i for i in gym.registry if i.startswith(("Fetch", "Hand")) and "Dense" not in i)


def env_spec(env: Any) -> EnvSpec:
    """The sizes, horizon, success radius and reward range of an env made by :func:`make_env`."""
    obs_space = env.observation_space
    return EnvSpec(
        obs_dim=obs_space["observation"].shape[0],
        goal_dim=obs_space["desired_goal"].shape[0],
        action_dim=env.action_space.shape[0],
        horizon=env.max_episode_steps,
        max_action=float(env.action_space.high[0]),
        distance_threshold=success_radius(env),
        reward_range=reward_range(env),
    )


def check_success_reported(env: Any, task: TaskConfig) -> None:
    """ConfigError (one line) unless the step info of ``task``'s env (``env`` is one of them) reports success
    (:data:`SUCCESS_KEYS`). Fetch and Hand envs always do (gymnasium-robotics' RobotEnv.step); any other is
    stepped once from a reset in a scratch env of its own: the run's envs and random streams are untouched."""
    if reward_family(env) in ROBOT_FAMILIES:
        return
    scratch = make_env(task)
    try:
        scratch.reset(seed=0)
        info = scratch.step(np.zeros(scratch.action_space.shape, scratch.action_space.dtype))[-1]
    finally:
        scratch.close()
    if not any(key in info for key in SUCCESS_KEYS):
        raise ConfigError(f"task.env_id={task.env_id!r}: its step info has none of {', '.join(SUCCESS_KEYS)}, so "
                          f"hersd cannot tell success (info keys: {', '.join(sorted(info)) or 'none'})")


def step_success(info: dict) -> bool:
    """A step's success as the env reports it in its info (:data:`SUCCESS_KEYS`, checked by
    :func:`check_success_reported` before a run starts)."""
    return bool((info["is_success"] if "is_success" in info else info["success"]) > 0)
