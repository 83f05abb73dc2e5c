"""Time ``hersd-report`` on 500 synthetic runs x 200 epochs (4 tasks x 25 configurations x 5 seeds).

    python benchmarks/bench_report.py [--keep DIR]

Runs ``python -m analysis.report FOLDER`` (what the ``hersd-report`` script runs) in a fresh
interpreter and prints its wall and CPU seconds and the split the report prints (load /
metrics / figures / html); fails (exit 1) when it takes 15 s or more of wall-clock time. The logs are written with
RunLogWriter in a temporary folder (not timed), or in ``--keep DIR`` to look at them after.
"""

from __future__ import annotations

import argparse
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

from analysis.synthetic import write_run
from hersd.config import AlgoConfig, MEPConfig, ScheduleConfig, TaskConfig, TrainConfig
from hersd.runstore import run_dir
from hersd.schedules import schedule_mean_rate

BUDGET_SECONDS = 15.0
EPOCHS = 200
SEEDS = 5
TASK_DIFFICULTY = {"reach": 0.02, "push": 0.25, "pick_and_place": 0.45, "slide": 0.8}


def configurations() -> list[tuple[AlgoConfig, ScheduleConfig]]:
    """25 (algo, schedule) pairs: HER, ARCHER, HER-MEP, linear-MEP, the paper's linear and
    exponential grids with lambda_h = 1 and 0.5, and five more exponential points."""
    her, archer = AlgoConfig(name="her"), AlgoConfig(name="archer", lambda_h=0.5)
    her_mep = AlgoConfig(name="her_mep", mep=MEPConfig(enabled=True))
    decays = [ScheduleConfig("linear", beta1=b) for b in (0.25, 0.5, 0.75, 1.0)]
    decays += [ScheduleConfig("exponential", beta1=b, beta2=b) for b in (0.25, 0.5, 0.75, 1.0)]
    extra = [ScheduleConfig("exponential", beta1=0.5, beta2=-0.5), ScheduleConfig("exponential", beta1=0.75, beta2=1.5),
             ScheduleConfig("exponential", beta1=1.0, beta2=-0.25), ScheduleConfig("exponential", beta1=0.25, beta2=-0.5),
             ScheduleConfig("exponential", beta1=0.5, beta2=1.0)]
    pairs = [(her, ScheduleConfig()), (archer, ScheduleConfig()), (her_mep, ScheduleConfig()),
             (her_mep, ScheduleConfig("linear", beta1=0.5))]
    pairs += [(algo, schedule) for algo in (her, archer) for schedule in decays]
    pairs += [(her, schedule) for schedule in extra]
    return pairs


def success_curve(rng: np.random.Generator, difficulty: float, mean_rate: float, epochs: int) -> np.ndarray:
    """A noisy logistic learning curve: 20 test episodes per epoch, faster when mu_eps is near 0.85."""
    speed = 1.0 - 2.0 * abs(mean_rate - 0.85) + rng.normal(0.0, 0.1)
    midpoint = epochs * (0.15 + difficulty) / max(speed, 0.2)
    ceiling = 1.0 - 0.6 * difficulty + rng.normal(0.0, 0.05)
    k = np.arange(1, epochs + 1)
    probability = np.clip(ceiling / (1.0 + np.exp(-(k - midpoint) / (0.08 * epochs))), 0.0, 1.0)
    return rng.binomial(20, probability) / 20.0


def write_logs(folder: Path) -> int:
    """Write the 500 synthetic run logs below ``folder``; returns how many.

    RunLogWriter fsyncs every message so a killed run keeps its epochs; here that only makes
    the setup slow on a busy disk (minutes), so fsync is a no-op while writing. The bytes
    written are the same.
    """
    with mock.patch("os.fsync", lambda fd: None):
        return _write_logs(folder)


def _write_logs(folder: Path) -> int:
    rng = np.random.default_rng(0)
    count = 0
    for task, difficulty in TASK_DIFFICULTY.items():
        for algo, schedule in configurations():
            for seed in range(SEEDS):
                config = TrainConfig(task=TaskConfig(name=task), algo=algo,
                                     schedule=schedule, seed=seed, epochs=EPOCHS, results_dir=str(folder))
                curve = success_curve(rng, difficulty, schedule_mean_rate(schedule, EPOCHS), EPOCHS)
                write_run(run_dir(config), config, curve)
                count += 1
    return count


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="write the logs and the report here instead of a temporary folder")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hersd-bench-") as temporary:
        folder = args.keep or Path(temporary)
        start = time.perf_counter()
        count = write_logs(folder)
        print(f"wrote {count} synthetic runs x {EPOCHS} epochs in {time.perf_counter() - start:.1f} s (not timed)")
        # The command as a user runs it: a fresh interpreter, imports included.
        start = time.perf_counter()
        finished = subprocess.run([sys.executable, "-m", "analysis.report", str(folder)], capture_output=True, text=True)
        total = time.perf_counter() - start
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(finished.stdout + finished.stderr, end="")
    if finished.returncode != 0:
        print(f"hersd-report failed with exit status {finished.returncode}")
        return 1
    stages = re.search(r"\((load .*)\)\s*$", finished.stdout).group(1)
    print(f"hersd-report on {count} runs: {total:.2f} s wall total, {cpu.ru_utime + cpu.ru_stime:.2f} s CPU; "
          f"stages: {stages}; the rest is interpreter start and imports; budget {BUDGET_SECONDS:g} s wall")
    return 0 if total < BUDGET_SECONDS else 1


if __name__ == "__main__":
    sys.exit(main())
