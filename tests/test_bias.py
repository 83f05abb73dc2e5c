"""The bias evaluation (hersd/engine/bias.py): known returns through the time limit, hindsight goals valued by
rollouts from the restored state, and a run's metrics and folder untouched by it."""

import mujoco
import numpy as np
import pandas as pd
import pytest
from helpers import TINY, metrics

from hersd.engine.bias import MJ_STATE, BiasEvaluator, discounted_returns, draw_pairs, restore
from hersd.contract.compose import compose_train
from hersd.engine.envs.make import env_spec, make_env
from hersd.engine.envs.goal_envs import vectorised_reward
from hersd.contract.runlog import read_run
from hersd.engine.train import train

GAMMA = 0.98
BIAS_FIELDS = [f"{part}_{goal}_{stat}" for goal in ("real", "hindsight", "moved")
               for part, stat in (("bias", "mean"), ("bias", "std"), ("bias", "count"), ("return", "mean"))
               ] + ["bias_hindsight_zero_share"]


class GoalSeeker:
    """A stand-in policy for FetchReach: moves the gripper (obs[:, :3]) towards its goal at most ``speed``
    (a share of the largest step) per step, and values every state at ``value``."""

    def __init__(self, speed: float, value: float = -50.0):
        self.speed, self.value = speed, value

    def act(self, obs, goal, explore, rng):
        action = np.zeros((obs.shape[0], 4))
        action[:, :3] = np.clip(20.0 * (goal - obs[:, :3]), -self.speed, self.speed)
        return action

    def policy_value(self, obs, goal):
        return np.full(obs.shape[0], self.value)


def evaluator(*overrides: str) -> BiasEvaluator:
    cfg = compose_train(["task=reach", *overrides])
    env = make_env(cfg.task)
    evaluator = BiasEvaluator(cfg.bias, cfg.task, seed=0, horizon=env_spec(env).horizon, gamma=GAMMA,
                              reward=vectorised_reward(env))
    env.close()
    return evaluator


def test_discounted_returns_sum_each_window():
    rewards = np.array([[-1.0, 0.0, -1.0, -1.0]])
    assert discounted_returns(rewards, 0.5, 2).tolist() == [[-1.0, -0.5, -1.5]]


def test_returns_run_past_the_time_limit_as_the_critic_bootstraps():
    """A policy that never succeeds (success radius 1e-9 m): every return is -sum_{j<300} gamma^j = -49.88,
    the critic's fixed point -50 less the tail gamma^300 * 50; returns cut at the time limit T = 50 would
    give -18.2 from t = 0 and -1 from t = 49, and any other discount or horizon another number."""
    bias = evaluator("task.distance_threshold=1e-9", "bias.episodes=2", "bias.hindsight_pairs=0", "bias.moved_pairs=0")
    fields = bias.evaluate(GoalSeeker(speed=0.0, value=-50.0), epoch=1)
    expected = -(1 - GAMMA ** 300) / (1 - GAMMA)
    assert fields["return_real_mean"] == pytest.approx(expected, abs=1e-9)
    assert fields["bias_real_mean"] == pytest.approx(-50.0 - expected, abs=1e-9)  # Q - return = -0.116
    assert fields["bias_real_std"] == pytest.approx(0.0, abs=1e-9)
    assert fields["bias_real_count"] == 2 * 50  # every state s_t, t < T, of both episodes
    assert fields["bias_hindsight_count"] == 0 and fields["bias_hindsight_mean"] is None
    assert fields["bias_moved_count"] == 0 and fields["bias_hindsight_zero_share"] is None
    bias.close()


def test_hindsight_goals_are_valued_by_rollouts_pursuing_them_from_the_restored_state():
    """A slow goal seeker (2.5 mm a step) passes through its future achieved goals on the way to its real
    goal and leaves them behind; pursuing g' = ag_{t'} from the restored s_t, it is within the 5 cm radius
    after at most t' - t steps and stays: its return is at least -sum_{j < t'-t} gamma^j. The episode's own
    continuation (driven by the real goal) ends at the real goal, up to 25 cm away, failing for good."""
    bias = evaluator("bias.episodes=4", "bias.hindsight_pairs=16", "bias.moved_pairs=8")
    policy = GoalSeeker(speed=0.05, value=0.0)
    fields = bias.evaluate(policy, epoch=3)
    assert fields["bias_hindsight_count"] == 16 and fields["bias_moved_count"] == 8
    # moved pairs start outside the radius (some -1s) and are reached within t' - t <= T steps as well
    assert -(1 - GAMMA ** 50) / (1 - GAMMA) < fields["return_moved_mean"] < fields["return_hindsight_mean"] <= 0.0
    assert -5.0 < fields["return_hindsight_mean"] <= 0.0
    assert fields["bias_hindsight_mean"] == pytest.approx(-fields["return_hindsight_mean"])
    assert fields["return_real_mean"] < -15.0  # the real goal is far for this slow seeker: the case discriminates
    again = bias.evaluate(policy, epoch=3)
    assert again | {"bias_seconds": 0} == fields | {"bias_seconds": 0}  # its own stream: the same run and epoch
    bias.close()


def test_the_evaluation_changes_no_metric_and_no_run_folder(tmp_path):
    run = [o for o in TINY if o != "bias.epochs=[]"] + ["epochs=2", "seed=4", "quiet=true", "threads=1",
                                                        "bias.episodes=1", "bias.hindsight_pairs=2"]
    evaluated = train(compose_train([*run, "bias.epochs=[1,2]", f"results_dir={tmp_path / 'a'}"]))
    plain = train(compose_train([*run, "bias.epochs=[]", f"results_dir={tmp_path / 'b'}"]))
    pd.testing.assert_frame_equal(metrics(evaluated).drop(columns=BIAS_FIELDS), metrics(plain).drop(columns=BIAS_FIELDS))
    assert evaluated.relative_to(tmp_path / "a") == plain.relative_to(tmp_path / "b")
    logged = read_run(evaluated).epochs
    assert logged["bias_real_count"].tolist() == [50, 50] and logged["bias_hindsight_count"].tolist() == [2, 2]
    moved = logged["bias_moved_count"]  # 16, or 0 when the policy moved nothing beyond the radius
    assert moved.isin([0, 16]).all() and (logged["bias_moved_mean"].notna() == (moved == 16)).all()
    assert logged["bias_hindsight_zero_share"].between(0, 1).all()
    assert logged["bias_real_mean"].notna().all() and read_run(plain).epochs["bias_real_mean"].isna().all()


def test_q_split_by_row_type_recombines_into_q_mean(tmp_path):
    log = read_run(train(compose_train([*TINY, "epochs=2", "quiet=true", "threads=1", f"results_dir={tmp_path}"])))
    epochs = log.epochs
    share = epochs["share_hindsight"]
    recombined = share * epochs["q_hindsight_mean"] + (1 - share) * epochs["q_real_mean"]
    assert np.allclose(recombined, epochs["q_mean"], rtol=1e-5, atol=1e-6)
    assert (epochs["q_hindsight_mean"] != epochs["q_real_mean"]).all()


def test_a_policy_that_never_moves_gives_only_trivial_hindsight_pairs_and_no_moved_ones():
    """Standing still, every future achieved goal is the present one: each hindsight return is exactly 0
    (zero share 1) and no pair's goal lies beyond the success radius."""
    bias = evaluator("bias.episodes=2", "bias.hindsight_pairs=6", "bias.moved_pairs=4")
    fields = bias.evaluate(GoalSeeker(speed=0.0, value=0.0), epoch=1)
    assert fields["bias_hindsight_zero_share"] == 1.0 and fields["return_hindsight_mean"] == 0.0
    assert fields["bias_moved_count"] == 0 and fields["bias_moved_mean"] is None
    bias.close()


def test_moved_pairs_are_drawn_uniformly_among_the_pairs_beyond_the_radius():
    """One episode, T = 3, on a line: ag = 0, 0, 1, 3 (1-d goals). Pairs (t, t') with |ag_t' - ag_t| > 1.5:
    (0, 3), (1, 3), (2, 3) only, each drawn about a third of the time; none when nothing lies that far."""
    achieved = np.array([[[0.0], [0.0], [1.0], [3.0]]])
    episode, t, future = draw_pairs(np.random.default_rng(0), achieved, horizon=3, count=3000, radius=1.5)
    assert set(zip(t.tolist(), future.tolist())) == {(0, 3), (1, 3), (2, 3)} and (episode == 0).all()
    assert np.allclose(np.bincount(t, minlength=3) / 3000, 1 / 3, atol=0.03)
    assert all(part.size == 0 for part in draw_pairs(np.random.default_rng(0), achieved, 3, 5, radius=3.5))


def test_plain_pairs_keep_hers_future_draw():
    """Without a radius: t uniform in 0..T-1, t' uniform in t+1..T (every such pair reachable, none other)."""
    episode, t, future = draw_pairs(np.random.default_rng(1), np.zeros((2, 4, 1)), horizon=3, count=4000)
    assert set(zip(t.tolist(), future.tolist())) == {(a, b) for a in range(3) for b in range(a + 1, 4)}
    assert set(episode.tolist()) == {0, 1}


def _recorded_episode(env, seed: int, rng: np.random.Generator):
    """Reset ``env`` and step 50 random actions -> the first state, the actions (50, 4), the integration
    state before each step (50, size) and the observations after each (50, obs_dim)."""
    env.reset(seed=seed)
    size = mujoco.mj_stateSize(env.model, MJ_STATE)
    start = np.empty(size)
    mujoco.mj_getState(env.model, env.data, start, MJ_STATE)
    actions, states, obs = rng.uniform(-1, 1, (50, 4)), np.empty((50, size)), []
    for step, action in enumerate(actions):
        mujoco.mj_getState(env.model, env.data, states[step], MJ_STATE)
        obs.append(env.step(action)[0]["observation"])
    return start, actions, states, np.array(obs)


@pytest.mark.parametrize("task_name", ["pick_and_place", "push", "slide", "reach"])
def test_the_restore_is_exact_on_every_fetch_task(task_name):
    """A restored state's continuation under the recorded actions equals the recorded episode (to 1e-9; here
    bit for bit), the state reached by stepping again from the episode's start in an env with another history
    (another warm start). FetchPickAndPlace's step does not end with mj_forward: there setting the integration
    state at t directly drifts (by ~1e-3 here), and the test tells the two apart."""
    task = compose_train([f"task={task_name}"]).task
    env, restored = make_env(task), make_env(task)
    rng = np.random.default_rng(0)
    for seed in range(3):
        start, actions, states, obs = _recorded_episode(env, seed, rng)
        _recorded_episode(restored, seed + 10, rng)  # another episode first: the restoring env has a past
        t = 20
        restore(restored, start, actions[:t])
        continued = np.array([restored.step(action)[0]["observation"] for action in actions[t:]])
        assert np.abs(continued - obs[t:]).max() <= 1e-9
        if task_name != "pick_and_place":
            continue
        mujoco.mj_setState(restored.model, restored.data, states[t], MJ_STATE)
        mujoco.mj_forward(restored.model, restored.data)
        set_directly = np.array([restored.step(action)[0]["observation"] for action in actions[t:]])
        assert np.abs(set_directly - obs[t:]).max() > 1e-6
    env.close()
    restored.close()
