"""sweeps/status.py: what a sweep's dry run shows for each run (the run lock and its holder's pid: tests/test_runstore.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np

from analysis.synthetic import write_run
from hersd.contract.config import TrainConfig
from hersd.contract.runstore import RunFolder, RunStatus, run_status
from sweeps.status import time_to_go

SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]


def write_log(directory: Path, epochs_done: int, complete: bool = False) -> Path:
    """A synthetic 200-epoch run's log holding ``epochs_done`` epochs (45 s each)."""
    with mock.patch("os.fsync"):
        return write_run(directory, TrainConfig(epochs=200), np.linspace(0, 1, epochs_done), complete=complete)


def test_each_state_with_its_progress(tmp_path):
    now = 1e10
    assert run_status(tmp_path / "nothing", 200) == RunStatus("new", "", 200)
    write_log(tmp_path / "done", 200, complete=True)
    # the mean test success of the last 10 epochs: (190 + ... + 199) / 199 / 10 = 0.977
    assert run_status(tmp_path / "done", 200) == \
        RunStatus("complete", "200 epochs, test success 0.98 over its last 10 epochs", 0)
    write_log(tmp_path / "paused", 12)
    (tmp_path / "paused" / "checkpoint.pt").write_bytes(b"")
    log_time = (tmp_path / "paused" / "run.mcap").stat().st_mtime
    assert run_status(tmp_path / "paused", 200, now=log_time + 3 * 3600) == \
        RunStatus("resumable", "epoch 12 of 200, last epoch 3.0 h ago, test success 0.59 over its last 10 epochs", 188)
    write_log(tmp_path / "lost", 5)
    lost = run_status(tmp_path / "lost", 200)
    assert lost.state == "new" and "epoch 5 of 200" in lost.detail and lost.epochs_left == 200  # starts afresh
    assert "test success 0.50 over its last 5 epochs" in lost.detail  # fewer than 10: the mean of all 5
    write_log(tmp_path / "training", 7)
    with RunFolder(tmp_path / "training").lock():
        training = run_status(tmp_path / "training", 200, now=now)
    assert training.state == "running" and (training.epochs_left, training.pace) == (193, 45.0)
    assert training.detail.startswith(f"epoch 7 of 200, pid {os.getpid()}, 45 s per epoch, ~2.4 h to go")  # 193 x 45 s


def test_time_to_go_sums_the_epochs_left_at_the_median_pace_of_the_runs_training():
    statuses = [RunStatus("complete", "", 0), RunStatus("running", "", 100, 30.0), RunStatus("running", "", 50, 50.0),
                RunStatus("running", "", 10, 20.0), RunStatus("resumable", "", 40), RunStatus("new", "", 200)]
    # 400 epochs at 30 s (the median of 20, 30, 50), 2 at once: 6000 s
    assert time_to_go(statuses, 2) == ("to go: 5 runs, 400 epochs, ~100 min at 2 runs at once and 30 s per epoch "
                                       "(the median pace of the runs training now)")
    assert time_to_go(statuses[4:], 2) == "to go: 2 runs, 240 epochs"  # none trains: no pace to go by
    assert time_to_go(statuses, None) == "to go: 5 runs, 400 epochs"  # a cluster's runs: no time
    assert time_to_go([RunStatus("running", "", 10, 20.0)], 8) == \
        "to go: 1 run, 10 epochs, ~3 min at 1 run at once and 20 s per epoch (the median pace of the runs training now)"
    assert time_to_go(statuses[:1], 2) is None


def test_a_dry_run_lists_each_run_with_its_state_and_the_pids_training(tmp_path):
    args = ["+grid=smoke", "schedule=constant", f"results_dir={tmp_path}", "--dry-run"]
    first = subprocess.run([*SWEEP, *args], capture_output=True, text=True, check=True).stdout
    runs = [Path(line.split()[1]) for line in first.splitlines() if line.startswith("  new ")]
    write_log(runs[0], 4, complete=True)
    write_log(runs[1], 2)
    with RunFolder(runs[1]).lock():
        out = subprocess.run([*SWEEP, *args], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out[1].split()[:3] == ["complete", str(runs[0]), "4"]
    assert out[2].split()[:2] == ["running", str(runs[1])] and f"epoch 2 of 4, pid {os.getpid()}," in out[2]
    assert out[-2] == f"1 training now (pid {os.getpid()})"
    assert out[-1].startswith("to go: 1 run, 2 epochs, ~")  # the running run's 2 epochs left


def test_a_dry_run_read_in_part_ends_quietly(tmp_path):
    read, write = os.pipe()
    os.close(read)  # as `| head` does once it has its lines
    listed = subprocess.run([*SWEEP, "+grid=smoke", f"results_dir={tmp_path}", "--dry-run"], stdout=write,
                            stderr=subprocess.PIPE, text=True)
    os.close(write)
    assert (listed.returncode, listed.stderr) == (-signal.SIGPIPE, "")


def test_a_run_that_stopped_with_an_error_is_failed_with_the_first_line_of_its_error(tmp_path):
    """A sweep's run that raised (its traceback in error.log, written after its log) is ``failed``, never a run
    to resume or start as if nothing happened; a log written after the error (the run went on) is not."""
    write_log(tmp_path / "crashed", 2)
    (tmp_path / "crashed" / "checkpoint.pt").write_bytes(b"")
    error = tmp_path / "crashed" / "error.log"
    error.write_text("Traceback (most recent call last):\n  File \"train.py\", line 3, in <module>\n    step()\n"
                     "RuntimeError: [enforce fail at inline_container.cc:672]\n  more of its message\n")
    log_time = (tmp_path / "crashed" / "run.mcap").stat().st_mtime
    os.utime(error, (log_time + 5, log_time + 5))
    status = run_status(tmp_path / "crashed", 200, now=log_time + 60)
    assert status.state == "failed" and status.epochs_left == 198
    assert status.detail.startswith("RuntimeError: [enforce fail at inline_container.cc:672], epoch 2 of 200")
    (tmp_path / "at_start").mkdir()  # failed before its first epoch: no log, no checkpoint
    (tmp_path / "at_start" / "error.log").write_text("Traceback (most recent call last):\n  File \"x\"\nOSError: "
                                                      "[Errno 28] No space left on device\n")
    assert run_status(tmp_path / "at_start", 2) == RunStatus("failed", "OSError: [Errno 28] No space left on device", 2)
    os.utime(error, (log_time - 5, log_time - 5))  # the run was resumed after the error: the log is newer
    assert run_status(tmp_path / "crashed", 200).state == "resumable"
