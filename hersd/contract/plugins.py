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
    "schedule") if its module is not found, fails as it is imported, or lacks it."""
    module, _, name = path.rpartition(".")
    if not module:
        raise ConfigError(f"{what} class {path}: give its import path, <module>.<Class>")
    try:
        found = importlib.import_module(module)
    except ModuleNotFoundError as err:
        if err.name is None or not (module == err.name or module.startswith(f"{err.name}.")):
            raise ConfigError(_failed(what, path, module, err)) from None  # the module found, one it imports not
        raise ConfigError(f"{what} class {path} cannot be imported ({err}); is its module on PYTHONPATH?") from None
    except (Exception, SystemExit) as err:  # the module's own code failed: a SyntaxError, an error it raises, or
        # a script's sys.exit() (which would end a report, or stop its worker)
        raise ConfigError(_failed(what, path, module, err)) from None
    found = getattr(found, name, None)
    if isinstance(found, types.ModuleType) or found is None and _is_module(path):
        raise ConfigError(f"{what} class {path}: {path} is a module; give <module>.<Class>")
    if found is None:
        raise ConfigError(f"{what} class {path} cannot be imported (module {module!r} has no attribute {name!r}); "
                          "is the class's name right?")
    return found


def _failed(what: str, path: str, module: str, err: BaseException) -> str:
    """The line for a module that failed as it was imported: the error, where in the module (a SyntaxError's own
    text names the line), and the fix."""
    spec = _spec(module)
    own = [frame for frame in traceback.extract_tb(err.__traceback__) if spec and frame.filename == spec.origin]
    at = f" at {own[-1].filename}:{own[-1].lineno}" if own and not isinstance(err, SyntaxError) else ""
    text = " ".join(str(err).split())
    return f"{what} class {path}: importing {module} raised {type(err).__name__}: {text}{at}; fix that module"


def _spec(module: str) -> Any:
    """The module's import spec, None if there is none (or its parent is no package)."""
    try:
        return importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None


def _is_module(path: str) -> bool:
    return _spec(path) is not None
