"""Launchers checked before anything is launched, by both commands that launch runs: ``hersd-sweep``'s Hydra
launcher (:func:`check_launcher`, from :mod:`sweeps.launch`) and ``hersd-search``'s SLURM workers
(:func:`check_slurm`, from :mod:`sweeps.search.workers`). SLURM is asked (``sinfo``) the same way for both, and a
bad setting is one line naming it: exit 2, before any run or job.

The lifetime of local workers, ``hersd-sweep``'s and ``hersd-search``'s alike: a command whose workers train on this
machine names its main process to them (:func:`main_process`; a sweep through :func:`watched_by_jobs`, a search as
its workers' argument), and each worker ends within a second of that process, however it ends (``kill -9``
included: no signal reaches a worker then, and joblib's loky workers would otherwise train on and idle for minutes,
holding their runs' locks, so a re-run would find them "running elsewhere"). Each worker polls it (:func:`end_with`;
a sweep's jobs through :func:`end_with_sweep`) rather than asking the kernel for a signal at its parent's death
(``PR_SET_PDEATHSIG``): that signal follows the parent *thread* that started the worker, is Linux-only, and
submitit's local jobs are grandchildren. Once the workers are gone, the resource trackers they share with the main
process see their pipes close and end too. SLURM jobs (their own allocation, another machine) are never watched.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping

from omegaconf import DictConfig

from hersd.contract.cores import available_cores
from hersd.contract.errors import ConfigError
from hersd.contract.runstore import pid_alive
from sweeps.hydra_private import cap_local_workers
from sweeps.plan import SweepError

SLURM_RESOURCES = {"timeout_min": "minutes", "cpus_per_task": "CPUs", "mem_gb": "GB of memory"}  # per job


def check_slurm(partition: str | None, chosen_by: str, key: str) -> None:
    """ConfigError unless SLURM answers here (``sinfo``) and has the partition(s) asked for (``a,b``: each);
    ``chosen_by`` names the setting that chose SLURM (``search.launcher=slurm``), ``key`` the partition's."""
    import subprocess

    try:
        done = subprocess.run(["sinfo", "--noheader", "--format=%P"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as err:
        raise ConfigError(f"{chosen_by}: cannot run sinfo here ({err}); submit from a SLURM login node") from None
    if done.returncode != 0:
        reason = (done.stderr.strip().splitlines() or [f"exit code {done.returncode}"])[-1]
        raise ConfigError(f"{chosen_by}: SLURM does not answer here ({reason})")
    known = [name.rstrip("*") for name in done.stdout.split()]
    missing = [name for name in (partition or "").split(",") if name and name not in known]
    if missing:
        raise ConfigError(f"{key}={partition}: no partition {', '.join(missing)} here; "
                          f"choose among: {', '.join(known)}")


def check_slurm_resources(settings: Mapping[str, Any], prefix: str) -> None:
    """ConfigError unless each job's minutes, CPUs and memory in ``settings`` (null: SLURM's default) are 1 or
    more; ``prefix`` names where they are set (``hydra.launcher.``)."""
    for name, unit in SLURM_RESOURCES.items():
        value = settings.get(name)
        if value is not None and not (isinstance(value, int) and value >= 1):
            raise ConfigError(f"{prefix}{name}={value}: give the {unit} of each job, 1 or more")


def check_launcher(launcher: DictConfig, submits: bool = True) -> None:
    """SweepError (exit 2) for a launcher that cannot launch the sweep's runs. A launcher's ``n_jobs`` (runs at
    once on this machine, which threads=auto divides the cores by) must be 1 or more: joblib's counts below 1
    (its plugin's default, -1) are refused, not guessed. A SLURM launcher (one with a ``partition``, as
    ``RUNS_AT_ONCE`` in :mod:`sweeps.launch` tells it) must give each job 1 or more minutes, CPUs and GB, and,
    unless nothing is submitted (``submits`` False: a dry run), SLURM must answer here with that partition."""
    try:
        if "partition" in launcher:
            check_slurm_resources(launcher, "hydra.launcher.")
            if submits:
                check_slurm(launcher.get("partition"), "hydra/launcher=slurm", "hydra.launcher.partition")
    except ConfigError as err:
        raise SweepError(str(err), exit_code=2) from None
    if "n_jobs" not in launcher:
        return
    n_jobs = launcher.get("n_jobs")
    if not isinstance(n_jobs, int) or n_jobs < 1:
        raise SweepError(f"hydra.launcher.n_jobs={n_jobs}: give the number of runs to train at once, 1 or more, "
                         f"or ${{hersd_cores:}} for one per core ({available_cores()} here, the default of "
                         "hydra/launcher=local)", exit_code=2)


SWEEP_ENV = "HERSD_SWEEP_PROCESS"  # "<pid>:<start time>" of the sweep's main process, for its local jobs
POLL_SECONDS = 0.5  # how often a worker looks for its command's main process
_watching: list[str] = []  # the process this worker process watches (once per process: loky reuses its workers)


def process_start(pid: int) -> str:
    """When process ``pid`` started (``/proc/<pid>/stat``'s field 22, clock ticks since boot): with the pid it names
    one process, whose pid the system may reuse once it is gone; "" where /proc is absent (not Linux), "gone" if
    there is no such process or it has ended and waits to be reaped (a zombie, state Z or X: a main process killed
    while its own parent, e.g. one reading its output until its workers close the pipes, has not waited for it)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return "gone" if fields[0] in ("Z", "X") else fields[19]
    except FileNotFoundError:
        return "gone" if Path("/proc/self/stat").exists() else ""
    except (OSError, IndexError):
        return ""


def alive(pid: int, start: str) -> bool:
    """Whether the process ``pid`` that started at ``start`` (:func:`process_start`) still runs."""
    return process_start(pid) == start if start else pid_alive(pid)


def main_process() -> str:
    """This process as its workers watch it (:func:`end_with`): ``"<pid>:<start time>"``."""
    return f"{os.getpid()}:{process_start(os.getpid())}"


@contextmanager
def watched_by_jobs(launcher: Any, jobs: int, here: bool = True) -> Iterator[None]:
    """In a sweep's main process, around the launch of its ``jobs``, if they train on this machine (``here``): name
    this process to them (:data:`SWEEP_ENV`, inherited by the processes the launcher starts; as it was afterwards),
    and start no more joblib workers than jobs (:func:`sweeps.hydra_private.cap_local_workers`: a worker without a
    job would never watch)."""
    if not here:
        yield
        return
    cap_local_workers(launcher, jobs)
    before = os.environ.get(SWEEP_ENV)
    os.environ[SWEEP_ENV] = main_process()
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(SWEEP_ENV, None)
        else:
            os.environ[SWEEP_ENV] = before


def end_with_sweep() -> None:
    """In a job process of a sweep that trains here (:data:`SWEEP_ENV` set): :func:`end_with` the sweep's main
    process. Its run keeps what its log and checkpoint hold (both written atomically): a re-run resumes it."""
    if named := os.environ.get(SWEEP_ENV):
        end_with(named, "hersd-sweep", "its run resumes when the same command runs again")


def end_with(named: str, command: str, then: str) -> None:
    """In a worker process of ``command`` whose main process is ``named`` (:func:`main_process`): a daemon thread
    that ends this process within :data:`POLL_SECONDS` of that one, with one line on stderr (``then``: what becomes
    of its work); once per process, and never where the main process is this one."""
    if _watching == [named]:
        return
    _watching[:] = [named]
    pid, _, start = named.partition(":")
    if int(pid) == os.getpid():  # a launcher that runs the jobs in the command's own process
        return
    threading.Thread(target=_end_after, args=(int(pid), start, command, then), daemon=True,
                     name=f"{command}-watch").start()


def _end_after(pid: int, start: str, command: str, then: str) -> None:
    while alive(pid, start):
        time.sleep(POLL_SECONDS)
    try:
        print(f"{command}: its main process (pid {pid}) is gone; its worker {os.getpid()} ends with it ({then})",
              file=sys.stderr, flush=True)
    finally:
        os._exit(1)
