"""hersd.engine.envs.goal_envs: the vectorised reward of each env family equals the env's own compute_reward
on (achieved, desired) pairs drawn from real observations (pair by pair: the env's batched call is
wrong for the Pen tasks, see hersd/engine/envs/goal_envs.py); the family's reward range and success radius
are the env's."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import hersd.engine.envs.make  # noqa: F401  (registers the gymnasium-robotics envs quietly)
from hersd.engine.envs.goal_envs import is_goal_env, reward_family, reward_range, success_radius, vectorised_reward

pytestmark = pytest.mark.usefixtures("private_tempdir")  # maze envs' model files stay in tmp_path

FAMILIES = {
    "FetchReach-v4": "fetch",
    "FetchReachDense-v4": "fetch",
    "HandReach-v3": "hand_reach",
    "HandManipulateBlockRotateZ-v1": "hand_manipulate",
    "HandManipulateEggFull-v1": "hand_manipulate",  # position and rotation both count
    "HandManipulateBlockFullDense-v1": "hand_manipulate",  # dense: -(10 d_pos + d_rot)
    "HandManipulatePenRotate-v1": "hand_manipulate",  # ignore_z_target_rotation
    "PointMaze_UMaze-v3": "maze",  # 1 on success, else 0
    "PointMaze_UMazeDense-v3": "maze",  # exp(-distance)
    "AntMaze_UMaze-v5": "maze",
}


def real_goals(env_id: str, episodes: int = 3, steps: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """Achieved goals of random-action rollouts (episodes, steps + 1, g) and desired goals of resets (episodes, g)."""
    env = gym.make(env_id).unwrapped
    env.action_space.seed(0)
    achieved, desired = [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        desired.append(obs["desired_goal"])
        trajectory = [obs["achieved_goal"]]
        for _ in range(steps):
            obs = env.step(env.action_space.sample())[0]
            trajectory.append(obs["achieved_goal"])
        achieved.append(trajectory)
    env.close()
    return np.asarray(achieved, np.float64), np.asarray(desired, np.float64)


def pairs(env_id: str) -> tuple[np.ndarray, np.ndarray]:
    """(achieved, desired) (B, g): achieved goals against reset goals, against later achieved goals of
    their episode (what 'future' relabelling pairs), and against small perturbations of themselves
    straddling the success thresholds (so both rewards occur)."""
    rng = np.random.default_rng(1)
    achieved, desired = real_goals(env_id)
    n_episodes, n_steps, dim = achieved.shape
    flat = achieved.reshape(-1, dim)
    against_reset = (flat, np.repeat(desired, n_steps, axis=0))
    t = rng.integers(0, n_steps - 1, 64)
    later = t + 1 + (rng.random(64) * (n_steps - 1 - t)).astype(int)
    episode = rng.integers(0, n_episodes, 64)
    against_future = (achieved[episode, t], achieved[episode, later])
    base = flat[rng.integers(0, len(flat), 64)]
    near = base.copy()
    if dim == 7:  # position, quaternion: rotate by up to 0.2 rad (threshold 0.1), shift by up to 2 cm (1 cm)
        axis = rng.normal(size=(64, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        angle = rng.uniform(0, 0.2, 64)
        turn = np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis], axis=1)
        near[:, 3:] = [quat_mul(q, r) for q, r in zip(base[:, 3:], turn)]
        near[:, :3] += rng.normal(size=(64, 3)) * rng.uniform(0, 0.02, (64, 1)) / np.sqrt(3)
    else:  # shift by up to twice the success radius in a random direction
        step = rng.normal(size=(64, dim))
        radius = getattr(gym.make(env_id).unwrapped, "distance_threshold", 0.45)
        near += step / np.linalg.norm(step, axis=1, keepdims=True) * rng.uniform(0, 2 * radius, (64, 1))
    against_near = (base, near)
    parts = (against_reset, against_future, against_near)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def quat_mul(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    w0, x0, y0, z0 = q
    w1, x1, y1, z1 = r
    return np.array([w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                     w0 * y1 + y0 * w1 + z0 * x1 - x0 * z1, w0 * z1 + z0 * w1 + x0 * y1 - y0 * x1])


@pytest.fixture(scope="module", params=list(FAMILIES))
def case(request):
    env_id = request.param
    env = gym.make(env_id)  # wrapped: the functions unwrap it themselves
    achieved, desired = pairs(env_id)
    yield env_id, env, achieved, desired
    env.close()


def test_goal_envs_are_recognised_and_sorted_into_their_family(case):
    env_id, env, _, _ = case
    assert is_goal_env(env)
    assert reward_family(env) == FAMILIES[env_id]


def test_vectorised_reward_equals_the_envs_own_compute_reward_row_by_row(case):
    env_id, env, achieved, desired = case
    reward = vectorised_reward(env)(achieved, desired)
    expected = np.array([env.unwrapped.compute_reward(a, d, {}) for a, d in zip(achieved, desired)])
    assert reward.dtype == np.float32 and reward.shape == (len(achieved),)
    np.testing.assert_allclose(reward, expected, rtol=1e-6, atol=1e-6)
    if "Dense" not in env_id:  # both outcomes occur, so a wrong threshold or distance would show
        assert len(np.unique(reward)) == 2, np.unique(reward)


def test_rewards_lie_in_the_familys_range_and_sparse_ones_at_its_two_ends(case):
    env_id, env, achieved, desired = case
    low, high = reward_range(env)
    reward = vectorised_reward(env)(achieved, desired)
    assert np.all((low <= reward) & (reward <= high)), (low, high, reward.min(), reward.max())
    if "Dense" not in env_id:
        assert set(np.unique(reward)) == {low, high}
    else:
        assert np.isinf(low) or low < reward.min()  # a dense reward: the range is a bound, not the values


@pytest.mark.parametrize("env_id", ["FetchReach-v4", "HandReach-v3", "PointMaze_UMaze-v3"])
def test_the_success_radius_is_where_the_envs_sparse_reward_changes(env_id):
    env = gym.make(env_id).unwrapped
    radius, (low, high) = success_radius(env), reward_range(env)
    goal = np.zeros(env.observation_space["desired_goal"].shape[0])
    inside, outside = goal.copy(), goal.copy()
    inside[0], outside[0] = 0.99 * radius, 1.01 * radius
    assert (env.compute_reward(inside, goal, {}), env.compute_reward(outside, goal, {})) == (high, low)
    env.close()


def test_vectorised_reward_takes_float32_goals_and_any_leading_shape(case):
    """The replay stores goals as float32 and may pass (n, T, g) arrays."""
    env_id, env, achieved, desired = case
    a32, d32 = achieved[:60].astype(np.float32), desired[:60].astype(np.float32)
    reward = vectorised_reward(env)(a32.reshape(4, 15, -1), d32.reshape(4, 15, -1))
    expected = np.array([env.unwrapped.compute_reward(a, d, {}) for a, d in zip(a32, d32)])
    assert reward.shape == (4, 15)
    np.testing.assert_allclose(reward.reshape(-1), expected, rtol=1e-5, atol=1e-5)


def test_batched_compute_reward_agrees_where_the_env_handles_batches():
    """Fetch, HandReach and HandManipulate without ignore_z: the env's own batched call is the reference too."""
    for env_id in ("FetchReach-v4", "HandReach-v3", "HandManipulateBlockRotateZ-v1"):
        env = gym.make(env_id).unwrapped
        achieved, desired = pairs(env_id)
        np.testing.assert_array_equal(vectorised_reward(env)(achieved, desired),
                                      env.compute_reward(achieved, desired, None).astype(np.float32))
        env.close()


def test_the_threshold_is_the_envs():
    env = gym.make("FetchReach-v4").unwrapped
    achieved, desired = np.zeros((2, 3)), np.array([[0.04, 0, 0], [0.06, 0, 0]])
    assert vectorised_reward(env)(achieved, desired).tolist() == [0.0, -1.0]
    env.distance_threshold = 0.07  # as task.distance_threshold sets it
    assert vectorised_reward(env)(achieved, desired).tolist() == [0.0, 0.0]


class RowOnlyGoalEnv(gym.Env):
    """A goal env whose compute_reward only takes one pair (float() of a norm)."""

    observation_space = gym.spaces.Dict({key: gym.spaces.Box(-1, 1, (2,)) for key in
                                         ("observation", "achieved_goal", "desired_goal")})
    action_space = gym.spaces.Box(-1, 1, (2,))

    def compute_reward(self, achieved_goal, desired_goal, info):
        return -float(float(np.linalg.norm(achieved_goal - desired_goal)) > 0.5)


def test_an_env_that_takes_one_pair_at_a_time_is_called_per_row():
    env = RowOnlyGoalEnv()
    rng = np.random.default_rng(0)
    achieved, desired = rng.uniform(-1, 1, (50, 2)), rng.uniform(-1, 1, (50, 2))
    expected = [env.compute_reward(a, d, {}) for a, d in zip(achieved, desired)]
    assert reward_family(env) == "other" and len(set(expected)) == 2
    assert vectorised_reward(env)(achieved, desired).tolist() == expected
    assert reward_range(env) == (-np.inf, np.inf) and np.isnan(success_radius(env))  # nothing known: no clip


def test_envs_without_vector_goals_are_refused():
    class NoGoals(RowOnlyGoalEnv):
        observation_space = gym.spaces.Box(-1, 1, (2,))

    class NoReward(gym.Env):
        observation_space = RowOnlyGoalEnv.observation_space

    class DictGoal(RowOnlyGoalEnv):  # like FrankaKitchen: goals are dicts of tasks
        observation_space = gym.spaces.Dict({"observation": gym.spaces.Box(-1, 1, (2,)),
                                             "achieved_goal": gym.spaces.Dict({"a": gym.spaces.Box(-1, 1, (2,))}),
                                             "desired_goal": gym.spaces.Dict({"a": gym.spaces.Box(-1, 1, (2,))})})

    assert is_goal_env(RowOnlyGoalEnv())
    for env in (NoGoals(), NoReward(), DictGoal()):
        assert not is_goal_env(env)
        with pytest.raises(ValueError, match="not a goal-conditioned env"):
            vectorised_reward(env)
