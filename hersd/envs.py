"""The Fetch tasks of gymnasium-robotics, used without gymnasium's wrappers.

The training loop runs exactly T steps per episode itself, so the TimeLimit and checker
wrappers are only overhead; the unwrapped env still computes ``is_success`` and rewards
as the registered one does.
"""

from __future__ import annotations

import contextlib
import io
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from hersd.config import TaskConfig

# gymnasium-robotics prints a notice about the Adroit envs' rewards at import; it does not
# concern the Fetch tasks and would otherwise open every run's output.
with contextlib.redirect_stderr(io.StringIO()):
    import gymnasium_robotics

gym.register_envs(gymnasium_robotics)


class EnvSpec(NamedTuple):
    """Sizes of a task: observation, goal and action dimensions, horizon T, max action."""

    obs_dim: int
    goal_dim: int
    action_dim: int
    horizon: int
    max_action: float
    distance_threshold: float


def make_env(task: TaskConfig) -> Any:
    """One unwrapped Fetch env; ``task.distance_threshold`` (if set) replaces the success radius."""
    env = gym.make(task.env_id).unwrapped
    env.max_episode_steps = gym.spec(task.env_id).max_episode_steps
    if task.distance_threshold is not None:
        env.distance_threshold = float(task.distance_threshold)
    return env


def env_spec(env: Any) -> EnvSpec:
    obs_space = env.observation_space
    return EnvSpec(
        obs_dim=obs_space["observation"].shape[0],
        goal_dim=obs_space["desired_goal"].shape[0],
        action_dim=env.action_space.shape[0],
        horizon=env.max_episode_steps,
        max_action=float(env.action_space.high[0]),
        distance_threshold=float(env.distance_threshold),
    )


def goal_reward(achieved: np.ndarray, desired: np.ndarray, distance_threshold: float) -> np.ndarray:
    """The Fetch sparse reward: 0 where ||achieved - desired|| <= threshold, else -1.

    achieved, desired: (..., goal_dim) -> (...,) float32. Same rule as the envs' compute_reward.
    """
    distance = np.linalg.norm(achieved - desired, axis=-1)
    return -(distance > distance_threshold).astype(np.float32)
