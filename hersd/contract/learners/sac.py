"""SAC's card (hersd/engine/learners/sac.py): its settings, ``learner.sac.*``, and no fast update."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from hersd.contract.checks import LR_LIMIT, SCALE_LIMIT, check_number, setting_name
from hersd.contract.learners import LearnerCard


@dataclass
class SACConfig:
    # SAC (Haarnoja et al. 2018, automatic temperature): squashed Gaussian policy, twin critics.
    init_alpha: float = 1.0  # initial entropy temperature alpha (log alpha 0: the usual start; the SAC paper gives none)
    alpha_lr: float = 1e-3  # Adam learning rate of log(alpha): the networks' (ddpg.actor_lr), as SAC uses one rate for every parameter
    target_entropy: Optional[float] = None  # entropy alpha steers the policy to; null: -dim(A), the SAC paper's

    def __post_init__(self) -> None:
        check_number(setting_name("sac", "init_alpha"), self.init_alpha, 1 / SCALE_LIMIT, SCALE_LIMIT)
        check_number(setting_name("sac", "alpha_lr"), self.alpha_lr, 0.0, LR_LIMIT, low_open=True)
        if self.target_entropy is not None:
            check_number(setting_name("sac", "target_entropy"), self.target_entropy, -SCALE_LIMIT, SCALE_LIMIT)


CARD = LearnerCard(name="sac", settings=SACConfig, fast_update=False)
