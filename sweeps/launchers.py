"""Launchers checked before anything is launched, by both commands that launch runs: ``hersd-sweep``'s Hydra
launcher (:func:`check_launcher`, from :mod:`sweeps.launch`) and ``hersd-search``'s SLURM workers
(:func:`check_slurm`, from :mod:`sweeps.search.workers`). SLURM is asked (``sinfo``) the same way for both, and a
bad setting is one line naming it: exit 2, before any run or job.
"""

from __future__ import annotations

from typing import Any, Mapping

from omegaconf import DictConfig

from hersd.contract.cores import available_cores
from hersd.contract.errors import ConfigError
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
