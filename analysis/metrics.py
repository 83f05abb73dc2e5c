"""Metrics on the tidy tables of :mod:`analysis.load`: pure functions, no drawing.

Vocabulary (each formula is restated in docs/ANALYSIS.md):

- *smoothed curve* of a run: trailing moving average of test success over ``window``
  epochs; the first epochs average the epochs so far (min_periods=1).
- *median curve* of a (task, config): at each epoch, the median over the seeds that reached
  that epoch of their smoothed curves; ``low`` / ``high`` are the min / max over those seeds.
- *horizon* of a (task, config): the last epoch every one of its seeds completed.
- *final success* of a seed: its smoothed curve at the horizon.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.load import schedule_label
from hersd.config import ScheduleConfig
from hersd.schedules import FIXED_KINDS, SCHEDULE_KINDS, mean_rate_approx, mean_rate_exact, relabel_rate
from hersd.tasks import task_rank

GROUP = ["task", "config"]
SUCCESS_THRESHOLDS = (0.5, 0.9)
BASELINE = "HER"
BOOTSTRAP_SEED = 0
BOOTSTRAP_RESAMPLES = 2000
CONFIDENCE = 0.95
SHARE_COLUMNS = ("share_real_success", "share_real_failure", "share_hindsight")


def smoothed_curves(epochs: pd.DataFrame, window: int) -> pd.DataFrame:
    """Per run, the trailing mean of test_success over ``window`` epochs (min_periods=1).

    ``epochs``: the tidy epoch table. Returns columns task, config, run, seed, epoch,
    success (raw), smoothed; sorted by run then epoch.
    """
    if window < 1:
        raise ValueError(f"the smoothing window must be >= 1 epoch, got {window}")
    curves = epochs[["task", "config", "run", "seed", "epoch", "test_success"]].sort_values(["run", "epoch"])
    curves = curves.rename(columns={"test_success": "success"}).reset_index(drop=True)
    rolling = curves.groupby("run", sort=False)["success"].rolling(window, min_periods=1).mean()
    curves["smoothed"] = rolling.to_numpy()
    return curves


def median_curves(curves: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): median, low (min), high (max) of ``smoothed`` over seeds, n_seeds."""
    grouped = curves.groupby([*GROUP, "epoch"], observed=True)["smoothed"]
    summary = grouped.agg(median="median", low="min", high="max", n_seeds="count")
    return summary.reset_index()


def horizons(curves: pd.DataFrame) -> pd.Series:
    """Per (task, config): the last epoch that every seed completed (min over runs of max epoch)."""
    return curves.groupby(["task", "config", "run"], observed=True)["epoch"].max().groupby(level=GROUP, observed=True).min()


def final_success(curves: pd.DataFrame) -> pd.DataFrame:
    """Per seed: the smoothed curve at its (task, config)'s horizon.

    Returns columns task, config, run, seed, final.
    """
    horizon = horizons(curves).rename("horizon").reset_index()
    at_horizon = curves.merge(horizon, on=GROUP)
    at_horizon = at_horizon[at_horizon["epoch"] == at_horizon["horizon"]]
    return at_horizon[[*GROUP, "run", "seed", "smoothed"]].rename(columns={"smoothed": "final"}).reset_index(drop=True)


def first_epoch_reaching(epoch: np.ndarray, values: np.ndarray, threshold: float) -> float:
    """The first epoch whose value is >= threshold, NaN if none (arrays of shape (n,), epoch ascending)."""
    reached = np.flatnonzero(np.asarray(values) >= threshold)
    return float(epoch[reached[0]]) if len(reached) else float("nan")


def interquartile_mean(values: np.ndarray) -> float:
    """Mean of the middle 50 %: scipy.stats.trim_mean(values, 0.25)."""
    return float(stats.trim_mean(np.asarray(values, dtype=float), 0.25))


def iqm_interval(strata: list[np.ndarray], seed: int = BOOTSTRAP_SEED,
                 resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Percentile-bootstrap interval of the IQM of the pooled values, resampling within each stratum.

    ``strata``: one array of final successes per task (shape (n_seeds_of_task,)). Each
    bootstrap sample redraws every stratum's seeds with replacement, within that stratum;
    a stratum with one seed cannot be redrawn and is held fixed. Returns (low, high), or
    NaNs when no stratum has two seeds. The generator is ``np.random.default_rng(seed)``,
    so the same input always gives the same interval.
    """
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


def summary_table(curves: pd.DataFrame, runs: pd.DataFrame, baseline: str = BASELINE,
                  seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """One row per (task, config).

    Columns: task, config, seeds, complete (runs that finished), horizon, final_median
    (median over seeds of final success), auc (mean over epochs 1..horizon of the median
    curve), epochs_to_0.5 / epochs_to_0.9 (first epoch the median curve reaches it, NaN if
    never), iqm, iqm_low, iqm_high (IQM of final success and its bootstrap interval),
    p_improve_<baseline> (probability of improvement on the baseline's seeds; NaN if the
    task has no baseline).
    """
    medians = median_curves(curves)
    finals = final_success(curves)
    horizon = horizons(curves)
    complete = runs.groupby(GROUP, observed=True)["complete"].sum()
    baseline_finals = {task: group["final"].to_numpy()
                       for (task, config), group in finals.groupby(GROUP, observed=True) if config == baseline}
    rows = []
    for (task, config), median in medians.groupby(GROUP, observed=True, sort=True):
        last = horizon[(task, config)]
        median = median[median["epoch"] <= last]
        final = finals[(finals["task"] == task) & (finals["config"] == config)]["final"].to_numpy()
        low, high = iqm_interval([final], seed=seed)
        row = {
            "task": task, "config": config, "seeds": len(final), "complete": int(complete[(task, config)]),
            "horizon": int(last), "final_median": float(np.median(final)),
            "auc": float(median["median"].mean()),
        }
        for threshold in SUCCESS_THRESHOLDS:
            row[f"epochs_to_{threshold:g}"] = first_epoch_reaching(median["epoch"].to_numpy(),
                                                                  median["median"].to_numpy(), threshold)
        row.update(iqm=interquartile_mean(final), iqm_low=low, iqm_high=high)
        row[f"p_improve_{baseline}"] = (probability_of_improvement(final, baseline_finals[task])
                                        if task in baseline_finals else float("nan"))
        rows.append(row)
    table = pd.DataFrame.from_records(rows)
    for threshold in SUCCESS_THRESHOLDS:
        table[f"epochs_to_{threshold:g}"] = table[f"epochs_to_{threshold:g}"].astype("Int64")  # empty when never
    table["config"] = pd.Categorical(table["config"], categories=curves["config"].cat.categories, ordered=True)
    table["task_rank"] = table["task"].map(task_rank)
    return table.sort_values(["task_rank", "config"]).drop(columns="task_rank").reset_index(drop=True)


def aggregate_table(curves: pd.DataFrame, baseline: str = BASELINE, seed: int = BOOTSTRAP_SEED) -> pd.DataFrame:
    """One row per config, across the tasks it was run on.

    Columns: config, tasks, seeds, iqm (IQM of the pooled final successes), iqm_low,
    iqm_high (bootstrap stratified by task), p_improve_<baseline> (mean over the tasks
    that have both the config and the baseline of the per-task probability).
    """
    finals = final_success(curves)
    per_task = {key: group["final"].to_numpy() for key, group in finals.groupby(GROUP, observed=True)}
    rows = []
    for config, group in finals.groupby("config", observed=True, sort=True):
        tasks = list(dict.fromkeys(group["task"]))
        strata = [per_task[(task, config)] for task in tasks]
        low, high = iqm_interval(strata, seed=seed)
        improvements = [probability_of_improvement(per_task[(task, config)], per_task[(task, baseline)])
                        for task in tasks if (task, baseline) in per_task]
        rows.append({"config": config, "tasks": len(tasks), "seeds": int(sum(len(s) for s in strata)),
                     "iqm": interquartile_mean(np.concatenate(strata)), "iqm_low": low, "iqm_high": high,
                     f"p_improve_{baseline}": float(np.mean(improvements)) if improvements else float("nan")})
    return pd.DataFrame.from_records(rows)


def composition(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): the median over seeds of each minibatch share (SHARE_COLUMNS).

    The three medians are rescaled to sum to 1 so they stack to the whole minibatch.
    """
    shares = epochs.groupby([*GROUP, "epoch"], observed=True)[list(SHARE_COLUMNS)].median()
    total = shares.sum(axis=1).replace(0.0, np.nan)
    return shares.div(total, axis=0).reset_index()


def mean_q(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per (task, config, epoch): q_mean averaged over seeds (column q_mean) and n_seeds."""
    grouped = epochs.groupby([*GROUP, "epoch"], observed=True)["q_mean"]
    return grouped.agg(q_mean="mean", n_seeds="count").reset_index()


def schedule_curves(runs: pd.DataFrame) -> pd.DataFrame:
    """eps(k) for k = 1..K of every distinct fixed schedule (kind, eps, beta1, beta2, K) among the runs
    (success schedules depend on each run's progress: their rates are in the logs, not drawn here).

    Returns columns label (:func:`schedule_label`), schedule, eps_setting, beta1, beta2,
    total_epochs, epoch, eps; in the order constant, linear, exponential, then by beta1, beta2.
    """
    settings = ["schedule", "eps", "beta1", "beta2", "total_epochs"]
    distinct = runs.loc[runs["schedule"].isin(FIXED_KINDS), settings].drop_duplicates()
    distinct = distinct.assign(order=distinct["schedule"].map({kind: i for i, kind in enumerate(SCHEDULE_KINDS)}))
    frames = []
    for run in distinct.sort_values(["order", "beta1", "beta2", "eps", "total_epochs"]).itertuples(index=False):
        schedule = ScheduleConfig(kind=run.schedule, eps=run.eps, beta1=run.beta1, beta2=run.beta2)
        k = np.arange(1, run.total_epochs + 1)
        frames.append(pd.DataFrame({
            "label": schedule_label(run.schedule, run.eps, run.beta1, run.beta2), "schedule": run.schedule,
            "eps_setting": run.eps, "beta1": run.beta1, "beta2": run.beta2, "total_epochs": run.total_epochs,
            "epoch": k, "eps": [relabel_rate(schedule, int(i), run.total_epochs) for i in k]}))
    return pd.concat(frames, ignore_index=True)


def mean_rate_lines(beta2_values: list[float], total_epochs: int, points: int = 101) -> pd.DataFrame:
    """mu_eps over beta1 in [0, 1] for each beta2: eq. 10 (``exact``, with K = total_epochs)
    and eq. 11 (``approx``). Columns beta2, beta1, exact, approx."""
    beta1 = np.linspace(0.0, 1.0, points)
    frames = [pd.DataFrame({"beta2": beta2, "beta1": beta1,
                            "exact": [mean_rate_exact(b1, beta2, total_epochs) for b1 in beta1],
                            "approx": mean_rate_approx(beta1, beta2)})
              for beta2 in sorted(set(beta2_values))]
    return pd.concat(frames, ignore_index=True)


@dataclass
class Analysis:
    """Everything the figures and the report draw from.

    runs / epochs: the tables of :mod:`analysis.load`; curves: :func:`smoothed_curves`;
    medians: :func:`median_curves`; summary / aggregate: the two tables; window: the
    smoothing window in epochs.
    """

    runs: pd.DataFrame
    epochs: pd.DataFrame
    curves: pd.DataFrame
    medians: pd.DataFrame
    summary: pd.DataFrame
    aggregate: pd.DataFrame
    window: int


def analyse(runs: pd.DataFrame, epochs: pd.DataFrame, window: int, seed: int = BOOTSTRAP_SEED) -> Analysis:
    """Compute every table the report needs (runs without a completed epoch are left out)."""
    curves = smoothed_curves(epochs, window)
    return Analysis(runs=runs, epochs=epochs, curves=curves, medians=median_curves(curves),
                    summary=summary_table(curves, runs[runs["epochs_done"] > 0], seed=seed),
                    aggregate=aggregate_table(curves, seed=seed), window=window)
