"""Plain values and functions the tests import (``from helpers import TINY, metrics``): tiny run configs, tiny
learners and their batches, a run's metrics, a command in a fresh interpreter. Fixtures live in conftest.py."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

from hersd.contract.runlog import EPOCH_FIELDS, read_run

# A run small enough for a unit test: FetchReach, 2 cycles of 5 updates on 64 transitions,
# one test round, no policy animation (tests/test_render.py renders) and no bias evaluation
# (tests/test_bias.py evaluates). Learning is not expected at this size; the code paths are all exercised.
TINY = ["task=reach", "task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1",
        "ddpg.batch_size=64", "render_every=0", "bias.epochs=[]"]
TIMING = [name for name in EPOCH_FIELDS if name.endswith("_seconds")]  # wall-clock fields: never compared

# Learners small enough for unit tests of their update rules (tests/test_ddpg.py, test_learners.py,
# test_learner_rules.py): 2 x 16 networks, obs/goal/action sizes 5/3/2, hand-made batches of 16, no env.
OBS, GOAL, ACTION, BATCH = 5, 3, 2, 16


def tiny_spec(max_action: float = 1.0):
    """An EnvSpec of the tiny learners' sizes (a Fetch-like horizon and reward range)."""
    from hersd.engine.envs.make import EnvSpec

    return EnvSpec(obs_dim=OBS, goal_dim=GOAL, action_dim=ACTION, horizon=50, max_action=max_action,
                   distance_threshold=0.05, reward_range=(-1.0, 0.0))


def tiny_learner(name: str = "ddpg", max_action: float = 1.0, seed: int = 0,
                 q_range: tuple[float, float] = (-50.0, 0.0), ddpg: dict | None = None, **settings):
    """Learner ``name`` built by its class from torch seed ``seed`` (gamma 0.98, target range ``q_range``), with
    ``ddpg.*`` changes and its own settings (``learner.<name>.*``); its normalisers have seen 100 random rows."""
    import numpy as np
    import torch

    from hersd.contract.config import DDPGConfig, LearnerConfig, TrainConfig
    from hersd.engine.learners import learner_class

    learner = LearnerConfig(name=name)
    if settings:
        learner.settings = type(learner.settings)(**settings)
    cfg = TrainConfig(ddpg=DDPGConfig(hidden_layers=2, hidden_units=16, **(ddpg or {})), learner=learner)
    torch.manual_seed(seed)
    agent = learner_class(name).build(cfg, tiny_spec(max_action), 0.98, q_range, torch.device("cpu"))
    rng = np.random.default_rng(0)
    agent.update_normalizers(rng.normal(size=(100, OBS)), rng.normal(size=(100, GOAL)))
    return agent


def batch(reward: float = -1.0, seed: int = 1):
    """A TransitionBatch of BATCH random transitions with one reward, no relabelled row."""
    import numpy as np

    from hersd.engine.replay.buffer import TransitionBatch

    rng = np.random.default_rng(seed)
    f32 = np.float32
    return TransitionBatch(obs=rng.normal(size=(BATCH, OBS)).astype(f32),
                           next_obs=rng.normal(size=(BATCH, OBS)).astype(f32), goal=rng.normal(size=(BATCH, GOAL)).astype(f32),
                           action=rng.uniform(-1, 1, size=(BATCH, ACTION)).astype(f32),
                           reward=np.full(BATCH, reward, f32), relabelled=np.zeros(BATCH, bool),
                           real_success=np.zeros(BATCH, bool), episode=np.zeros(BATCH, int), t=np.zeros(BATCH, int))


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


def command(module_main: str, args: list[str], module_dir: Path) -> subprocess.CompletedProcess:
    """A command's entry point in a fresh interpreter with ``module_dir`` on PYTHONPATH."""
    module, function = module_main.split(":")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(module_dir), os.environ.get("PYTHONPATH", "")])}
    code = f"import sys; from {module} import {function}; sys.exit({function}())"
    result = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=600, env=env)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    return result


def train_killed_at_epoch(args: list[str], epoch: int = 2) -> None:
    """Run ``hersd-train args`` (``quiet=false``: it prints each epoch) in a fresh interpreter and SIGKILL it
    as it prints epoch ``epoch``'s first line: the log then holds the epochs before it, and maybe that one."""
    import signal
    proc = subprocess.Popen([sys.executable, "-m", "hersd.engine.cli", *args], stdout=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if line.startswith("epoch") and line.split()[1].startswith(f"{epoch}/"):
            os.kill(proc.pid, signal.SIGKILL)
            break
    proc.wait()
    assert proc.returncode == -signal.SIGKILL


def full_disk_writes(monkeypatch, pattern: str) -> None:
    """Every file opened for writing whose name matches ``pattern`` fails as on a full disk: it is created, its
    first bytes written, then ENOSPC (``open`` and ``io.open`` replaced: whatever writes it, hersd or a library)."""
    import builtins
    import errno
    import io

    real_open = builtins.open

    class Full:
        def __init__(self, stream) -> None:
            self.stream = stream

        def __enter__(self) -> "Full":
            return self

        def __exit__(self, *exc_info) -> None:
            self.stream.close()

        def __getattr__(self, name: str):
            return getattr(self.stream, name)

        def write(self, data) -> int:
            self.stream.write(data[:16])
            self.stream.flush()
            raise OSError(errno.ENOSPC, "No space left on device")

    def full_open(file, mode="r", *args, **kwargs):
        stream = real_open(file, mode, *args, **kwargs)
        named = isinstance(file, (str, os.PathLike)) and Path(file).match(pattern)
        return Full(stream) if named and set(mode) & set("wax+") else stream

    monkeypatch.setattr(builtins, "open", full_open)
    monkeypatch.setattr(io, "open", full_open)


def group_alive(group: int, seconds: float = 10.0) -> bool:
    """Whether processes of the process group ``group`` are still running after ``seconds``."""
    import time

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            return False
        time.sleep(0.1)
    return True


def killed_while_training(command: list[str], folder: Path, stderr: Path | None = None) -> int:
    """Start ``command`` (a sweep or search of two runs at once, in a session of its own, stderr into the file
    ``stderr`` if given), SIGKILL its main process alone once both runs under ``folder`` train (each has a
    checkpoint), and check that every process it started is gone within 5 s -> its pid (its process group)."""
    import signal
    import time

    with open(stderr or os.devnull, "w") as err:
        proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
    deadline = time.monotonic() + 300
    while len(list(folder.rglob("checkpoint.pt"))) < 2 and time.monotonic() < deadline:  # both runs training
        time.sleep(0.2)
    assert proc.poll() is None
    os.kill(proc.pid, signal.SIGKILL)  # no signal reaches its workers
    proc.wait()
    assert not group_alive(proc.pid, seconds=5)  # the workers and the resource trackers are gone
    return proc.pid
