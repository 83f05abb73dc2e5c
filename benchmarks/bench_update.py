"""update=fast against the default (autograd) update: the CPU time of one learner update, DDPG and TD3.

CPU seconds (process time: what a loaded machine's time slicing leaves out) of one update at FetchPush's
sizes and the paper's settings (3 x 256 networks, batches of 256, one fused Adam), 1 thread, on random
batches, the two updates interleaved in rounds of 40 updates (one cycle's) after a warm-up round (``rounds.py``);
the learner's update alone, without the minibatch's sampling (``bench_cycle.py`` times both, and the cycle).
Prints the CPU's name, family and model, each update's median (min-max) and the median of per-round ratios.

Usage: python benchmarks/bench_update.py [--rounds 20] (about a minute; docs/LEARNERS.md, "The fast update").
"""

from __future__ import annotations

import argparse

import torch

from hersd.contract.config import DDPGConfig, LearnerConfig, TrainConfig
from hersd.engine.learners import learner_class
from hersd.engine.learners.fast import fast_learner_class

from bench_precision import PUSH_SPEC, UPDATES, seconds_per_update  # FetchPush's sizes, one cycle's updates
from rounds import cpu_line, faster_line, spread


def update_cpu_seconds(name: str, rounds: int) -> dict[str, list[float]]:
    """Update ("autograd", "fast") -> CPU seconds per update of learner ``name`` in each round."""
    cfg = TrainConfig(ddpg=DDPGConfig(), learner=LearnerConfig(name=name))
    cls = learner_class(name)
    learners = {}
    for update, learner in {"autograd": cls, "fast": fast_learner_class(cls)}.items():
        torch.manual_seed(0)
        learners[update] = learner.build(cfg, PUSH_SPEC, 0.98, (-50.0, 0.0), torch.device("cpu"))
    return seconds_per_update(learners, rounds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    print(cpu_line())
    for name in ("ddpg", "td3"):
        seconds = update_cpu_seconds(name, args.rounds)
        print(f"{name.upper()} update CPU time, {args.rounds} interleaved rounds of {UPDATES}, median (min-max): "
              f"autograd {spread(seconds['autograd'], 1e3, 2)} ms, fast {spread(seconds['fast'], 1e3, 2)} ms")
        print(faster_line(f"ratio: {name.upper()} update, fp32 fast", seconds["fast"], seconds["autograd"],
                          "autograd", "update"))


if __name__ == "__main__":
    main()
