"""TD3's card (hersd/engine/learners/td3.py): its settings, ``learner.td3.*``, and a fast update."""

from __future__ import annotations

from dataclasses import dataclass

from hersd.contract.checks import SCALE_LIMIT, check, check_number, setting_name
from hersd.contract.learners import LearnerCard


@dataclass
class TD3Config:
    # TD3 (Fujimoto et al. 2018): twin critics (the target takes their minimum), target policy smoothing.
    policy_noise: float = 0.2  # std of the Gaussian noise on target actions, as a share of max action
    noise_clip: float = 0.5  # that noise is clipped to +-noise_clip (share of max action)
    policy_delay: int = 2  # the actor steps once per policy_delay critic steps

    def __post_init__(self) -> None:
        for name in ("policy_noise", "noise_clip"):
            check_number(setting_name("td3", name), getattr(self, name), 0.0, SCALE_LIMIT)
        check(self.policy_delay >= 1, f"{setting_name('td3', 'policy_delay')} must be >= 1, got {self.policy_delay}")


CARD = LearnerCard(name="td3", settings=TD3Config, fast_update=True)
