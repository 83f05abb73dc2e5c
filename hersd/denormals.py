"""Denormal floats flushed to zero in the run's torch work (``flush_denormal``)."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import torch


@contextmanager
def denormals_flushed(enabled: bool) -> Iterator[None]:
    """Inside the block, with ``enabled``, this thread's float arithmetic treats denormals as zero
    (x86 FTZ/DAZ through torch.set_flush_denormal); outside it, IEEE denormals as everywhere else."""
    if not enabled:
        yield
        return
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)
