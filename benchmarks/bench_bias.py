"""The bias evaluation's cost against a training epoch, measured side by side in one process.

Builds a run's state at the paper's settings (FetchPush by default), trains ``--epochs`` epochs
(``hersd.engine.train.run_epoch``) and after each runs one bias evaluation at the defaults
(``hersd.engine.bias.BiasEvaluator``, its envs made once before the first), so machine load drifting hits
both alike. Printed: each epoch's and evaluation's seconds, the envs' making, and the share of a
run of K epochs that the default evaluation epochs take (those <= K, times the median evaluation,
plus one making of the envs per session) against K median epochs.

Usage: python benchmarks/bench_bias.py [--task push] [--epochs 3] [--threads 1]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from hersd.engine.bias import BiasEvaluator
from hersd.contract.compose import compose_train
from hersd.engine.envs.make import make_env
from hersd.engine.run_state import RunState
from hersd.engine.train import run_epoch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = compose_train([f"task={args.task}", "render_every=0", "quiet=true"])
    state = RunState(cfg)
    bias = BiasEvaluator(cfg.bias, cfg.task, cfg.seed, state.spec.horizon, state.gamma, state.reward,
                         cfg.flush_denormal)
    n_envs = max(cfg.bias.episodes, cfg.bias.hindsight_pairs)
    tic = time.perf_counter()
    bias.envs = [make_env(cfg.task) for _ in range(n_envs)]
    making = time.perf_counter() - tic
    epochs, evaluations = [], []
    for epoch in range(1, args.epochs + 1):
        tic = time.perf_counter()
        run_epoch(state, epoch)
        epochs.append(time.perf_counter() - tic)
        evaluations.append(bias.evaluate(state.agent, epoch)["bias_seconds"])
        print(f"epoch {epoch}: training {epochs[-1]:.1f} s, bias evaluation {evaluations[-1]:.2f} s", flush=True)
    bias.close()
    state.close()
    evaluated = [k for k in cfg.bias.epochs if k <= cfg.epochs]
    cost = len(evaluated) * statistics.median(evaluations) + making
    run = cfg.epochs * statistics.median(epochs)
    print(f"making {n_envs} envs: {making:.1f} s")
    print(f"{len(evaluated)} evaluations of K = {cfg.epochs}: {cost:.0f} s against {run:.0f} s of training: "
          f"{100 * cost / run:.2f} % of a run")


if __name__ == "__main__":
    main()
