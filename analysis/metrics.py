"""Metrics on the tidy tables of :mod:`analysis.load`: pure functions, no drawing.

Vocabulary (each formula is restated in docs/ANALYSIS.md):

- *smoothed curve* of a run: trailing moving average of test success over ``window``
  epochs; the first epochs average the epochs so far (min_periods=1).
- *failed*: a run that stopped with an error (its ``error.log``, :meth:`hersd.contract.runstore.RunFolder.error`);
  it is not in progress, and like one enters no statistic.
- *in progress*: a run whose log has no completion marker (still running, or stopped), not failed. It
  enters no statistic: not the median curves, tables, IQM, P(improve), composition or mean Q;
  the learning-curve figures draw it on its own (``Analysis.curves``, ``complete`` False).
- *median curve* of a (task, config): at each epoch, the median over its complete seeds of
  their smoothed curves; ``low`` / ``high`` are the min / max over those seeds.
- *final success* of a complete seed: its smoothed curve at its last epoch K.
"""

from __future__ import annotations

import functools
import json
import math
import warnings
from collections import defaultdict
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np
import pandas as pd

from analysis.load import HER_EPS, HER_WEIGHTS, RATE_TOLERANCE, logged_schedule
from hersd.contract.config import PAPER_LEARNER
from hersd.contract.schedules import schedule_rank
from hersd.contract.tasks import task_rank

GROUP = ["task", "config"]
SUCCESS_THRESHOLDS = (0.5, 0.9)
BASELINE = "HER"
BOOTSTRAP_SEED = 0
BOOTSTRAP_RESAMPLES = 2000
CONFIDENCE = 0.95
SHARE_COLUMNS = ("share_real_success", "share_real_failure", "share_hindsight")
# The seed paper's Fig. 2 numbers (its Sec. III text): FetchPush, HER (eps = 0.8), the minibatch
# at epoch 150 holds 5.3 % successful real, 80 % hindsight and 14.7 % unsuccessful real transitions.
PAPER_COMPOSITION_TASK = "push"
PAPER_COMPOSITION_EPOCH = 150
PAPER_COMPOSITION = {"share_real_success": 0.053, "share_hindsight": 0.80, "share_real_failure": 0.147}
SUMMARY_COLUMNS = ["task", "config", "total_epochs", "seeds", "in_progress", "mu_eps", "final_median", "auc",
                   *(f"epochs_to_{threshold:g}" for threshold in SUCCESS_THRESHOLDS),
                   *(f"raw_epochs_to_{threshold:g}" for threshold in SUCCESS_THRESHOLDS), "iqm", "iqm_low", "iqm_high",
                   f"p_improve_{BASELINE}"]

RUN_AUC = "raw_auc"  # besides RUN_OUTCOME_COLUMNS in run_outcomes: a run's mean raw test success over its epochs
RUN_OUTCOME_COLUMNS = ["final", *(f"{prefix}epochs_to_{threshold:g}" for prefix in ("", "raw_")
                                  for threshold in SUCCESS_THRESHOLDS)]

# The permutation tests (permutation_p_values) count every split of the pooled seeds when there are at most
# EXACT_SPLITS (5 seeds against 5: 252; 10 against 10: 184,756; 11 against 11: 705,432), and beyond that draw
# PERMUTATION_RESAMPLES splits at random from a seeded generator (scipy.stats.permutation_test).
EXACT_SPLITS = 1_000_000
PERMUTATION_RESAMPLES = 9999
STATISTIC_DECIMALS = 10  # the permutation tests' mean differences: see _mean_difference
PERMUTATION_BATCH = 64  # random splits evaluated at once: bounds memory (~ batch x rows x seeds floats)
SPLITS_BATCH = 65_536  # exact splits evaluated at once: bounds memory (~ batch x (rows + seeds) floats)
# The decay against the constant rate at the same mean rate (equal_mu_tests, Fig. 12's arms side by side): mu_eps
# equal within this tolerance. A beta1 solved from schedule.mean_rate is rounded to 6 decimals (its mu_eps within
# ~3e-7 of the target), and a control typed from summary.csv's 6-decimal mu_eps lies within 5e-7 of the decay's.
EQUAL_MU_TOLERANCE = 1e-6
EQUAL_MU_OUTCOMES = [*RUN_OUTCOME_COLUMNS, RUN_AUC]
TWO_WAY_COLUMNS = ["seeds", "versus_seeds", "outcome", "config_mean", "versus_mean", "p_config_better",
                   "p_versus_better", "splits", "smallest_p"]  # two_way_tests' columns after the pair's
EQUAL_MU_COLUMNS = ["task", "config", "versus", "mu_eps", *TWO_WAY_COLUMNS]
VARIANT_COLUMNS = ["task", "config", "versus", "variant", *TWO_WAY_COLUMNS]
PERMUTATION_COLUMNS = ["task", "config", "versus", "seeds", "versus_seeds",
                       *(f"p_{outcome}" for outcome in RUN_OUTCOME_COLUMNS)]

SMOOTHED_DECIMALS = 12  # without a grid (below): far finer than any success rate, far coarser than float noise
# Test success is k/n (n test episodes, 20 by default): the grid. A value within GRID_TOLERANCE of a fraction
# with a denominator up to MAX_TEST_EPISODES is that fraction; the grid of a table is the least common
# denominator of its values (at most MAX_GRID, else it has none).
MAX_TEST_EPISODES = 10_000
MAX_GRID = 1_000_000
GRID_TOLERANCE = 1e-12


def success_grid(success: np.ndarray) -> float:
    """D, the least common denominator of the test-success values (shape (n,)), so that every value times D
    is a whole number (20 for 20 test episodes); NaN when a value is no fraction k/n with n <= MAX_TEST_EPISODES
    (within GRID_TOLERANCE) or D would exceed MAX_GRID."""
    denominator = 1
    for value in np.unique(np.asarray(success, dtype=float)):
        if not np.isfinite(value):
            continue
        fraction = Fraction(float(value)).limit_denominator(MAX_TEST_EPISODES)
        denominator = math.lcm(denominator, fraction.denominator)
        if abs(float(fraction) - value) > GRID_TOLERANCE or denominator > MAX_GRID:
            return float("nan")
    return float(denominator)


def on_grid(values, denominators) -> np.ndarray:
    """Each value (shape (n,) or scalar) made the float nearest the multiple of 1/denominator it stands for:
    its exact fraction, rounded once (a median or mean of such values computed in floats may lie 1e-16 below
    it: 0.85 and 0.95 average to 0.8999999999999999). Where a denominator is NaN (no grid), the value rounded
    to SMOOTHED_DECIMALS instead."""
    values, denominators = np.asarray(values, dtype=float), np.asarray(denominators, dtype=float)
    with np.errstate(invalid="ignore"):
        snapped = np.round(values * denominators) / denominators
    return np.where(np.isnan(denominators), np.round(values, SMOOTHED_DECIMALS), snapped)


def grid_mean(values: np.ndarray, denominators: np.ndarray) -> float:
    """The exact mean of ``values`` (shape (n,)), each a multiple of 1/its denominator (shape (n,)), rounded once:
    summed as fractions; the float mean rounded to SMOOTHED_DECIMALS when a denominator is NaN."""
    values, denominators = np.asarray(values, dtype=float), np.asarray(denominators, dtype=float)
    if len(values) == 0:
        return float("nan")
    if np.isnan(denominators).any():
        return float(np.round(values.mean(), SMOOTHED_DECIMALS))
    distinct, which = np.unique(denominators, return_inverse=True)
    numerators = np.bincount(which, weights=np.round(values * denominators))  # whole numbers, exact below 2**53
    total = sum(Fraction(int(numerator), int(denominator)) for numerator, denominator in zip(numerators, distinct))
    return float(total / len(values))


def grid_median(values: np.ndarray, denominator: float) -> float:
    """The exact median of ``values`` (shape (n,)), all multiples of 1/denominator: the mean of the two middle
    values of an even count lies on the grid 1/(2 denominator)."""
    return float(on_grid(np.median(values), 2 * denominator)) if len(values) else float("nan")


def common_grid(grids) -> float:
    """The least common multiple of denominators (whole numbers as floats): a grid all their values lie on;
    NaN when one is NaN."""
    grids = np.asarray(grids, dtype=float)
    return float("nan") if np.isnan(grids).any() or len(grids) == 0 else float(np.lcm.reduce(grids.astype(np.int64)))


def smoothed_curves(epochs: pd.DataFrame, window: int) -> pd.DataFrame:
    """Per run, the trailing mean of test_success over ``window`` epochs (min_periods=1), exact: each value is
    the sum of the test successes in its window over the number of epochs it averages, made the float nearest
    that fraction (:func:`on_grid`; pandas' running sum alone gave 0.49999999999999994 for 25 of 50).

    ``epochs``: the tidy epoch table. Returns columns task, config, run, seed, complete, epoch, success (raw),
    smoothed, success_grid (D of :func:`success_grid`, the same for every row; NaN: none) and
    smoothed_grid (D times the epochs the value averages: its denominator); sorted by run then epoch.
    """
    if window < 1:
        raise ValueError(f"the smoothing window must be >= 1 epoch, got {window}")
    curves = epochs[["task", "config", "run", "seed", "complete", "epoch", "test_success"]].sort_values(["run", "epoch"])
    curves = curves.rename(columns={"test_success": "success"}).reset_index(drop=True)
    grid = success_grid(curves["success"].to_numpy())
    curves["success"] = on_grid(curves["success"].to_numpy(), grid)
    by_run = curves.groupby("run", sort=False)
    rolling = by_run["success"].rolling(window, min_periods=1).mean()
    curves["success_grid"] = grid
    curves["smoothed_grid"] = grid * np.minimum(by_run.cumcount().to_numpy() + 1, window)
    curves["smoothed"] = on_grid(rolling.to_numpy(), curves["smoothed_grid"].to_numpy())
    return curves


def median_curves(curves: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): median, low (min), high (max) of ``smoothed`` over seeds, n_seeds,
    raw_median (the median of the raw, unsmoothed success) and median_grid (the denominator of median:
    2 smoothed_grid), medians exact (:func:`on_grid`)."""
    grouped = curves.groupby([*GROUP, "epoch"], observed=True)
    summary = grouped.agg(median=("smoothed", "median"), low=("smoothed", "min"), high=("smoothed", "max"),
                          n_seeds=("smoothed", "count"), raw_median=("success", "median"),
                          grid_low=("smoothed_grid", "min"), grid_high=("smoothed_grid", "max"))
    # seeds averaging different numbers of epochs at one epoch have no common grid: NaN, rounded instead
    summary["median_grid"] = 2 * summary["grid_low"].where(summary["grid_low"] == summary["grid_high"])
    summary["median"] = on_grid(summary["median"].to_numpy(), summary["median_grid"].to_numpy())
    success_grid = curves["success_grid"].iloc[0] if len(curves) else float("nan")  # one for the whole table
    summary["raw_median"] = on_grid(summary["raw_median"].to_numpy(), 2 * success_grid)
    summary = summary.drop(columns=["grid_low", "grid_high"])
    return summary.reset_index()


def final_success(curves: pd.DataFrame) -> pd.DataFrame:
    """Per seed: its smoothed curve at its last epoch (``curves``: :func:`smoothed_curves` of complete runs).

    Returns columns task, config, run, seed, final, final_grid (its denominator).
    """
    last = curves.sort_values(["run", "epoch"]).groupby("run", sort=False).tail(1)
    return (last[[*GROUP, "run", "seed", "smoothed", "smoothed_grid"]]
            .rename(columns={"smoothed": "final", "smoothed_grid": "final_grid"}).reset_index(drop=True))


def run_outcomes(curves: pd.DataFrame) -> pd.DataFrame:
    """Per run, in progress or complete (``curves``: :func:`smoothed_curves`): ``final``, its smoothed
    success at its last epoch so far; ``epochs_to_0.5 / 0.9``, the first epoch its smoothed curve
    reaches it, and ``raw_epochs_to_0.5 / 0.9`` its raw test success (NaN: not reached); ``auc``, the mean
    of its raw test success over its epochs so far (exact: on the grid of D times its epochs).

    Returns columns run, then RUN_OUTCOME_COLUMNS, then auc; one row per run in ``curves``.
    """
    by_run = curves.groupby("run", sort=True)
    table = pd.DataFrame({"final": by_run["smoothed"].last()})
    auc_grid = by_run["success_grid"].first() * by_run.size()
    for prefix, column in (("", "smoothed"), ("raw_", "success")):
        for threshold in SUCCESS_THRESHOLDS:
            reached = curves[curves[column] >= threshold].groupby("run")["epoch"].min()
            table[f"{prefix}epochs_to_{threshold:g}"] = reached.reindex(table.index).astype("Int64")
    table[RUN_AUC] = on_grid(by_run["success"].mean().to_numpy(), auc_grid.to_numpy())
    return table.rename_axis("run").reset_index()[["run", *RUN_OUTCOME_COLUMNS, RUN_AUC]]


def run_state(complete: bool, error: str, done: int, total: int) -> str:
    """A run's state: ``complete``, ``failed (epoch N of K): <the first line of its error>`` for a run that stopped
    with an error (``error``: the run table's), else ``in progress (epoch N of K)``."""
    if complete:
        return "complete"
    return f"failed (epoch {done} of {total}): {error}" if error else f"in progress (epoch {done} of {total})"


def run_states(runs: pd.DataFrame) -> pd.Series:
    """Per run (the run table): :func:`run_state`."""
    return pd.Series([run_state(*values) for values in
                      zip(runs["complete"], runs["error"], runs["epochs_done"], runs["total_epochs"])],
                     index=runs.index, dtype=object)


def first_epoch_reaching(epoch: np.ndarray, values: np.ndarray, threshold: float) -> float:
    """The first epoch whose value is >= threshold, NaN if none (arrays of shape (n,), epoch ascending)."""
    reached = np.flatnonzero(np.asarray(values) >= threshold)
    return float(epoch[reached[0]]) if len(reached) else float("nan")


def interquartile_mean(values: np.ndarray, denominator: float = float("nan")) -> float:
    """Mean of the middle 50 % (shape (n,)): scipy.stats.trim_mean(values, 0.25), which drops int(n / 4) values
    at each end; exact (:func:`on_grid`) when every value is a multiple of 1/denominator."""
    from scipy import stats  # scipy.stats takes most of a second to import: only when computing

    values = np.asarray(values, dtype=float)
    kept = len(values) - 2 * int(0.25 * len(values))
    return float(on_grid(stats.trim_mean(values, 0.25), kept * denominator))


def iqm_interval(strata: list[np.ndarray], seed: int = BOOTSTRAP_SEED,
                 resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Percentile-bootstrap interval of the IQM of the pooled values, resampling within each stratum.

    ``strata``: one array of final successes per task (shape (n_seeds_of_task,)). Each
    bootstrap sample redraws every stratum's seeds with replacement, within that stratum;
    a stratum with one seed cannot be redrawn and is held fixed. Returns (low, high), or
    NaNs when no stratum has two seeds. The generator is ``np.random.default_rng(seed)``,
    so the same input always gives the same interval.
    """
    from scipy import stats

    strata = [np.asarray(values, dtype=float) for values in strata]
    resampled = [values for values in strata if len(values) >= 2]
    fixed = np.concatenate([values for values in strata if len(values) < 2] or [np.empty(0)])
    if not resampled:
        return float("nan"), float("nan")

    def pooled_iqm(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
        batch_shape = samples[0].shape[:-1]
        pooled = np.concatenate([*samples, np.broadcast_to(fixed, (*batch_shape, len(fixed)))], axis=-1)
        return stats.trim_mean(pooled, 0.25, axis=-1)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)  # identical values: the interval is a point
        result = stats.bootstrap(tuple(resampled), pooled_iqm, n_resamples=resamples, confidence_level=confidence,
                                 method="percentile", vectorized=True, rng=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def probability_of_improvement(candidate: np.ndarray, baseline: np.ndarray) -> float:
    """P(X > Y) + 0.5 P(X = Y) over all pairs (x in candidate, y in baseline); shapes (n,), (m,)."""
    x = np.asarray(candidate, dtype=float)[:, None]
    y = np.asarray(baseline, dtype=float)[None, :]
    return float(np.mean((x > y) + 0.5 * (x == y)))


def her_baselines(runs: pd.DataFrame) -> dict[tuple[str, str], str]:
    """(task, config) -> the configuration its probability of improvement compares with: the
    HER configuration (constant HER_EPS, HER's reward weights, no MEP) of the same task, learner, K and variant
    (``HER precision=bf16`` for a bf16 run: :func:`analysis.load.variant`). Left out when there is none, or more than
    one (they differ in other settings)."""
    setup = ["task", "learner", "total_epochs", "variant"]
    her = runs[runs["constant_rate"] & (runs["eps"] == HER_EPS) & (runs["lambda_r"] == HER_WEIGHTS[0])
               & (runs["lambda_h"] == HER_WEIGHTS[1]) & ~runs["mep"].astype(bool)]
    her_configs = {key: set(group["config"].astype(str)) for key, group in her.groupby(setup, observed=True)}
    baselines = {}
    for (task, config), group in runs.groupby(GROUP, observed=True):
        setups = set(group[setup].itertuples(index=False, name=None))
        candidates = her_configs.get(setups.pop(), set()) if len(setups) == 1 else set()
        if len(candidates) == 1:
            (baselines[(task, config)],) = candidates
    return baselines


def summary_table(curves: pd.DataFrame, runs: pd.DataFrame, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """One row per (task, config) of the run table; only complete runs enter its statistics.

    ``curves``: :func:`smoothed_curves` of the complete runs; ``runs``: the run table (every run).
    Columns: task, config, total_epochs (K: one per config, its label says it), seeds (complete runs),
    in_progress (its runs left out, neither complete nor failed: the run list names failed runs),
    mu_eps (the mean rate: the run table's, the median over seeds
    for an adaptive schedule; a configuration without complete runs: its fixed schedule's eq. 10, NaN if adaptive),
    final_median (median over seeds of final success), auc (mean over epochs 1..K
    of the median curve), epochs_to_0.5 / epochs_to_0.9 (first epoch the median curve
    reaches it, NaN if never), raw_epochs_to_0.5 / raw_epochs_to_0.9 (the same for the median
    of the raw, unsmoothed success), iqm, iqm_low, iqm_high (IQM of final success and its bootstrap
    interval), p_improve_HER (probability of improvement on the seeds of its
    :func:`her_baselines` HER configuration; NaN without one). A configuration whose runs are all in
    progress has seeds 0 and these statistics empty.
    """
    baselines = her_baselines(runs[runs["complete"]])
    finals, grids = {}, {}
    for key, group in final_success(curves).groupby(GROUP, observed=True):
        finals[key] = group["final"].to_numpy()
        grids[key] = common_grid(group["final_grid"])
    medians = dict(list(median_curves(curves).groupby(GROUP, observed=True)))
    runs = runs.assign(running=~runs["complete"] & (runs["error"] == ""))  # neither complete nor failed
    configs = runs.groupby(GROUP, observed=True).agg(
        total_epochs=("total_epochs", "first"), in_progress=("running", "sum"),
        adaptive=("adaptive", "first"), mu_eps_any=("mu_eps", "median"))
    configs["mu_eps"] = runs[runs["complete"]].groupby(GROUP, observed=True)["mu_eps"].median()
    configs["mu_eps"] = configs["mu_eps"].fillna(configs["mu_eps_any"].where(~configs["adaptive"].astype(bool)))
    rows = []
    for (task, config), setup in configs.iterrows():
        row = {"task": task, "config": config, "total_epochs": int(setup["total_epochs"]), "seeds": 0,
               "in_progress": int(setup["in_progress"]), "mu_eps": float(setup["mu_eps"])}
        if (task, config) in finals:
            final, grid = finals[(task, config)], grids[(task, config)]
            row.update(_complete_statistics(final, grid, medians[(task, config)], seed))
            baseline = baselines.get((task, config))
            row[f"p_improve_{BASELINE}"] = (probability_of_improvement(final, finals[(task, baseline)])
                                            if (task, baseline) in finals else float("nan"))
        rows.append(row)
    table = pd.DataFrame.from_records(rows, columns=SUMMARY_COLUMNS)
    for column in [c for c in SUMMARY_COLUMNS if "epochs_to_" in c]:
        table[column] = table[column].astype("Int64")  # empty when never
    table["config"] = pd.Categorical(table["config"], categories=runs["config"].cat.categories, ordered=True)
    table["task_rank"] = table["task"].map(task_rank)
    return table.sort_values(["task_rank", "config"]).drop(columns="task_rank").reset_index(drop=True)


def _complete_statistics(final: np.ndarray, grid: float, median: pd.DataFrame, seed: int) -> dict:
    """A summary row's statistics of one configuration's complete seeds: ``final`` their final successes (shape
    (seeds,), on the grid 1/``grid``), ``median`` its :func:`median_curves` rows."""
    low, high = iqm_interval([final], seed=seed)
    row = {"seeds": len(final), "final_median": grid_median(final, grid),
           "auc": grid_mean(median["median"].to_numpy(), median["median_grid"].to_numpy())}
    for threshold in SUCCESS_THRESHOLDS:
        for prefix, column in (("", "median"), ("raw_", "raw_median")):
            row[f"{prefix}epochs_to_{threshold:g}"] = first_epoch_reaching(
                median["epoch"].to_numpy(), median[column].to_numpy(), threshold)
    return row | {"iqm": interquartile_mean(final, grid), "iqm_low": low, "iqm_high": high}


def aggregate_table(curves: pd.DataFrame, runs: pd.DataFrame, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """One row per config, across the tasks it was run on (a config's label names its K: runs of different K are
    never pooled).

    Columns: config, total_epochs (K), tasks, seeds, iqm (IQM of the pooled final successes), iqm_low,
    iqm_high (bootstrap stratified by task), p_improve_HER (mean over the tasks where the
    config has a :func:`her_baselines` HER configuration of the per-task probability).
    ``curves`` and ``runs`` as for :func:`summary_table`: only complete runs enter.
    """
    baselines = her_baselines(runs[runs["complete"]])
    finals = final_success(curves)
    per_task = {key: group["final"].to_numpy() for key, group in finals.groupby(GROUP, observed=True)}
    grids = finals.groupby("config", observed=True)["final_grid"].agg(common_grid)
    epochs = runs.groupby("config", observed=True)["total_epochs"].first()
    rows = []
    for config, group in finals.groupby("config", observed=True, sort=True):
        tasks = list(dict.fromkeys(group["task"]))
        strata = [per_task[(task, config)] for task in tasks]
        low, high = iqm_interval(strata, seed=seed)
        improvements = [probability_of_improvement(per_task[(task, config)], per_task[(task, baselines[(task, config)])])
                        for task in tasks if (task, baselines.get((task, config))) in per_task]
        rows.append({"config": config, "total_epochs": int(epochs[config]), "tasks": len(tasks), "seeds": int(sum(len(s) for s in strata)),
                     "iqm": interquartile_mean(np.concatenate(strata), grids[config]), "iqm_low": low, "iqm_high": high,
                     f"p_improve_{BASELINE}": float(np.mean(improvements)) if improvements else float("nan")})
    return pd.DataFrame.from_records(rows, columns=["config", "total_epochs", "tasks", "seeds", "iqm", "iqm_low", "iqm_high",
                                                    f"p_improve_{BASELINE}"])


def _outcomes_higher_is_better(runs: pd.DataFrame, outcomes: pd.DataFrame,
                               columns: list[str] = RUN_OUTCOME_COLUMNS) -> dict[tuple[str, str], tuple]:
    """(task, config) -> ((learner, K), its complete seeds' ``columns`` of ``outcomes``, shape (len(columns),
    n_seeds)), each signed so that higher is better: success (final, auc) as is, epochs to a threshold negated,
    ``never`` counted as K + 1 epochs. Only configurations with at least two complete seeds (a configuration's
    label names its learner and K, so all its runs share them)."""
    complete = runs.loc[runs["complete"], [*GROUP, "run", "learner", "total_epochs"]].merge(outcomes, on="run")
    never = complete["total_epochs"].astype(float) + 1.0
    values = np.column_stack([-complete[column].astype(float).fillna(never).to_numpy() if "epochs_to_" in column
                              else complete[column].to_numpy(float) for column in columns])  # (n_runs, columns)
    grouped = complete.groupby(GROUP, observed=True)
    setups = grouped[["learner", "total_epochs"]].first()
    return {key: (tuple(setups.loc[key]), values[rows].T) for key, rows in grouped.indices.items() if len(rows) >= 2}


def _mean_difference(x: np.ndarray, y: np.ndarray, axis: int) -> np.ndarray:
    """mean(x) - mean(y) along ``axis``, rounded to STATISTIC_DECIMALS: sides with equal means (the same
    seeds' values summed in another order) differ by float noise that would break their tie."""
    return np.round(x.mean(axis=axis) - y.mean(axis=axis), STATISTIC_DECIMALS)


def permutation_p_values(x: np.ndarray, y: np.ndarray, seed: int = BOOTSTRAP_SEED) -> tuple[np.ndarray, np.ndarray]:
    """Permutation tests of the difference of the means, one per row: x (rows, n) and y (rows, m) ->
    (p_greater, p_less), each (rows,): the share of the splits of each row's n + m pooled values into n and m
    whose :func:`_mean_difference` is >= (<=) the observed one, the observed split included.

    Exact, every one of the C(n + m, n) splits, when there are at most EXACT_SPLITS: only the n values' sum
    varies between splits, so a batch of splits is one matrix product with their 0/1 membership matrix
    (scipy.stats.permutation_test enumerates the same splits, with the same p-values, 40x slower: 3.4 s against
    0.08 s for seven outcomes at 10 against 10). Beyond that, scipy.stats.permutation_test with PERMUTATION_RESAMPLES random splits drawn from ``seed``.
    A two-sided p is min(1, 2 min(p_greater, p_less)), as scipy's.
    """
    n, m = x.shape[-1], y.shape[-1]
    splits = math.comb(n + m, n)
    if splits > EXACT_SPLITS:
        from scipy import stats

        return tuple(stats.permutation_test((x, y), _mean_difference, permutation_type="independent",
                                            vectorized=True, alternative=alternative, axis=-1,
                                            n_resamples=PERMUTATION_RESAMPLES, batch=PERMUTATION_BATCH,
                                            rng=np.random.default_rng(seed)).pvalue
                     for alternative in ("greater", "less"))
    pooled = np.concatenate([x, y], axis=-1)  # (rows, n + m)
    total = pooled.sum(axis=-1, keepdims=True)
    at_least, at_most, observed = 0, 0, None
    memberships = _split_memberships(n + m, n)  # (splits, n + m), the observed split first
    for start in range(0, splits, SPLITS_BATCH):
        sums = pooled @ memberships[start:start + SPLITS_BATCH].T.astype(float)  # (rows, batch): the n values' sums
        null = np.round(sums / n - (total - sums) / m, STATISTIC_DECIMALS)
        observed = null[:, :1] if observed is None else observed
        at_least = at_least + (null >= observed).sum(axis=-1)
        at_most = at_most + (null <= observed).sum(axis=-1)
    return at_least / splits, at_most / splits


@functools.lru_cache(maxsize=4)
def _split_memberships(size: int, chosen: int) -> np.ndarray:
    """Every way to choose ``chosen`` of ``size`` positions, in itertools.combinations order (first: the first
    ``chosen``), as 0/1 rows: bool (C(size, chosen), size). Built by the recurrence that splits on position 0
    (with it: every choice of chosen - 1 of the rest; without: of chosen), ~20x faster than itertools."""
    tables = {0: np.zeros((1, 0), bool)}  # chosen of the last 0 positions -> its table; then of the last 1, 2, ...
    for known in range(1, size + 1):
        tables = {count: np.vstack([np.hstack([np.full((len(rest), 1), first), rest])
                                    for first, rest in ((True, tables.get(count - 1)), (False, tables.get(count)))
                                    if rest is not None])
                  for count in range(max(0, chosen - size + known), min(known, chosen) + 1)}
    memberships = tables[chosen]
    memberships.flags.writeable = False
    return memberships


def shift_interval(x: np.ndarray, y: np.ndarray, alpha: float, tolerance: float) -> tuple[float, float]:
    """The shifts d of x's values that the two-sided permutation test of x - d against y does not separate at
    ``alpha`` (p >= alpha): the (1 - alpha) interval of the difference of the means by inverting the test,
    (low, high) to ``tolerance``. x (n,), y (m,); a shift outside it is one these seeds would have detected.
    Each end by bisection: the test's p falls as d moves away from the observed difference."""
    def not_separated(shift: float) -> bool:
        greater, less = permutation_p_values((x - shift)[None], y[None])
        return min(1.0, 2 * min(greater[0], less[0])) >= alpha

    observed = float(x.mean() - y.mean())
    reach = 2 * (float(np.ptp(np.concatenate([x, y]))) + abs(observed)) + 1  # beyond it every split lies on one side

    def edge(outside: float) -> float:
        inside = observed
        while abs(outside - inside) > tolerance:
            middle = (inside + outside) / 2
            inside, outside = (middle, outside) if not_separated(middle) else (inside, middle)
        return inside
    return edge(observed - reach), edge(observed + reach)


def smallest_p_value(seeds: int, versus_seeds: int, two_sided: bool = False) -> float:
    """The smallest p :func:`permutation_p_values` can give, the test's power: one split (two, two-sided) of
    all C(seeds + versus_seeds, seeds) when exact, else of the PERMUTATION_RESAMPLES random ones + the observed."""
    splits = math.comb(seeds + versus_seeds, seeds)
    return (2 if two_sided else 1) / (splits if splits <= EXACT_SPLITS else PERMUTATION_RESAMPLES + 1)


def permutation_tests(runs: pd.DataFrame, outcomes: pd.DataFrame, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """One-sided permutation tests between the complete seeds of every ordered pair (config, versus) of
    configurations of a task with the same learner and K, each with at least two complete seeds.

    ``runs``: the run table; ``outcomes``: :func:`run_outcomes`. Columns PERMUTATION_COLUMNS: seeds /
    versus_seeds count each side's seeds; p_<outcome> is the p-value of "config does better than versus"
    on that outcome (higher final; fewer epochs to a threshold, ``never`` counted as K + 1) for the
    difference of the means over seeds: :func:`permutation_p_values`, exact up to EXACT_SPLITS splits.
    """
    signed = _outcomes_higher_is_better(runs, outcomes)
    by_sizes = defaultdict(list)  # pairs with the same seed counts share one vectorised test
    for config, (setup, values) in signed.items():
        for versus, (versus_setup, versus_values) in signed.items():
            if config != versus and config[0] == versus[0] and setup == versus_setup:
                by_sizes[(values.shape[1], versus_values.shape[1])].append((config, versus))
    p_columns = [f"p_{outcome}" for outcome in RUN_OUTCOME_COLUMNS]
    rows = []
    for (seeds, versus_seeds), pairs in by_sizes.items():
        x = np.concatenate([signed[config][1] for config, _ in pairs])  # (5 * pairs, seeds)
        y = np.concatenate([signed[versus][1] for _, versus in pairs])  # (5 * pairs, versus_seeds)
        p_greater, _ = permutation_p_values(x, y, seed)
        for ((task, config), (_, versus)), p_values in zip(pairs, p_greater.reshape(len(pairs), -1)):
            rows.append({"task": task, "config": config, "versus": versus, "seeds": seeds,
                         "versus_seeds": versus_seeds, **dict(zip(p_columns, p_values.tolist()))})
    table = pd.DataFrame.from_records(rows, columns=PERMUTATION_COLUMNS)
    ranks = {"task": task_rank, "config": _config_rank(runs), "versus": _config_rank(runs)}
    return table.sort_values(list(ranks), key=lambda column: column.map(ranks[column.name])).reset_index(drop=True)


def equal_mu_pairs(runs: pd.DataFrame) -> pd.DataFrame:
    """Every pair of configurations of a task at the same mean rate: one a schedule that is neither constant nor
    adaptive, the other a constant rate (the control), with the same learner, K, reward weights and MEP, both
    with at least two complete seeds, their mu_eps within EQUAL_MU_TOLERANCE. Columns task, config, versus
    (the constant), mu_eps (the decay's); in configuration order."""
    setup = ["task", "learner", "total_epochs", "lambda_r", "lambda_h", "mep"]
    complete = runs[runs["complete"]]
    configs = complete.groupby(GROUP, observed=True).agg(
        **{name: (name, "first") for name in [*setup[1:], "constant_rate", "adaptive", "mu_eps"]},
        seeds=("run", "size")).reset_index()
    configs = configs[(configs["seeds"] >= 2) & ~configs["adaptive"].astype(bool)]
    constant = configs["constant_rate"].astype(bool)
    pairs = configs[~constant].merge(configs[constant], on=setup, suffixes=("", "_versus"))
    pairs = pairs[(pairs["mu_eps"] - pairs["mu_eps_versus"]).abs() < EQUAL_MU_TOLERANCE]
    pairs = pairs.rename(columns={"config_versus": "versus"})[["task", "config", "versus", "mu_eps"]]
    ranks = {"task": task_rank, "config": _config_rank(runs), "versus": _config_rank(runs)}
    return pairs.sort_values(list(ranks), key=lambda column: column.map(ranks[column.name])).reset_index(drop=True)


def _config_rank(runs: pd.DataFrame):
    """config label -> its rank in the configurations' order (the run table's categories)."""
    order = {config: rank for rank, config in enumerate(runs["config"].cat.categories)}
    return order.get


def _outcome_grids(curves: pd.DataFrame) -> pd.DataFrame:
    """Per run (index): the denominator of each EQUAL_MU_OUTCOMES value (epochs: 1; NaN: no grid)."""
    by_run = curves.groupby("run", sort=True)
    grids = pd.DataFrame({"final": by_run["smoothed_grid"].last(),
                          RUN_AUC: by_run["success_grid"].first() * by_run.size()})
    return grids.assign(**{column: 1.0 for column in RUN_OUTCOME_COLUMNS[1:]})


def variant_pairs(runs: pd.DataFrame) -> pd.DataFrame:
    """Every configuration run at a variant (settings added after the first runs, at other than their earlier
    value: ``precision=bf16``, ``update=fast``; :func:`analysis.load.variant`) paired with the same configuration
    at the defaults (the same ``defaults_id``), both with at least two complete seeds. Columns task, config,
    versus (the configuration at the defaults), variant; in configuration order."""
    complete = runs[runs["complete"]]
    configs = complete.groupby(GROUP, observed=True).agg(variant=("variant", "first"),
                                                          defaults_id=("defaults_id", "first"),
                                                          seeds=("run", "size")).reset_index()
    configs = configs[configs["seeds"] >= 2]
    at_defaults = configs["variant"] == ""
    pairs = configs[~at_defaults].merge(configs[at_defaults], on=["task", "defaults_id"], suffixes=("", "_versus"))
    pairs = pairs.rename(columns={"config_versus": "versus"})[["task", "config", "versus", "variant"]]
    ranks = {"task": task_rank, "config": _config_rank(runs), "versus": _config_rank(runs)}
    return pairs.sort_values(list(ranks), key=lambda column: column.map(ranks[column.name])).reset_index(drop=True)


def equal_mu_tests(runs: pd.DataFrame, outcomes: pd.DataFrame, curves: pd.DataFrame,
                   seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """Decay against constant rate at the same mu_eps (:func:`equal_mu_pairs`): :func:`two_way_tests`, columns
    EQUAL_MU_COLUMNS."""
    return two_way_tests(equal_mu_pairs(runs), EQUAL_MU_COLUMNS, runs, outcomes, curves, seed)


def variant_tests(runs: pd.DataFrame, outcomes: pd.DataFrame, curves: pd.DataFrame,
                  seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """Each variant against its configuration at the defaults (:func:`variant_pairs`; e.g. ``HER precision=bf16``
    against ``HER``): :func:`two_way_tests`, columns VARIANT_COLUMNS."""
    return two_way_tests(variant_pairs(runs), VARIANT_COLUMNS, runs, outcomes, curves, seed)


def two_way_tests(pairs: pd.DataFrame, columns: list[str], runs: pd.DataFrame, outcomes: pd.DataFrame,
                  curves: pd.DataFrame, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """Both one-sided permutation tests of each pair (``pairs``: task, config, versus, then what ``columns``
    keeps of the pair before TWO_WAY_COLUMNS), one row per outcome (EQUAL_MU_OUTCOMES). config_mean /
    versus_mean: each side's mean over its complete seeds (exact; ``never`` counted as K + 1 epochs);
    p_config_better / p_versus_better: the two one-sided p-values (as :func:`permutation_tests`: difference of
    the means, exact up to EXACT_SPLITS splits); splits, C(seeds + versus_seeds, seeds); smallest_p,
    the smallest p either can be: :func:`smallest_p_value`.
    """
    signed = _outcomes_higher_is_better(runs, outcomes, EQUAL_MU_OUTCOMES)
    grids = _outcome_grids(curves).loc[:, EQUAL_MU_OUTCOMES]
    runs_of = runs[runs["complete"]].groupby(GROUP, observed=True)["run"].apply(list)
    sign = np.array([-1.0 if "epochs_to_" in outcome else 1.0 for outcome in EQUAL_MU_OUTCOMES])
    pair_columns = columns[:len(columns) - len(TWO_WAY_COLUMNS)]
    rows = []
    for pair in pairs[pair_columns].to_dict("records"):
        x, y = signed[(pair["task"], pair["config"])][1], signed[(pair["task"], pair["versus"])][1]
        p_values = permutation_p_values(x, y, seed)
        splits = math.comb(x.shape[1] + y.shape[1], x.shape[1])
        smallest = smallest_p_value(x.shape[1], y.shape[1])
        means = [on_grid((sign[:, None] * values).mean(axis=1),
                         values.shape[1] * grids.loc[runs_of[(pair["task"], config)]].agg(common_grid).to_numpy())
                 for config, values in ((pair["config"], x), (pair["versus"], y))]
        for index, outcome in enumerate(EQUAL_MU_OUTCOMES):
            rows.append({**pair, "seeds": x.shape[1], "versus_seeds": y.shape[1], "outcome": outcome,
                         "config_mean": means[0][index], "versus_mean": means[1][index],
                         "p_config_better": p_values[0][index], "p_versus_better": p_values[1][index],
                         "splits": splits, "smallest_p": smallest})
    return pd.DataFrame.from_records(rows, columns=columns)


def composition(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): the median over seeds of each minibatch share (SHARE_COLUMNS),
    rescaled so the three sum to 1 (they stack to the whole minibatch), and n_seeds."""
    grouped = epochs.groupby([*GROUP, "epoch"], observed=True)
    shares = grouped[list(SHARE_COLUMNS)].median()
    total = shares.sum(axis=1).replace(0.0, np.nan)
    shares = shares.div(total, axis=0)
    shares["n_seeds"] = grouped.size()
    return shares.reset_index()


def composition_versus_paper(shares: pd.DataFrame, runs: pd.DataFrame, task: str = PAPER_COMPOSITION_TASK,
                             epoch: int = PAPER_COMPOSITION_EPOCH) -> pd.DataFrame:
    """The paper's Fig. 2 composition (HER on FetchPush at epoch 150) beside this data's.

    ``shares``: :func:`composition`; ``runs``: the run table. One row for the paper, then one per
    HER configuration of ``task`` (constant HER_EPS, HER's reward weights, no MEP, DDPG) with
    seeds at ``epoch``. Columns: source, config, seeds (that reached the epoch), epoch, then
    share_real_success, share_hindsight, share_real_failure (the paper's order). Empty when no
    such run reached the epoch.
    """
    her = runs[(runs["task"] == task) & runs["constant_rate"] & (runs["eps"] == HER_EPS)
               & (runs["lambda_r"] == HER_WEIGHTS[0]) & (runs["lambda_h"] == HER_WEIGHTS[1]) & ~runs["mep"]
               & (runs["learner"] == PAPER_LEARNER)]
    ours = shares[(shares["task"] == task) & (shares["epoch"] == epoch) & shares["config"].isin(her["config"])]
    columns = ["source", "config", "seeds", "epoch", *PAPER_COMPOSITION]
    if ours.empty:
        return pd.DataFrame(columns=columns)
    paper = pd.DataFrame([{"source": "paper (Fig. 2)", "config": BASELINE, "seeds": pd.NA, "epoch": epoch,
                           **PAPER_COMPOSITION}])
    ours = ours.assign(source="hersd", config=ours["config"].astype(str), seeds=ours["n_seeds"])
    table = pd.concat([paper, ours], ignore_index=True)[columns]
    return table.astype({"seeds": "Int64", "epoch": "int64"})


def mean_q(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): q_mean averaged over seeds (column q_mean) and n_seeds."""
    grouped = epochs.groupby([*GROUP, "epoch"], observed=True)["q_mean"]
    return grouped.agg(q_mean="mean", n_seeds="count").reset_index()


SCHEDULE_CURVE_COLUMNS = ["line", "configs", "schedule", "constant_rate", "adaptive", "eps_setting", "beta1", "beta2",
                          "total_epochs", "epoch", "eps"]


def schedule_curves(runs: pd.DataFrame, epochs: pd.DataFrame) -> pd.DataFrame:
    """The per-epoch rates eps(k), k = 1..K, of every schedule of the runs, as their logs recorded them: one line
    per distinct schedule and K that does not adapt (the configurations sharing it, e.g. HER and ARCHER, share the
    line; its logged rates, median over its runs at each epoch, and where none of them has logged an epoch yet, its
    class's rates when the class gives the logged ones: :func:`fixed_rates`), and one per task and configuration
    whose schedule adapts (the rates its runs realised: the logs' relabel_rate, median over seeds at each epoch
    they reached).

    ``runs`` / ``epochs``: the tables of :mod:`analysis.load`. Returns columns SCHEDULE_CURVE_COLUMNS: line (its
    legend label: :func:`line_label`, an adaptive line's task added), configs (the first configuration's
    label: its style), the schedule's kind and settings, total_epochs, epoch, eps; in the registry's order of kinds,
    then by beta1, beta2, eps, K.
    """
    fixed, frames = runs[~runs["adaptive"].astype(bool)], []
    for (record, total), group in fixed.groupby(["schedule_record", "total_epochs"], sort=False):
        configs = [str(config) for config in group["config"].drop_duplicates().sort_values()]  # config order
        logged = epochs[epochs["run"].isin(group["run"])].groupby("epoch")["relabel_rate"].median()
        epoch, eps = fixed_rates(record, int(total), logged)
        frames.append(_schedule_line(group.iloc[0], line_label(configs, group.iloc[0]), configs[0], epoch, eps))
    adaptive = epochs[epochs["adaptive"].astype(bool)]
    for (task, config), group in adaptive.groupby(["task", "config"], observed=True):
        rates = group.groupby("epoch")["relabel_rate"].median()
        line = f"{config} on {task} (realised, median over seeds)"
        frames.append(_schedule_line(group.iloc[0], line, str(config), rates.index.to_numpy(), rates.to_numpy()))
    if not frames:
        return pd.DataFrame(columns=SCHEDULE_CURVE_COLUMNS)
    curves = pd.concat(frames, ignore_index=True)
    curves["order"] = curves["schedule"].map(schedule_rank)
    curves = curves.sort_values(["order", "adaptive", "beta1", "beta2", "eps_setting", "total_epochs", "line", "epoch"],
                                kind="stable")
    return curves[SCHEDULE_CURVE_COLUMNS].reset_index(drop=True)


LINE_CONFIGS = 3  # a schedule shared by more configurations than this is named by its label, not theirs


def line_label(configs: list[str], run: pd.Series) -> str:
    """Fig. 1's legend entry of a schedule its configurations share: their labels, or, for more than
    LINE_CONFIGS (learner variants of one schedule, say), the schedule's label and how many share it."""
    if len(configs) <= LINE_CONFIGS:
        return ", ".join(configs)
    return f"{run['schedule_label']} ({len(configs)} configurations: {configs[0]} and others)"


def fixed_rates(record: str, total_epochs: int, logged: pd.Series) -> tuple[np.ndarray, np.ndarray]:
    """(epoch, eps) of a schedule that does not adapt: the ``logged`` rates (epoch -> rate, shape (n,)), and for the
    epochs 1..K none of its runs has logged yet, the rates of its class (``record``: the schedule's record as JSON)
    when that class can be imported, takes the logged settings (:func:`analysis.load.logged_schedule`) and gives
    every logged rate; else the logged epochs alone."""
    epoch, eps = logged.index.to_numpy(dtype=int), logged.to_numpy(dtype=float)
    if len(epoch) >= total_epochs:
        return epoch, eps
    try:
        schedule, unfit = logged_schedule(json.loads(record))
        rates = None if unfit else schedule.epoch_rates(total_epochs)
    except Exception:  # noqa: BLE001 - a class whose rate raises: the logged rates alone
        return epoch, eps
    if rates is None or not np.allclose(rates[epoch - 1], eps, rtol=0.0, atol=RATE_TOLERANCE):
        return epoch, eps
    rates[epoch - 1] = eps
    return np.arange(1, total_epochs + 1), rates


def _schedule_line(run: pd.Series, line: str, config: str, epoch: np.ndarray, eps: np.ndarray) -> pd.DataFrame:
    """One line of :func:`schedule_curves`: its rates eps (shape (n,)) at ``epoch`` (shape (n,)), the schedule's
    settings from ``run`` (a row of the run table)."""
    return pd.DataFrame({"line": line, "configs": config, "schedule": run["schedule"],
                         "constant_rate": bool(run["constant_rate"]), "adaptive": bool(run["adaptive"]),
                         "eps_setting": run["eps"], "beta1": run["beta1"], "beta2": run["beta2"],
                         "total_epochs": int(run["total_epochs"]), "epoch": epoch, "eps": eps})


def mean_rate_outcomes(runs: pd.DataFrame, outcomes: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Fig. 12's data: each complete seed's outcome and mean rate, and each configuration's summary of them.

    ``runs``: the run table; ``outcomes``: :func:`run_outcomes`. Returns (seeds, arms). seeds: one row per
    complete run, columns task, config, seed, kind (``constant``, ``fixed`` or ``adaptive``: its schedule),
    total_epochs, mu_eps (the run table's: eq. 10 exact, the realised mean for an adaptive schedule),
    raw_auc, epochs_to_0.5 (``never`` as K + 1), never (bool). arms: one row per (task, config), columns task,
    config, kind, seeds, mu_eps / mu_low / mu_high (median, min, max over seeds), and for raw_auc and
    epochs_to_0.5 the median, ``<outcome>_low`` and ``<outcome>_high`` (min, max) over seeds; configuration order.
    """
    complete = runs.loc[runs["complete"], [*GROUP, "run", "seed", "constant_rate", "adaptive", "total_epochs",
                                           "mu_eps"]]
    seeds = complete.merge(outcomes[["run", RUN_AUC, "epochs_to_0.5"]], on="run")
    kinds = np.where(seeds["constant_rate"].astype(bool), "constant rate",
                     np.where(seeds["adaptive"].astype(bool), "adaptive", "fixed"))
    reached = seeds["epochs_to_0.5"].astype(float)
    seeds = seeds.assign(kind=kinds, never=reached.isna(), **{"epochs_to_0.5": reached.fillna(seeds["total_epochs"] + 1.0)})
    seeds = seeds[[*GROUP, "seed", "kind", "total_epochs", "mu_eps", RUN_AUC, "epochs_to_0.5", "never"]]
    grouped = seeds.groupby(GROUP, observed=True, sort=True)
    arms = grouped.agg(kind=("kind", "first"), seeds=("seed", "size"), mu_eps=("mu_eps", "median"),
                       mu_low=("mu_eps", "min"), mu_high=("mu_eps", "max"),
                       **{f"{outcome}{suffix}": (outcome, statistic) for outcome in (RUN_AUC, "epochs_to_0.5")
                          for suffix, statistic in (("", "median"), ("_low", "min"), ("_high", "max"))})
    return seeds.reset_index(drop=True), arms.reset_index()


@dataclass
class Analysis:
    """Everything the figures and the report draw from.

    runs / epochs: the tables of :mod:`analysis.load` (every run); curves: :func:`smoothed_curves`
    of every run (``complete`` False: in progress, drawn on its own); the rest from complete
    runs only: medians: :func:`median_curves`; summary / aggregate: the two tables; shares:
    :func:`composition`; q_means: :func:`mean_q`; composition_vs_paper:
    :func:`composition_versus_paper`; window: the smoothing window in epochs; outcomes:
    :func:`run_outcomes` of every run (each run's own numbers, the run list's); tests:
    :func:`permutation_tests` between the configurations of each task; equal_mu_tests: :func:`equal_mu_tests`;
    variant_tests: :func:`variant_tests`.
    """

    runs: pd.DataFrame
    epochs: pd.DataFrame
    curves: pd.DataFrame
    medians: pd.DataFrame
    summary: pd.DataFrame
    aggregate: pd.DataFrame
    shares: pd.DataFrame
    q_means: pd.DataFrame
    composition_vs_paper: pd.DataFrame
    window: int
    outcomes: pd.DataFrame
    tests: pd.DataFrame
    equal_mu_tests: pd.DataFrame
    variant_tests: pd.DataFrame


def analyse(runs: pd.DataFrame, epochs: pd.DataFrame, window: int, seed: int = BOOTSTRAP_SEED) -> Analysis:
    """Compute every table the report needs; runs in progress enter none of them (only ``curves``)."""
    return with_statistics(analyse_curves(runs, epochs, window), seed=seed)


def analyse_curves(runs: pd.DataFrame, epochs: pd.DataFrame, window: int) -> Analysis:
    """What the figures draw (curves, medians, shares, q_means, outcomes); the statistics tables (summary,
    aggregate, composition_vs_paper, tests, equal_mu_tests, variant_tests) empty until :func:`with_statistics`
    (the report computes them while worker processes draw)."""
    curves = smoothed_curves(epochs, window)
    complete_epochs = epochs[epochs["complete"]]
    empty = pd.DataFrame()
    return Analysis(runs=runs, epochs=epochs, curves=curves, medians=median_curves(curves[curves["complete"]]),
                    summary=empty, aggregate=empty, shares=composition(complete_epochs),
                    q_means=mean_q(complete_epochs), composition_vs_paper=empty, window=window,
                    outcomes=run_outcomes(curves), tests=empty, equal_mu_tests=empty, variant_tests=empty)


def with_statistics(analysis: Analysis, seed: int = BOOTSTRAP_SEED) -> Analysis:
    """``analysis`` (:func:`analyse_curves`) with its statistics tables computed."""
    runs, curves, outcomes = analysis.runs, analysis.curves, analysis.outcomes
    complete_curves = curves[curves["complete"]]
    return replace(analysis, summary=summary_table(complete_curves, runs, seed=seed),
                   aggregate=aggregate_table(complete_curves, runs, seed=seed),
                   composition_vs_paper=composition_versus_paper(analysis.shares, runs[runs["complete"]]),
                   tests=permutation_tests(runs, outcomes, seed=seed),
                   equal_mu_tests=equal_mu_tests(runs, outcomes, curves, seed=seed),
                   variant_tests=variant_tests(runs, outcomes, curves, seed=seed))
