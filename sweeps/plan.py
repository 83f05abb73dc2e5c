"""What a sweep runs, and in which order: its grid (or stages of grids) expanded into runs.

A grid is ``hydra.sweeper.params``, a mapping from override keys to comma lists (Hydra's basic
sweeper syntax), expanded as the cartesian product with the command line's overrides. It may
instead be a list of *stages*, run one after another, each a grid or a list of grids:

    params:
      - [{task: pick_and_place, schedule: "constant,paper_linear_025", seed: "range(0,5)"},
         {task: push, schedule: "constant,paper_linear_025", seed: "range(5,10)"}]
      - {task: pick_and_place, schedule: paper_exp_025, seed: "range(0,5)"}

Runs go **seed by seed**: within a stage every arm's first seed comes before any arm's second
(a grid's n-th seed is the n-th value its ``seed`` takes; the grids of a stage take turns, in
their order, within each seed). Launched one per core in that order, a sweep stopped at any
point leaves every arm with seeds in equal number (one apart at most), not a few arms complete
and the rest missing. A run named twice is planned once, where it first appears.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict

from hersd.compose import open_schedule, register_schema, register_train_schema
from hersd.config import ConfigError, TrainConfig, to_train_config
from hersd.resources import available_cores
from hersd.runstore import run_dir
from sweeps.hydra_private import basic_sweeper_class, grid_overrides


@dataclass
class SweepConfig(TrainConfig):
    seeds: int = 5  # grids sweep ``seed`` over range(seeds)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.seeds < 1:
            raise ConfigError(f"seeds must be >= 1, got {self.seeds}")


class SweepError(RuntimeError):
    """A sweep cannot start (bad input, e.g. a run's config is invalid: exit code 2) or ended
    with failed runs (exit code 1)."""

    def __init__(self, message: str, exit_code: int):
        super().__init__(message)
        self.exit_code = exit_code


@dataclass(frozen=True)
class PlannedRun:
    job: list[str]  # the run's overrides: ``hersd-sweep <job>`` is the one-run sweep of it
    epochs: int


def register_schemas() -> None:
    """``train_schema`` and ``sweep_schema`` (which conf/sweep.yaml lists first)."""
    register_train_schema()
    register_schema("sweep_schema", open_schedule(SweepConfig))


# ``${hersd_cores:}``: this process's cores, the local launcher's n_jobs (conf/hydra/launcher/local.yaml);
# registered on import, so in the sweep and in every job process that unpickles a job of it
OmegaConf.register_new_resolver("hersd_cores", available_cores, replace=True)


def job_train_config(cfg: DictConfig) -> TrainConfig:
    """A composed sweep job config (with or without its ``hydra`` node) -> its TrainConfig."""
    cfg = cfg.copy()
    if "hydra" in cfg:
        with open_dict(cfg):
            del cfg["hydra"]
    sweep_cfg = to_train_config(cfg)
    return TrainConfig(**{f.name: getattr(sweep_cfg, f.name) for f in fields(TrainConfig)})


def grid_stages(params: Any) -> list[list[dict[str, str]]]:
    """``hydra.sweeper.params`` (a grid, or a list of stages each a grid or a list of grids) ->
    stages, each a list of grids, each a plain ``{key: values}`` dict."""
    if isinstance(params, (DictConfig, ListConfig)):
        params = OmegaConf.to_container(params, resolve=True)
    if params is None or isinstance(params, dict):
        return [[params or {}]]
    stages = [stage if isinstance(stage, list) else [stage] for stage in params]
    if not stages or not all(stage and all(isinstance(grid, dict) for grid in stage) for stage in stages):
        raise SweepError("hydra.sweeper.params must be a grid (key: values) or a list of stages, each a grid "
                         "or a list of grids", exit_code=2)
    return stages


def seed_of(job: list[str]) -> str | None:
    """The ``seed=`` value a job's overrides set (the last one), None if they set none."""
    values = [override.split("=", 1)[1] for override in job if override.split("=", 1)[0].lstrip("+~") == "seed"]
    return values[-1] if values else None


def seed_by_seed(grids: list[list[list[str]]]) -> list[list[str]]:
    """The jobs of a stage's grids, each grid's in its own order, merged seed by seed: every
    grid's jobs of its first seed (grid after grid), then of its second, and so on."""
    keyed = []
    for number, jobs in enumerate(grids):
        seeds = list(dict.fromkeys(seed_of(job) for job in jobs))  # the grid's seeds in order of first use
        keyed += [((seeds.index(seed_of(job)), number, index), job) for index, job in enumerate(jobs)]
    return [job for _, job in sorted(keyed, key=lambda pair: pair[0])]


def expand(grid: dict[str, str], arguments: list[str], parser: Any) -> list[list[str]]:
    """One grid with the command line's overrides -> each run's overrides, as Hydra's basic sweeper
    expands them (the grid's keys first, a key given again on the command line taking its values)."""
    sweeper = basic_sweeper_class()(max_batch_size=None, params=grid)
    overrides = parser.parse_overrides(grid_overrides(sweeper) + list(arguments))
    return [list(job) for batch in sweeper.split_arguments(overrides, None) for job in batch]


def plan_runs(sweeper: Any, arguments: list[str]) -> dict[Path, PlannedRun]:
    """The sweep's runs, composed and checked, in launch order: stage by stage, seed by seed
    -> run dir -> its job. An invalid run config stops the sweep (SweepError, exit code 2)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create(config_loader=sweeper.hydra_context.config_loader)
    jobs = [job for stage in grid_stages(sweeper.grid)
            for job in seed_by_seed([expand(grid, arguments, parser) for grid in stage])]
    if not jobs:
        raise SweepError("the sweep expands to no runs; give each swept key at least one value", exit_code=2)
    planned: dict[Path, PlannedRun] = {}
    for job in jobs:
        job_cfg = sweeper.hydra_context.config_loader.load_sweep_config(sweeper.config, job)
        try:
            train_cfg = job_train_config(job_cfg)
            planned.setdefault(run_dir(train_cfg), PlannedRun(job, train_cfg.epochs))
        except ConfigError as err:
            raise SweepError(f"run [{' '.join(job)}]: {err}", exit_code=2) from None
    return planned
