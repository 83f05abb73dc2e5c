"""The Hydra internals hersd-sweep relies on, in one place (tests/test_hydra_private.py fails
when a Hydra release changes them; hydra-core is pinned in pyproject.toml).

- :func:`basic_sweeper_class`: Hydra's grid sweeper, which the ``runstore`` sweeper extends,
  only importable from ``hydra._internal``. Hydra's plugin scan re-executes that module, so the
  class is looked up when the plugin module runs, never cached here (a class imported before
  the scan makes ``super()`` fail inside Hydra).
- :func:`grid_overrides`: the grid of ``hydra.sweeper.params`` as override strings
  (``BasicSweeper._parse_config``), which the sweeper joins with the command line's.
- :func:`job_error`: the exception of a failed job (``JobReturn._return_value``; the public
  ``return_value`` re-raises it instead).
"""

from __future__ import annotations

import importlib
from typing import Any

from hydra.core.utils import JobReturn


def basic_sweeper_class() -> type:
    """``hydra._internal.core_plugins.basic_sweeper.BasicSweeper`` as the module holds it now."""
    return importlib.import_module("hydra._internal.core_plugins.basic_sweeper").BasicSweeper


def grid_overrides(sweeper: Any) -> list[str]:
    """``hydra.sweeper.params`` as overrides, e.g. ``["seed=range(5)", "task=push"]``."""
    return sweeper._parse_config()


def job_error(result: JobReturn) -> Any:
    """What a failed job raised (its exception object)."""
    return result._return_value
