"""``hersd-sweep``: many training runs (a grid x tasks x seeds) through a Hydra launcher.

Data flow: ``conf/sweep.yaml`` (+ ``conf/grid/<name>.yaml`` and command-line overrides) ->
the ``runstore`` sweeper (``hydra_plugins/hersd_sweeper``) expands the grid and calls
:func:`sweep_runs`, which composes and checks every run before any starts, skips the
complete ones, and hands the rest to the launcher (joblib locally, one job per core;
submitit for SLURM). Each job calls :func:`run_job`, i.e. ``hersd.engine.train.train`` on its own
config; the run store (one directory per config, a lock, checkpoints) makes re-running a
sweep finish what is missing and nothing else.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from hersd.contract.errors import ConfigError, sigterm_as_ctrl_c
from hersd.contract.learner_registry import typed_instead
from hersd.contract.cores import resolve_threads

if TYPE_CHECKING:  # the rest loads in the functions, inside main's Ctrl-C handling (the module loads in ~0.1 s)
    from omegaconf import DictConfig

PROGRESS_NAME = "progress.jsonl"
_composed = False  # set once the sweeper is reached: the command line composed into a config
_hydra_full_error = "0"  # the user's HYDRA_FULL_ERROR ("1": tracebacks), restored once composed


# How many of a sweep's n_runs train on this machine at once, read from the launcher's own settings:
# the first key of this table that its config has decides (so a launcher YAML needs no code).
# None: its jobs run elsewhere, each on its own allocation, and resolve threads=auto there.
RUNS_AT_ONCE: tuple[tuple[str, Callable[[Any, int], int | None]], ...] = (
    ("partition", lambda partition, n_runs: None),  # a cluster's queue (submitit's SLURM)
    ("n_jobs", lambda n_jobs, n_runs: int(n_jobs)),  # joblib (1 or more: sweeps.launchers.check_launcher)
    ("array_parallelism", lambda at_most, n_runs: int(at_most or n_runs)),  # an executor's cap
    ("tasks_per_node", lambda tasks, n_runs: n_runs),  # an executor that starts every job (submitit's local)
)  # none of them (Hydra's basic launcher): one after another


def concurrent_runs(launcher: DictConfig, n_runs: int) -> int | None:
    """How many of the sweep's ``n_runs`` share this machine's cores at once (:data:`RUNS_AT_ONCE`),
    None if each runs on an allocation of its own."""
    for key, runs_at_once in RUNS_AT_ONCE:
        if key in launcher:
            at_once = runs_at_once(launcher.get(key), n_runs)
            return None if at_once is None else max(1, min(at_once, n_runs))
    return 1


# --------------------------------------------------------------------------- in the sweeping process
def sweep_runs(sweeper: Any, arguments: list[str]) -> list:
    """Expand, check, list (dry run) or launch the grid; print a summary; raise if any run failed."""
    from hersd.contract.runstore import RunFolder, check_writable
    from sweeps.launchers import check_launcher, watched_by_jobs
    from sweeps.plan import SweepConfig, SweepError, launched, plan_runs, save_specs, trainable_here

    global _composed
    _composed = True
    os.environ["HYDRA_FULL_ERROR"] = _hydra_full_error  # composed: Hydra reports the rest as the user set it
    try:  # the sweep's own setting, before the grid expands it; plan_runs checks every run's config (not the
        SweepConfig.check_seeds(sweeper.config.seeds)  # grid's base: schedule=linear,exponential schedule.beta1=0.3
    except ConfigError as err:                         # is valid, though the base's constant has no beta1)
        raise SweepError(str(err), exit_code=2) from None
    sweep_threads = sweeper.config.threads
    check_launcher(sweeper.config.hydra.launcher, submits=not sweeper.dry_run)
    planned = plan_runs(sweeper, arguments)
    states = {directory: RunFolder(directory).state() for directory in planned}
    counts = {state: sum(s == state for s in states.values()) for state in ("complete", "resumable", "new")}
    plan = [f"sweep: {len(planned)} runs: {counts['complete']} complete (skipped), {counts['resumable']} to resume, "
            f"{counts['new']} new"]  # printed once the checks pass: bad input is the error's line alone
    at_once = concurrent_runs(sweeper.config.hydra.launcher, len(planned) - counts["complete"])
    if at_once is not None:  # they train here: skip now what this machine cannot run (all of them: refused)
        planned, skipped = trainable_here(planned, states)
        plan += skipped
    runs = [run for directory, run in planned.items() if states[directory] != "complete"]
    sweep_dir = Path(sweeper.config.hydra.sweep.dir)
    if runs:  # below results_dir, like every run's folder; a dry run checks it too, leaving no folder behind
        try:
            check_writable(sweep_dir, keep=not sweeper.dry_run)
        except ConfigError as err:
            raise SweepError(str(err), exit_code=2) from None
    print("\n".join(plan), flush=True)
    if sweeper.dry_run:
        list_runs(planned, at_once)
        return []
    if not runs:
        return []
    threads = auto_threads(sweeper.config.hydra.launcher, len(runs)) if sweep_threads == "auto" else None
    specs = dict(launched(run, threads) for run in runs)
    to_launch = [list(job) for job in specs]
    save_specs(sweep_dir, specs, len(to_launch))  # a full disk: exit 2
    with watched_by_jobs(sweeper.launcher, len(to_launch), here=at_once is not None):  # jobs here end with this
        results = launch_jobs(sweeper, to_launch)
    report_outcomes(to_launch, results, skipped=counts["complete"])
    return [results]


def list_runs(planned: dict, at_once: int | None) -> None:
    """The dry run's listing: one line per run, in launch order, with its state (:func:`run_status`),
    directory, progress and job; then the runs training now with their pids, and what is left
    (:func:`sweeps.status.time_to_go`; ``at_once``: runs sharing this machine, None on a cluster)."""
    from hersd.contract.runstore import run_status
    from sweeps.status import time_to_go
    statuses = []
    for directory, run in planned.items():
        status = run_status(directory, run.epochs)
        statuses.append(status)
        print(f"  {status.state:<9} {directory}  " + (f"{status.detail}  " if status.detail else "")
              + f"[{' '.join(run.job)}]")
    holders = [str(status.holder) for status in statuses if status.state == "running"]
    if holders:
        print(f"{len(holders)} training now (pid {', '.join(holders)})")
    if (left := time_to_go(statuses, at_once)) is not None:
        print(left)


def auto_threads(launcher: DictConfig, n_runs: int) -> int | None:
    """``threads=auto`` for each run of a local launcher: this machine's idle cores divided among
    the runs in flight at once (:func:`hersd.contract.cores.resolve_threads`). None where each job has
    an allocation of its own (SLURM): it resolves ``auto`` itself (``SLURM_CPUS_PER_TASK``, its CPU affinity)."""
    at_once = concurrent_runs(launcher, n_runs)
    return None if at_once is None else resolve_threads("auto", at_once)


def launch_jobs(sweeper: Any, jobs: list[list[str]]) -> list:
    """Launch the jobs -> their results; a submitit job, or a joblib worker, that died or was cut short is a
    SweepError (a worker killed, by hand or the OOM killer: loky's TerminatedWorkerError, one line, not a traceback)."""
    from sweeps.plan import SweepError
    try:
        return sweeper.launcher.launch(jobs, initial_job_idx=0)
    except Exception as err:  # noqa: BLE001 - only submitit's and joblib's job errors are translated
        kind = type(err).__name__
        if not type(err).__module__.startswith(("submitit", "joblib")):
            raise
        first_line = (str(err).strip().splitlines() or [kind])[0][:200]
        what = ("a job timed out or was cancelled (its run is resumable)" if kind == "UncompletedJobError"
                else "a worker process died outside hersd (its run is resumable)" if kind == "TerminatedWorkerError"
                else "a job died outside hersd")
        raise SweepError(f"{what}: {first_line}; finished runs are kept: run the same command again to resume "
                         f"the rest", exit_code=1) from None


def report_outcomes(jobs: list[list[str]], results: list, skipped: int) -> None:
    """Print how each launched run ended; raise (exit code 1) if any failed."""
    from hydra.core.utils import JobStatus

    from sweeps.hydra_private import job_error
    from sweeps.plan import SweepError

    outcomes: dict[str, list[str]] = {"done": [], "resumed": [], "busy": [], "failed": [], "full_disk": []}
    for job, result in zip(jobs, results):
        if result.status == JobStatus.FAILED:
            outcomes["failed"].append(f"[{' '.join(job)}]: {job_error(result)}")
        else:
            outcome = result.return_value
            detail = outcome["run_dir"] + (f" (see {outcome['error_log']})" if outcome.get("error_log") else "")
            outcomes[outcome["status"]].append(detail)
            outcomes["full_disk"] += [outcome["full_disk"]] if "full_disk" in outcome else []
    print(f"sweep finished: {len(outcomes['done'])} done, {skipped} skipped (complete), "
          f"{len(outcomes['resumed'])} resumed, {len(outcomes['busy'])} running elsewhere, "
          f"{len(outcomes['failed'])} failed", flush=True)
    for line in outcomes["failed"]:
        print(f"  failed: {line}", flush=True)
    if outcomes["full_disk"]:  # a failed run whose error.log found no space (sweeps.status.failed_outcome)
        raise SweepError(outcomes["full_disk"][0], exit_code=2)
    if outcomes["failed"]:
        raise SweepError(f"{len(outcomes['failed'])} run(s) failed; fix the cause and run the same command "
                         f"again (finished runs are kept and skipped)", exit_code=1)


# --------------------------------------------------------------------------- in each job process
def run_job(cfg: DictConfig) -> dict[str, Any]:
    """Train one run of the sweep; never raises, so one failure does not stop the others."""
    from hydra.core.hydra_config import HydraConfig

    from hersd.contract.runstore import RunFolder, RunLockedError
    from hersd.engine.train import train
    from sweeps.launchers import end_with_sweep
    from sweeps.plan import job_spec
    from sweeps.status import failed_outcome

    end_with_sweep()
    hydra_cfg = HydraConfig.get()
    spec = job_spec(cfg, Path(hydra_cfg.sweep.dir), list(hydra_cfg.overrides.task))
    directory = spec.folder
    state = RunFolder(directory).state()
    outcome: dict[str, Any] = {"run_dir": str(directory)}
    tic = time.time()
    try:
        train(spec, command=" ".join(["hersd-sweep", *hydra_cfg.overrides.task]))
        outcome["status"] = "resumed" if state == "resumable" else "done"
    except RunLockedError:
        outcome["status"] = "busy"
    except Exception:  # noqa: BLE001 - any failure is this run's alone; it is reported, the sweep goes on
        outcome.update(failed_outcome(directory, traceback.format_exc()))  # its error.log; a full disk: one line
    _report_progress(Path(hydra_cfg.sweep.dir), outcome, time.time() - tic)
    return outcome


def _report_progress(sweep_dir: Path, outcome: dict[str, Any], seconds: float) -> None:
    """Append this run's outcome to the sweep's progress file and print runs done / total and ETA."""
    from sweeps.plan import PLAN_NAME
    from sweeps.status import record_progress

    finished = record_progress(sweep_dir / PROGRESS_NAME, {**outcome, "seconds": seconds})  # full disk: left out
    plan_path = sweep_dir / PLAN_NAME
    plan = json.loads(plan_path.read_text()) if plan_path.exists() else {"runs": finished, "start": time.time()}
    elapsed = time.time() - plan["start"]
    remaining = max(plan["runs"] - finished, 0)
    eta = time.strftime("%H:%M:%S", time.gmtime(elapsed / finished * remaining)) if finished else "?"
    print(f"[sweep {finished}/{plan['runs']}] {outcome['status']:<7} {outcome['run_dir']} "
          f"({seconds:.0f} s)  ETA {eta}", flush=True)


def launcher_options() -> list[str]:
    """The hydra/launcher options: hersd's YAMLs (conf/hydra/launcher) and submitit's own local one."""
    from hersd.contract.compose import group_options
    return [*group_options("hydra/launcher"), "submitit_local"]


def usage() -> str:
    """``hersd-sweep --help``: the command, its groups (those a sweep takes) and keys."""
    from hersd.contract.compose import group_choices
    groups = [f"  {'+grid' if group == 'grid' else group}={'|'.join(group_choices(group))}"
              for group in ("grid", "task", "algo", "schedule", "learner")]
    return "\n".join([
        "usage: hersd-sweep [+grid=NAME] [KEY=VALUE ...] [--dry-run]", "",
        "Trains many runs (a grid x tasks x seeds) seed by seed, one per core (or on SLURM); complete",
        "runs are skipped and interrupted ones resumed, so the same command finishes a sweep. A key",
        "given a comma list (schedule=constant,linear) is swept. --dry-run lists each run and its state",
        "(complete; running: epoch N of K and its pid; failed; resumable: epoch N of K; new) without running.", "",
        "config groups:", *groups,
        f"  hydra/launcher={'|'.join(launcher_options())}   (local: this machine, one run per core, the default)", "",
        "keys: seeds=5 (without seed=, each grid sweeps seed over range(seeds)), results_dir=results,",
        "hydra.launcher.n_jobs=N (local: runs at once), every hersd-train key (hersd-train --help lists them).", "",
        "examples:",
        "  hersd-sweep +grid=smoke",
        "  hersd-sweep task=reach seeds=3 schedule=linear schedule.beta1=0.5,0.7   (6 runs)",
        "  hersd-sweep +grid=beta task=push seeds=3 epochs=50 --dry-run",
        "  hersd-sweep +grid=beta hydra/launcher=slurm hydra.launcher.partition=P",
        "See README.md (Commands) and docs/ARCHITECTURE.md (sweeps/).",
    ])


@sigterm_as_ctrl_c()  # ``kill PID`` too: one line, exit 130, finished runs kept
def main() -> None:
    """Entry point: Hydra's command line over ``conf/sweep.yaml``; ``--dry-run`` lists the runs; an
    interrupt (Ctrl-C) ends with one line and exit code 130, from the start (the modules load in here); a command
    line that does not compose, with one line and exit code 2 (the traceback with ``HYDRA_FULL_ERROR=1``)."""
    global _hydra_full_error
    try:
        import hydra

        from hersd.contract.compose import CONFIG_PATH, explain_config_error, null_group
        from hersd.engine.cli import unknown_option
        from sweeps.plan import register_schemas

        if any(arg in ("-h", "--help") for arg in sys.argv[1:]):
            print(usage())
            return
        if said := unknown_option(sys.argv[1:], "hersd-sweep", ("-h", "--help", "--dry-run")):
            raise ConfigError(said)  # before --dry-run becomes hydra.sweeper.dry_run=true: what the user typed
        if "--dry-run" in sys.argv:
            signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # a listing: a reader gone (``| head``) ends it quietly
            sys.argv = [arg for arg in sys.argv if arg != "--dry-run"] + ["hydra.sweeper.dry_run=true"]
        for arg in sys.argv[1:]:  # a class by its path is no config of the group: one line saying what selects it
            key, _, value = arg.partition("=")
            if key.lstrip("+") == "learner" and (instead := typed_instead(value)):
                print(f"hersd-sweep: error: {arg} names a class, which no config of the learner group holds; "
                      f"type {instead}", file=sys.stderr)
                sys.exit(2)
        register_schemas()
        _hydra_full_error = os.environ.get("HYDRA_FULL_ERROR", "0")
        os.environ["HYDRA_FULL_ERROR"] = "1"  # a composition error reaches the except below; sweep_runs restores it
        if said := null_group(sys.argv[1:]):
            raise ConfigError(said)
        hydra.main(config_path=CONFIG_PATH, config_name="sweep", version_base="1.3")(run_job)()
    except KeyboardInterrupt:
        print("hersd-sweep: interrupted; finished runs and epochs are kept: re-run the same command to resume",
              file=sys.stderr)
        sys.exit(130)
    except Exception as err:  # the command line does not compose: nothing ran
        if _composed or _hydra_full_error == "1":
            raise
        said = explain_config_error(err, what="sweep setting", see="hersd-sweep --help")
        print(f"hersd-sweep: error: {'+' if said.startswith('grid=') else ''}{said}", file=sys.stderr)
        sys.exit(2)
