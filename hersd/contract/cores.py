"""How many threads a run gets: the rule of ``threads=auto``, shared by the run engine, the sweeps and
searches that share the cores among their runs in flight, and the report's worker processes.

``threads=auto`` gives a run the cores it may use (its CPU affinity, capped by
``SLURM_CPUS_PER_TASK`` inside a SLURM job) divided by the runs sharing them, and never more
than the cores left idle by other processes when the run starts: intra-op threads that wait on
a core another process holds cost more than they give (a FetchReach epoch beside one busy
neighbour on 2 cores took 2.1x as long with 2 threads as with 1; ``benchmarks/bench_threads.py``).
A neighbour that starts later is not seen; give ``threads=N`` to fix the count.
"""

from __future__ import annotations

import os
import time
from pathlib import Path


IDLE_SAMPLE_SECONDS = 0.3  # how long threads=auto watches the cores for other processes' work


def _affinity() -> list[int]:
    """The CPU numbers this process may run on."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # no affinity API (macOS)
        return list(range(os.cpu_count() or 1))


def available_cores() -> int:
    """CPU cores this process may run on: its affinity mask, capped inside a SLURM job by
    ``SLURM_CPUS_PER_TASK`` (clusters without CPU binding leave the mask at the whole node)."""
    cores = len(_affinity())
    per_task = os.environ.get("SLURM_CPUS_PER_TASK", "")
    return max(1, min(cores, int(per_task)) if per_task.isdigit() and int(per_task) > 0 else cores)


def _cpu_times(cpus: list[int]) -> dict[int, tuple[int, int]] | None:
    """cpu -> (idle + iowait, total) jiffies from /proc/stat; None where /proc/stat is missing."""
    stat = Path("/proc/stat")
    if not stat.exists():
        return None
    times = {}
    for line in stat.read_text().splitlines():
        name, *values = line.split()
        if name.startswith("cpu") and name[3:].isdigit() and int(name[3:]) in cpus:
            counts = [int(v) for v in values[:8]]
            times[int(name[3:])] = (counts[3] + counts[4], sum(counts))
    return times


def idle_cores(seconds: float = IDLE_SAMPLE_SECONDS) -> float:
    """How many of this process's cores other processes left idle over the next ``seconds``
    (0 .. available_cores(); available_cores() where the kernel does not tell)."""
    cpus = _affinity()
    before = _cpu_times(cpus)
    if not before:
        return float(available_cores())
    time.sleep(seconds)
    after = _cpu_times(cpus) or {}
    idle = sum((after[c][0] - before[c][0]) / max(after[c][1] - before[c][1], 1) for c in before if c in after)
    return min(idle, float(available_cores()))


def resolve_threads(threads: str, concurrent_runs: int = 1) -> int:
    """``auto`` -> the cores shared by ``concurrent_runs`` runs, no more than the idle ones (>= 1);
    a number -> itself."""
    if threads == "auto":
        share = available_cores() // max(1, concurrent_runs)
        return max(1, min(share, int(idle_cores() + 0.5)))
    return int(threads)
