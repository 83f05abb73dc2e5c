"""Spreading the report's independent jobs (reading logs, drawing figures) over the cores.

:class:`ForkedMap` runs ``function(item)`` for every item in forked worker processes, one per
core: a forked child starts with the parent's memory (the loaded tables, the imported
modules), so the jobs themselves are never pickled, only their results. With one core, one
job, or no ``fork`` on the platform, the jobs run in this process instead, with the same results.
While the children run, the parent's objects are frozen out of garbage collection (:func:`gc.freeze`): the
children's collections then skip the parent's many objects (the imported modules' and the tables').
A worker that dies before its jobs are done (killed, out of memory) is :class:`WorkerLostError`, not a wait forever.
"""

from __future__ import annotations

import gc
import multiprocessing
from typing import Any, Callable, Sequence

from hersd.contract.cores import available_cores

_JOBS: tuple[Callable[[Any], Any], Sequence[Any]] | None = None  # what the forked children inherit
POLL_SECONDS = 0.2  # how often the parent, waiting, checks that no worker died


class WorkerLostError(RuntimeError):
    """A worker process stopped before its jobs were done (killed, or its job exited the process): its job is lost,
    which the pool itself would wait for forever."""


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
        self._pool = None
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            _JOBS = (function, items)
            gc.freeze()  # unfrozen in results()
            self._pool = multiprocessing.get_context("fork").Pool(workers)  # the children fork here
            self._workers = list(self._pool._pool)  # the pool replaces a worker that dies, losing its job
            self._pending = self._pool.map_async(_run_job, range(len(items)), chunksize=1)

    def results(self) -> list[Any]:
        if self._pool is None:
            return [self._function(item) for item in self._items]
        try:
            while not self._pending.ready():
                self._pending.wait(POLL_SECONDS)
                lost = [worker.exitcode for worker in self._workers if worker.exitcode is not None]
                if lost and not self._pending.ready():
                    status = (f"killed by signal {-lost[0]}: out of memory?" if lost[0] < 0
                              else f"exit status {lost[0]}")
                    raise WorkerLostError(f"a worker process stopped before finishing its jobs ({status})")
            results = self._pending.get()
            self._pool.close()  # every job is done: let the workers exit
            return results
        finally:
            self.close()

    def close(self) -> None:
        """Stop the workers still running and unfreeze the parent's objects (after :meth:`results`, or after an
        error in the parent while they worked); with a ``with`` block, on its way out."""
        global _JOBS
        if self._pool is None:
            return
        self._pool.terminate()  # after pool.close(), only reaps; otherwise stops the jobs left
        self._pool.join()
        self._pool = None
        gc.unfreeze()
        _JOBS = None

    def __enter__(self) -> ForkedMap:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
