"""Wall-clock of one small sweep with one job at a time vs one job per core (2 here).

Runs ``hersd-sweep +grid=smoke`` (4 FetchReach runs, lengthened to ~20 s each) twice into
fresh temporary folders, first with ``hydra.launcher.n_jobs=1`` then with ``n_jobs=2``,
and prints the two times and their ratio. Run it on an otherwise idle machine.

Usage: python benchmarks/bench_sweep.py [--epochs 4]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time


def sweep_seconds(n_jobs: int, epochs: int) -> float:
    with tempfile.TemporaryDirectory() as results:
        tic = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from sweeps.launch import main; main()", "+grid=smoke",
                        f"epochs={epochs}", "task.cycles_per_epoch=5", "ddpg.batches_per_cycle=40",
                        f"hydra.launcher.n_jobs={n_jobs}", f"results_dir={results}"],
                       check=True, capture_output=True)
        return time.perf_counter() - tic


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=4)
    args = parser.parse_args()
    one = sweep_seconds(1, args.epochs)
    two = sweep_seconds(2, args.epochs)
    print(f"4-run sweep, 1 job at a time: {one:6.1f} s")
    print(f"4-run sweep, 2 jobs at a time: {two:6.1f} s  -> speed-up {one / two:.2f}x")


if __name__ == "__main__":
    main()
