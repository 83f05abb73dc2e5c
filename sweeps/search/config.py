"""The search's own settings: the :class:`SearchConfig` schema (Hydra's ConfigStore entry
``search/search_schema``, which every ``conf/search/*.yaml`` lists first), its range checks,
and its composition from ``conf/search/<name>.yaml`` plus ``search.*`` overrides. What it draws,
``search.space``, is :mod:`sweeps.search.space`.

Every check raises :class:`hersd.contract.errors.ConfigError` with one line naming the field.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from importlib.resources import files
from typing import Any, Optional

from omegaconf import OmegaConf

from hersd.contract.checks import check
from hersd.contract.compose import (CONFIG_MODULE, compose, explain_config_error, group_options,
                                    register_schema as store_schema)
from hersd.contract.errors import ConfigError
from hersd.contract.cores import available_cores
from hersd.contract.runlog import EPOCH_FIELDS, OPTIONAL_EPOCH_FIELDS
from hersd.contract.schedules import schedule_class
from hersd.contract.study import JOURNAL_PREFIX, REWARD_PARAM, kind_params, stored_params
from sweeps.search.space import SpaceConfig, check_schedule, check_space, is_number, split_range_overrides

OBJECTIVES = ("auc", "final")
PRUNERS = ("median", "hyperband", "none")
LAUNCHERS = ("local", "slurm")
METRICS = tuple(name for name, (kind, _) in EPOCH_FIELDS.items()
                if kind == "number" and name not in OPTIONAL_EPOCH_FIELDS)
MAX_SLURM_JOBS = 10_000  # worker jobs of one search (SLURM's array limit is usually lower: sbatch says so)
STUDY_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,199}")  # it names files: <study>.db, <study>/


@dataclass
class SamplerConfig:
    """Optuna's TPE sampler."""

    seed: int = 0  # TPE seed; each trial's draws are seeded by (this seed, the trial's number)
    n_startup_trials: int = 10  # random trials before TPE models the results
    multivariate: bool = True  # model beta1 and beta2 jointly (they trade off along mu_eps iso-lines)


@dataclass
class PrunerConfig:
    """The pruner that may stop a trial after any epoch."""

    kind: str = "median"  # median | hyperband | none
    n_startup_trials: int = 5  # median: finished trials before any pruning
    n_warmup_steps: int = 5  # median: steps (epochs) a trial always runs
    min_resource: int = 5  # hyperband: steps every trial runs
    reduction_factor: int = 3  # hyperband: 1/reduction_factor of the trials go on at each rung


@dataclass
class SlurmConfig:
    """The worker jobs of search.launcher=slurm."""

    # null takes the value of hersd-sweep's preset (hydra/launcher/slurm.yaml in the hersd.conf package).
    partition: Optional[str] = None  # SLURM partition
    timeout_min: Optional[int] = None  # minutes per worker job; a worker runs many trials
    cpus_per_task: Optional[int] = None  # CPUs per worker job (its runs use them all with threads=auto)
    mem_gb: Optional[int] = None  # memory per worker job


@dataclass
class SearchConfig:
    """Every ``search.*`` setting (conf/search/*.yaml holds only what differs from these defaults)."""

    study_name: Optional[str] = None  # null: <task>-<algo>-<search file>-<hash of what the objective depends on>
    storage: Optional[str] = None  # null: sqlite under <results_dir>/search; or a SQLAlchemy URL, or journal:<path>
    n_trials: int = 50  # complete + pruned trials the study should hold
    n_jobs: int = 1  # worker processes (local, at most one per core) or SLURM jobs sharing the study
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


def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    """ConfigError naming the choices unless ``value`` is one of them."""
    check(value in choices, f"{name}={value!r} is unknown; choose one of: {', '.join(choices)}")


def check_counts(search: SearchConfig) -> None:
    """Trials, workers, seeds, staleness and the pruner's and sampler's integers in range."""
    for name in ("n_trials", "n_jobs", "seeds"):
        check(getattr(search, name) >= 1, f"search.{name} must be >= 1, got {getattr(search, name)}")
    cores = available_cores()
    check(search.launcher != "local" or search.n_jobs <= cores,
          f"search.n_jobs={search.n_jobs}: local workers are processes of this machine, which has {cores} "
          f"core(s); use search.n_jobs<={cores}, or search.launcher=slurm")
    check(search.first_seed >= 0, f"search.first_seed must be >= 0, got {search.first_seed}")
    check(search.stale_after_minutes > 0,  # NaN fails too
          f"search.stale_after_minutes must be > 0 (longer than an epoch), got {search.stale_after_minutes}")
    check(0 <= search.sampler.seed < 2**32,  # numpy's seeds, which TPE takes
          f"search.sampler.seed must be >= 0 and < 2**32 (4294967296), got {search.sampler.seed}")
    check(search.sampler.n_startup_trials >= 0,
          f"search.sampler.n_startup_trials must be >= 0, got {search.sampler.n_startup_trials}")
    pruner = search.pruner
    check(pruner.n_startup_trials >= 0 and pruner.n_warmup_steps >= 0,
          "search.pruner.n_startup_trials and search.pruner.n_warmup_steps must be >= 0")
    check(pruner.min_resource >= 1 and pruner.reduction_factor >= 2,
          "search.pruner.min_resource must be >= 1 and search.pruner.reduction_factor >= 2")
    check(search.launcher != "slurm" or search.n_jobs <= MAX_SLURM_JOBS,
          f"search.n_jobs={search.n_jobs}: at most {MAX_SLURM_JOBS} SLURM worker jobs (each runs many trials)")
    for name, value in vars(search.slurm).items():
        check(value is None or name == "partition" or value >= 1, f"search.slurm.{name} must be >= 1 or null")


def enqueued_kind(params: dict[str, Any], kinds: list[str]) -> str | None:
    """An enqueued set's kind: given, the only one searched, or the one whose parameters cover the set's; else None."""
    # e.g. with kinds [linear, exponential]: {beta1, beta2} is exponential, {beta1} is ambiguous
    if "kind" in params or len(kinds) == 1:
        return params.get("kind", kinds[0])
    names = set(params) - {REWARD_PARAM}
    fitting = [kind for kind in kinds if names <= set(kind_params(kind))]
    return fitting[0] if len(fitting) == 1 else None


def taken_by(params: dict[str, Any], kinds: list[str]) -> bool:
    """Whether a searched kind takes an enqueued set: the kind it names is searched, or it names none and its
    keys are among a searched kind's parameters."""
    if "kind" in params:
        return params["kind"] in kinds
    return any(set(params) - {REWARD_PARAM} <= set(kind_params(kind)) for kind in kinds)


def enqueued_params(params: dict[str, Any], kinds: list[str]) -> dict[str, Any]:
    """An enqueued set as Optuna stores it (:func:`hersd.contract.study.stored_params`), its kind inferred, the
    kind's settings it leaves out as ``schedule=<kind>`` sets them (a left-out lambda_h is drawn)."""
    kind = enqueued_kind(params, kinds)
    defaults = {name: value for name, value in kind_defaults(kind).items() if name in kind_params(kind)}
    return stored_params({"kind": kind, **defaults, **params}, kinds)


def kind_defaults(kind: str) -> dict[str, Any]:
    """The settings of a run given ``schedule=<kind>``: its preset's (conf/schedule/<kind>.yaml, e.g. exponential's
    beta1 = beta2 = 0.25), else the class's declared defaults (HER's eps = 0.8; a class of one's own)."""
    declared = {item.name: item.default for item in schedule_class(kind).params()
                if isinstance(item.default, (int, float)) and not isinstance(item.default, bool)}
    if kind not in group_options("schedule"):
        return declared
    preset = OmegaConf.to_container(OmegaConf.load(files(CONFIG_MODULE) / "schedule" / f"{kind}.yaml")) or {}
    return {**declared, **{name: value for name, value in preset.items() if name in declared}}


def check_enqueue(search: SearchConfig) -> None:
    """Each enqueued set: a searched kind, only that kind's parameters, finite numbers the schedule accepts."""
    # Sets may lie outside the searched ranges (a narrowed search keeps its file's sets): Optuna warns and tries them.
    kinds = list(search.space.kinds)
    for index, params in enumerate(search.enqueue):
        where = f"search.enqueue[{index}]"
        kind = enqueued_kind(params, kinds)
        check(kind in kinds, f"{where}: kind={params.get('kind')!r} is not among search.space.kinds {kinds}"
              if "kind" in params else f"{where}: say which kind it is (kind: one of {kinds})")
        allowed = kind_params(kind) + ((REWARD_PARAM,) if search.space.lambda_h is not None else ())
        extra = sorted(map(str, set(params) - {"kind", *allowed}))
        check(not extra, f"{where}: {', '.join(extra)} not searched for kind {kind}; its parameters: "
                         f"{', '.join(allowed)}")
        for name in allowed:
            check(name not in params or is_number(params[name]),
                  f"{where}.{name} must be a finite number, got {params.get(name)!r}")
        check_schedule(kind, params, where)
        check(params.get(REWARD_PARAM, 1.0) > 0, f"{where}.{REWARD_PARAM} must be > 0, got {params.get(REWARD_PARAM)}")


def validate(search: SearchConfig) -> None:
    """Raise :class:`ConfigError` (one line) on the first out-of-range setting."""
    check_space(search.space)
    check_counts(search)
    _choice("search.objective", search.objective, OBJECTIVES)
    _choice("search.metric", search.metric, METRICS)
    _choice("search.launcher", search.launcher, LAUNCHERS)
    _choice("search.pruner.kind", search.pruner.kind, PRUNERS)
    check_enqueue(search)
    check(search.study_name is None or bool(STUDY_NAME.fullmatch(search.study_name)),
          f"search.study_name={search.study_name!r}: use 1-200 letters, digits, '.', '_' or '-' (it names files)")
    check(search.storage is None or bool(search.storage.strip()),
          "search.storage is empty; leave it null for the default SQLite file")
    check(search.storage != JOURNAL_PREFIX, "search.storage=journal:<path> needs a file path after 'journal:'")


def register_schema() -> None:
    """Put :class:`SearchConfig` in Hydra's ConfigStore as ``search/search_schema``."""
    store_schema("search_schema", SearchConfig, group="search")


def _merge_at_parent(override: str) -> str:
    """``search.a.b={...}`` -> ``search.a={b: {...}}``, the same merge made from the parent node."""
    # OmegaConf 2.3 cannot merge a mapping into a null structured node (search.space.lambda_h) by the
    # node's own key (AttributeError), but can from its parent.
    key, sep, value = override.partition("=")
    parent, _, leaf = key.rpartition(".")
    if not sep or not value.lstrip().startswith("{") or parent.count(".") < 1 or key.startswith(("+", "~")):
        return override
    return f"{parent}={{{leaf}: {value}}}"


def compose_search(search_name: str, overrides: list[str]) -> SearchConfig:
    """``conf/search/<search_name>.yaml`` + ``search.*`` overrides -> validated :class:`SearchConfig`."""
    from hydra.errors import HydraException, MissingConfigException
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    register_schema()
    overrides, ranges = split_range_overrides(overrides)
    try:
        composed = compose(None, [f"+search={search_name}", *map(_merge_at_parent, overrides)],
                           job_name="hersd-search")
        search = OmegaConf.to_object(composed.search)
        search.space.ranges.update(ranges)
    except MissingConfigException:
        raise ConfigError(f"search={search_name} is not a known search; choose one of: "
                          f"{', '.join(group_options('search'))}") from None
    except (HydraException, OmegaConfBaseException) as err:
        raise ConfigError(_composition_error(err)) from None
    check_space(search.space)  # the kinds known, before the file's sets are matched to them
    if not any(override.partition("=")[0].lstrip("+~") == "search.enqueue" for override in overrides):
        # the file's sets (e.g. the paper's point) only where the searched kinds take them; the command's all
        search.enqueue = [params for params in search.enqueue if taken_by(params, list(search.space.kinds))]
    validate(search)
    return search


def _composition_error(err: Exception) -> str:
    """A Hydra/OmegaConf error while composing the search -> one line naming the ``search.*`` field."""
    cause = err.__cause__ if err.__cause__ is not None else err
    key = getattr(cause, "full_key", None) or ""
    if key.startswith("search.enqueue") or str(err).startswith("Error merging override search.enqueue"):
        return "search.enqueue must be a list of mappings like [{beta1: 0.25, beta2: 0.25}]"
    return explain_config_error(err, what="search setting", see="SearchConfig in sweeps/search/config.py")
