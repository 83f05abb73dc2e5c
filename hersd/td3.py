"""TD3 (Fujimoto, van Hoof & Meger 2018) on the DDPG core's inputs, networks and settings.

Differences from :class:`hersd.ddpg.DDPG`, and nothing else:

- twin critics; both regress to r + gamma * min(Q1', Q2')(s', a'), clipped to [q_min, q_max];
- target policy smoothing: a' = clip(pi'(s') + clip(N(0, policy_noise), +-noise_clip), +-1)
  in the tanh scale (a share of max action), the noise drawn from torch's generator;
- the actor steps once per ``policy_delay`` updates, on the first of each group (updates 1, 3,
  5, ... for a delay of 2; loss -mean Q1(s, pi(s)) + action_l2 * mean(pi^2), as DDPG's);
  between actor steps ``actor_loss`` reports the last actor step's.

The targets move by polyak averaging once per cycle, as in the DDPG core (the TD3 paper moves
them after every actor step): learners then differ only in their update rule, so a schedule's
effect is compared under one target-update rhythm.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from hersd.config import DDPGConfig, TD3Config
from hersd.learner import GoalConditionedLearner, UpdateStats, frozen_q, mlp, noisy_action
from hersd.replay import TransitionBatch


class TD3(GoalConditionedLearner):
    """DDPG's actor, inputs and exploration with twin critics, smoothed targets, delayed actor steps."""

    PARTS = ("actor", "critic", "actor_target", "critic_target", "optimizer", "obs_norm", "goal_norm",
             "critic2", "critic2_target")

    def __init__(self, cfg: DDPGConfig, td3: TD3Config, obs_dim: int, goal_dim: int, action_dim: int,
                 max_action: float, gamma: float, q_min: float, device: torch.device = torch.device("cpu"),
                 q_max: float = 0.0):
        super().__init__(cfg, obs_dim, goal_dim, max_action, gamma, device)
        self.td3, self.q_min, self.q_max = td3, q_min, q_max
        in_dim = obs_dim + goal_dim  # networks made in DDPG's order (actor, critic, then critic2): one torch RNG stream
        self.actor = mlp(in_dim, action_dim, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.critic = mlp(in_dim + action_dim, 1, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic2 = mlp(in_dim + action_dim, 1, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.critic2_target = copy.deepcopy(self.critic2).requires_grad_(False)
        self.optimizer = torch.optim.Adam([{"params": self.actor.parameters(), "lr": cfg.actor_lr},
                                           {"params": self.critic.parameters(), "lr": cfg.critic_lr},
                                           {"params": self.critic2.parameters(), "lr": cfg.critic_lr}], fused=True)
        self.update_count = 0  # updates taken; the actor steps when update_count % policy_delay == 0 before it
        self.last_actor_loss = 0.0

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """DDPG's acting: tanh(actor) * max_action, with explore through :func:`hersd.learner.noisy_action`."""
        action = (torch.tanh(self.actor(self._inputs(obs, goal))) * self.max_action).cpu().numpy().astype(np.float64)
        return noisy_action(action, self.cfg, self.max_action, rng) if explore else action

    @torch.no_grad()
    def target_q(self, next_inputs: torch.Tensor, reward: torch.Tensor) -> torch.Tensor:
        """r + gamma * min(Q1', Q2')(s', smoothed pi'(s')) clipped to [q_min, q_max]: (B, in_dim), (B, 1) -> (B, 1)."""
        next_action = torch.tanh(self.actor_target(next_inputs))
        noise = (torch.randn_like(next_action) * self.td3.policy_noise).clamp(-self.td3.noise_clip, self.td3.noise_clip)
        next_action = (next_action + noise).clamp(-1.0, 1.0)
        target_inputs = torch.cat([next_inputs, next_action], dim=1)
        next_q = torch.minimum(self.critic_target(target_inputs), self.critic2_target(target_inputs))
        return torch.clamp(reward + self.gamma * next_q, self.q_min, self.q_max)

    def update(self, batch: TransitionBatch) -> UpdateStats:
        """Both critics step on every call; the actor on every ``policy_delay``-th (counted across calls)."""
        inputs = self._inputs(batch.obs, batch.goal)
        action = self.tensor(batch.action) / self.max_action
        target_q = self.target_q(self._inputs(batch.next_obs, batch.goal), self.tensor(batch.reward).unsqueeze(1))
        critic_inputs = torch.cat([inputs, action], dim=1)
        q = self.critic(critic_inputs)
        loss = torch.mean(torch.square(target_q - q)) + torch.mean(torch.square(target_q - self.critic2(critic_inputs)))
        critic_loss = loss.item()
        actor_step = self.update_count % self.td3.policy_delay == 0
        self.update_count += 1
        if actor_step:
            policy_action = torch.tanh(self.actor(inputs))
            policy_q = frozen_q(self.critic, torch.cat([inputs, policy_action], dim=1))
            actor_loss = -policy_q.mean() + self.cfg.action_l2 * torch.mean(torch.square(policy_action))
            self.last_actor_loss = actor_loss.item()
            loss = loss + actor_loss
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        q = q.detach()
        return UpdateStats.of(critic_loss, self.last_actor_loss, q, batch)

    def update_targets(self) -> None:
        """Polyak-move the actor's and both critics' targets."""
        self.polyak((self.actor, self.actor_target), (self.critic, self.critic_target),
                    (self.critic2, self.critic2_target))

    def state_dict(self) -> dict:
        return {**super().state_dict(),
                "counters": {"update_count": self.update_count, "last_actor_loss": self.last_actor_loss}}

    def load_state_dict(self, state: dict) -> None:
        state = dict(state)
        counters = state.pop("counters")
        self.update_count, self.last_actor_loss = counters["update_count"], counters["last_actor_loss"]
        super().load_state_dict(state)
