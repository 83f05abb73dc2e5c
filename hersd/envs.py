"""Goal-conditioned gymnasium-robotics envs (the Fetch tasks and any other), without wrappers.

The training loop runs exactly T steps per episode itself, so the TimeLimit and checker
wrappers are only overhead; the unwrapped env still computes ``is_success`` and rewards
as the registered one does. Rewards of relabelled transitions are recomputed in one call:
for Fetch by :func:`goal_reward`, for every other env by its family's rule
(:func:`hersd.goal_envs.vectorised_reward`).
"""

from __future__ import annotations

import contextlib
import io
from functools import partial
from typing import Any, Callable, NamedTuple

import gymnasium as gym
import numpy as np

from hersd.config import ConfigError, TaskConfig
from hersd.goal_envs import GOAL_KEYS, is_goal_env, reward_family, vectorised_reward

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


def make_env(task: TaskConfig, **make_kwargs: Any) -> Any:
    """One unwrapped goal env; ``task.distance_threshold`` (if set) replaces the success radius;
    ``make_kwargs`` go to ``gym.make`` (e.g. ``render_mode="rgb_array"``, :mod:`hersd.render`).
    An unknown env id or an env that is not goal-conditioned raises ConfigError (one line)."""
    try:
        env = gym.make(task.env_id, **make_kwargs).unwrapped
    except gym.error.Error as err:
        raise ConfigError(f"task.env_id={task.env_id!r}: {' '.join(str(err).split())[:200]}; goal-conditioned envs "
                          f"include: {', '.join(goal_env_ids()[:12])}, ...") from None
    if not is_goal_env(env):
        env.close()
        raise ConfigError(f"task.env_id={task.env_id!r} is not goal-conditioned (needs a dict observation with "
                          f"{', '.join(GOAL_KEYS)} and compute_reward); e.g. {', '.join(goal_env_ids()[:6])}")
    env.max_episode_steps = gym.spec(task.env_id).max_episode_steps
    if task.distance_threshold is not None:
        env.distance_threshold = float(task.distance_threshold)
    return env


def goal_env_ids() -> list[str]:
    """Registered gymnasium-robotics ids of sparse-reward Fetch and Hand envs (for error messages)."""
    return sorted(i for i in gym.registry if i.startswith(("Fetch", "Hand")) and "Dense" not in i)


def reward_function(env: Any, env_id: str) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The task's sparse reward as one vectorised call: achieved, desired (..., goal_dim) -> (...,) float32.

    Raises ConfigError for an env whose rewards leave [-1, 0] (the critic's target clip assumes
    them; e.g. the mazes give 1 on success)."""
    if env_id.startswith("Fetch"):
        return partial(goal_reward, distance_threshold=float(env.distance_threshold))
    reward = vectorised_reward(env)
    if reward_family(env) == "other":
        probe_rng = np.random.default_rng(0)  # a private generator: the env's and the run's stay untouched
        box = env.observation_space["desired_goal"]
        goals = np.clip(probe_rng.normal(size=(2, box.shape[0])), box.low, box.high)
        values = np.concatenate([reward(goals, goals), reward(goals, goals[::-1])])
        if np.any(values < -1) or np.any(values > 0):
            raise ConfigError(f"task.env_id={env_id!r} gives rewards {sorted(set(values.tolist()))}, outside [-1, 0]: "
                              "hersd's target clip to [q_min, 0] assumes sparse rewards -1 (fail) and 0 (success)")
    return reward


def env_spec(env: Any) -> EnvSpec:
    obs_space = env.observation_space
    return EnvSpec(
        obs_dim=obs_space["observation"].shape[0],
        goal_dim=obs_space["desired_goal"].shape[0],
        action_dim=env.action_space.shape[0],
        horizon=env.max_episode_steps,
        max_action=float(env.action_space.high[0]),
        distance_threshold=float(getattr(env, "distance_threshold", float("nan"))),
    )


def goal_reward(achieved: np.ndarray, desired: np.ndarray, distance_threshold: float) -> np.ndarray:
    """The Fetch sparse reward: 0 where ||achieved - desired|| <= threshold, else -1.

    achieved, desired: (..., goal_dim) -> (...,) float32. Same rule as the envs' compute_reward.
    """
    distance = np.linalg.norm(achieved - desired, axis=-1)
    return -(distance > distance_threshold).astype(np.float32)
