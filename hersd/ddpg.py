"""DDPG with the reference HER code's details (see docs/ARCHITECTURE.md, "Fidelity").

- inputs: raw obs/goal clipped to +-clip_obs, normalised by running mean/std
  (std >= norm_eps), clipped to +-clip_norm;
- actor: MLP -> tanh * max_action; critic: MLP over [obs, goal, action / max_action];
- target Q clipped to [q_min, q_max]: the bounds of a discounted sum of the env's weighted
  rewards (hersd.run_state.discounting; Fetch: [-max(lambda) / (1 - gamma), 0], the reference
  code's); no done mask;
- actor loss = -mean Q(s, pi(s)) + action_l2 * mean((pi / max_action)^2);
- targets are moved by polyak averaging once per cycle (:meth:`DDPG.update_targets`).

Networks, optimiser and normaliser statistics live on ``device``; minibatches arrive as numpy
arrays from the host-side replay buffer and are moved there once per update.
"""

from __future__ import annotations

import copy
from typing import NamedTuple, Optional

import numpy as np
import torch
from torch import nn

from hersd.config import DDPGConfig
from hersd.replay import TransitionBatch


class RunningNormalizer:
    """Running mean/std of vectors of size dim, from sums kept in float64."""

    def __init__(self, dim: int, eps: float, clip: float, device: torch.device):
        self.eps, self.clip, self.device = eps, clip, device
        self.total = np.zeros(dim)
        self.total_sq = np.zeros(dim)
        self.count = 0
        self.mean = torch.zeros(dim, device=device)
        self.std = torch.ones(dim, device=device)

    def update(self, values: np.ndarray) -> None:
        """Add values (n, dim) to the statistics and recompute mean and std."""
        values = values.reshape(-1, self.total.shape[0]).astype(np.float64)
        self.total += values.sum(axis=0)
        self.total_sq += np.square(values).sum(axis=0)
        self.count += values.shape[0]
        mean = self.total / self.count
        std = np.sqrt(np.maximum(self.eps ** 2, self.total_sq / self.count - np.square(mean)))
        self.mean = torch.as_tensor(mean, dtype=torch.float32, device=self.device)
        self.std = torch.as_tensor(std, dtype=torch.float32, device=self.device)

    def __call__(self, values: torch.Tensor) -> torch.Tensor:
        return torch.clamp((values - self.mean) / self.std, -self.clip, self.clip)

    def state_dict(self) -> dict:
        return {"total": self.total.copy(), "total_sq": self.total_sq.copy(), "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.total, self.total_sq, self.count = state["total"].copy(), state["total_sq"].copy(), state["count"]
        if self.count:
            self.update(np.zeros((0, self.total.shape[0])))


def mlp(in_dim: int, out_dim: int, hidden_layers: int, hidden_units: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for _ in range(hidden_layers):  # in-place ReLU: Linear's backward does not need its output
        layers += [nn.Linear(in_dim, hidden_units), nn.ReLU(inplace=True)]
        in_dim = hidden_units
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class UpdateStats(NamedTuple):
    """Per-update scalars: losses, the mean and mean square of Q(s, a) over the batch, and (SAC
    only) the mean -log pi(a|s) of the actor's sampled actions."""

    critic_loss: float
    actor_loss: float
    q_mean: float
    q_sq_mean: float
    entropy: Optional[float] = None


class DDPG:
    """Actor, critic, their targets and optimisers, and the input normalisers."""

    def __init__(self, cfg: DDPGConfig, obs_dim: int, goal_dim: int, action_dim: int, max_action: float,
                 gamma: float, q_min: float, device: torch.device = torch.device("cpu"), q_max: float = 0.0):
        self.cfg, self.max_action, self.gamma, self.device = cfg, max_action, gamma, device
        self.q_min, self.q_max = q_min, q_max  # target Q's clip; q_max = 0 for rewards <= 0 (Fetch, Hand)
        self.obs_norm = RunningNormalizer(obs_dim, cfg.norm_eps, cfg.clip_norm, device)
        self.goal_norm = RunningNormalizer(goal_dim, cfg.norm_eps, cfg.clip_norm, device)
        in_dim = obs_dim + goal_dim
        self.actor = mlp(in_dim, action_dim, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.critic = mlp(in_dim + action_dim, 1, cfg.hidden_layers, cfg.hidden_units).to(device)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        # One Adam over both networks (one parameter group each): a single fused step per update.
        self.optimizer = torch.optim.Adam([{"params": self.actor.parameters(), "lr": cfg.actor_lr},
                                           {"params": self.critic.parameters(), "lr": cfg.critic_lr}], fused=True)

    def tensor(self, array: np.ndarray) -> torch.Tensor:
        """A host numpy array as a tensor on the agent's device (no copy on the CPU)."""
        return torch.from_numpy(array).to(self.device)

    def _inputs(self, obs: np.ndarray, goal: np.ndarray) -> torch.Tensor:
        """Raw obs (B, obs_dim) and goal (B, goal_dim) -> normalised actor input (B, obs_dim + goal_dim)."""
        clip = self.cfg.clip_obs
        obs_t = self.tensor(np.clip(obs, -clip, clip, dtype=np.float32))
        goal_t = self.tensor(np.clip(goal, -clip, clip, dtype=np.float32))
        return torch.cat([self.obs_norm(obs_t), self.goal_norm(goal_t)], dim=1)

    def update_normalizers(self, obs: np.ndarray, goal: np.ndarray) -> None:
        clip = self.cfg.clip_obs
        self.obs_norm.update(np.clip(obs, -clip, clip))
        self.goal_norm.update(np.clip(goal, -clip, clip))

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions (n, action_dim) for obs (n, obs_dim) and goal (n, goal_dim).

        With explore: add N(0, noise_eps * max_action), clip, then with probability
        random_eps replace the whole action by a uniform random one.
        """
        action = (torch.tanh(self.actor(self._inputs(obs, goal))) * self.max_action).cpu().numpy().astype(np.float64)
        if not explore:
            return action
        cfg = self.cfg
        action = np.clip(action + cfg.noise_eps * self.max_action * rng.standard_normal(action.shape),
                         -self.max_action, self.max_action)
        random_action = rng.uniform(-self.max_action, self.max_action, size=action.shape)
        take_random = rng.random((action.shape[0], 1)) < cfg.random_eps
        return np.where(take_random, random_action, action)

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
        parameters, so only the critic loss moves the critic.
        """
        inputs = self._inputs(batch.obs, batch.goal)
        next_inputs = self._inputs(batch.next_obs, batch.goal)
        action = self.tensor(batch.action) / self.max_action
        target_q = self.target_q(next_inputs, self.tensor(batch.reward).unsqueeze(1))
        q = self.critic(torch.cat([inputs, action], dim=1))
        critic_loss = torch.mean(torch.square(target_q - q))
        policy_action = torch.tanh(self.actor(inputs))  # = pi(s) / max_action
        frozen_critic = {name: p.detach() for name, p in self.critic.named_parameters()}
        policy_q = torch.func.functional_call(self.critic, frozen_critic, (torch.cat([inputs, policy_action], dim=1),))
        actor_loss = -policy_q.mean() + self.cfg.action_l2 * torch.mean(torch.square(policy_action))
        self.optimizer.zero_grad(set_to_none=True)
        (critic_loss + actor_loss).backward()
        self.optimizer.step()
        q = q.detach()
        return UpdateStats(critic_loss.item(), actor_loss.item(), q.mean().item(), torch.square(q).mean().item())

    @torch.no_grad()
    def update_targets(self) -> None:
        """target <- polyak * target + (1 - polyak) * online, for actor and critic."""
        for online, target in ((self.actor, self.actor_target), (self.critic, self.critic_target)):
            torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), 1.0 - self.cfg.polyak)

    def state_dict(self) -> dict:
        return {name: getattr(self, name).state_dict() for name in
                ("actor", "critic", "actor_target", "critic_target", "optimizer", "obs_norm", "goal_norm")}

    def load_state_dict(self, state: dict) -> None:
        for name, value in state.items():
            getattr(self, name).load_state_dict(value)
