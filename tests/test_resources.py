"""threads=auto: the cores a run may use (affinity, SLURM_CPUS_PER_TASK), shared among the runs
in flight, never more than other processes leave idle (hersd/contract/cores.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from hersd.contract import cores as shared_cores
from hersd.contract.cores import available_cores, idle_cores, resolve_threads


def test_slurm_cpus_per_task_caps_the_cores(monkeypatch):
    affinity = len(os.sched_getaffinity(0))
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", "1")
    assert available_cores() == 1
    monkeypatch.setenv("SLURM_CPUS_PER_TASK", str(affinity + 7))  # never more than the mask
    assert available_cores() == affinity
    monkeypatch.delenv("SLURM_CPUS_PER_TASK")
    assert available_cores() == affinity


def test_idle_cores_add_up_the_idle_share_of_each_core(monkeypatch):
    samples = iter([{0: (100, 1000), 1: (500, 1000)},    # (idle + iowait, total) jiffies
                    {0: (100, 1100), 1: (600, 1100)}])   # cpu0 fully busy, cpu1 fully idle
    monkeypatch.setattr(shared_cores, "_affinity", lambda: [0, 1])
    monkeypatch.setattr(shared_cores, "_cpu_times", lambda cpus: next(samples))
    monkeypatch.delenv("SLURM_CPUS_PER_TASK", raising=False)
    assert idle_cores(seconds=0.0) == pytest.approx(1.0)


@pytest.mark.parametrize("cores, idle, concurrent, expected", [
    (2, 2.0, 1, 2),    # idle machine, a lone run: every core
    (2, 0.9, 1, 1),    # one neighbour busy: the one idle core
    (2, 0.0, 1, 1),    # all busy: still one thread
    (8, 8.0, 2, 4),    # two runs in flight share the cores
    (8, 2.6, 2, 3),    # ... but take no more than the idle ones
])
def test_auto_takes_the_share_of_idle_cores(monkeypatch, cores, idle, concurrent, expected):
    monkeypatch.setattr(shared_cores, "available_cores", lambda: cores)
    monkeypatch.setattr(shared_cores, "idle_cores", lambda seconds=0.0: idle)
    assert resolve_threads("auto", concurrent) == expected
    assert resolve_threads("3", concurrent) == 3  # an explicit count is used as given


@pytest.mark.skipif(available_cores() < 2, reason="needs 2 cores: one for the neighbour")
def test_a_busy_neighbour_is_seen_on_the_real_machine():
    """A process spinning on one of our cores leaves at most cores - 1/2 idle (whatever else runs)."""
    cpu = sorted(os.sched_getaffinity(0))[0]
    spin = f"import os, time; os.sched_setaffinity(0, {{{cpu}}}); end = time.time() + 20\nwhile time.time() < end: pass"
    neighbour = subprocess.Popen([sys.executable, "-c", spin])
    try:
        idle_cores(0.3)  # let it start spinning
        assert idle_cores(0.5) <= available_cores() - 0.5
    finally:
        neighbour.kill()
        neighbour.wait()


def test_a_lone_run_on_a_busy_machine_takes_only_the_idle_cores(tmp_path, monkeypatch):
    from helpers import TINY

    from hersd.contract.compose import compose_train
    from hersd.contract.runlog import read_run
    from hersd.engine.train import train

    monkeypatch.setattr(shared_cores, "idle_cores", lambda seconds=0.0: available_cores() - 1.0)
    log = train(compose_train([*TINY, "epochs=1", "quiet=true", "threads=auto", f"results_dir={tmp_path}"]))
    assert read_run(log).meta["threads"] == max(1, available_cores() - 1)
