"""The Optuna internals hersd-search relies on, in one place (tests/test_search_optuna_private.py fails when an
Optuna release changes them), as :mod:`sweeps.hydra_private` keeps Hydra's.

- :func:`seed_tpe`: a TPE sampler's random generators (its own and its random sampler's, which draws the
  startup trials), reseeded before each trial by :class:`sweeps.search.study.TrialSeededTPE`.
- :func:`fixed_params`: the parameters ``Study.enqueue_trial`` gave a trial (its system attribute
  ``fixed_params``), which a WAITING trial holds before any is drawn.
"""

from __future__ import annotations

from typing import Any

from optuna.samplers import TPESampler
from optuna.trial import FrozenTrial

FIXED_PARAMS = "fixed_params"  # the system attribute enqueue_trial stores a trial's parameters in


def seed_tpe(sampler: TPESampler, seed: int) -> None:
    """Reseed ``sampler``'s draws (TPE's and its startup trials') with ``seed``."""
    sampler._rng.rng.seed(seed)
    sampler._random_sampler._rng.rng.seed(seed)


def fixed_params(trial: FrozenTrial) -> dict[str, Any]:
    """The parameters a trial was enqueued with ({} if none)."""
    return dict(trial.system_attrs.get(FIXED_PARAMS, {}))
