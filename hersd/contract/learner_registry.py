"""Learner classes by name (docs/LEARNERS.md), for the config as for the run engine, importing none of them
(and so not torch) until one is asked for.

Every :class:`hersd.engine.learners.GoalConditionedLearner` subclass that declares a ``NAME`` registers itself in
:data:`LEARNERS` when its module is imported. A name is found there (after importing the packages of the entry
point group ``hersd.learner_modules``, hersd's own learners among them, when it is not registered yet), then among
the entry points of the group ``hersd.learners``, then as a class path ``<module>.<Class>`` (``learner._target_``),
the way schedules are found (:mod:`hersd.contract.schedules.registry`).
"""

from __future__ import annotations

import dataclasses
from importlib.metadata import entry_points
from typing import Any

from hersd.contract.errors import ConfigError
from hersd.contract.plugins import class_at, entry_point_class
from hersd.contract.plugins import entry_point_names as declared_names

LEARNERS: dict[str, type] = {}  # NAME -> learner class, filled as the classes are defined
ENTRY_POINT_GROUP = "hersd.learners"  # other packages' learners: ``mytd3 = my_pkg.learners:MyTD3``
TARGET_KEY = "learner._target_"  # a class by its path: learner._target_=<module>.<Class>
MODULE_GROUP = "hersd.learner_modules"  # packages whose import registers learners by NAME (pyproject.toml)


def learner_class(name: str, known: tuple[str, ...] = ()) -> Any:
    """The learner class a ``learner=`` name or class path selects; ConfigError (one line, listing ``known``
    and the registered names) if none, or if it declares SETTINGS that are not a dataclass."""
    cls = _registered(name) or entry_point_class(ENTRY_POINT_GROUP, name)
    if cls is None and "." in name:
        cls = class_at(name, "learner")
        declared = vars(cls).get("NAME") if isinstance(cls, type) else None
        if declared and not _found_by_name(declared, cls):  # its logs would record a name nothing finds
            raise ConfigError(f"learner {name} declares NAME={declared!r}, which a later command (hersd-render "
                              f"of its runs) could not find: remove NAME (its runs are then recorded by its "
                              f"path), or declare it as an entry point of {ENTRY_POINT_GROUP}")
    if cls is None:
        names = sorted({*known, *LEARNERS, *entry_point_names()})
        raise ConfigError(f"learner={name!r} is unknown; choose one of: {', '.join(names)}, "
                          "or a class: learner._target_=<module>.<Class>")
    settings = getattr(cls, "SETTINGS", None)
    if not isinstance(cls, type) or not callable(getattr(cls, "build", None)):
        raise ConfigError(f"learner {name} is not a hersd.engine.learners.GoalConditionedLearner subclass")
    if settings is not None and not dataclasses.is_dataclass(settings):
        raise ConfigError(f"learner {name}: its SETTINGS must be a dataclass (or None), got {settings!r}")
    _check_inherited_settings(name, cls)
    return cls


def _check_inherited_settings(name: str, cls: type) -> None:
    """ConfigError (one line) unless ``cls``'s SETTINGS extend those of every learner class it extends: their
    code (``build``, the update) reads them from the one settings object the run holds."""
    own = cls.SETTINGS
    for base in cls.__mro__[1:]:
        parent = vars(base).get("SETTINGS")
        if parent is not None and not (isinstance(own, type) and issubclass(own, parent)):
            raise ConfigError(f"learner {name} extends {base.__name__}, whose code reads {parent.__name__}: its "
                              f"SETTINGS ({getattr(own, '__name__', own)}) must be {parent.__name__} or a subclass "
                              f"of it (@dataclass class MySettings({parent.__name__}): ...)")


def _found_by_name(name: str, cls: type) -> bool:
    """Whether a fresh process finds ``cls`` by ``name``: an entry point of that name, or a class of the packages
    of :data:`MODULE_GROUP` (which register as they are imported)."""
    packages = [point.value for point in entry_points(group=MODULE_GROUP)]
    return entry_point_class(ENTRY_POINT_GROUP, name) is cls or any(
        cls.__module__ == package or cls.__module__.startswith(f"{package}.") for package in packages)


def _registered(name: str) -> Any:
    """The class registered under ``name``, or None; a name not registered yet first imports the packages of
    :data:`MODULE_GROUP` (hersd.engine.learners, and so torch), whose classes register as they are defined."""
    if name not in LEARNERS and "." not in name:
        for point in entry_points(group=MODULE_GROUP):
            point.load()
    return LEARNERS.get(name)


def entry_point_names() -> list[str]:
    """The names other packages' learners are declared under (entry points of :data:`ENTRY_POINT_GROUP`), sorted:
    each a ``learner=<name>`` choice beside conf/learner/'s (:func:`hersd.contract.compose.register_train_schema`)."""
    return declared_names(ENTRY_POINT_GROUP)


def typed_instead(choice: str) -> str | None:
    """What to type for ``learner=<choice>`` (a value, or a sweep's comma list) naming a class by its path, which
    no config of the group can hold: ``learner._target_=<choice>`` for one class, ``learner.name=<choice>`` for a
    list (``learner.name`` takes names and class paths alike); None when no item is a path."""
    if not any("." in item for item in choice.split(",")):
        return None
    return f"learner.name={choice}" if "," in choice else f"{TARGET_KEY}={choice}"


def recorded_name(cls: type) -> str:
    """The name a learner class's runs record (``learner.name`` of their logs): the ``NAME`` it declares itself
    (not one it inherits: a subclass of TD3 is not TD3), else its import path."""
    return cls.__dict__.get("NAME") or f"{cls.__module__}.{cls.__qualname__}"
