"""The study in its storage: created or loaded (and checked to measure the same thing), its
sampler and pruner, and the recovery of trials lost by dead or stopped workers."""

from __future__ import annotations

import os
import socket
import time
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import optuna
from optuna.exceptions import ExperimentalWarning, UpdateFinishedTrialError
from optuna.storages import BaseStorage
from optuna.trial import FrozenTrial, TrialState

from hersd.contract.errors import ConfigError
from hersd.contract.study import RETRY_OF_ATTR, SETTINGS_ATTR, TRAIN_OVERRIDES_ATTR
from sweeps.search.config import SamplerConfig, enqueued_params
from sweeps.search.space import space_record
from sweeps.search.plan import SearchPlan

FINISHED_STATES = (TrialState.COMPLETE, TrialState.PRUNED)  # what search.n_trials counts, less skipped trials
SKIPPED_ATTR = "skipped"  # trial: pruned unrun, because another worker held its run (the same parameters): why
ERROR_ATTR = "error"  # trial: the exception that failed it, on one line (the command names the first)
SPACE_ATTR = "space"  # study: what it draws (sweeps.search.space.space_record), set when it is created


class TrialSeededTPE(optuna.samplers.TPESampler):
    """TPE whose random draws of trial n come from (sampler.seed, n): every trial number is unique in a study,
    so workers started apart (other commands, other hosts) never draw alike, and a study's draws are reproducible."""

    def __init__(self, seed: int, **settings) -> None:
        super().__init__(seed=seed, **settings)
        self.base_seed = seed

    def before_trial(self, study: optuna.Study, trial: FrozenTrial) -> None:
        seed = int(np.random.SeedSequence([self.base_seed, trial.number]).generate_state(1)[0])
        self._rng.rng.seed(seed)  # TPE's own draws and its random sampler's (the startup trials)
        self._random_sampler._rng.rng.seed(seed)
        super().before_trial(study, trial)


def make_sampler(sampler: SamplerConfig) -> optuna.samplers.TPESampler:
    """Seeded TPE, each trial's draws seeded by (sampler.seed, trial number) (:class:`TrialSeededTPE`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        return TrialSeededTPE(sampler.seed, n_startup_trials=sampler.n_startup_trials,
                              multivariate=sampler.multivariate, group=sampler.multivariate)


class StopWhenDone:
    """Optuna callback: stop the study once it holds ``n_trials`` complete or pruned trials, not counting skipped ones."""

    def __init__(self, n_trials: int) -> None:
        self.n_trials = n_trials

    def __call__(self, study: optuna.Study, trial: FrozenTrial) -> None:
        if count_finished(study) >= self.n_trials:
            study.stop()


def make_pruner(plan: SearchPlan) -> optuna.pruners.BasePruner:
    """Median or Hyperband pruner over the per-epoch steps (``seeds * epochs`` in all), or none."""
    pruner = plan.search.pruner
    if pruner.kind == "median":
        return optuna.pruners.MedianPruner(n_startup_trials=pruner.n_startup_trials,
                                           n_warmup_steps=pruner.n_warmup_steps)
    if pruner.kind == "hyperband":
        return optuna.pruners.HyperbandPruner(min_resource=pruner.min_resource,
                                              max_resource=plan.search.seeds * plan.epochs,
                                              reduction_factor=pruner.reduction_factor)
    return optuna.pruners.NopPruner()


def open_study(plan: SearchPlan, storage: BaseStorage) -> optuna.Study:
    """Create the study (enqueuing ``search.enqueue``) or load it, checking it measures the same thing."""
    if plan.study_name not in optuna.get_all_study_names(storage):
        try:
            study = optuna.create_study(storage=storage, study_name=plan.study_name, direction="maximize")
        except optuna.exceptions.DuplicatedStudyError:  # another machine created it first
            return open_study(plan, storage)
        study.set_user_attr(SETTINGS_ATTR, asdict(plan.settings))
        study.set_user_attr(SPACE_ATTR, space_record(plan.search.space))
        study.set_user_attr(TRAIN_OVERRIDES_ATTR, plan.train_overrides)
        for params in plan.search.enqueue:
            study.enqueue_trial(enqueued_params(params, list(plan.search.space.kinds)))
        return study
    study = optuna.load_study(study_name=plan.study_name, storage=storage)
    stored, settings = study.user_attrs.get(SETTINGS_ATTR), asdict(plan.settings)
    if stored is not None and stored != settings:
        changed = sorted(k for k in settings if stored.get(k) != settings[k])
        raise ConfigError(f"study {plan.study_name!r} was made with other settings ({', '.join(changed)} differ: "
                          f"{ {k: stored.get(k) for k in changed} }); choose another search.study_name")
    space = study.user_attrs.get(SPACE_ATTR)
    if space is not None and space != space_record(plan.search.space):
        raise ConfigError(f"study {plan.study_name!r} draws from another search space ({space}); choose another "
                          f"search.study_name, or the space it was made with")
    return study


def count_finished(study: optuna.Study) -> int:
    """Complete plus pruned trials, less skipped ones: what ``search.n_trials`` counts."""
    return sum(SKIPPED_ATTR not in trial.user_attrs for trial in study.get_trials(deepcopy=False, states=FINISHED_STATES))


def trial_counts(study: optuna.Study) -> dict[str, int]:
    """{"complete": n, "pruned": n, "fail": n, "skipped": n}."""
    trials = study.get_trials(deepcopy=False)
    counts = {state.name.lower(): sum(trial.state == state and SKIPPED_ATTR not in trial.user_attrs for trial in trials)
              for state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)}
    return {**counts, "skipped": sum(SKIPPED_ATTR in trial.user_attrs for trial in trials)}


def first_error(study: optuna.Study, first_trial: int) -> str | None:
    """If no trial from number ``first_trial`` on finished and some failed: the first failure (``trial n: error``)."""
    trials = [trial for trial in study.get_trials(deepcopy=False) if trial.number >= first_trial]
    failed = [trial for trial in trials if trial.state == TrialState.FAIL]
    if not failed or any(trial.state in FINISHED_STATES for trial in trials):
        return None
    reason = failed[0].user_attrs.get(ERROR_ATTR) or failed[0].user_attrs.get("refused") or "see the warnings above"
    return f"trial {failed[0].number}: {reason}"


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` of this host runs (a zombie, killed but not reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    if not Path("/proc/self/stat").exists():  # no procfs (macOS): trust the signal check
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def stale_reason(trial: FrozenTrial, now: float, stale_after_seconds: float) -> str | None:
    """Why a RUNNING trial is lost (its worker on this host is gone, or no heartbeat for too long), or None."""
    host, _, pid = str(trial.user_attrs.get("worker", "")).rpartition(":")
    if host == socket.gethostname() and pid.isdigit() and not _pid_alive(int(pid)):
        return f"worker {host}:{pid} is gone"
    heartbeat = trial.user_attrs.get("heartbeat")
    if heartbeat is None and trial.datetime_start is not None:
        heartbeat = trial.datetime_start.timestamp()
    if heartbeat is not None and now - heartbeat > stale_after_seconds:
        return f"no heartbeat for {(now - heartbeat) / 60:.0f} min"
    return None


def _mark_lost(storage: BaseStorage, study: optuna.Study, trial: FrozenTrial, reason: str) -> bool:
    """Set a RUNNING trial FAIL with user attribute ``lost``; False if it finished meanwhile."""
    study_id = storage.get_study_id_from_name(study.study_name)
    trial_id = storage.get_trial_id_from_study_id_trial_number(study_id, trial.number)
    try:
        storage.set_trial_user_attr(trial_id, "lost", reason)
        storage.set_trial_state_values(trial_id, TrialState.FAIL)
    except UpdateFinishedTrialError:
        return False
    return True


def requeue_lost_trials(study: optuna.Study, storage: BaseStorage, stale_after_seconds: float) -> list[int]:
    """Mark lost RUNNING trials FAIL, re-enqueue their (and Ctrl-C'd trials') parameters -> the trial numbers."""
    # Runs once, in the process that starts the workers, before any starts. Each lost trial is
    # re-enqueued at most once: its retry carries user attribute retry_of.
    trials = study.get_trials(deepcopy=False)
    retried = {t.user_attrs[RETRY_OF_ATTR] for t in trials if RETRY_OF_ATTR in t.user_attrs}
    now = time.time()
    requeued = []
    for trial in (t for t in trials if t.number not in retried):
        if trial.state == TrialState.RUNNING:
            reason = stale_reason(trial, now, stale_after_seconds)
            if reason is None or not _mark_lost(storage, study, trial, reason):
                continue
        elif not (trial.state == TrialState.FAIL and trial.user_attrs.get("interrupted")):
            continue
        params = {**trial.system_attrs.get("fixed_params", {}), **trial.params}
        study.enqueue_trial(params, user_attrs={RETRY_OF_ATTR: trial.number})
        requeued.append(trial.number)
    return requeued
