"""A run's state as a sweep's listing (``hersd-sweep ... --dry-run``) shows it: read from the run
store's files only (its log, checkpoint and lock file), so it works while runs are training.

- ``complete``   the log has its complete marker;
- ``running``    a live process holds the run's lock (the pid it recorded in ``run.lock``):
                 ``epoch N of K``, that pid, the recent pace and the time to go;
- ``failed``     it stopped with an error (``error.log`` newer than its log): the error's first line, the
                 epochs logged; a re-run resumes it (a checkpoint) or starts it afresh;
- ``resumable``  ``epoch N of K`` logged and a checkpoint to resume from;
- ``new``        nothing yet, or a log without checkpoint (set aside when the run starts again).

Runs started by hersd before lock files recorded pids show as ``resumable`` while they train;
the age of their last epoch tells the two apart. A run with logged epochs also shows how it learns: its
mean test success over its last RECENT_EPOCHS. :func:`time_to_go` sums what the listed runs have left.

A sweep's job records how its run ended: a failed run's ``error.log`` (:func:`failed_outcome`) and a line in the
sweep's progress file (:func:`record_progress`), neither of which a full disk turns into a traceback.
"""

from __future__ import annotations

import json
import re
import statistics
import time
from pathlib import Path
from typing import NamedTuple, Sequence

from hersd.contract.errors import DiskFullError, full_disk
from hersd.contract.runlog import RunLogError, replace_file
from hersd.contract.runstore import ERROR_NAME, RunFolder, error_line

PACE_EPOCHS = 5  # a run's pace: the mean time of its last this many epochs
RECENT_EPOCHS = 10  # how a run learns at a glance: its mean test success over its last this many epochs


def ago(seconds: float) -> str:
    """``25 s``, ``14 min``, ``3.2 h``."""
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 \
        else f"{seconds / 3600:.1f} h"


class RunStatus(NamedTuple):
    """A run's line in a sweep's listing: its state and detail, the epochs it has left, and, while it trains,
    its pace (seconds per epoch, the mean of its last PACE_EPOCHS) and the pid holding its lock."""

    state: str
    detail: str
    epochs_left: int
    pace: float | None = None
    holder: int | None = None


def recent_success(records: Sequence[dict]) -> str:
    """``test success 0.35 over its last 10 epochs``: the mean of the last RECENT_EPOCHS epochs' test success
    (``records``: the log's epoch records, at least one)."""
    recent = [record["test_success"] for record in records[-RECENT_EPOCHS:]]
    return f"test success {sum(recent) / len(recent):.2f} over its last {len(recent)} epoch{'s' * (len(recent) > 1)}"


def run_status(directory: Path, epochs: int, now: float | None = None) -> RunStatus:
    """The status of the run in ``directory`` planned for ``epochs`` epochs, e.g. state ``running``, detail
    ``epoch 45 of 200, pid 1701, 31 s per epoch, ~2.7 h to go, last epoch 12 s ago, test success 0.35 over its
    last 10 epochs``, 155 epochs left, pace 31."""
    folder = RunFolder(directory)
    holder = folder.holder()
    done: list = []
    detail = []
    pace = None
    try:
        records = folder.records()
    except RunLogError as err:
        detail.append(f"log unreadable ({str(err).removeprefix(f'{folder.log}: ')})")
    else:
        if records is not None and records.complete:
            return RunStatus("complete", f"{len(records.records)} epochs, {recent_success(records.records)}", 0)
        if records is not None:
            done = records.records
            detail.append(f"epoch {len(done)} of {epochs}")
    if not done and holder is not None and not detail:
        detail.append(f"epoch 0 of {epochs}")
    if holder is not None:
        detail.append(f"pid {holder}")
        recent = [record["epoch_seconds"] for record in done[-PACE_EPOCHS:]]
        if recent:
            pace = sum(recent) / len(recent)
            detail.append(f"{pace:.0f} s per epoch, ~{ago(pace * max(epochs - len(done), 0))} to go")
    if done:
        detail.append(f"last epoch {ago(max(0.0, (now or time.time()) - folder.log.stat().st_mtime))} ago")
        detail.append(recent_success(done))
    left = max(epochs - len(done), 0)
    if holder is not None:
        return RunStatus("running", ", ".join(detail), left, pace, holder)
    if (error := folder.error()) is not None:
        return RunStatus("failed", ", ".join([error, *detail]), left if folder.checkpoint.exists() else epochs)
    if folder.checkpoint.exists():
        return RunStatus("resumable", ", ".join(detail), left)
    if detail:
        detail.append("no checkpoint: starts afresh, the log kept aside")
    return RunStatus("new", ", ".join(detail), epochs)


def time_to_go(statuses: Sequence[RunStatus], at_once: int | None) -> str | None:
    """What the listed runs have left, e.g. ``to go: 21 runs, 3880 epochs, ~11 h at 2 runs at once and 20 s
    per epoch (the median pace of the runs training now)``: the time only when some run trains and the
    sweep's runs share this machine (``at_once``, :func:`sweeps.launch.concurrent_runs`; None on a cluster).
    None when nothing is left."""
    left = [status for status in statuses if status.state != "complete"]
    if not left:
        return None
    epochs = sum(status.epochs_left for status in left)
    line = f"to go: {len(left)} run{'s' * (len(left) > 1)}, {epochs} epochs"
    paces = [status.pace for status in left if status.pace is not None]
    if paces and at_once:
        pace, at_once = statistics.median(paces), min(at_once, len(left))
        line += (f", ~{ago(epochs * pace / at_once)} at {at_once} run{'s' * (at_once > 1)} at once and {pace:.0f} s "
                 "per epoch (the median pace of the runs training now)")
    return line


def failed_outcome(directory: Path, error: str) -> dict[str, str]:
    """How a sweep's job records its run stopped by ``error`` (a traceback): ``error.log`` in the run's folder,
    written whole (:func:`hersd.contract.runlog.replace_file`: never a temporary or half-written file) ->
    ``{"status": "failed", "error_log": <its path>}``. On a full disk, where the error log cannot be written either,
    ``{"status": "failed", "full_disk": <one line>}``: the error log, the bytes it needs and the run's error, which the
    sweep ends with (exit 2). Any other error writing it is raised."""
    path, data = directory / ERROR_NAME, error.encode()
    try:
        directory.mkdir(parents=True, exist_ok=True)
        replace_file(path, data)
    except (OSError, DiskFullError) as err:
        if not full_disk(err):
            raise
        stopped = re.sub(r"^(\w+\.)+(?=\w+(:|$))", "", error_line(error))  # DiskFullError, not hersd.contract....
        then = (f"the run stopped with {stopped}; free some and run the same command again (finished runs are kept "
                "and skipped, the others resume)")
        return {"status": "failed", "full_disk": str(DiskFullError(path, len(data), then))}
    return {"status": "failed", "error_log": str(path)}


def record_progress(path: Path, outcome: dict) -> int:
    """Append ``outcome`` to the sweep's progress file ``path`` (one JSON line, one write) -> the runs it records,
    this one included. On a full disk the line is left out (the outcome still reaches the sweep's summary)."""
    try:
        with open(path, "a") as progress:
            progress.write(json.dumps(outcome) + "\n")
    except OSError as err:
        if not full_disk(err):
            raise
        return len(path.read_bytes().splitlines()) + 1 if path.exists() else 1
    return len(path.read_bytes().splitlines())
