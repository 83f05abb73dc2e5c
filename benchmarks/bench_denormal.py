"""Update cycles with and without ``flush_denormal``, from the checkpoint of a run in progress.

A trained run's Adam moments hold many denormal floats (units whose gradient died decay through
the denormal range for thousands of steps), and x86 CPUs compute on denormals many times slower.
Fresh networks have none, so this benchmark starts from a real checkpoint: ``RUN_DIR`` must hold
``run.mcap`` and ``checkpoint.pt`` (a run in progress, or one made with ``keep_checkpoint=true``).

Each variant reloads the checkpoint (so both start from the same denormals), then times
``--cycles`` update cycles of ``hersd.train.update`` (40 updates of 256 and one target move at the
paper's settings) on one thread, alternating (off, on, off, on, ...) in this one process so drift
in the machine's load hits both. Printed: each timing, then the ratio of the fastest of each, and
the share of denormals in the checkpoint's optimiser state.

Usage: python benchmarks/bench_denormal.py RUN_DIR [--cycles 5] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import torch

from hersd.render import load_run
from hersd.run_state import RunState
from hersd.train import EpochStats, update


def denormal_share(optimizer_state: dict) -> float:
    """The share of denormal values among the floats of an optimiser's state dict."""
    tiny, denormal, total = torch.finfo(torch.float32).tiny, 0, 0
    for moments in optimizer_state["state"].values():
        for value in moments.values():
            if torch.is_tensor(value) and value.is_floating_point() and value.numel() > 1:
                denormal += int(((value != 0) & (value.abs() < tiny)).sum())
                total += value.numel()
    return denormal / max(total, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--cycles", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg, checkpoint = load_run(args.run_dir, None)
    print(f"{args.run_dir}: epoch {checkpoint['epoch']}, denormals in Adam's state: "
          f"{denormal_share(checkpoint['agent']['optimizer']):.1%}")
    state = RunState(cfg)
    best = {False: float("inf"), True: float("inf")}
    for _ in range(args.repeats):
        for flush in (False, True):
            state.load_state_dict(load_run(args.run_dir, None)[1])
            state.cfg = replace(cfg, flush_denormal=flush)
            stats = EpochStats(checkpoint["epoch"] + 1, 0.8)
            start = time.perf_counter()
            for _ in range(args.cycles):
                update(state, 0.8, stats)
            seconds = (time.perf_counter() - start) / args.cycles
            best[flush] = min(best[flush], seconds)
            print(f"flush_denormal={str(flush).lower():<5}  {seconds:.3f} s per update cycle", flush=True)
    print(f"fastest: {best[False]:.3f} s without, {best[True]:.3f} s with -> {best[False] / best[True]:.2f}x faster")


if __name__ == "__main__":
    main()
