"""``hersd-search``, the command (its entry point ``sweeps.search:main`` calls :func:`main`): compose the search
and training configs, open the study, re-enqueue lost trials, run or submit the workers, and
print the outcome with the ``hersd-report`` command that draws the study (the search never
imports the analysis: data flows search -> storage -> report).

Exit codes: 0 done (or jobs submitted), 1 a worker process died or every trial of the command failed
(the first error named), 2 bad input (one line on stderr, before any work) or a run the training layer
refused, 130 interrupted.
"""

from __future__ import annotations

import shlex
import sys
import time
from pathlib import Path
from typing import NoReturn

import optuna
from optuna.storages import BaseStorage
from optuna.trial import TrialState

from hersd.contract.errors import ConfigError, sigterm_as_ctrl_c
from hersd.contract.study import found_by_report, shown, storage_file
from hersd.engine.resources import check_machine
from sweeps.search.storage import open_storage
from sweeps.search.config import compose_search
from sweeps.search.plan import SearchPlan, make_plan
from sweeps.search.study import (POLL_SECONDS, count_finished, first_error, live_running, open_study,
                                 requeue_lost_trials, trial_counts)
from sweeps.search.workers import check_slurm, run_local, split_trials, submit_slurm

USAGE = """usage: hersd-search [search=NAME] [search.KEY=VALUE ...] [TRAINING OVERRIDES ...]

Optuna search of the relabel-rate schedule: (beta1, beta2) by default; any kind's searched settings,
a class of your own's too (search.space.kinds=[my_pkg.steps.Step]); optionally lambda_h.
Each trial trains one run per seed through the run store; re-running the same command
resumes the study. search.* settings: SearchConfig in sweeps/search/config.py, conf/search/*.yaml;
every other override goes to the training config as for hersd-train (task=reach epochs=50 ...).

  search=default|wide|ci        search.n_trials=50  search.n_jobs=1  search.seeds=1   (the defaults)
  search.objective=auc|final    search.pruner.kind=median|hyperband|none
  search.space.beta2.low=-1     search.storage=journal:/shared/hersd/study.log
  search.space.ranges.k0={low: 1, high: 50}   (any searched setting's range)
  search.launcher=slurm         search.slurm.partition=<name>

The study's figures and tables: hersd-report <results_dir> (printed at the end of each search).
"""
REPORT_REMOVED = ("--report was removed: hersd-search no longer draws figures; draw the study with "
                  "hersd-report <results_dir> (plus --storage <URL> for a search.storage outside "
                  "<results_dir>/search), the command every search prints at its end")


def _fail(message: str, code: int = 2) -> NoReturn:
    """One error line on stderr, then exit with ``code``."""
    print(f"hersd-search: error: {message}", file=sys.stderr)
    sys.exit(code)


def split_overrides(argv: list[str]) -> tuple[str, list[str], list[str]]:
    """Command-line arguments -> (search file name, ``search.*`` overrides, training overrides)."""
    search_overrides, train_overrides = [], []
    search_name = "default"
    for arg in argv:
        key = arg.split("=", 1)[0].lstrip("+")
        if key == "search":
            search_name = arg.split("=", 1)[1] if "=" in arg else ""
        elif key.startswith("search."):
            search_overrides.append(arg)
        elif arg.startswith("-"):
            raise ConfigError(REPORT_REMOVED if arg == "--report" else f"unknown option {arg}; see hersd-search --help")
        else:
            train_overrides.append(arg)
    return search_name, search_overrides, train_overrides


def start(argv: list[str]) -> tuple[SearchPlan, BaseStorage, optuna.Study]:
    """Parse, compose, plan, open the storage and the study; ConfigError (one line) on bad input."""
    search_name, search_overrides, train_overrides = split_overrides(argv)
    plan = make_plan(compose_search(search_name, search_overrides), train_overrides, search_name)
    if plan.search.launcher == "slurm":
        check_slurm(plan.search.slurm)
    else:  # its runs train here: refuse now what this machine cannot run, before any trial is made
        check_machine(plan.base.device, plan.base.precision)
    storage = open_storage(plan.storage)
    return plan, storage, open_study(plan, storage)


def launch(plan: SearchPlan, storage: BaseStorage, study: optuna.Study) -> list[int] | None:
    """Re-enqueue lost trials, then run the local workers (-> exit codes) or submit SLURM jobs (-> None)."""
    requeued = requeue_lost_trials(study, storage, plan.search.stale_after_minutes * 60)
    if requeued:
        print(f"re-enqueued the parameters of lost trials {requeued}", flush=True)
    finished = count_finished(study)
    remaining = plan.search.n_trials - finished
    if remaining <= 0:
        print(f"the study already holds {finished} complete or pruned trials (search.n_trials="
              f"{plan.search.n_trials}); nothing to run", flush=True)
        return []
    shares = split_trials(remaining, plan.search.n_jobs)
    print(f"{finished} of {plan.search.n_trials} trials finished; running {remaining} on "
          f"{len(shares)} {plan.search.launcher} worker(s)", flush=True)
    if plan.search.launcher == "slurm":
        job_ids = submit_slurm(plan, shares)
        print(f"submitted SLURM jobs {', '.join(job_ids)}; logs in {plan.study_dir}/slurm. Once they end, draw "
              f"the study with: {report_command(plan.base.results_dir, plan.storage)} (re-run this command to "
              f"resume a search cut short)")
        return None
    codes = run_local(plan, shares)
    await_other_workers(plan, study)
    return codes


def await_other_workers(plan: SearchPlan, study: optuna.Study) -> None:
    """Wait for the trials other commands' workers run while the study holds fewer than search.n_trials finished
    ones: commands joined on one study then end on one count."""
    stale_after_seconds = plan.search.stale_after_minutes * 60
    running = live_running(study, stale_after_seconds)
    if not running or count_finished(study) >= plan.search.n_trials:
        return
    print(f"waiting for trial(s) {', '.join(map(str, running))}, run by other workers on this study", flush=True)
    while running and count_finished(study) < plan.search.n_trials:
        time.sleep(POLL_SECONDS)
        running = live_running(study, stale_after_seconds)


def report_command(results_dir: str, spec: str) -> str:
    """The ``hersd-report`` command that draws the runs of ``results_dir`` and the studies of storage ``spec``
    (``--storage`` only when the report would not find the storage itself)."""
    command = ["hersd-report", str(Path(results_dir).resolve())]
    if not found_by_report(results_dir, spec):
        command += ["--storage", shown(spec)]  # a password shows as ***: libpq also reads PGPASSWORD
    return shlex.join(command)


def summarise(plan: SearchPlan, storage: BaseStorage, earlier: set[int]) -> str | None:
    """Print the trial counts, the best trial, and the commands that show the study -> the first error if every
    trial but the ``earlier`` ones (this command's: those it ran, the sets it enqueued among them) failed."""
    study = optuna.load_study(study_name=plan.study_name, storage=storage)
    counts = trial_counts(study)
    print(f"trials: {', '.join(f'{n} {state}' for state, n in counts.items() if n or state != 'skipped')}")
    if counts["complete"]:
        best = study.best_trial
        print(f"best: trial {best.number}, value {best.value:.4f}, params {best.params}")
    print(f"figures and tables: {report_command(plan.base.results_dir, plan.storage)}")
    target = shown(plan.storage) if "://" in plan.storage else str(storage_file(plan.storage))  # URL or journal
    print(f"dashboard: pip install optuna-dashboard; optuna-dashboard {shlex.quote(target)}")
    return first_error(study, earlier)


@sigterm_as_ctrl_c()  # ``kill PID`` too: one line, exit 130, each trial recorded as interrupted
def main(argv: list[str] | None = None) -> None:
    """``hersd-search [search=NAME] [search.KEY=VALUE ...] [TRAINING OVERRIDES ...]``."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if any(arg in ("-h", "--help") for arg in argv):
        print(USAGE)
        return
    try:
        plan, storage, study = start(argv)
        print(f"study {plan.study_name} in {shown(plan.storage)}", flush=True)
        earlier = {trial.number for trial in study.get_trials(deepcopy=False) if trial.state != TrialState.WAITING}
        worker_codes = launch(plan, storage, study)
    except ConfigError as err:
        _fail(str(err))
    except KeyboardInterrupt:
        print("hersd-search: interrupted; re-run the same command to resume", file=sys.stderr)
        sys.exit(130)
    if worker_codes is None:  # SLURM jobs submitted
        return
    error = summarise(plan, storage, earlier)
    failed = [code for code in worker_codes if code != 0]
    if 2 in failed:
        _fail("a worker stopped because a run was refused (the line above); fix the input and re-run")
    if error is not None:
        _fail(f"every trial of this search failed; the first, {error}", code=1)
    if failed:
        _fail(f"{len(failed)} worker(s) exited abnormally (codes {failed}); re-run the same command to resume",
              code=1)
