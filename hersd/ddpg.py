"""DDPG with the reference HER code's details (see docs/ARCHITECTURE.md, "Fidelity").

- inputs (:class:`hersd.learner.GoalConditionedLearner`, every learner's): raw obs/goal
  clipped to +-clip_obs, normalised by running mean/std (std >= norm_eps), clipped to +-clip_norm;
- actor: MLP -> tanh * max_action; critic: MLP over [obs, goal, action / max_action];
- target Q clipped to [q_min, q_max]: the bounds of a discounted sum of the env's weighted
  rewards (hersd.run_state.discounting; Fetch: [-max(lambda) / (1 - gamma), 0], the reference
  code's); no done mask;
- actor loss = -mean Q(s, pi(s)) + action_l2 * mean((pi / max_action)^2);
- targets are moved by polyak averaging once per cycle (:meth:`DDPG.update_targets`).

TD3 and SAC (hersd/td3.py, hersd/sac.py) are its siblings on the same base, not subclasses.

Networks, optimiser and normaliser statistics live on ``device``; minibatches arrive as numpy
arrays from the host-side replay buffer and are moved there once per update.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from hersd.config import DDPGConfig
from hersd.learner import GoalConditionedLearner, UpdateStats, frozen_q, mlp, noisy_action
from hersd.replay import TransitionBatch


class DDPG(GoalConditionedLearner):
    """Actor, critic, their targets and one optimiser, on the shared input normalisers."""

    PARTS = ("actor", "critic", "actor_target", "critic_target", "optimizer", "obs_norm", "goal_norm")

    def __init__(self, cfg: DDPGConfig, obs_dim: int, goal_dim: int, action_dim: int, max_action: float,
                 gamma: float, q_min: float, device: torch.device = torch.device("cpu"), q_max: float = 0.0):
        super().__init__(cfg, obs_dim, goal_dim, max_action, gamma, device)
        self.q_min, self.q_max = q_min, q_max  # target Q's clip; q_max = 0 for rewards <= 0 (Fetch, Hand)
        in_dim = obs_dim + goal_dim
        self.actor = mlp(in_dim, action_dim, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.critic = mlp(in_dim + action_dim, 1, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        # One Adam over both networks (one parameter group each): a single fused step per update.
        self.optimizer = torch.optim.Adam([{"params": self.actor.parameters(), "lr": cfg.actor_lr},
                                           {"params": self.critic.parameters(), "lr": cfg.critic_lr}], fused=True)

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions (n, action_dim) for obs (n, obs_dim) and goal (n, goal_dim): tanh(actor) * max_action,
        with explore passed through :func:`hersd.learner.noisy_action` (Gaussian noise, random actions)."""
        action = (torch.tanh(self.actor(self._inputs(obs, goal))) * self.max_action).cpu().numpy().astype(np.float64)
        return noisy_action(action, self.cfg, self.max_action, rng) if explore else action

    @torch.no_grad()
    def target_q(self, next_inputs: torch.Tensor, reward: torch.Tensor) -> torch.Tensor:
        """r + gamma * Q'(s', pi'(s')) clipped to [q_min, q_max]: next_inputs (B, in_dim), reward (B, 1) -> (B, 1)."""
        next_action = torch.tanh(self.actor_target(next_inputs))
        next_q = self.critic_target(torch.cat([next_inputs, next_action], dim=1))
        return torch.clamp(reward + self.gamma * next_q, self.q_min, self.q_max)

    def update(self, batch: TransitionBatch) -> UpdateStats:
        """One simultaneous actor and critic step on a batch of B transitions.

        As in the reference code, both losses are computed with the current networks and
        both optimisers then step: the actor's loss sees the critic through detached
        parameters (:func:`hersd.learner.frozen_q`), so only the critic loss moves the critic.
        """
        inputs = self._inputs(batch.obs, batch.goal)
        next_inputs = self._inputs(batch.next_obs, batch.goal)
        action = self.tensor(batch.action) / self.max_action
        target_q = self.target_q(next_inputs, self.tensor(batch.reward).unsqueeze(1))
        q = self.critic(torch.cat([inputs, action], dim=1))
        critic_loss = torch.mean(torch.square(target_q - q))
        policy_action = torch.tanh(self.actor(inputs))  # = pi(s) / max_action
        policy_q = frozen_q(self.critic, torch.cat([inputs, policy_action], dim=1))
        actor_loss = -policy_q.mean() + self.cfg.action_l2 * torch.mean(torch.square(policy_action))
        self.optimizer.zero_grad(set_to_none=True)
        (critic_loss + actor_loss).backward()
        self.optimizer.step()
        q = q.detach()
        return UpdateStats.of(critic_loss.item(), actor_loss.item(), q, batch)

    def update_targets(self) -> None:
        """target <- polyak * target + (1 - polyak) * online, for actor and critic."""
        self.polyak((self.actor, self.actor_target), (self.critic, self.critic_target))
