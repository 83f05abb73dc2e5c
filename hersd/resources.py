"""How a run uses the machine: intra-op threads and the torch device.

``threads=auto`` gives a run this machine's cores divided by the runs sharing it: a lone
``hersd-train`` uses every core; a sweep or search with several runs at once passes
``concurrent_runs`` so each gets its share (at least one thread). ``device=auto`` is CUDA
when torch sees a GPU, else the CPU.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import Any


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask, e.g. a SLURM allocation)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity API (macOS)
        return os.cpu_count() or 1


def resolve_threads(threads: str, concurrent_runs: int = 1) -> int:
    """``auto`` -> max(1, cores // concurrent_runs); a number -> itself."""
    if threads == "auto":
        return max(1, available_cores() // max(1, concurrent_runs))
    return int(threads)


def available_memory_bytes() -> int | None:
    """Memory this machine can still give (Linux ``MemAvailable``); None where unknown."""
    meminfo = Path("/proc/meminfo")
    if not meminfo.exists():
        return None
    for line in meminfo.read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) * 1024
    return None


def resolve_device(device: str) -> Any:
    """``auto`` -> cuda if available else cpu; ``cuda[:N]`` must be available (else ConfigError)."""
    import torch

    from hersd.config import ConfigError

    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device={device}: torch sees no CUDA device here; use device=cpu or device=auto")
    if device.startswith("cuda:") and int(device[5:]) >= torch.cuda.device_count():
        raise ConfigError(f"device={device}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    return torch.device(device)


def machine_info() -> dict[str, Any]:
    """The CPU (model, cores) and the instruction set torch's kernels use: bitwise results hold
    on one machine, not across CPU types, so two logs that differ can be told apart by this."""
    import torch

    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        names = [line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
                 if line.startswith("model name")]
        model = names[0] if names else model
    return {"cpu_model": model, "cpu_cores": available_cores(), "machine": platform.machine(),
            "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
            "cuda_device": torch.cuda.get_device_name() if torch.cuda.is_available() else None}
