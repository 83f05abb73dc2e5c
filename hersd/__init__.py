"""hersd: DDPG + hindsight experience replay with a decaying relabel rate.

Two subpackages: :mod:`hersd.contract`, what the run engine, the sweeps and the analysis share (config schema,
errors, schedules, tasks, run log, run folder, study encoding; neither torch nor MuJoCo), and :mod:`hersd.engine`,
one training run, which imports the contract and never the reverse. Importing the package is cheap.

A module's path from before that split (:data:`MOVED`, e.g. ``hersd.runlog``, ``hersd.schedules.linear``) still
imports until hersd :data:`OLD_PATHS_REMOVED_IN`, with a ``FutureWarning`` naming its new path: an old module is the
very module of its new path (so classes, ``isinstance``, ``_target_`` strings and pickles that name the old path
keep working); an old package (``hersd.schedules``) is a stand-in whose names are the new package's, so the new
packages are never changed by it (``hersd.envs.tasks`` is the contract's, ``hersd.engine.envs`` stays without one).
The finder answering those names is the last of ``sys.meta_path``: asked only of names no module of the tree has.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__version__ = "0.1.0"
OLD_PATHS_REMOVED_IN = "0.2.0"  # the release without MOVED: its old paths then fail to import

# The path of each module (a package: with its submodules) before the split -> its path now.
MOVED = {
    "hersd.errors": "hersd.contract.errors",
    "hersd.envs.tasks": "hersd.contract.tasks",
    "hersd.runlog": "hersd.contract.runlog",
    "hersd.schedules": "hersd.contract.schedules",
    "hersd.learner_registry": "hersd.contract.learner_registry",
    "hersd.config": "hersd.contract.config",
    "hersd.compose": "hersd.contract.compose",
    "hersd.runstore": "hersd.contract.runstore",
    "hersd.study": "hersd.contract.study",
    "hersd.resources": "hersd.engine.resources",  # its threads=auto rule is hersd.contract.cores now
    "hersd.train": "hersd.engine.train",
    "hersd.run_state": "hersd.engine.run_state",
    "hersd.bias": "hersd.engine.bias",
    "hersd.render": "hersd.engine.render",
    "hersd.denormals": "hersd.engine.denormals",
    "hersd.cli": "hersd.engine.cli",
    "hersd.envs": "hersd.engine.envs",
    "hersd.replay": "hersd.engine.replay",
    "hersd.learners": "hersd.engine.learners",
}


def moved_to(name: str) -> str | None:
    """The path a module of the old layout has now (``hersd.schedules.linear`` -> ``hersd.contract.schedules.linear``);
    None for a name that did not move."""
    old = max((old for old in MOVED if name == old or name.startswith(old + ".")), key=len, default=None)
    return None if old is None else MOVED[old] + name[len(old):]


def _warn(old: str, new: str) -> None:
    """The FutureWarning of importing ``old``, at the line that imports it (importlib's own frames are skipped)."""
    warnings.warn(f"{old} is {new} now: import {new} (the old path goes in hersd {OLD_PATHS_REMOVED_IN})",
                  FutureWarning, stacklevel=3)


def _old_package(old: str, package: types.ModuleType) -> types.ModuleType:
    """The stand-in of the moved package ``package`` under its old path ``old``: no ``__path__`` of the tree (so its
    submodules are asked of :class:`OldPaths`, never loaded twice); each name is the old child's or the package's."""
    stand_in = types.ModuleType(old, package.__doc__)
    stand_in.__path__ = []

    def __getattr__(name: str):
        if name.startswith("__"):  # the stand-in's own (no __file__: it is no file)
            raise AttributeError(f"module {old!r} has no attribute {name!r}")
        child = moved_to(f"{old}.{name}")
        try:
            is_module = importlib.util.find_spec(child) is not None
        except (ImportError, ValueError):
            is_module = False
        if not is_module:
            return getattr(package, name)
        _warn(f"{old}.{name}", child)
        module = sys.modules[f"{old}.{name}"] = importlib.import_module(child)
        setattr(stand_in, name, module)
        return module

    stand_in.__getattr__ = __getattr__
    stand_in.__dir__ = lambda: dir(package)
    return stand_in


class OldPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports an old path (warning once, naming its new one): a module as the module of its new path, a package as
    its stand-in."""

    def find_spec(self, name, path=None, target=None):  # noqa: ARG002 - the finder protocol's signature
        new = moved_to(name)
        if new is None:
            return None
        module = importlib.import_module(new)
        _warn(name, new)
        return importlib.util.spec_from_loader(name, self, is_package=hasattr(module, "__path__"))

    def create_module(self, spec):
        module = importlib.import_module(moved_to(spec.name))
        if hasattr(module, "__path__"):
            return _old_package(spec.name, module)
        spec.loader_state = module.__spec__  # the import system sets __spec__ to the old path's: put back below
        return module

    def exec_module(self, module):
        if module.__spec__.loader_state is not None:
            module.__spec__ = module.__spec__.loader_state

    def get_code(self, name):  # python -m <old path>
        return importlib.util.find_spec(moved_to(name)).loader.get_code(moved_to(name))


sys.meta_path.append(OldPaths())
