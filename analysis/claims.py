"""The seed paper's claims, each against hersd's measurement: the table docs/RESULTS.md and the report open with.

A :class:`Claim` names a task, the paper's statement and figure, two configurations and the statistic
that decides it; :func:`claims_table` reads the measurement from the report's own tables (``summary``,
``permutation_tests``, ``critic_bias_tests``) and words a verdict the numbers support:

- a claim that one configuration does better: ``reproduced`` when the one-sided permutation p of
  that direction is below :data:`ALPHA` (the critic's bias: the two-sided p of ``critic_bias_tests``,
  with the difference in the claimed direction); ``same direction, not significant at n v m`` when the medians
  point that way but p is not; ``not reproduced: the other way, not significant`` or ``contradicted``
  (the other direction's p below ALPHA) otherwise;
- a claim that two do alike (FetchSlide): ``consistent: not separated at n v m`` when the two-sided p
  (twice the smaller one-sided p) is at least ALPHA, ``not reproduced: separated`` otherwise;
- ``not reproduced: both final medians are 0`` (``neither median reaches <level>``) whatever p says, where
  neither configuration's median learns: two arms that both fail are not alike in the paper's sense;
- ``too few seeds to test at n v m`` where even the most extreme split of the seeds could not reach
  ALPHA (two-sided at 5 v 2: 2/21 = 0.095), with ``the arms as far apart as the seeds allow`` when p is
  that smallest value: "not separated" would then say nothing about the claim;
- ``not measured yet`` where either configuration lacks two complete seeds.

The configurations are named by the schedule classes themselves (:func:`analysis.load.config_label`), so
the table follows any renaming; the control's rate is the linear schedule's exact mean (eq. 10).
Pure pandas: no torch, no MuJoCo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.load import HER_WEIGHTS, PAPER_EPOCHS, config_label
from analysis.metrics import EXACT_SPLITS, PERMUTATION_RESAMPLES, smallest_p_value
from hersd.contract.tasks import task_title
from hersd.contract.schedules.constant import Constant
from hersd.contract.schedules.exponential import Exponential
from hersd.contract.schedules.linear import Linear

ALPHA = 0.05  # the significance level of every verdict

HER = config_label(Constant(), *HER_WEIGHTS, mep=False)
LINEAR_025 = config_label(Linear(beta1=0.25), *HER_WEIGHTS, mep=False)
EXP_025 = config_label(Exponential(beta1=0.25, beta2=0.25), *HER_WEIGHTS, mep=False)
CONTROL = config_label(Constant(eps=Linear(beta1=0.25).exact_mean_rate(PAPER_EPOCHS)), *HER_WEIGHTS, mep=False)

# statistic -> (its words, whether lower is better); the permutation tables' columns are p_<statistic>
STATISTICS = {"epochs_to_0.5": ("smoothed median first reaches 0.5 at epoch", True),
              "epochs_to_0.9": ("smoothed median first reaches 0.9 at epoch", True),
              "final": ("final median test success", False),
              "bias_real": ("critic bias on real goals, epochs 1-50", True)}
CLAIM_COLUMNS = ["task", "claim", "paper", "hersd", "seeds", "test", "p", "verdict"]


@dataclass(frozen=True)
class Claim:
    task: str
    statement: str  # the paper's claim, in a few words
    figure: str  # where the paper shows it
    config: str  # the configuration claimed better (or alike)
    versus: str
    statistic: str  # a key of STATISTICS
    alike: bool = False  # the claim is that the two do alike


CLAIMS = (
    Claim("push", "linear decay 0.25 learns faster than HER", "Fig. 4(a)", LINEAR_025, HER, "epochs_to_0.9"),
    Claim("push", "exponential decay 0.25 learns faster than HER", "Fig. 4(b)", EXP_025, HER, "epochs_to_0.9"),
    Claim("push", "the decay corrects the early overestimation faster", "Fig. 10(a)", LINEAR_025, HER, "bias_real"),
    Claim("push", "the gain is the mean rate mu_eps, not the decay (Fig. 12's reading)", "Fig. 12", LINEAR_025,
          CONTROL, "epochs_to_0.9", alike=True),
    Claim("pick_and_place", "linear decay 0.25 ends ~20 % higher than HER", "Fig. 6(a)", LINEAR_025, HER, "final"),
    Claim("pick_and_place", "linear decay 0.25 learns faster than HER", "Fig. 6(a)", LINEAR_025, HER, "epochs_to_0.5"),
    Claim("pick_and_place", "exponential decay 0.25 ends ~20 % higher than HER", "Fig. 6(b)", EXP_025, HER, "final"),
    Claim("pick_and_place", "the decay corrects the early overestimation faster", "Fig. 10(b)", LINEAR_025, HER,
          "bias_real"),
    Claim("pick_and_place", "the gain is the mean rate mu_eps, not the decay (Fig. 12's reading)", "Fig. 12",
          LINEAR_025, CONTROL, "final", alike=True),
    Claim("slide", "linear decay 0.25 and HER end alike", "Fig. 8", LINEAR_025, HER, "final", alike=True),
)


def claims_table(summary: pd.DataFrame, tests: pd.DataFrame, bias_tests: pd.DataFrame,
                 claims: tuple[Claim, ...] = CLAIMS) -> pd.DataFrame:
    """One row per claim whose task has runs (CLAIM_COLUMNS): the measurement of both configurations,
    their seeds, the test, its p and the verdict (module docstring)."""
    rows = [_claim_row(claim, summary, tests, bias_tests) for claim in claims
            if (summary["task"] == claim.task).any()]
    return pd.DataFrame.from_records(rows, columns=CLAIM_COLUMNS)


def _claim_row(claim: Claim, summary: pd.DataFrame, tests: pd.DataFrame, bias_tests: pd.DataFrame) -> dict:
    words, lower_better = STATISTICS[claim.statistic]
    row = {"task": claim.task, "claim": claim.statement, "paper": claim.figure}
    measured = _measured(claim, summary, bias_tests)
    if measured is None:
        return row | {"hersd": f"{claim.config} or {claim.versus}: fewer than 2 complete seeds", "seeds": "",
                      "test": "", "p": math.nan, "verdict": "not measured yet"}
    (value, versus_value), (seeds, versus_seeds) = measured
    at = f"{seeds} v {versus_seeds}"
    row |= {"hersd": f"{words} {_number(value)} ({claim.config}) vs {_number(versus_value)} ({claim.versus})",
            "seeds": at}
    direction = _better(value, versus_value, lower_better)
    two_sided = claim.alike or claim.statistic == "bias_real"
    if claim.statistic == "bias_real":
        p = p_better = p_worse = float(_pair_row(bias_tests[bias_tests["goal_type"] == "real"], claim)["p_two_sided"])
    else:
        p_better, p_worse = _one_sided(claim, tests)
        p = min(1.0, 2 * min(p_better, p_worse)) if two_sided else p_better
    row |= {"test": permutation_words(seeds, versus_seeds, two_sided), "p": p}
    if (failed := _neither_learns(claim.statistic, value, versus_value)) is not None:
        return row | {"verdict": f"not reproduced: {failed} at {at}"}
    if (smallest := smallest_p_value(seeds, versus_seeds, two_sided)) >= ALPHA:
        apart = ": the arms as far apart as the seeds allow" if math.isclose(p, smallest) else ""
        return row | {"verdict": f"too few seeds to test at {at}{apart}"}
    if claim.alike:
        return row | {"verdict": f"consistent: not separated at {at}" if p >= ALPHA else "not reproduced: separated"}
    if p_better < ALPHA and (direction or not two_sided):
        verdict = "reproduced"
    elif p_worse < ALPHA and (not direction or not two_sided):
        verdict = "contradicted"
    elif direction:
        verdict = f"same direction, not significant at {at}"
    else:
        verdict = "not reproduced: the other way, not significant"
    return row | {"verdict": verdict}


def _better(value: float, versus_value: float, lower_better: bool) -> bool:
    """Whether the configuration's median is the better one; a level never reached (NaN) comes after any epoch."""
    if lower_better:
        value, versus_value = (math.inf if math.isnan(v) else v for v in (value, versus_value))
        return value < versus_value
    return value > versus_value


def _neither_learns(statistic: str, value: float, versus_value: float) -> str | None:
    """The words for two medians that both fail (final success 0, or a level never reached), else None."""
    if statistic == "final" and value == versus_value == 0:
        return "both final medians are 0"
    if statistic.startswith("epochs_to_") and math.isnan(value) and math.isnan(versus_value):
        return f"neither median reaches {statistic.removeprefix('epochs_to_')}"
    return None


def permutation_words(seeds: int, versus_seeds: int, two_sided: bool) -> str:
    """The permutation test's kind and power: exact when the splits number at most EXACT_SPLITS."""
    splits = math.comb(seeds + versus_seeds, seeds)
    kind = "exact" if splits <= EXACT_SPLITS else f"{PERMUTATION_RESAMPLES} random splits of {splits}"
    return (f"permutation, {'two' if two_sided else 'one'}-sided, {kind} "
            f"(smallest p possible {smallest_p_value(seeds, versus_seeds, two_sided):.2g})")


def _measured(claim: Claim, summary: pd.DataFrame, bias_tests: pd.DataFrame):
    """((config's value, versus's value), (seeds, versus seeds)), or None when either lacks 2 seeds."""
    if claim.statistic == "bias_real":
        row = _pair_row(bias_tests[bias_tests["goal_type"] == "real"], claim)
        if row is None:
            return None
        swapped = row["config"] != claim.config
        values = (row["versus_bias"], row["config_bias"]) if swapped else (row["config_bias"], row["versus_bias"])
        seeds = (row["versus_seeds"], row["seeds"]) if swapped else (row["seeds"], row["versus_seeds"])
        return values, tuple(int(n) for n in seeds)
    column = "final_median" if claim.statistic == "final" else claim.statistic
    found = [summary[(summary["task"] == claim.task) & (summary["config"] == config)] for config in
             (claim.config, claim.versus)]
    if any(len(part) != 1 or part["seeds"].iloc[0] < 2 for part in found):
        return None
    values = tuple(part[column].iloc[0] for part in found)  # NA where the median never reached the level
    return tuple(math.nan if pd.isna(v) else float(v) for v in values), tuple(int(part["seeds"].iloc[0]) for part in found)


def _one_sided(claim: Claim, tests: pd.DataFrame) -> tuple[float, float]:
    """(p that config does better than versus, p that it does worse), one-sided."""
    column = f"p_{claim.statistic}"
    if tests.empty:
        return math.nan, math.nan
    in_task = tests[tests["task"] == claim.task]
    better = in_task[(in_task["config"] == claim.config) & (in_task["versus"] == claim.versus)]
    worse = in_task[(in_task["config"] == claim.versus) & (in_task["versus"] == claim.config)]
    return (float(better[column].iloc[0]) if len(better) else math.nan,
            float(worse[column].iloc[0]) if len(worse) else math.nan)


def _pair_row(table: pd.DataFrame, claim: Claim) -> pd.Series | None:
    pair = table[(table["task"] == claim.task) & (table["config"].isin([claim.config, claim.versus]))
                 & (table["versus"].isin([claim.config, claim.versus]))]
    return None if pair.empty or pair.iloc[0][["seeds", "versus_seeds"]].min() < 2 else pair.iloc[0]


def _number(value: float) -> str:
    if not np.isfinite(value):
        return "never"
    return f"{value:.0f}" if float(value).is_integer() else f"{value:.3g}"


def claims_markdown(table: pd.DataFrame) -> str:
    """The claims table as GitHub markdown, one table per task (the lines docs/RESULTS.md holds)."""
    parts = []
    for task, rows in table.groupby("task", sort=False):
        lines = [f"**{task_title(task)}**", "", "| claim | paper | hersd | seeds | test | p | verdict |", "| --- " * 7 + "|"]
        for row in rows.itertuples():
            p = "" if not np.isfinite(row.p) else f"{row.p:.2g}"
            lines.append(f"| {row.claim} | {row.paper} | {row.hersd} | {row.seeds} | {row.test} | {p} | {row.verdict} |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"
