"""The search's own settings: the :class:`SearchConfig` schema (Hydra's ConfigStore entry
``search/search_schema``, which every ``conf/search/*.yaml`` lists first), its range checks,
and its composition from ``conf/search/<name>.yaml`` plus ``search.*`` overrides.

Every check raises :class:`hersd.contract.errors.ConfigError` with one line naming the field.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from importlib.resources import files
from typing import Any, Dict, Optional

from omegaconf import OmegaConf

from hersd.contract.compose import (CONFIG_MODULE, compose, explain_config_error, group_options,
                                    register_schema as store_schema)
from hersd.contract.errors import ConfigError
from hersd.contract.cores import available_cores
from hersd.contract.runlog import EPOCH_FIELDS, OPTIONAL_EPOCH_FIELDS
from hersd.contract.schedules import SCHEDULES, Exponential, known_kinds, schedule_class
from hersd.contract.study import (JOURNAL_PREFIX, PAPER_SETTINGS, REWARD_PARAM, kind_params, schedule_config,
                                  searchable, stored_params)

OBJECTIVES = ("auc", "final")
PRUNERS = ("median", "hyperband", "none")
LAUNCHERS = ("local", "slurm")
METRICS = tuple(name for name, (kind, _) in EPOCH_FIELDS.items()
                if kind == "number" and name not in OPTIONAL_EPOCH_FIELDS)
MAX_SLURM_JOBS = 10_000  # worker jobs of one search (SLURM's array limit is usually lower: sbatch says so)
RANGES_KEY = "search.space.ranges"
STUDY_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,199}")  # it names files: <study>.db, <study>/


@dataclass
class Bounds:
    """A searched range of one parameter."""

    low: float  # smallest value tried
    high: float  # largest value tried
    log: bool = False  # sample on a log scale (needs low > 0)


@dataclass
class SpaceConfig:
    """What the search draws: the schedule kinds and each parameter's range."""

    # schedule kinds searched (a categorical if > 1): registered names or class paths (hersd.contract.schedules)
    kinds: list[str] = field(default_factory=lambda: [Exponential.kind])
    # beta1, beta2 and eps as the package's kinds declare them (a class declaring its own: its declared range)
    beta1: Bounds = field(default_factory=lambda: Bounds(0.0, 1.0))  # eq. 9 final drop, within [0, 1]
    beta2: Bounds = field(default_factory=lambda: Bounds(-2.0, 2.0))  # eq. 9 shape (exponential kind only)
    eps: Bounds = field(default_factory=lambda: Bounds(0.5, 1.0))  # fixed rate (constant kind only)
    lambda_h: Optional[Bounds] = None  # hindsight reward weight (eq. 8); null keeps the algo's
    # any searched setting's range by name (e.g. cosine's start, a class's k0), over beta1, beta2, eps above, for
    # every kind; default: the range the schedule declares. Command line: search.space.ranges.k0={low: 1, high: 50}
    ranges: Dict[str, Bounds] = field(default_factory=dict)


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


def _check(condition: bool, message: str) -> None:
    """Raise ConfigError(message) unless ``condition``."""
    if not condition:
        raise ConfigError(message)


def _is_number(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    """ConfigError naming the choices unless ``value`` is one of them."""
    _check(value in choices, f"{name}={value!r} is unknown; choose one of: {', '.join(choices)}")


def declaration(kind: str, name: str) -> dataclasses.Field:
    """Setting ``name`` as ``kind``'s class declares (or inherits) it."""
    found = [item for item in schedule_class(kind).params() if item.name == name]
    _check(bool(found), f"search.space.kinds: {kind} searches {name} but declares no such setting; declare it "
                        f"with param(...) or leave it out of searched")
    return found[0]


def package_setting(kind: str, name: str) -> bool:
    """Whether search.space.<name> ranges ``kind``'s setting ``name``: beta1, beta2 or eps as one of the package's
    kinds declares it (inherited by a subclass too), not a class's own declaration of that name."""
    item = declaration(kind, name)
    return name in PAPER_SETTINGS and any(item is own for cls in SCHEDULES.values() for own in cls.params())


def space_bounds(space: SpaceConfig, kind: str, name: str) -> Bounds:
    """The range a search draws parameter ``name`` of ``kind`` from: search.space.ranges.<name>,
    search.space.<name> for the package kinds' beta1, beta2 and eps, else the range the schedule class declares."""
    if name in space.ranges:
        return space.ranges[name]
    if package_setting(kind, name):
        return getattr(space, name)
    meta = declaration(kind, name).metadata
    return Bounds(meta["low"], meta["high"])


def whole_number(kind: str, name: str) -> bool:
    """Whether ``kind`` declares setting ``name`` a whole number (drawn with Optuna's suggest_int)."""
    return any(item.name == name and item.metadata.get("integer", False) for item in schedule_class(kind).params())


def space_record(space: SpaceConfig) -> dict[str, Any]:
    """What a search draws, as the study's identity holds it: the kinds and each searched range [low, high, log]."""
    return {"kinds": list(space.kinds),
            **{name: [bounds.low, bounds.high, bounds.log] for name, bounds in sorted(searched_bounds(space).items())}}


def searched_bounds(space: SpaceConfig) -> dict[str, Bounds]:
    """The ranges the search draws from, by parameter name (unused ranges left out)."""
    named = {name: space_bounds(space, kind, name) for kind in space.kinds for name in kind_params(kind)}
    return {**named, REWARD_PARAM: space.lambda_h} if space.lambda_h is not None else named


def shown_bounds(bounds: Bounds) -> str:
    """A range for messages: ``[0, 0.5]``, ``[0.01, 1, log]``."""
    ends = ", ".join(f"{end:g}" if _is_number(end) else repr(end) for end in (bounds.low, bounds.high))
    return f"[{ends}{', log' if bounds.log else ''}]"


def check_shared_settings(space: SpaceConfig) -> None:
    """ConfigError unless each setting several searched kinds draw is drawn one way (one type, one range): Optuna
    draws a name one way, and the study's identity holds one range per name."""
    first: dict[str, str] = {}  # setting -> the first searched kind drawing it
    for kind in space.kinds:
        for name in kind_params(kind):
            other = first.setdefault(name, kind)
            if whole_number(other, name) != whole_number(kind, name):
                whole, real = (other, kind) if whole_number(other, name) else (kind, other)
                raise ConfigError(f"search.space.kinds: {whole} declares {name} a whole number and {real} does not; "
                                  "rename it in one of the classes")
            ours, theirs = space_bounds(space, other, name), space_bounds(space, kind, name)
            _check(ours is theirs or ours == theirs,
                   f"search.space.kinds: {other} and {kind} both search {name}, over {shown_bounds(ours)} and "
                   f"{shown_bounds(theirs)}; give it one range, search.space.ranges.{name}={{low: ..., high: ...}}")


def check_schedule(kind: str, params: dict[str, Any], where: str) -> None:
    """The schedule's own checks (:class:`hersd.contract.config.ScheduleConfig`) on ``params``; errors prefixed by ``where``."""
    try:
        schedule_config({**params, "kind": kind})
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from None


def check_space(space: SpaceConfig) -> None:
    """Kinds known and distinct; each searched range finite, ordered, loggable, and valid for the schedule."""
    kinds = list(space.kinds)
    _check(bool(kinds) and len(set(kinds)) == len(kinds), f"search.space.kinds must be a non-empty list of "
                                                          f"distinct kinds; got {kinds}")
    for kind in kinds:
        try:
            fits = searchable(kind)
        except ConfigError as err:
            raise ConfigError(f"search.space.kinds: {err}") from None
        _check(fits, f"search.space.kinds: {kind} cannot be searched (it declares no searched parameters or adapts "
                     f"to the run); searchable kinds: {', '.join(k for k in known_kinds() if searchable(k))}")
    drawn = {name for kind in kinds for name in kind_params(kind)}
    for name in space.ranges:
        _check(name in drawn, f"search.space.ranges.{name}: no searched kind draws {name}; they draw "
                              f"{', '.join(sorted(drawn))}")
    check_shared_settings(space)
    for name, bounds in searched_bounds(space).items():
        where = f"search.space.{'ranges.' if name in space.ranges else ''}{name}"
        _check(_is_number(bounds.low) and _is_number(bounds.high),
               f"{where}: bounds must be finite numbers, got [{bounds.low}, {bounds.high}]; set "
               f"search.space.ranges.{name}={{low: ..., high: ...}}")
        _check(isinstance(bounds.log, bool), f"{where}.log must be true or false, got {bounds.log!r}")
        _check(bounds.low <= bounds.high, f"{where}: low ({bounds.low}) must be <= high ({bounds.high})")
        _check(not bounds.log or bounds.low > 0, f"{where}: log=true needs low > 0, got {bounds.low}")
        for kind in (k for k in kinds if name in kind_params(k)):
            for end in ("low", "high"):
                check_schedule(kind, {name: getattr(bounds, end)}, f"{where}.{end}={getattr(bounds, end)}")
    if space.lambda_h is not None:
        _check(space.lambda_h.low > 0, f"search.space.lambda_h: low must be > 0, got {space.lambda_h.low}")


def check_counts(search: SearchConfig) -> None:
    """Trials, workers, seeds, staleness and the pruner's and sampler's integers in range."""
    for name in ("n_trials", "n_jobs", "seeds"):
        _check(getattr(search, name) >= 1, f"search.{name} must be >= 1, got {getattr(search, name)}")
    cores = available_cores()
    _check(search.launcher != "local" or search.n_jobs <= cores,
           f"search.n_jobs={search.n_jobs}: local workers are processes of this machine, which has {cores} "
           f"core(s); use search.n_jobs<={cores}, or search.launcher=slurm")
    _check(search.first_seed >= 0, f"search.first_seed must be >= 0, got {search.first_seed}")
    _check(search.stale_after_minutes > 0,  # NaN fails too
           f"search.stale_after_minutes must be > 0 (longer than an epoch), got {search.stale_after_minutes}")
    _check(search.sampler.seed >= 0, f"search.sampler.seed must be >= 0, got {search.sampler.seed}")
    _check(search.sampler.n_startup_trials >= 0,
           f"search.sampler.n_startup_trials must be >= 0, got {search.sampler.n_startup_trials}")
    pruner = search.pruner
    _check(pruner.n_startup_trials >= 0 and pruner.n_warmup_steps >= 0,
           "search.pruner.n_startup_trials and search.pruner.n_warmup_steps must be >= 0")
    _check(pruner.min_resource >= 1 and pruner.reduction_factor >= 2,
           "search.pruner.min_resource must be >= 1 and search.pruner.reduction_factor >= 2")
    _check(search.launcher != "slurm" or search.n_jobs <= MAX_SLURM_JOBS,
           f"search.n_jobs={search.n_jobs}: at most {MAX_SLURM_JOBS} SLURM worker jobs (each runs many trials)")
    for name, value in vars(search.slurm).items():
        _check(value is None or name == "partition" or value >= 1, f"search.slurm.{name} must be >= 1 or null")


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
        _check(kind in kinds, f"{where}: kind={params.get('kind')!r} is not among search.space.kinds {kinds}"
               if "kind" in params else f"{where}: say which kind it is (kind: one of {kinds})")
        allowed = kind_params(kind) + ((REWARD_PARAM,) if search.space.lambda_h is not None else ())
        extra = sorted(map(str, set(params) - {"kind", *allowed}))
        _check(not extra, f"{where}: {', '.join(extra)} not searched for kind {kind}; its parameters: "
                          f"{', '.join(allowed)}")
        for name in allowed:
            _check(name not in params or _is_number(params[name]),
                   f"{where}.{name} must be a finite number, got {params.get(name)!r}")
        check_schedule(kind, params, where)
        _check(params.get(REWARD_PARAM, 1.0) > 0, f"{where}.{REWARD_PARAM} must be > 0, got {params.get(REWARD_PARAM)}")


def validate(search: SearchConfig) -> None:
    """Raise :class:`ConfigError` (one line) on the first out-of-range setting."""
    check_space(search.space)
    check_counts(search)
    _choice("search.objective", search.objective, OBJECTIVES)
    _choice("search.metric", search.metric, METRICS)
    _choice("search.launcher", search.launcher, LAUNCHERS)
    _choice("search.pruner.kind", search.pruner.kind, PRUNERS)
    check_enqueue(search)
    _check(search.study_name is None or bool(STUDY_NAME.fullmatch(search.study_name)),
           f"search.study_name={search.study_name!r}: use 1-200 letters, digits, '.', '_' or '-' (it names files)")
    _check(search.storage is None or bool(search.storage.strip()),
           "search.storage is empty; leave it null for the default SQLite file")
    _check(search.storage != JOURNAL_PREFIX, "search.storage=journal:<path> needs a file path after 'journal:'")


def split_range_overrides(overrides: list[str]) -> tuple[list[str], dict[str, Bounds]]:
    """``search.space.ranges={name: {low, high}}`` and ``search.space.ranges.<name>={low, high}`` (``+`` or not)
    -> (the other overrides, the ranges they set); Hydra cannot add a key to a typed mapping, so these are read here."""
    import yaml

    rest, ranges = [], {}
    for override in overrides:
        key, _, value = override.partition("=")
        key = key.lstrip("+")
        if key != RANGES_KEY and not (key.startswith(f"{RANGES_KEY}.") and key.count(".") == RANGES_KEY.count(".") + 1):
            rest.append(override)
            continue
        try:
            parsed = yaml.safe_load(value)
        except yaml.YAMLError:
            parsed = None
        given = parsed if key == RANGES_KEY else {key.rpartition(".")[2]: parsed}
        _check(isinstance(given, dict) and all(isinstance(bounds, dict) for bounds in given.values()),
               f"{override}: give a range as {RANGES_KEY}.<setting>={{low: 1, high: 50}} or "
               f"{RANGES_KEY}={{<setting>: {{low: 1, high: 50}}}}")
        for name, bounds in given.items():
            _check(set(bounds) in ({"low", "high"}, {"low", "high", "log"}),
                   f"{RANGES_KEY}.{name}: give low and high (and log), got {', '.join(map(str, bounds)) or 'none'}")
            ranges[str(name)] = Bounds(**bounds)
    return rest, ranges


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
