"""The Hydra internals hersd-sweep relies on, in one place (tests/test_hydra_private.py fails
when a Hydra release changes them; hydra-core is pinned in pyproject.toml).

- :func:`basic_sweeper_class`: Hydra's grid sweeper, which the ``runstore`` sweeper extends,
  only importable from ``hydra._internal``. Hydra's plugin scan re-executes that module, so the
  class is looked up when the plugin module runs, never cached here (a class imported before
  the scan makes ``super()`` fail inside Hydra).
- :func:`grid_overrides`: the grid of ``hydra.sweeper.params`` as override strings
  (``BasicSweeper._parse_config``), which the sweeper joins with the command line's.
- :func:`cap_local_workers`: the joblib launcher's settings as its ``launch`` hands them to joblib
  (``JoblibLauncher.joblib``), whose ``n_jobs`` the sweep lowers to its jobs' count.
- :func:`job_error`: the exception of a failed job (``JobReturn._return_value``; the public
  ``return_value`` re-raises it instead).
- :func:`group_test` and :func:`apply_value_overrides`: how Hydra's composition tells a group
  override (``task=push``) from a value override (``seed=0``), in the sweep's search path
  (``ConfigLoaderImpl._parse_overrides_and_create_caching_repo``), and how it applies the
  latter to a composed config (``ConfigLoaderImpl._apply_overrides_to_config``): the sweep
  plans its runs with them (:class:`sweeps.plan.JobConfigs`).
"""

from __future__ import annotations

import importlib
from typing import Any, Callable

from hydra.core.override_parser.types import Override
from hydra.core.utils import JobReturn
from omegaconf import DictConfig, OmegaConf


def basic_sweeper_class() -> type:
    """``hydra._internal.core_plugins.basic_sweeper.BasicSweeper`` as the module holds it now."""
    return importlib.import_module("hydra._internal.core_plugins.basic_sweeper").BasicSweeper


def grid_overrides(sweeper: Any) -> list[str]:
    """``hydra.sweeper.params`` as overrides, e.g. ``["seed=range(5)", "task=push"]``."""
    return sweeper._parse_config()


def cap_local_workers(launcher: Any, jobs: int) -> None:
    """At most ``jobs`` workers for a joblib launcher (its ``joblib`` settings; other launchers are left as they
    are): loky starts every worker at once, and one that never gets a job never learns that the sweep ended."""
    settings = getattr(launcher, "joblib", None)
    if settings is not None and int(settings.get("n_jobs") or 0) > jobs:
        settings["n_jobs"] = jobs


def job_error(result: JobReturn) -> Any:
    """What a failed job raised (its exception object)."""
    return result._return_value


def group_test(config_loader: Any, config: DictConfig) -> Callable[[str], bool]:
    """Whether a name (``task``, ``schedule.beta1``) is a config group in the search path of the
    sweep's ``config`` (its ``hydra.searchpath`` included), as Hydra's defaults list decides it."""
    hydra_overrides = OmegaConf.to_container(config.hydra.overrides.hydra)
    _, repository = config_loader._parse_overrides_and_create_caching_repo(config.hydra.job.config_name,
                                                                           hydra_overrides)
    return repository.group_exists


def apply_value_overrides(overrides: list[Override], cfg: DictConfig) -> None:
    """Apply parsed value overrides (``seed=0``, ``+key=v``, ``~key``) to a composed config, in place."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl._apply_overrides_to_config(overrides, cfg)
