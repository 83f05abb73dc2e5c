"""Each run's own numbers at fixed epochs, and the per-seed tables docs/RESULTS.md shows of them.

:func:`seed_values` makes one row per run (``tables/per_seed.csv`` of ``hersd-report``): its outcomes
(:func:`analysis.metrics.run_outcomes`), its mean rate, and its logged values at the epochs of
:data:`CHECKPOINTS` (column ``<field>_at_<epoch>``; empty where the run has not reached the epoch or did
not log the field there), its real-goal bias averaged over epochs 1-50 (:func:`analysis.critic.integrated_bias`)
and its cost (:func:`analysis.provenance.run_cost`).

:func:`seed_markdown` renders some runs of one configuration as a table, a column per seed and a row
per :data:`SEED_ROWS` entry, from that file alone: the tables of docs/RESULTS.md are its output,
rewritten by :mod:`analysis.doc_tables` and checked against the committed report by the tests.
Pure pandas: no torch, no MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from analysis.critic import GOAL_TYPES, integrated_bias
from analysis.metrics import GROUP, RUN_AUC, RUN_OUTCOME_COLUMNS
from analysis.provenance import run_cost

# logged field -> the epochs a per-seed table reads it at
CHECKPOINTS = {
    "smoothed": (50, 100, 150, 200),  # the run's smoothed test success (analysis.metrics.smoothed_curves)
    "relabel_rate": (1, 50, 100, 150, 200),
    "q_mean": (10, 50, 100, 200),
    "bias_real_mean": (1, 10, 20, 50, 100, 200),
    "bias_moved_mean": (5, 20, 30, 50, 75, 100, 150, 200),  # empty where no hindsight pair had moved the object
    "share_real_success": (150,), "share_hindsight": (150,), "share_real_failure": (150,),
}
BIAS_1_50 = "bias_real_1_50"  # the real-goal bias averaged over epochs 1-50


def checkpoint(field: str, epoch: int) -> str:
    """The column holding ``field`` at ``epoch``."""
    return f"{field}_at_{epoch}"


SEED_COLUMNS = ["task", "config", "seed", "complete", "epochs_done", *RUN_OUTCOME_COLUMNS, RUN_AUC, "mu_eps",
                *(checkpoint(field, epoch) for field, epochs in CHECKPOINTS.items() for epoch in epochs), BIAS_1_50,
                "paced_hours", "epoch_hours", "bias_percent", "path"]


def seed_values(runs: pd.DataFrame, epochs: pd.DataFrame, curves: pd.DataFrame,
                outcomes: pd.DataFrame) -> pd.DataFrame:
    """One row per run (columns: SEED_COLUMNS), ordered by task, configuration and seed. ``runs`` / ``epochs``:
    :class:`analysis.load.RunTable`'s; ``curves`` / ``outcomes``: :class:`analysis.metrics.Analysis`'."""
    logged = epochs.set_index(["run", "epoch"])
    smoothed = curves.set_index(["run", "epoch"])["smoothed"]
    table = runs[["run", *GROUP, "seed", "complete", "epochs_done", "mu_eps", "path"]].merge(outcomes, on="run")
    for field, at in CHECKPOINTS.items():
        values = smoothed if field == "smoothed" else logged[field]
        for epoch in at:
            table[checkpoint(field, epoch)] = values.reindex(pd.MultiIndex.from_arrays(
                [table["run"], np.full(len(table), epoch)])).to_numpy(float)
    evaluated = epochs.dropna(subset=["bias_real_mean"])
    bias = integrated_bias(evaluated[[*GROUP, "run", "epoch", *(f"bias_{kind}_mean" for kind in GOAL_TYPES)]])
    table = table.merge(bias[["run", "bias_real"]].rename(columns={"bias_real": BIAS_1_50}), on="run", how="left")
    cost = run_cost(epochs)[["paced_hours", "epoch_hours", "bias_percent"]]
    table = table.merge(cost, left_on="run", right_index=True, how="left")
    return table.sort_values([*GROUP, "seed", "path"])[SEED_COLUMNS].reset_index(drop=True)


@dataclass(frozen=True)
class SeedRow:
    """One row of a per-seed table: its words, the columns it joins with `` / `` (then ``; `` and ``last``)."""

    words: str
    columns: tuple[str, ...]
    form: Callable[[float], str]
    last: str | None = None  # a summary column after "; "
    last_form: Callable[[float], str] | None = None  # its form, if not ``form``


def _share(value: float) -> str:
    return f"{value:.3f}"


def _epoch(value: float) -> str:
    return "never" if pd.isna(value) else f"{int(value)}"


SEED_ROWS = {
    "smoothed": SeedRow("smoothed test success at epoch 50 / 100 / 150 / 200",
                        tuple(checkpoint("smoothed", epoch) for epoch in CHECKPOINTS["smoothed"]), _share),
    "raw_epochs": SeedRow("first epoch the raw test success reaches 0.5 / 0.9",
                          ("raw_epochs_to_0.5", "raw_epochs_to_0.9"), _epoch),
    "smoothed_epochs": SeedRow("first epoch the smoothed curve reaches 0.5 / 0.9", ("epochs_to_0.5", "epochs_to_0.9"),
                               _epoch),
    "minibatch": SeedRow("minibatch at epoch 150 (real successful / hindsight / real unsuccessful)",
                         tuple(checkpoint(field, 150) for field in ("share_real_success", "share_hindsight",
                                                                    "share_real_failure")), _share),
    "q": SeedRow("mean Q at epoch 10 / 50 / 100 / 200", tuple(checkpoint("q_mean", epoch)
                                                             for epoch in CHECKPOINTS["q_mean"]), "{:.2f}".format),
    "bias": SeedRow("critic bias on real goals at epoch 1 / 10 / 20 / 50 / 100 / 200; averaged over epochs 1-50",
                    tuple(checkpoint("bias_real_mean", epoch) for epoch in CHECKPOINTS["bias_real_mean"]),
                    "{:+.1f}".format, last=BIAS_1_50),
    "moved": SeedRow("critic bias on hindsight goals the object was moved to, at epoch 5 / 20 / 30 / 50 / 75 / 100 / "
                     "150 / 200",
                     tuple(checkpoint("bias_moved_mean", epoch) for epoch in CHECKPOINTS["bias_moved_mean"]),
                     "{:+.1f}".format),
    "rate": SeedRow("relabel rate at epoch 1 / 50 / 100 / 150 / 200; its mean over the 200 epochs",
                    tuple(checkpoint("relabel_rate", epoch) for epoch in CHECKPOINTS["relabel_rate"]), _share,
                    last="mu_eps"),
    "outcome": SeedRow("final smoothed test success; mean raw test success over the epochs (raw AUC)", ("final",),
                       _share, last=RUN_AUC),
    "cost": SeedRow("hours of epochs at the median pace / wall clock; the bias evaluations' share of the first",
                    ("paced_hours", "epoch_hours"), "{:.2f} h".format, last="bias_percent",
                    last_form="{:.2f} %".format),
}


def _cell(row: SeedRow, values: pd.Series) -> str:
    def shown(column: str, form: Callable[[float], str]) -> str:
        value = values[column]
        return "-" if pd.isna(value) and form is not _epoch else form(value)

    cell = " / ".join(shown(column, row.form) for column in row.columns)
    return cell + (f"; {shown(row.last, row.last_form or row.form)}" if row.last else "")


def seed_markdown(table: pd.DataFrame, task: str, config: str, seeds: Sequence[int], name: str,
                  rows: Sequence[str]) -> str:
    """The markdown table of ``config``'s ``seeds`` on ``task`` (``table``: :func:`seed_values`' rows, as written
    to per_seed.csv and read back): a column per seed headed ``<name> seed <s>``, a row per key of SEED_ROWS in
    ``rows``; ``-`` where a run lacks the value. Raises ValueError naming what is missing."""
    unknown = [key for key in rows if key not in SEED_ROWS]
    if unknown:
        raise ValueError(f"unknown per-seed rows {unknown}; known: {', '.join(SEED_ROWS)}")
    chosen = table[(table["task"] == task) & (table["config"] == config)].set_index("seed")
    if chosen.index.duplicated().any():
        raise ValueError(f"{config!r} on {task} has more than one run of a seed: name the runs apart")
    missing = [seed for seed in seeds if seed not in chosen.index]
    if missing:
        raise ValueError(f"no run of {config!r} on {task} with seed {missing} in the per-seed table")
    lines = ["| | " + " | ".join(f"{name} seed {seed}" for seed in seeds) + " |",
             "| --- " * (len(seeds) + 1) + "|"]
    for key in rows:
        row = SEED_ROWS[key]
        lines.append(f"| {row.words} | " + " | ".join(_cell(row, chosen.loc[seed]) for seed in seeds) + " |")
    return "\n".join(lines) + "\n"
