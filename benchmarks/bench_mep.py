"""Epoch time with MEP over epoch time without, on FetchPush with a buffer of 2,000+ episodes.

Both variants run one full epoch of ``hersd.engine.train.train`` itself (50 cycles of 2 episodes and
40 updates, 20 test episodes, the paper's settings) from the same starting point, in this one
process, alternating (off, on, on, off, ...) so drift in the shared machine's load hits both:

1. a short run (1 cycle) makes a checkpoint after epoch 1;
2. its buffer is replaced by ``--prefill`` random-policy FetchPush episodes (uniform actions),
   standing in for the episodes of earlier epochs; for the MEP variant the checkpoint also
   gets a density model fit on all but the last 100 of them, as the previous epoch's fit
   would have been (that first, cold fit is not timed: a run pays it once);
3. each variant resumes that checkpoint for epoch 2 with 50 cycles; its log gives
   ``epoch_seconds`` (wall clock) and ``mep_fit_seconds``; the process CPU time of the
   resumed run is measured too, since on a shared machine other jobs inflate wall-clock
   times at random (the CPU time includes the resume's start-up, the same for both).

Printed: each epoch, then the ratios with/without MEP of the mean CPU seconds and of the
fastest (least disturbed) wall-clock epoch.

Usage: python benchmarks/bench_mep.py [--prefill 2000] [--repeats 2]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from hersd.contract.compose import compose_train as compose
from hersd.engine.envs.make import make_env
from hersd.engine.replay.buffer import EpisodeBuffer, Episodes
from hersd.engine.run_state import RunState, load_checkpoint, save_checkpoint
from hersd.contract.runlog import read_run
from hersd.contract.runstore import CHECKPOINT_NAME
from hersd.engine.train import train

BASE = ["task=push", "seed=0", "epochs=2", "quiet=true", "keep_checkpoint=true", "threads=1"]
EPISODES_PER_EPOCH = 100  # 50 cycles x 2 rollouts


class StopAfterFirstEpoch(Exception):
    pass


def random_policy_episodes(n: int, seed: int) -> Episodes:
    """n FetchPush episodes under uniform random actions: obs (n, T+1, 25), achieved (n, T+1, 3), ..."""
    cfg = compose(["task=push"])
    env = make_env(cfg.task)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    horizon = env.max_episode_steps
    obs = np.empty((n, horizon + 1, env.observation_space["observation"].shape[0]), np.float32)
    achieved = np.empty((n, horizon + 1, 3), np.float32)
    goal = np.empty((n, horizon, 3), np.float32)
    action = rng.uniform(-1, 1, (n, horizon, env.action_space.shape[0])).astype(np.float32)
    for i in range(n):
        first, _ = env.reset()
        obs[i, 0], achieved[i, 0], goal[i] = first["observation"], first["achieved_goal"], first["desired_goal"]
        for t in range(horizon):
            step, *_ = env.step(action[i, t])
            obs[i, t + 1], achieved[i, t + 1] = step["observation"], step["achieved_goal"]
    env.close()
    return Episodes(obs, achieved, goal, action)


def prefilled_start(directory: Path, prefill: Episodes, mep: bool) -> None:
    """Make ``directory`` a run stopped after epoch 1 whose buffer holds ``prefill``."""
    def stop(_record: dict) -> None:
        raise StopAfterFirstEpoch

    algo = "algo=her_mep" if mep else "algo=her"
    cfg = compose([*BASE, algo, "task.cycles_per_epoch=1", "ddpg.test_rollouts=1", f"run_dir={directory}"])
    try:
        train(cfg, on_epoch=stop)
    except StopAfterFirstEpoch:
        pass
    path = directory / CHECKPOINT_NAME
    state = RunState(cfg)
    state.load_state_dict(load_checkpoint(path, torch.device("cpu")))
    n, horizon = prefill.goal.shape[:2]
    state.buffer = EpisodeBuffer(cfg.ddpg.buffer_size, horizon, prefill.obs.shape[-1], 3, prefill.action.shape[-1])
    state.buffer.store(prefill)
    if mep:
        state.prioritizer.fit(prefill.achieved[:n - EPISODES_PER_EPOCH], np.random.default_rng(0))
        state.prioritizer.score_new(np.arange(n - EPISODES_PER_EPOCH, n), prefill.achieved[n - EPISODES_PER_EPOCH:])
    save_checkpoint(path, state.state_dict())
    state.close()


def timed_epoch(start: Path, work: Path, mep: bool) -> dict:
    """Resume a copy of ``start`` for one full epoch; its log record plus ``cpu_seconds``."""
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(start, work)
    algo = "algo=her_mep" if mep else "algo=her"
    tic = time.process_time()
    log_path = train(compose([*BASE, algo, f"run_dir={work}"]))
    cpu_seconds = time.process_time() - tic
    return {**read_run(log_path).epochs.iloc[-1].to_dict(), "cpu_seconds": cpu_seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prefill", type=int, default=2000, help="random-policy episodes in the buffer")
    parser.add_argument("--repeats", type=int, default=2, help="timed epochs per variant")
    args = parser.parse_args()

    tic = time.perf_counter()
    prefill = random_policy_episodes(args.prefill, seed=0)
    print(f"prefill: {args.prefill} random-policy FetchPush episodes in {time.perf_counter() - tic:.0f} s")
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        starts = {mep: root / f"start-mep{int(mep)}" for mep in (False, True)}
        for mep, directory in starts.items():
            prefilled_start(directory, prefill, mep)
        records: dict[bool, list[dict]] = {False: [], True: []}
        order = [False, True, True, False] * ((args.repeats + 1) // 2)
        for mep in order[:2 * args.repeats]:
            record = timed_epoch(starts[mep], root / "work", mep)
            records[mep].append(record)
            fit = f"  fit {record['mep_fit_seconds']:.2f} s  entropy {record['priority_entropy']:.3f} nats" if mep else ""
            print(f"{'MEP' if mep else 'HER'} epoch {record['epoch_seconds']:6.1f} s wall, "
                  f"{record['cpu_seconds']:6.1f} s CPU  ({record['episodes_stored']:.0f} episodes stored){fit}")
    cpu = {mep: np.mean([r["cpu_seconds"] for r in records[mep]]) for mep in records}
    wall = {mep: min(r["epoch_seconds"] for r in records[mep]) for mep in records}
    fit = np.mean([r["mep_fit_seconds"] for r in records[True]])
    print(f"mean CPU seconds per epoch: without MEP {cpu[False]:.1f}, with MEP {cpu[True]:.1f} "
          f"(mean fit {fit:.2f} s)")
    print(f"fastest wall-clock epoch:   without MEP {wall[False]:.1f}, with MEP {wall[True]:.1f}")
    print(f"ratio with/without MEP: CPU {cpu[True] / cpu[False]:.3f}, wall clock {wall[True] / wall[False]:.3f}")


if __name__ == "__main__":
    main()
