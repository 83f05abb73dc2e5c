"""Classes found by name for the registries of schedules and learners: those other packages declare as entry
points (``step = my_pkg.schedules:Step`` in a group), and any class by its import path (Hydra's ``_target_``
convention: ``my_pkg.schedules.Step``)."""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any

from hersd.contract.errors import ConfigError


def entry_point_class(group: str, name: str) -> Any:
    """The object the entry point ``name`` of ``group`` declares, loaded; None if no package declares it."""
    found = entry_points(group=group, name=name)
    return next(iter(found)).load() if found else None


def entry_point_names(group: str) -> list[str]:
    """The names declared in the entry point ``group``, sorted."""
    return sorted({point.name for point in entry_points(group=group)})


def class_at(path: str, what: str) -> Any:
    """The object at the import path ``<module>.<Class>``; ConfigError (one line naming ``what``, e.g.
    "schedule") if its module cannot be imported or lacks it."""
    module, _, name = path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError, ValueError) as err:
        raise ConfigError(f"{what} class {path} cannot be imported ({err}); is its module on PYTHONPATH?") from None
