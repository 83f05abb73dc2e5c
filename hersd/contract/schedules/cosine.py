"""cosine: from ``start`` to ``end`` over the K epochs along half a cosine,
eps(k) = end + (start - end) * (1 + cos(pi * k / K)) / 2, so eps(K) = end and eps(0) would be start.

Exact mean rate: sum_{k=1..K} cos(pi k / K) = -1, so mu_eps = (start + end) / 2 - (start - end) / (2K).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from hersd.contract.schedules.base import Schedule, param
from hersd.contract.schedules.constant import Constant


@dataclass
class Cosine(Schedule):
    kind = "cosine"
    formula = "eps(k) = end + (start - end) * (1 + cos(pi * k / K)) / 2"
    title = "cosine decay"
    searched = ("start", "end")
    line = ":"

    start: float = param(1.0, 0.0, 1.0, "the rate the cosine starts from (eps(0))")
    end: float = param(0.5, 0.0, 1.0, "the rate at the last epoch K")

    def equivalent(self) -> Schedule:
        """start = end is the constant rate ``end`` (its runs are that constant's); not for a subclass."""
        return Constant(eps=self.end) if self.start == self.end and type(self) is Cosine else self

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return self.end + (self.start - self.end) * (1.0 + math.cos(math.pi * k / total_epochs)) / 2.0

    def exact_mean_rate(self, total_epochs: int) -> float:
        return (self.start + self.end) / 2.0 - (self.start - self.end) / (2.0 * total_epochs)

    def limit_mean_rate(self) -> float:
        return (self.start + self.end) / 2.0

    def tag(self) -> str:
        return f"cosine-{self.start:g}_{self.end:g}"

    def label(self) -> str:
        return f"cosine {self.start:g}→{self.end:g}"
