"""What a search draws: the schedule kinds and each searched setting's range (:class:`SpaceConfig`, the
``search.space`` node of :class:`sweeps.search.config.SearchConfig`), the range each setting is drawn from, and
their checks. Every check raises :class:`hersd.contract.errors.ConfigError` with one line naming the field.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Dict, Iterator, Optional

import numpy as np

from hersd.contract.checks import check, shown_number
from hersd.contract.errors import ConfigError
from hersd.contract.schedules import SCHEDULES, Exponential, known_kinds, schedule_class
from hersd.contract.study import PAPER_SETTINGS, REWARD_PARAM, kind_params, schedule_config, searchable

RANGES_KEY = "search.space.ranges"
BOX_POINTS = 500  # about how many combinations of a kind's searched settings the start check evaluates (a grid)


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


def is_number(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def declaration(kind: str, name: str) -> dataclasses.Field:
    """Setting ``name`` as ``kind``'s class declares (or inherits) it."""
    found = [item for item in schedule_class(kind).params() if item.name == name]
    check(bool(found), f"search.space.kinds: {kind} searches {name} but declares no such setting; declare it "
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
    ends = ", ".join(f"{end:g}" if is_number(end) else repr(end) for end in (bounds.low, bounds.high))
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
            check(ours is theirs or ours == theirs,
                  f"search.space.kinds: {other} and {kind} both search {name}, over {shown_bounds(ours)} and "
                  f"{shown_bounds(theirs)}; give it one range, search.space.ranges.{name}={{low: ..., high: ...}}")


def check_schedule(kind: str, params: dict[str, Any], where: str) -> None:
    """The schedule's own checks (its class's ``__post_init__``, built by :func:`hersd.contract.study.schedule_config`)
    on ``params``; errors prefixed by ``where``."""
    try:
        schedule_config({**params, "kind": kind})
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from None


def check_space(space: SpaceConfig) -> None:
    """Kinds known and distinct; each searched range finite, ordered, loggable, and valid for the schedule."""
    kinds = list(space.kinds)
    check(bool(kinds) and len(set(kinds)) == len(kinds), f"search.space.kinds must be a non-empty list of "
                                                         f"distinct kinds; got {kinds}")
    for kind in kinds:
        try:
            fits = searchable(kind)
        except ConfigError as err:
            raise ConfigError(f"search.space.kinds: {err}") from None
        check(fits, f"search.space.kinds: {kind} cannot be searched (it declares no searched parameters or adapts "
                    f"to the run); searchable kinds: {', '.join(k for k in known_kinds() if searchable(k))}")
        for name in set(kind_params(kind)) & {"kind", REWARD_PARAM}:  # a trial's parameters name these already
            used = "the schedule's kind" if name == "kind" else f"ARCHER's reward weight algo.{REWARD_PARAM}"
            raise ConfigError(f"search.space.kinds: {kind} searches a setting named {name}, the name a trial gives "
                              f"{used}; rename the setting in the class")
    drawn = {name for kind in kinds for name in kind_params(kind)}
    for name in space.ranges:
        check(name in drawn, f"search.space.ranges.{name}: no searched kind draws {name}; they draw "
                             f"{', '.join(sorted(drawn))}")
    check_shared_settings(space)
    for name, bounds in searched_bounds(space).items():
        where = f"search.space.{'ranges.' if name in space.ranges else ''}{name}"
        check(is_number(bounds.low) and is_number(bounds.high),
              f"{where}: bounds must be finite numbers, got [{shown_number(bounds.low)}, "
              f"{shown_number(bounds.high)}]; set "
              f"search.space.ranges.{name}={{low: ..., high: ...}}")
        check(isinstance(bounds.log, bool), f"{where}.log must be true or false, got {bounds.log!r}")
        check(bounds.low <= bounds.high,
              f"{where}: low ({shown_number(bounds.low)}) must be <= high ({shown_number(bounds.high)})")
        check(not bounds.log or bounds.low > 0, f"{where}: log=true needs low > 0, got {shown_number(bounds.low)}")
        for kind in (k for k in kinds if name in kind_params(k)):
            for end in ("low", "high"):
                given = getattr(bounds, end)
                check_schedule(kind, {name: given}, f"{where}.{end}={shown_number(given)}")
    if space.lambda_h is not None:
        check(space.lambda_h.low > 0, f"search.space.lambda_h: low must be > 0, got {shown_number(space.lambda_h.low)}")


def axis_values(bounds: Bounds, whole: bool, count: int) -> list[Any]:
    """``count`` values over a range, its ends included (log-spaced for a log range); a whole-number setting's at
    whole numbers, every one when the range holds no more than ``count``."""
    low, high = (math.ceil(bounds.low), math.floor(bounds.high)) if whole else (bounds.low, bounds.high)
    if whole and high - low + 1 <= count:
        return list(range(low, high + 1))
    spaced = (np.geomspace if bounds.log else np.linspace)(low, high, count)
    values = [int(round(value)) if whole else float(value) for value in spaced]
    return [low, *values[1:-1], high]  # the ends exactly


def box_points(space: SpaceConfig, kind: str) -> Iterator[dict[str, Any]]:
    """The combinations of ``kind``'s searched settings the start check evaluates: the searched box's corners, then
    a grid over it (about BOX_POINTS points, whole numbers at whole values), each once."""
    names = kind_params(kind)
    ranges = [(space_bounds(space, kind, name), whole_number(kind, name)) for name in names]
    per_axis = max(2, int(BOX_POINTS ** (1 / len(names)) + 1e-9))
    corners = itertools.product(*(axis_values(bounds, whole, 2) for bounds, whole in ranges))
    grid = itertools.product(*(axis_values(bounds, whole, per_axis) for bounds, whole in ranges))
    seen = set()
    for values in itertools.chain(corners, grid):
        if values not in seen:
            seen.add(values)
            yield dict(zip(names, values))


def split_range_overrides(overrides: list[str]) -> tuple[list[str], dict[str, Bounds]]:
    """``search.space.ranges={name: {low, high}}`` and ``search.space.ranges.<name>={low, high}`` (``+`` or not, Hydra's
    syntax: ``{low:1,high:2}`` too) -> (the other overrides, the ranges they set); Hydra cannot add a key to a typed
    mapping, so these are read here."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    rest, ranges = [], {}
    for override in overrides:
        key = override.partition("=")[0].lstrip("+")
        if key != RANGES_KEY and not (key.startswith(f"{RANGES_KEY}.") and key.count(".") == RANGES_KEY.count(".") + 1):
            rest.append(override)
            continue
        try:
            parsed = OverridesParser.create().parse_override(override.lstrip("+")).value()
        except HydraException:
            parsed = None
        given = parsed if key == RANGES_KEY else {key.rpartition(".")[2]: parsed}
        check(isinstance(given, dict) and all(isinstance(bounds, dict) for bounds in given.values()),
              f"{override}: give a range as {RANGES_KEY}.<setting>={{low: 1, high: 50}} or "
              f"{RANGES_KEY}={{<setting>: {{low: 1, high: 50}}}}")
        for name, bounds in given.items():
            check(set(bounds) in ({"low", "high"}, {"low", "high", "log"}),
                  f"{RANGES_KEY}.{name}: give low and high (and log), got {', '.join(map(str, bounds)) or 'none'}")
            ranges[str(name)] = Bounds(**bounds)
    return rest, ranges
