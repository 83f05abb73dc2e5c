"""Classes found by name for the registries of schedules and learners: those other packages declare as entry
points (``step = my_pkg.schedules:Step`` in a group), and any class by its import path (Hydra's ``_target_``
convention: ``my_pkg.schedules.Step``)."""

from __future__ import annotations

import importlib
import importlib.util
import traceback
import types
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
        found = importlib.import_module(module)
    except (ImportError, ValueError) as err:
        raise ConfigError(f"{what} class {path} cannot be imported ({err}); is its module on PYTHONPATH?") from None
    except Exception as err:  # the module's own code failed: a SyntaxError (its text names the line), a raise
        frames = traceback.extract_tb(err.__traceback__)
        at = "" if isinstance(err, SyntaxError) or not frames else f" at {frames[-1].filename}:{frames[-1].lineno}"
        raise ConfigError(f"{what} class {path}: importing {module} raised {type(err).__name__}: {err}{at}; "
                          "fix that module") from None
    found = getattr(found, name, None)
    if isinstance(found, types.ModuleType) or found is None and _is_module(path):
        raise ConfigError(f"{what} class {path}: {path} is a module; give <module>.<Class>")
    if found is None:
        raise ConfigError(f"{what} class {path} cannot be imported (module {module!r} has no attribute {name!r}); "
                          "is its module on PYTHONPATH?")
    return found


def _is_module(path: str) -> bool:
    try:
        return importlib.util.find_spec(path) is not None
    except (ImportError, ValueError):  # its parent is no package
        return False
