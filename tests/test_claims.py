"""The claims table (analysis/claims.py): each verdict from hand-made tables, and docs/RESULTS.md opening
with the tables the committed report generated."""

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.claims import CONTROL, EXP_025, HER, LINEAR_025, Claim, claims_markdown, claims_table

ROOT = Path(__file__).resolve().parent.parent
FASTER = Claim("push", "decay faster", "Fig. 4(a)", LINEAR_025, HER, "epochs_to_0.9")
ALIKE = Claim("push", "alike", "Fig. 12", LINEAR_025, CONTROL, "epochs_to_0.9", alike=True)
BIAS = Claim("push", "bias lower", "Fig. 10(a)", LINEAR_025, HER, "bias_real")


def summary_table(linear: float, her: float, seeds: int = 5) -> pd.DataFrame:
    return pd.DataFrame({"task": "push", "config": [LINEAR_025, HER, CONTROL], "seeds": [seeds, seeds, 3],
                         "epochs_to_0.9": [linear, her, linear], "final_median": [0.9, 0.8, 0.9]})


def permutation_table(p_linear_better: float, p_her_better: float) -> pd.DataFrame:
    rows = [(LINEAR_025, HER, p_linear_better), (HER, LINEAR_025, p_her_better),
            (LINEAR_025, CONTROL, 0.3), (CONTROL, LINEAR_025, 0.8)]
    return pd.DataFrame([{"task": "push", "config": c, "versus": v, "p_epochs_to_0.9": p, "p_final": p}
                         for c, v, p in rows])


NO_BIAS = pd.DataFrame(columns=["task", "goal_type", "config", "versus", "seeds", "versus_seeds", "config_bias",
                                "versus_bias", "difference", "p_two_sided"])


@pytest.mark.parametrize("linear, her, p_better, p_worse, verdict", [
    (100, 140, 0.01, 0.99, "reproduced"),
    (100, 140, 0.20, 0.80, "same direction, not significant at 5 v 5"),
    (150, 140, 0.70, 0.30, "not reproduced: the other way, not significant"),
    (150, 100, 0.99, 0.01, "contradicted"),
])
def test_a_one_sided_claim_gets_the_verdict_its_p_and_direction_support(linear, her, p_better, p_worse, verdict):
    row = claims_table(summary_table(linear, her), permutation_table(p_better, p_worse), NO_BIAS, (FASTER,)).iloc[0]
    assert row["verdict"] == verdict and row["p"] == p_better and row["seeds"] == "5 v 5"
    assert row["test"] == "permutation, one-sided, exact (smallest p possible 0.004)"  # 1 / C(10, 5)
    assert f"{linear} ({LINEAR_025}) vs {her} ({HER})" in row["hersd"]


@pytest.mark.parametrize("p_better, p_worse, verdict, reversed_verdict", [
    (0.01, 0.99, "reproduced", "contradicted"),
    (0.20, 0.80, "same direction, not significant at 5 v 5", "not reproduced: the other way, not significant")])
def test_a_level_never_reached_reads_never_and_comes_after_any_epoch(p_better, p_worse, verdict, reversed_verdict):
    table = summary_table(100, 140).astype({"epochs_to_0.9": "Int64"})
    table.loc[1, "epochs_to_0.9"] = pd.NA  # HER's median never reached 0.9
    row = claims_table(table, permutation_table(p_better, p_worse), NO_BIAS, (FASTER,)).iloc[0]
    assert f"100 ({LINEAR_025}) vs never ({HER})" in row["hersd"] and row["verdict"] == verdict
    table.loc[[0, 1], "epochs_to_0.9"] = [pd.NA, 140]  # the decay's never reached: the other way
    row = claims_table(table, permutation_table(p_worse, p_better), NO_BIAS, (FASTER,)).iloc[0]
    assert row["verdict"] == reversed_verdict


def test_an_alike_claim_is_two_sided_and_says_its_power():
    row = claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), NO_BIAS, (ALIKE,)).iloc[0]
    assert row["p"] == pytest.approx(0.6)  # twice the smaller one-sided p, 0.3
    assert row["verdict"] == "consistent: not separated at 5 v 3"
    assert row["test"].endswith(f"(smallest p possible {2 / math.comb(8, 3):.2g})")


def test_two_arms_that_both_fail_are_not_reproduced_whatever_p_says():
    slide = Claim("push", "alike", "Fig. 8", LINEAR_025, HER, "final", alike=True)
    failed = summary_table(100, 140).assign(final_median=[0.0, 0.0, 0.0])
    row = claims_table(failed, permutation_table(1.0, 1.0), NO_BIAS, (slide,)).iloc[0]
    assert row["p"] == 1.0 and row["verdict"] == "not reproduced: both final medians are 0 at 5 v 5"
    assert claims_table(failed.assign(final_median=[0.0, 0.02, 0.0]), permutation_table(0.9, 0.3), NO_BIAS,
                        (slide,)).iloc[0]["verdict"] == "consistent: not separated at 5 v 5"
    never = summary_table(np.nan, np.nan)
    row = claims_table(never, permutation_table(1.0, 1.0), NO_BIAS, (FASTER,)).iloc[0]
    assert row["verdict"] == "not reproduced: neither median reaches 0.9 at 5 v 5" and "never" in row["hersd"]


def test_seeds_too_few_for_the_test_to_reach_alpha_say_so_not_not_separated():
    two = summary_table(100, 140).assign(seeds=[5, 5, 2])  # the control: 2 seeds; two-sided smallest p 2/21
    table = permutation_table(0.01, 0.99)
    table.loc[table["config"] == LINEAR_025, "p_epochs_to_0.9"] = [0.01, 1 / 21]  # v HER; v the control: extreme
    row = claims_table(two, table, NO_BIAS, (ALIKE,)).iloc[0]
    assert row["p"] == pytest.approx(2 / 21) and row["seeds"] == "5 v 2"
    assert row["verdict"] == "too few seeds to test at 5 v 2: the arms as far apart as the seeds allow"
    table.loc[table["config"] == LINEAR_025, "p_epochs_to_0.9"] = [0.01, 0.3]
    assert claims_table(two, table, NO_BIAS, (ALIKE,)).iloc[0]["verdict"] == "too few seeds to test at 5 v 2"
    three = two.assign(seeds=[5, 5, 3])  # two-sided smallest p 2/56 = 0.036: testable
    assert claims_table(three, table, NO_BIAS, (ALIKE,)).iloc[0]["verdict"] == "consistent: not separated at 5 v 3"


def test_too_few_seeds_is_not_measured_and_a_task_without_runs_has_no_rows():
    row = claims_table(summary_table(100, 140, seeds=1), permutation_table(0.01, 0.99), NO_BIAS, (FASTER,)).iloc[0]
    assert row["verdict"] == "not measured yet" and np.isnan(row["p"])
    slide = Claim("slide", "alike", "Fig. 8", LINEAR_025, HER, "final", alike=True)
    assert claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), NO_BIAS, (slide,)).empty


def test_the_bias_claim_reads_the_two_sided_test_in_either_row_order():
    bias = NO_BIAS.copy()
    bias.loc[0] = ["push", "real", HER, LINEAR_025, 5, 4, 30.0, 20.0, 10.0, 0.01]  # HER listed first
    row = claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), bias, (BIAS,)).iloc[0]
    assert "20 (" + LINEAR_025 + ") vs 30 (" + HER + ")" in row["hersd"] and row["seeds"] == "4 v 5"
    assert (row["verdict"], row["p"]) == ("reproduced", 0.01)
    bias.loc[0, ["config_bias", "versus_bias", "difference"]] = [20.0, 30.0, -10.0]  # the decay's bias higher
    assert claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), bias, (BIAS,)).iloc[0]["verdict"] == "contradicted"


def test_the_names_are_the_schedules_own_labels():
    assert (HER, LINEAR_025, EXP_025, CONTROL) == ("HER", "linear b1=0.25", "exp b1=0.25 b2=0.25", "HER eps=0.874375")


def test_results_md_opens_with_the_claims_tables_of_the_committed_report():
    table = pd.read_csv(ROOT / "results/report/tables/claims.csv", dtype=str, keep_default_na=False)
    generated = claims_markdown(table.assign(p=pd.to_numeric(table["p"], errors="coerce")))
    opening = "\n".join((ROOT / "docs/RESULTS.md").read_text(encoding="utf-8").splitlines()[:80])
    assert generated.strip() in opening
