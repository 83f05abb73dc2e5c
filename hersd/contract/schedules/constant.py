"""constant: eps(k) = eps, HER's fixed relabel rate (0.8, the reference code's replay_k = 4)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from hersd.contract.schedules.base import HER_RATE, Schedule, param


@dataclass
class Constant(Schedule):
    kind = "constant"
    formula = "eps(k) = eps  (HER: 0.8)"
    title = "constant"
    constant_rate = True
    searched = ("eps",)
    flat_record = True

    eps: float = param(HER_RATE, 0.0, 1.0, "the fixed relabel rate (HER: 0.8, i.e. replay_k = 4)")

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return float(self.eps)

    def exact_mean_rate(self, total_epochs: int) -> float:
        return float(self.eps)

    def limit_mean_rate(self) -> float:
        return float(self.eps)

    def tag(self) -> str:
        return f"constant-{self.eps:g}"

    def label(self) -> str:
        return f"constant eps={self.eps:g}"
