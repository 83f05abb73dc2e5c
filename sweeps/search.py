"""``hersd-search``: an Optuna search of the relabel-rate schedule over the ordinary run store.

``hersd-search search=default task=reach epochs=50 search.n_trials=40 search.n_jobs=2``
composes ``conf/search/<name>.yaml`` (the ``search.*`` overrides) and the training config
(every other override, as for ``hersd-train``), then has Optuna choose beta1, beta2 (and
optionally lambda_h and the schedule kind) for each trial. A trial trains one run per seed,
one after the other, through :func:`hersd.train.train`, so its runs are ordinary runs in
``results/<task>/...`` (skipped when complete, resumed from their checkpoint when not) and
``hersd-report`` sees them. After every epoch the trial reports the running objective (the
mean over seeds of the AUC, i.e. mean over epochs, or the final value of ``search.metric``)
at a step index that keeps increasing across seeds, so a median or Hyperband pruner can stop
it early; a NaN objective prunes the trial and a crashed run fails it, and the study goes on.

The study lives in SQLite under ``results/search/<study>.db`` unless ``search.storage`` names
any SQLAlchemy URL or ``journal:/shared/path/file.log``. ``search.n_jobs`` worker processes
share it, each running Optuna's loop until the study holds ``search.n_trials`` complete or
pruned trials. Re-running the same command resumes the study: trials left RUNNING by a dead
worker (same host and its process gone, or no heartbeat for ``search.stale_after_minutes``)
and trials stopped by Ctrl-C are marked failed and their parameters re-enqueued, and since
their runs resume from checkpoints, the repeated trial continues where the lost one stopped.
``search.launcher=slurm`` submits the workers through submitit instead (docs/SEARCH.md).
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import multiprocessing
import os
import socket
import sys
import threading
import time
import warnings
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Optional

import numpy as np
import optuna
from omegaconf import OmegaConf
from optuna.exceptions import ExperimentalWarning, UpdateFinishedTrialError
from optuna.storages import BaseStorage, JournalStorage, RDBStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import TrialState

from hersd.config import SCHEDULE_KINDS, ConfigError, ScheduleConfig
from hersd.runlog import EPOCH_FIELDS, LOG_NAME, OPTIONAL_EPOCH_FIELDS, read_run
from hersd.runstore import config_hash, run_dir
from hersd.compose import compose, compose_train, explain_config_error, group_options, register_schema as store_schema
from hersd.schedules import schedule_mean_rates

JOURNAL_PREFIX = "journal:"
SQLITE_TIMEOUT_SECONDS = 60  # how long a writer waits for SQLite's lock before failing
FINISHED_STATES = (TrialState.COMPLETE, TrialState.PRUNED)  # what search.n_trials counts
OBJECTIVES = ("auc", "final")
PRUNERS = ("median", "hyperband", "none")
LAUNCHERS = ("local", "slurm")
METRICS = tuple(name for name, (kind, _) in EPOCH_FIELDS.items()
                if kind == "number" and name not in OPTIONAL_EPOCH_FIELDS)
PARAM_NAMES = ("kind", "beta1", "beta2", "eps", "lambda_h")
SLURM_PRESET = ("hydra", "launcher", "slurm.yaml")  # hersd-sweep's SLURM settings, inside the hersd.conf package
SLURM_FALLBACK = {"partition": None, "timeout_min": 240, "cpus_per_task": 1, "mem_gb": 8}


# --------------------------------------------------------------------------- configuration
@dataclass
class Bounds:
    low: float  # smallest value tried
    high: float  # largest value tried
    log: bool = False  # sample on a log scale (needs low > 0)


@dataclass
class SpaceConfig:
    kinds: list[str] = field(default_factory=lambda: ["exponential"])  # schedule kinds searched (a categorical if > 1)
    beta1: Bounds = field(default_factory=lambda: Bounds(0.0, 1.0))  # eq. 9 final drop, within [0, 1]
    beta2: Bounds = field(default_factory=lambda: Bounds(-2.0, 2.0))  # eq. 9 shape (exponential kind only)
    eps: Bounds = field(default_factory=lambda: Bounds(0.5, 1.0))  # fixed rate (constant kind only)
    lambda_h: Optional[Bounds] = None  # hindsight reward weight (eq. 8); null keeps the algo's


@dataclass
class SamplerConfig:
    seed: int = 0  # TPE seed; each worker's is derived from it, its index and the study's size
    n_startup_trials: int = 10  # random trials before TPE models the results
    multivariate: bool = True  # model beta1 and beta2 jointly (they trade off along mu_eps iso-lines)


@dataclass
class PrunerConfig:
    kind: str = "median"  # median | hyperband | none
    n_startup_trials: int = 5  # median: finished trials before any pruning
    n_warmup_steps: int = 5  # median: steps (epochs) a trial always runs
    min_resource: int = 5  # hyperband: steps every trial runs
    reduction_factor: int = 3  # hyperband: 1/reduction_factor of the trials go on at each rung


@dataclass
class SlurmConfig:
    # null takes the value of conf/hydra/launcher/slurm.yaml (hersd-sweep's preset) if it exists.
    partition: Optional[str] = None  # SLURM partition
    timeout_min: Optional[int] = None  # minutes per worker job; a worker runs many trials
    cpus_per_task: Optional[int] = None  # CPUs per worker job (training uses one thread)
    mem_gb: Optional[int] = None  # memory per worker job


@dataclass
class SearchConfig:
    study_name: Optional[str] = None  # null: <task>-<algo>-<search file>-<hash of what the objective depends on>
    storage: Optional[str] = None  # null: sqlite under <results_dir>/search; or a SQLAlchemy URL, or journal:<path>
    n_trials: int = 50  # complete + pruned trials the study should hold
    n_jobs: int = 1  # worker processes (local) or SLURM jobs sharing the study
    launcher: str = "local"  # local | slurm
    seeds: int = 1  # runs per trial, seeds first_seed .. first_seed + seeds - 1, trained one after another
    first_seed: int = 0
    objective: str = "auc"  # auc: mean of the metric over epochs; final: its value at the last epoch
    metric: str = "test_success"  # the per-epoch field the objective is made of (maximised)
    stale_after_minutes: float = 30.0  # a RUNNING trial without a heartbeat (one per epoch) for this long is lost
    space: SpaceConfig = field(default_factory=SpaceConfig)
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    pruner: PrunerConfig = field(default_factory=PrunerConfig)
    slurm: SlurmConfig = field(default_factory=SlurmConfig)
    enqueue: list[dict[str, Any]] = field(default_factory=list)  # parameter sets tried first, when the study is created


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def validate(search: SearchConfig) -> None:
    """Raise :class:`ConfigError` (one line) on the first out-of-range setting."""
    space = search.space
    _check(bool(space.kinds) and all(kind in SCHEDULE_KINDS for kind in space.kinds),
           f"search.space.kinds must be a non-empty list of {', '.join(SCHEDULE_KINDS)}; got {list(space.kinds)}")
    named_bounds = {"beta1": space.beta1, "beta2": space.beta2, "eps": space.eps, "lambda_h": space.lambda_h}
    for name, bounds in named_bounds.items():
        if bounds is None:
            continue
        _check(np.isfinite([bounds.low, bounds.high]).all(),
               f"search.space.{name}: bounds must be finite numbers, got [{bounds.low}, {bounds.high}]")
        _check(bounds.low <= bounds.high,
               f"search.space.{name}: low ({bounds.low}) must be <= high ({bounds.high})")
        _check(not bounds.log or bounds.low > 0, f"search.space.{name}: log=true needs low > 0, got {bounds.low}")
    for name in ("beta1", "eps"):
        bounds = named_bounds[name]
        _check(0.0 <= bounds.low and bounds.high <= 1.0,
               f"search.space.{name}: bounds must lie in [0, 1], got [{bounds.low}, {bounds.high}]")
    if space.lambda_h is not None:
        _check(space.lambda_h.low > 0, f"search.space.lambda_h: low must be > 0, got {space.lambda_h.low}")
    for name in ("n_trials", "n_jobs", "seeds"):
        _check(getattr(search, name) >= 1, f"search.{name} must be >= 1, got {getattr(search, name)}")
    _check(search.first_seed >= 0, f"search.first_seed must be >= 0, got {search.first_seed}")
    _check(search.objective in OBJECTIVES,
           f"search.objective={search.objective!r} is unknown; choose one of: {', '.join(OBJECTIVES)}")
    _check(search.metric in METRICS,
           f"search.metric={search.metric!r} is not a per-epoch number; choose one of: {', '.join(METRICS)}")
    _check(search.launcher in LAUNCHERS,
           f"search.launcher={search.launcher!r} is unknown; choose one of: {', '.join(LAUNCHERS)}")
    _check(search.stale_after_minutes > 0, f"search.stale_after_minutes must be > 0, got {search.stale_after_minutes}")
    pruner = search.pruner
    _check(pruner.kind in PRUNERS,
           f"search.pruner.kind={pruner.kind!r} is unknown; choose one of: {', '.join(PRUNERS)}")
    _check(pruner.n_startup_trials >= 0 and pruner.n_warmup_steps >= 0,
           "search.pruner.n_startup_trials and n_warmup_steps must be >= 0")
    _check(pruner.min_resource >= 1 and pruner.reduction_factor >= 2,
           "search.pruner.min_resource must be >= 1 and search.pruner.reduction_factor >= 2")
    _check(search.sampler.n_startup_trials >= 0,
           f"search.sampler.n_startup_trials must be >= 0, got {search.sampler.n_startup_trials}")
    for params in search.enqueue:
        unknown = sorted(set(params) - set(PARAM_NAMES))
        _check(not unknown, f"search.enqueue: unknown parameter(s) {unknown}; use {', '.join(PARAM_NAMES)}")
        _check(params.get("kind", space.kinds[0]) in space.kinds,
               f"search.enqueue: kind={params.get('kind')!r} is not among search.space.kinds {list(space.kinds)}")
    if search.storage is not None:
        storage_location(search.storage)


def register_schema() -> None:
    """Register :class:`SearchConfig` as ``search/search_schema``, which every ``conf/search`` file
    lists first in its defaults: files then hold only their differences, and unknown keys or
    wrong types fail at composition."""
    store_schema("search_schema", SearchConfig, group="search")


def compose_search(overrides: list[str]) -> SearchConfig:
    """``conf/search/<name>.yaml`` + ``search.*`` overrides -> validated :class:`SearchConfig`.

    ``overrides`` are Hydra overrides with the group selected as ``+search=<name>``.
    """
    from hydra.errors import HydraException, MissingConfigException
    from omegaconf.errors import ConfigAttributeError, ConfigKeyError, ValidationError

    register_schema()
    try:
        composed = compose(None, overrides, job_name="hersd-search")
    except MissingConfigException as err:
        choices = group_options("search")
        name = (err.missing_cfg_file or "").partition("/")[2] or "?"
        raise ConfigError(f"search={name} is not a known search; choose one of: {', '.join(choices)}") from None
    except HydraException as err:
        cause = err.__cause__ if err.__cause__ is not None else err
        key = getattr(cause, "full_key", None)
        if isinstance(cause, (ConfigAttributeError, ConfigKeyError)) and key:
            raise ConfigError(f"{key} is not a search setting; see conf/search/default.yaml") from None
        if isinstance(cause, ValidationError) and key:
            raise ConfigError(f"{key}: {str(cause).splitlines()[0]}") from None
        raise ConfigError(explain_config_error(err)) from None
    search = OmegaConf.to_object(composed.search)
    validate(search)
    return search


# --------------------------------------------------------------------------- storage
def storage_location(spec: str) -> tuple[str, str]:
    """A storage spec -> ("rdb", SQLAlchemy URL) or ("journal", file path).

    ``journal:<path>`` is a journal file; ``<scheme>://...`` a SQLAlchemy URL; a plain path
    ending in .log/.journal a journal file, any other plain path a SQLite file.
    """
    if spec.startswith(JOURNAL_PREFIX):
        path = spec[len(JOURNAL_PREFIX):]
        _check(bool(path), "search.storage=journal:<path> needs a file path after 'journal:'")
        return "journal", str(Path(path).expanduser().resolve())
    if "://" in spec:
        return "rdb", spec
    path = Path(spec).expanduser().resolve()
    if path.suffix in (".log", ".journal"):
        return "journal", str(path)
    return "rdb", f"sqlite:///{path}"


class SQLiteStorage(RDBStorage):
    """RDBStorage on a local SQLite file, with queue claims serialised by a file lock.

    Optuna pops an enqueued trial by reading it as WAITING and then setting it RUNNING; SQLite
    (through Python's sqlite3) reads outside the write transaction, so two workers popping at
    the same moment can both claim one trial, and both train it. Holding ``<db>.lock`` around
    the WAITING -> RUNNING step makes the second claimant see RUNNING and move on.
    """

    def __init__(self, path: Path) -> None:
        super().__init__(f"sqlite:///{path}", engine_kwargs={"connect_args": {"timeout": SQLITE_TIMEOUT_SECONDS}})
        self.claim_lock_path = path.with_name(path.name + ".lock")

    def set_trial_state_values(self, trial_id: int, state: TrialState, values=None) -> bool:
        if state != TrialState.RUNNING:
            return super().set_trial_state_values(trial_id, state, values)
        with open(self.claim_lock_path, "a") as lock_file:
            fcntl.flock(lock_file, fcntl.LOCK_EX)
            return super().set_trial_state_values(trial_id, state, values)


def open_storage(spec: str, create: bool = True) -> BaseStorage:
    """Open the study storage named by ``spec`` (see :func:`storage_location`).

    ``create=False`` raises FileNotFoundError instead of creating a missing SQLite or journal file.
    """
    kind, location = storage_location(spec)
    sqlite = location.startswith("sqlite:///")
    path = Path(location) if kind == "journal" else Path(location[len("sqlite:///"):]) if sqlite else None
    if path is not None:
        if not create and not path.exists():
            raise FileNotFoundError(f"{path}: no such study storage")
        path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "journal":
        return JournalStorage(JournalFileBackend(str(path)))
    if sqlite:
        return SQLiteStorage(path)
    return open_database(location)


def open_database(url: str) -> RDBStorage:
    """An RDB storage at a SQLAlchemy URL; ConfigError (one line) for an unknown scheme, a missing
    database driver or a database that cannot be reached."""
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError, OperationalError

    shown = url.split("@")[-1]  # no password in messages
    try:
        return RDBStorage(url, engine_kwargs={"pool_pre_ping": True})
    except (NoSuchModuleError, ArgumentError) as err:
        raise ConfigError(f"search.storage: {' '.join(str(err).split())[:200]}; use sqlite:///<file>, "
                          f"postgresql://..., mysql://... or journal:<file>") from None
    except ImportError as err:
        raise ConfigError(f"search.storage: the database driver is missing ({err.name or err}); for PostgreSQL "
                          f'pip install "hersd[cluster]"') from None
    except OperationalError as err:
        reason = " ".join(str(err.orig or err).split())[:200]
        raise ConfigError(f"search.storage: cannot reach the database at {shown} ({reason})") from None


# --------------------------------------------------------------------------- the plan a worker receives
@dataclass
class SearchPlan:
    """Everything a worker needs (picklable: it crosses process and SLURM boundaries)."""

    search: SearchConfig
    study_name: str
    storage: str
    train_overrides: list[str]  # the training overrides every run of every trial starts from
    settings: dict[str, Any]  # what the objective depends on; stored with the study and checked on load
    report_dir: str  # figures and tables go here; SLURM logs below it

    @property
    def epochs(self) -> int:
        return int(self.settings["epochs"])


def searched_keys(search: SearchConfig) -> tuple[str, ...]:
    """Training-config keys the search sets itself (so they may not be overridden by hand)."""
    keys = ("seed", "schedule", "schedule.kind", "schedule.beta1", "schedule.beta2", "schedule.eps")
    return keys + (("algo.lambda_h",) if search.space.lambda_h is not None else ())


def make_plan(search: SearchConfig, train_overrides: list[str], search_name: str = "default") -> SearchPlan:
    """Compose the base training config, derive the study's name, storage and settings.

    ``search_name`` (the ``conf/search`` file) is part of the default study name, so another
    search file starts another study while narrowed or widened ranges continue the same one.
    """
    taken = searched_keys(search)
    for override in train_overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        _check(key not in taken, f"{override}: {key} is chosen by the search (search.space, search.seeds); remove it")
    base = compose_train(train_overrides)
    steps = search.seeds * base.epochs
    _check(search.pruner.kind != "hyperband" or search.pruner.min_resource <= steps,
           f"search.pruner.min_resource ({search.pruner.min_resource}) exceeds the steps of a trial "
           f"(seeds x epochs = {steps})")
    neutral = replace(base, seed=0, schedule=ScheduleConfig())
    if search.space.lambda_h is not None:
        neutral = replace(neutral, algo=replace(neutral.algo, lambda_h=1.0))
    settings = {"objective": search.objective, "metric": search.metric, "seeds": search.seeds,
                "first_seed": search.first_seed, "epochs": base.epochs, "task": base.task.name,
                "algo": base.algo.name, "train_config": config_hash(neutral)}
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:8]
    study_name = search.study_name or f"{base.task.name}-{base.algo.name}-{search_name}-{digest}"
    search_dir = Path(base.results_dir).resolve() / "search"
    storage = search.storage or f"sqlite:///{search_dir / f'{study_name}.db'}"
    return SearchPlan(search=search, study_name=study_name, storage=storage,
                      train_overrides=list(train_overrides), settings=settings,
                      report_dir=str(search_dir / study_name))


# --------------------------------------------------------------------------- the study
def make_sampler(sampler: SamplerConfig, worker_index: int, trials_before: int) -> optuna.samplers.TPESampler:
    """Seeded TPE; the seed mixes in the worker and the study's size so resumed or parallel
    workers never replay the same random draws."""
    seed = int(np.random.SeedSequence([sampler.seed, worker_index, trials_before]).generate_state(1)[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        return optuna.samplers.TPESampler(seed=seed, n_startup_trials=sampler.n_startup_trials,
                                          multivariate=sampler.multivariate, group=sampler.multivariate)


def make_pruner(plan: SearchPlan) -> optuna.pruners.BasePruner:
    """Median or Hyperband pruner over the per-epoch steps (``seeds * epochs`` in all)."""
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
        study.set_user_attr("settings", plan.settings)
        study.set_user_attr("train_overrides", plan.train_overrides)
        for params in plan.search.enqueue:
            study.enqueue_trial(dict(params))
        return study
    study = optuna.load_study(study_name=plan.study_name, storage=storage)
    stored = study.user_attrs.get("settings")
    if stored is not None and stored != plan.settings:
        changed = sorted(k for k in plan.settings if stored.get(k) != plan.settings[k])
        raise ConfigError(f"study {plan.study_name!r} was made with other settings ({', '.join(changed)} differ: "
                          f"{ {k: stored.get(k) for k in changed} }); choose another search.study_name")
    return study


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


def _stale_reason(trial: optuna.trial.FrozenTrial, now: float, stale_after_seconds: float) -> str | None:
    host, _, pid = str(trial.user_attrs.get("worker", "")).rpartition(":")
    if host == socket.gethostname() and pid.isdigit() and not _pid_alive(int(pid)):
        return f"worker {host}:{pid} is gone"
    heartbeat = trial.user_attrs.get("heartbeat")
    if heartbeat is None and trial.datetime_start is not None:
        heartbeat = trial.datetime_start.timestamp()
    if heartbeat is not None and now - heartbeat > stale_after_seconds:
        return f"no heartbeat for {(now - heartbeat) / 60:.0f} min"
    return None


def requeue_lost_trials(study: optuna.Study, storage: BaseStorage, stale_after_seconds: float) -> list[int]:
    """Mark lost RUNNING trials FAIL and re-enqueue their parameters (and those of Ctrl-C'd trials).

    Runs once, in the process that starts the workers, before any starts. Each lost trial is
    re-enqueued at most once (its retry carries ``retry_of``); returns the re-enqueued numbers.
    """
    trials = study.get_trials(deepcopy=False)
    retried = {t.user_attrs["retry_of"] for t in trials if "retry_of" in t.user_attrs}
    study_id = storage.get_study_id_from_name(study.study_name)
    now = time.time()
    requeued = []
    for trial in trials:
        if trial.number in retried:
            continue
        if trial.state == TrialState.RUNNING:
            reason = _stale_reason(trial, now, stale_after_seconds)
            if reason is None:
                continue
            trial_id = storage.get_trial_id_from_study_id_trial_number(study_id, trial.number)
            try:
                storage.set_trial_user_attr(trial_id, "lost", reason)
                storage.set_trial_state_values(trial_id, TrialState.FAIL)
            except UpdateFinishedTrialError:  # it finished after all
                continue
        elif not (trial.state == TrialState.FAIL and trial.user_attrs.get("interrupted")):
            continue
        params = {**trial.system_attrs.get("fixed_params", {}), **trial.params}
        study.enqueue_trial(params, user_attrs={"retry_of": trial.number})
        requeued.append(trial.number)
    return requeued


def count_finished(study: optuna.Study) -> int:
    return len(study.get_trials(deepcopy=False, states=FINISHED_STATES))


# --------------------------------------------------------------------------- one trial
def suggest_params(trial: optuna.Trial, space: SpaceConfig) -> dict[str, Any]:
    """Draw a trial's schedule (and lambda_h) from the search space."""
    kinds = list(space.kinds)
    kind = trial.suggest_categorical("kind", kinds) if len(kinds) > 1 else kinds[0]
    params: dict[str, Any] = {"kind": kind}
    if kind == "constant":
        params["eps"] = trial.suggest_float("eps", space.eps.low, space.eps.high, log=space.eps.log)
    else:
        params["beta1"] = trial.suggest_float("beta1", space.beta1.low, space.beta1.high, log=space.beta1.log)
        if kind == "exponential":
            params["beta2"] = trial.suggest_float("beta2", space.beta2.low, space.beta2.high, log=space.beta2.log)
    if space.lambda_h is not None:
        params["lambda_h"] = trial.suggest_float("lambda_h", space.lambda_h.low, space.lambda_h.high,
                                                 log=space.lambda_h.log)
    return params


def param_overrides(params: dict[str, Any]) -> list[str]:
    """A trial's parameters as ``hersd-train`` overrides (floats written exactly)."""
    overrides = [f"schedule={params['kind']}"]
    overrides += [f"schedule.{name}={float(params[name])!r}" for name in ("eps", "beta1", "beta2") if name in params]
    if "lambda_h" in params:
        overrides.append(f"algo.lambda_h={float(params['lambda_h'])!r}")
    return overrides


def mean_rates(params: dict[str, Any], epochs: int) -> tuple[float, float]:
    """mu_eps of a trial's schedule: exact over its epochs (eq. 10) and the approximation (eq. 11)."""
    return schedule_mean_rates(params["kind"], params.get("eps"), params.get("beta1"), params.get("beta2"), epochs)


def seed_objective(values: np.ndarray, objective: str) -> float:
    """One run's objective from its per-epoch metric values so far."""
    return float(np.mean(values)) if objective == "auc" else float(values[-1])


class TrialProgress:
    """Reports a trial's running objective at step ``seed_index * epochs + epoch`` and prunes.

    The running objective is the mean over the seeds done so far and the current one's
    objective over its epochs so far. Steps a resumed run skipped are reported from its log.
    """

    def __init__(self, trial: optuna.Trial, objective: str, epochs: int) -> None:
        self.trial = trial
        self.objective = objective
        self.epochs = epochs
        self.seed_values: list[float] = []
        self.reported: set[int] = set()

    def update(self, seed_index: int, values: np.ndarray, may_prune: bool) -> None:
        """Report every unreported step up to ``len(values)`` of seed ``seed_index``; maybe prune."""
        for epoch in range(1, len(values) + 1):
            step = seed_index * self.epochs + epoch
            if step in self.reported:
                continue
            running = float(np.mean(self.seed_values + [seed_objective(values[:epoch], self.objective)]))
            if not np.isfinite(running):
                self.trial.set_user_attr("pruned_reason", f"non-finite objective at step {step}")
                raise optuna.TrialPruned(f"non-finite objective at step {step}")
            self.trial.report(running, step)
            self.reported.add(step)
        if may_prune and self.trial.should_prune():
            self.trial.set_user_attr("pruned_reason", f"pruner at step {max(self.reported)}")
            raise optuna.TrialPruned(f"pruned at step {max(self.reported)}")

    def finish_seed(self, values: np.ndarray) -> None:
        """Record a finished run's objective (a non-finite one prunes the trial)."""
        value = seed_objective(values, self.objective)
        if not np.isfinite(value):
            self.trial.set_user_attr("pruned_reason", "non-finite objective")
            raise optuna.TrialPruned("non-finite objective")
        self.seed_values.append(value)

    def value(self) -> float:
        """The trial's objective: the mean over the finished seeds."""
        return float(np.mean(self.seed_values))


def _metric_values(log_path: Path, metric: str, up_to_epoch: int | None = None) -> np.ndarray:
    epochs = read_run(log_path).epochs
    if up_to_epoch is not None:
        epochs = epochs[epochs["epoch"] <= up_to_epoch]
    return epochs[metric].to_numpy(dtype=float)


def _heartbeat(trial: optuna.Trial) -> None:
    trial.set_user_attr("heartbeat", time.time())


def objective(trial: optuna.Trial, plan: SearchPlan) -> float:
    """Train the trial's runs (one per seed, in turn) and return the mean of their objectives."""
    from hersd.train import train

    trial.set_user_attr("worker", f"{socket.gethostname()}:{os.getpid()}")
    _heartbeat(trial)
    params = suggest_params(trial, plan.search.space)
    mu_exact, mu_approx = mean_rates(params, plan.epochs)
    trial.set_user_attr("mu_eps", mu_exact)
    trial.set_user_attr("mu_eps_approx", mu_approx)
    search = plan.search
    progress = TrialProgress(trial, search.objective, plan.epochs)
    quiet = [] if any(o.split("=", 1)[0] == "quiet" for o in plan.train_overrides) else ["quiet=true"]
    run_dirs: list[str] = []
    try:
        for seed_index in range(search.seeds):
            overrides = [*plan.train_overrides, *param_overrides(params), f"seed={search.first_seed + seed_index}",
                         *quiet]
            cfg = compose_train(overrides)
            log_path = run_dir(cfg) / LOG_NAME
            run_dirs.append(str(run_dir(cfg)))
            trial.set_user_attr("run_dirs", run_dirs)

            def on_epoch(record: dict, seed_index: int = seed_index, log_path: Path = log_path) -> None:
                _heartbeat(trial)
                values = _metric_values(log_path, search.metric, record["epoch"])
                progress.update(seed_index, values, may_prune=record["epoch"] < plan.epochs)

            command = f"hersd-search study={plan.study_name} trial={trial.number}: hersd-train {' '.join(overrides)}"
            train(cfg, command=command, on_epoch=on_epoch)
            values = _metric_values(log_path, search.metric)
            if len(values) != plan.epochs:
                raise RuntimeError(f"{log_path} holds {len(values)} of {plan.epochs} epochs after training")
            last_seed = seed_index == search.seeds - 1
            progress.update(seed_index, values, may_prune=not last_seed)
            progress.finish_seed(values)
    except KeyboardInterrupt:
        trial.set_user_attr("interrupted", True)
        raise
    return progress.value()


# --------------------------------------------------------------------------- workers
def _exit_when_orphaned(parent_pid: int) -> None:
    """A local worker ends when the search process that started it is gone (e.g. kill -9)."""
    while os.getppid() == parent_pid:
        time.sleep(2.0)
    os._exit(1)


def run_worker(plan: SearchPlan, worker_index: int, n_trials: int, trials_before: int,
               parent_pid: int | None = None) -> None:
    """One worker: Optuna's loop on the shared study for at most ``n_trials`` trials."""
    if parent_pid is not None:
        threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), daemon=True).start()
    storage = open_storage(plan.storage)
    study = optuna.load_study(study_name=plan.study_name, storage=storage,
                              sampler=make_sampler(plan.search.sampler, worker_index, trials_before),
                              pruner=make_pruner(plan))
    stop_when_done = optuna.study.MaxTrialsCallback(plan.search.n_trials, states=FINISHED_STATES)
    try:
        study.optimize(partial(objective, plan=plan), n_trials=n_trials, catch=(Exception,),
                       callbacks=[stop_when_done])
    except KeyboardInterrupt:
        if parent_pid is None:  # in the search's own process: let main() report it
            raise
        sys.exit(130)  # a worker process: the trial is recorded as interrupted; no traceback


def split_trials(n_trials: int, n_workers: int) -> list[int]:
    """``n_trials`` shared as evenly as possible among at most ``n_workers`` workers."""
    n_workers = max(1, min(n_workers, n_trials))
    return [n_trials // n_workers + (i < n_trials % n_workers) for i in range(n_workers)]


def run_local(plan: SearchPlan, shares: list[int], trials_before: int) -> list[int]:
    """Run the workers here: in this process if one, else as spawned processes; -> exit codes."""
    if len(shares) == 1:
        run_worker(plan, 0, shares[0], trials_before)
        return [0]
    context = multiprocessing.get_context("spawn")  # no fork: torch, MuJoCo and open DB connections
    workers = [context.Process(target=run_worker, name=f"hersd-search-{i}",
                               args=(plan, i, share, trials_before, os.getpid()))
               for i, share in enumerate(shares)]
    for worker in workers:
        worker.start()
    try:
        for worker in workers:
            worker.join()
    except KeyboardInterrupt:  # the workers got the same SIGINT: let them record it
        for worker in workers:
            worker.join()
        raise
    return [worker.exitcode for worker in workers]


def slurm_settings(slurm: SlurmConfig) -> dict[str, Any]:
    """Partition, time, CPUs and memory per worker job: ``search.slurm`` over hersd-sweep's preset."""
    from importlib.resources import files

    settings = dict(SLURM_FALLBACK)
    preset = files("hersd.conf").joinpath(*SLURM_PRESET)
    if preset.is_file():
        loaded = OmegaConf.to_container(OmegaConf.create(preset.read_text()))
        settings.update({key: loaded[key] for key in SLURM_FALLBACK if key in loaded})
    settings.update({key: value for key, value in asdict(slurm).items() if value is not None})
    return settings


def submit_slurm(plan: SearchPlan, shares: list[int], trials_before: int) -> list[str]:
    """Submit one SLURM job per worker through submitit; -> job ids."""
    import submitit

    settings = slurm_settings(plan.search.slurm)
    try:
        executor = submitit.AutoExecutor(folder=Path(plan.report_dir) / "slurm" / "%j", cluster="slurm")
    except RuntimeError as err:  # no SLURM here
        raise ConfigError(f"search.launcher=slurm: {err}") from None
    executor.update_parameters(name=f"hersd-search-{plan.study_name}", timeout_min=settings["timeout_min"],
                               cpus_per_task=settings["cpus_per_task"], mem_gb=settings["mem_gb"],
                               **({"slurm_partition": settings["partition"]} if settings["partition"] else {}))
    n = len(shares)
    jobs = executor.map_array(run_worker, [plan] * n, list(range(n)), shares, [trials_before] * n)
    return [job.job_id for job in jobs]


# --------------------------------------------------------------------------- command line
USAGE = """usage: hersd-search [--report] [search=NAME] [search.KEY=VALUE ...] [TRAINING OVERRIDES ...]

Optuna search of the relabel-rate schedule (beta1, beta2; optionally lambda_h and the kind).
Each trial trains one run per seed through the run store; re-running the same command
resumes the study. search.* settings: conf/search/default.yaml and sweeps/search.py; every
other override goes to the training config as for hersd-train (task=reach epochs=50 ...).

  search=default|wide|ci        search.n_trials=50  search.n_jobs=2  search.seeds=3
  search.objective=auc|final    search.pruner.kind=median|hyperband|none
  search.space.beta2.low=-1     search.storage=journal:/shared/hersd/study.log
  search.launcher=slurm         search.slurm.partition=<name>
  --report                      only (re)draw results/search/<study>/ from the stored study
"""


def split_overrides(argv: list[str]) -> tuple[str, list[str], list[str]]:
    """Command-line overrides -> (search file name, ``search.*`` overrides, training overrides)."""
    search_overrides, train_overrides = [], []
    group = "default"
    for arg in argv:
        key = arg.split("=", 1)[0].lstrip("+")
        if key == "search":
            group = arg.split("=", 1)[1]
        elif key.startswith("search."):
            search_overrides.append(arg)
        elif arg.startswith("-"):
            raise ConfigError(f"unknown option {arg}; see hersd-search --help")
        else:
            train_overrides.append(arg)
    return group, search_overrides, train_overrides


def write_report(plan: SearchPlan) -> list[Path]:
    """Draw the study's figures and tables by running the analysis layer's command (data flows
    from the search to its storage to the analysis; the search never imports the analysis)."""
    import subprocess

    result = subprocess.run([sys.executable, "-m", "analysis.search_figures", plan.storage, plan.report_dir,
                             "--study", plan.study_name], capture_output=True, text=True)
    if result.returncode != 0:
        print(f"hersd-search: the study's figures were not drawn: {result.stderr.strip()}", file=sys.stderr)
        return []
    return [Path(line) for line in result.stdout.splitlines() if line.strip()]


def _fail(message: str) -> None:
    print(f"hersd-search: error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: list[str] | None = None) -> None:
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    argv = sys.argv[1:] if argv is None else argv
    if any(arg in ("-h", "--help") for arg in argv):
        print(USAGE)
        return
    report_only = "--report" in argv
    try:
        search_name, search_overrides, train_overrides = split_overrides([a for a in argv if a != "--report"])
        plan = make_plan(compose_search([f"+search={search_name}", *search_overrides]), train_overrides, search_name)
        storage = open_storage(plan.storage, create=not report_only)
        _check(not report_only or plan.study_name in optuna.get_all_study_names(storage),
               f"no study {plan.study_name!r} in {plan.storage}; run the search first (same command without --report)")
        study = open_study(plan, storage)
    except FileNotFoundError as err:
        _fail(f"{err}; run the search first (same command without --report)")
    except ConfigError as err:
        _fail(str(err))
    except (HydraException, OmegaConfBaseException) as err:
        _fail(explain_config_error(err))
    print(f"study {plan.study_name} in {plan.storage}", flush=True)
    worker_codes: list[int] = []
    if not report_only:
        requeued = requeue_lost_trials(study, storage, plan.search.stale_after_minutes * 60)
        if requeued:
            print(f"re-enqueued the parameters of lost trials {requeued}", flush=True)
        finished = count_finished(study)
        remaining = plan.search.n_trials - finished
        if remaining <= 0:
            print(f"the study already holds {finished} complete or pruned trials (search.n_trials="
                  f"{plan.search.n_trials}); nothing to run", flush=True)
        else:
            shares = split_trials(remaining, plan.search.n_jobs)
            trials_before = len(study.get_trials(deepcopy=False))
            print(f"{finished} of {plan.search.n_trials} trials finished; running {remaining} on "
                  f"{len(shares)} {plan.search.launcher} worker(s)", flush=True)
            if plan.search.launcher == "slurm":
                try:
                    job_ids = submit_slurm(plan, shares, trials_before)
                except ConfigError as err:
                    _fail(str(err))
                print(f"submitted SLURM jobs {', '.join(job_ids)}; logs in {plan.report_dir}/slurm. When they end, "
                      f"re-run this command with --report (or without, to resume a cut-short search)")
                return
            try:
                worker_codes = run_local(plan, shares, trials_before)
            except KeyboardInterrupt:
                print("hersd-search: interrupted; re-run the same command to resume", file=sys.stderr)
                sys.exit(130)
    paths = write_report(plan)
    study = optuna.load_study(study_name=plan.study_name, storage=storage)
    counts = {state.name.lower(): len(study.get_trials(deepcopy=False, states=(state,)))
              for state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)}
    print(f"trials: {', '.join(f'{n} {name}' for name, n in counts.items())}")
    if counts["complete"]:
        best = study.best_trial
        print(f"best: trial {best.number}, value {best.value:.4f}, params {best.params}")
    for path in paths:
        print(path)
    kind, location = storage_location(plan.storage)
    if kind == "rdb":
        print(f"dashboard: pip install optuna-dashboard; optuna-dashboard {location}")
    failed_workers = [code for code in worker_codes if code != 0]
    if failed_workers:
        print(f"hersd-search: {len(failed_workers)} worker(s) exited abnormally (codes {failed_workers}); "
              f"re-run the same command to resume", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
