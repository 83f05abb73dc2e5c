"""What a sweep's listing (``hersd-sweep ... --dry-run``) shows of its runs, and how a sweep's job records its run's end.

Each run's state and detail are :func:`hersd.contract.runstore.run_status`'s (complete, running, failed, resumable,
new: read from the run store's files only, so it works while runs are training; ``hersd-train --dry-run`` shows the
same); :func:`time_to_go` sums what the listed runs have left.

A sweep's job records how its run ended: a failed run's ``error.log`` (:func:`failed_outcome`) and a line in the
sweep's progress file (:func:`record_progress`), neither of which a full disk turns into a traceback.
"""

from __future__ import annotations

import json
import re
import statistics
from pathlib import Path
from typing import Sequence

from hersd.contract.errors import DiskFullError, full_disk
from hersd.contract.runlog import replace_file
from hersd.contract.runstore import ERROR_NAME, RunStatus, ago, error_line


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
