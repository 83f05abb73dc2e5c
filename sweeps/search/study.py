"""The study in its storage: created or loaded (and checked to measure the same thing), its
sampler and pruner, its search.enqueue sets (each tried once), the trials live workers run (so that
workers of joined commands stop at search.n_trials), and the recovery of trials lost by dead or stopped
workers."""

from __future__ import annotations

import json
import socket
import time
import warnings
from dataclasses import asdict

import numpy as np
import optuna
from optuna.exceptions import ExperimentalWarning, UpdateFinishedTrialError
from optuna.storages import BaseStorage
from optuna.trial import FrozenTrial, TrialState

from hersd.contract.errors import ConfigError
from hersd.contract.study import RETRY_OF_ATTR, SETTINGS_ATTR, TRAIN_OVERRIDES_ATTR
from hersd.contract.runstore import pid_alive
from sweeps.search.config import SamplerConfig, enqueued_params
from sweeps.search.optuna_private import fixed_params, seed_tpe
from sweeps.search.space import space_record
from sweeps.search.plan import SearchPlan

FINISHED_STATES = (TrialState.COMPLETE, TrialState.PRUNED)  # what search.n_trials counts, less skipped trials
SKIPPED_ATTR = "skipped"  # trial: pruned unrun, because another worker held its run (the same parameters): why
ERROR_ATTR = "error"  # trial: the exception that failed it, on one line (the command names the first)
ENQUEUED_ATTR = "enqueued"  # trial: the search.enqueue set it tries, as JSON (a set is tried once per study)
POLL_SECONDS = 2.0  # how often a worker waiting for other workers' trials looks at the study
SPACE_ATTR = "space"  # study: what it draws (sweeps.search.space.space_record), set when it is created


class TrialSeededTPE(optuna.samplers.TPESampler):
    """TPE whose random draws of trial n come from (sampler.seed, n): every trial number is unique in a study,
    so workers started apart (other commands, other hosts) never draw alike, and a study's draws are reproducible."""

    def __init__(self, seed: int, **settings) -> None:
        super().__init__(seed=seed, **settings)
        self.base_seed = seed

    def before_trial(self, study: optuna.Study, trial: FrozenTrial) -> None:
        seed = int(np.random.SeedSequence([self.base_seed, trial.number]).generate_state(1)[0])
        seed_tpe(self, seed)  # TPE's own draws and its random sampler's (the startup trials)
        super().before_trial(study, trial)


def make_sampler(sampler: SamplerConfig) -> optuna.samplers.TPESampler:
    """Seeded TPE, each trial's draws seeded by (sampler.seed, trial number) (:class:`TrialSeededTPE`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        return TrialSeededTPE(sampler.seed, n_startup_trials=sampler.n_startup_trials,
                              multivariate=sampler.multivariate, group=sampler.multivariate)


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
        enqueue_sets(study, plan)
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
    enqueue_sets(study, plan)
    return study


def enqueue_sets(study: optuna.Study, plan: SearchPlan) -> None:
    """Enqueue each ``search.enqueue`` set the study holds no trial of (a line names those it holds): a set is
    tried once per study, however many commands name it; two commands enqueuing one set at the same moment are
    settled when a worker takes the later copy (:func:`enqueued_before`). A set the study has no room left for
    (search.n_trials finished or taken by the sets waiting before it) is not enqueued, in one line: it would
    wait, and a later command's trials would try it instead of their own."""
    trials = study.get_trials(deepcopy=False)
    room = plan.search.n_trials - count_finished(study) - sum(trial.state == TrialState.WAITING for trial in trials)
    for index, params in enumerate(plan.search.enqueue):
        stored = enqueued_params(params, list(plan.search.space.kinds))
        key = json.dumps(stored, sort_keys=True)
        held = [trial.number for trial in trials if trial.user_attrs.get(ENQUEUED_ATTR) == key
                or all({**fixed_params(trial), **trial.params}.get(name) == value
                       for name, value in stored.items())]
        if held:
            print(f"search.enqueue[{index}] {stored}: the study holds it already (trial {held[0]}); not enqueued "
                  "again", flush=True)
        elif room <= 0:
            print(f"search.enqueue[{index}] {stored}: not enqueued, search.n_trials={plan.search.n_trials} leaves "
                  "no room for it; raise search.n_trials to try it", flush=True)
        else:
            study.enqueue_trial(stored, user_attrs={ENQUEUED_ATTR: key})
            room -= 1


def enqueued_before(trial: optuna.Trial) -> int | None:
    """The number of an earlier trial of the same ``search.enqueue`` set as ``trial``, if any."""
    key = trial.user_attrs.get(ENQUEUED_ATTR)
    if key is None:
        return None
    return next((other.number for other in trial.study.get_trials(deepcopy=False)
                 if other.number < trial.number and other.user_attrs.get(ENQUEUED_ATTR) == key), None)


def live_running(study: optuna.Study, stale_after_seconds: float) -> list[int]:
    """The numbers of RUNNING trials whose workers are alive (not lost, :func:`stale_reason`)."""
    now = time.time()
    return [trial.number for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
            if stale_reason(trial, now, stale_after_seconds) is None]


def room_for_trial(study: optuna.Study, n_trials: int, stale_after_seconds: float) -> bool:
    """Wait while the trials other workers run could bring the study to ``n_trials`` -> whether one more trial
    may start (False once the study holds ``n_trials`` complete or pruned trials)."""
    while True:
        finished = count_finished(study)
        if finished >= n_trials:
            return False
        if finished + len(live_running(study, stale_after_seconds)) < n_trials:
            return True
        time.sleep(POLL_SECONDS)


def beyond_target(trial: optuna.Trial, n_trials: int, stale_after_seconds: float) -> bool:
    """Whether the study's finished trials and the live trials numbered below ``trial`` make ``n_trials`` already
    (two workers that started a trial at one moment: the later one is not needed)."""
    running = [number for number in live_running(trial.study, stale_after_seconds) if number < trial.number]
    return count_finished(trial.study) + len(running) >= n_trials


def count_finished(study: optuna.Study) -> int:
    """Complete plus pruned trials, less skipped ones: what ``search.n_trials`` counts."""
    return sum(SKIPPED_ATTR not in trial.user_attrs for trial in study.get_trials(deepcopy=False, states=FINISHED_STATES))


def trial_counts(study: optuna.Study) -> dict[str, int]:
    """{"complete": n, "pruned": n, "fail": n, "skipped": n}."""
    trials = study.get_trials(deepcopy=False)
    counts = {state.name.lower(): sum(trial.state == state and SKIPPED_ATTR not in trial.user_attrs for trial in trials)
              for state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)}
    return {**counts, "skipped": sum(SKIPPED_ATTR in trial.user_attrs for trial in trials)}


def first_error(study: optuna.Study, earlier: set[int]) -> str | None:
    """If no trial but the ``earlier`` ones (those a command found begun) finished and some failed: the first
    failure (``trial n: error``)."""
    trials = [trial for trial in study.get_trials(deepcopy=False) if trial.number not in earlier]
    failed = [trial for trial in trials if trial.state == TrialState.FAIL]
    if not failed or any(trial.state in FINISHED_STATES for trial in trials):
        return None
    reason = failed[0].user_attrs.get(ERROR_ATTR) or failed[0].user_attrs.get("refused") or "see the warnings above"
    return f"trial {failed[0].number}: {reason}"


def stale_reason(trial: FrozenTrial, now: float, stale_after_seconds: float) -> str | None:
    """Why a RUNNING trial is lost (its worker on this host is gone, or no heartbeat for too long), or None."""
    host, _, pid = str(trial.user_attrs.get("worker", "")).rpartition(":")
    if host == socket.gethostname() and pid.isdigit() and not pid_alive(int(pid)):
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
        params = {**fixed_params(trial), **trial.params}
        study.enqueue_trial(params, user_attrs={RETRY_OF_ATTR: trial.number})
        requeued.append(trial.number)
    return requeued
