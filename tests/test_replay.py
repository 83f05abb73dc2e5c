"""HER invariants of the sampler, on episodes whose achieved goals encode (episode, step)."""

import numpy as np
import pytest

from hersd.engine.envs.goal_envs import goal_reward
from hersd.engine.replay.buffer import EpisodeBuffer, Episodes, sample_transitions

T, N_EPISODES = 50, 40


def encoded_episodes(n: int = N_EPISODES, horizon: int = T) -> Episodes:
    """achieved[e, t] = (e, t, 0); desired goals far from every achieved goal."""
    episode = np.arange(n)[:, None].repeat(horizon + 1, axis=1)
    step = np.arange(horizon + 1)[None, :].repeat(n, axis=0)
    achieved = np.stack([episode, step, np.zeros_like(step)], axis=-1).astype(np.float32)
    obs = np.random.default_rng(0).standard_normal((n, horizon + 1, 5)).astype(np.float32)
    goal = np.full((n, horizon, 3), -100.0, np.float32)
    action = np.random.default_rng(1).standard_normal((n, horizon, 4)).astype(np.float32)
    return Episodes(obs, achieved, goal, action)


def reward_fn(achieved, goal):
    return goal_reward(achieved, goal, 0.05)


@pytest.mark.parametrize("relabel_prob", [0.0, 0.3, 0.8, 1.0])
def test_share_relabelled_matches_rate(relabel_prob):
    batch = sample_transitions(encoded_episodes(), 20_000, relabel_prob, np.random.default_rng(2), reward_fn)
    tolerance = 5 * np.sqrt(relabel_prob * (1 - relabel_prob) / 20_000) + 1e-12
    assert abs(batch.relabelled.mean() - relabel_prob) <= tolerance


@pytest.mark.parametrize("strategy", ["future", "final", "episode"])
def test_relabelled_goals_are_achieved_goals_of_the_same_episode(strategy):
    episodes = encoded_episodes()
    batch = sample_transitions(episodes, 5000, 0.8, np.random.default_rng(3), reward_fn, strategy=strategy)
    goal = batch.goal[batch.relabelled]
    t = batch.t[batch.relabelled]
    assert np.array_equal(goal[:, 0], batch.episode[batch.relabelled])  # same episode
    goal_step = goal[:, 1].astype(int)
    if strategy == "future":
        assert np.all(goal_step > t) and np.all(goal_step <= T)
        assert set(np.unique(goal_step - t)) >= {1, 2}  # not always the next step
    elif strategy == "final":
        assert np.all(goal_step == T)
    else:
        assert goal_step.min() >= 1 and goal_step.max() == T
    # goals kept real are the stored desired goals
    assert np.all(batch.goal[~batch.relabelled] == -100.0)


@pytest.mark.parametrize("lambdas", [(1.0, 1.0), (1.0, 0.5), (2.0, 0.25)])
def test_every_reward_is_lambda_times_reward_of_its_goal(lambdas):
    lambda_real, lambda_hindsight = lambdas
    episodes = encoded_episodes()
    batch = sample_transitions(episodes, 5000, 0.5, np.random.default_rng(4), reward_fn, lambda_real, lambda_hindsight)
    expected = reward_fn(episodes.achieved[batch.episode, batch.t + 1], batch.goal)
    weight = np.where(batch.relabelled, lambda_hindsight, lambda_real)
    assert np.array_equal(batch.reward, (weight * expected).astype(np.float32))
    # relabelled rewards include successes (goal reached at t+1), real ones never do here
    assert (batch.reward[batch.relabelled] == 0).any()
    assert np.all(batch.reward[~batch.relabelled] == -lambda_real)
    assert not batch.real_success.any()


def test_transition_fields_come_from_the_same_episode_and_step():
    episodes = encoded_episodes()
    batch = sample_transitions(episodes, 1000, 0.5, np.random.default_rng(5), reward_fn)
    assert np.array_equal(batch.obs, episodes.obs[batch.episode, batch.t])
    assert np.array_equal(batch.next_obs, episodes.obs[batch.episode, batch.t + 1])
    assert np.array_equal(batch.action, episodes.action[batch.episode, batch.t])
    assert batch.t.min() >= 0 and batch.t.max() == T - 1


def test_real_successes_are_counted():
    episodes = encoded_episodes()
    goal = episodes.goal.copy()
    goal[:] = episodes.achieved[:, 1:]  # every real transition reaches its own goal
    batch = sample_transitions(episodes._replace(goal=goal), 1000, 0.25, np.random.default_rng(6), reward_fn)
    assert np.array_equal(batch.real_success, ~batch.relabelled)


def test_real_successes_are_the_success_reward_of_the_env():
    """A maze-like reward (1 on success, 0 otherwise): success_reward=1 sorts the real transitions,
    and a failure's 0 is not taken for the Fetch success reward."""
    episodes = encoded_episodes()
    goal = episodes.goal.copy()
    goal[::2] = episodes.achieved[::2, 1:]  # real transitions of even episodes reach their goal

    def maze_reward(achieved, desired):
        return goal_reward(achieved, desired, 0.05) + np.float32(1.0)

    batch = sample_transitions(episodes._replace(goal=goal), 1000, 0.25, np.random.default_rng(6), maze_reward,
                               success_reward=1.0)
    assert np.array_equal(batch.real_success, ~batch.relabelled & (batch.episode % 2 == 0))
    assert batch.real_success.any() and (~batch.relabelled & ~batch.real_success).any()


def test_same_generator_state_gives_same_batch():
    episodes = encoded_episodes()
    first = sample_transitions(episodes, 256, 0.8, np.random.default_rng(7), reward_fn)
    second = sample_transitions(episodes, 256, 0.8, np.random.default_rng(7), reward_fn)
    for a, b in zip(first, second):
        assert np.array_equal(a, b)


def test_buffer_is_a_fifo_ring_of_whole_episodes():
    episodes = encoded_episodes(n=7, horizon=4)
    buffer = EpisodeBuffer(capacity_transitions=20, horizon=4, obs_dim=5, goal_dim=3, action_dim=4)
    assert buffer.capacity == 5
    buffer.store(Episodes(*(x[:3] for x in episodes)))
    assert buffer.size == 3
    slots = buffer.store(Episodes(*(x[3:7] for x in episodes)))
    assert list(slots) == [3, 4, 0, 1] and buffer.size == 5
    assert np.array_equal(buffer.achieved[:, 0, 0], [5, 6, 2, 3, 4])  # episodes 0, 1 overwritten
    restored = EpisodeBuffer(capacity_transitions=20, horizon=4, obs_dim=5, goal_dim=3, action_dim=4)
    restored.load_state_dict(buffer.state_dict())
    assert restored.next_slot == buffer.next_slot and np.array_equal(restored.obs, buffer.obs)
