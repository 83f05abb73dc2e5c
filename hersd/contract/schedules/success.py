"""success: the rate follows the agent's train success instead of the epoch count (beyond the
paper; its conclusion suggests the optimal decay need not be a function of the epoch):
eps(k) = clip(1 - beta1 * s(k), eps_min, 1), s(k) the mean train success of the last ``window``
epochs before k (fewer while k <= window; s(1) = 0). Its mean rate is known only once run."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from hersd.contract.schedules.base import Schedule, param


@dataclass
class Success(Schedule):
    kind = "success"
    formula = "eps(k) = clip(1 - beta1 * s(k), eps_min, 1), s(k) = mean train success of the `window` epochs before k"
    title = "success-driven rate"
    adaptive = True
    flat_record = True

    beta1: float = param(0.0, 0.0, 1.0, "drop of the rate when the agent always succeeds, in [0, 1]")
    window: int = param(10, 1, float("inf"), "epochs of train success averaged into s(k)", integer=True)
    eps_min: float = param(0.0, 0.0, 1.0, "lower bound of the rate")

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        recent = list(train_success)[-self.window:]
        progress = float(np.mean(recent)) if recent else 0.0
        return float(min(1.0, max(self.eps_min, 1.0 - self.beta1 * progress)))

    def tag(self) -> str:
        return f"success-b1_{self.beta1:g}-w{self.window}"

    def label(self) -> str:
        return f"success b1={self.beta1:g}"
