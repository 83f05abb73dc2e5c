"""Microseconds per HER minibatch of hersd's sampler on a full FetchPush-sized buffer, by reward function.

``hersd.engine.replay.buffer.sample_transitions`` draws 256 transitions ('future' relabelling at 0.8, the
paper's settings) from a full buffer of FetchPush's shape (1e6 transitions: 20,000 episodes of
T = 50, obs 25, goal 3, action 4; synthetic arrays, since the cost depends on the shapes only).
Side by side in one process, the reward function the sampler is given:

(a) before: the Fetch rule as hersd.engine.envs.reward_function gave it up to commit a30b165
    (``partial(goal_reward, distance_threshold=0.05)``, its body copied here);
(b) after: ``hersd.engine.envs.goal_envs.vectorised_reward`` of a FetchPush env, which hersd uses now;
(c) for scale: the env's own ``compute_reward`` called once on the whole batch;
(d) for scale: the env's own ``compute_reward`` called per row (what an env that takes one pair
    at a time costs, hersd.engine.envs.goal_envs._env_reward's fallback).

The variants run in interleaved rounds (``benchmarks/rounds.py``: each round runs every variant once, after
a warm-up round), so load from other processes hits them alike; printed: the CPU, each variant's median
(min-max) over the rounds and its ratio to (a) as the median of per-round ratios.

Usage: python benchmarks/bench_sampler.py [--samples 2000] [--rounds 7]
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from typing import Callable

import gymnasium as gym
import numpy as np

import hersd.engine.envs.make  # noqa: F401  (registers the gymnasium-robotics envs quietly)
from hersd.engine.envs.goal_envs import vectorised_reward
from hersd.contract.tasks import TASKS
from hersd.engine.replay.buffer import Episodes, sample_transitions
from rounds import cpu_line, faster_line, interleaved, spread

EPISODES, HORIZON, OBS, GOAL, ACTION = 20_000, 50, 25, 3, 4  # 1e6 transitions of FetchPush
BATCH, RELABEL_RATE = 256, 0.8
BEFORE = "(a) before: partial(goal_reward)"


def reward_before(achieved: np.ndarray, desired: np.ndarray, distance_threshold: float) -> np.ndarray:
    """hersd.engine.envs.goal_reward as of commit a30b165."""
    distance = np.linalg.norm(achieved - desired, axis=-1)
    return -(distance > distance_threshold).astype(np.float32)


def full_buffer() -> Episodes:
    """Synthetic episodes of FetchPush's shapes: goals near the achieved ones, so both rewards occur."""
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(EPISODES, HORIZON + 1, OBS)).astype(np.float32)
    achieved = rng.normal(size=(EPISODES, HORIZON + 1, GOAL)).astype(np.float32) * np.float32(0.05)
    action = rng.uniform(-1, 1, (EPISODES, HORIZON, ACTION)).astype(np.float32)
    return Episodes(obs, achieved, achieved[:, 1:] + np.float32(0.03), action)


def microseconds_per_sample(episodes: Episodes, reward: Callable, samples: int) -> float:
    rng = np.random.default_rng(1)
    tic = time.perf_counter()
    for _ in range(samples):
        sample_transitions(episodes, BATCH, RELABEL_RATE, rng, reward, strategy="future")
    return (time.perf_counter() - tic) / samples * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=2000, help="minibatches per timing")
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds (after one warm-up round)")
    args = parser.parse_args()
    env = gym.make(TASKS["push"].env_id).unwrapped
    threshold = float(env.distance_threshold)
    variants = {
        BEFORE: partial(reward_before, distance_threshold=threshold),
        "(b) after: vectorised_reward(env)": vectorised_reward(env),
        "(c) env.compute_reward, one batched call": lambda a, d: env.compute_reward(a, d, None).astype(np.float32),
        "(d) env.compute_reward, per row": lambda a, d: np.array([env.compute_reward(x, y, None)
                                                                  for x, y in zip(a, d)], np.float32),
    }
    episodes = full_buffer()
    check = sample_transitions(episodes, BATCH, RELABEL_RATE, np.random.default_rng(2), variants[BEFORE])
    for reward in variants.values():  # every variant gives the same minibatch
        other = sample_transitions(episodes, BATCH, RELABEL_RATE, np.random.default_rng(2), reward)
        assert np.array_equal(other.reward, check.reward) and len(np.unique(check.reward)) == 2

    def timed(name: str) -> dict[str, float]:
        samples = args.samples if "per row" not in name else max(1, args.samples // 20)
        return {"us": microseconds_per_sample(episodes, variants[name], samples)}

    kept = interleaved({name: partial(timed, name) for name in variants}, args.rounds)
    print(cpu_line())
    print(f"HER minibatch of {BATCH} from {EPISODES} episodes x T={HORIZON}, relabel rate {RELABEL_RATE}; "
          f"{args.rounds} interleaved rounds; median (min-max) over the rounds")
    for name in variants:
        print(f"{name:<44} {spread(kept[name]['us'], digits=1)} us")
    for name in list(variants)[1:]:
        print(faster_line(f"ratio: {name}", kept[name]["us"], kept[BEFORE]["us"], "(a)"))

if __name__ == "__main__":
    main()
