"""hersd: DDPG + hindsight experience replay with a decaying relabel rate.

Two subpackages: :mod:`hersd.contract`, what the run engine, the sweeps and the analysis share (config schema,
errors, schedules, tasks, run log, run folder, study encoding; neither torch nor MuJoCo), and :mod:`hersd.engine`,
one training run, which imports the contract and never the reverse. Importing the package is cheap.

A module's path from before that split (:data:`MOVED`, e.g. ``hersd.runlog``, ``hersd.schedules.linear``) still
imports, as the very module of its new path: one module object under both names, so classes, ``isinstance``,
``_target_`` strings and pickled checkpoints that name the old path keep working.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

__version__ = "0.1.0"

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


class OldPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports an old path as the module of its new path (imported first if need be), not as a copy."""

    def find_spec(self, name, path=None, target=None):  # noqa: ARG002 - the finder protocol's signature
        return importlib.util.spec_from_loader(name, self) if moved_to(name) else None

    def create_module(self, spec):
        module = importlib.import_module(moved_to(spec.name))
        spec.loader_state = module.__spec__  # the import system sets __spec__ to the old path's: put back below
        return module

    def exec_module(self, module):
        old = module.__spec__.name
        module.__spec__ = module.__spec__.loader_state
        moved_elsewhere = {child.rpartition(".")[2] for child in MOVED if child.rpartition(".")[0] == old
                           and moved_to(child) != f"{module.__name__}.{child.rpartition('.')[2]}"}
        if moved_elsewhere and not hasattr(module, "__getattr__"):  # from hersd.envs import tasks (now contract's)
            def __getattr__(name):
                if name in moved_elsewhere:
                    return importlib.import_module(f"{old}.{name}")
                raise AttributeError(f"module {module.__name__!r} has no attribute {name!r}")
            module.__getattr__ = __getattr__

    def get_code(self, name):  # python -m <old path>
        return importlib.util.find_spec(moved_to(name)).loader.get_code(moved_to(name))


sys.meta_path.insert(0, OldPaths())
