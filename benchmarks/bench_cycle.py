"""Seconds per training cycle on FetchPush at the paper's settings: every path in interleaved rounds.

A cycle is 2 episodes x 50 env steps plus 40 updates on minibatches of 256 and one target move. Each round
measures every path below once, in this order (``rounds.py``: A B C, A B C, ...), after one warm-up round;
the script prints the CPU (model name, family, model), each path's median (min-max) over the rounds, and each
ratio's median of per-round ratios:

(a) idealised floor: raw ``mujoco.mj_step`` calls of one cycle (2 x 50 x 20 substeps, best of 3) plus the
    update's matrix-product FLOPs at this machine's 256x256x256 matmul rate, fp32 and (on a CPU with bf16
    instructions) bf16, the faster of ``torch.mm``'s and oneDNN's (torch's float32 ``mm`` is MKL's, which on
    AMD CPUs runs its AVX2 code) (not reachable with these layer shapes: inputs of 28-32 columns, outputs of 1
    and 4);
(b) practical floor: the same raw physics plus 40 updates of a minimal plain-PyTorch DDPG (``nn.Sequential``
    nets of the same sizes, two Adams, the textbook critic-then-actor step) on batches already in memory;
(c) hersd's own ``collect`` + ``update`` steps (hersd/engine/train.py) at 1 thread: the default (fp32
    autograd), ``update=fast`` (fp32, the networks' passes by hand, oneDNN products: hersd/engine/learners/fast.py),
    ``precision=bf16`` (bf16 autocast over the autograd update) and ``precision=bf16 update=fast`` (the hand
    passes on bf16 weight copies), the bf16 ones on a CPU with bf16 instructions only (hersd refuses them
    elsewhere); per cycle and per update (sampling its minibatch + one learner update); the fp32 paths again
    with the buffer holding what 30 paper epochs store (3,000 episodes = 150,000 transitions), and the
    default at ``threads=auto`` (every core) at both fills;
(d) stable-baselines3 2.9.2 DDPG + HerReplayBuffer configured the same (1 thread), with an empty buffer and
    with 150,000 stored transitions; skipped if not installed (``pip install stable-baselines3==2.9.2``).

Usage: python benchmarks/bench_cycle.py [--rounds 15] [--cycles 4] (about 7 minutes on a quiet 2-core AMD
EPYC; each round runs --cycles cycles of each path). Run it on an idle machine; on a loaded one the
medians are the load's, though the interleaving keeps the ratios fair.
"""

from __future__ import annotations

import argparse
import copy
import time
from typing import Callable, Optional

import mujoco
import numpy as np
import torch
from torch import nn

from hersd.contract.compose import compose_train
from hersd.contract.config import DDPGConfig
from hersd.contract.cores import available_cores
from hersd.contract.tasks import TASKS
from hersd.engine.resources import cpu_has_bf16
from hersd.engine.run_state import RunState
from hersd.engine.train import EpochStats, collect, update

from rounds import cpu_line, faster_line, interleaved, ratio, ratio_spread, spread

EPISODES_PER_CYCLE, HORIZON, BATCHES = 2, 50, 40
# hersd's paths: name -> its overrides (the default: fp32, the autograd update)
PATHS = {"fp32": [], "fast": ["update=fast"], "bf16": ["precision=bf16"],
         "bf16 fast": ["precision=bf16", "update=fast"]}
LABELS = {"fp32": "fp32 autograd", "fast": "fp32 fast", "bf16": "bf16, autocast", "bf16 fast": "bf16, fast"}
STEPS_PER_CYCLE = EPISODES_PER_CYCLE * HORIZON
FILL_EPISODES = 30 * 50 * EPISODES_PER_CYCLE  # what 30 paper epochs store
Measure = Callable[[], dict[str, float]]  # one round of one path: measure name -> seconds


# --------------------------------------------------------------------------- (a) and (b): floors
def physics_seconds_per_cycle(env, repeats: int = 3) -> float:
    """Best of ``repeats`` timings of one cycle's raw mj_step calls on ``env``."""
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


def onednn_mm(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a @ b by oneDNN's matmul, as ``update=fast`` runs its hidden layers (hersd/engine/learners/fast.py)."""
    return torch.ops.mkldnn._linear_pointwise(a, b.t(), None, "none", [], "")


def matmul_flops_per_second(product: Callable, dtype: torch.dtype, size: int = 256, repeats: int = 500) -> float:
    """FLOP/s of ``product`` (``torch.mm`` or :func:`onednn_mm`) of two size x size matrices in ``dtype`` at the
    current thread count (after 50 warm-ups)."""
    a, b = torch.randn(size, size).to(dtype), torch.randn(size, size).to(dtype)
    for _ in range(50):
        product(a, b)
    tic = time.perf_counter()
    for _ in range(repeats):
        product(a, b)
    return 2 * size ** 3 * repeats / (time.perf_counter() - tic)


def floor_measure(env, flops: float, bf16: bool) -> Measure:
    """One round of (a): the physics, the matmul rates (torch.mm's and oneDNN's) and the idealised floors at the
    faster of the two (fp32; bf16 on such a CPU)."""
    def measure() -> dict[str, float]:
        torch.set_num_threads(1)
        physics = physics_seconds_per_cycle(env)
        measures = {"physics": physics}
        for dtype, name, floor in ((torch.float32, "fp32", "ideal"), (torch.bfloat16, "bf16", "ideal bf16"))[:1 + bf16]:
            measures[f"{name} mm rate"] = matmul_flops_per_second(torch.mm, dtype)
            measures[f"{name} onednn rate"] = matmul_flops_per_second(onednn_mm, dtype)
            rate = max(measures[f"{name} mm rate"], measures[f"{name} onednn rate"])
            measures[floor] = physics + BATCHES * flops / rate
        return measures
    return measure


def plain_update_measure(in_dim: int, action_dim: int, cycles: int) -> Measure:
    """One round of (b)'s updates: seconds per cycle of 40 updates + one polyak move of a minimal plain-PyTorch
    DDPG (its own networks, kept from round to round)."""
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

    def measure() -> dict[str, float]:
        torch.set_num_threads(1)
        tic = time.perf_counter()
        for _ in range(cycles):
            one_cycle()
        return {"update": (time.perf_counter() - tic) / cycles}
    return measure


# --------------------------------------------------------------------------- (c) hersd
def hersd_state(overrides: list[str], threads: int, fill_episodes: int) -> RunState:
    """A FetchPush run's state at ``threads`` intra-op threads, warmed up by 2 cycles, its buffer holding at
    least ``fill_episodes`` episodes (copies of real ones: sampling cost depends on the count only)."""
    torch.set_num_threads(threads)
    state = RunState(compose_train(["task=push", "quiet=true", f"threads={threads}", *overrides]))
    stats = EpochStats(1, 0.8)
    for _ in range(2):
        collect(state, 0.8, stats)
        update(state, 0.8, stats)
    episodes = state.buffer.stored()
    while state.buffer.size < fill_episodes:
        state.buffer.store(episodes)
    return state


def hersd_measure(state: RunState, threads: int, cycles: int) -> Measure:
    """One round of a hersd path: ``cycles`` cycles; seconds per cycle and per update (its sampling included)."""
    def measure() -> dict[str, float]:
        torch.set_num_threads(threads)
        stats = EpochStats(1, 0.8)
        for _ in range(cycles):
            with stats.timed("cycle"):
                collect(state, 0.8, stats)
                with stats.timed("update"):
                    update(state, 0.8, stats)
        return {"cycle": stats.seconds["cycle"] / cycles, "update": stats.seconds["update"] / (cycles * BATCHES)}
    return measure


# --------------------------------------------------------------------------- (d) stable-baselines3
def sb3_measure(fill_transitions: int, cycles: int) -> Optional[Measure]:
    """One round of SB3 DDPG + HerReplayBuffer: seconds per cycle, after storing ``fill_transitions`` (random)
    transitions; None if stable-baselines3 is not installed."""
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

    def measure() -> dict[str, float]:
        torch.set_num_threads(1)
        tic = time.perf_counter()
        model.learn(total_timesteps=cycles * STEPS_PER_CYCLE, reset_num_timesteps=False)
        return {"cycle": (time.perf_counter() - tic) / cycles}
    return measure


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


# --------------------------------------------------------------------------- the rounds and their report
def measures(cycles: int, bf16: bool, cores: int) -> tuple[dict[str, Measure], list[RunState]]:
    """Every path's round, in the order the rounds run them, and the run states to close after."""
    probe = RunState(compose_train(["task=push", "quiet=true"]))
    spec, env = probe.spec, probe.train_envs[0]
    flops = update_flops(DDPGConfig(), spec.obs_dim, spec.goal_dim, spec.action_dim)
    paths: dict[str, Measure] = {"floor": floor_measure(env, flops, bf16),
                                 "plain": plain_update_measure(spec.obs_dim + spec.goal_dim, spec.action_dim, cycles)}
    states = [probe]
    runs = [(name, overrides, 1, 0) for name, overrides in PATHS.items() if bf16 or not name.startswith("bf16")]
    runs += [(f"{name} full", PATHS[name], 1, FILL_EPISODES) for name in ("fp32", "fast")]
    if cores > 1:
        runs += [("auto", [], cores, 0), ("auto full", [], cores, FILL_EPISODES)]
    for name, overrides, threads, fill in runs:
        states.append(hersd_state(overrides, threads, fill))
        paths[name] = hersd_measure(states[-1], threads, cycles)
    for name, fill in (("sb3", 0), ("sb3 full", FILL_EPISODES)):
        sb3 = sb3_measure(fill * HORIZON, cycles)
        if sb3 is not None:
            paths[name] = sb3
    return paths, states


def report(kept: dict[str, dict[str, list[float]]], cores: int) -> list[str]:
    """The printed lines of the rounds' results (after the CPU line)."""
    floor = kept["floor"]
    practical = [a + b for a, b in zip(floor["physics"], kept["plain"]["update"])]
    lines = [f"matmul rate 256x256x256, 1 thread, GFLOP/s, torch.mm / oneDNN: fp32 "
             f"{spread(floor['fp32 mm rate'], 1e-9, 1)} / {spread(floor['fp32 onednn rate'], 1e-9, 1)}"
             + (f"; bf16 {spread(floor['bf16 mm rate'], 1e-9, 1)} / {spread(floor['bf16 onednn rate'], 1e-9, 1)}"
                if "bf16 mm rate" in floor else "") + " (the floors take the faster)",
             f"raw mj_step of one cycle          {spread(floor['physics'])} s",
             f"(a) idealised floor, fp32         {spread(floor['ideal'])} s/cycle"]
    if "ideal bf16" in floor:
        lines.append(f"(a) idealised floor, bf16         {spread(floor['ideal bf16'])} s/cycle")
    lines.append(f"(b) practical floor               {spread(practical)} s/cycle")
    for name, label in LABELS.items():
        if name in kept:
            cycle, per_update = kept[name]["cycle"], kept[name]["update"]
            ideal = floor["ideal bf16"] if name.startswith("bf16") else floor["ideal"]
            lines.append(f"(c) hersd, 1 thread, {label:<15}{spread(cycle)} s/cycle, {spread(per_update, 1e3, 2)} "
                         f"ms/update; {ratio_spread(ratio(cycle, ideal))} the idealised floor"
                         f"{' (bf16)' if name.startswith('bf16') else ''}, {ratio_spread(ratio(cycle, practical))} "
                         "the practical floor")
    for name in ("fp32 full", "fast full"):
        label = LABELS[name.split()[0]]
        lines.append(f"(c) hersd, 1 thread, {label}, 30-epoch buffer {spread(kept[name]['cycle'])} s/cycle")
    if cores > 1:
        lines.append(f"(c) hersd, threads=auto ({cores}), fp32 autograd {spread(kept['auto']['cycle'])} s/cycle; "
                     f"30-epoch buffer {spread(kept['auto full']['cycle'])} s/cycle")
    for name, fill in (("sb3", "empty"), ("sb3 full", "30-epoch")):
        if name in kept:
            lines.append(f"(d) SB3 2.9.2, {fill} buffer {spread(kept[name]['cycle'])} s/cycle")
    return lines + ratio_lines(kept, cores)


def ratio_lines(kept: dict[str, dict[str, list[float]]], cores: int) -> list[str]:
    """The ratios, each the median of per-round ratios: each path against the fp32 default, fast bf16 against
    autocast, threads=auto against 1 thread, stable-baselines3 against hersd's default and fast fp32 paths."""
    fp32 = kept["fp32"]
    lines = []
    for name in ("fast", "bf16", "bf16 fast"):
        for per in ("cycle", "update"):
            if name in kept:
                lines.append(faster_line(f"ratio: hersd, 1 thread, {LABELS[name]}", kept[name][per], fp32[per],
                                         "fp32", per))
    if "bf16 fast" in kept:
        lines.append(faster_line("ratio: hersd, 1 thread, bf16, fast", kept["bf16 fast"]["cycle"],
                                 kept["bf16"]["cycle"], "bf16 autocast", "cycle"))
    if cores > 1:
        lines.append(faster_line(f"ratio: hersd, threads=auto ({cores}), fp32 autograd", kept["auto"]["cycle"],
                                 fp32["cycle"], "1 thread", "cycle"))
    for sb3, fill, label in (("sb3", "", "empty"), ("sb3 full", " full", "30-epoch")):
        for name in ("fp32", "fast"):
            if sb3 in kept:
                lines.append(faster_line(f"ratio: stable-baselines3, {label} buffer", kept[sb3]["cycle"],
                                         kept[f"{name}{fill}"]["cycle"], f"hersd {LABELS[name]}", "cycle"))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15, help="interleaved rounds (after one warm-up round)")
    parser.add_argument("--cycles", type=int, default=4, help="cycles of each path per round")
    args = parser.parse_args()
    if args.rounds < 1 or args.cycles < 1:
        parser.error("--rounds and --cycles must be at least 1")
    cores, bf16 = available_cores(), cpu_has_bf16()
    print(cpu_line())
    paths, states = measures(args.cycles, bf16, cores)
    kept = interleaved(paths, args.rounds)
    for state in states:
        state.close()
    print(f"{args.rounds} interleaved rounds of {args.cycles} cycles per path, 1 torch thread unless a line says "
          "otherwise; median (min-max) over the rounds; a ratio: the median of per-round ratios")
    if not bf16:
        print("bf16 paths skipped: this CPU has no bf16 instructions")
    print("\n".join(report(kept, cores)))


if __name__ == "__main__":
    main()
