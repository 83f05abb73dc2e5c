"""A run's state as a sweep's listing (``hersd-sweep ... --dry-run``) shows it: read from the run
store's files only (its log, checkpoint and lock file), so it works while runs are training.

- ``complete``   the log has its complete marker;
- ``running``    a live process holds the run's lock (the pid it recorded in ``run.lock``):
                 ``epoch N of K``, that pid, the recent pace and the time to go;
- ``resumable``  ``epoch N of K`` logged and a checkpoint to resume from;
- ``new``        nothing yet, or a log without checkpoint (set aside when the run starts again).

Runs started by hersd before lock files recorded pids show as ``resumable`` while they train;
the age of their last epoch tells the two apart.
"""

from __future__ import annotations

import time
from pathlib import Path

from hersd.contract.runlog import RunLogError
from hersd.contract.runstore import RunFolder

PACE_EPOCHS = 5  # a run's pace: the mean time of its last this many epochs


def ago(seconds: float) -> str:
    """``25 s``, ``14 min``, ``3.2 h``."""
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 \
        else f"{seconds / 3600:.1f} h"


def run_status(directory: Path, epochs: int, now: float | None = None) -> tuple[str, str]:
    """(state, detail) of the run in ``directory`` planned for ``epochs`` epochs, e.g.
    ``("running", "epoch 45 of 200, pid 1701, 31 s per epoch, ~2.7 h to go, last epoch 12 s ago")``."""
    folder = RunFolder(directory)
    holder = folder.holder()
    done: list = []
    detail = []
    try:
        records = folder.records()
    except RunLogError as err:
        detail.append(f"log unreadable ({str(err).removeprefix(f'{folder.log}: ')})")
    else:
        if records is not None and records.complete:
            return "complete", f"{len(records.records)} epochs"
        if records is not None:
            done = records.records
            detail.append(f"epoch {len(done)} of {epochs}")
    if not done and holder is not None and not detail:
        detail.append(f"epoch 0 of {epochs}")
    if holder is not None:
        detail.append(f"pid {holder}")
        recent = [record["epoch_seconds"] for record in done[-PACE_EPOCHS:]]
        if recent:
            per_epoch = sum(recent) / len(recent)
            detail.append(f"{per_epoch:.0f} s per epoch, ~{ago(per_epoch * max(epochs - len(done), 0))} to go")
    if done:
        detail.append(f"last epoch {ago(max(0.0, (now or time.time()) - folder.log.stat().st_mtime))} ago")
    has_checkpoint = folder.checkpoint.exists()
    if holder is not None:
        return "running", ", ".join(detail)
    if has_checkpoint:
        return "resumable", ", ".join(detail)
    if detail:
        detail.append("no checkpoint: starts afresh, the log kept aside")
    return "new", ", ".join(detail)
