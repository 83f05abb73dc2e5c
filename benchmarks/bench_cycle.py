"""Seconds per training cycle on FetchPush with the paper's settings, side by side.

A cycle is 2 episodes x 50 env steps plus 40 updates on batches of 256. Three numbers are
measured in this one process, one thread each, and their ratios printed:

- hersd: ``hersd.train.train`` itself, from the rollout and update timings in its log;
- floor: the same count of raw ``mujoco.mj_step`` calls (2 x 50 x 20 substeps) plus the
  matrix products of 40 updates (counted from the layer sizes) at the measured fp32
  matmul rate of this machine;
- stable-baselines3 2.9.2 DDPG + HerReplayBuffer configured the same (needs
  ``pip install stable-baselines3==2.9.2``; skipped if it is missing).

Usage: python benchmarks/bench_cycle.py [--cycles 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import mujoco
import numpy as np
import torch

from hersd.config import DDPGConfig
from hersd.envs import env_spec, make_env
from hersd.runlog import read_run
from hersd.train import compose, train

STEPS_PER_CYCLE = 2 * 50


def hersd_seconds_per_cycle(cycles: int) -> float:
    with tempfile.TemporaryDirectory() as results:
        cfg = compose(["task=push", "epochs=1", f"task.cycles_per_epoch={cycles}", "ddpg.test_rollouts=1",
                       "quiet=true", f"results_dir={results}", "checkpoint_every=0"])
        epoch = read_run(train(cfg)).epochs.iloc[0]
    return (epoch["rollout_seconds"] + epoch["update_seconds"]) / cycles


def physics_seconds_per_cycle(repeats: int = 5) -> float:
    env = make_env(compose(["task=push"]).task)
    env.reset(seed=0)
    model, data = env.model, env.data
    substeps = env.n_substeps
    best = float("inf")
    for _ in range(repeats):
        tic = time.perf_counter()
        for _ in range(STEPS_PER_CYCLE * substeps):
            mujoco.mj_step(model, data)
        best = min(best, time.perf_counter() - tic)
    return best


def update_flops(cfg: DDPGConfig, obs_dim: int, goal_dim: int, action_dim: int) -> float:
    """Multiply-add FLOPs of one DDPG update (forward and backward matrix products)."""
    def forward(in_dim: int, out_dim: int) -> tuple[float, float]:
        """(all layers, first layer) FLOPs of one forward pass over the batch."""
        sizes = [in_dim] + [cfg.hidden_units] * cfg.hidden_layers + [out_dim]
        layers = [2 * cfg.batch_size * a * b for a, b in zip(sizes[:-1], sizes[1:])]
        return sum(layers), layers[0]

    actor, actor_first = forward(obs_dim + goal_dim, action_dim)
    critic, critic_first = forward(obs_dim + goal_dim + action_dim, 1)
    targets = actor + critic
    critic_step = critic + critic + (critic - critic_first)  # forward, weight grads, input grads
    actor_step = actor + critic + critic + actor + (actor - actor_first)  # through the critic to pi
    return targets + critic_step + actor_step


def matmul_flops_per_second(size: int = 256, repeats: int = 2000) -> float:
    a, b = torch.randn(size, size), torch.randn(size, size)
    for _ in range(50):
        a @ b
    tic = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size ** 3 * repeats / (time.perf_counter() - tic)


def sb3_seconds_per_cycle(cycles: int) -> float | None:
    try:
        from stable_baselines3 import DDPG, HerReplayBuffer
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.noise import NormalActionNoise
    except ImportError:
        return None
    import gymnasium as gym

    env = make_vec_env(lambda: gym.make("FetchPush-v4"), n_envs=2, seed=0)
    model = DDPG(
        "MultiInputPolicy", env, learning_rate=1e-3, buffer_size=1_000_000, batch_size=256, tau=0.05, gamma=0.98,
        learning_starts=STEPS_PER_CYCLE, train_freq=(50, "step"), gradient_steps=40,
        action_noise=NormalActionNoise(np.zeros(4), 0.2 * np.ones(4)),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [256, 256, 256]}, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=2 * STEPS_PER_CYCLE)  # warm-up: fill past learning_starts
    tic = time.perf_counter()
    model.learn(total_timesteps=cycles * STEPS_PER_CYCLE, reset_num_timesteps=False)
    return (time.perf_counter() - tic) / cycles


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20)
    args = parser.parse_args()
    torch.set_num_threads(1)

    env = make_env(compose(["task=push"]).task)
    spec = env_spec(env)
    flops = update_flops(DDPGConfig(), spec.obs_dim, spec.goal_dim, spec.action_dim)
    rate = matmul_flops_per_second()
    physics = physics_seconds_per_cycle()
    matmuls = 40 * flops / rate
    floor = physics + matmuls
    ours = hersd_seconds_per_cycle(args.cycles)
    sb3 = sb3_seconds_per_cycle(args.cycles)

    print(f"matmul rate            {rate / 1e9:7.1f} GFLOP/s (fp32, 256x256x256, 1 thread)")
    print(f"update                 {flops / 1e9:7.3f} GFLOP -> {flops / rate * 1e3:.2f} ms at that rate")
    print(f"floor per cycle        {floor:7.3f} s  (mj_step {physics:.3f} s + matmuls {matmuls:.3f} s)")
    print(f"hersd per cycle        {ours:7.3f} s  -> {ours / floor:.2f}x the floor")
    if sb3 is None:
        print("stable-baselines3      not installed (pip install stable-baselines3==2.9.2)")
    else:
        print(f"SB3 DDPG+HER per cycle {sb3:7.3f} s  -> hersd is {sb3 / ours:.2f}x faster")


if __name__ == "__main__":
    main()
