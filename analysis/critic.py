"""The critic's accuracy (the seed paper's Fig. 10 question) from the logs' bias evaluations and Q split.

- :func:`critic_curves`: per (task, config, epoch), the median over seeds and the quartiles of
  each :data:`CRITIC_COLUMNS` field (the bias of Q against the policy's true return, for real and
  hindsight goals and hindsight goals the object was moved to, hersd/engine/bias.py; the share of hindsight
  pairs whose return is exactly 0; the mean Q of real-goal and relabelled training rows);
- :func:`integrated_bias`: per run and goal type, the bias averaged over epochs 1-50 (trapezoids
  over the evaluated epochs, so the dense early evaluations weigh what they span);
- :func:`bias_tests`: two-sided permutation tests of that average between the configurations of a task;
- :func:`bias_evaluations`: every logged evaluation of every run, one row each (``tables/bias_evaluations.csv``).

Pure computations on the tables of :mod:`analysis.load`; the figure is drawn in :mod:`analysis.figures`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.metrics import BOOTSTRAP_SEED, GROUP, permutation_p_values

GOAL_TYPES = ("real", "hindsight", "moved")
CRITIC_COLUMNS = ("bias_real_mean", "bias_hindsight_mean", "bias_moved_mean", "bias_hindsight_zero_share",
                  "q_real_mean", "q_hindsight_mean")
INTEGRATION_EPOCHS = (1, 50)
EVALUATION_COLUMNS = ["task", "config", "seed", "complete", "epoch", "bias_real_mean", "bias_hindsight_mean",
                      "bias_hindsight_zero_share", "bias_moved_mean", "bias_moved_count", "bias_seconds", "path"]
BIAS_TEST_COLUMNS = ["task", "goal_type", "config", "versus", "seeds", "versus_seeds", "config_bias", "versus_bias",
                     "difference", "p_two_sided"]


def critic_curves(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch) with any CRITIC_COLUMNS value: <column>_median, <column>_q25, <column>_q75
    over seeds (NaN where no seed has it) and n_seeds (seeds with a bias evaluation at that epoch)."""
    present = epochs.dropna(subset=list(CRITIC_COLUMNS), how="all")
    grouped = present.groupby([*GROUP, "epoch"], observed=True)
    parts = {f"{column}_{name}": grouped[column].quantile(q) if q != 0.5 else grouped[column].median()
             for column in CRITIC_COLUMNS for name, q in (("median", 0.5), ("q25", 0.25), ("q75", 0.75))}
    table = pd.DataFrame(parts)
    table["n_seeds"] = grouped["bias_real_mean"].count()
    return table.reset_index()


def integrated_bias(epochs: pd.DataFrame, first: int = INTEGRATION_EPOCHS[0],
                    last: int = INTEGRATION_EPOCHS[1]) -> pd.DataFrame:
    """Per run with bias evaluations at both ``first`` and ``last``: task, config, run, and per goal type
    ``bias_<type>`` = the trapezoid integral of its mean bias over the evaluated epochs in [first, last],
    divided by last - first (a time average)."""
    rows = []
    for (task, config, run), group in epochs.groupby([*GROUP, "run"], observed=True):
        row = {"task": task, "config": config, "run": run}
        for goal_type in GOAL_TYPES:
            evaluated = group[group["epoch"].between(first, last)].dropna(subset=[f"bias_{goal_type}_mean"])
            epoch = evaluated["epoch"].to_numpy(float)
            covered = epoch.size >= 2 and epoch.min() == first and epoch.max() == last
            row[f"bias_{goal_type}"] = (np.trapezoid(evaluated[f"bias_{goal_type}_mean"].to_numpy(float), epoch)
                                        / (last - first)) if covered else np.nan
        rows.append(row)
    return pd.DataFrame.from_records(rows, columns=[*GROUP, "run", *(f"bias_{g}" for g in GOAL_TYPES)])


def bias_tests(integrated: pd.DataFrame, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """Per task and goal type, every pair of configurations with at least two runs' integrated bias
    (:func:`integrated_bias`): their mean over runs, the difference config - versus and its two-sided
    permutation p-value (:func:`analysis.metrics.permutation_p_values`, exact up to its EXACT_SPLITS splits).
    Columns: BIAS_TEST_COLUMNS."""
    rows = []
    for goal_type in GOAL_TYPES:
        column = f"bias_{goal_type}"
        values = integrated.dropna(subset=[column])
        for task, in_task in values.groupby("task", observed=True):
            samples = {config: group[column].to_numpy(float)
                       for config, group in in_task.groupby("config", observed=True) if len(group) >= 2}
            configs = list(samples)
            for i, config in enumerate(configs):
                for versus in configs[i + 1:]:
                    x, y = samples[config], samples[versus]
                    p_greater, p_less = permutation_p_values(x[None], y[None], seed)
                    rows.append({"task": task, "goal_type": goal_type, "config": config, "versus": versus,
                                 "seeds": x.size, "versus_seeds": y.size, "config_bias": x.mean(),
                                 "versus_bias": y.mean(), "difference": x.mean() - y.mean(),
                                 "p_two_sided": float(min(1.0, 2 * min(p_greater[0], p_less[0])))})
    return pd.DataFrame.from_records(rows, columns=BIAS_TEST_COLUMNS)


def bias_evaluations(epochs: pd.DataFrame) -> pd.DataFrame:
    """One row per run x epoch with a bias evaluation, as its log holds it (columns: EVALUATION_COLUMNS; fields a
    log's gauge did not yet have are empty), ordered by task, configuration, seed and epoch."""
    evaluated = epochs[epochs["bias_seconds"].notna()]
    return evaluated.sort_values([*GROUP, "seed", "path", "epoch"])[EVALUATION_COLUMNS].reset_index(drop=True)
