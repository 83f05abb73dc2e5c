"""The seed paper's equations, pure functions of the epoch index k (1..K) and the total K.

- eq. 9:  eps(k) = 1 - beta1 * (k / K) ** exp(beta2)
- eq. 10: mu_eps = (1/K) * sum_{k=1..K} eps(k), the exact mean rate
- eq. 11: mu_eps ~ 1 - beta1 / (1 + exp(beta2)), its K -> infinity limit
"""

from __future__ import annotations

import math

import numpy as np

from hersd.contract.schedules.base import HER_RATE

# mu_eps between the HER paper's two best fixed rates (replay_k = 4, HER's rate, and 8: 8/9, which the seed paper
# writes 0.889): its "optimal region" (its Fig. 12), drawn in the mu_eps and beta-plane figures.
MU_EPS_BAND = (HER_RATE, 0.889)
# |beta2| beyond this makes eq. 9 a step function in float64 (and exp(beta2) overflows past ~709).
BETA2_LIMIT = 50.0


def decay_rate(k: int | np.ndarray, total_epochs: int, beta1: float, beta2: float) -> float | np.ndarray:
    """eq. 9: 1 - beta1 * (k / K) ** exp(beta2); k may be an int or an array of epoch indices."""
    return 1.0 - beta1 * (np.asarray(k, dtype=float) / total_epochs) ** math.exp(beta2)


def mean_rate_exact(beta1: float, beta2: float, total_epochs: int) -> float:
    """eq. 10: (1/K) * sum_{k=1..K} eps(k)."""
    k = np.arange(1, total_epochs + 1)
    return float(np.mean(decay_rate(k, total_epochs, beta1, beta2)))


def mean_rate_approx(beta1: float | np.ndarray, beta2: float | np.ndarray) -> float | np.ndarray:
    """eq. 11: 1 - beta1 / (1 + exp(beta2)), the K -> infinity limit of eq. 10."""
    return 1.0 - np.asarray(beta1, dtype=float) / (1.0 + np.exp(np.asarray(beta2, dtype=float)))


def beta1_for_mean_rate(mean_rate: float, beta2: float, total_epochs: int) -> float:
    """The beta1 whose schedule has mean rate ``mean_rate`` over total_epochs (eq. 10 is linear
    in beta1: mu = 1 - beta1 * mean_k (k/K)^exp(beta2)); rounded to 6 decimals."""
    steps = [(k / total_epochs) ** math.exp(beta2) for k in range(1, total_epochs + 1)]
    return round((1.0 - mean_rate) / (sum(steps) / total_epochs), 6)
