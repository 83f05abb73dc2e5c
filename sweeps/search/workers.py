"""The workers that run Optuna's loop on the shared study: in this process (one worker),
as spawned local processes (several), or as SLURM jobs through submitit.

A worker's runs use ``threads=N`` if the user gave it, else the cores shared by the workers
that run at once on them: ``len(shares)`` local workers on this machine, one per SLURM job
(whose allocation is the worker's).
"""

from __future__ import annotations

import logging
import multiprocessing
import signal
import os
import sys
from contextlib import nullcontext
from dataclasses import asdict
from functools import partial
from multiprocessing import resource_tracker
from pathlib import Path
from typing import Any

import optuna

from hersd.contract.compose import CONFIG_MODULE
from hersd.contract.errors import ConfigError, sigterm_as_ctrl_c
from sweeps.launchers import check_slurm as check_slurm_answers, end_with, main_process
from sweeps.search.storage import open_storage
from sweeps.search.config import SlurmConfig
from sweeps.search.objective import objective
from sweeps.search.plan import SearchPlan, run_threads
from sweeps.search.study import make_pruner, make_sampler, room_for_trial

SLURM_PRESET = ("hydra", "launcher", "slurm.yaml")  # hersd-sweep's SLURM settings, in the hersd.conf package
STOPS = {signal.SIGINT, signal.SIGTERM}  # Ctrl-C and ``kill PID``: blocked while a local worker starts
SLURM_FALLBACK = {"partition": None, "timeout_min": 240, "cpus_per_task": 1, "mem_gb": 8}


class QuietInterrupt(logging.Filter):
    """Optuna's log of a trial a Ctrl-C ended (the KeyboardInterrupt's traceback, then "failed with value
    None"), and anything it logs after, dropped: the command says the interrupt in one line."""

    def __init__(self) -> None:
        super().__init__()
        self.interrupted = False

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and isinstance(record.exc_info[1], KeyboardInterrupt):
            self.interrupted = True
        return not self.interrupted


class OneLineFailures(logging.Filter):
    """Optuna's lines on a failed trial made one: the error without its traceback, the "failed with value None"
    line dropped (the trial's user attribute ``error`` keeps the error; the command names the first); nothing of a
    trial the training layer refused (its objective NaN, ``refusals`` not empty: the command's line says why)."""

    def __init__(self, refusals: list[str]) -> None:
        super().__init__()
        self.refusals = refusals

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        refused = bool(self.refusals) and " failed " in message
        if message.startswith("Trial ") and (" failed with value " in message or refused):
            return False
        if record.exc_info and not isinstance(record.exc_info[1], KeyboardInterrupt):
            record.msg, record.args = " ".join(message.split()), None
            record.exc_info, record.exc_text = None, None
        return True


def interrupted(err: BaseException | None) -> bool:
    """Whether ``err`` is a Ctrl-C or was raised while one was handled: Optuna's bookkeeping cut by the
    KeyboardInterrupt between trials ends in another error (the trial stays RUNNING: re-run as lost)."""
    while err is not None:
        if isinstance(err, KeyboardInterrupt):
            return True
        err = err.__context__
    return False


def run_worker(plan: SearchPlan, n_trials: int, concurrent_runs: int, search_process: str | None = None) -> None:
    """One worker: Optuna's loop on the shared study for at most ``n_trials`` trials, sharing the cores. A local
    worker process (``search_process`` given: the search's main process, :func:`sweeps.launchers.main_process`) ends
    within a second of that process, however it ends (:func:`sweeps.launchers.end_with`: its trial, left RUNNING, is
    lost and re-run by the next command); it starts with SIGINT and SIGTERM blocked (:func:`run_local`) and takes
    them here, where a Ctrl-C or ``kill`` ends it with exit code 130 and no traceback."""
    local = search_process is not None
    if local:
        end_with(search_process, "hersd-search", "its trial is re-run when the same command runs again")
    refusals: list[str] = []
    filters, handlers = (QuietInterrupt(), OneLineFailures(refusals)), logging.getLogger("optuna").handlers
    for handler in handlers:
        for log_filter in filters:
            handler.addFilter(log_filter)
    try:
        with sigterm_as_ctrl_c() if local else nullcontext():
            if local:  # a Ctrl-C or kill while it started arrives now
                signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)
            _optimize(plan, n_trials, concurrent_runs, refusals)
    except BaseException as err:
        if not interrupted(err):
            raise
        if not local:  # in the search's own process (or a SLURM job): let it report it
            raise KeyboardInterrupt from None
        sys.exit(130)  # a worker process: the trial is recorded as interrupted (or re-run as lost); no traceback
    finally:
        for handler in handlers:
            for log_filter in filters:
                handler.removeFilter(log_filter)
    if refusals and not local:
        raise ConfigError(refusals[0])
    if refusals:
        print(f"hersd-search: error: {refusals[0]}", file=sys.stderr, flush=True)
        sys.exit(2)


def _optimize(plan: SearchPlan, n_trials: int, concurrent_runs: int, refusals: list[str]) -> None:
    """Optuna's loop on the shared study: at most ``n_trials`` trials, fewer once the study has search.n_trials
    (counting the trials other workers run) or a run was refused (``refusals``)."""
    study = optuna.load_study(study_name=plan.study_name, storage=open_storage(plan.storage),
                              sampler=make_sampler(plan.search.sampler), pruner=make_pruner(plan))
    run_trial = partial(objective, plan=plan, threads=run_threads(plan.base, concurrent_runs), refusals=refusals)
    for _ in range(n_trials):
        if refusals or not room_for_trial(study, plan.search.n_trials, plan.search.stale_after_minutes * 60):
            break
        study.optimize(run_trial, n_trials=1, catch=(Exception,))


def split_trials(n_trials: int, n_workers: int) -> list[int]:
    """``n_trials`` shared as evenly as possible among at most ``n_workers`` workers -> trials per worker."""
    n_workers = max(1, min(n_workers, n_trials))
    return [n_trials // n_workers + (i < n_trials % n_workers) for i in range(n_workers)]


def run_local(plan: SearchPlan, shares: list[int]) -> list[int]:
    """Run the workers here: in this process if one, else as spawned processes -> their exit codes."""
    if len(shares) == 1:
        run_worker(plan, shares[0], concurrent_runs=1)
        return [0]
    context = multiprocessing.get_context("spawn")  # no fork: torch, MuJoCo and open DB connections
    workers = [context.Process(target=run_worker, name=f"hersd-search-{i}",
                               args=(plan, share, len(shares), main_process()))
               for i, share in enumerate(shares)]
    # SIGINT and SIGTERM blocked while they start: a worker is never half started, and each inherits the block
    # (across exec) until run_worker takes the signals, so a Ctrl-C in its start-up is no traceback; a blocked one
    # waits. The start of multiprocessing's resource tracker unblocks SIGINT: it is started first.
    resource_tracker.ensure_running()
    signal.pthread_sigmask(signal.SIG_BLOCK, STOPS)
    previous = signal.signal(signal.SIGTERM, partial(_stop_workers, workers))
    try:
        for worker in workers:
            worker.start()
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)  # a Ctrl-C or kill during the starts arrives here
        for worker in workers:
            worker.join()
    except KeyboardInterrupt:  # the workers got the same SIGINT (a terminal's Ctrl-C) or SIGTERM: they record it
        for worker in workers:
            worker.join()
        raise
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)
        signal.signal(signal.SIGTERM, previous)
    return [worker.exitcode for worker in workers]


def _stop_workers(workers: list[multiprocessing.process.BaseProcess], signum: int, frame: object) -> None:
    """``kill PID`` of the search (SIGTERM, which reaches no worker, unlike a terminal's Ctrl-C): passed on to each
    running worker, once, then a Ctrl-C here. Each records its trial as interrupted, as for a Ctrl-C."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    for worker in workers:
        if worker.is_alive():
            os.kill(worker.pid, signal.SIGTERM)
    raise KeyboardInterrupt


def slurm_settings(slurm: SlurmConfig) -> dict[str, Any]:
    """{partition, timeout_min, cpus_per_task, mem_gb} per worker job: search.slurm over hersd-sweep's preset."""
    # The preset is read from the installed hersd.conf package (works from a wheel); without it, SLURM_FALLBACK.
    from importlib.resources import files

    from omegaconf import OmegaConf

    settings = dict(SLURM_FALLBACK)
    preset = files(CONFIG_MODULE).joinpath(*SLURM_PRESET)
    if preset.is_file():
        loaded = OmegaConf.to_container(OmegaConf.create(preset.read_text()))
        settings.update({key: loaded[key] for key in SLURM_FALLBACK if key in loaded})
    settings.update({key: value for key, value in asdict(slurm).items() if value is not None})
    return settings


def check_slurm(slurm: SlurmConfig) -> None:
    """ConfigError unless SLURM answers here (``sinfo``) and has the partition(s) asked for, as hersd-sweep
    checks its own (:func:`sweeps.launchers.check_slurm`)."""
    check_slurm_answers(slurm_settings(slurm)["partition"], "search.launcher=slurm", "search.slurm.partition")


def submit_slurm(plan: SearchPlan, shares: list[int]) -> list[str]:
    """Submit one SLURM job per worker (a submitit job array) -> job ids; ConfigError if SLURM refuses."""
    import submitit

    settings = slurm_settings(plan.search.slurm)
    try:
        executor = submitit.AutoExecutor(folder=Path(plan.study_dir) / "slurm" / "%j", cluster="slurm")
        executor.update_parameters(name=f"hersd-search-{plan.study_name}", timeout_min=settings["timeout_min"],
                                   cpus_per_task=settings["cpus_per_task"], mem_gb=settings["mem_gb"],
                                   **({"slurm_partition": settings["partition"]} if settings["partition"] else {}))
        n = len(shares)
        jobs = executor.map_array(run_worker, [plan] * n, shares, [1] * n)
    except Exception as err:  # noqa: BLE001 - no SLURM here, or sbatch refused the jobs
        raise ConfigError(f"search.launcher=slurm: {' '.join(str(err).split())[:300]}") from None
    return [job.job_id for job in jobs]
