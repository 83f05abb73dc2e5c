"""SAC with automatic temperature (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and
Applications") on the DDPG core's inputs, networks and settings: ``learner=sac``.

- policy: an MLP of DDPG's size giving the mean and log std (clamped to [-20, 2], as in the
  authors' code) of a Gaussian over pre-tanh actions; a = tanh(u), and
  log pi(a|s) = log N(u) - sum log(1 - tanh(u)^2 + 1e-6);
- twin critics (their loss and the minimum of their targets are every learner's,
  :class:`hersd.engine.learners.base.GoalConditionedLearner`); soft target
  r + gamma * (min(Q1', Q2')(s', a') - alpha * log pi(a'|s')), a' ~ pi(s'), not clipped (``SAC.target_q``);
- actor loss mean(alpha * log pi(a|s) - min(Q1, Q2)(s, a)), a ~ pi(s) (no action_l2 term:
  the entropy term is SAC's regulariser);
- temperature: log alpha (starting at log init_alpha) steps with Adam (alpha_lr) on
  -mean(log alpha * (log pi + target_entropy)), target_entropy = -dim(A) unless set.

Exploration samples the policy with the run's numpy Generator (no added noise or random
actions); test actions are tanh(mean). Critic targets move by polyak averaging once per cycle,
as in the DDPG core; there is no actor target. Sampling inside updates uses torch's generator.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import torch

from hersd.contract.config import DDPGConfig, TrainConfig
from hersd.contract.learners.sac import CARD, SACConfig
from hersd.engine.learners.base import TWIN_CRITICS, GoalConditionedLearner, UpdateStats, frozen_q
from hersd.engine.replay.buffer import TransitionBatch

if TYPE_CHECKING:
    from hersd.engine.envs.make import EnvSpec

LOG_STD_RANGE = (-20.0, 2.0)


class SAC(GoalConditionedLearner, card=CARD):
    """A squashed-Gaussian actor, twin critics and a learnt temperature, on the shared input normalisers."""

    CRITICS = TWIN_CRITICS
    TARGETS = CRITICS  # no actor target
    PARTS = ("actor", "critic", "critic2", "critic_target", "critic2_target", "optimizer", "alpha_optimizer",
             "obs_norm", "goal_norm")  # + "log_alpha", below
    LOSS_SETTINGS = "learner.sac.init_alpha, learner.sac.alpha_lr, learner.sac.target_entropy"
    UPDATE_PASSES = 8  # the actor on s' and s, both critics on (s, a), both frozen on (s, a~), both targets
    target_range = None  # the soft target is not clipped (target_q)

    @classmethod
    def build(cls, cfg: TrainConfig, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
              device: torch.device) -> "SAC":
        return cls(cfg.ddpg, cfg.learner.settings, spec, gamma, device, cfg.precision)  # q_range: not SAC's bound (target_q)

    @classmethod
    def networks(cls, spec: "EnvSpec") -> dict[str, tuple[int, int]]:
        """The shared layout, with an actor that gives a mean and a log std per action."""
        in_dim = spec.obs_dim + spec.goal_dim
        return {**super().networks(spec), "actor": (in_dim, 2 * spec.action_dim)}

    def __init__(self, cfg: DDPGConfig, sac: SACConfig, spec: "EnvSpec", gamma: float,
                 device: torch.device = torch.device("cpu"), precision: str = "fp32"):
        super().__init__(cfg, spec, gamma, device, precision)
        self.optimizer = torch.optim.Adam([{"params": self.actor.parameters(), "lr": cfg.actor_lr},
                                           {"params": [*self.critic.parameters(), *self.critic2.parameters()],
                                            "lr": cfg.critic_lr}], fused=True)
        self.log_alpha = torch.tensor([math.log(sac.init_alpha)], device=device, requires_grad=True)
        self.alpha_optimizer = torch.optim.Adam([self.log_alpha], lr=sac.alpha_lr)
        self.target_entropy = -float(spec.action_dim) if sac.target_entropy is None else sac.target_entropy

    def policy(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised inputs (B, in_dim) -> mean and std (B, action_dim) of the pre-tanh Gaussian."""
        mean, log_std = self.actor(inputs).chunk(2, dim=1)
        return mean, log_std.clamp(*LOG_STD_RANGE).exp()

    @staticmethod
    def squash(mean: torch.Tensor, std: torch.Tensor, noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """u = mean + std * noise -> (tanh(u) (B, A), log pi(tanh(u)) (B, 1))."""
        pre_tanh = mean + std * noise
        action = torch.tanh(pre_tanh)
        log_prob = (-0.5 * noise.square() - std.log() - 0.5 * math.log(2 * math.pi)).sum(1, keepdim=True)
        return action, log_prob - torch.log(1.0 - action.square() + 1e-6).sum(1, keepdim=True)

    def sample(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """An action in the tanh scale (B, A) drawn from the policy with torch's generator, and its log prob (B, 1)."""
        mean, std = self.policy(inputs)
        return self.squash(mean, std, torch.randn_like(mean))

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions (n, action_dim): sampled from the policy with ``rng`` if explore, else tanh(mean)."""
        mean, std = self.policy(self._inputs(obs, goal))
        if explore:
            noise = self.tensor(rng.standard_normal(mean.shape).astype(np.float32))
            action = torch.tanh(mean + std * noise)
        else:
            action = torch.tanh(mean)
        return (action * self.max_action).cpu().numpy().astype(np.float64)

    @property
    def alpha(self) -> float:
        return float(self.log_alpha.exp().item())

    @torch.no_grad()
    def target_q(self, next_inputs: torch.Tensor, reward: torch.Tensor) -> torch.Tensor:
        """r + gamma * (min Q'(s', a') - alpha * log pi(a'|s')), a' ~ pi(s'), unclipped: (B, 1).

        DDPG's clip to [q_min, 0] bounds discounted sums of non-positive rewards. A soft Q also
        sums the discounted entropy bonuses -alpha * log pi of every later step, which are positive
        for a wide policy and scale with a temperature that moves during training, so it has no
        fixed range: clipping at 0 pins every target while the bonus outweighs the reward, and
        clipping only r + gamma * min Q' would still cut the later bonuses that Q' carries. As in
        the SAC authors' code (softlearning) and stable-baselines3, the soft target is not clipped.
        """
        next_action, next_log_prob = self.sample(next_inputs)
        next_q = self.min_target_q(torch.cat([next_inputs, next_action], dim=1))
        return reward + self.gamma * (next_q - self.log_alpha.exp() * next_log_prob)

    def update(self, batch: TransitionBatch) -> UpdateStats:
        """One step of both critics, the actor (through frozen critics) and the temperature; the passes
        run in ``matmul_context``."""
        with self.matmul_context():
            inputs = self._inputs(batch.obs, batch.goal)
            action = self.tensor(batch.action) / self.max_action
            target_q = self.target_q(self._inputs(batch.next_obs, batch.goal), self.tensor(batch.reward).unsqueeze(1))
            critic_loss, q = self.critic_loss(torch.cat([inputs, action], dim=1), target_q)
            policy_action, log_prob = self.sample(inputs)
            policy_inputs = torch.cat([inputs, policy_action], dim=1)
            policy_q = torch.minimum(frozen_q(self.critic, policy_inputs), frozen_q(self.critic2, policy_inputs))
            alpha = self.log_alpha.exp().detach()
            actor_loss = torch.mean(alpha * log_prob - policy_q)
        self.optimizer.zero_grad(set_to_none=True)
        (critic_loss + actor_loss).backward()
        self.optimizer.step()
        alpha_loss = -torch.mean(self.log_alpha * (log_prob.detach() + self.target_entropy))
        self.alpha_optimizer.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_optimizer.step()
        q = q.detach()
        return UpdateStats.of(critic_loss.item(), actor_loss.item(), q, batch, entropy=-log_prob.detach().mean().item())

    def state_dict(self) -> dict:
        return {**super().state_dict(), "log_alpha": self.log_alpha.detach().clone()}

    def load_state_dict(self, state: dict) -> None:
        state = dict(state)
        with torch.no_grad():
            self.log_alpha.copy_(state.pop("log_alpha"))
        super().load_state_dict(state)
