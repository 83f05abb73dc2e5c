"""What every worker of a search receives (:class:`SearchPlan`) and how a trial's run configs
are made from it.

The training config is composed once, from the command's training overrides, into
``plan.base``; a trial's run is ``base`` with the trial's schedule, ``algo.lambda_h`` when
searched, the seed and the thread count replaced (:func:`hersd.contract.study.trial_config`). Its
directory and hash are those ``hersd-train`` gives for the equivalent overrides
(:func:`hersd.contract.study.param_overrides`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from hersd.contract.compose import compose_train, explain_config_error
from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.cores import resolve_threads
from hersd.contract.runstore import check_writable, config_hash
from hersd.contract.runspec import resolve
from hersd.contract.schedules import DEFAULT, settle
from hersd.contract.schedules.base import ScheduleRateError, check_rates
from hersd.contract.study import (REWARD_PARAM, SEARCH_FOLDER, StudySettings, default_storage, kind_params,
                                  schedule_config, trial_config)
from sweeps.search.storage import resolve_storage
from sweeps.search.config import SearchConfig, enqueued_kind
from sweeps.search.space import box_points, space_bounds, space_record

# Training keys a search override may not set: the search chooses them, or (run_dir) every
# run of every trial would share one directory.
SEARCHED_KEYS = ("seed", "schedule", "run_dir")


@dataclass
class SearchPlan:
    """Everything a worker needs (picklable: it crosses process and SLURM boundaries)."""

    search: SearchConfig
    base: TrainConfig  # the composed training config every run of every trial starts from
    train_overrides: list[str]  # the command's training overrides (recorded with the study and each run)
    study_name: str
    storage: str  # the storage spec workers open (see hersd.contract.study)
    settings: StudySettings  # what the objective depends on; stored with the study and checked on load
    study_dir: str  # <results_dir>/search/<study>/: SLURM job logs

    @property
    def epochs(self) -> int:
        """K, the epochs of every run."""
        return self.base.epochs


def refuse_searched_keys(train_overrides: list[str], search: SearchConfig) -> None:
    """ConfigError if a training override sets what the search chooses (seed, schedule*, run_dir, lambda_h)."""
    taken = SEARCHED_KEYS + ((f"algo.{REWARD_PARAM}",) if search.space.lambda_h is not None else ())
    for override in train_overrides:
        key = override.split("=", 1)[0].lstrip("+~")
        if key in taken or key.startswith("schedule."):
            raise ConfigError(f"{override}: {key} is set by the search for each run (search.space, search.seeds, "
                              f"search.first_seed); remove it")


def run_threads(base: TrainConfig, concurrent_runs: int) -> str:
    """A worker's runs' thread count (a str, as TrainConfig.threads): the user's N, else the cores / concurrent_runs."""
    # Resolved in the worker's process: on a SLURM node the cores are the job's allocation.
    return base.threads if base.threads != "auto" else str(resolve_threads("auto", concurrent_runs))


def study_settings(search: SearchConfig, base: TrainConfig) -> StudySettings:
    """What the objective depends on."""
    # The training config is hashed with the searched fields neutralised, so a study's name
    # stays the same while ranges change, and changes with any other training setting.
    neutral = replace(base, seed=0, schedule=DEFAULT())
    if search.space.lambda_h is not None:
        neutral = replace(neutral, algo=replace(neutral.algo, lambda_h=1.0))
    return StudySettings(objective=search.objective, metric=search.metric, seeds=search.seeds,
                         first_seed=search.first_seed, epochs=base.epochs, task=base.task.name,
                         algo=base.algo.name, train_config=config_hash(neutral))


def check_trial_configs(search: SearchConfig, base: TrainConfig) -> None:
    """Build the runs of the enqueued sets and ranges' ends (first, last seed), so bad ones stop us now."""
    last_seed = search.first_seed + search.seeds - 1
    kinds = list(search.space.kinds)
    probes = [(f"search.enqueue[{i}]", {**params, "kind": enqueued_kind(params, kinds)})
              for i, params in enumerate(search.enqueue)]
    for kind in search.space.kinds:
        for end in ("low", "high"):
            params = {"kind": kind, **{name: getattr(space_bounds(search.space, kind, name), end)
                                       for name in kind_params(kind)}}
            if search.space.lambda_h is not None:
                params[REWARD_PARAM] = getattr(search.space.lambda_h, end)
            probes.append((f"search.space ({kind}, {end} ends)", params))
    for where, params in probes:
        for seed in (search.first_seed, last_seed):
            try:
                resolve(trial_config(base, params, seed))
            except ScheduleRateError as err:  # the class's rate, or these settings of it
                other = where if where.startswith("search.enqueue") else "search.space.ranges"
                raise ConfigError(f"{where}: {err}, or change {other}") from None
            except ConfigError as err:
                raise ConfigError(f"{where}: {err}") from None
    for kind in kinds:
        check_box(kind, search, base.epochs)


def check_box(kind: str, search: SearchConfig, epochs: int) -> None:
    """ConfigError (one line) naming the first combination of the searched box (corners, then a grid) at which
    ``kind`` is no schedule of ``epochs`` epochs, e.g. a rate outside [0, 1]: a trial would draw near it."""
    for point in box_points(search.space, kind):
        try:
            check_rates(settle(schedule_config({"kind": kind, **point}), epochs), epochs)
        except ConfigError as err:
            shown = ", ".join(f"{name}={value:.6g}" for name, value in point.items())
            raise ConfigError(f"search.space: {kind} at {shown}, within the searched ranges: {err}; narrow "
                              f"search.space.ranges to settings it accepts together") from None


def make_plan(search: SearchConfig, train_overrides: list[str], search_name: str = "default") -> SearchPlan:
    """Compose the base training config once; check it and derive the study's name, storage and settings."""
    # search_name (the conf/search file) and the search space (kinds, ranges) are part of the default study
    # name: another file or another space starts another study; n_trials and the workers do not.
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    refuse_searched_keys(train_overrides, search)
    try:
        base = compose_train(train_overrides)
    except (HydraException, OmegaConfBaseException) as err:  # an unknown choice or key: one line, as hersd-train's
        raise ConfigError(explain_config_error(err)) from None
    if not any(override.split("=", 1)[0].lstrip("+~") == "quiet" for override in train_overrides):
        base = replace(base, quiet=True)  # workers' per-epoch lines would interleave
    steps = search.seeds * base.epochs
    if search.pruner.kind == "hyperband" and search.pruner.min_resource > steps:
        raise ConfigError(f"search.pruner.min_resource ({search.pruner.min_resource}) exceeds the steps of a trial "
                          f"(seeds x epochs = {steps})")
    check_trial_configs(search, base)
    storage = resolve_storage(search.storage) if search.storage else None
    check_writable(Path(base.results_dir))  # the runs go here, the default storage below it
    search_dir = Path(base.results_dir).resolve() / SEARCH_FOLDER
    settings = study_settings(search, base)
    identity = {**asdict(settings), "space": space_record(search.space)}  # what it measures, over what it draws
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:8]
    study_name = search.study_name or f"{base.task.name}-{base.algo.name}-{search_name}-{digest}"
    storage = storage or default_storage(base.results_dir, study_name)
    return SearchPlan(search=search, base=base, train_overrides=list(train_overrides), study_name=study_name,
                      storage=storage, settings=settings,
                      study_dir=str(search_dir / study_name))
