"""``hersd-report FOLDER --tensorboard DIR``: every run log below FOLDER as TensorBoard event files, no training.

One folder per run, ``DIR/<task title>/<configuration label>/seed<N>/`` (the report's labels,
:mod:`analysis.load`), so ``tensorboard --logdir DIR`` lists ``FetchPush/linear b1=0.25/seed0``; in each,
what :mod:`hersd.contract.tensorboard_events` writes (the files a run with ``tensorboard=true`` writes as
it trains). Re-running replaces: each run's folder is rewritten, and a run folder an earlier conversion wrote
(listed in DIR's :data:`MANIFEST`) of the tasks and algos converted now that this one did not write (a run since
relabelled, or gone) loses its event files, with the folders they leave empty. Nothing else below DIR is touched
(another tool's runs, a live run's ``tensorboard/`` folder when DIR is FOLDER, the runs of a task filtered out).
Needs the tensorboard package, not torch.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable

from analysis.load import RunTable, load_runs
from hersd.contract.runlog import replace_file
from hersd.contract.tasks import task_title
from hersd.contract.tensorboard_events import EVENT_FILES, require_tensorboard, write_run_events

MANIFEST = ".hersd-tensorboard.json"  # {run folder relative to DIR: {"task": name, "algo": name}} of what it wrote


def run_folder_name(task: str, label: str, seed: int) -> Path:
    """A run's folder below DIR, its name in TensorBoard's run selector: ``FetchPush/HER eps=0.874375/seed0``
    (a ``/`` inside a label becomes ``|``, so it makes no folder)."""
    return Path(task_title(task), label.replace("/", "|"), f"seed{seed}")


def export_events(folder: str | Path, out: str | Path, tasks: Iterable[str] | None = None,
                  algos: Iterable[str] | None = None) -> tuple[list[Path], RunTable]:
    """Event files of every run below ``folder`` (those of ``tasks`` / ``algos`` if given) into ``out`` -> (the
    runs' folders written, the runs read: their warnings name the logs left out); ConfigError without
    tensorboard, ReportInputError without logs."""
    require_tensorboard("--tensorboard")
    folder, out = Path(folder), Path(out)
    table = load_runs(folder, tasks, algos)
    written: dict[str, dict[str, str]] = {}
    for run in table.runs.itertuples():
        target = run_folder_name(run.task, str(run.config), run.seed)
        write_run_events(folder / run.path, out / target)
        written[target.as_posix()] = {"task": run.task, "algo": run.algo}
    earlier = _manifest(out)
    stale = [name for name, run in earlier.items() if name not in written
             and (tasks is None or run["task"] in tasks) and (algos is None or run["algo"] in algos)]
    for name in stale:
        _remove_events(out, out / name)
    kept = {name: run for name, run in earlier.items() if name not in stale}
    replace_file(out / MANIFEST, json.dumps({**kept, **written}, indent=1, sort_keys=True).encode())
    return [out / name for name in written], table


def _manifest(out: Path) -> dict[str, dict[str, str]]:
    """The run folders earlier conversions into ``out`` wrote (none if no manifest, or not one of ours)."""
    try:
        listed = json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    return {name: run for name, run in listed.items() if isinstance(run, dict)} if isinstance(listed, dict) else {}


def _remove_events(out: Path, run_folder: Path) -> None:
    """The event files of a run folder below ``out``, and the folders that leaves empty up to ``out``."""
    for stale in run_folder.glob(EVENT_FILES):
        stale.unlink()
    for parent in (run_folder, *run_folder.parents):
        if parent == out or not parent.is_dir() or any(parent.iterdir()):
            break
        parent.rmdir()
