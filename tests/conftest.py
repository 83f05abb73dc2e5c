"""Shared test settings: tiny run configs and the helpers every test file uses."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from hersd.runlog import EPOCH_FIELDS, read_run

# A run small enough for a unit test: FetchReach, 2 cycles of 5 updates on 64 transitions,
# one test round, no policy animation (tests/test_render.py renders) and no bias evaluation
# (tests/test_bias.py evaluates). Learning is not expected at this size; the code paths are all exercised.
TINY = ["task=reach", "task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1",
        "ddpg.batch_size=64", "render_every=0", "bias.epochs=[]"]
TIMING = [name for name in EPOCH_FIELDS if name.endswith("_seconds")]  # wall-clock fields: never compared


def metrics(log_path: Path) -> pd.DataFrame:
    """Every logged metric of a run except wall-clock timings (one row per epoch)."""
    return read_run(log_path).epochs.drop(columns=TIMING)


def run_command(module_main: str, *args: str, check: bool = False, timeout: float = 600,
                cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run a command's entry point (e.g. ``sweeps.launch:main``) in a fresh interpreter."""
    module, function = module_main.split(":")
    code = f"import sys; from {module} import {function}; sys.exit({function}())"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, check=check,
                          timeout=timeout, cwd=cwd)


@pytest.fixture
def tiny(tmp_path) -> list[str]:
    """TINY overrides writing below this test's temporary folder."""
    return [*TINY, "quiet=true", f"results_dir={tmp_path / 'results'}"]


@pytest.fixture
def idle_machine(monkeypatch):
    """threads=auto sees every core idle (in this process): its thread count no longer depends on
    what else the machine (e.g. another test worker) is doing."""
    from hersd import resources

    monkeypatch.setattr(resources, "idle_cores", lambda seconds=0.0: float(resources.available_cores()))


@pytest.fixture(scope="module")
def private_tempdir(tmp_path_factory):
    """The process's temporary folder is one of pytest's while a module runs: gymnasium-robotics' maze
    envs write their model file (``ant_maze<time>.xml``) beside a temporary directory and never remove it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tempfile, "tempdir", str(tmp_path_factory.mktemp("tempdir")))
        yield
