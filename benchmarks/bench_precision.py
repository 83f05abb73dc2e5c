"""precision=bf16 against fp32: how far a bf16 critic's Q lies from the float32 one's, with its output
layer in bf16 or in float32, and the CPU time of one DDPG update at each precision.

(1) A freshly initialised critic of the paper's size (3 x 256 ReLU, FetchPush's 32 inputs) on one batch
of 256 normalised inputs, its output bias set to 0 and to -15 (a trained Fetch critic's Q lies in
[-50, 0]), run under bf16 autocast with every layer bf16 and with the output layer float32
(:class:`hersd.engine.learners.base.FullPrecisionLinear`, what precision=bf16 builds), each against float32.
(2) CPU seconds (process time: what a loaded machine's time slicing leaves out) of one DDPG update at
FetchPush's sizes and the paper's settings, 1 thread, random batches of 256, four paths (fp32 autograd,
fp32 fast, bf16 autocast, bf16 fast) interleaved in rounds of 40 updates (``rounds.py``), after a warm-up
round: each path's median (min-max) and its ratio to fp32 autograd (the median of per-round ratios), under
the CPU's name, family and model. On a CPU without bf16 instructions torch emulates bf16: the lines say
so, and measure what hersd's refusal of precision=bf16 there avoids.

Usage: python benchmarks/bench_precision.py [--rounds 20] (about a minute; docs/LEARNERS.md, "Precision").
"""

from __future__ import annotations

import argparse
import time
from typing import Any
from unittest import mock

import numpy as np
import torch

from hersd.contract.config import DDPGConfig
from hersd.engine.envs.make import EnvSpec
from hersd.engine.learners.base import FullPrecisionLinear, mlp
from hersd.engine.resources import cpu_has_bf16
from hersd.engine.learners.ddpg import DDPG
from hersd.engine.learners.fast import FastDDPG
from hersd.engine.replay.buffer import TransitionBatch

from rounds import cpu_line, faster_line, interleaved, spread

INPUTS, BATCH, OFFSETS = 32, 256, (0.0, -15.0)
OBS, GOAL, ACTION, UPDATES = 25, 3, 4, 40  # FetchPush's sizes; updates per round (one cycle's)
PUSH_SPEC = EnvSpec(obs_dim=OBS, goal_dim=GOAL, action_dim=ACTION, horizon=50, max_action=1.0,
                    distance_threshold=0.05, reward_range=(-1.0, 0.0))


def q_errors(offset: float) -> dict[str, torch.Tensor]:
    """abs(Q_bf16 - Q_fp32) (BATCH, 1) of the two bf16 variants of a critic whose Q is about ``offset``."""
    torch.manual_seed(0)
    inputs = torch.randn(BATCH, INPUTS).clamp(-5.0, 5.0)
    plain = mlp(INPUTS, 1, 3, 256)
    with torch.no_grad():
        plain[-1].bias.fill_(offset)
    float_output = mlp(INPUTS, 1, 3, 256, FullPrecisionLinear)
    float_output.load_state_dict(plain.state_dict())
    with torch.no_grad():
        q = plain(inputs)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return {"every layer bf16": (plain(inputs).float() - q).abs(),
                    "output layer float32": (float_output(inputs) - q).abs()}


def random_batch(rng: np.random.Generator) -> TransitionBatch:
    """BATCH random FetchPush-sized transitions, rewards 0 or -1, a fifth of them real-goal rows."""
    def normal(dim: int) -> np.ndarray:
        return rng.normal(size=(BATCH, dim)).astype(np.float32)
    zeros = np.zeros(BATCH, int)
    return TransitionBatch(obs=normal(OBS), next_obs=normal(OBS), goal=normal(GOAL),
                           action=rng.uniform(-1, 1, (BATCH, ACTION)).astype(np.float32),
                           reward=-rng.integers(0, 2, BATCH).astype(np.float32), relabelled=rng.random(BATCH) < 0.8,
                           real_success=zeros.astype(bool), episode=zeros, t=zeros)


def seconds_per_update(learners: dict[str, Any], rounds: int) -> dict[str, list[float]]:
    """Label -> CPU seconds per update of that learner in each of ``rounds`` rounds of UPDATES random
    batches (1 thread; the learners interleaved round by round, after a warm-up round)."""
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    batches = [random_batch(rng) for _ in range(UPDATES)]

    def one_round(learner: Any) -> dict[str, float]:
        tic = time.process_time()
        for batch in batches:
            learner.update(batch)
        return {"update": (time.process_time() - tic) / UPDATES}

    kept = interleaved({label: (lambda learner=learner: one_round(learner)) for label, learner in learners.items()},
                       rounds)
    return {label: kept[label]["update"] for label in learners}


PATHS = {"fp32 autograd": (DDPG, "fp32"), "fp32 fast": (FastDDPG, "fp32"), "bf16, autocast": (DDPG, "bf16"),
         "bf16, fast": (FastDDPG, "bf16")}  # label -> (learner class, precision)


def update_cpu_seconds(rounds: int) -> dict[str, list[float]]:
    """Path label -> CPU seconds per update of each round (the paths interleaved, after a warm-up). Builds the
    bf16 learners past hersd's refusal on a CPU without bf16 instructions, to measure their cost."""
    with mock.patch("hersd.engine.learners.base.check_precision"):
        learners = {label: cls(DDPGConfig(), PUSH_SPEC, 0.98, (-50.0, 0.0), precision=precision)
                    for label, (cls, precision) in PATHS.items()}
    return seconds_per_update(learners, rounds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    print(cpu_line())
    for offset in OFFSETS:
        for label, error in q_errors(offset).items():
            print(f"Q near {offset:+5.0f}, {label:<21} mean abs error {error.mean():.1e}, max {error.max():.1e}")
    seconds = update_cpu_seconds(args.rounds)
    emulated = "" if cpu_has_bf16() else " (bf16 emulated: this CPU has no bf16 instructions)"
    print(f"DDPG update CPU time, {args.rounds} interleaved rounds of {UPDATES} updates, median (min-max){emulated}:")
    for label, values in seconds.items():
        print(f"  {label:<15} {spread(values, 1e3, 2)} ms")
    for label in list(PATHS)[1:]:
        print(faster_line(f"ratio: DDPG update, {label}", seconds[label], seconds["fp32 autograd"], "fp32", "update"))


if __name__ == "__main__":
    main()
