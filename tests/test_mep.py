"""MEP prioritisation: the priorities, the sampler under them, and MEP inside a training run."""

import math

import numpy as np
import pandas as pd
import pytest

import hersd.engine.replay.mep as mep_module
import hersd.engine.train as train_module
from hersd.contract.compose import compose_train as compose
from hersd.contract.config import MEPConfig
from hersd.engine.envs.goal_envs import goal_reward
from hersd.engine.replay.mep import EpisodePrioritizer, entropy, rank_priorities
from hersd.engine.replay.buffer import Episodes, sample_transitions
from helpers import TIMING
from hersd.contract.runlog import read_run
from hersd.engine.train import train

HORIZON = 50
# 3 cycles of 4 updates on small networks: enough stored episodes for a mixture fit in epoch 2; no bias
# evaluation (tests/test_bias.py evaluates).
TINY = ["task=reach", "task.cycles_per_epoch=3", "ddpg.batches_per_cycle=4", "ddpg.test_rollouts=1",
        "ddpg.batch_size=64", "ddpg.hidden_units=32", "quiet=true", "threads=1", "bias.epochs=[]"]


def reward_fn(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
    return goal_reward(achieved, goal, 0.05)


def still_and_moving_trajectories(rng: np.random.Generator, n_still: int, n_moving: int) -> np.ndarray:
    """Achieved goals (n_still + n_moving, T+1, 3) shaped like FetchPush's: objects placed uniformly
    on the table (+-15 cm) that stay put (the common case), then ones pushed 20 cm along the
    table in a random direction (rare)."""
    n = n_still + n_moving
    start = np.array([1.3, 0.75, 0.42]) + rng.uniform(-0.15, 0.15, (n, 1, 3)) * [1, 1, 0]
    achieved = np.repeat(start, HORIZON + 1, axis=1) + rng.normal(0, 1e-3, (n, HORIZON + 1, 3))
    direction = rng.normal(0, 1, (n_moving, 1, 3)) * [1, 1, 0]
    progress = np.linspace(0, 0.2, HORIZON + 1)[None, :, None]
    achieved[n_still:] += progress * direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    return achieved.astype(np.float32)


def test_priorities_are_a_distribution_increasing_with_rarity():
    rarity = np.array([3.0, -1.0, 10.0, 3.0, 0.5])
    probs = rank_priorities(rarity, temperature=1.0)
    assert probs.shape == (5,) and np.all(probs > 0) and probs.sum() == pytest.approx(1.0)
    assert list(np.argsort(probs, kind="stable")) == [1, 4, 0, 3, 2]
    assert probs[0] == probs[3]  # equal rarities share a rank
    flatter = rank_priorities(rarity, temperature=10.0)
    assert entropy(flatter) > entropy(probs) and entropy(flatter) < math.log(5)


def test_entropy_in_nats():
    assert entropy(np.full(8, 1 / 8)) == pytest.approx(math.log(8))
    assert entropy(np.array([1.0, 0.0, 0.0])) == 0.0


def test_rare_trajectories_get_higher_priority():
    rng = np.random.default_rng(0)
    achieved = still_and_moving_trajectories(rng, n_still=600, n_moving=4)
    prioritizer = EpisodePrioritizer(MEPConfig(enabled=True), capacity=700)
    assert prioritizer.probs(604) is None and prioritizer.entropy(604) == pytest.approx(math.log(604))
    prioritizer.fit(achieved, rng)
    probs = prioritizer.probs(604)
    assert probs.shape == (604,) and probs.sum() == pytest.approx(1.0)
    assert probs[600:].min() > probs[:600].max()
    assert prioritizer.entropy(604) < math.log(604)


def test_rare_trajectories_stay_on_top_when_fit_on_a_subsample():
    """Trajectories inside the fitted subsample score a little denser than those outside (the
    model overfits slightly in (T+1) * 3 = 153 dimensions), but far less than rare ones differ."""
    rng = np.random.default_rng(0)
    achieved = still_and_moving_trajectories(rng, n_still=600, n_moving=4)
    prioritizer = EpisodePrioritizer(MEPConfig(enabled=True, fit_subsample=400), capacity=700)
    prioritizer.fit(achieved, rng)
    probs = prioritizer.probs(604)
    assert probs[600:].min() > np.quantile(probs[:600], 0.95)


def test_new_episodes_are_scored_with_the_current_model():
    rng = np.random.default_rng(1)
    achieved = still_and_moving_trajectories(rng, n_still=200, n_moving=0)
    prioritizer = EpisodePrioritizer(MEPConfig(enabled=True), capacity=210)
    prioritizer.fit(achieved, rng)
    new = still_and_moving_trajectories(rng, n_still=1, n_moving=1)
    prioritizer.score_new(np.array([200, 201]), new)
    probs = prioritizer.probs(202)
    assert np.argmax(probs) == 201 and probs[201] > probs[200]


def test_too_few_episodes_to_fit_keeps_uniform_sampling():
    prioritizer = EpisodePrioritizer(MEPConfig(enabled=True), capacity=10)
    prioritizer.fit(np.zeros((2, HORIZON + 1, 3), np.float32), np.random.default_rng(0))
    assert not prioritizer.fitted and prioritizer.probs(2) is None


def test_sampling_frequencies_follow_the_priorities():
    rng = np.random.default_rng(2)
    n = 12
    episodes = Episodes(obs=np.zeros((n, HORIZON + 1, 2), np.float32),
                        achieved=np.zeros((n, HORIZON + 1, 3), np.float32),
                        goal=np.ones((n, HORIZON, 3), np.float32), action=np.zeros((n, HORIZON, 4), np.float32))
    probs = rank_priorities(rng.normal(size=n), temperature=0.5)
    draws = 200_000
    episode = np.concatenate([sample_transitions(episodes, 10_000, 0.8, rng, reward_fn, episode_probs=probs).episode
                              for _ in range(draws // 10_000)])
    frequency = np.bincount(episode, minlength=n) / draws
    standard_error = np.sqrt(probs * (1 - probs) / draws)
    assert np.all(np.abs(frequency - probs) < 5 * standard_error)


def test_mep_off_leaves_the_training_sampler_untouched(tmp_path, monkeypatch):
    """With mep.enabled=false no MEP object exists and every draw is the uniform one, so the run
    consumes its Generator exactly as before MEP existed (docs/MEP.md records the batch digest
    check against the commit before MEP)."""

    def no_prioritizer(*_args, **_kwargs):
        raise AssertionError("EpisodePrioritizer built with MEP off")

    recorded_probs, batches = [], []

    def recording_sampler(*args, **kwargs):
        recorded_probs.append(kwargs.get("episode_probs"))
        batch = sample_transitions(*args, **kwargs)
        batches.append((batch.episode, batch.t, batch.goal))
        return batch

    monkeypatch.setattr(mep_module, "EpisodePrioritizer", no_prioritizer)  # where the run state finds it
    monkeypatch.setattr(train_module, "sample_transitions", recording_sampler)
    log = read_run(train(compose([*TINY, "epochs=2", f"results_dir={tmp_path}"])))
    assert recorded_probs and all(p is None for p in recorded_probs)
    assert log.epochs["mep_fit_seconds"].isna().all() and log.epochs["priority_entropy"].isna().all()
    first_run = batches[:]
    batches.clear()
    train(compose([*TINY, "epochs=2", f"results_dir={tmp_path / 'again'}"]))
    assert len(batches) == len(first_run) > 0
    assert all(np.array_equal(a, b) for old, new in zip(first_run, batches) for a, b in zip(old, new))


def test_mep_run_logs_fit_time_and_entropy_and_samples_by_priority(tmp_path, monkeypatch):
    recorded_probs = []

    def recording_sampler(*args, **kwargs):
        recorded_probs.append(kwargs.get("episode_probs"))
        return sample_transitions(*args, **kwargs)

    monkeypatch.setattr(train_module, "sample_transitions", recording_sampler)
    log = read_run(train(compose([*TINY, "algo=her_mep", "epochs=2", f"results_dir={tmp_path}"])))
    epochs = log.epochs
    assert (epochs["mep_fit_seconds"] >= 0).all()
    assert epochs["priority_entropy"][0] == pytest.approx(math.log(6))  # epoch 1: uniform over 6 episodes
    assert epochs["priority_entropy"][1] < math.log(12)
    per_epoch = len(recorded_probs) // 2
    assert all(p is None for p in recorded_probs[:per_epoch])  # no fit before epoch 2
    sampled_probs = [p for p in recorded_probs[per_epoch:] if p is not None]
    assert len(sampled_probs) == 3 * 4  # every training batch of epoch 2 (3 cycles x 4 batches)
    assert all(p.sum() == pytest.approx(1.0) for p in sampled_probs)


class StopHere(Exception):
    pass


def test_resume_with_mep_gives_the_uninterrupted_metrics(tmp_path):
    overrides = [*TINY, "algo=her_mep", "epochs=3", "seed=5"]
    reference = train(compose([*overrides, f"results_dir={tmp_path / 'ref'}"]))
    cfg = compose([*overrides, f"results_dir={tmp_path / 'cut'}"])

    def stop_after_epoch_2(record):
        if record["epoch"] == 2:
            raise StopHere

    with pytest.raises(StopHere):
        train(cfg, on_epoch=stop_after_epoch_2)
    resumed = train(cfg)
    log = read_run(resumed)
    assert log.complete and [s["resumed_from_epoch"] for s in log.sessions] == [0, 2]
    pd.testing.assert_frame_equal(log.epochs.drop(columns=TIMING),
                                  read_run(reference).epochs.drop(columns=TIMING))

