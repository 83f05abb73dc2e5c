"""Relabel-rate schedules: pure functions of the epoch index k (1..K) and the total K.

eps is the probability that a sampled transition's goal is replaced by a hindsight goal.

- constant:     eps(k) = eps                                  (HER: 0.8)
- linear:       eps(k) = 1 - beta1 * (k / K)                  (eq. 9 with beta2 = 0)
- exponential:  eps(k) = 1 - beta1 * (k / K) ** exp(beta2)    (eq. 9)
- success:      eps(k) = clip(1 - beta1 * s(k), eps_min, 1), s(k) = the mean train success
                of the last `window` epochs before k (fewer while k <= window; s(1) = 0): the
                rate follows the agent's progress instead of the epoch count (beyond the
                paper; its conclusion suggests the optimal decay need not be a function of
                the epoch)

mu_eps is the mean rate over the K epochs: exactly (eq. 10) or by the continuous
approximation 1 - beta1 / (1 + exp(beta2)) (eq. 11); a success schedule's mean rate is known only
once run (the mean of its logged rates). A schedule is anything with the attributes ``kind``,
``eps``, ``beta1``, ``beta2`` (and for ``success`` ``window``, ``eps_min``), e.g.
:class:`hersd.config.ScheduleConfig`.
This module imports neither torch nor the config, so every layer can use it.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

SCHEDULE_KINDS = ("constant", "linear", "exponential", "success")  # also the order of reports and tables
FIXED_KINDS = SCHEDULE_KINDS[:3]  # a function of the epoch alone (eq. 9), known before the run
# mu_eps between the HER paper's two best fixed rates (replay_k = 4 and 8): the seed paper's
# "optimal region" (its Fig. 12), drawn in the mu_eps and beta-plane figures.
MU_EPS_BAND = (0.8, 0.889)
# |beta2| beyond this makes eq. 9 a step function in float64 (and exp(beta2) overflows past ~709).
BETA2_LIMIT = 50.0


def effective_beta2(kind: str, beta2: float) -> float:
    """The beta2 of eq. 9 that a schedule of this kind uses: 0 for ``linear``, beta2 otherwise."""
    return 0.0 if kind == "linear" else float(beta2)


def decay_rate(k: int | np.ndarray, total_epochs: int, beta1: float, beta2: float) -> float | np.ndarray:
    """eq. 9: 1 - beta1 * (k / K) ** exp(beta2); k may be an int or an array of epoch indices."""
    return 1.0 - beta1 * (np.asarray(k, dtype=float) / total_epochs) ** math.exp(beta2)


def relabel_rate(schedule: Any, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
    """The relabel rate in force during epoch k (1-based) of total_epochs; ``train_success`` holds
    the train success of epochs 1..k-1 (used by ``success`` schedules only)."""
    if not 1 <= k <= total_epochs:
        raise ValueError(f"epoch index k={k} is outside 1..{total_epochs}")
    if schedule.kind == "constant":
        return float(schedule.eps)
    if schedule.kind == "success":
        recent = list(train_success)[-schedule.window:]
        progress = float(np.mean(recent)) if recent else 0.0
        return float(min(1.0, max(schedule.eps_min, 1.0 - schedule.beta1 * progress)))
    return float(decay_rate(k, total_epochs, schedule.beta1, effective_beta2(schedule.kind, schedule.beta2)))


def mean_rate_exact(beta1: float, beta2: float, total_epochs: int) -> float:
    """eq. 10: (1/K) * sum_{k=1..K} eps(k)."""
    k = np.arange(1, total_epochs + 1)
    return float(np.mean(decay_rate(k, total_epochs, beta1, beta2)))


def mean_rate_approx(beta1: float | np.ndarray, beta2: float | np.ndarray) -> float | np.ndarray:
    """eq. 11: 1 - beta1 / (1 + exp(beta2)), the K -> infinity limit of eq. 10."""
    return 1.0 - np.asarray(beta1, dtype=float) / (1.0 + np.exp(np.asarray(beta2, dtype=float)))


def schedule_mean_rate(schedule: Any, total_epochs: int) -> float:
    """mu_eps of a schedule over total_epochs (eq. 10; eps itself for constant; NaN for success,
    whose mean rate is the mean of the rates its run logged)."""
    if schedule.kind == "constant":
        return float(schedule.eps)
    if schedule.kind == "success":
        return float("nan")
    return mean_rate_exact(schedule.beta1, effective_beta2(schedule.kind, schedule.beta2), total_epochs)


def schedule_mean_rates(kind: str, eps: float | None, beta1: float | None, beta2: float | None,
                        total_epochs: int) -> tuple[float, float]:
    """mu_eps of a schedule given by its parameters: (exact over total_epochs (eq. 10), eq. 11);
    NaN for success schedules (known only from their logs)."""
    if kind == "constant":
        return float(eps), float(eps)
    if kind == "success":
        return float("nan"), float("nan")
    beta2 = effective_beta2(kind, beta2 or 0.0)
    return mean_rate_exact(beta1, beta2, total_epochs), float(mean_rate_approx(beta1, beta2))


def beta1_for_mean_rate(mean_rate: float, beta2: float, total_epochs: int) -> float:
    """The beta1 whose schedule has mean rate ``mean_rate`` over total_epochs (eq. 10 is linear
    in beta1: mu = 1 - beta1 * mean_k (k/K)^exp(beta2)); rounded to 6 decimals."""
    steps = [(k / total_epochs) ** math.exp(beta2) for k in range(1, total_epochs + 1)]
    return round((1.0 - mean_rate) / (sum(steps) / total_epochs), 6)
