"""What a run reads of the machine besides its thread count (:mod:`hersd.contract.cores`): the torch device
(``device=auto`` is CUDA when torch sees a GPU, else the CPU), whether it can run the precision asked for, the
memory it may still take, and the machine description every log records. torch is imported only by the functions
that need it.
"""

from __future__ import annotations

import platform
from pathlib import Path
from typing import Any

from hersd.contract.cores import available_cores, idle_cores, resolve_threads  # noqa: F401 (hersd.resources named them)
from hersd.contract.errors import ConfigError


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

    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device={device}: torch sees no CUDA device here; use device=cpu or device=auto")
    if device.startswith("cuda:") and int(device[5:]) >= torch.cuda.device_count():
        raise ConfigError(f"device={device}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    return torch.device(device)


BF16_CPU_FLAGS = ("avx512_bf16", "amx_bf16", "bf16")  # /proc/cpuinfo flags of bf16 instructions (x86; Arm's bf16)


def cpu_has_bf16() -> bool:
    """Whether this CPU lists bf16 instructions in /proc/cpuinfo (False where there is none)."""
    cpuinfo = Path("/proc/cpuinfo")
    if not cpuinfo.exists():
        return False
    flags = {flag for line in cpuinfo.read_text().splitlines()
             if line.startswith(("flags", "Features")) for flag in line.split(":", 1)[1].split()}
    return any(flag in flags for flag in BF16_CPU_FLAGS)


def check_precision(precision: str, device_type: str) -> None:
    """ConfigError for precision=bf16 on a CPU (``device_type`` "cpu") without bf16 instructions: emulated, it is
    slower than fp32, and running fp32 instead would file fp32 results under a bf16 run's identity."""
    if precision == "bf16" and device_type == "cpu" and not cpu_has_bf16():
        raise ConfigError("precision=bf16: this CPU has no bf16 instructions (avx512_bf16, amx_bf16); "
                          "use precision=fp32")


def check_machine(device: str, precision: str) -> None:
    """ConfigError if this machine cannot train a run of ``device`` and ``precision`` (:func:`resolve_device`, then
    :func:`check_precision`): what ``hersd-train``, and a sweep or search training here, check before it starts.
    Loads torch only where the answer needs it: a ``cuda`` device, or ``auto`` with bf16."""
    if device in ("cpu", "auto") and precision == "fp32":  # auto falls back to the CPU, which runs fp32
        return
    check_precision(precision, "cpu" if device == "cpu" else resolve_device(device).type)


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
