"""threads=auto beside a busy neighbour: never slower than threads=1.

One process spins on one core (a neighbour: another run, a build, a second terminal); then a
1-epoch FetchReach ``hersd-train`` runs with threads=1, threads=auto and threads=<all cores>
(what auto gave before it looked at idle cores), interleaved, ``--repeats`` times each. Prints
each epoch's seconds (from the run log) and the ratios to threads=1; the goal is auto / 1 <= 1.05.
Run it on an otherwise quiet machine (pause long runs with kill -STOP).

    python benchmarks/bench_threads.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from hersd.contract.cores import available_cores
from hersd.contract.runlog import read_run

SPIN = "import os; os.sched_setaffinity(0, {{{cpu}}})\nwhile True: pass"


def epoch_seconds(threads: str, results: Path) -> tuple[float, int]:
    """One fresh 1-epoch FetchReach run -> (its epoch's seconds, the threads it logged)."""
    folder = Path(tempfile.mkdtemp(dir=results))
    subprocess.run(["hersd-train", "task=reach", "epochs=1", "quiet=true", f"threads={threads}",
                    f"results_dir={folder}"], check=True, stdout=subprocess.DEVNULL)
    log = read_run(next(folder.rglob("run.mcap")))
    return float(log.epochs["epoch_seconds"].iloc[0]), int(log.meta["threads"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cores = available_cores()
    if cores < 2:
        sys.exit("bench_threads: needs 2 cores or more (one for the neighbour)")
    settings = ["1", "auto", str(cores)]
    seconds: dict[str, list[float]] = {s: [] for s in settings}
    logged: dict[str, int] = {}
    neighbour = subprocess.Popen([sys.executable, "-c", SPIN.format(cpu=sorted(os.sched_getaffinity(0))[0])])
    try:
        with tempfile.TemporaryDirectory() as results:
            for _ in range(args.repeats):
                for setting in settings:
                    value, logged[setting] = epoch_seconds(setting, Path(results))
                    seconds[setting].append(value)
    finally:
        neighbour.kill()
    base = statistics.median(seconds["1"])
    print(f"{cores} cores, one busy neighbour; 1-epoch FetchReach, median of {args.repeats}:")
    for setting in settings:
        median = statistics.median(seconds[setting])
        runs = " ".join(f"{value:.2f}" for value in seconds[setting])
        print(f"  threads={setting:<5} (ran {logged[setting]} threads): {median:6.2f} s  {median / base:5.2f}x threads=1"
              f"  (runs: {runs})")
    ratio = statistics.median(seconds["auto"]) / base
    print(f"auto / 1 = {ratio:.2f} (goal <= 1.05): {'met' if ratio <= 1.05 else 'NOT met'}")


if __name__ == "__main__":
    main()
