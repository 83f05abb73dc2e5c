"""Replay of whole episodes and HER relabelling.

Episodes are stored whole (the reference HER layout): ``obs``/``achieved`` are
(capacity, T+1, dim), ``goal``/``action`` are (capacity, T, dim). Transition t of episode
e is (obs[e, t], action[e, t], obs[e, t+1]) pursuing goal[e, t]; its reward depends only on
(achieved[e, t+1], goal), so it is recomputed after relabelling.

:func:`sample_transitions` is a pure function of the stored arrays, the relabel rate in
force and a numpy Generator: the schedule passes the rate on every call.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import numpy as np


class Episodes(NamedTuple):
    """A batch of n whole episodes: obs (n, T+1, obs_dim), achieved (n, T+1, goal_dim),
    goal (n, T, goal_dim), action (n, T, action_dim)."""

    obs: np.ndarray
    achieved: np.ndarray
    goal: np.ndarray
    action: np.ndarray


class TransitionBatch(NamedTuple):
    """B sampled transitions: obs/next_obs (B, obs_dim), goal (B, goal_dim), action
    (B, action_dim), reward (B,) already weighted by lambda_r or lambda_h, relabelled (B,)
    bool, real_success (B,) bool (kept real and given the success reward), episode/t (B,) int."""

    obs: np.ndarray
    next_obs: np.ndarray
    goal: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    relabelled: np.ndarray
    real_success: np.ndarray
    episode: np.ndarray
    t: np.ndarray


RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


class EpisodeBuffer:
    """A FIFO ring of whole episodes holding at most ``capacity_transitions // T`` episodes.

    (The reference code overwrites random episodes once full; with the paper's 1e6
    transitions and 200 epochs the buffer never fills, so the two agree there.)
    """

    def __init__(self, capacity_transitions: int, horizon: int, obs_dim: int, goal_dim: int, action_dim: int):
        self.capacity = max(1, capacity_transitions // horizon)
        self.horizon = horizon
        self.obs = np.zeros((self.capacity, horizon + 1, obs_dim), np.float32)
        self.achieved = np.zeros((self.capacity, horizon + 1, goal_dim), np.float32)
        self.goal = np.zeros((self.capacity, horizon, goal_dim), np.float32)
        self.action = np.zeros((self.capacity, horizon, action_dim), np.float32)
        self.size = 0
        self.next_slot = 0

    def store(self, episodes: Episodes) -> np.ndarray:
        """Copy n episodes in (oldest overwritten first); returns their slots, shape (n,)."""
        n = episodes.obs.shape[0]
        slots = (self.next_slot + np.arange(n)) % self.capacity
        self.obs[slots] = episodes.obs
        self.achieved[slots] = episodes.achieved
        self.goal[slots] = episodes.goal
        self.action[slots] = episodes.action
        self.next_slot = int((self.next_slot + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)
        return slots

    def stored(self) -> Episodes:
        """Views of the filled part, each (size, ...)."""
        return Episodes(self.obs[:self.size], self.achieved[:self.size], self.goal[:self.size],
                        self.action[:self.size])

    def state_dict(self) -> dict:
        return {"size": self.size, "next_slot": self.next_slot, **self.stored()._asdict()}

    def load_state_dict(self, state: dict) -> None:
        self.size, self.next_slot = int(state["size"]), int(state["next_slot"])
        for name in Episodes._fields:
            getattr(self, name)[:self.size] = state[name]


def hindsight_time(t: np.ndarray, horizon: int, strategy: str, rng: np.random.Generator) -> np.ndarray:
    """Index into ``achieved`` (0..T) of the hindsight goal for transitions at steps t (B,).

    future: uniform over t+1..T (a goal reached later in the episode); final: T;
    episode: uniform over 1..T (any goal reached in the episode).
    """
    if strategy == "future":
        return t + 1 + (rng.random(t.shape) * (horizon - t)).astype(np.int64)
    if strategy == "final":
        return np.full_like(t, horizon)
    if strategy == "episode":
        return rng.integers(1, horizon + 1, size=t.shape)
    raise ValueError(f"unknown goal strategy {strategy!r}")


def sample_transitions(episodes: Episodes, batch_size: int, relabel_prob: float, rng: np.random.Generator,
                       reward_fn: RewardFn, lambda_real: float = 1.0, lambda_hindsight: float = 1.0,
                       strategy: str = "future", episode_probs: Optional[np.ndarray] = None,
                       success_reward: float = 0.0) -> TransitionBatch:
    """Draw batch_size transitions and relabel each with probability relabel_prob.

    Episodes are drawn uniformly (or by ``episode_probs``, shape (n,), summing to 1), t
    uniformly in 0..T-1. Example with T = 50: a transition at t = 47 that is relabelled under
    'future' takes its goal from achieved[e, 48], [e, 49] or [e, 50]; its reward becomes
    lambda_hindsight * reward_fn(achieved[e, 48], that goal). ``success_reward`` is the raw
    reward that marks success (a sparse reward's highest: 0 for Fetch and Hand, 1 for the
    mazes); it only sorts the real transitions into real successes and failures.
    """
    n_episodes, horizon = episodes.goal.shape[0], episodes.goal.shape[1]
    if episode_probs is None:
        episode = rng.integers(0, n_episodes, size=batch_size)
    else:
        episode = rng.choice(n_episodes, size=batch_size, p=episode_probs)
    t = rng.integers(0, horizon, size=batch_size)
    relabelled = rng.random(batch_size) < relabel_prob
    goal = episodes.goal[episode, t]
    relabel_rows = np.flatnonzero(relabelled)
    if relabel_rows.size:
        goal_t = hindsight_time(t[relabel_rows], horizon, strategy, rng)
        goal[relabel_rows] = episodes.achieved[episode[relabel_rows], goal_t]
    next_achieved = episodes.achieved[episode, t + 1]
    raw_reward = reward_fn(next_achieved, goal)
    reward = raw_reward * np.where(relabelled, np.float32(lambda_hindsight), np.float32(lambda_real))
    return TransitionBatch(
        obs=episodes.obs[episode, t], next_obs=episodes.obs[episode, t + 1], goal=goal,
        action=episodes.action[episode, t], reward=reward.astype(np.float32), relabelled=relabelled,
        real_success=~relabelled & (raw_reward == success_reward), episode=episode, t=t,
    )
