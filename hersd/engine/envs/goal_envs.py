"""Rewards of any gymnasium-robotics goal-conditioned env, for relabelled batches.

HER recomputes the reward of every relabelled transition, so the replay needs the env's
reward rule as a vectorised function of (achieved, desired) goals. :func:`vectorised_reward`
returns it by the env's family (read from its class hierarchy, so the MuJoCo and mujoco-py
variants and the touch-sensor variants are covered alike):

- fetch, hand_reach: sparse -(||a - g|| > distance_threshold), dense -||a - g||
  (gymnasium_robotics/envs/fetch/fetch_env.py, shadow_dexterous_hand/reach.py);
- hand_manipulate: goals are (position (3), quaternion (4)); d_pos = ||a_pos - g_pos|| (0 if
  target_position is "ignore"), d_rot = 2 arccos(clip(<a_quat, g_quat>, -1, 1)) (0 if
  target_rotation is "ignore"; with ignore_z_target_rotation the achieved Euler z angle is
  first replaced by the desired one); sparse: 0 where d_pos < distance_threshold and
  d_rot < rotation_threshold, else -1; dense: -(10 d_pos + d_rot)
  (shadow_dexterous_hand/manipulate.py). The env's own batched ``compute_reward`` is wrong
  for ignore_z_target_rotation (the Pen tasks): it overwrites row 2 of the Euler batch
  instead of column 2; the rule here applies the per-pair one to every row;
- maze (PointMaze, AntMaze): the env's own ``compute_reward``, which takes batches: sparse
  1 where ||a - g|| <= 0.45, else 0; dense exp(-||a - g||) (envs/maze/maze_v4.py);
- other: the env's own ``compute_reward`` when it accepts a batch (probed at creation: a
  2-row call must equal the two 1-row calls), else one call per row (slow).

Unlike the env's own batched ``compute_reward``, the rules here are also right for the Pen
tasks and take goals with more than one leading dimension (the env's quaternion product
asserts on (n, T, 7) arrays).

Rewards are float32 (...,) for goals (..., goal_dim). The env's settings (thresholds, reward
type, targets) are read once, when :func:`vectorised_reward` is called.

The family also gives what the learner needs besides the reward: :func:`reward_range`, the
bounds of one reward (the critic's target clip follows from them, hersd/engine/run_state.py), and
:func:`success_radius`, the goal distance that counts as success (logged with the run).
"""

from __future__ import annotations

import contextlib
import io
import math
from functools import partial
from typing import Any, Callable

import gymnasium as gym
import numpy as np

with contextlib.redirect_stderr(io.StringIO()):  # gymnasium-robotics' import-time notice on the Adroit envs
    from gymnasium_robotics.utils import rotations

RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")
_FAMILY_BASES = {"BaseFetchEnv": "fetch", "BaseHandReachEnv": "hand_reach", "BaseManipulateEnv": "hand_manipulate",
                 "MazeEnv": "maze"}
# The mazes' success radius, fixed in their compute_reward, compute_terminated and info["success"]
# (gymnasium_robotics/envs/maze/maze_v4.py): they have no distance_threshold attribute.
MAZE_SUCCESS_RADIUS = 0.45


def is_goal_env(env: Any) -> bool:
    """True for an env (wrapped or not) whose observations are a Dict of 1-D Boxes
    observation / achieved_goal / desired_goal (the two goals of one shape) and that has a
    callable ``compute_reward(achieved, desired, info)``."""
    env = getattr(env, "unwrapped", env)
    space = getattr(env, "observation_space", None)
    if not isinstance(space, gym.spaces.Dict) or not all(key in space.spaces for key in GOAL_KEYS):
        return False
    boxes = [space[key] for key in GOAL_KEYS]
    if not all(isinstance(box, gym.spaces.Box) and len(box.shape) == 1 for box in boxes):
        return False
    return boxes[1].shape == boxes[2].shape and callable(getattr(env, "compute_reward", None))


def reward_family(env: Any) -> str:
    """fetch | hand_reach | hand_manipulate | maze | other: which rule :func:`vectorised_reward` uses."""
    env = getattr(env, "unwrapped", env)
    for cls in type(env).__mro__:
        if cls.__module__.startswith("gymnasium_robotics.") and cls.__name__ in _FAMILY_BASES:
            return _FAMILY_BASES[cls.__name__]
    return "other"


def vectorised_reward(env: Any) -> RewardFn:
    """The reward rule of a goal env: (achieved (..., goal_dim), desired (..., goal_dim)) -> (...,) float32.

    Raises ValueError if ``env`` is not a goal env (see :func:`is_goal_env`).
    """
    if not is_goal_env(env):
        raise ValueError(f"{type(getattr(env, 'unwrapped', env)).__name__} is not a goal-conditioned env: its "
                         f"observations need {', '.join(GOAL_KEYS)} (1-D boxes) and it needs compute_reward")
    env = env.unwrapped
    family = reward_family(env)
    if family in ("fetch", "hand_reach"):
        return _distance_reward(float(env.distance_threshold), env.reward_type == "sparse")
    if family == "hand_manipulate":
        return _manipulate_reward(env)
    return _env_reward(env)


def reward_range(env: Any) -> tuple[float, float]:
    """(lowest, highest) reward the env can give, by family; an infinite bound where none is known.

    Sparse Fetch and Hand rewards are -1 or 0; their dense rewards, -distance, have no lower
    bound the env states (-inf). The mazes give 0 or 1 (sparse) and exp(-distance) in (0, 1]
    (dense). Any other env's range is unknown: (-inf, inf)."""
    env = getattr(env, "unwrapped", env)
    family = reward_family(env)
    if family == "maze":
        return 0.0, 1.0
    if family == "other":
        return -math.inf, math.inf
    return (-1.0 if env.reward_type == "sparse" else -math.inf), 0.0


def success_radius(env: Any) -> float:
    """The goal distance within which the env counts success: its ``distance_threshold`` (Fetch, Hand;
    for HandManipulate the position's, next to its rotation_threshold), the mazes' fixed 0.45,
    NaN for an env that states none."""
    env = getattr(env, "unwrapped", env)
    if reward_family(env) == "maze":
        return MAZE_SUCCESS_RADIUS
    return float(getattr(env, "distance_threshold", math.nan))


def goal_reward(achieved: np.ndarray, desired: np.ndarray, distance_threshold: float) -> np.ndarray:
    """The sparse reward of Fetch and HandReach: 0 where ||achieved - desired|| <= threshold, else -1.

    achieved, desired: (..., goal_dim) -> (...,) float32. Same rule as the envs' compute_reward.
    """
    distance = np.linalg.norm(achieved - desired, axis=-1)
    return -(distance > distance_threshold).astype(np.float32)


def _distance_reward(threshold: float, sparse: bool) -> RewardFn:
    if sparse:
        return partial(goal_reward, distance_threshold=threshold)

    def dense_reward(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        return (-np.linalg.norm(achieved - desired, axis=-1)).astype(np.float32)

    return dense_reward


def _manipulate_reward(env: Any) -> RewardFn:
    use_pos, use_rot = env.target_position != "ignore", env.target_rotation != "ignore"
    ignore_z, sparse = bool(env.ignore_z_target_rotation), env.reward_type == "sparse"
    pos_threshold, rot_threshold = float(env.distance_threshold), float(env.rotation_threshold)

    def distances(achieved: np.ndarray, desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d_pos = np.zeros_like(achieved[..., 0])
        d_rot = np.zeros_like(desired[..., 0])
        if use_pos:
            d_pos = np.linalg.norm(achieved[..., :3] - desired[..., :3], axis=-1)
        if use_rot:
            quat_a, quat_b = achieved[..., 3:], desired[..., 3:]
            if ignore_z:
                euler_a, euler_b = rotations.quat2euler(quat_a), rotations.quat2euler(quat_b)
                euler_a[..., 2] = euler_b[..., 2]
                quat_a = rotations.euler2quat(euler_a)
            # real part of quat_a * conj(quat_b), summed in the order the env's quat_mul sums it
            w = quat_a[..., 0] * quat_b[..., 0] + quat_a[..., 1] * quat_b[..., 1] \
                + quat_a[..., 2] * quat_b[..., 2] + quat_a[..., 3] * quat_b[..., 3]
            d_rot = 2 * np.arccos(np.clip(w, -1.0, 1.0))
        return d_pos, d_rot

    def reward(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        d_pos, d_rot = distances(achieved, desired)
        if sparse:
            return ((d_pos < pos_threshold) & (d_rot < rot_threshold)).astype(np.float32) - np.float32(1.0)
        return (-(10.0 * d_pos + d_rot)).astype(np.float32)

    return reward


def _env_reward(env: Any) -> RewardFn:
    """The env's compute_reward, called once on the whole batch if it handles batches, else per row."""
    space = env.observation_space
    probe_rng = np.random.default_rng(0)  # a private generator: the env's and the run's stay untouched
    box = space["achieved_goal"]
    goals = [np.clip(probe_rng.normal(size=(2, box.shape[0])), box.low, box.high) for _ in range(2)]
    try:
        batched = np.asarray(env.compute_reward(goals[0], goals[1], [{}, {}]), dtype=np.float64)
        rows = np.array([env.compute_reward(goals[0][i], goals[1][i], {}) for i in range(2)], dtype=np.float64)
        accepts_batches = batched.shape == (2,) and np.array_equal(batched, rows)
    except Exception:  # noqa: BLE001 - any failure of the batched call means: call it per row
        accepts_batches = False

    def reward(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        shape = achieved.shape[:-1]
        flat_a, flat_d = achieved.reshape(-1, achieved.shape[-1]), desired.reshape(-1, desired.shape[-1])
        if accepts_batches:
            values = env.compute_reward(flat_a, flat_d, [{}] * flat_a.shape[0])
        else:
            values = [env.compute_reward(a, d, {}) for a, d in zip(flat_a, flat_d)]
        return np.asarray(values, dtype=np.float32).reshape(shape)

    return reward
