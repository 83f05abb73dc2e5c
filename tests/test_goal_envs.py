"""Any goal-conditioned env: dimensions from the env, the vectorised reward equals the env's own."""

from __future__ import annotations

import numpy as np
import pytest

from hersd.compose import compose_train
from hersd.config import ConfigError
from hersd.envs import env_spec, make_env, reward_function
from hersd.run_state import RunState
from hersd.runlog import read_run
from hersd.train import evaluate, train


@pytest.mark.parametrize("overrides", [["task=reach"], ["task=hand_reach"], ["task=hand_block"],
                                       ["task=custom", "task.env_id=HandManipulateEggRotate-v1"],
                                       ["task=custom", "task.env_id=HandManipulatePenRotate-v1"]])
def test_the_vectorised_reward_equals_the_envs_own_on_real_goals(overrides):
    task = compose_train(overrides).task
    env = make_env(task)
    spec = env_spec(env)
    rng = np.random.default_rng(0)
    achieved, desired = [], []
    for episode in range(3):
        obs, _ = env.reset(seed=episode)
        desired.append(obs["desired_goal"])
        for _ in range(10):
            obs, *_ = env.step(env.action_space.sample())
            achieved.append(obs["achieved_goal"])
    achieved = np.array(achieved, np.float32)
    desired = np.array(desired, np.float32)[rng.integers(0, 3, len(achieved))]
    desired[::4] = achieved[::4]  # some exact successes too
    batched = reward_function(env, task.env_id)(achieved, desired)
    one_by_one = np.array([env.compute_reward(a, d, None) for a, d in zip(achieved, desired)], np.float32)
    assert batched.shape == (len(achieved),) and np.array_equal(batched, one_by_one)
    assert set(np.unique(batched)) == {-1.0, 0.0}
    assert (spec.goal_dim, spec.action_dim) == (achieved.shape[1], env.action_space.shape[0])
    env.close()


@pytest.mark.parametrize("env_id, message", [("NoSuchEnv-v0", "NoSuchEnv"), ("CartPole-v1", "not goal-conditioned")])
def test_an_unknown_or_plain_env_is_one_line(env_id, message):
    with pytest.raises(ConfigError, match=message) as err:
        make_env(compose_train(["task=custom", f"task.env_id={env_id}"]).task)
    assert "\n" not in str(err.value)


def test_an_env_whose_rewards_leave_the_clip_range_is_refused_in_one_line():
    """The mazes reward 1 on success: hersd's target clip to [q_min, 0] would be wrong for them."""
    task = compose_train(["task=custom", "task.env_id=PointMaze_UMaze-v3"]).task
    env = make_env(task)
    with pytest.raises(ConfigError, match=r"outside \[-1, 0\]") as err:
        reward_function(env, task.env_id)
    assert "\n" not in str(err.value)
    env.close()


@pytest.mark.slow
def test_hand_reach_ends_its_test_episodes_much_closer_to_the_goal_after_2_epochs(tmp_path):
    """HandReach (50 cycles/epoch, paper settings): success needs all five fingertips within
    1 cm, which a 2-epoch run rarely reaches, so the test reads the final distance instead."""
    cfg = compose_train(["task=hand_reach", "epochs=2", "seed=0", "quiet=true", "threads=1",
                         f"results_dir={tmp_path}"])
    _, untrained_distance = evaluate(RunState(cfg))
    log = read_run(train(cfg))
    assert log.epochs["test_distance"].iloc[-1] < 0.5 * untrained_distance.mean(), \
        (untrained_distance.mean(), log.epochs["test_distance"].tolist())
