"""linear: eq. 9 with beta2 = 0, eps(k) = 1 - beta1 * k / K; beta1 may be solved from a mean rate."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

from hersd.contract.errors import ConfigError
from hersd.contract.schedules.base import Schedule, param
from hersd.contract.schedules.constant import Constant
from hersd.contract.schedules.equations import beta1_for_mean_rate, decay_rate, mean_rate_approx, mean_rate_exact

BETA1_DOC = "eq. 9: final drop of the rate, in [0, 1]"
MEAN_RATE_DOC = "if set, beta1 is solved so that mu_eps over the run's K epochs (eq. 10, exact) is this"


def solved_beta1(mean_rate: float, beta2: float, total_epochs: int) -> float:
    """The beta1 of eq. 9 with mean rate ``mean_rate`` over total_epochs (ConfigError if it exceeds 1)."""
    beta1 = beta1_for_mean_rate(mean_rate, beta2, total_epochs)
    if beta1 > 1.0:
        raise ConfigError(f"schedule.mean_rate={mean_rate} with beta2={beta2} needs beta1={beta1:.3f} > 1; "
                          "raise mean_rate or lower beta2")
    return beta1


@dataclass
class Linear(Schedule):
    kind = "linear"
    formula = "eps(k) = 1 - beta1 * (k / K)  (eq. 9 with beta2 = 0)"
    title = "linear decay (β2 = 0)"
    searched = ("beta1",)
    flat_record = True

    beta1: float = param(0.0, 0.0, 1.0, BETA1_DOC)
    mean_rate: Optional[float] = param(None, 0.0, 1.0, MEAN_RATE_DOC, optional=True)

    beta2 = 0.0  # eq. 9's shape in effect (not a setting)

    def resolve(self, total_epochs: int) -> None:
        if self.mean_rate is not None:
            self.beta1 = solved_beta1(self.mean_rate, 0.0, total_epochs)

    def equivalent(self) -> Schedule:
        """beta1 = 0 is the constant rate 1 (its runs are constant-1's); not for a subclass, or a beta1 still to
        be solved from mean_rate."""
        return Constant(eps=1.0) if self.beta1 == 0 and self.mean_rate is None and type(self) is Linear else self

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return float(decay_rate(k, total_epochs, self.beta1, 0.0))

    def exact_mean_rate(self, total_epochs: int) -> float:
        return mean_rate_exact(self.beta1, 0.0, total_epochs)

    def limit_mean_rate(self) -> float:
        return float(mean_rate_approx(self.beta1, 0.0))

    def tag(self) -> str:
        return f"linear-b1_{self.beta1:g}"

    def label(self) -> str:
        return f"linear b1={self.beta1:g}"
