"""Time ``hersd-report`` on 500 synthetic runs x 200 epochs (4 tasks x 25 configurations x 5 seeds).

    python benchmarks/bench_report.py [--keep DIR] [--repeat 5]

Runs ``python -m analysis.report FOLDER`` (what the ``hersd-report`` script runs) in a fresh
interpreter, as a user would, and prints its wall and CPU seconds (CPU: the report and its
worker processes) and the split: interpreter start and ``import analysis.report`` (timed
alone in another fresh interpreter), then the stages the report prints, one after another (load,
including the imports of scipy and matplotlib done while worker processes read the logs; metrics: the
curves; figures, drawn by worker processes while the report computes the statistics and writes the
table files, both timed inside it; writing: the page). ``--repeat N`` (default 5) runs it N times and
prints the CPU (model name, family, model: ``rounds.py``), each run and the median (min-max) wall and CPU
seconds, with the split of the median run. Fails (exit 1) when the median takes 8 s or more of wall-clock
time. The logs are written with RunLogWriter in a temporary folder (not timed), or
in ``--keep DIR`` to look at them after.
"""

from __future__ import annotations

import argparse
import os
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
from hersd.contract.config import AlgoConfig, MEPConfig, TaskConfig, TrainConfig
from hersd.contract.runstore import run_dir
from hersd.contract.schedules import Constant, Exponential, Linear, Schedule

from rounds import cpu_line, spread

BUDGET_SECONDS = 8.0
EPOCHS = 200
SEEDS = 5
TASK_DIFFICULTY = {"reach": 0.02, "push": 0.25, "pick_and_place": 0.45, "slide": 0.8}


def configurations() -> list[tuple[AlgoConfig, Schedule]]:
    """25 (algo, schedule) pairs: HER, ARCHER, HER-MEP, linear-MEP, the paper's linear and
    exponential grids with lambda_h = 1 and 0.5, and five more exponential points."""
    her, archer = AlgoConfig(name="her"), AlgoConfig(name="archer", lambda_h=0.5)
    her_mep = AlgoConfig(name="her_mep", mep=MEPConfig(enabled=True))
    decays = [Linear(beta1=b) for b in (0.25, 0.5, 0.75, 1.0)]
    decays += [Exponential(beta1=b, beta2=b) for b in (0.25, 0.5, 0.75, 1.0)]
    extra = [Exponential(beta1=0.5, beta2=-0.5), Exponential(beta1=0.75, beta2=1.5),
             Exponential(beta1=1.0, beta2=-0.25), Exponential(beta1=0.25, beta2=-0.5),
             Exponential(beta1=0.5, beta2=1.0)]
    pairs = [(her, Constant()), (archer, Constant()), (her_mep, Constant()),
             (her_mep, Linear(beta1=0.5))]
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
                curve = success_curve(rng, difficulty, config.schedule.exact_mean_rate(EPOCHS), EPOCHS)
                write_run(run_dir(config), config, curve)
                count += 1
    return count


def time_report(folder: Path) -> tuple[float, float, str]:
    """One ``python -m analysis.report folder`` in a fresh interpreter -> (wall s, CPU s, its last line)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    finished = subprocess.run([sys.executable, "-m", "analysis.report", str(folder)], capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)  # includes the report's own worker processes
    if finished.returncode != 0:
        raise SystemExit(f"hersd-report failed with exit status {finished.returncode}:\n{finished.stderr}")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return wall, cpu, finished.stdout.strip().splitlines()[-1]


def time_start_up() -> float:
    """Wall seconds of a fresh interpreter that only imports the report's module."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import analysis.report"], check=True)
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="write the logs and the report here instead of a temporary folder")
    parser.add_argument("--repeat", type=int, default=5, help="time the report this many times (default 5)")
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    print(cpu_line())
    with tempfile.TemporaryDirectory(prefix="hersd-bench-") as temporary:
        folder = args.keep or Path(temporary)
        start = time.perf_counter()
        count = write_logs(folder)
        print(f"wrote {count} synthetic runs x {EPOCHS} epochs in {time.perf_counter() - start:.1f} s (not timed)")
        timings = [time_report(folder) for _ in range(args.repeat)]
        start_up = min(time_start_up() for _ in range(args.repeat))
    for wall, cpu, line in timings:
        print(f"  {wall:.2f} s wall, {cpu:.2f} s CPU: {line}")
    walls = sorted(timing[0] for timing in timings)
    median_wall = float(np.median(walls))
    wall, _, line = sorted(timings)[(len(timings) - 1) // 2]  # the median run (the lower of two middle ones)
    stages = re.search(r"\((load .*)\)\s*$", line).group(1)
    print(f"hersd-report on {count} runs, {len(timings)} runs of it: {spread(walls, digits=2)} s wall (median "
          f"(min-max)), {spread([timing[1] for timing in timings], digits=2)} s CPU on {os.cpu_count()} cores; "
          f"interpreter start and import analysis.report {start_up:.2f} s, then (the median run, {wall:.2f} s) "
          f"{stages}; budget {BUDGET_SECONDS:g} s wall for the median")
    return 0 if median_wall < BUDGET_SECONDS else 1


if __name__ == "__main__":
    sys.exit(main())
