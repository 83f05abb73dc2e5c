"""Spreading the report's independent jobs (reading logs, drawing figures) over the cores.

:class:`ForkedMap` runs ``function(item)`` for every item in forked worker processes, one per
core: a forked child starts with the parent's memory (the loaded tables, the imported
modules), so the jobs themselves are never pickled, only their results. With one core, one
job, or no ``fork`` on the platform, the jobs run in this process instead, with the same results.
While the children run, the parent's objects are frozen out of garbage collection (:func:`gc.freeze`): the
children's collections then skip the parent's many objects (the imported modules' and the tables').
A worker that dies before its jobs are done (killed, out of memory) is :class:`WorkerLostError`, not a wait forever
(:class:`concurrent.futures.ProcessPoolExecutor` breaks at once; a ``multiprocessing.Pool`` replaces the worker and waits).
A worker ignores Ctrl-C: the command says the interrupt, and its pool lets the running jobs finish (seconds), as a
worker stopped while it sends its result back would leave the pool reading that result forever. A worker ends within
a second of the process that forked it, however that ends (``kill -9`` included: none is left waiting on a pipe).
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Sequence

from hersd.contract.cores import available_cores

_JOBS: tuple[Callable[[Any], Any], Sequence[Any]] | None = None  # what the forked children inherit
PARENT_POLL_SECONDS = 0.5  # how often a worker looks whether the process that forked it is still there


class WorkerLostError(RuntimeError):
    """A worker process stopped before its jobs were done (killed, out of memory, or its job exited the process)."""


def _start_worker() -> None:
    """In each forked worker, first: Ctrl-C ignored; SIGTERM the default again (not the command's handler,
    inherited through the fork); a thread that ends it once its parent is gone (it is then re-parented)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threading.Thread(target=_end_with_parent, args=(os.getppid(),), daemon=True, name="end-with-parent").start()


def _end_with_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_SECONDS)
    os._exit(1)


def _run_job(index: int) -> Any:
    function, items = _JOBS
    return function(items[index])


class ForkedMap:
    """``[function(item) for item in items]``, computed in up to ``workers`` forked processes
    (default: one per core), started at once; :meth:`results` waits for them, in item order."""

    def __init__(self, function: Callable[[Any], Any], items: Sequence[Any], workers: int | None = None) -> None:
        global _JOBS
        self._function, self._items = function, items
        workers = min(workers or available_cores(), len(items))
        self._pool: ProcessPoolExecutor | None = None
        self._pending: list[Future] = []
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            _JOBS = (function, items)
            gc.freeze()  # unfrozen in close()
            # A worker that dies breaks the whole pool at once (BrokenProcessPool): no job is waited for forever.
            self._pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                             initializer=_start_worker)
            self._pending = [self._pool.submit(_run_job, index) for index in range(len(items))]  # forks at the first

    def results(self) -> list[Any]:
        if self._pool is None:
            return [self._function(item) for item in self._items]
        try:
            return [job.result() for job in self._pending]
        except BrokenProcessPool:
            raise WorkerLostError("a worker process stopped before finishing its jobs (killed, or out of "
                                  "memory?)") from None
        finally:
            self.close()

    def close(self) -> None:
        """Cancel the jobs not started, wait for those running (seconds: a log read, a figure drawn; a Ctrl-C too)
        and unfreeze the parent's objects (after :meth:`results`, or after an error in the parent while they
        worked); with a ``with`` block, on its way out. The workers are never signalled."""
        global _JOBS
        if self._pool is None:
            return
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
        gc.unfreeze()
        _JOBS = None

    def __enter__(self) -> ForkedMap:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
