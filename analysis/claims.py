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
- ``not measured yet`` where either configuration lacks two complete seeds;
- ``interim at n v m: judged at N v M`` for a registered hypothesis whose arms have fewer complete seeds than it
  was registered to be judged at (its p shown, no verdict drawn from it: looking again as seeds arrive is not a test
  at ALPHA).

Its words say the medians (``summary.csv``) and, given ``per_seed.csv``, the seeds' means the permutation test
compares (an epoch never reached counted as K + 1). Besides the paper's claims it holds a row per hypothesis
registered before its runs (:data:`REGISTRY`, docs/registered.csv: its id, arms, statistic, direction and the
commit that registered it; a one-sided one reads ``supported`` / ``not supported at n v m``, never ``contradicted``
(its registration tested one direction); a two-sided one reads ``separated`` / ``not separated``, the latter with the 95 %
interval of the difference of seed means by inverting the test: the differences its seeds would have separated), a
row per claim of the paper no committed run measures (:data:`NOT_MEASURED`: ``registered: <id>`` or ``not planned
yet``), and two claims measured from ``per_seed.csv`` alone (:func:`spread_row`, :func:`slide_q_row`).
:func:`late_judged_runs` names the runs a hypothesis judges that started before its registration.

The configurations are named by the schedule classes themselves (:func:`analysis.load.config_label`), so
the table follows any renaming; the control's rate is the linear schedule's exact mean (eq. 10).
Pure pandas and scipy: no torch, no MuJoCo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.load import HER_WEIGHTS, PAPER_EPOCHS, config_label
from analysis.metrics import EXACT_SPLITS, PERMUTATION_RESAMPLES, shift_interval, smallest_p_value
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
CLAIM_COLUMNS = ["task", "claim", "paper", "hersd", "seeds", "test", "p", "verdict", "registered"]
REGISTRY = Path(__file__).resolve().parent.parent / "docs" / "registered.csv"  # the hypotheses registered before runs


@dataclass(frozen=True)
class Claim:
    task: str
    statement: str  # the paper's claim, in a few words
    figure: str  # where the paper shows it
    config: str  # the configuration claimed better (or alike)
    versus: str
    statistic: str  # a key of STATISTICS
    alike: bool = False  # the claim is that the two do alike
    two_sided: bool = False  # a registered hypothesis without a direction: do the two differ?
    registered: str = ""  # a registered hypothesis's id (docs/registered.csv); "" for the paper's claims
    plan: str = ""  # the registered hypotheses that will measure it, while it is not measured
    judged_at: tuple[int, int] | None = None  # a registered hypothesis's seeds (config, versus) it is judged at


CLAIMS = (
    Claim("push", "linear decay 0.25 learns faster than HER", "Fig. 4(a)", LINEAR_025, HER, "epochs_to_0.9"),
    Claim("push", "exponential decay 0.25 learns faster than HER", "Fig. 4(b)", EXP_025, HER, "epochs_to_0.9",
          plan="exp-push-speed"),
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
                 claims: tuple[Claim, ...] = CLAIMS, per_seed: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per claim whose task has runs (CLAIM_COLUMNS): the measurement of both configurations (with the
    seeds' means the test compares, given ``per_seed``: per_seed.csv), their seeds, the test, its p and the verdict
    (module docstring)."""
    rows = [_claim_row(claim, summary, tests, bias_tests, per_seed) for claim in claims
            if (summary["task"] == claim.task).any()]
    return pd.DataFrame.from_records(rows, columns=CLAIM_COLUMNS)


def _claim_row(claim: Claim, summary: pd.DataFrame, tests: pd.DataFrame, bias_tests: pd.DataFrame,
               per_seed: pd.DataFrame | None = None) -> dict:
    words, lower_better = STATISTICS[claim.statistic]
    row = {"task": claim.task, "claim": claim.statement, "paper": claim.figure, "registered": claim.registered}
    measured = _measured(claim, summary, bias_tests)
    if measured is None:
        return row | {"hersd": f"{claim.config} or {claim.versus}: fewer than 2 complete seeds", "seeds": "",
                      "test": "", "p": math.nan,
                      "verdict": "not measured yet" + (f" (registered: {claim.plan})" if claim.plan else "")}
    (value, versus_value), (seeds, versus_seeds) = measured
    at = f"{seeds} v {versus_seeds}"
    row |= {"hersd": f"{words} {_number(value)} ({claim.config}) vs {_number(versus_value)} ({claim.versus})"
                     + _seed_means_words(claim, per_seed), "seeds": at}
    direction = _better(value, versus_value, lower_better)
    two_sided = claim.alike or claim.two_sided or claim.statistic == "bias_real"
    if claim.statistic == "bias_real":
        p = p_better = p_worse = float(_pair_row(bias_tests[bias_tests["goal_type"] == "real"], claim)["p_two_sided"])
    else:
        p_better, p_worse = _one_sided(claim, tests)
        p = min(1.0, 2 * min(p_better, p_worse)) if two_sided else p_better
    row |= {"test": permutation_words(seeds, versus_seeds, two_sided), "p": p}
    if claim.judged_at and (seeds, versus_seeds) != claim.judged_at:  # fewer: not yet; more: not as registered
        when = "interim" if seeds <= claim.judged_at[0] and versus_seeds <= claim.judged_at[1] else "beyond the registration"
        return row | {"verdict": f"{when} at {at}: judged at {claim.judged_at[0]} v {claim.judged_at[1]}"}
    if (failed := _neither_learns(claim.statistic, value, versus_value)) is not None:
        return row | {"verdict": f"not reproduced: {failed} at {at}"}
    if (smallest := smallest_p_value(seeds, versus_seeds, two_sided)) >= ALPHA:
        apart = ": the arms as far apart as the seeds allow" if math.isclose(p, smallest) else ""
        return row | {"verdict": f"too few seeds to test at {at}{apart}"}
    if claim.alike:
        return row | {"verdict": f"consistent: not separated at {at}" if p >= ALPHA else "not reproduced: separated"}
    if claim.two_sided and claim.statistic != "bias_real":
        better = p_better <= p_worse  # the direction of the seeds' means, the statistic tested
        if p < ALPHA:
            return row | {"verdict": f"separated: {claim.config} {'better' if better else 'worse'}"}
        return row | {"hersd": row["hersd"] + _detectable_words(claim, per_seed), "verdict": f"not separated at {at}"}
    if claim.registered:  # one-sided as registered: the other direction was never a hypothesis
        return row | {"verdict": "supported" if p_better < ALPHA else f"not supported at {at}"}
    if p_better < ALPHA and (direction or not two_sided):
        verdict = "reproduced"
    elif p_worse < ALPHA and (not direction or not two_sided):
        verdict = "contradicted"
    elif direction:
        verdict = f"same direction, not significant at {at}"
    else:
        verdict = "not reproduced: the other way, not significant"
    return row | {"verdict": verdict}


def _seed_means_words(claim: Claim, per_seed: pd.DataFrame | None) -> str:
    """``; seed means A vs B (the test's statistic)``: each configuration's mean over its complete seeds of what
    the permutation test compares (an epoch never reached counted as K + 1); "" without ``per_seed`` or for the
    critic's bias (its test's own table says its means)."""
    if per_seed is None or claim.statistic not in per_seed.columns:
        return ""
    means = [_seed_values(per_seed, claim, config).mean() for config in (claim.config, claim.versus)]
    return f"; seed means {means[0]:.4g} vs {means[1]:.4g} (the test's statistic)"


def _detectable_words(claim: Claim, per_seed: pd.DataFrame | None) -> str:
    """``; the test would have separated a difference of seed means below L or above H``: the ends of the 95 %
    interval of that difference by inverting the two-sided test (:func:`analysis.metrics.shift_interval`), what a
    two-sided registered hypothesis that is not separated reports; "" without ``per_seed``."""
    if per_seed is None or claim.statistic not in per_seed.columns:
        return ""
    x, y = (_seed_values(per_seed, claim, config) for config in (claim.config, claim.versus))
    epochs = claim.statistic.startswith("epochs_to_")
    low, high = shift_interval(x, y, ALPHA, tolerance=0.01 if epochs else 1e-4)
    digits = 1 if epochs else 3
    return (f"; the test would have separated a difference of seed means below {low:+.{digits}f} or above "
            f"{high:+.{digits}f} (95 % interval, the test inverted)")


def _seed_values(per_seed: pd.DataFrame, claim: Claim, config: str) -> np.ndarray:
    """The complete seeds' values of ``claim``'s statistic for ``config`` (an epoch never reached: K + 1): (seeds,)."""
    rows = _complete(per_seed, claim.task, config)
    seeds = rows[claim.statistic].astype(float)
    if claim.statistic.startswith("epochs_to_"):  # the run's own K + 1, as the permutation tests count it
        seeds = seeds.fillna(rows["epochs_done"].astype(float) + 1)
    return seeds.to_numpy()


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
    """The claims table as GitHub markdown, one table per task (the lines docs/RESULTS.md holds); a ``registered``
    column (the registering commit, as code) when the table has one."""
    registered = "registered" in table.columns
    parts = []
    for task, rows in table.groupby("task", sort=False):
        header = ["claim", "paper", "hersd", "seeds", "test", "p", "verdict", *(["registered"] if registered else [])]
        lines = [f"**{task_title(task)}**", "", "| " + " | ".join(header) + " |", "| --- " * len(header) + "|"]
        for row in rows.itertuples():
            p = "" if not np.isfinite(row.p) else f"{row.p:.2g}"
            cells = [row.claim, row.paper, row.hersd, row.seeds, row.test, p, row.verdict,
                     *([row.registered] if registered else [])]
            lines.append("| " + " | ".join(str(cell) for cell in cells) + " |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"


# ----------------------------------------------------------------------------- registered before the runs
@dataclass(frozen=True)
class Hypothesis:
    """A hypothesis registered before its runs (a row of docs/registered.csv): its claim (the arms, the statistic,
    two-sided or one-sided for ``config``), the arms whose runs it judges, the commit that registered it and that
    commit's date (ISO 8601; both empty until the stage's commit is made)."""

    claim: Claim
    stage: str
    judges: tuple[str, ...]  # the configurations whose runs must start after the registration
    commit: str
    date: str

    def registered_words(self) -> str:
        """``id, `<commit>` <date> UTC`` (the commit as code), or ``id, not committed yet``."""
        if not self.commit:
            return f"{self.claim.registered}, not committed yet"
        when = pd.Timestamp(self.date).tz_convert("UTC").strftime("%Y-%m-%d %H:%M")
        return f"{self.claim.registered}, `{self.commit[:7]}` {when} UTC"


def registered_hypotheses(path: Path = REGISTRY) -> list[Hypothesis]:
    """The rows of docs/registered.csv (columns id, stage, task, claim, config, versus, statistic, sides
    ``one-sided`` (for config) or ``two-sided``, judges ``config`` / ``versus`` / ``both``, seeds ``N v M`` it is
    judged at (empty: at the seeds complete when it is read), commit, date)."""
    table = pd.read_csv(path, dtype=str, keep_default_na=False)
    hypotheses = []
    for row in table.itertuples():
        judged_at = tuple(int(n) for n in row.seeds.split(" v ")) if row.seeds else None
        claim = Claim(row.task, f"{row.id}: {row.claim}", f"stage {row.stage}", row.config, row.versus, row.statistic,
                      two_sided=row.sides == "two-sided", registered=row.id, judged_at=judged_at)
        judged = {"config": (row.config,), "versus": (row.versus,), "both": (row.config, row.versus)}[row.judges]
        hypotheses.append(Hypothesis(claim, row.stage, judged, row.commit, row.date))
    return hypotheses


def late_judged_runs(hypotheses: list[Hypothesis], runs: pd.DataFrame, sessions: pd.DataFrame) -> list[str]:
    """One line per run a hypothesis judges whose first session started before the registering commit's date, or
    whose hypothesis names no commit yet (``runs``: the run table's task, config, run, path; ``sessions``: its
    sessions' run and ``started``, ns); [] when every judged run started after the commit that registered it."""
    first_start = sessions.groupby("run")["started"].min()
    late = []
    for hypothesis in hypotheses:
        registered = pd.Timestamp(hypothesis.date).value if hypothesis.commit else math.inf
        judged = runs[(runs["task"] == hypothesis.claim.task) & runs["config"].isin(hypothesis.judges)]
        for run in judged.itertuples():
            if first_start[run.run] <= registered:
                started = pd.Timestamp(first_start[run.run], tz="UTC").strftime("%Y-%m-%d %H:%M:%S")
                when = (f"({hypothesis.commit[:7]}, {hypothesis.date})" if hypothesis.commit
                        else "(docs/registered.csv names no commit yet)")
                late.append(f"{run.path}: started {started} UTC, before {hypothesis.claim.registered} was "
                            f"registered {when}")
    return late


# ----------------------------------------------------------------------------- the paper's other claims
@dataclass(frozen=True)
class PaperClaim:
    """A claim of the paper that no configuration pair of :data:`CLAIMS` measures: where it stands."""

    task: str
    statement: str
    figure: str
    plan: str = ""  # the registered hypotheses that test it, or "" (not planned yet)


NOT_MEASURED = (
    PaperClaim("push", "linear 0.25 is the best linear decay (of beta1 = 0.25, 0.5, 0.75, 1)", "Fig. 4(a)"),
    PaperClaim("push", "exponential decays 0.5 and 0.75 improve over HER; 1.0 marginally, epochs 50-200", "Fig. 4(b)"),
    PaperClaim("push", "every decay improves over ARCHER; linear 0.25 best", "Fig. 5, conclusion"),
    PaperClaim("pick_and_place", "linear decay 0.5 ends ~20 % higher than HER; 0.75 and 1 comparable", "Fig. 6(a)"),
    PaperClaim("pick_and_place", "exponential decays 0.5, 0.75 and 1 end ~20 % higher than HER", "Fig. 6(b)"),
    PaperClaim("pick_and_place", "the decay ends ~20 % higher than ARCHER (linear 0.25 best)", "Fig. 7, conclusion",
               "archer-decay-final, archer-her-final"),
    PaperClaim("pick_and_place", "any decay with mu_eps in (0.8, 0.889) works, whatever its shape", "conclusion, Fig. 12",
               "order-final, late-final, late-her"),
    PaperClaim("pick_and_place", "HER-MEP improves over HER", "Fig. 11(b)"),
    PaperClaim("pick_and_place", "the decay (or decay-MEP) learns fastest and ends highest of HER, HER-MEP, decay",
               "Fig. 11"),
    PaperClaim("slide", "linear decays 0.5 and 0.75 reach the best final median", "Fig. 8(a)"),
    PaperClaim("slide", "linear decays match ARCHER; ARCHER marginally better than the exponential decays", "Fig. 9"),
)


def _not_measured_row(claim: PaperClaim) -> dict:
    return {"task": claim.task, "claim": claim.statement, "paper": claim.figure, "hersd": "", "seeds": "", "test": "",
            "p": math.nan, "verdict": f"registered: {claim.plan}" if claim.plan else "not planned yet",
            "registered": ""}


def _complete(per_seed: pd.DataFrame, task: str, config: str) -> pd.DataFrame:
    return per_seed[(per_seed["task"] == task) & (per_seed["config"] == config) & per_seed["complete"].astype(bool)]


SPREAD_EPOCHS = (50, 100, 150, 200)  # the epochs of per_seed.csv's smoothed success (smoothed_at_<epoch>)


def seed_spread(per_seed: pd.DataFrame) -> np.ndarray:
    """Each seed's distance to its configuration's median curve: the mean over SPREAD_EPOCHS of |its smoothed
    success - the seeds' median there| (``per_seed``: one configuration's seeds), shape (seeds,)."""
    curves = per_seed[[f"smoothed_at_{epoch}" for epoch in SPREAD_EPOCHS]].to_numpy(float)
    return np.abs(curves - np.median(curves, axis=0)).mean(axis=1)


def _difference_of_means(first: np.ndarray, second: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(first, axis=axis) - np.mean(second, axis=axis)


def spread_row(per_seed: pd.DataFrame, task: str = "push", config: str = LINEAR_025, versus: str = HER) -> dict | None:
    """Fig. 4's "the variation with different random seeds is smaller with the sampling rate decay": the seeds'
    spread (:func:`seed_spread`) of the decay against HER's, a two-sided permutation test of the difference of the
    means (exact where the splits number at most EXACT_SPLITS); None without two complete seeds a side."""
    if any(f"smoothed_at_{epoch}" not in per_seed.columns for epoch in SPREAD_EPOCHS):
        return None
    seeds_of = [_complete(per_seed, task, name) for name in (config, versus)]
    if min(len(seeds) for seeds in seeds_of) < 2:  # checked before any median: an empty one only warns
        return None
    spreads = [seed_spread(seeds) for seeds in seeds_of]
    if any(np.isnan(spread).any() for spread in spreads):
        return None
    seeds = tuple(len(spread) for spread in spreads)
    from scipy import stats  # most of a second to import: only when computing
    test = stats.permutation_test(spreads, _difference_of_means, permutation_type="independent", vectorized=True,
                                  alternative="two-sided", n_resamples=max(EXACT_SPLITS, PERMUTATION_RESAMPLES),
                                  random_state=0)
    means = [float(np.mean(spread)) for spread in spreads]
    verdict = (f"not separated at {seeds[0]} v {seeds[1]}" if test.pvalue >= ALPHA
               else "reproduced" if means[0] < means[1] else "contradicted")
    return {"task": task, "claim": "the variation over random seeds is smaller with the decay", "paper": "Fig. 4 (text)",
            "hersd": f"mean distance of a seed's smoothed success to its configuration's median at epochs "
                     f"{', '.join(map(str, SPREAD_EPOCHS))}: {means[0]:.3g} ({config}) vs {means[1]:.3g} ({versus})",
            "seeds": f"{seeds[0]} v {seeds[1]}", "test": permutation_words(*seeds, two_sided=True), "p": float(test.pvalue),
            "verdict": verdict, "registered": ""}


def slide_q_row(per_seed: pd.DataFrame, configs: tuple[str, ...] = (HER, LINEAR_025), early: int = 10,
                late: int = PAPER_EPOCHS) -> dict | None:
    """Fig. 10(c)'s "the mean Q-value for the Slide task is not significantly diminished over time, regardless of
    methods": each complete FetchSlide seed's mean Q at epoch ``late`` minus at ``early`` (``q_mean_at_<epoch>``),
    both configurations' seeds pooled, an exact two-sided sign-flip permutation test of their mean; the critic's
    bias on real goals (Q minus the true return) over the same epochs beside it. A seed without both Q values is left
    out (the seeds counted say so). None without two seeds."""
    seeds = pd.concat([_complete(per_seed, "slide", config) for config in configs])
    q_columns, bias_columns = (f"q_mean_at_{early}", f"q_mean_at_{late}"), (f"bias_real_mean_at_{early}",
                                                                           f"bias_real_mean_at_{late}")
    if any(column not in seeds.columns for column in (*q_columns, *bias_columns)):
        return None
    seeds = seeds.dropna(subset=list(q_columns))
    if len(seeds) < 2:
        return None
    change = (seeds[q_columns[1]] - seeds[q_columns[0]]).to_numpy(float)
    from scipy import stats  # most of a second to import: only when computing
    test = stats.permutation_test((change,), np.mean, permutation_type="samples", vectorized=True,
                                  alternative="two-sided", n_resamples=2 ** len(change), random_state=0)
    diminished = test.pvalue < ALPHA and change.mean() < 0
    per_config = "; ".join(f"{config} {seeds.loc[seeds['config'] == config, q_columns[0]].mean():.3g} -> "
                           f"{seeds.loc[seeds['config'] == config, q_columns[1]].mean():.3g}" for config in configs)
    bias = seeds[list(bias_columns)].mean()
    return {"task": "slide", "claim": "the mean Q-value is not significantly diminished over time, whatever the method",
            "paper": "Fig. 10(c)",
            "hersd": f"mean Q, epoch {early} -> {late}: {per_config}; the critic's bias on real goals "
                     f"{bias.iloc[0]:.3g} -> {bias.iloc[1]:.3g} (all seeds)",
            "seeds": f"{len(change)} paired",
            "test": f"sign-flip permutation of the seeds' changes, two-sided, exact (smallest p possible "
                    f"{2 / 2 ** len(change):.2g})", "p": float(test.pvalue),
            "verdict": "not reproduced: diminished" if diminished else f"consistent: not diminished at {len(change)} seeds",
            "registered": ""}


def full_claims_table(summary: pd.DataFrame, tests: pd.DataFrame, bias_tests: pd.DataFrame, per_seed: pd.DataFrame,
                      registry: Path = REGISTRY) -> pd.DataFrame:
    """The report's claims table: the paper's claims measured (:data:`CLAIMS`, the seed spread and FetchSlide's
    Q from ``per_seed``), each registered hypothesis (its commit in ``registered``) and the paper's claims not
    measured, task by task in the order of the tasks' first rows; empty when no claim of CLAIMS has runs."""
    measured = claims_table(summary, tests, bias_tests, CLAIMS, per_seed)
    if measured.empty:
        return measured
    hypotheses = registered_hypotheses(registry)
    rows = [*measured.to_dict("records"), *(row for row in (spread_row(per_seed), slide_q_row(per_seed)) if row),
            *claims_table(summary, tests, bias_tests, tuple(h.claim for h in hypotheses), per_seed).to_dict("records"),
            *(_not_measured_row(claim) for claim in NOT_MEASURED)]
    words = {h.claim.registered: h.registered_words() for h in hypotheses}
    table = pd.DataFrame.from_records(rows, columns=CLAIM_COLUMNS)
    table["registered"] = table["registered"].map(lambda key: words.get(key, key))
    order = {task: rank for rank, task in enumerate(dict.fromkeys(table["task"]))}
    return table.sort_values("task", key=lambda column: column.map(order), kind="stable").reset_index(drop=True)
