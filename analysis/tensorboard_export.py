"""``hersd-report FOLDER --tensorboard DIR``: every run log below FOLDER as TensorBoard event files, no training.

One folder per run, ``DIR/<task title>/<configuration label>/seed<N>/`` (the report's labels,
:mod:`analysis.load`), so ``tensorboard --logdir DIR`` lists ``FetchPush/linear b1=0.25/seed0``; in each,
what :mod:`hersd.contract.tensorboard_events` writes (the files a run with ``tensorboard=true`` writes as
it trains). Re-running replaces: each run's folder is rewritten, and event files below DIR that this
conversion did not write (a run since relabelled, or gone) are removed, with the folders they leave empty.
Needs the tensorboard package, not torch.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from analysis.load import load_runs
from hersd.contract.tasks import task_title
from hersd.contract.tensorboard_events import EVENT_FILES, require_tensorboard, write_run_events


def run_folder_name(task: str, label: str, seed: int) -> Path:
    """A run's folder below DIR, its name in TensorBoard's run selector: ``FetchPush/HER eps=0.874375/seed0``
    (a ``/`` inside a label becomes ``|``, so it makes no folder)."""
    return Path(task_title(task), label.replace("/", "|"), f"seed{seed}")


def export_events(folder: str | Path, out: str | Path, tasks: Iterable[str] | None = None,
                  algos: Iterable[str] | None = None) -> list[Path]:
    """Event files of every run below ``folder`` (those of ``tasks`` / ``algos`` if given) into ``out``;
    returns the runs' folders written (ConfigError without tensorboard, ReportInputError without logs)."""
    require_tensorboard("--tensorboard")
    folder, out = Path(folder), Path(out)
    table = load_runs(folder, tasks, algos)
    written = []
    for run in table.runs.itertuples():
        target = out / run_folder_name(run.task, str(run.config), run.seed)
        write_run_events(folder / run.path, target)
        written.append(target)
    kept = set(written)
    for stale in list(out.rglob(EVENT_FILES)):
        if stale.parent not in kept:
            stale.unlink()
            for parent in stale.parents:
                if parent == out or any(parent.iterdir()):
                    break
                parent.rmdir()
    return written
