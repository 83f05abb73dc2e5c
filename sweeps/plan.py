"""What a sweep runs, and in which order: its grid (or stages of grids) expanded into runs.

A grid is ``hydra.sweeper.params``, a mapping from override keys to comma lists (Hydra's basic sweeper syntax),
expanded as the cartesian product with the command line's overrides. It may instead be a list of *stages*, run one
after another, each a grid or a list of grids:

    params:
      - [{task: pick_and_place, schedule: "constant,paper_linear_025", seed: "range(0,5)"},
         {task: push, schedule: "constant,paper_linear_025", seed: "range(5,10)"}]
      - {task: pick_and_place, schedule: paper_exp_025, seed: "range(0,5)"}

Runs go **seed by seed**: within a stage every arm's first seed comes before any arm's second (a grid's n-th seed is
the n-th value its ``seed`` takes; the grids of a stage take turns, in their order, within each seed). Launched one
per core in that order, a sweep stopped at any point leaves every arm with seeds in equal number (one apart at
most), not a few arms complete and the rest missing. A run named twice is planned once, where it first appears.

``seeds=N`` sweeps ``seed`` over 0..N-1 in every grid that sets no ``seed`` of its own, unless the command line sets
``seed``: ``hersd-sweep task=reach seeds=3`` is three runs; ``seeds=`` and ``seed=`` on one command line are refused
(one line, exit 2), not one silently dropped.

A sweep that trains here skips, one line each, the runs this machine cannot train (``precision=bf16`` on a CPU
without bf16 instructions) and trains the rest; one that can train none of them is refused (:func:`trainable_here`).

Every run is composed and checked before any starts. Hydra composes a config per distinct set of group choices
(``task=push``, ``schedule=linear``); a run's other overrides (``seed=0``, ``schedule.beta1=0.25``) are applied to a
copy of it as Hydra applies them (:class:`JobConfigs`): the 300 runs of ``+grid=beta`` need 3 compositions, not 300.
"""

from __future__ import annotations

import copy
import json
import pickle
import time
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hydra.errors import HydraException
from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException

from hersd.contract.compose import (explain_config_error, null_group, open_schedule, register_schema,
                                   register_train_schema)
from hersd.contract.config import TrainConfig, to_train_config
from hersd.contract.errors import ConfigError, DiskFullError
from hersd.contract.cores import available_cores
from hersd.contract.runspec import RunSpec, resolve
from sweeps.hydra_private import apply_value_overrides, basic_sweeper_class, group_test, grid_overrides


@dataclass
class SweepConfig(TrainConfig):
    seeds: int = 5  # a sweep that sets no ``seed`` sweeps it over range(seeds)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.check_seeds(self.seeds)

    @staticmethod
    def check_seeds(seeds: int) -> None:
        """ConfigError unless ``seeds`` >= 1: the sweep's own setting, which no run of it holds."""
        if seeds < 1:
            raise ConfigError(f"seeds must be >= 1, got {seeds}")


SWEEP_ONLY_KEYS = ("hydra", "seeds")  # a sweep's config keys that are no setting of its runs
SPECS_NAME = "specs.pkl"  # in the sweep's folder: its jobs' resolved runs (save_specs)
PLAN_NAME = "sweep.json"  # in the sweep's folder: how many runs it launched, and when (save_specs)


class SweepError(RuntimeError):
    """A sweep cannot start (bad input, e.g. a run's config is invalid: exit code 2) or ended
    with failed runs (exit code 1)."""

    def __init__(self, message: str, exit_code: int):
        super().__init__(message)
        self.exit_code = exit_code


@dataclass(frozen=True)
class PlannedRun:
    job: list[str]  # the run's overrides: ``hersd-sweep <job>`` is the one-run sweep of it
    spec: RunSpec  # the run, resolved once (hersd.contract.runspec)

    @property
    def epochs(self) -> int:
        return self.spec.config.epochs

    @property
    def machine(self) -> tuple[str, str]:
        """(device, precision): what it asks of the machine that trains it."""
        return self.spec.machine


def register_schemas() -> None:
    """``train_schema`` and ``sweep_schema`` (which conf/sweep.yaml lists first)."""
    register_train_schema()
    register_schema("sweep_schema", open_schedule(SweepConfig))


# ``${hersd_cores:}``: this process's cores, the local launcher's n_jobs (conf/hydra/launcher/local.yaml);
# registered on import, so in the sweep and in every job process that unpickles a job of it
OmegaConf.register_new_resolver("hersd_cores", available_cores, replace=True)


def job_train_config(cfg: DictConfig) -> TrainConfig:
    """A composed sweep job config (with or without its ``hydra`` node) -> its TrainConfig, validated once (the
    sweep's own keys, ``seeds`` and ``hydra``, left out)."""
    values = OmegaConf.to_container(cfg, resolve=True)
    for key in SWEEP_ONLY_KEYS:
        values.pop(key, None)
    return to_train_config(OmegaConf.merge(OmegaConf.structured(TrainConfig), values))


def launched(run: PlannedRun, threads: int | None) -> tuple[tuple[str, ...], RunSpec]:
    """(its job's overrides, its spec) of a run as launched: with ``threads=<threads>`` (a share of the cores,
    logged, not part of its identity) unless ``threads`` is None or its job sets threads itself."""
    if threads is None or any(override.split("=", 1)[0].lstrip("+") == "threads" for override in run.job):
        return tuple(run.job), run.spec
    return (*run.job, f"threads={threads}"), run.spec.with_threads(threads)


def save_specs(sweep_dir: Path, specs: dict[tuple[str, ...], RunSpec], runs: int) -> None:
    """The resolved runs of a sweep's jobs (job overrides -> spec), for the jobs to take (:func:`job_spec`), and its
    plan (``runs`` launched, the start time), each written whole (:func:`hersd.contract.runlog.replace_file`). A full
    disk is a SweepError (exit 2, one line: the file, the bytes it needs); no file left, nor the folder if empty."""
    from hersd.contract.runlog import replace_file

    files = {SPECS_NAME: pickle.dumps(specs), PLAN_NAME: json.dumps({"runs": runs, "start": time.time()}).encode()}
    try:
        for name, data in files.items():
            replace_file(sweep_dir / name, data, sync=False)
    except DiskFullError as err:
        for name in files:
            (sweep_dir / name).unlink(missing_ok=True)
        with suppress(OSError):  # not empty: another sweep's files (a sweep.dir given twice)
            sweep_dir.rmdir()
        raise SweepError(f"{err}; nothing ran yet", exit_code=2) from None


def job_spec(cfg: DictConfig, sweep_dir: Path, job: list[str]) -> RunSpec:
    """A sweep job's run as its sweep resolved it (:func:`save_specs`): nothing resolved again; a job launched
    without one (the file gone) resolves its composed ``cfg``."""
    try:
        return pickle.loads((sweep_dir / SPECS_NAME).read_bytes())[tuple(job)]
    except (OSError, KeyError):
        return resolve(job_train_config(cfg))


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
    """The ``seed=`` value a job's overrides set (the last one), None if they set none; SweepError (one line)
    for ``~seed``, which would leave a run without its seed."""
    keys = [(override.partition("=")[0], override.partition("=")[2]) for override in job]
    if any(key == "~seed" for key, _ in keys):
        raise SweepError("~seed deletes the runs' seed: give seed=N (or seeds=N for seeds 0..N-1) instead",
                         exit_code=2)
    values = [value for key, value in keys if key.lstrip("+") == "seed"]
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


def with_seeds(grid: dict[str, str], arguments: list[str], seeds: int) -> dict[str, str]:
    """The grid, sweeping ``seed`` over range(seeds) unless it or the command line sets ``seed``."""
    if seed_of(arguments) is not None or any(key.lstrip("+~") == "seed" for key in grid):
        return grid
    return {**grid, "seed": f"range({seeds})"}


class JobConfigs:
    """Each job's composed config (without its ``hydra`` node), equal to the one Hydra composes for
    it (``load_sweep_config``) at a fraction of the cost: Hydra composes once per distinct set of
    group overrides (and hydra.* ones); the job's value overrides are applied to a copy of that."""

    def __init__(self, sweeper: Any, parser: Any) -> None:
        self.loader = sweeper.hydra_context.config_loader
        self.sweep_config = sweeper.config
        self.parser = parser
        self.is_group = group_test(self.loader, sweeper.config)
        self.parsed: dict[str, tuple[Any, bool]] = {}  # override -> (Hydra's parse, a value override?)
        self.composed: dict[tuple[str, ...], DictConfig] = {}

    def parse(self, line: str) -> tuple[Any, bool]:
        """An override -> (Hydra's parse of it, whether it is a value override), as Hydra's defaults
        list tells them apart (its ``Overrides``); parsed once, as jobs share most of theirs."""
        if line not in self.parsed:
            override = self.parser.parse_overrides([line])[0]
            is_value = isinstance(override.value(), dict) or not self.is_group(override.key_or_group)
            self.parsed[line] = override, is_value and not override.is_hydra_override()
        return self.parsed[line]

    def config(self, job: list[str]) -> DictConfig:
        """The job's config, as :func:`job_train_config` reads it."""
        parsed = [self.parse(line) for line in job]
        values = [override for override, is_value in parsed if is_value]
        choices = [override for override, is_value in parsed if not is_value]
        key = tuple(override.input_line for override in choices)
        if said := null_group(list(key)):
            raise ConfigError(said)
        if key not in self.composed:
            composed = self.loader.load_sweep_config(self.sweep_config, list(key))
            with open_dict(composed):
                del composed["hydra"]
            self.composed[key] = composed
        cfg = copy.deepcopy(self.composed[key])
        apply_value_overrides(values, cfg)
        return cfg


def plan_runs(sweeper: Any, arguments: list[str]) -> dict[Path, PlannedRun]:
    """The sweep's runs, composed and checked, in launch order: stage by stage, seed by seed
    -> run dir -> its job. An invalid run config stops the sweep (SweepError, exit code 2)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create(config_loader=sweeper.hydra_context.config_loader)
    for override in parser.parse_overrides(arguments):
        if override.key_or_group == "grid" and override.is_sweep_override():  # Hydra would read no grid's params
            raise SweepError(f"{override.input_line}: a sweep runs one grid; run hersd-sweep once per grid",
                             exit_code=2)
        if override.key_or_group == "seeds" and seed_of(arguments) is not None:  # seed= would win in silence
            raise SweepError(f"{override.input_line} with seed={seed_of(arguments)}: give seed=N (or seed=a,b) for "
                             "those seeds, or seeds=N for seeds 0..N-1, not both", exit_code=2)
    seeds = int(sweeper.config.seeds)
    jobs = [job for stage in grid_stages(sweeper.grid)
            for job in seed_by_seed([expand(with_seeds(grid, arguments, seeds), arguments, parser) for grid in stage])]
    if not jobs:
        raise SweepError("the sweep expands to no runs; give each swept key at least one value", exit_code=2)
    configs = JobConfigs(sweeper, parser)
    planned: dict[Path, PlannedRun] = {}
    for job in jobs:
        try:
            spec = resolve(job_train_config(configs.config(job)))
            if spec.config.run_dir is not None and len(jobs) > 1:  # each run would be planned into the first's folder
                raise SweepError(f"run_dir={spec.config.run_dir} would put the sweep's {len(jobs)} runs in one folder; "
                                 "leave it out: each run gets its own under results_dir", exit_code=2)
            planned.setdefault(spec.folder, PlannedRun(job, spec))
        except (ConfigError, HydraException, OmegaConfBaseException) as err:  # e.g. a swept value no config names
            said = explain_config_error(err, what="sweep setting", see="hersd-sweep --help")
            raise SweepError(f"run [{' '.join(job)}]: {said}", exit_code=2) from None
    return planned


def refused_here(machines: set[tuple[str, str]]) -> dict[tuple[str, str], str]:
    """(device, precision) -> the one line saying why this machine cannot train runs of it (e.g. ``precision=bf16``
    on a CPU without bf16 instructions: :func:`hersd.engine.resources.check_machine`), for each it cannot train."""
    from hersd.engine.resources import check_machine  # torch: only for a sweep that trains here

    refused = {}
    for device, precision in sorted(machines):
        try:
            check_machine(device, precision)
        except ConfigError as err:
            refused[(device, precision)] = str(err)
    return refused


def trainable_here(planned: dict[Path, PlannedRun], states: dict[Path, str]) -> tuple[dict[Path, PlannedRun],
                                                                                       list[str]]:
    """The planned runs this machine can train or that are complete, and a line for each other run, skipped
    (``sweep: skipped <dir>: <why>``), so a campaign whose first stage needs bf16 goes on to the next on a CPU
    without it. SweepError (exit 2, the reason) when it can train none of the runs left to do."""
    refused = refused_here({run.machine for directory, run in planned.items() if states[directory] != "complete"})
    skipped = [directory for directory, run in planned.items()
               if states[directory] != "complete" and run.machine in refused]
    if skipped and len(skipped) == sum(state != "complete" for state in states.values()):
        raise SweepError(refused[min(refused)], exit_code=2)
    return ({directory: run for directory, run in planned.items() if directory not in skipped},
            [f"sweep: skipped {directory}: {refused[planned[directory].machine]}" for directory in skipped])
