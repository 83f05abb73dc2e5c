"""Schedule kinds by name: the package's own (:data:`SCHEDULES`), those other packages declare in
the entry point group ``hersd.schedules`` (``step = my_pkg.schedules:Step``), and any class by its
import path (Hydra's ``_target_`` convention: ``schedule._target_=my_pkg.schedules.Step``)."""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from hersd.contract.errors import ConfigError
from hersd.contract.plugins import class_at, entry_point_class, entry_point_names
from hersd.contract.schedules.base import Schedule, kind_name
from hersd.contract.schedules.constant import Constant
from hersd.contract.schedules.cosine import Cosine
from hersd.contract.schedules.exponential import Exponential
from hersd.contract.schedules.linear import Linear
from hersd.contract.schedules.rising import Rising
from hersd.contract.schedules.success import Success
from hersd.contract.schedules.table import Table

# The package's kinds, in the order of reports and tables.
SCHEDULES: dict[str, type[Schedule]] = {cls.kind: cls for cls in (Constant, Linear, Exponential, Rising, Success, Cosine,
                                                                      Table)}
DEFAULT = Constant  # the schedule of a config that names none (HER)
ENTRY_POINT_GROUP = "hersd.schedules"
TARGET_KEY = "_target_"


def registered(kind: str) -> type[Schedule] | None:
    """The class registered under ``kind`` (the package's or an entry point's), else None."""
    return SCHEDULES.get(kind) or entry_point_class(ENTRY_POINT_GROUP, kind)


def known_kinds() -> list[str]:
    """Every registered kind: the package's, then the entry points' (sorted)."""
    return [*SCHEDULES, *(name for name in entry_point_names(ENTRY_POINT_GROUP) if name not in SCHEDULES)]


def schedule_class(kind: str) -> type[Schedule]:
    """The class of a kind name or of an import path ``package.module.Class`` (ConfigError, one line, if none)."""
    cls = registered(kind)
    if cls is None and "." in kind:
        cls = class_at(kind, "schedule")
        declared = getattr(cls, "__dict__", {}).get("kind")
        if declared and registered(declared) is not cls:  # its logs would name a kind that is not this class
            raise ConfigError(f"schedule {kind} declares kind={declared!r}, which "
                              f"{'is another class' if registered(declared) else 'nothing registers'}: its runs "
                              f"could not be read back by that name; remove kind (its runs are then recorded by "
                              f"its path), or declare it as an entry point of {ENTRY_POINT_GROUP}")
    if cls is None:
        raise ConfigError(f"schedule.kind={kind!r} is unknown; choose one of: {', '.join(known_kinds())}, "
                          f"or a class: schedule.{TARGET_KEY}=<module>.<Class>")
    if not (isinstance(cls, type) and issubclass(cls, Schedule)):
        raise ConfigError(f"schedule {kind} is not a hersd.contract.schedules.Schedule subclass")
    if any(isinstance(value, dataclasses.Field) for value in vars(cls).values()):  # param() fields left unprocessed
        raise ConfigError(f"schedule {kind}: put @dataclass above its class (from dataclasses import dataclass): "
                          "its param() settings are dataclass fields")
    for item in dataclasses.fields(cls):  # a setting named tag makes schedule.tag a number, not the method
        if item.name in dir(Schedule) and ("doc" in item.metadata or callable(getattr(Schedule, item.name))):
            what = "setting" if "doc" in item.metadata else "field"
            raise ConfigError(f"schedule {kind}: its {what} {item.name} shadows Schedule.{item.name}, which hersd "
                              f"{'calls' if callable(getattr(Schedule, item.name)) else 'reads'}; rename the {what}")
        if "doc" not in item.metadata and item.init and item.name not in dir(Schedule):  # (title: str = ...: read)
            raise ConfigError(f"schedule {kind}: its field {item.name} is no setting; declare it with "
                              f"param(default, low, high, \"doc\") (from hersd.contract.schedules import param), or "
                              f"with field(init=False) if it is not one")
    if cls.rate is Schedule.rate:
        raise ConfigError(f"schedule {kind} defines no rate(self, k, total_epochs, train_success=()); "
                          "a schedule needs it (tag and label have defaults)")
    return cls


def schedule_from_config(node: Mapping[str, Any], total_epochs: int) -> Schedule:
    """A config's ``schedule`` mapping (``kind`` or ``_target_`` and the parameters) -> the resolved schedule of
    a run of total_epochs (:func:`settle`); ConfigError (one line) for an unknown kind, a setting it lacks or a
    value out of range (its rates are checked when its run is resolved)."""
    settings = dict(node)
    target, kind = settings.pop(TARGET_KEY, None), settings.pop("kind", None)
    cls = schedule_class(target or kind) if target or kind else DEFAULT
    names = [item.name for item in cls.params()]
    unknown = sorted(set(settings) - set(names))
    if unknown:
        raise ConfigError(f"schedule.{unknown[0]} is not a setting of schedule {target or kind or DEFAULT.kind}; "
                          f"its settings: {', '.join(names) or 'none'}")
    return settle(build(cls, settings, target or kind or DEFAULT.kind), total_epochs)


def build(cls: type[Schedule], settings: Mapping[str, Any], name: str) -> Schedule:
    """``cls(**settings)``; an error other than ConfigError its ``__post_init__`` raises is one ConfigError line
    naming the schedule ``name`` and the settings."""
    try:
        return cls(**settings)
    except ConfigError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's __post_init__: one line naming it, before any work
        given = " ".join(f"schedule.{key}={value}" for key, value in settings.items()) or "their defaults"
        raise ConfigError(f"schedule {name}: its settings refused {given}: {raised(err)}") from None


def settle(schedule: Schedule, total_epochs: int) -> Schedule:
    """The schedule a run of total_epochs uses: the kind it equals (:meth:`Schedule.equivalent`), resolved for
    total_epochs, its tag checked (:func:`check_tag`); its rates are checked when its run is resolved
    (:func:`hersd.contract.schedules.base.check_rates`)."""
    schedule = schedule.equivalent()
    try:
        schedule.resolve(total_epochs)
    except ConfigError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's resolve: one line naming it, before any work
        raise ConfigError(f"schedule {kind_name(type(schedule))}: resolve() raised {raised(err)}") from None
    check_tag(schedule)
    return schedule


def check_tag(schedule: Schedule) -> None:
    """ConfigError (one line) unless ``schedule.tag()`` is a plain folder name, the one level of
    ``<task>/<algo>/<tag>/<seed-hash>`` it names: a non-empty str of printable characters without ``/`` or ``\\``,
    not ``.`` or ``..``, of at most 255 bytes (a folder name's limit)."""
    name = kind_name(type(schedule))
    try:
        tag = schedule.tag()
    except ConfigError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's tag: one line naming it, before any work
        raise ConfigError(f"schedule {name}: tag() raised {raised(err)}") from None
    if not (isinstance(tag, str) and tag not in ("", ".", "..") and tag.isprintable()
            and "/" not in tag and "\\" not in tag and len(tag.encode()) <= 255):  # 255: a folder name's limit
        shown = repr(tag) if isinstance(tag, str) else f"{' '.join(repr(tag).split())}, a {type(tag).__name__}"
        raise ConfigError(f"schedule {name}: tag() returned {shown}, not a folder name; fix {name}.tag to return a "
                          "non-empty name of printable characters without / or \\, not . or .., of at most 255 bytes")


def raised(err: Exception) -> str:
    """A user's error as one line: ``ValueError: <its message, on one line>``."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def schedule_from_record(record: Mapping[str, Any]) -> Schedule:
    """The schedule a log's config holds (:meth:`Schedule.record`); settings the kind lacks (the flat
    schema's) are ignored. ConfigError if its class cannot be found."""
    cls = schedule_class(record["kind"])
    names = {item.name for item in cls.params()}
    return cls(**{name: value for name, value in record.items() if name in names})


def schedule_rank(kind: str) -> int:
    """Sort key of a kind: its place in SCHEDULES, other kinds after them."""
    return list(SCHEDULES).index(kind) if kind in SCHEDULES else len(SCHEDULES)
