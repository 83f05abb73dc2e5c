"""Relabel-rate schedules: pure functions of the epoch index k (1..K) and the total K.

eps is the probability that a sampled transition's goal is replaced by a hindsight goal.

- ``constant``:     eps(k) = eps                                (HER: 0.8)
- ``linear``:       eps(k) = 1 - beta1 * (k / K)                 (eq. 9 with beta2 = 0)
- ``exponential``:  eps(k) = 1 - beta1 * (k / K) ** exp(beta2)    (eq. 9)

mu_eps is the mean rate over the K epochs: exactly (eq. 10) or by the continuous
approximation 1 - beta1 / (1 + exp(beta2)) (eq. 11).
"""

from __future__ import annotations

import math

import numpy as np

from hersd.config import ScheduleConfig


def decay_rate(k: int | np.ndarray, total_epochs: int, beta1: float, beta2: float) -> float | np.ndarray:
    """eq. 9: 1 - beta1 * (k / K) ** exp(beta2); k may be an int or an array of epoch indices."""
    return 1.0 - beta1 * (np.asarray(k, dtype=float) / total_epochs) ** math.exp(beta2)


def relabel_rate(schedule: ScheduleConfig, k: int, total_epochs: int) -> float:
    """The relabel rate in force during epoch k (1-based) of total_epochs."""
    if not 1 <= k <= total_epochs:
        raise ValueError(f"epoch index k={k} is outside 1..{total_epochs}")
    if schedule.kind == "constant":
        return float(schedule.eps)
    beta2 = 0.0 if schedule.kind == "linear" else schedule.beta2
    return float(decay_rate(k, total_epochs, schedule.beta1, beta2))


def mean_rate_exact(beta1: float, beta2: float, total_epochs: int) -> float:
    """eq. 10: (1/K) * sum_{k=1..K} eps(k)."""
    k = np.arange(1, total_epochs + 1)
    return float(np.mean(decay_rate(k, total_epochs, beta1, beta2)))


def mean_rate_approx(beta1: float | np.ndarray, beta2: float | np.ndarray) -> float | np.ndarray:
    """eq. 11: 1 - beta1 / (1 + exp(beta2)), the K -> infinity limit of eq. 10."""
    return 1.0 - np.asarray(beta1, dtype=float) / (1.0 + np.exp(np.asarray(beta2, dtype=float)))


def schedule_mean_rate(schedule: ScheduleConfig, total_epochs: int) -> float:
    """mu_eps of a configured schedule over total_epochs (eq. 10; eps itself for constant)."""
    if schedule.kind == "constant":
        return float(schedule.eps)
    beta2 = 0.0 if schedule.kind == "linear" else schedule.beta2
    return mean_rate_exact(schedule.beta1, beta2, total_epochs)
