"""exponential: eq. 9, eps(k) = 1 - beta1 * (k / K) ** exp(beta2); beta1 may be solved from a mean rate."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

from hersd.contract.schedules.base import Schedule, param
from hersd.contract.schedules.equations import BETA2_LIMIT, decay_rate, mean_rate_approx, mean_rate_exact
from hersd.contract.schedules.linear import BETA1_DOC, MEAN_RATE_DOC, Linear, solved_beta1


@dataclass
class Exponential(Schedule):
    kind = "exponential"
    formula = "eps(k) = 1 - beta1 * (k / K) ** exp(beta2)  (eq. 9)"
    title = "exponential decay"
    searched = ("beta1", "beta2")
    line = "-."
    flat_record = True

    beta1: float = param(0.0, 0.0, 1.0, BETA1_DOC)
    beta2: float = param(0.0, -BETA2_LIMIT, BETA2_LIMIT, "eq. 9: shape; 0 is linear, > 0 concave, < 0 convex")
    mean_rate: Optional[float] = param(None, 0.0, 1.0, MEAN_RATE_DOC, optional=True)

    def resolve(self, total_epochs: int) -> None:
        if self.mean_rate is not None:
            self.beta1 = solved_beta1(self.mean_rate, self.beta2, total_epochs)

    def equivalent(self) -> Schedule:
        """beta2 = 0 is the linear kind, beta1 = 0 (mean_rate unset) the constant rate 1: its runs are theirs (the
        same folder and identity). Not for a subclass, whose rate may be its own: its runs stay its own."""
        if type(self) is not Exponential or self.beta2 != 0 and (self.beta1 != 0 or self.mean_rate is not None):
            return self
        return Linear(beta1=self.beta1, mean_rate=self.mean_rate).equivalent()

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return float(decay_rate(k, total_epochs, self.beta1, self.beta2))

    def exact_mean_rate(self, total_epochs: int) -> float:
        return mean_rate_exact(self.beta1, self.beta2, total_epochs)

    def limit_mean_rate(self) -> float:
        return float(mean_rate_approx(self.beta1, self.beta2))

    def tag(self) -> str:
        return f"exponential-b1_{self.beta1:g}-b2_{self.beta2:g}"

    def label(self) -> str:
        return f"exp b1={self.beta1:g} b2={self.beta2:g}"
