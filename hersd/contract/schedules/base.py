"""What every relabel-rate schedule declares about itself (:class:`Schedule`).

A schedule is a dataclass whose fields are its parameters, each made by :func:`param` with a
range and a one-line doc: they are the ``schedule.<name>`` keys of ``hersd-train --help``, the
range checks (one-line :class:`ConfigError` naming the field) and the search's default range.
Its methods give the rate of epoch k of K, the exact mean rate (None when it adapts to the
run), the folder tag and the report's label (both by default from the class name and its settings),
the kind it equals (:meth:`Schedule.equivalent`) and the record logs keep (the run's identity).
Every rate must lie in [0, 1]: a fixed schedule's are checked when its run is resolved
(:func:`check_rates`, its first CHECKED_UP_FRONT epochs, by :func:`hersd.contract.runspec.resolve`), every other at its epoch
(:meth:`Schedule.checked_rate`), one :class:`ScheduleRateError` line naming the epoch; a fixed schedule whose rate reads
``train_success`` is refused there too (:class:`TrainSuccessRead`). Imports neither torch nor the config: every layer can use it.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, NoReturn, Sequence

import numpy as np

from hersd.contract.checks import shown_number
from hersd.contract.errors import ConfigError

# The settings every log of the paper's kinds (constant, linear, exponential, success) holds, at
# these values where the kind has no such setting: one flat schema served them when those logs
# were written, and their folders' hashes cover these fields (hersd.contract.runstore.run_identity).
HER_RATE = 0.8  # HER's relabel rate (the reference code's replay_k = 4): the constant kind's default
FLAT_RECORD: dict[str, Any] = {"eps": HER_RATE, "beta1": 0.0, "beta2": 0.0, "mean_rate": None, "window": 10,
                               "eps_min": 0.0}


class ScheduleRateError(ConfigError):
    """A schedule gave a rate outside [0, 1]; the message is one line naming the schedule and the epoch."""


class TrainSuccessRead(ConfigError):
    """A fixed schedule's rate read ``train_success``, which only an adaptive one is given (:func:`check_rates`)."""


class ScheduleRateRaised(RuntimeError):
    """A schedule's rate raised once its run was under way (an adaptive schedule's, or a fixed one's past the
    epochs checked up front): one line naming the schedule, the epoch and the error; the finished epochs are kept."""


def param(default: Any, low: float, high: float, doc: str, integer: bool = False, optional: bool = False) -> Any:
    """A schedule parameter: ``default``, its range [low, high], a one-line ``doc``; ``integer`` for whole
    numbers, ``optional`` when null is allowed (the default then is usually None); ConfigError (one line) for a
    range that is not two numbers, low <= high."""
    if not all(isinstance(end, numbers.Real) and not isinstance(end, bool) for end in (low, high)) or low > high:
        raise ConfigError(f"param({default!r}, {low!r}, {high!r}, {doc!r}): its range must be two numbers, "
                          "low <= high (e.g. param(0.5, 0.0, 1.0, \"...\"))")
    return field(default=default, metadata={"low": low, "high": high, "doc": doc, "integer": integer,
                                            "optional": optional})


@dataclass
class Schedule:
    """A relabel-rate schedule: eps(k), the probability that a sampled transition's goal is
    replaced by a hindsight goal during epoch k (1..K)."""

    # The name schedule.kind selects: the package's kinds and entry points (hersd.contract.schedules.registry) set it;
    # a class without one is selected and recorded by its import path (schedule._target_=<module>.<Class>).
    kind: ClassVar[str] = ""
    formula: ClassVar[str] = ""  # eps(k) in one line, for hersd-train --help
    title: ClassVar[str] = ""  # the report's panel title for schedules of this kind ("" : the kind)
    adaptive: ClassVar[bool] = False  # the rate depends on the run's history, not on the epoch alone
    constant_rate: ClassVar[bool] = False  # one rate at every epoch (the report's baselines: HER, ARCHER)
    searched: ClassVar[tuple[str, ...]] = ()  # the parameters a search draws (hersd-search)
    line: ClassVar[str] = "-"  # matplotlib line style of its curves in the report
    flat_record: ClassVar[bool] = False  # its logs hold FLAT_RECORD's fields too (the paper's kinds)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass of a kind that names its own folders and labels (linear's ``linear-b1_0.25``) names its own
        by default, the class name and every setting, unless it defines tag or label: it is another schedule. One
        that defines its own rate drops its parent's closed-form mean rates (eq. 10, 11) for the mean of its own
        rates, and refuses a ``mean_rate`` its parent's resolve would solve by the parent's formula."""
        super().__init_subclass__(**kwargs)
        own_rate = "rate" in vars(cls)
        for method in ("tag", "label", *(("exact_mean_rate", "limit_mean_rate") if own_rate else ())):
            if method not in vars(cls) and getattr(cls, method) is not getattr(Schedule, method):
                setattr(cls, method, getattr(Schedule, method))
        if own_rate and "resolve" not in vars(cls) and cls.resolve is not Schedule.resolve:
            cls.resolve = _without_inherited_solve(cls.resolve)

    def __post_init__(self) -> None:
        for item in self.params():
            if "low" in item.metadata:
                check_param(item, getattr(self, item.name))
                value = getattr(self, item.name)
                if item.metadata["integer"] and isinstance(value, float):  # 5.0 is 5, one identity
                    setattr(self, item.name, int(value))
                elif not item.metadata["integer"] and isinstance(value, int) and not isinstance(value, bool):
                    setattr(self, item.name, float(value))  # 1 is 1.0, one identity

    @classmethod
    def params(cls) -> list[dataclasses.Field]:
        """The parameters (fields with a ``doc``; ranged ones made by :func:`param`), in declaration order."""
        return [item for item in dataclasses.fields(cls) if "doc" in item.metadata]

    def resolve(self, total_epochs: int) -> None:
        """Settle what depends on the run's K (or on files) before the run; called once per config."""

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        """eps(k) in force during epoch k (1-based) of total_epochs; ``train_success`` (k-1,) holds the
        train success of epochs 1..k-1 (adaptive schedules read it)."""
        raise NotImplementedError

    def checked_rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        """:meth:`rate`; ScheduleRateError (one line) when it is not a number in [0, 1], ScheduleRateRaised
        (one line) when computing it raises (TrainSuccessRead as it is: :func:`check_rates`)."""
        try:
            rate = self.rate(k, total_epochs, train_success)
        except TrainSuccessRead:
            raise
        except Exception as err:  # noqa: BLE001 - a user's rate: one line naming it
            raise ScheduleRateRaised(f"schedule {kind_name(type(self))}: its rate at epoch {k} of {total_epochs} "
                                     f"raised {type(err).__name__}: {' '.join(str(err).split())}") from None
        if isinstance(rate, np.ndarray) and rate.size == 1:  # np.where(...) of a scalar: a 0-d array (or [x])
            rate = rate.item()
        is_number = isinstance(rate, numbers.Real) and not isinstance(rate, bool)  # numpy's scalars too
        if not (is_number and 0.0 <= rate <= 1.0):  # NaN fails too
            shown = shown_rate(float(rate)) if is_number else f"{rate!r}, a {type(rate).__name__}"
            raise ScheduleRateError(f"schedule {self.label()}: its rate at epoch {k} of {total_epochs} is {shown}, "
                                    f"not in [0, 1]; fix {kind_name(type(self))}.rate")
        return float(rate)

    def equivalent(self) -> Schedule:
        """The schedule of the kind it equals when its settings make it one (exponential with beta2 = 0 is
        linear), so that its runs are that kind's runs; else itself."""
        return self

    def epoch_rates(self, total_epochs: int) -> np.ndarray:
        """eps(k) for k = 1..K, shape (K,); only for schedules that do not adapt."""
        return np.array([self.rate(k, total_epochs) for k in range(1, total_epochs + 1)], dtype=float)

    def exact_mean_rate(self, total_epochs: int) -> float | None:
        """mu_eps, the mean of eps(k) over k = 1..K exactly; None when the schedule adapts to the run."""
        return None if self.adaptive else float(np.mean(self.epoch_rates(total_epochs)))

    def limit_mean_rate(self) -> float | None:
        """mu_eps as K -> infinity (eq. 11 for eq. 9's kinds); None when unknown."""
        return None

    def tag(self) -> str:
        """The folder a run of it lives in, below <task>/<algo>/, e.g. ``linear-b1_0.25``; by default the
        class name and each setting, ``step-high_0.9-low_0.4-k0_5`` (characters a folder name avoids as ``_``)."""
        words = [short_name(type(self)), *(f"{name}_{shown_value(value)}" for name, value in self.settings())]
        return re.sub(r"[^A-Za-z0-9._=-]", "_", "-".join(words))

    def label(self) -> str:
        """Its name in the report, e.g. ``linear b1=0.25``; by default the class name and each setting,
        ``step high=0.9 low=0.4 k0=5``."""
        return " ".join([short_name(type(self)), *(f"{name}={shown_value(value)}" for name, value in self.settings())])

    def settings(self) -> list[tuple[str, Any]]:
        """(name, value) of each parameter, in declaration order."""
        return [(item.name, getattr(self, item.name)) for item in self.params()]

    def record(self) -> dict[str, Any]:
        """The schedule as a log's ``/run/meta`` config holds it and the run's identity hashes it:
        ``kind`` and every parameter (and FLAT_RECORD's fields for the paper's kinds)."""
        own = dict(self.settings())
        return {"kind": kind_name(type(self)), **(FLAT_RECORD if self.flat_record else {}), **own}


def _without_inherited_solve(inherited: Callable[[Schedule, int], None]) -> Callable[[Schedule, int], None]:
    """``inherited`` (a parent kind's resolve) for a subclass with a rate of its own: ConfigError (one line) when
    ``mean_rate`` is set, which the parent solves by its own formula (eq. 10 for linear and exponential)."""
    def resolve(self: Schedule, total_epochs: int) -> None:
        if getattr(self, "mean_rate", None) is not None:
            raise ConfigError(f"schedule.mean_rate: {kind_name(type(self))} has a rate of its own, which its parent's "
                              f"mean_rate solve does not know; set its settings instead, or define its resolve()")
        inherited(self, total_epochs)

    return resolve


def kind_name(cls: type[Schedule]) -> str:
    """The kind a schedule class is recorded under: the ``kind`` it declares itself (not one it inherits, so a
    subclass of a registered kind is not taken for it), else its import path."""
    return cls.__dict__.get("kind") or f"{cls.__module__}.{cls.__qualname__}"


def short_name(cls: type[Schedule]) -> str:
    """A schedule class's name in default tags and labels: its kind, else its class name in lower case."""
    return cls.__dict__.get("kind") or cls.__name__.lower()


def shown_rate(rate: float) -> str:
    """A rate outside [0, 1] for messages, rounded (-0.05, not -0.04999999999999993) unless rounding would put it
    inside."""
    rounded = f"{rate:.6g}"
    return repr(rate) if 0.0 <= float(rounded) <= 1.0 else rounded


def shown_value(value: Any) -> str:
    """A setting as default tags and labels write it: numbers as ``:g`` (0.25, 5), null, else str."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:g}"
    return "null" if value is None else str(value)


CHECKED_UP_FRONT = 100_000  # a fixed schedule's epochs checked before any work; later ones at their epoch


class _Unread(Sequence):
    """The ``train_success`` a fixed schedule's rates are computed with (:func:`check_rates`): reading it (its
    length, items, truth, an iteration, numpy's view of it) is a TrainSuccessRead naming the class."""

    def __init__(self, cls: type[Schedule]) -> None:
        self.cls = cls

    def _refuse(self, *args: Any, **kwargs: Any) -> NoReturn:
        raise TrainSuccessRead(f"{self.cls.__module__}.{self.cls.__qualname__}.rate reads train_success: declare "
                               "adaptive = True in the class (docs/ARCHITECTURE.md, \"Add a schedule\")")

    __len__ = __iter__ = __getitem__ = __bool__ = __contains__ = __reversed__ = __array__ = _refuse


def check_rates(schedule: Schedule, total_epochs: int) -> tuple[float, ...] | None:
    """The rates of a fixed schedule's epochs 1..min(total_epochs, CHECKED_UP_FRONT), shape (K,), each checked in
    [0, 1] (ScheduleRateError, one line, for one outside or one that raises; TrainSuccessRead, one line, for a rate
    that reads ``train_success``: the class is adaptive); None for an adaptive schedule, whose rate training
    checks at each epoch, as it does a longer run's epochs past CHECKED_UP_FRONT."""
    if schedule.adaptive:
        return None
    unread = _Unread(type(schedule))
    try:
        return tuple(schedule.checked_rate(k, total_epochs, unread)
                     for k in range(1, min(total_epochs, CHECKED_UP_FRONT) + 1))
    except ScheduleRateRaised as err:  # before any work: bad input
        raise ScheduleRateError(str(err)) from None


def check_param(item: dataclasses.Field, value: Any) -> None:
    """ConfigError (one line, naming ``schedule.<name>``) unless ``value`` is in the parameter's range."""
    meta = item.metadata
    if value is None and meta["optional"]:
        return
    whole = meta["integer"]
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and (not whole or float(value).is_integer()) and meta["low"] <= value <= meta["high"]
    if not ok:
        what = "a whole number" if whole else "a number"
        raise ConfigError(f"schedule.{item.name} must be {what} in [{meta['low']:g}, {meta['high']:g}]"
                          f"{' or null' if meta['optional'] else ''}, got {shown_number(value)}")
