"""``flush_denormal`` off (the default before 2026-11-25) against on (the default since), side by side.

A trained run's Adam moments hold many denormal floats (units whose gradient died decay through
the denormal range for thousands of steps), and x86 CPUs compute on denormals many times slower.
Fresh networks have none. Every part alternates its variants (A B A B ...) in this one process,
on one thread, so drift in the machine's load hits all of them:

- ``cycles RUN_DIR``: update cycles (``hersd.engine.train.update``: 40 updates of 256 and one target move
  at the paper's settings) from a run's checkpoint (``RUN_DIR`` holds ``run.mcap`` and
  ``checkpoint.pt``: a run in progress, or one made with ``keep_checkpoint=true``), reloaded before
  each timing; with ``--fresh``, from a fresh run of the same config instead (two cycles collected).
  Prints the share of denormals in the optimiser's state. A run that flushed holds none in its
  checkpoints: ``--unflushed-epochs N`` first trains N epochs without flushing, as a run at the
  former default would have.
- ``epochs RUN_DIR --epochs 20``: whole epochs (rollouts, updates, test episodes), two copies of the
  run continued from its checkpoint, one per setting, taking turns epoch by epoch (k+1 off, k+1 on,
  k+2 off, ...): the seconds per epoch a run at each default spends over those epochs.
- ``sb3 RUN_DIR``: stable-baselines3 2.9.2 DDPG + HerReplayBuffer at its defaults (IEEE denormals)
  and with ``torch.set_flush_denormal(True)``, against hersd at its defaults before and after,
  per cycle (2 episodes x 50 steps + 40 updates), at equal buffer fill: fresh (two cycles stored)
  and the checkpoint's buffer (hersd its trained networks and buffer; SB3 its own fresh networks
  and as many stored transitions, random ones: its sampling cost depends on the count only).
  Needs ``pip install "hersd[bench]"``.

Usage: python benchmarks/bench_denormal.py {cycles,epochs,sb3} RUN_DIR [--fresh] [--cycles 5]
       [--repeats 3] [--epochs 20] [--unflushed-epochs N]
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from hersd.engine.denormals import set_intra_op_threads
from hersd.contract.tasks import TASKS
from hersd.engine.render_cli import load_run
from hersd.engine.run_state import RunState
from hersd.engine.train import EpochStats, collect, run_epoch, update

SETTINGS = (False, True)  # flush_denormal: the default before, the default after
HORIZON, ENVS, BATCHES = 50, 2, 40
STEPS_PER_CYCLE = HORIZON * ENVS


def denormal_share(optimizer_state: dict) -> float:
    """The share of denormal values among the floats of an optimiser's state dict."""
    tiny, denormal, total = torch.finfo(torch.float32).tiny, 0, 0
    for moments in optimizer_state["state"].values():
        for value in moments.values():
            if torch.is_tensor(value) and value.is_floating_point() and value.numel() > 1:
                denormal += int(((value != 0) & (value.abs() < tiny)).sum())
                total += value.numel()
    return denormal / max(total, 1)


def state_at(run_dir: Path, flush: bool, fresh: bool, unflushed_epochs: int = 0) -> RunState:
    """The run's state at its checkpoint (or fresh, two cycles collected) with ``flush_denormal=flush``, after
    ``unflushed_epochs`` epochs trained from there without flushing: a checkpoint of a run that flushed holds no
    denormals, and a few thousand unflushed updates give it those an unflushed run carries."""
    cfg, checkpoint = load_run(run_dir, None)
    state = RunState(replace(cfg, flush_denormal=False))
    if fresh:
        for _ in range(2):
            collect(state, 0.8, EpochStats(1, 0.8))
    else:
        state.load_state_dict(checkpoint)
    for _ in range(unflushed_epochs):
        run_epoch(state, state.epochs_done + 1)
    state.cfg = replace(cfg, flush_denormal=flush)
    return state


def seconds_per_cycle(state: RunState, flush: bool, cycles: int, rollouts: bool = False) -> float:
    """Mean seconds of ``cycles`` update cycles of ``state`` at ``flush_denormal=flush`` (with ``rollouts``,
    whole cycles: collect + update)."""
    state.cfg = replace(state.cfg, flush_denormal=flush)
    stats = EpochStats(state.epochs_done + 1, 0.8)
    start = time.perf_counter()
    for _ in range(cycles):
        if rollouts:
            collect(state, 0.8, stats)
        update(state, 0.8, stats)
    return (time.perf_counter() - start) / cycles


def bench_cycles(args: argparse.Namespace) -> None:
    cfg, checkpoint = load_run(args.run_dir, None)
    where = "fresh networks" if args.fresh else f"checkpoint at epoch {checkpoint['epoch']}"
    state = state_at(args.run_dir, False, args.fresh, args.unflushed_epochs)
    where += f" + {args.unflushed_epochs} unflushed epochs" if args.unflushed_epochs else ""
    print(f"{args.run_dir}: {where}, denormals in Adam's state: "
          f"{denormal_share(state.agent.state_dict()['optimizer']):.1%}")
    snapshot = copy.deepcopy(state.state_dict())
    times: dict[bool, list[float]] = {flush: [] for flush in SETTINGS}
    for _ in range(args.repeats):
        for flush in SETTINGS:
            state.load_state_dict(copy.deepcopy(snapshot))
            times[flush].append(seconds_per_cycle(state, flush, args.cycles))
            print(f"flush_denormal={str(flush).lower():<5}  {times[flush][-1]:.3f} s per update cycle", flush=True)
    off, on = min(times[False]), min(times[True])
    print(f"fastest: {off:.3f} s without, {on:.3f} s with -> {off / on:.2f}x faster")


def bench_epochs(args: argparse.Namespace) -> None:
    states = {flush: state_at(args.run_dir, flush, fresh=False) for flush in SETTINGS}  # one checkpoint, two copies
    first = states[False].epochs_done + 1
    seconds: dict[bool, list[float]] = {flush: [] for flush in SETTINGS}
    for epoch in range(first, first + args.epochs):
        for flush, state in states.items():
            record = run_epoch(state, epoch)
            seconds[flush].append(record["epoch_seconds"])
            print(f"epoch {epoch}  flush_denormal={str(flush).lower():<5}  {record['epoch_seconds']:6.1f} s  "
                  f"(updates {record['update_seconds']:.1f} s, test success {record['test_success']:.2f})", flush=True)
    off, on = statistics.median(seconds[False]), statistics.median(seconds[True])
    print(f"epochs {first}-{first + args.epochs - 1}, median seconds per epoch: {off:.1f} without, {on:.1f} with "
          f"-> {off / on:.2f}x faster; mean {np.mean(seconds[False]):.1f} against {np.mean(seconds[True]):.1f}")


def sb3_model(fill_transitions: int):
    """SB3 2.9.2 DDPG + HerReplayBuffer at the paper's settings on FetchPush, past its learning start, holding
    ``fill_transitions`` more (random) transitions."""
    import gymnasium as gym
    from stable_baselines3 import DDPG, HerReplayBuffer
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.noise import NormalActionNoise

    env = make_vec_env(lambda: gym.make(TASKS["push"].env_id), n_envs=ENVS, seed=0)
    model = DDPG(
        "MultiInputPolicy", env, learning_rate=1e-3, buffer_size=1_000_000, batch_size=256, tau=0.05, gamma=0.98,
        learning_starts=STEPS_PER_CYCLE, train_freq=(HORIZON, "step"), gradient_steps=BATCHES,
        action_noise=NormalActionNoise(np.zeros(4), 0.2 * np.ones(4)), replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [256, 256, 256]}, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=2 * STEPS_PER_CYCLE)
    rng, space = np.random.default_rng(0), env.observation_space
    def observation() -> dict:
        return {key: rng.normal(size=(ENVS, *space[key].shape)).astype(np.float32) for key in space.spaces}
    for _ in range(fill_transitions // STEPS_PER_CYCLE):
        obs = observation()
        for t in range(HORIZON):
            next_obs, last = observation(), t == HORIZON - 1
            infos = [{"TimeLimit.truncated": True, "terminal_observation": {k: v[i] for k, v in next_obs.items()}}
                     if last else {} for i in range(ENVS)]
            model.replay_buffer.add(obs, next_obs, rng.uniform(-1, 1, (ENVS, 4)).astype(np.float32),
                                    -np.ones(ENVS), np.full(ENVS, last), infos)
            obs = next_obs
    return model


def sb3_seconds_per_cycle(model, flush: bool, cycles: int) -> float:
    torch.set_flush_denormal(flush)
    try:
        start = time.perf_counter()
        model.learn(total_timesteps=cycles * STEPS_PER_CYCLE, reset_num_timesteps=False)
        return (time.perf_counter() - start) / cycles
    finally:
        torch.set_flush_denormal(False)


def bench_sb3(args: argparse.Namespace) -> None:
    for fresh in (True, False):
        state = state_at(args.run_dir, True, fresh, 0 if fresh else args.unflushed_epochs)
        fill = state.buffer.size * HORIZON
        model = sb3_model(0 if fresh else fill - 2 * STEPS_PER_CYCLE)
        label = "fresh" if fresh else f"trained, epoch {state.epochs_done}"
        print(f"-- {label}: hersd holds {fill} transitions, SB3 {model.replay_buffer.size() * ENVS}", flush=True)
        variants = {
            "hersd flush_denormal=false (default before)": lambda: seconds_per_cycle(state, False, args.cycles, True),
            "hersd flush_denormal=true (default now)": lambda: seconds_per_cycle(state, True, args.cycles, True),
            "SB3 2.9.2 at its defaults": lambda: sb3_seconds_per_cycle(model, False, args.cycles),
            "SB3 2.9.2 + torch.set_flush_denormal(True)": lambda: sb3_seconds_per_cycle(model, True, args.cycles)}
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.repeats):
            for name, measure in variants.items():
                times[name].append(measure())
        best = {name: min(values) for name, values in times.items()}
        for name, seconds in best.items():
            print(f"   {name:<45} {seconds:.3f} s per cycle (fastest of {args.repeats})", flush=True)
        names = list(best)
        print(f"   SB3 defaults / hersd defaults: {best[names[2]] / best[names[1]]:.2f}x; "
              f"both flushing: {best[names[3]] / best[names[1]]:.2f}x; hersd before / after: "
              f"{best[names[0]] / best[names[1]]:.2f}x", flush=True)
        state.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("cycles", "epochs", "sb3"))
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--fresh", action="store_true", help="cycles: fresh networks instead of the checkpoint's")
    parser.add_argument("--cycles", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--unflushed-epochs", type=int, default=0,
                        help="cycles, sb3: train this many epochs without flushing first (a flushing run's "
                             "checkpoint holds no denormals)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    set_intra_op_threads(False)
    {"cycles": bench_cycles, "epochs": bench_epochs, "sb3": bench_sb3}[args.part](args)


if __name__ == "__main__":
    main()
