"""One trial: draw its schedule, train its runs (one per seed, in turn) through
:func:`hersd.engine.train.train`, and report its running objective after every epoch so that the
pruner can stop it there (a stopped run stays resumable).

The running objective is the mean over the seeds already finished plus the current seed's
objective so far, reported at step ``seed_index * epochs + epoch``; a non-finite one prunes
the trial.
"""

from __future__ import annotations

import math
import os
import shlex
import socket
import time
from typing import Any

import numpy as np
import optuna

from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.runspec import RunSpec, resolve
from hersd.contract.runstore import RunLockedError
from hersd.contract.study import (KIND_ATTR, REWARD_PARAM, RUN_DIRS_ATTR, kind_params, one_line, param_overrides,
                                  trial_config)
from sweeps.search.space import SpaceConfig, space_bounds, whole_number
from sweeps.search.plan import SearchPlan
from sweeps.search.study import ERROR_ATTR, SKIPPED_ATTR, beyond_target, enqueued_before

PRUNED_REASON_ATTR = "pruned_reason"  # trial: why it was pruned (the pruner, a non-finite objective, no schedule)


def suggest_params(trial: optuna.Trial, space: SpaceConfig) -> dict[str, Any]:
    """Draw a trial's schedule -> {"kind", then the kind's searched parameters [, "lambda_h"]: int for whole-number
    settings, else float}."""
    kinds = list(space.kinds)
    kind = trial.suggest_categorical("kind", kinds) if len(kinds) > 1 else kinds[0]
    params: dict[str, Any] = {"kind": kind}
    for name in kind_params(kind) + ((REWARD_PARAM,) if space.lambda_h is not None else ()):
        bounds = space.lambda_h if name == REWARD_PARAM else space_bounds(space, kind, name)
        if name != REWARD_PARAM and whole_number(kind, name):  # the type the schedule declares
            params[name] = trial.suggest_int(name, math.ceil(bounds.low), math.floor(bounds.high), log=bounds.log)
        else:
            params[name] = trial.suggest_float(name, bounds.low, bounds.high, log=bounds.log)
    return params


def seed_objective(values: np.ndarray, objective: str) -> float:
    """One run's objective from its per-epoch metric values so far (shape (epochs,)): mean or last."""
    return float(np.mean(values)) if objective == "auc" else float(values[-1])


def metric_value(record: dict[str, Any], metric: str) -> float:
    """One epoch's metric from its record (as training hands it over); null (or NaN) as NaN."""
    value = record[metric]
    return np.nan if value is None else float(value)


class TrialProgress:
    """Reports a trial's running objective at step ``seed_index * epochs + epoch`` and prunes.

    Steps a resumed run skipped (already in its log) are reported from the log.
    """

    def __init__(self, trial: optuna.Trial, objective: str, epochs: int) -> None:
        """Nothing reported yet; ``objective`` is auc or final, ``epochs`` is K."""
        self.trial = trial
        self.objective = objective
        self.epochs = epochs
        self.seed_values: list[float] = []
        self.epochs_reported: dict[int, int] = {}  # seed index -> its epochs 1..n reported
        self.last_step = 0

    def _prune(self, reason: str) -> None:
        """Stop the trial as pruned, recording why."""
        self.trial.set_user_attr(PRUNED_REASON_ATTR, reason)
        raise optuna.TrialPruned(reason)

    def update(self, seed_index: int, values: np.ndarray, may_prune: bool) -> None:
        """Report the unreported steps of seed ``seed_index`` up to ``len(values)`` (values: its metric
        of epochs 1..n, shape (n,)); maybe prune."""
        for epoch in range(self.epochs_reported.get(seed_index, 0) + 1, len(values) + 1):
            step = seed_index * self.epochs + epoch
            running = float(np.mean(self.seed_values + [seed_objective(values[:epoch], self.objective)]))
            if not np.isfinite(running):
                self._prune(f"non-finite objective at step {step}")
            self.trial.report(running, step)
            self.epochs_reported[seed_index], self.last_step = epoch, step
        if may_prune and self.trial.should_prune():
            self._prune(f"pruner at step {self.last_step}")

    def finish_seed(self, values: np.ndarray) -> None:
        """Record a finished run's objective (a non-finite one prunes the trial)."""
        value = seed_objective(values, self.objective)
        if not np.isfinite(value):
            self._prune("non-finite objective")
        self.seed_values.append(value)

    def value(self) -> float:
        """The trial's objective: the mean over the finished seeds."""
        return float(np.mean(self.seed_values))


def _heartbeat(trial: optuna.Trial) -> None:
    """Record that the trial's worker is alive now (user attribute ``heartbeat``, a Unix time)."""
    trial.set_user_attr("heartbeat", time.time())


def run_command(plan: SearchPlan, trial_number: int, params: dict[str, Any], cfg: TrainConfig) -> str:
    """The run's ``command`` in its log: the search's trial and the equivalent ``hersd-train`` command."""
    overrides = [*plan.train_overrides, *param_overrides(params), f"seed={cfg.seed}"]
    if plan.base.threads == "auto":
        overrides.append(f"threads={cfg.threads}")
    return f"hersd-search study={plan.study_name} trial={trial_number}: hersd-train {shlex.join(overrides)}"


def train_seed(trial: optuna.Trial, plan: SearchPlan, progress: TrialProgress, params: dict[str, Any],
               spec: RunSpec, seed_index: int) -> None:
    """Train (or resume, or find complete) one run of the trial, reporting each epoch from the record training
    hands over (a resumed or complete run's earlier epochs too, once, as training read them): the log is not read
    here; record its objective."""
    from hersd.engine.train import train  # torch and MuJoCo: only in the processes that train

    metric, epochs = plan.search.metric, plan.epochs
    values: list[float] = []  # the run's metric of epochs 1..k so far, k = the last record's epoch

    def on_logged(records: list[dict]) -> None:
        """The epochs the log already holds (a resumed or complete run), reported with the next epoch."""
        values.extend(metric_value(record, metric) for record in records)

    def on_epoch(record: dict) -> None:
        """After each logged epoch: heartbeat, report the new step(s), maybe prune."""
        _heartbeat(trial)
        values.append(metric_value(record, metric))
        progress.update(seed_index, np.array(values, dtype=float), record["epoch"] < epochs)

    train(spec, command=run_command(plan, trial.number, params, spec.config), on_epoch=on_epoch, on_logged=on_logged)
    if len(values) != epochs:
        raise RuntimeError(f"{spec.folder} holds {len(values)} of {epochs} epochs after training")
    logged = np.array(values, dtype=float)
    progress.update(seed_index, logged, may_prune=seed_index < plan.search.seeds - 1)
    progress.finish_seed(logged)


def shown_params(params: dict[str, Any]) -> str:
    """A trial's parameters for messages, numbers rounded: ``kind=my.Ramp, drop=0.97, k_step=1``."""
    return ", ".join(f"{name}={value:.6g}" if isinstance(value, float) else f"{name}={value}"
                     for name, value in params.items())


def skip_unneeded(trial: optuna.Trial, plan: SearchPlan) -> None:
    """Skip (prune unrun, user attribute ``skipped``) a trial the study does not need: a copy of a search.enqueue set
    an earlier trial tries, or one past search.n_trials counting the live trials started before it."""
    earlier = enqueued_before(trial)
    if earlier is not None:
        reason = f"trial {earlier} tries the same search.enqueue set"
    elif beyond_target(trial, plan.search.n_trials, plan.search.stale_after_minutes * 60):
        reason = f"the study holds search.n_trials={plan.search.n_trials} trials, finished or running"
    else:
        return
    trial.set_user_attr(SKIPPED_ATTR, reason)
    raise optuna.TrialPruned(f"skipped: {reason}")


def trial_runs(trial: optuna.Trial, plan: SearchPlan, params: dict[str, Any], threads: str) -> list[RunSpec]:
    """The trial's runs, one per seed, each resolved once (its config validated once); a draw that makes no valid
    schedule (a rate outside [0, 1] the start check's grid missed) prunes the trial, its reason naming the draw."""
    try:
        return [resolve(trial_config(plan.base, params, plan.search.first_seed + index, threads))
                for index in range(plan.search.seeds)]
    except ConfigError as err:
        reason = f"no schedule at {shown_params(params)}: {err}"
        trial.set_user_attr(PRUNED_REASON_ATTR, reason)
        raise optuna.TrialPruned(reason) from None


def objective(trial: optuna.Trial, plan: SearchPlan, threads: str, refusals: list[str] | None = None) -> float:
    """Train the trial's runs (one per seed, in turn, ``threads`` each) -> the mean of their objectives."""
    trial.set_user_attr("worker", f"{socket.gethostname()}:{os.getpid()}")
    _heartbeat(trial)
    skip_unneeded(trial, plan)
    params = suggest_params(trial, plan.search.space)
    trial.set_user_attr(KIND_ATTR, params["kind"])
    specs = trial_runs(trial, plan, params, threads)
    mu_exact, mu_approx = specs[0].mean_rate(), specs[0].config.schedule.limit_mean_rate()
    trial.set_user_attr("mu_eps", float("nan") if mu_exact is None else mu_exact)
    trial.set_user_attr("mu_eps_approx", float("nan") if mu_approx is None else mu_approx)
    progress = TrialProgress(trial, plan.search.objective, plan.epochs)
    run_dirs: list[str] = []
    try:
        for seed_index, spec in enumerate(specs):
            run_dirs.append(str(spec.folder))
            trial.set_user_attr(RUN_DIRS_ATTR, run_dirs)  # before training: failed and pruned trials have it too
            train_seed(trial, plan, progress, params, spec, seed_index)
    except KeyboardInterrupt:
        trial.set_user_attr("interrupted", True)
        raise
    except RunLockedError as err:  # another worker trains this run (the same parameters): not this trial's to do
        trial.set_user_attr(SKIPPED_ATTR, one_line(err))
        raise optuna.TrialPruned(f"skipped: {one_line(err)}") from None
    except ConfigError as err:  # the run layer refused the run (memory, device, a damaged checkpoint): stop
        trial.set_user_attr("refused", str(err))
        trial.study.stop()
        if refusals is not None:
            refusals.append(str(err))
        return float("nan")  # Optuna records the trial FAIL (its line dropped: sweeps.search.workers.OneLineFailures)
    except Exception as err:
        trial.set_user_attr(ERROR_ATTR, one_line(f"{type(err).__name__}: {err}"))  # the command names the first
        raise
    return progress.value()
