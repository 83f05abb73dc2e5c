"""One resolved run: :func:`resolve` turns a validated :class:`TrainConfig` into a frozen :class:`RunSpec` once,
and every layer below takes the spec (the CLI, a sweep's planner and its jobs, a search trial, ``train``), so
none of them validates the settings, hashes the identity, derives the folder or computes the schedule's rates
again. Light (no torch): a sweep resolves hundreds of runs with it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.runstore import folder_path, identity_hash, run_identity
from hersd.contract.schedules.base import Schedule, check_rates


@dataclass(frozen=True)
class RunSpec:
    """A run as every layer below the command line sees it, made once by :func:`resolve`.

    ``config`` is the validated settings (read, never changed); ``identity`` what the run's hash covers
    (:func:`hersd.contract.runstore.run_identity`) and ``run_id`` that hash (8 hex digits); ``folder`` the run's
    directory; ``rates`` eps(k) of a fixed schedule for k = 1..min(K, CHECKED_UP_FRONT), shape (K,) for any run
    of the paper's scale, each checked in [0, 1] (None when the schedule adapts to the run: its rate is known
    at its epoch); ``machine`` (device, precision), what it asks of the machine that trains it.
    """

    config: TrainConfig
    identity: dict[str, Any]
    run_id: str
    folder: Path
    rates: tuple[float, ...] | None
    machine: tuple[str, str]

    def rate(self, epoch: int, train_success: Sequence[float] = ()) -> float:
        """eps(epoch): the rate resolved up front, else (an adaptive schedule, or an epoch past those checked up
        front) the schedule's checked rate now."""
        if self.rates is not None and epoch <= len(self.rates):
            return self.rates[epoch - 1]
        return self.config.schedule.checked_rate(epoch, self.config.epochs, train_success)

    def mean_rate(self) -> float | None:
        """mu_eps, the mean of eps(k) over k = 1..K (None when the schedule adapts): the schedule's closed form where
        it has one (eq. 10), else the mean of the rates resolved up front (its default, to the bit)."""
        schedule, epochs = self.config.schedule, self.config.epochs
        closed_form = type(schedule).exact_mean_rate is not Schedule.exact_mean_rate
        if self.rates is None or len(self.rates) < epochs or closed_form:
            return schedule.exact_mean_rate(epochs)
        return float(np.mean(np.array(self.rates, dtype=float)))

    def check_unchanged(self) -> None:
        """ConfigError (one line) if its config was edited after :func:`resolve` (``spec.config.seed = 7``): the
        identity, hash, folder and rates resolved then would no longer be the run's."""
        identity = run_identity(self.config)
        if identity != self.identity or folder_path(self.config, identity_hash(identity)) != self.folder:
            changed = sorted(key for key in {**identity, **self.identity}
                             if identity.get(key) != self.identity.get(key)) or ["results_dir"]
            raise ConfigError(f"the run's settings were changed after it was resolved ({', '.join(changed)}); a spec "
                              "is made once: resolve(config) the changed config instead")

    def with_threads(self, threads: int) -> RunSpec:
        """The same run on ``threads`` intra-op threads (a sweep's share of the cores): threads are logged, not part
        of the identity, so nothing else is resolved again."""
        config = copy.copy(self.config)
        config.threads = str(threads)
        return RunSpec(config, self.identity, self.run_id, self.folder, self.rates, self.machine)


def resolve(config: TrainConfig) -> RunSpec:
    """The frozen spec of a validated config: its identity and hash, its folder, its schedule's rates (checked:
    ScheduleRateError, one line, for one outside [0, 1]) and its machine needs, each computed here once."""
    identity = run_identity(config)
    run_id = identity_hash(identity)
    rates = check_rates(config.schedule, config.epochs)
    return RunSpec(config, identity, run_id, folder_path(config, run_id), rates, (config.device, config.precision))

