"""What every learner (DDPG, TD3, SAC) shares; each writes out its own networks and update rule.

- :class:`RunningNormalizer`, :func:`mlp`, :class:`UpdateStats`;
- :class:`GoalConditionedLearner`: the obs/goal normalisers and the inputs they make, host
  arrays as device tensors, the polyak move of (online, target) pairs, and the checkpoint of
  the learner's named parts (``PARTS``);
- :func:`frozen_q`: a critic evaluated through detached parameters, for the actor's loss;
- :func:`noisy_action`: DDPG's and TD3's exploration (Gaussian noise, then random actions).
"""

from __future__ import annotations

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
    """Per-update scalars: losses, the mean and mean square of Q(s, a) over the batch, (SAC only) the
    mean -log pi(a|s) of the actor's sampled actions, and Q(s, a) summed over the batch's real-goal and
    relabelled rows (the Q split by row type)."""

    critic_loss: float
    actor_loss: float
    q_mean: float
    q_sq_mean: float
    entropy: Optional[float] = None
    q_real_sum: float = 0.0
    q_hindsight_sum: float = 0.0

    @classmethod
    def of(cls, critic_loss: float, actor_loss: float, q: torch.Tensor, batch: TransitionBatch,
           entropy: Optional[float] = None) -> "UpdateStats":
        """The stats of an update whose critic gave q (B, 1), detached, on ``batch``."""
        relabelled = torch.from_numpy(batch.relabelled).to(q.device)
        q_rows = q.squeeze(1).double()
        return cls(critic_loss, actor_loss, q.mean().item(), torch.square(q).mean().item(), entropy,
                   q_rows[~relabelled].sum().item(), q_rows[relabelled].sum().item())


def frozen_q(critic: nn.Module, inputs: torch.Tensor) -> torch.Tensor:
    """Q of critic inputs (B, in_dim + action_dim) -> (B, 1) through detached parameters: gradients
    reach the inputs (the actor's action), never the critic."""
    frozen = {name: p.detach() for name, p in critic.named_parameters()}
    return torch.func.functional_call(critic, frozen, (inputs,))


def noisy_action(action: np.ndarray, cfg: DDPGConfig, max_action: float, rng: np.random.Generator) -> np.ndarray:
    """Add N(0, noise_eps * max_action) to actions (n, action_dim), clip, then with probability
    random_eps replace a whole action by a uniform random one."""
    action = np.clip(action + cfg.noise_eps * max_action * rng.standard_normal(action.shape), -max_action, max_action)
    random_action = rng.uniform(-max_action, max_action, size=action.shape)
    take_random = rng.random((action.shape[0], 1)) < cfg.random_eps
    return np.where(take_random, random_action, action)


class GoalConditionedLearner:
    """The input normalisers and the plumbing of a learner; subclasses build their networks and
    optimisers after calling this constructor, list their checkpointed parts in ``PARTS`` and
    define ``act``, ``update`` and ``update_targets``."""

    PARTS: tuple[str, ...] = ()  # attributes with state_dict/load_state_dict, in checkpoint order

    def __init__(self, cfg: DDPGConfig, obs_dim: int, goal_dim: int, max_action: float, gamma: float,
                 device: torch.device):
        self.cfg, self.max_action, self.gamma, self.device = cfg, max_action, gamma, device
        self.obs_norm = RunningNormalizer(obs_dim, cfg.norm_eps, cfg.clip_norm, device)
        self.goal_norm = RunningNormalizer(goal_dim, cfg.norm_eps, cfg.clip_norm, device)

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
    def polyak(self, *pairs: tuple[nn.Module, nn.Module]) -> None:
        """target <- polyak * target + (1 - polyak) * online for each (online, target) pair."""
        for online, target in pairs:
            torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), 1.0 - self.cfg.polyak)

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError

    @torch.no_grad()
    def policy_value(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Q(s, pi(s, g), g) of the deterministic policy for obs (n, obs_dim), goal (n, goal_dim) -> (n,)
        float64, by ``self.critic`` (the critic the actor climbs; TD3's and SAC's first twin)."""
        action = self.act(obs, goal, explore=False, rng=None) / self.max_action
        inputs = torch.cat([self._inputs(obs, goal), self.tensor(action.astype(np.float32))], dim=1)
        return self.critic(inputs).squeeze(1).cpu().numpy().astype(np.float64)

    def update(self, batch: TransitionBatch) -> UpdateStats:
        raise NotImplementedError

    def update_targets(self) -> None:
        raise NotImplementedError

    def state_dict(self) -> dict:
        return {name: getattr(self, name).state_dict() for name in self.PARTS}

    def load_state_dict(self, state: dict) -> None:
        for name, value in state.items():
            getattr(self, name).load_state_dict(value)
