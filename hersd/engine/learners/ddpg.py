"""DDPG with the reference HER code's details (see docs/ARCHITECTURE.md, "Fidelity"): ``learner=ddpg``.

- inputs (:class:`hersd.engine.learners.base.GoalConditionedLearner`, every learner's): raw obs/goal
  clipped to +-clip_obs, normalised by running mean/std (std >= norm_eps), clipped to +-clip_norm;
- actor: MLP -> tanh * max_action; critic: MLP over [obs, goal, action / max_action];
- target Q clipped to [q_min, q_max]: the bounds of a discounted sum of the env's weighted
  rewards (hersd.engine.run_state.discounting; Fetch: [-max(lambda) / (1 - gamma), 0], the reference
  code's); no done mask;
- actor loss = -mean Q(s, pi(s)) + action_l2 * mean((pi / max_action)^2);
- targets are moved by polyak averaging once per cycle (``update_targets``).

The update is written over the critics (``CRITICS``) and with two hooks, ``target_action`` and
``actor_step_due``, so that TD3 (hersd/engine/learners/td3.py) is this class with twin critics, smoothed
target actions and a delayed actor step (docs/LEARNERS.md says why TD3 extends DDPG).

Networks, optimiser and normaliser statistics live on ``device``; minibatches arrive as numpy
arrays from the host-side replay buffer and are moved there once per update.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from hersd.contract.config import DDPGConfig, TrainConfig
from hersd.contract.learners.ddpg import CARD
from hersd.engine.learners.base import GoalConditionedLearner, UpdateStats, frozen_q
from hersd.engine.replay.buffer import TransitionBatch

if TYPE_CHECKING:
    from hersd.engine.envs.make import EnvSpec


def noisy_action(action: np.ndarray, cfg: DDPGConfig, max_action: float, rng: np.random.Generator) -> np.ndarray:
    """Add N(0, noise_eps * max_action) to actions (n, action_dim), clip, then with probability
    random_eps replace a whole action by a uniform random one."""
    action = np.clip(action + cfg.noise_eps * max_action * rng.standard_normal(action.shape), -max_action, max_action)
    random_action = rng.uniform(-max_action, max_action, size=action.shape)
    take_random = rng.random((action.shape[0], 1)) < cfg.random_eps
    return np.where(take_random, random_action, action)


class DDPG(GoalConditionedLearner, card=CARD):
    """A deterministic actor, its critic(s), their targets and one optimiser, on the shared input normalisers."""

    TARGETS = ("actor", "critic")
    PARTS = ("actor", "critic", "actor_target", "critic_target", "optimizer", "obs_norm", "goal_norm")
    LOSS_SETTINGS = "ddpg.action_l2"
    UPDATE_PASSES = 5  # actor(s), critic(s, a), critic(s, pi(s)), actor_target(s'), critic_target(s', a')

    @classmethod
    def build(cls, cfg: TrainConfig, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
              device: torch.device) -> "DDPG":
        return cls(cfg.ddpg, spec, gamma, q_range, device, cfg.precision)

    def __init__(self, cfg: DDPGConfig, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
                 device: torch.device = torch.device("cpu"), precision: str = "fp32"):
        super().__init__(cfg, spec, gamma, device, precision)
        self.target_range = q_range  # (q_min, q_max); q_max = 0 for rewards <= 0 (Fetch, Hand)
        # One Adam over actor and critics (one parameter group each): a single fused step per update.
        self.optimizer = torch.optim.Adam([{"params": self.actor.parameters(), "lr": cfg.actor_lr},
                                           *({"params": getattr(self, name).parameters(), "lr": cfg.critic_lr}
                                             for name in self.CRITICS)], fused=True)
        self.last_actor_loss = 0.0  # the last actor step's loss (reported on updates without one)

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions (n, action_dim) for obs (n, obs_dim) and goal (n, goal_dim): tanh(actor) * max_action,
        with explore passed through :func:`noisy_action` (Gaussian noise, random actions)."""
        action = (torch.tanh(self.actor(self._inputs(obs, goal))) * self.max_action).cpu().numpy().astype(np.float64)
        return noisy_action(action, self.cfg, self.max_action, rng) if explore else action

    def target_action(self, next_inputs: torch.Tensor) -> torch.Tensor:
        """a' = pi'(s') in the tanh scale: (B, in_dim) -> (B, action_dim)."""
        return torch.tanh(self.actor_target(next_inputs))

    @torch.no_grad()
    def target_q(self, next_inputs: torch.Tensor, reward: torch.Tensor) -> torch.Tensor:
        """r + gamma * min_i Q_i'(s', a') clipped to ``target_range``: (B, in_dim), (B, 1) -> (B, 1)."""
        next_q = self.min_target_q(torch.cat([next_inputs, self.target_action(next_inputs)], dim=1))
        return torch.clamp(reward + self.gamma * next_q, *self.target_range)

    def actor_loss(self, inputs: torch.Tensor) -> torch.Tensor:
        """-mean Q(s, pi(s)) + action_l2 * mean(pi^2), Q the first critic through detached parameters
        (:func:`hersd.engine.learners.base.frozen_q`): only the actor's parameters get its gradient."""
        policy_action = torch.tanh(self.actor(inputs))  # = pi(s) / max_action
        policy_q = frozen_q(self.critic, torch.cat([inputs, policy_action], dim=1))
        return -policy_q.mean() + self.cfg.action_l2 * torch.mean(torch.square(policy_action))

    def actor_step_due(self) -> bool:
        """Whether this update steps the actor too: always (TD3 counts)."""
        return True

    def update(self, batch: TransitionBatch) -> UpdateStats:
        """One step of the critics and, if due, the actor on a batch of B transitions.

        As in the reference code, both losses are computed with the current networks and
        the one optimiser then steps: the actor's loss sees the critic through detached
        parameters, so only the critic loss moves the critics. The passes run in ``matmul_context``.
        """
        with self.matmul_context():
            inputs = self._inputs(batch.obs, batch.goal)
            action = self.tensor(batch.action) / self.max_action
            target_q = self.target_q(self._inputs(batch.next_obs, batch.goal), self.tensor(batch.reward).unsqueeze(1))
            loss, q = self.critic_loss(torch.cat([inputs, action], dim=1), target_q)
            critic_loss = loss.item()
            if self.actor_step_due():
                actor_loss = self.actor_loss(inputs)
                self.last_actor_loss = actor_loss.item()
                loss = loss + actor_loss
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        return UpdateStats.of(critic_loss, self.last_actor_loss, q.detach(), batch)
