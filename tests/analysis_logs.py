"""Synthetic run logs with hand-computed outcomes, shared by the tests of analysis/ (test_load.py,
test_metrics.py, test_figures.py, test_report.py, ...): their configs, curves and the smoothing window.
The folders of logs made from them are fixtures in conftest.py (``hand_sized``, ``sweep``, ``push_paper``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.load import load_runs
from analysis.synthetic import write_run
from hersd.contract.config import AlgoConfig, MEPConfig, TaskConfig, TrainConfig
from hersd.contract.schedules import Constant, Exponential, Linear, Schedule

# Five seeds x six epochs of HER test success, smoothed with a trailing window of 3 epochs.
WINDOW = 3
HER_SUCCESS = [
    [0.0, 0.0, 0.3, 0.6, 0.9, 0.9],  # smoothed: 0, 0,    0.1, 0.3,    0.6,    0.8
    [0.0, 0.3, 0.6, 0.7, 0.9, 1.0],  # smoothed: 0, 0.15, 0.3, 0.5333, 0.7333, 0.8667
    [0.0, 0.0, 0.0, 0.3, 0.3, 0.6],  # smoothed: 0, 0,    0,   0.1,    0.2,    0.4
    [0.3, 0.6, 0.9, 1.0, 1.0, 1.0],  # smoothed: 0.3, 0.45, 0.6, 0.8333, 0.9667, 1.0
    [0.6, 0.6, 0.6, 0.6, 0.6, 0.3],  # smoothed: 0.6, 0.6, 0.6, 0.6,    0.6,    0.5
]
# Median over the five seeds at each epoch, by hand from the smoothed values above.
HER_MEDIAN = [0.0, 0.15, 0.3, 1.6 / 3, 0.6, 0.8]
HER_FINALS = [0.8, 2.6 / 3, 0.4, 1.0, 0.5]
LINEAR_SUCCESS = [[0.95] * 6, [0.2] * 6]  # two flat seeds of "linear b1=0.5"


def make_config(task: str = "push", schedule: Schedule | None = None, seed: int = 0, epochs: int = 6,
                lambda_h: float = 1.0, mep: bool = False) -> TrainConfig:
    return TrainConfig(task=TaskConfig(name=task),
                       algo=AlgoConfig(name="archer" if lambda_h != 1.0 else "her", lambda_h=lambda_h,
                                       mep=MEPConfig(enabled=mep)),
                       schedule=schedule or Constant(), seed=seed, epochs=epochs)


def write_campaign_midway(folder: Path, in_progress: bool = True) -> None:
    """Two complete seeds each of HER and linear b1=0.5; with ``in_progress``, besides them a HER
    seed that succeeds at once (4 of 6 epochs), a linear seed that never does (5 of 6 epochs) and
    a configuration with only an unfinished run (exp, 3 of 6 epochs)."""
    linear, exponential = Linear(beta1=0.5), Exponential(beta1=0.5, beta2=0.5)
    for seed in (0, 1):
        write_run(folder / f"her{seed}", make_config(seed=seed), np.array(HER_SUCCESS[seed]))
        write_run(folder / f"linear{seed}", make_config(schedule=linear, seed=seed), np.array(LINEAR_SUCCESS[seed]))
    if in_progress:
        write_run(folder / "her2", make_config(seed=2), np.ones(4), complete=False)
        write_run(folder / "linear2", make_config(schedule=linear, seed=2), np.zeros(5), complete=False)
        write_run(folder / "exp0", make_config(schedule=exponential), np.ones(3), complete=False)


def run_tables(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The runs and epochs tables of every log under ``folder``."""
    table = load_runs(folder)
    return table.runs, table.epochs


# --- the FetchPush comparison of the paper (Figs. 2, 4, 10 and the summary) ---------------------------------------

# Test success per seed: 0 until the step epoch, 1 after it, so the 50-epoch moving average at epoch
# k > step is min(k - step, 50) / 50 (the window holds k - step successes).
PUSH_STEPS = {"HER": (50, 60, 80), "linear b1=0.25": (40, 50, 120), "HER eps=0.874375": (45, 55, 70)}
PUSH_SCHEDULES = {"HER": Constant(), "linear b1=0.25": Linear(beta1=0.25),
                  "HER eps=0.874375": Constant(eps=0.874375)}
# HER's minibatch shares at epoch 150 per seed (real successful, hindsight, real unsuccessful):
# medians 0.06, 0.80, 0.14, which already sum to 1.
HER_SHARES_150 = [(0.02, 0.80, 0.18), (0.06, 0.80, 0.14), (0.09, 0.80, 0.11)]
PUSH_EPOCHS = 150
