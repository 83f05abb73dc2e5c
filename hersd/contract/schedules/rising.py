"""rising: eq. 9's decay run backwards, eps(k) = 1 - beta1 * ((K + 1 - k) / K) ** exp(beta2).

The same K rates as the linear (beta2 = 0) or exponential decay of these settings, in the reverse order: it starts at
the decay's last rate (1 - beta1) and ends at its first, so its mean rate (eq. 10) is the decay's exactly. Set beside
the decay it tells the order of the rates from the rates themselves (docs/RESULTS.md, "Registered before the runs").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from hersd.contract.schedules.base import Schedule, param
from hersd.contract.schedules.constant import Constant
from hersd.contract.schedules.equations import BETA2_LIMIT, decay_rate, mean_rate_approx, mean_rate_exact
from hersd.contract.schedules.linear import BETA1_DOC


@dataclass
class Rising(Schedule):
    kind = "rising"
    formula = "eps(k) = 1 - beta1 * ((K + 1 - k) / K) ** exp(beta2)  (eq. 9's rates in reverse order)"
    title = "rising (the decay reversed)"
    searched = ("beta1", "beta2")
    line = ":"  # dotted: apart from the decays' solid and dash-dot lines

    beta1: float = param(0.0, 0.0, 1.0, BETA1_DOC + " (here the first epoch's drop)")
    beta2: float = param(0.0, -BETA2_LIMIT, BETA2_LIMIT, "eq. 9: shape of the decay it reverses; 0 is linear")

    def equivalent(self) -> Schedule:
        """beta1 = 0 is the constant rate 1 (its runs are constant-1's); not for a subclass."""
        return Constant(eps=1.0) if self.beta1 == 0 and type(self) is Rising else self

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return float(decay_rate(total_epochs + 1 - k, total_epochs, self.beta1, self.beta2))

    def exact_mean_rate(self, total_epochs: int) -> float:
        return mean_rate_exact(self.beta1, self.beta2, total_epochs)

    def limit_mean_rate(self) -> float:
        return float(mean_rate_approx(self.beta1, self.beta2))

    def tag(self) -> str:
        return f"rising-b1_{self.beta1:g}" + (f"-b2_{self.beta2:g}" if self.beta2 else "")

    def label(self) -> str:
        return f"rising b1={self.beta1:g}" + (f" b2={self.beta2:g}" if self.beta2 else "")
