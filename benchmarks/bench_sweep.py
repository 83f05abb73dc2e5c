"""Wall-clock of one small sweep with one job at a time vs one job per core (2 here).

Runs ``hersd-sweep +grid=smoke`` (4 FetchReach runs) with FetchReach's paper settings per
epoch (10 cycles, 20 test episodes) and ``--epochs`` epochs (default 8: ~45 s per run) twice
into fresh temporary folders, one torch thread per run, first with ``hydra.launcher.n_jobs=1``
then with ``n_jobs=2``, and prints the two times and their ratio. Also printed: the start-up costs that do not
shrink with more jobs (the sweep command composing and checking its runs; each worker
process importing torch and MuJoCo), which short runs cannot amortise; and the dry run of the
300-run beta grid (``+grid=beta --dry-run``: every run composed and checked, nothing trained)
in wall-clock and CPU seconds (the CPU time is what an idle core would take). Run it on an
otherwise idle machine.

Usage: python benchmarks/bench_sweep.py [--epochs 8] [--plan-only]
(``--plan-only``: the beta grid's dry run alone, without the two sweeps.)
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time


SWEEP = ["-c", "from sweeps.launch import main; main()", "+grid=smoke"]
PLAN_BETA = ["-c", "from sweeps.launch import main; main()", "+grid=beta", "--dry-run"]


def python_seconds(args: list[str]) -> float:
    """Wall-clock seconds of ``python <args>`` in a fresh interpreter."""
    return python_wall_and_cpu(args)[0]


def python_wall_and_cpu(args: list[str]) -> tuple[float, float]:
    """(wall-clock, CPU) seconds of ``python <args>`` in a fresh interpreter (CPU: its user + system time)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    tic = time.perf_counter()
    subprocess.run([sys.executable, *args], check=True, capture_output=True)
    wall = time.perf_counter() - tic
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def sweep_seconds(n_jobs: int, epochs: int) -> float:
    with tempfile.TemporaryDirectory() as results:
        return python_seconds([*SWEEP, f"epochs={epochs}", "task.cycles_per_epoch=10", "ddpg.test_rollouts=10",
                               f"hydra.launcher.n_jobs={n_jobs}", "threads=1", f"results_dir={results}"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=8)
    parser.add_argument("--plan-only", action="store_true", help="only the beta grid's dry run")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as results:
        wall, cpu = python_wall_and_cpu([*PLAN_BETA, f"results_dir={results}"])
    print(f"planning the 300-run beta grid (--dry-run): {wall:.1f} s wall-clock, {cpu:.1f} s CPU")
    if args.plan_only:
        return
    one = sweep_seconds(1, args.epochs)
    two = sweep_seconds(2, args.epochs)
    with tempfile.TemporaryDirectory() as results:
        sweep_start = python_seconds([*SWEEP, "--dry-run", f"results_dir={results}"])
    worker_start = python_seconds(["-c", "import hersd.engine.train"])
    print(f"start-up: sweep command {sweep_start:.1f} s, each worker's imports {worker_start:.1f} s")
    print(f"4-run sweep, 1 job at a time: {one:6.1f} s")
    print(f"4-run sweep, 2 jobs at a time: {two:6.1f} s  -> speed-up {one / two:.2f}x")


if __name__ == "__main__":
    main()
