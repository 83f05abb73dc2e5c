"""Denormal floats flushed to zero in a run's torch work (``flush_denormal``, on by default).

The reference implementation runs on TensorFlow, whose executor wraps every CPU kernel in
``port::ScopedFlushDenormal``: its kernels treat denormals (|x| < 1.2e-38 in float32) as zero, and
x86 CPUs compute on denormals many times slower. ``torch.set_flush_denormal`` sets the x86 FTZ/DAZ
bits of the calling thread only, so a run sets them in two places:

- once on every intra-op worker thread of torch's OpenMP runtime (:func:`set_intra_op_threads`,
  at the start of a run): those threads run torch kernels only;
- on the run's own thread around each piece of torch work (:func:`denormals_flushed`): updates,
  acting in rollouts and test episodes, the bias evaluation and the policy animations. The same
  thread steps the physics between actions, and MuJoCo runs in IEEE arithmetic, as it did beside
  the reference, where TensorFlow's flag covers its own kernels only.

:func:`thread_flush_states` checks the flag on each intra-op thread rather than assuming it.
"""

from __future__ import annotations

import ctypes
import threading
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Iterator

import torch

_REGION = ctypes.CFUNCTYPE(None, ctypes.c_void_p)  # the body of an OpenMP parallel region: void (*)(void *)
_DENORMAL = 1e-40  # below float32's smallest normal, 1.18e-38


@lru_cache(maxsize=1)
def _openmp_runtime() -> ctypes.CDLL | None:
    """The OpenMP runtime torch's intra-op threads belong to (the libgomp inside torch's Linux wheels; LLVM's
    and Intel's runtimes export the same entry point), or None when torch uses none. Other packages may load
    runtimes of their own (scikit-learn does), with threads of their own: torch's own folder comes first."""
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "omp" in line.rsplit("/", 1)[-1]}
    except OSError:
        return None
    torch_folder = str(Path(torch.__file__).resolve().parent)
    for path in sorted(paths, key=lambda path: not path.startswith(torch_folder)):
        library = ctypes.CDLL(path)
        if hasattr(library, "GOMP_parallel"):
            library.GOMP_parallel.argtypes = [_REGION, ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint]
            return library
    return None


def _on_each_intra_op_thread(body) -> None:
    """Run ``body()`` once on every thread of a parallel region as wide as torch's intra-op pool (the
    calling thread is one of them): OpenMP reuses the same worker threads for every region it starts."""
    runtime = _openmp_runtime()
    if runtime is None:
        body()
        return
    region = _REGION(lambda _data: body())
    runtime.GOMP_parallel(region, None, torch.get_num_threads(), 0)


def set_intra_op_threads(flush: bool) -> None:
    """Set (``flush``) or clear FTZ/DAZ on every intra-op worker thread; the calling thread's flag is
    left as it was (:func:`denormals_flushed` sets it around the torch work)."""
    caller = threading.get_ident()

    def body() -> None:
        if threading.get_ident() != caller:
            torch.set_flush_denormal(flush)

    _on_each_intra_op_thread(body)


def thread_flush_states() -> list[bool]:
    """Whether each thread of the intra-op pool (the calling thread first) turns a denormal to zero,
    measured by a multiplication on that thread."""
    caller, states = threading.get_ident(), {}

    def body() -> None:
        states[threading.get_ident()] = bool((torch.tensor([_DENORMAL]) * 1.0).item() == 0.0)

    _on_each_intra_op_thread(body)
    return [states.pop(caller), *states.values()]


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
