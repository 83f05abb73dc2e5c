"""``hersd-campaign``: a campaign of sweeps (``conf/campaign/<name>.yaml``) as one resumable command.

A campaign is a list of stages, each a list of ``hersd-sweep`` command lines; run one after
another they make every run of the campaign. Subcommands (``--results-dir`` defaults to
``~/hersd-campaign``, outside the work tree):

- ``start``  runs the campaign in a detached background process (``run``), output to
  ``<DIR>/campaign.log``, and returns at once; a campaign already running for DIR is left alone;
- ``run``    the same in the foreground (what ``start`` runs);
- ``status`` one line per planned run: complete, ``epoch N of K`` or new, and what is training;
- ``land``   copies each planned run's ``run.mcap`` into the repository's results folder;
- ``import`` checks logs of the campaign made on another machine (``../shared/campaign``) and
  copies those that pass (:func:`import_logs`) into the same folder.

On a fresh machine (or after the results folder was lost) ``run`` first copies in each planned
run that ``land`` already put in the repository complete (:func:`reuse_landed`), so no complete
run is trained twice.

Planned runs are found the way hersd-sweep finds them: each sweep's grid is expanded by
Hydra's basic sweeper and every job composed into its TrainConfig, whose
:func:`hersd.runstore.run_dir` is the run's directory. ``run`` keeps one run per core training
(``--jobs``), in plan order (stage by stage), each as the one-run sweep ``hersd-sweep <its
overrides>``: a stage's last runs share the machine with the next stage's first instead of
leaving cores idle. The run store resumes interrupted runs, so starting a campaign again
finishes what is missing.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import time
from collections import deque
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Callable, Sequence

from hersd.compose import CONFIG_MODULE, explain_config_error, group_options
from hersd.config import TrainConfig
from hersd.resources import available_cores
from hersd.runlog import LOG_NAME, RunLogError, RunRecords, read_records
from hersd.runstore import LOCK_NAME, config_hash, policy_animations, run_dir, run_state
from sweeps.hydra_private import basic_sweeper_class, grid_overrides
from sweeps.launch import job_train_config, register_schemas, with_threads

GROUP = "campaign"  # conf/campaign/<name>.yaml
DEFAULT_CAMPAIGN = "push_paper"
DEFAULT_RESULTS_DIR = Path.home() / "hersd-campaign"
DEFAULT_INTO = Path("results")
DEFAULT_SOURCE = Path("../shared/campaign")  # logs of the campaign made on other machines, beside the repository
PROJECT_COMMANDS = ("hersd-sweep", "hersd-train")  # what made an importable log
PID_NAME = "campaign.pid"
CAMPAIGN_LOG = "campaign.log"
RUNNER = [sys.executable, "-m", "sweeps.campaign", "run"]  # what ``start`` detaches; its command line names this module
SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]  # hersd-sweep in this interpreter
POLL_SECONDS = 2.0  # how often the runner looks for a finished run
PACE_EPOCHS = 5  # status: a training run's pace is the mean time of its last this many epochs
STOP_SECONDS = 60.0  # how long an interrupted runner waits for its runs to save and end before stopping them


class CampaignError(ValueError):
    """Bad input: an unknown campaign, a folder that cannot be created or written."""


@dataclass(frozen=True)
class Stage:
    name: str
    sweeps: list[list[str]]  # each a hersd-sweep command line (without results_dir)


@dataclass(frozen=True)
class PlannedRun:
    """One run of the campaign: the first stage that names it, its directory below the results dir."""

    stage: int  # 1-based
    relative: Path  # e.g. push/her/constant-0.8/seed1-0c03aeaf
    config: TrainConfig
    overrides: tuple[str, ...]  # hersd-sweep's command line for this run alone (its stage's sweep's job)

    @property
    def seed(self) -> int:
        return self.config.seed

    @property
    def epochs(self) -> int:
        return self.config.epochs

    @property
    def arm(self) -> str:
        return self.relative.parent.as_posix()


def load_campaign(name: str) -> list[Stage]:
    """The stages of ``conf/campaign/<name>.yaml``."""
    from importlib.resources import files

    from omegaconf import OmegaConf

    if name not in group_options(GROUP):
        raise CampaignError(f"unknown campaign {name!r}; choose one of: {', '.join(group_options(GROUP))}")
    conf = OmegaConf.create(files(CONFIG_MODULE).joinpath(GROUP, f"{name}.yaml").read_text())
    return [Stage(str(stage.name), [shlex.split(sweep) for sweep in stage.sweeps]) for stage in conf.stages]


# --------------------------------------------------------------------------- the plan
def sweep_jobs(overrides: list[str], compose: Callable) -> list[list[str]]:
    """One hersd-sweep command line -> each run's overrides, in the order hersd-sweep runs them:
    the grid's ``hydra.sweeper.params`` then the command line, expanded by Hydra's basic sweeper."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    parser = OverridesParser.create()
    fixed = [o.input_line for o in parser.parse_overrides(overrides) if not o.is_sweep_override()]
    params = compose("sweep", fixed, return_hydra_config=True).hydra.sweeper.params
    sweeper = basic_sweeper_class()(max_batch_size=None, params=OmegaConf.to_container(params, resolve=True))
    batches = sweeper.split_arguments(parser.parse_overrides(grid_overrides(sweeper) + overrides), None)
    return [job for batch in batches for job in batch]


def job_config(job: list[str], compose: Callable, composed: dict[tuple[str, ...], TrainConfig]) -> TrainConfig:
    """One job's TrainConfig. Jobs that differ only in ``seed`` and ``seeds`` (which set no other
    field) are composed once, in ``composed``, and the seed set afterwards: composing is slow."""
    key = tuple(override for override in job if override.split("=", 1)[0] not in ("seed", "seeds"))
    if key not in composed:
        composed[key] = job_train_config(compose("sweep", list(key)))
    seeds = [override.removeprefix("seed=") for override in job if override.startswith("seed=")]
    return replace(composed[key], seed=int(seeds[0])) if seeds else composed[key]


def plan_runs(stages: list[Stage], results_dir: Path) -> list[PlannedRun]:
    """Every run of the stages, in stage order, each once (under the first stage that names it)."""
    from hydra import compose, initialize_config_module

    register_schemas()
    planned: dict[Path, PlannedRun] = {}
    composed: dict[tuple[str, ...], TrainConfig] = {}
    try:
        with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3", job_name="hersd-campaign"):
            for number, stage in enumerate(stages, 1):
                for sweep in stage.sweeps:
                    for job in sweep_jobs([*sweep, f"results_dir={results_dir}"], compose):
                        cfg = job_config(job, compose, composed)
                        relative = run_dir(cfg).relative_to(results_dir)
                        planned.setdefault(relative, PlannedRun(number, relative, cfg, tuple(job)))
    except Exception as err:  # noqa: BLE001 - Hydra's composition errors become one line
        raise CampaignError(f"the campaign's sweeps do not compose: {explain_config_error(err)}") from None
    return list(planned.values())


# --------------------------------------------------------------------------- what is running
def campaign_pid(results_dir: Path) -> int | None:
    """The pid of the campaign process running for ``results_dir`` (its pid file names a live
    process whose command line is the runner's), else None."""
    pid = _pid_file(results_dir)
    if pid is None:
        return None
    try:
        os.kill(pid, 0)
    except OSError:  # no such process, or another user's: not a runner we started
        return None
    try:
        command = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:  # no /proc: trust the live pid
        return pid
    if state == "Z":  # exited, not yet reaped
        return None
    # the runner start detached, or hersd-campaign run, not a reused pid (empty: just started, exec under way)
    return pid if not command or "sweeps.campaign" in command or "hersd-campaign" in command else None


def _pid_file(results_dir: Path) -> int | None:
    try:
        return int((results_dir / PID_NAME).read_text().strip())
    except (OSError, ValueError):
        return None


def runs_in_training(results_dir: Path) -> dict[Path, int]:
    """Run directories below ``results_dir`` whose lock a process holds -> that process's pid
    (from Linux's /proc/locks, read only; empty where there is none)."""
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return {}
    holders = {}
    for line in lines:  # "1: FLOCK  ADVISORY  WRITE 2159 fe:00:1474567 0 EOF" (major:minor:inode)
        fields = line.split()
        if len(fields) > 5 and fields[1] == "FLOCK":
            holders[fields[5]] = int(fields[4])
    found = {}
    for lock in Path(results_dir).rglob(LOCK_NAME):
        try:
            stat = lock.stat()
        except OSError:  # removed meanwhile
            continue
        key = f"{os.major(stat.st_dev):02x}:{os.minor(stat.st_dev):02x}:{stat.st_ino}"
        if key in holders:
            found[lock.parent] = holders[key]
    return found


def progress(log: Path, epochs: int) -> str:
    """``complete``, ``epoch N of K`` (a log being written or interrupted), ``new`` (no log yet)
    or ``unreadable (...)``."""
    if not log.exists():
        return "new"
    try:
        records = read_records(log)
    except RunLogError as err:
        return f"unreadable ({str(err).removeprefix(f'{log}: ')})"
    return "complete" if records.complete else f"epoch {len(records.records)} of {epochs}"


def pace(log: Path, epochs: int) -> str:
    """A run's recent seconds per epoch (the mean of its last PACE_EPOCHS) and the time its
    remaining epochs take at that pace, e.g. ``31 s per epoch, ~1.5 h to go``; "" without epochs."""
    try:
        done = read_records(log).records
    except (OSError, RunLogError):
        return ""
    recent = [record["epoch_seconds"] for record in done[-PACE_EPOCHS:]]
    if not recent:
        return ""
    seconds = sum(recent) / len(recent)
    left = seconds * max(epochs - len(done), 0)
    return f"{seconds:.0f} s per epoch, ~" + (f"{left / 3600:.1f} h" if left >= 3600 else f"{left / 60:.0f} min") \
        + " to go"


# --------------------------------------------------------------------------- subcommands
def status(campaign: str, results_dir: Path) -> int:
    """Print the campaign process's state and one line per planned run."""
    plan = plan_runs(load_campaign(campaign), results_dir)
    pid = campaign_pid(results_dir)
    busy = runs_in_training(results_dir)
    if pid:
        process = f"running (pid {pid}, log {results_dir / CAMPAIGN_LOG})"
    elif busy:
        process = f"not running; process(es) {', '.join(map(str, sorted(set(busy.values()))))} train runs here"
    else:
        process = "not running (hersd-campaign start)"
    print(f"campaign {campaign} in {results_dir}: {process}")
    print(f"{'stage':<6} {'arm':<32} {'seed':<5} state")
    states = []
    for run in plan:
        log = results_dir / run.relative / LOG_NAME
        state = progress(log, run.epochs)
        holder = busy.get(results_dir / run.relative)
        states.append(state)  # counted before the training note
        if holder:
            recent = pace(log, run.epochs) if state.startswith("epoch ") else ""
            state += f", training (pid {holder})" + (f", {recent}" if recent else "")
        print(f"{run.stage:<6} {run.arm:<32} {run.seed:<5} {state}")
    done = states.count("complete")
    started = sum(state.startswith("epoch ") for state in states)
    print(f"{len(plan)} planned runs: {done} complete, {started} in progress, {states.count('new')} new"
          + (f"; {len(busy)} training now" if busy else ""))
    return 0


def land(campaign: str, results_dir: Path, into: Path) -> int:
    """Copy every planned run's log (complete or not) and its policy animations to the same
    relative paths below ``into``; a complete log there is never replaced by an unfinished one
    (a run imported from another machine that this campaign is training as well)."""
    plan = plan_runs(load_campaign(campaign), results_dir)
    landed, gone = [], []
    for run in plan:
        source_dir, target_dir = results_dir / run.relative, into / run.relative
        if not (source_dir / LOG_NAME).exists():
            continue
        state = progress(source_dir / LOG_NAME, run.epochs)
        if state != "complete" and progress(target_dir / LOG_NAME, run.epochs) == "complete":
            print(f"{'kept':<9} {target_dir / LOG_NAME}  complete (the campaign's copy: {state})")
            continue
        (written, removed), log = copy_run(source_dir, target_dir), target_dir / LOG_NAME
        print(f"{'landed' if log in written else 'unchanged':<9} {log}  {progress(log, run.epochs)}")
        for verb, paths in (("landed", written), ("removed", removed)):
            for path in paths:
                if path != log:
                    print(f"{verb:<9} {path}")
        landed += written
        gone += removed
    print(f"{len(landed)} file(s) landed in {into}" + (f", {len(gone)} removed" if gone else "")
          + _git_add(landed + gone))
    return 0


def _git_add(paths: list[Path]) -> str:
    """The end of a summary line: the command that commits ``paths`` (written or removed), if any."""
    return "; commit them with:\n  git add -- " + " ".join(shlex.quote(str(p)) for p in paths) if paths else ""


def copy_atomically(source: Path, target: Path) -> bool:
    """Copy ``source`` to ``target`` through a temporary name and a rename, so ``target`` is
    never partly written; False (nothing written) when ``target`` already holds the same bytes."""
    data = source.read_bytes()  # one snapshot of a log that may be growing
    if target.exists() and target.read_bytes() == data:
        return False
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        temporary.write_bytes(data)
        os.replace(temporary, target)
    except OSError as err:
        raise CampaignError(f"cannot write {target} ({err.strerror})") from None
    return True


def start(campaign: str, results_dir: Path, landed: Path = DEFAULT_INTO, jobs: int | None = None,
          commit: bool = False) -> int:
    """Start the campaign (:func:`run`) in a detached process unless one runs for ``results_dir`` already."""
    load_campaign(campaign)  # an unknown campaign is an error here, not in the log
    pid = campaign_pid(results_dir)
    log = results_dir / CAMPAIGN_LOG
    if pid:
        print(f"campaign already running for {results_dir} (pid {pid}); log {log}")
        return 0
    others = sorted(set(runs_in_training(results_dir).values()))
    if others:
        print(f"not started: runs under {results_dir} are being trained by process(es) "
              f"{', '.join(map(str, others))} (a sweep started by hand?); start the campaign when they end")
        return 1
    make_folder(results_dir)
    with open(log, "a") as output:
        process = subprocess.Popen([*RUNNER, "--campaign", campaign, "--results-dir", str(results_dir),
                                    "--landed", str(landed.absolute()), *(["--jobs", str(jobs)] if jobs else []),
                                    *(["--commit"] if commit else [])],
                                   stdin=subprocess.DEVNULL, stdout=output, stderr=subprocess.STDOUT,
                                   start_new_session=True)
    (results_dir / PID_NAME).write_text(f"{process.pid}\n")
    print(f"campaign {campaign} started in the background: pid {process.pid}, log {log} "
          f"(stop it with: kill -- -{process.pid})")
    return 0


def run(campaign: str, results_dir: Path, landed: Path = DEFAULT_INTO, jobs: int | None = None,
        commit: bool = False) -> int:
    """Run the campaign in this process: reuse the complete runs landed in ``landed``, then train
    the rest ``jobs`` at a time (:func:`train_runs`; None: one per core); with ``commit``, land
    each run in ``landed`` and commit it the moment it completes (:func:`land_and_commit`).
    Exit 1 if any run failed."""
    stages = load_campaign(campaign)
    pid = campaign_pid(results_dir)
    if pid and pid != os.getpid():
        print(f"campaign already running for {results_dir} (pid {pid})")
        return 0
    make_folder(results_dir)
    (results_dir / PID_NAME).write_text(f"{os.getpid()}\n")
    try:
        plan = plan_runs(stages, results_dir)
        reused = reuse_landed(plan, results_dir, landed)
        if reused:
            _say(f"{len(reused)} complete run(s) landed in {landed} reused, not trained again: "
                 + ", ".join(str(run.relative) for run in reused))
        completed = partial(land_and_commit, results_dir=results_dir, into=landed.absolute()) if commit else None
        failed = train_runs(plan, stages, results_dir, jobs or available_cores(), completed)
    except KeyboardInterrupt:
        _say("interrupted; finished runs and epochs are kept: hersd-campaign start resumes the campaign")
        return 130
    finally:
        if _pid_file(results_dir) == os.getpid():
            (results_dir / PID_NAME).unlink()
    _say(f"campaign {campaign} finished" + (f"; failed: {', '.join(failed)} (hersd-campaign start retries them)"
                                            if failed else ": every stage done"))
    return 1 if failed else 0


def train_runs(plan: list[PlannedRun], stages: list[Stage], results_dir: Path, jobs: int,
               completed: Callable[[PlannedRun], None] | None = None) -> list[str]:
    """Train every planned run that is not complete, ``jobs`` at a time in plan order, each on
    ``cores // jobs`` threads: a run starts as soon as one ends, so a stage's last runs share the
    machine with the next stage's first. Each run is the one-run sweep ``hersd-sweep <its
    overrides>``, the command line its stage's sweep gives it, so its log records the same
    command and the run store resumes or skips it as that sweep would. ``completed`` is called
    with each run whose log is complete when its sweep ends. -> the failed runs' dirs, in plan order."""
    threads = max(1, available_cores() // jobs)
    waiting = deque(run for run in plan if run_state(results_dir / run.relative) != "complete")
    _say(f"{len(plan)} planned runs: {len(plan) - len(waiting)} complete, {len(waiting)} to train, "
         f"{jobs} at a time")
    sweeps_dir = results_dir / ".sweeps" / time.strftime("%Y%m%d-%H%M%S")
    training: dict[subprocess.Popen, PlannedRun] = {}
    failed: set[Path] = set()
    stage_said = 0
    try:
        while waiting or training:
            while waiting and len(training) < jobs:
                planned = waiting.popleft()
                if planned.stage != stage_said:
                    stage_said = planned.stage
                    _say(f"stage {planned.stage}/{len(stages)}: {stages[planned.stage - 1].name}")
                command = with_threads(list(planned.overrides), threads)
                _say(f"training {planned.relative}: hersd-sweep {shlex.join(command)}")
                # its own sweep folder: runs started in the same second must not share Hydra's
                sweep_dir = f"hydra.sweep.dir={sweeps_dir / planned.relative}"
                training[subprocess.Popen([*SWEEP, *command, sweep_dir], stdin=subprocess.DEVNULL)] = planned
            time.sleep(POLL_SECONDS)
            for process in [process for process in training if process.poll() is not None]:
                ended = training.pop(process)
                if process.returncode:
                    failed.add(ended.relative)
                    _say(f"failed: {ended.relative} (hersd-sweep exit {process.returncode}; see above)")
                elif completed and progress(results_dir / ended.relative / LOG_NAME, ended.epochs) == "complete":
                    completed(ended)
    except KeyboardInterrupt:  # Ctrl-C reaches the runs too (one process group): let them save and end
        for process in training:
            try:
                process.wait(timeout=STOP_SECONDS)
            except subprocess.TimeoutExpired:
                process.terminate()
                process.wait()
        raise
    return [str(run.relative) for run in plan if run.relative in failed]


def land_and_commit(run: PlannedRun, results_dir: Path, into: Path) -> None:
    """Copy a run that has just completed into ``into`` (:func:`copy_run`) and commit the files
    written or removed with git, and only those (whatever else is staged stays staged); a folder
    outside a git work tree or a failed git command leaves them landed, uncommitted, and says so."""
    written, removed = copy_run(results_dir / run.relative, into / run.relative)
    paths = [str(path) for path in written + removed]
    if not paths:
        return
    message = f"campaign: {run.relative} complete ({run.epochs} epochs), landed by hersd-campaign"
    for step in (["git", "add", "--", *paths], ["git", "commit", "--quiet", "--only", "-m", message, "--", *paths]):
        done = subprocess.run(step, cwd=into, stdin=subprocess.DEVNULL, capture_output=True, text=True)
        if done.returncode:
            cause = (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
            _say(f"landed {run.relative} in {into}, not committed (git {step[1]}: {cause}); "
                 f"commit it with: git add -- {shlex.join(paths)} && git commit")
            return
    _say(f"landed {run.relative} in {into} and committed it: {message}")


def reuse_landed(plan: list[PlannedRun], results_dir: Path, landed: Path) -> list[PlannedRun]:
    """Copy into ``results_dir`` the log and animations of each planned run that is new there
    (no log, no checkpoint) and complete in ``landed`` (:func:`complete_records`). Returns the runs copied."""
    reused = []
    for run in plan:
        source, target = landed / run.relative, results_dir / run.relative
        if (target / LOG_NAME).exists() or run_state(target) != "new" or not (source / LOG_NAME).exists():
            continue
        try:
            complete_records(source / LOG_NAME, run)
        except RejectedLog:
            continue
        copy_run(source, target)
        reused.append(run)
    return reused


class RejectedLog(Exception):
    """A log that is not a complete log of the planned run; the message says why."""


def complete_records(log: Path, run: PlannedRun) -> RunRecords:
    """``log``'s records if it is a complete log of ``run``: readable, its complete marker, the
    plan's number of epochs and a config whose hash is the planned run's; else RejectedLog."""
    try:
        records = read_records(log)
    except RunLogError as err:
        raise RejectedLog(f"unreadable ({str(err).removeprefix(f'{log}: ')})") from None
    if not records.complete:
        raise RejectedLog(f"not complete (epoch {len(records.records)} of {run.epochs})")
    if len(records.records) != run.epochs:
        raise RejectedLog(f"{len(records.records)} epochs, the plan has {run.epochs}")
    logged, planned = config_hash(records.meta["config"]), config_hash(run.config)
    if logged != planned:
        raise RejectedLog(f"its config is not the plan's (hash {logged}, the plan's {planned})")
    return records


def copy_run(source: Path, target: Path) -> tuple[list[Path], list[Path]]:
    """Copy a run directory's log and policy animations (never a checkpoint) from ``source`` to
    ``target`` (:func:`copy_atomically`), and remove the animations of ``target`` that ``source``
    lacks (drawn by an earlier attempt at the run, which restarted). Returns (files written, those
    that changed; files removed)."""
    animations = policy_animations(source)
    written = [target / path.relative_to(source) for path in [source / LOG_NAME, *animations.values()]
               if copy_atomically(path, target / path.relative_to(source))]
    removed = [path for epoch, path in policy_animations(target).items() if epoch not in animations]
    for path in removed:
        path.unlink()
    return written, removed


def import_logs(campaign: str, source: Path, into: Path) -> int:
    """Take in the logs of this campaign made on another machine: each ``run.mcap`` below ``source``
    whose folder is a planned run's (``.../push/her/<arm>/seed<N>-<hash>``) and which is a complete
    log of it (:func:`complete_records`), made by ``hersd-sweep`` or ``hersd-train``, is copied with
    its animations to the same path below ``into``, unless a complete log of the run is there
    already. Prints one line per log found: imported with its provenance, or why not."""
    if not source.is_dir():
        raise CampaignError(f"no folder {source}; pass the folder holding the other machine's logs")
    plan = plan_runs(load_campaign(campaign), Path("/campaign"))
    logs = sorted(source.rglob(LOG_NAME))
    imported, gone = [], []
    for log in logs:
        run = next((run for run in plan if log.parent.as_posix().endswith("/" + run.relative.as_posix())), None)
        try:
            if run is None:
                raise RejectedLog(f"not a run of campaign {campaign} (its folder names no planned run)")
            meta = complete_records(log, run).meta
            command = str(meta.get("command") or "")
            if command.split(" ", 1)[0] not in PROJECT_COMMANDS:
                raise RejectedLog(f"not made by {' or '.join(PROJECT_COMMANDS)} (command {command!r})")
            target = into / run.relative
            if progress(target / LOG_NAME, run.epochs) == "complete" \
                    and (target / LOG_NAME).read_bytes() != log.read_bytes():
                raise RejectedLog(f"kept {target / LOG_NAME}, a complete log of the run already there")
        except RejectedLog as reason:
            print(f"rejected  {log}: {reason}")
            continue
        written, removed = copy_run(log.parent, target)
        imported += written
        gone += removed
        machine = meta.get("machine") or {}
        print(f"{'imported' if written else 'unchanged':<9} {target / LOG_NAME}  from {log}: "
              f"made on {machine.get('cpu_model', 'an unrecorded CPU')} ({machine.get('cpu_cores', '?')} cores), "
              f"commit {meta.get('git_commit')}, started {meta.get('start_time')}: {command}")
    print(f"{len(logs)} log(s) found in {source}; {len(imported)} file(s) written to {into}"
          + (f", {len(gone)} removed" if gone else "") + _git_add(imported + gone))
    return 0


def _say(line: str) -> None:
    print(f"[{time.strftime('%Y-%m-%d %H:%M:%S')}] hersd-campaign: {line}", flush=True)


def make_folder(folder: Path) -> None:
    """Create ``folder`` (CampaignError when it cannot be created or written)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CampaignError(f"cannot create {folder} ({err.strerror}); pass --results-dir <a writable folder>") from None
    if not os.access(folder, os.W_OK):
        raise CampaignError(f"cannot write to {folder}; pass --results-dir <a writable folder>")


# --------------------------------------------------------------------------- command line
class _OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line on stderr, exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _positive(text: str) -> int:
    """An argparse type: an integer >= 1."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return int(text)


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = _OneLineParser(prog="hersd-campaign", description="A campaign of sweeps as one resumable command.")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_OneLineParser,
                                     metavar="{start,status,land,import,run}")
    for name, text in (("start", "start or resume the campaign in the background"),
                       ("status", "one line per planned run: complete, epoch N of K, or new"),
                       ("land", "copy every planned run's run.mcap and animations into the results folder"),
                       ("import", "check the campaign's logs made on another machine and copy those that "
                                  "pass into the results folder"),
                       ("run", "run the campaign in the foreground (what start runs)")):
        command = commands.add_parser(name, help=text, description=text)
        command.add_argument("--campaign", default=DEFAULT_CAMPAIGN, help=f"conf/campaign/<name>.yaml "
                             f"(default {DEFAULT_CAMPAIGN})")
        if name != "import":
            command.add_argument("--results-dir", type=Path, default=DEFAULT_RESULTS_DIR,
                                 help=f"where the runs are written (default {DEFAULT_RESULTS_DIR})")
        if name == "import":
            command.add_argument("source", nargs="?", type=Path, default=DEFAULT_SOURCE,
                                 help=f"the folder holding them, searched recursively (default {DEFAULT_SOURCE})")
        if name in ("land", "import"):
            command.add_argument("--into", type=Path, default=DEFAULT_INTO,
                                 help="the folder mirroring the results dir (default: results, the repository's)")
        if name in ("start", "run"):
            command.add_argument("--landed", type=Path, default=DEFAULT_INTO,
                                 help="complete runs landed here are copied in, not trained again "
                                      "(default: results, the repository's)")
            command.add_argument("--commit", action="store_true",
                                 help="land each run in the --landed folder the moment it completes and commit "
                                      "its log and animations there with git (those files only)")
            command.add_argument("--jobs", type=_positive, default=None,
                                 help="runs trained at once (default: one per core), each on cores/N "
                                      "threads; --jobs 1 trains one run at a time on every core")
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse(argv)
    try:
        if args.command == "import":
            return import_logs(args.campaign, args.source, args.into)
        results_dir = args.results_dir.expanduser().absolute()
        if args.command == "land":
            return land(args.campaign, results_dir, args.into)
        if args.command == "status":
            return status(args.campaign, results_dir)
        return {"start": start, "run": run}[args.command](args.campaign, results_dir, args.landed, args.jobs,
                                                          args.commit)
    except CampaignError as err:
        print(f"hersd-campaign: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader left (`hersd-campaign status | head`): stop quietly, as cat does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 141


if __name__ == "__main__":
    sys.exit(main())
