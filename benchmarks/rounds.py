"""Interleaved rounds for the benchmarks that compare paths: each round runs every path once, in one order
(A B C, A B C, ...), so a load that comes and goes, a clock that drifts or a cache that warms weighs on each
path alike; what they print is each path's min / median / max over the rounds and each ratio's median of
per-round ratios, under a line naming the CPU (model name, family, model: two VMs sold under one name can be
different CPUs, and a speed figure belongs to one of them).

Used by ``bench_cycle.py``, ``bench_precision.py``, ``bench_update.py`` and ``bench_sampler.py`` (run as scripts: this folder is on
their import path).
"""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Callable, Optional

from hersd.engine.resources import cpu_has_bf16


def cpu_line() -> str:
    """``CPU: <model name> (family F, model M, stepping S), N cores, bf16 instructions: yes|no`` from
    /proc/cpuinfo (``unknown`` for what it does not list)."""
    fields: dict[str, str] = {}
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    for line in lines:
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    cores = sum(line.startswith("processor") for line in lines)
    return (f"CPU: {fields.get('model name', 'unknown')} (family {fields.get('cpu family', 'unknown')}, model "
            f"{fields.get('model', 'unknown')}, stepping {fields.get('stepping', 'unknown')}), {cores} cores, "
            f"bf16 instructions: {'yes' if cpu_has_bf16() else 'no'}")


def interleaved(paths: dict[str, Callable[[], dict[str, float]]], rounds: int,
                warmup: int = 1) -> dict[str, dict[str, list[float]]]:
    """Run each path once per round, in the dict's order, ``warmup`` rounds first (not kept) and then
    ``rounds``. A path returns its measures of that round (name -> seconds, e.g. per cycle and per update).
    Returns path -> measure -> one value per kept round."""
    kept: dict[str, dict[str, list[float]]] = {name: {} for name in paths}
    for round_ in range(warmup + rounds):
        for name, run in paths.items():
            measures = run()
            if round_ >= warmup:
                for measure, value in measures.items():
                    kept[name].setdefault(measure, []).append(value)
    return kept


def spread(values: list[float], scale: float = 1.0, digits: int = 3) -> str:
    """``median (min-max)`` of values times ``scale``."""
    low, mid, high = (scale * value for value in (min(values), statistics.median(values), max(values)))
    return f"{mid:.{digits}f} ({low:.{digits}f}-{high:.{digits}f})"


def ratio(numerators: list[float], denominators: list[float]) -> list[float]:
    """The per-round ratios numerator / denominator of two paths measured in the same rounds."""
    return [a / b for a, b in zip(numerators, denominators)]


def ratio_spread(values: list[float]) -> str:
    """``N.NNx (min-max N.NN-N.NN)`` of per-round ratios: their median first."""
    return f"{statistics.median(values):.2f}x (min-max {min(values):.2f}-{max(values):.2f})"


def faster_line(label: str, path: list[float], reference: list[float], reference_name: str,
                per: Optional[str] = None) -> str:
    """``<label>: N.NNx faster than <reference_name>[ per <per>] (min-max ...)``, the median of the per-round
    ratios reference / path (``slower`` when below 1), for scripts to read."""
    ratios = ratio(reference, path)
    median = statistics.median(ratios)
    word, shown = ("faster", ratios) if median >= 1 else ("slower", [1 / value for value in ratios])
    suffix = f" per {per}" if per else ""
    return (f"{label}: {statistics.median(shown):.2f}x {word} than {reference_name}{suffix} "
            f"(median of {len(ratios)} rounds, min-max {min(shown):.2f}-{max(shown):.2f})")
