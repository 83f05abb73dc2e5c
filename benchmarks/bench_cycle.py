"""Seconds per training cycle on FetchPush at the paper's settings, side by side in one process.

A cycle is 2 episodes x 50 env steps plus 40 updates on minibatches of 256 and one target
move. Measured here, one after another, and printed with their ratios:

(a) idealised floor: raw ``mujoco.mj_step`` calls of one cycle (2 x 50 x 20 substeps) plus
    the update's matrix-product FLOPs at this machine's 256x256x256 fp32 matmul rate (not
    reachable with these layer shapes: inputs of 28-32 columns, outputs of 1 and 4);
(b) practical floor: the same raw physics plus 40 updates of a minimal plain-PyTorch DDPG
    (``nn.Sequential`` nets of the same sizes, two Adams, the textbook critic-then-actor
    step) on batches already in memory, written here;
(c) hersd's own ``collect`` + ``update`` steps (hersd/engine/train.py) at 1 thread and at
    ``threads=auto`` (every core of this machine), with an empty buffer and with the buffer
    holding what 30 paper epochs store (3,000 episodes = 150,000 transitions);
(c') hersd at 1 thread with ``precision=bf16`` (the updates' hidden layers in bfloat16), its
    ratio to fp32 per cycle and per update (update = sampling a minibatch + one learner update),
    on a CPU with bf16 instructions (skipped elsewhere: hersd refuses bf16 there); and with
    ``update=fast`` (fp32, the networks' passes written by hand: hersd/engine/learners/fast.py), its ratios
    to both floors and to the default (autograd) update per cycle and per update; the bf16, fast and
    1-thread default runs alternate their cycles in one process;
(d) stable-baselines3 2.9.2 DDPG + HerReplayBuffer configured the same (1 thread), with an
    empty buffer and with 150,000 stored transitions (its sampler's cost grows with the
    buffer); skipped if not installed (``pip install stable-baselines3==2.9.2``).

Usage: python benchmarks/bench_cycle.py [--cycles 20]. Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import copy
import time

import mujoco
import numpy as np
import torch
from torch import nn

from hersd.contract.compose import compose_train
from hersd.contract.config import DDPGConfig
from hersd.contract.tasks import TASKS
from hersd.engine.resources import cpu_has_bf16
from hersd.contract.cores import available_cores
from hersd.engine.run_state import RunState
from hersd.engine.train import EpochStats, collect, update

EPISODES_PER_CYCLE, HORIZON, BATCHES = 2, 50, 40
# hersd's 1-thread paths: name -> its overrides ("fp32": the default, autograd update)
PATHS = {"fp32": ["precision=fp32"], "fast": ["update=fast"], "bf16": ["precision=bf16"]}
STEPS_PER_CYCLE = EPISODES_PER_CYCLE * HORIZON
FILL_EPISODES = 30 * 50 * EPISODES_PER_CYCLE  # what 30 paper epochs store


# --------------------------------------------------------------------------- (a) and (b): floors
def physics_seconds_per_cycle(state: RunState, repeats: int = 5) -> float:
    """Best of ``repeats`` timings of one cycle's raw mj_step calls."""
    env = state.train_envs[0]
    best = float("inf")
    for _ in range(repeats):
        tic = time.perf_counter()
        for _ in range(STEPS_PER_CYCLE * env.n_substeps):
            mujoco.mj_step(env.model, env.data)
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


def plain_update_seconds(in_dim: int, action_dim: int, cycles: int) -> float:
    """Seconds for one cycle's 40 updates + one polyak move of a minimal plain-PyTorch DDPG."""
    def net(inputs: int, outputs: int) -> nn.Sequential:
        return nn.Sequential(nn.Linear(inputs, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(),
                             nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, outputs))

    actor, critic = net(in_dim, action_dim), net(in_dim + action_dim, 1)
    actor_target, critic_target = copy.deepcopy(actor), copy.deepcopy(critic)
    actor_opt, critic_opt = torch.optim.Adam(actor.parameters(), 1e-3), torch.optim.Adam(critic.parameters(), 1e-3)
    x, next_x = torch.randn(256, in_dim), torch.randn(256, in_dim)
    action, reward = torch.rand(256, action_dim) * 2 - 1, -torch.rand(256, 1).round()

    def one_cycle() -> None:
        for _ in range(BATCHES):
            with torch.no_grad():
                next_q = critic_target(torch.cat([next_x, torch.tanh(actor_target(next_x))], 1))
                target = torch.clamp(reward + 0.98 * next_q, -50.0, 0.0)
            critic_loss = (critic(torch.cat([x, action], 1)) - target).pow(2).mean()
            critic_opt.zero_grad()
            critic_loss.backward()
            critic_opt.step()
            pi = torch.tanh(actor(x))
            actor_loss = -critic(torch.cat([x, pi], 1)).mean() + pi.pow(2).mean()
            actor_opt.zero_grad()
            actor_loss.backward()
            actor_opt.step()
        with torch.no_grad():
            for net_, target_ in ((actor, actor_target), (critic, critic_target)):
                for p, tp in zip(net_.parameters(), target_.parameters()):
                    tp.mul_(0.95).add_(p, alpha=0.05)

    one_cycle()  # warm-up
    tic = time.perf_counter()
    for _ in range(cycles):
        one_cycle()
    return (time.perf_counter() - tic) / cycles


# --------------------------------------------------------------------------- (c) hersd
def hersd_seconds(threads: int, fill_episodes: int, cycles: int,
                  precisions: tuple[str, ...] = ("fp32",)) -> dict[str, tuple[float, float]]:
    """hersd's collect + update at ``threads`` intra-op threads, one run per path of :data:`PATHS` named in
    ``precisions``, the buffer holding at least ``fill_episodes`` episodes (copies of real ones: sampling cost
    depends on the count only); the runs' cycles alternate, so a load that comes and goes weighs on each alike.
    Path -> (seconds per cycle, seconds per update, its minibatch's sampling included)."""
    torch.set_num_threads(threads)
    states = {precision: RunState(compose_train(["task=push", "quiet=true", f"threads={threads}",
                                                 *PATHS[precision]])) for precision in precisions}
    for state in states.values():
        stats = EpochStats(1, 0.8)
        for _ in range(2):  # warm-up, and episodes to copy
            collect(state, 0.8, stats)
            update(state, 0.8, stats)
        episodes = state.buffer.stored()
        while state.buffer.size < fill_episodes:
            state.buffer.store(episodes)
    stats = {precision: EpochStats(1, 0.8) for precision in precisions}
    for _ in range(cycles):
        for precision, state in states.items():
            with stats[precision].timed("cycle"):
                collect(state, 0.8, stats[precision])
                with stats[precision].timed("update"):
                    update(state, 0.8, stats[precision])
    for state in states.values():
        state.close()
    return {precision: (stats[precision].seconds["cycle"] / cycles,
                        stats[precision].seconds["update"] / (cycles * BATCHES)) for precision in precisions}


# --------------------------------------------------------------------------- (d) stable-baselines3
def sb3_seconds_per_cycle(fill_transitions: int, cycles: int) -> float | None:
    """SB3 DDPG + HerReplayBuffer per cycle after storing ``fill_transitions`` (random) transitions."""
    try:
        from stable_baselines3 import DDPG, HerReplayBuffer
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.noise import NormalActionNoise
    except ImportError:
        return None
    import gymnasium as gym

    torch.set_num_threads(1)
    env = make_vec_env(lambda: gym.make(TASKS["push"].env_id), n_envs=2, seed=0)
    model = DDPG(
        "MultiInputPolicy", env, learning_rate=1e-3, buffer_size=1_000_000, batch_size=256, tau=0.05, gamma=0.98,
        learning_starts=STEPS_PER_CYCLE, train_freq=(50, "step"), gradient_steps=40,
        action_noise=NormalActionNoise(np.zeros(4), 0.2 * np.ones(4)),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [256, 256, 256]}, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=2 * STEPS_PER_CYCLE)  # warm-up: past learning_starts
    _fill_sb3_buffer(model.replay_buffer, env, fill_transitions)
    tic = time.perf_counter()
    model.learn(total_timesteps=cycles * STEPS_PER_CYCLE, reset_num_timesteps=False)
    return (time.perf_counter() - tic) / cycles


def _fill_sb3_buffer(buffer, env, transitions: int) -> None:
    """Add whole random episodes (2 envs x 50 steps at a time) until ``transitions`` more are stored."""
    rng = np.random.default_rng(0)
    space = env.observation_space
    def observation() -> dict:
        return {key: rng.normal(size=(2, *space[key].shape)).astype(np.float32) for key in space.spaces}
    for _ in range(transitions // STEPS_PER_CYCLE):
        obs = observation()
        for t in range(HORIZON):
            next_obs = observation()
            done = np.full(2, t == HORIZON - 1)
            infos = [{"TimeLimit.truncated": bool(done[0]), "terminal_observation": {k: v[i] for k, v in next_obs.items()}}
                     if done[0] else {} for i in range(2)]
            buffer.add(obs, next_obs, rng.uniform(-1, 1, (2, 4)).astype(np.float32), -np.ones(2), done, infos)
            obs = next_obs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20)
    args = parser.parse_args()
    cores = available_cores()
    torch.set_num_threads(1)
    state = RunState(compose_train(["task=push", "quiet=true"]))
    spec = state.spec
    in_dim = spec.obs_dim + spec.goal_dim
    flops = update_flops(DDPGConfig(), spec.obs_dim, spec.goal_dim, spec.action_dim)
    rate = matmul_flops_per_second()
    physics = physics_seconds_per_cycle(state)
    state.close()
    ideal = physics + BATCHES * flops / rate
    practical = physics + plain_update_seconds(in_dim, spec.action_dim, args.cycles)
    one_thread = hersd_seconds(1, 0, args.cycles, ("fp32", "fast", "bf16") if cpu_has_bf16() else ("fp32", "fast"))
    full = hersd_seconds(1, FILL_EPISODES, args.cycles, ("fp32", "fast"))  # the fill SB3's sampler is slowest at
    hersd = {(cores, fill): hersd_seconds(cores, fill, args.cycles)["fp32"][0] for fill in (0, FILL_EPISODES)}
    hersd.update({(1, 0): one_thread["fp32"][0], (1, FILL_EPISODES): full["fp32"][0]})
    fast = {0: one_thread["fast"][0], FILL_EPISODES: full["fast"][0]}  # the fastest fp32 path, per fill
    sb3 = {fill: sb3_seconds_per_cycle(fill * HORIZON, args.cycles) for fill in (0, FILL_EPISODES)}

    print(f"matmul rate               {rate / 1e9:7.1f} GFLOP/s (fp32, 256x256x256, 1 thread)")
    print(f"(a) idealised floor       {ideal:7.3f} s/cycle (mj_step {physics:.3f} s + matmuls at that rate "
          f"{BATCHES * flops / rate:.3f} s)")
    print(f"(b) practical floor       {practical:7.3f} s/cycle (mj_step {physics:.3f} s + plain PyTorch updates "
          f"{practical - physics:.3f} s)")
    one = hersd[(1, 0)]
    print(f"(c) hersd, 1 thread       {one:7.3f} s/cycle -> {one / practical:.2f}x the practical floor, "
          f"{one / ideal:.2f}x the idealised one")
    print(f"    hersd, 1 thread, 30-epoch buffer {hersd[(1, FILL_EPISODES)]:7.3f} s/cycle")
    (fast_cycle, fast_update), fp32_update = one_thread["fast"], one_thread["fp32"][1]
    print(f"    hersd, 1 thread, update=fast {fast_cycle:7.3f} s/cycle -> {fast_cycle / practical:.2f}x the practical "
          f"floor, {fast_cycle / ideal:.2f}x the idealised one; {one / fast_cycle:.2f}x faster than autograd per "
          f"cycle; per update {fast_update * 1e3:.2f} ms against {fp32_update * 1e3:.2f} ms, "
          f"{fp32_update / fast_update:.2f}x faster than autograd")
    if "bf16" not in one_thread:
        print("    hersd, 1 thread, bf16     skipped: this CPU has no bf16 instructions")
    else:
        (bf16_cycle, bf16_update), fp32_update = one_thread["bf16"], one_thread["fp32"][1]
        print(f"    hersd, 1 thread, bf16     {bf16_cycle:7.3f} s/cycle -> {one / bf16_cycle:.2f}x faster than fp32 "
              f"per cycle; per update {bf16_update * 1e3:.2f} ms against {fp32_update * 1e3:.2f} ms, "
              f"{fp32_update / bf16_update:.2f}x faster than fp32")
    if cores > 1:
        auto = hersd[(cores, 0)]
        print(f"    hersd, threads=auto ({cores}) {auto:7.3f} s/cycle -> {one / auto:.2f}x faster than 1 thread; "
              f"30-epoch buffer {hersd[(cores, FILL_EPISODES)]:.3f} s/cycle")
    for fill, seconds in sb3.items():
        label = "empty buffer" if fill == 0 else "30-epoch buffer"
        if seconds is None:
            print("(d) stable-baselines3      not installed (pip install stable-baselines3==2.9.2)")
            break
        print(f"(d) SB3 2.9.2, {label:<15} {seconds:7.3f} s/cycle -> hersd (1 thread, same fill) is "
              f"{seconds / hersd[(1, fill)]:.2f}x faster, with update=fast {seconds / fast[fill]:.2f}x")


if __name__ == "__main__":
    main()
