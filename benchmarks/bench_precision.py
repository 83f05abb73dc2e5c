"""precision=bf16 against fp32: how far a bf16 critic's Q lies from the float32 one's, with its output
layer in bf16 or in float32, and the CPU time of one DDPG update at each precision.

(1) A freshly initialised critic of the paper's size (3 x 256 ReLU, FetchPush's 32 inputs) on one batch
of 256 normalised inputs, its output bias set to 0 and to -15 (a trained Fetch critic's Q lies in
[-50, 0]), run under bf16 autocast with every layer bf16 and with the output layer float32
(:class:`hersd.engine.learners.base.FullPrecisionLinear`, what precision=bf16 builds), each against float32.
(2) CPU seconds (process time: what a loaded machine's time slicing leaves out) of one DDPG update at
FetchPush's sizes and the paper's settings, 1 thread, random batches of 256, the precisions alternating
in rounds of 40 updates. On a CPU without bf16 instructions torch emulates bf16: the line says so, and
measures what hersd's refusal of precision=bf16 there avoids.

Usage: python benchmarks/bench_precision.py [--rounds 4] (half a minute; docs/LEARNERS.md, "Precision").
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
from hersd.engine.replay.buffer import TransitionBatch

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
    batches (1 thread; the learners alternating round by round, after a warm-up round)."""
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    batches = [random_batch(rng) for _ in range(UPDATES)]
    seconds: dict[str, list[float]] = {label: [] for label in learners}
    for round_ in range(rounds + 1):
        for label, learner in learners.items():
            tic = time.process_time()
            for batch in batches:
                learner.update(batch)
            if round_:  # round 0 warms up
                seconds[label].append((time.process_time() - tic) / UPDATES)
    return seconds


def update_cpu_seconds(rounds: int) -> dict[str, list[float]]:
    """Precision -> CPU seconds per update of each round (the precisions alternating, after a warm-up).
    Builds the bf16 learner past hersd's refusal on a CPU without bf16 instructions, to measure its cost."""
    with mock.patch("hersd.engine.learners.base.check_precision"):
        learners = {precision: DDPG(DDPGConfig(), PUSH_SPEC, 0.98, (-50.0, 0.0), precision=precision)
                    for precision in ("fp32", "bf16")}
    return seconds_per_update(learners, rounds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    for offset in OFFSETS:
        for label, error in q_errors(offset).items():
            print(f"Q near {offset:+5.0f}, {label:<21} mean abs error {error.mean():.1e}, max {error.max():.1e}")
    seconds = update_cpu_seconds(args.rounds)
    fp32, bf16 = (float(np.median(seconds[precision])) for precision in ("fp32", "bf16"))
    ratio = f"{fp32 / bf16:.2f}x faster" if bf16 <= fp32 else f"{bf16 / fp32:.2f}x slower"
    emulated = "" if cpu_has_bf16() else " (emulated: this CPU has no bf16 instructions)"
    print(f"DDPG update CPU time (median of {args.rounds} rounds of {UPDATES}): fp32 {fp32 * 1e3:.2f} ms, "
          f"bf16 {bf16 * 1e3:.2f} ms -> bf16 {ratio}{emulated}")


if __name__ == "__main__":
    main()
