"""``hersd-sweep``: many training runs (a grid x tasks x seeds) through a Hydra launcher.

Data flow: ``conf/sweep.yaml`` (+ ``conf/grid/<name>.yaml`` and command-line overrides) ->
the ``runstore`` sweeper (``hydra_plugins/hersd_sweeper``) expands the grid and calls
:func:`sweep_runs`, which composes and checks every run before any starts, skips the
complete ones, and hands the rest to the launcher (joblib locally, one job per core;
submitit for SLURM). Each job calls :func:`run_job`, i.e. ``hersd.train.train`` on its own
config; the run store (one directory per config, a lock, checkpoints) makes re-running a
sweep finish what is missing and nothing else.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, open_dict

from hersd.compose import CONFIG_PATH, group_options, register_schema, register_train_schema
from hersd.config import ConfigError, TrainConfig, to_train_config
from hersd.resources import available_cores, resolve_threads
from hersd.runstore import RunLockedError, run_dir, run_state
from sweeps.hydra_private import grid_overrides, job_error

PROGRESS_NAME = "progress.jsonl"
PLAN_NAME = "sweep.json"
_composed = False  # set once the sweeper is reached: the command line composed into a config


@dataclass
class SweepConfig(TrainConfig):
    seeds: int = 5  # grids sweep ``seed`` over range(seeds)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.seeds < 1:
            raise ConfigError(f"seeds must be >= 1, got {self.seeds}")


class SweepError(RuntimeError):
    """A sweep cannot start (a run's config is invalid: exit code 2) or ended with failed
    runs (exit code 1)."""

    def __init__(self, message: str, exit_code: int):
        super().__init__(message)
        self.exit_code = exit_code


def register_schemas() -> None:
    """``train_schema`` and ``sweep_schema`` (which conf/sweep.yaml lists first)."""
    register_train_schema()
    register_schema("sweep_schema", SweepConfig)


def job_train_config(cfg: DictConfig) -> TrainConfig:
    """A composed sweep job config (with or without its ``hydra`` node) -> its TrainConfig."""
    cfg = cfg.copy()
    if "hydra" in cfg:
        with open_dict(cfg):
            del cfg["hydra"]
    sweep_cfg = to_train_config(cfg)
    return TrainConfig(**{f.name: getattr(sweep_cfg, f.name) for f in fields(TrainConfig)})


def concurrent_runs(launcher: DictConfig, n_runs: int) -> int:
    """How many of the sweep's ``n_runs`` share this machine's cores at once: joblib's n_jobs
    (-1: one per core), all of them for submitit_local, 1 for SLURM (each job has its own
    allocation) and for Hydra's basic launcher (one after another)."""
    target = str(launcher.get("_target_", ""))
    if target.endswith("JoblibLauncher"):
        n_jobs = int(launcher.get("n_jobs") or -1)
        at_once = n_jobs if n_jobs > 0 else max(1, available_cores() + 1 + n_jobs)  # joblib's rule for n_jobs < 0
    elif target.endswith("submitit_launcher.LocalLauncher"):
        at_once = int(launcher.get("array_parallelism") or n_runs)
    else:
        at_once = 1
    return max(1, min(at_once, n_runs))


def with_threads(job: list[str], threads: int) -> list[str]:
    """A job's overrides with ``threads=<threads>`` unless it sets threads itself."""
    return job if any(o.split("=", 1)[0].lstrip("+") == "threads" for o in job) else [*job, f"threads={threads}"]


# --------------------------------------------------------------------------- in the sweeping process
def sweep_runs(sweeper: Any, arguments: list[str]) -> list:
    """Expand, check, list (dry run) or launch the grid; print a summary; raise if any run failed."""
    global _composed
    _composed = True
    try:  # the sweep's own settings (e.g. seeds >= 1), before the grid expands them
        sweep_threads = job_train_config(sweeper.config).threads
    except ConfigError as err:
        raise SweepError(str(err), exit_code=2) from None
    planned = plan_runs(sweeper, arguments)
    states = {directory: run_state(directory) for directory in planned}
    counts = {state: sum(s == state for s in states.values()) for state in ("complete", "resumable", "new")}
    print(f"sweep: {len(planned)} runs: {counts['complete']} complete (skipped), "
          f"{counts['resumable']} to resume, {counts['new']} new", flush=True)
    if sweeper.dry_run:
        for directory, job in planned.items():
            print(f"  {states[directory]:<9} {directory}  [{' '.join(job)}]")
        return []

    to_launch = [job for directory, job in planned.items() if states[directory] != "complete"]
    if not to_launch:
        return []
    threads = auto_threads(sweeper.config.hydra.launcher, len(to_launch)) if sweep_threads == "auto" else None
    if threads is not None:
        to_launch = [with_threads(job, threads) for job in to_launch]
    sweep_dir = Path(sweeper.config.hydra.sweep.dir)
    sweep_dir.mkdir(parents=True, exist_ok=True)
    (sweep_dir / PLAN_NAME).write_text(json.dumps({"runs": len(to_launch), "start": time.time()}))
    results = launch_jobs(sweeper, to_launch)
    report_outcomes(to_launch, results, skipped=counts["complete"])
    return [results]


def auto_threads(launcher: DictConfig, n_runs: int) -> int | None:
    """``threads=auto`` for each run of a local launcher: this machine's idle cores divided among
    the runs in flight at once (:func:`hersd.resources.resolve_threads`). None for SLURM: each job
    resolves ``auto`` itself from what it was given (``SLURM_CPUS_PER_TASK``, its CPU affinity)."""
    if str(launcher.get("_target_", "")).endswith("SlurmLauncher"):
        return None
    return resolve_threads("auto", concurrent_runs(launcher, n_runs))


def launch_jobs(sweeper: Any, jobs: list[list[str]]) -> list:
    """Launch the jobs -> their results; a submitit job that died or was cut short is a SweepError."""
    try:
        return sweeper.launcher.launch(jobs, initial_job_idx=0)
    except Exception as err:  # noqa: BLE001 - only submitit's job errors are translated
        kind = type(err).__name__
        if not type(err).__module__.startswith("submitit"):
            raise
        first_line = (str(err).strip().splitlines() or [kind])[0][:200]
        what = ("a job timed out or was cancelled (its run is resumable)" if kind == "UncompletedJobError"
                else "a job died outside hersd")
        raise SweepError(f"{what}: {first_line}; finished runs are kept: run the same command again to resume "
                         f"the rest", exit_code=1) from None


def plan_runs(sweeper: Any, arguments: list[str]) -> dict[Path, list[str]]:
    """The grid (sweeper params + command line) expanded and checked -> run dir -> its overrides,
    in grid order; a grid naming a run twice runs it once. An invalid run config stops the sweep."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create(config_loader=sweeper.hydra_context.config_loader)
    overrides = parser.parse_overrides(grid_overrides(sweeper) + list(arguments))
    jobs = [list(job) for batch in sweeper.split_arguments(overrides, None) for job in batch]
    if not jobs:
        raise SweepError("the sweep expands to no runs; give each swept key at least one value", exit_code=2)
    planned: dict[Path, list[str]] = {}
    for job in jobs:
        job_cfg = sweeper.hydra_context.config_loader.load_sweep_config(sweeper.config, job)
        try:
            planned.setdefault(run_dir(job_train_config(job_cfg)), job)
        except ConfigError as err:
            raise SweepError(f"run [{' '.join(job)}]: {err}", exit_code=2) from None
    return planned


def report_outcomes(jobs: list[list[str]], results: list, skipped: int) -> None:
    """Print how each launched run ended; raise (exit code 1) if any failed."""
    from hydra.core.utils import JobStatus

    outcomes: dict[str, list[str]] = {"done": [], "resumed": [], "busy": [], "failed": []}
    for job, result in zip(jobs, results):
        if result.status == JobStatus.FAILED:
            outcomes["failed"].append(f"[{' '.join(job)}]: {job_error(result)}")
        else:
            outcome = result.return_value
            detail = outcome["run_dir"] + (f" (see {outcome['error_log']})" if outcome.get("error_log") else "")
            outcomes[outcome["status"]].append(detail)
    print(f"sweep finished: {len(outcomes['done'])} done, {skipped} skipped (complete), "
          f"{len(outcomes['resumed'])} resumed, {len(outcomes['busy'])} running elsewhere, "
          f"{len(outcomes['failed'])} failed", flush=True)
    for line in outcomes["failed"]:
        print(f"  failed: {line}", flush=True)
    if outcomes["failed"]:
        raise SweepError(f"{len(outcomes['failed'])} run(s) failed; fix the cause and run the same command "
                         f"again (finished runs are kept and skipped)", exit_code=1)


# --------------------------------------------------------------------------- in each job process
def run_job(cfg: DictConfig) -> dict[str, Any]:
    """Train one run of the sweep; never raises, so one failure does not stop the others."""
    from hydra.core.hydra_config import HydraConfig

    from hersd.train import train

    hydra_cfg = HydraConfig.get()
    train_cfg = job_train_config(cfg)
    directory = run_dir(train_cfg)
    state = run_state(directory)
    outcome: dict[str, Any] = {"run_dir": str(directory)}
    tic = time.time()
    try:
        train(train_cfg, command=" ".join(["hersd-sweep", *hydra_cfg.overrides.task]))
        outcome["status"] = "resumed" if state == "resumable" else "done"
    except RunLockedError:
        outcome["status"] = "busy"
    except Exception:  # noqa: BLE001 - any failure is this run's alone; it is reported, the sweep goes on
        error_log = directory / "error.log"
        error_log.parent.mkdir(parents=True, exist_ok=True)
        error_log.write_text(traceback.format_exc())
        outcome.update(status="failed", error_log=str(error_log))
    _report_progress(Path(hydra_cfg.sweep.dir), outcome, time.time() - tic)
    return outcome


def _report_progress(sweep_dir: Path, outcome: dict[str, Any], seconds: float) -> None:
    """Append this run's outcome to the sweep's progress file and print runs done / total and ETA."""
    line = json.dumps({**outcome, "seconds": seconds}) + "\n"
    with open(sweep_dir / PROGRESS_NAME, "a") as progress:
        progress.write(line)
    finished = len((sweep_dir / PROGRESS_NAME).read_text().splitlines())
    plan_path = sweep_dir / PLAN_NAME
    plan = json.loads(plan_path.read_text()) if plan_path.exists() else {"runs": finished, "start": time.time()}
    elapsed = time.time() - plan["start"]
    remaining = max(plan["runs"] - finished, 0)
    eta = time.strftime("%H:%M:%S", time.gmtime(elapsed / finished * remaining)) if finished else "?"
    print(f"[sweep {finished}/{plan['runs']}] {outcome['status']:<7} {outcome['run_dir']} "
          f"({seconds:.0f} s)  ETA {eta}", flush=True)


def main() -> None:
    """Entry point: Hydra's command line over ``conf/sweep.yaml``; ``--dry-run`` lists the runs; an
    interrupt (Ctrl-C) ends with one line and exit code 130."""
    import hydra

    if "--dry-run" in sys.argv:
        sys.argv = [arg for arg in sys.argv if arg != "--dry-run"] + ["hydra.sweeper.dry_run=true"]
    register_schemas()
    os.environ.setdefault("HYDRA_FULL_ERROR", "0")
    try:
        hydra.main(config_path=CONFIG_PATH, config_name="sweep", version_base="1.3")(run_job)()
    except SystemExit as end:
        if end.code and not _composed:
            print(f"hersd-sweep: valid choices: {choices_line()}", file=sys.stderr)
        raise
    except KeyboardInterrupt:
        print("hersd-sweep: interrupted; finished runs and epochs are kept: re-run the same command to resume",
              file=sys.stderr)
        sys.exit(130)


def choices_line() -> str:
    """One line listing the grid/task/algo/schedule options and the top-level keys."""
    groups = [f"{'+grid' if group == 'grid' else group}={'|'.join(group_options(group))}"
              for group in ("grid", "task", "algo", "schedule", "learner")]
    nested = ("task", "algo", "schedule", "ddpg", "learner")
    keys = [f.name for f in fields(SweepConfig) if f.name not in nested]
    return "  ".join(groups) + f"  keys: {', '.join(keys)}, " + ", ".join(f"{name}.*" for name in nested)
