"""sweeps/status.py: what a sweep's dry run shows for each run (the run lock and its holder's pid: tests/test_runstore.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np

from analysis.synthetic import write_run
from hersd.contract.config import TrainConfig
from hersd.contract.runstore import RunFolder
from sweeps.status import run_status

SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]


def write_log(directory: Path, epochs_done: int, complete: bool = False) -> Path:
    """A synthetic 200-epoch run's log holding ``epochs_done`` epochs (45 s each)."""
    with mock.patch("os.fsync"):
        return write_run(directory, TrainConfig(epochs=200), np.linspace(0, 1, epochs_done), complete=complete)


def test_each_state_with_its_progress(tmp_path):
    now = 1e10
    assert run_status(tmp_path / "nothing", 200) == ("new", "")
    write_log(tmp_path / "done", 200, complete=True)
    assert run_status(tmp_path / "done", 200) == ("complete", "200 epochs")
    write_log(tmp_path / "paused", 12)
    (tmp_path / "paused" / "checkpoint.pt").write_bytes(b"")
    log_time = (tmp_path / "paused" / "run.mcap").stat().st_mtime
    assert run_status(tmp_path / "paused", 200, now=log_time + 3 * 3600) == \
        ("resumable", "epoch 12 of 200, last epoch 3.0 h ago")
    write_log(tmp_path / "lost", 5)
    assert run_status(tmp_path / "lost", 200)[0] == "new"
    assert "epoch 5 of 200" in run_status(tmp_path / "lost", 200)[1]
    write_log(tmp_path / "training", 7)
    with RunFolder(tmp_path / "training").lock():
        state, detail = run_status(tmp_path / "training", 200, now=now)
    assert state == "running"
    assert detail.startswith(f"epoch 7 of 200, pid {os.getpid()}, 45 s per epoch, ~2.4 h to go")  # 193 x 45 s


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
    assert out[-1] == f"1 training now (pid {os.getpid()})"
