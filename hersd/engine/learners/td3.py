"""TD3 (Fujimoto, van Hoof & Meger 2018) on the DDPG core's inputs, networks and settings: ``learner=td3``.

:class:`hersd.engine.learners.ddpg.DDPG` with three changes, and nothing else:

- twin critics (``CRITICS``); both regress to r + gamma * min(Q1', Q2')(s', a'), clipped to [q_min, q_max];
- target policy smoothing (``target_action``): a' = clip(pi'(s') + clip(N(0, policy_noise), +-noise_clip), +-1)
  in the tanh scale (a share of max action), the noise drawn from torch's generator;
- the actor steps once per ``policy_delay`` updates (``actor_step_due``), on the first of each group
  (updates 1, 3, 5, ... for a delay of 2; loss -mean Q1(s, pi(s)) + action_l2 * mean(pi^2), DDPG's);
  between actor steps ``actor_loss`` reports the last actor step's.

Acting, the actor's loss and the clipped target are DDPG's. The targets move by polyak averaging
once per cycle, as in the DDPG core (the TD3 paper moves them after every actor step): learners
then differ only in their update rule, so a schedule's effect is compared under one target rhythm.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from hersd.contract.config import DDPGConfig, TrainConfig
from hersd.contract.learners.td3 import CARD, TD3Config
from hersd.engine.learners.base import TWIN_CRITICS
from hersd.engine.learners.ddpg import DDPG

if TYPE_CHECKING:
    from hersd.engine.envs.make import EnvSpec


class TD3(DDPG, card=CARD):
    """DDPG with twin critics, smoothed target actions and delayed actor steps."""

    CRITICS = TWIN_CRITICS
    TARGETS = ("actor", "critic", "critic2")
    PARTS = DDPG.PARTS + ("critic2", "critic2_target")  # + "counters" (the delay's phase), below
    UPDATE_PASSES = 7  # DDPG's 5, and critic2 on (s, a) and its target on (s', a')

    @classmethod
    def build(cls, cfg: TrainConfig, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
              device: torch.device) -> "TD3":
        return cls(cfg.ddpg, cfg.learner.settings, spec, gamma, q_range, device, cfg.precision)

    def __init__(self, cfg: DDPGConfig, td3: TD3Config, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
                 device: torch.device = torch.device("cpu"), precision: str = "fp32"):
        super().__init__(cfg, spec, gamma, q_range, device, precision)
        self.td3 = td3
        self.update_count = 0  # updates taken; the actor steps when update_count % policy_delay == 0 before it

    def target_action(self, next_inputs: torch.Tensor) -> torch.Tensor:
        """DDPG's a' = pi'(s') plus clipped Gaussian noise, clipped to the action range (tanh scale)."""
        next_action = super().target_action(next_inputs)
        noise = (torch.randn_like(next_action) * self.td3.policy_noise).clamp(-self.td3.noise_clip, self.td3.noise_clip)
        return (next_action + noise).clamp(-1.0, 1.0)

    def actor_step_due(self) -> bool:
        """True on the first of every ``policy_delay`` updates (counted across calls and resumes)."""
        due = self.update_count % self.td3.policy_delay == 0
        self.update_count += 1
        return due

    def state_dict(self) -> dict:
        return {**super().state_dict(),
                "counters": {"update_count": self.update_count, "last_actor_loss": self.last_actor_loss}}

    def load_state_dict(self, state: dict) -> None:
        state = dict(state)
        counters = state.pop("counters")
        self.update_count, self.last_actor_loss = counters["update_count"], counters["last_actor_loss"]
        super().load_state_dict(state)
