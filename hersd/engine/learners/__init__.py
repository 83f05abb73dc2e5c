"""The learners (docs/LEARNERS.md): one module per learner, each a class that declares what the run asks of it
(:mod:`hersd.engine.learners.base`), bound to its card, the module of the same name in :mod:`hersd.contract.learners`
(its name, its settings and whether it has a fast update, which the config reads without torch). Importing this
package imports every module in it, so every learner class is registered under its ``NAME``: :func:`learner_class`
finds it by ``learner=``, as it finds an entry point's (group ``hersd.learners``) or a class by its path
(``learner._target_``).
"""

from __future__ import annotations

import importlib
import pkgutil

from hersd.contract.learner_registry import LEARNERS
from hersd.engine.learners.base import GoalConditionedLearner, UpdateStats, learner_class

__all__ = ["LEARNERS", "GoalConditionedLearner", "UpdateStats", "learner_class"]

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")
