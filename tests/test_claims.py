"""The claims table (analysis/claims.py): each verdict from hand-made tables, and docs/RESULTS.md opening
with the tables the committed report generated."""

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.claims import (CONTROL, EXP_025, HER, LINEAR_025, NOT_MEASURED, REGISTRY, Claim, Hypothesis,
                             claims_markdown, claims_table, full_claims_table, late_judged_runs, registered_hypotheses,
                             slide_q_row, spread_row)
from analysis.metrics import permutation_p_values

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


def per_seed_table(values: dict[str, list[float]], column: str = "final", task: str = "push") -> pd.DataFrame:
    return pd.DataFrame([{"task": task, "config": config, "seed": seed, "complete": True, "epochs_done": 200, column: value}
                         for config, seeds in values.items() for seed, value in enumerate(seeds)])


def test_the_words_give_the_medians_and_the_seed_means_the_test_compares():
    """Medians 100 v 140 in the summary; the per-seed table's means, an epoch never reached counted as K + 1."""
    seeds = per_seed_table({LINEAR_025: [100, 110, np.nan], HER: [140, 150, 160]}, column="epochs_to_0.9")
    row = claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), NO_BIAS, (FASTER,), seeds).iloc[0]
    assert row["hersd"].endswith(f"; seed means {(100 + 110 + 201) / 3:.4g} vs 150 (the test's statistic)")


@pytest.mark.parametrize("p_better, p_worse, verdict", [(0.01, 0.99, "separated: linear b1=0.25 better"),
                                                        (0.99, 0.01, "separated: linear b1=0.25 worse"),
                                                        (0.3, 0.7, "not separated at 5 v 5")])
def test_a_registered_two_sided_hypothesis_says_separated_or_not_and_a_one_sided_one_supported(p_better, p_worse,
                                                                                              verdict):
    two_sided = Claim("push", "h: differ", "stage 2", LINEAR_025, HER, "epochs_to_0.9", two_sided=True, registered="h")
    row = claims_table(summary_table(100, 140), permutation_table(p_better, p_worse), NO_BIAS, (two_sided,)).iloc[0]
    assert (row["verdict"], row["p"], row["registered"]) == (verdict, pytest.approx(2 * min(p_better, p_worse)), "h")
    one_sided = Claim("push", "h: faster", "stage 3", LINEAR_025, HER, "epochs_to_0.9", registered="h")
    assert claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), NO_BIAS,
                        (one_sided,)).iloc[0]["verdict"] == "supported"


def test_a_hypothesis_short_of_the_seeds_it_is_judged_at_is_interim_whatever_its_p():
    """Registered to be judged at 5 v 5: at 2 v 5 its p is shown and no verdict drawn, even one below 0.05; at 5 v 5
    it is judged. Each hypothesis of docs/registered.csv carries the seeds its registration names."""
    one_sided = Claim("push", "h: faster", "stage 3", LINEAR_025, HER, "epochs_to_0.9", registered="h", judged_at=(5, 5))
    summary = summary_table(100, 140).assign(seeds=[2, 5, 3])
    early = claims_table(summary, permutation_table(1 / 21, 1.0), NO_BIAS, (one_sided,)).iloc[0]
    assert (early["seeds"], early["p"], early["verdict"]) == ("2 v 5", pytest.approx(1 / 21), "interim at 2 v 5: "
                                                                                              "judged at 5 v 5")
    full = claims_table(summary_table(100, 140), permutation_table(0.01, 0.99), NO_BIAS, (one_sided,)).iloc[0]
    assert full["verdict"] == "supported"
    more = claims_table(summary.assign(seeds=[5, 7, 3]), permutation_table(0.01, 0.99), NO_BIAS, (one_sided,)).iloc[0]
    assert more["verdict"] == "beyond the registration at 5 v 7: judged at 5 v 5"
    judged_at = {h.claim.registered: h.claim.judged_at for h in registered_hypotheses()}
    assert judged_at == {"bf16-final": (5, 10), "bf16-speed": (5, 10), "order-final": (5, 5), "late-final": (5, 5),
                         "late-her": (5, 5), "exp-push-speed": (5, 10), "archer-decay-final": None,
                         "archer-her-final": None}


def test_a_registered_one_sided_hypothesis_is_supported_or_not_never_contradicted():
    """Its registration tested one direction: the other way's small p is no verdict (no second test after the data)."""
    one_sided = Claim("push", "h: faster", "stage 3", LINEAR_025, HER, "epochs_to_0.9", registered="h")
    rows = [claims_table(summary_table(100, 140), permutation_table(better, worse), NO_BIAS, (one_sided,)).iloc[0]
            for better, worse in ((0.99, 0.01), (0.3, 0.7), (0.01, 0.99))]
    assert [row["verdict"] for row in rows] == ["not supported at 5 v 5", "not supported at 5 v 5", "supported"]
    paper = Claim("push", "faster", "Fig. 4", LINEAR_025, HER, "epochs_to_0.9")
    assert claims_table(summary_table(100, 140), permutation_table(0.99, 0.01), NO_BIAS,
                        (paper,)).iloc[0]["verdict"] == "contradicted"  # a claim of the paper's can be


def test_the_seed_means_count_a_level_never_reached_as_the_runs_own_k_plus_1():
    seeds = per_seed_table({LINEAR_025: [10, np.nan], HER: [20, 30]}, column="epochs_to_0.9").assign(epochs_done=50)
    row = claims_table(summary_table(10, 25), permutation_table(0.3, 0.7), NO_BIAS, (FASTER,), seeds).iloc[0]
    assert row["hersd"].endswith("; seed means 30.5 vs 25 (the test's statistic)")


def test_a_slide_seed_without_both_q_values_is_left_out_of_the_q_claim():
    seeds = pd.DataFrame({"task": "slide", "config": [HER] * 3 + [LINEAR_025] * 3, "complete": True,
                          "q_mean_at_10": [-4.0] * 6, "q_mean_at_200": [-9.0, np.nan, -9.5, -9.0, -10.0, -8.5],
                          "bias_real_mean_at_10": 30.0, "bias_real_mean_at_200": 20.0})
    row = slide_q_row(seeds)
    assert row["seeds"] == "5 paired" and row["p"] == pytest.approx(2 / 32) and "not diminished at 5 seeds" in row["verdict"]


def test_a_two_sided_hypothesis_not_separated_gives_the_differences_its_seeds_would_have_separated():
    """The words end with the 95 % interval of the difference of seed means by inverting the two-sided test: a
    shift just inside either end is not separated (p >= 0.05), one just outside is; a separated one has no interval."""
    seeds = per_seed_table({LINEAR_025: [0.90, 0.95, 0.80, 0.99, 0.93], HER: [0.97, 0.85, 0.99, 0.92, 0.96, 0.90]})
    two_sided = Claim("push", "h: differ", "stage 2", LINEAR_025, HER, "final", two_sided=True, registered="h")
    row = claims_table(summary_table(0.93, 0.94), permutation_table(0.3, 0.7), NO_BIAS, (two_sided,), seeds).iloc[0]
    match = re.search(r"separated a difference of seed means below ([-+.\d]+) or above ([-+.\d]+) \(95 % interval, "
                      r"the test inverted\)$", row["hersd"])
    low, high = float(match[1]), float(match[2])
    x, y = (seeds[seeds["config"] == config]["final"].to_numpy() for config in (LINEAR_025, HER))
    assert low < x.mean() - y.mean() < high

    def p(shift: float) -> float:
        greater, less = permutation_p_values((x - shift)[None], y[None])
        return min(1.0, 2 * min(greater[0], less[0]))
    assert p(low + 0.002) >= 0.05 > p(low - 0.002) and p(high - 0.002) >= 0.05 > p(high + 0.002)
    separated = claims_table(summary_table(0.93, 0.94), permutation_table(0.01, 0.99), NO_BIAS, (two_sided,), seeds)
    assert "interval" not in separated.iloc[0]["hersd"]


def test_the_seed_spread_claim_tests_the_spreads_two_sided_exactly():
    """Four tight decay seeds against four spread HER seeds: every split as extreme is 2 of C(8, 4) = 70."""
    curves = {LINEAR_025: [0.5, 0.51, 0.49, 0.5], HER: [0.1, 0.9, 0.3, 0.7]}
    seeds = pd.concat([per_seed_table(curves, column=f"smoothed_at_{epoch}") for epoch in (50, 100, 150, 200)],
                      axis=1).loc[:, lambda table: ~table.columns.duplicated()]
    row = spread_row(seeds)
    assert row["seeds"] == "4 v 4" and row["verdict"] == "reproduced" and row["p"] == pytest.approx(2 / 70)
    assert row["test"] == "permutation, two-sided, exact (smallest p possible 0.029)"
    assert spread_row(seeds.assign(config=seeds["config"].map({LINEAR_025: HER, HER: LINEAR_025})))["verdict"] == \
        "contradicted"


@pytest.mark.filterwarnings("error")
def test_the_seed_spread_claim_without_an_arms_seeds_is_no_row_and_no_warning():
    """A folder without HER's seeds (a one-run report): no row, and no numpy warning of an empty median."""
    curves = {LINEAR_025: [0.5, 0.51, 0.49]}
    seeds = pd.concat([per_seed_table(curves, column=f"smoothed_at_{epoch}") for epoch in (50, 100, 150, 200)],
                      axis=1).loc[:, lambda table: ~table.columns.duplicated()]
    assert spread_row(seeds) is None


def test_the_slide_q_claim_is_a_paired_two_sided_sign_flip_test_over_both_methods_seeds():
    seeds = pd.DataFrame({"task": "slide", "config": [HER] * 3 + [LINEAR_025] * 3, "complete": True,
                          "q_mean_at_10": [-4.0] * 6, "q_mean_at_200": [-9.0, -8.0, -9.5, -9.0, -10.0, -8.5],
                          "bias_real_mean_at_10": 30.0, "bias_real_mean_at_200": 20.0})
    row = slide_q_row(seeds)
    assert row["p"] == pytest.approx(2 / 64) and row["verdict"] == "not reproduced: diminished"
    mixed = seeds.assign(q_mean_at_200=[-9.0, 1.0, -9.5, 2.0, -10.0, 3.0])
    assert slide_q_row(mixed)["verdict"] == "consistent: not diminished at 6 seeds"


def test_every_registered_hypothesis_and_every_other_paper_claim_has_a_row():
    hypotheses = registered_hypotheses()
    ids = [h.claim.registered for h in hypotheses]
    assert {"bf16-final", "bf16-speed", "order-final", "late-final", "late-her", "exp-push-speed",
            "archer-decay-final", "archer-her-final"} == set(ids) and len(ids) == len(set(ids))
    table = full_claims_table(*(pd.read_csv(ROOT / f"results/report/tables/{name}.csv") for name in
                                ("summary", "permutation_tests", "critic_bias_tests", "per_seed")))
    registered = table[table["registered"] != ""]
    assert sorted(words.split(",")[0] for words in registered["registered"]) == sorted(ids)
    assert registered["registered"].str.contains(r"`[0-9a-f]{7}` \d{4}-\d\d-\d\d \d\d:\d\d UTC|not committed yet").all()
    assert set(table["claim"]) >= {claim.statement for claim in NOT_MEASURED}
    assert {"Fig. 4 (text)", "Fig. 10(c)"} <= set(table.loc[table["p"].notna(), "paper"])  # measured
    planned = {plan for claim in NOT_MEASURED for plan in claim.plan.split(", ") if plan}
    assert planned <= set(ids)


def test_the_registered_arms_are_the_labels_the_report_gives_their_runs():
    from analysis.load import config_label
    from hersd.contract.schedules import Constant, Exponential, Linear, Rising

    labels = {config_label(Constant(), 1, 1, False), config_label(Constant(), 1, 1, False, variants=["precision=bf16"]),
              config_label(Rising(beta1=0.25), 1, 1, False), config_label(Constant(eps=0.75), 1, 1, False),
              config_label(Exponential(beta1=0.25, beta2=0.25), 1, 1, False), config_label(Linear(beta1=0.25), 1, 1, False),
              config_label(Constant(), 1, 0.5, False, algo="archer"),
              config_label(Linear(beta1=0.25), 1, 0.5, False, algo="archer")}
    for hypothesis in registered_hypotheses():
        assert {hypothesis.claim.config, hypothesis.claim.versus} <= labels, hypothesis.claim.registered


def test_every_run_a_registered_hypothesis_judges_started_after_its_registering_commit(tmp_path):
    """The committed logs (and any landed since) against docs/registered.csv; then a planted registration newer
    than a run it judges fails, one line naming the run."""
    from analysis.load import load_runs

    hypotheses = registered_hypotheses()
    committed = load_runs(ROOT / "results")
    assert late_judged_runs(hypotheses, committed.runs, committed.sessions) == []
    planted = Hypothesis(Claim("push", "newer", "stage 9", HER, CONTROL, "final", registered="planted"), "9",
                         (HER,), "f" * 40, "2030-01-01T00:00:00+00:00")
    late = late_judged_runs([*hypotheses, planted], committed.runs, committed.sessions)
    assert late and all("before planted was registered (fffffff, 2030-01-01T00:00:00+00:00)" in line for line in late)
    assert len(late) == ((committed.runs["task"] == "push") & (committed.runs["config"] == HER)).sum()


def test_a_run_that_started_before_the_registration_is_named(tmp_path):
    from analysis.load import load_runs
    from analysis.synthetic import write_run
    from hersd.contract.config import TrainConfig

    for seed, start in ((0, "2026-11-28T20:00:00+0000"), (1, "2026-11-29T01:00:00+0000")):
        config = TrainConfig(seed=seed, precision="bf16")
        config.task.name = "push"
        write_run(tmp_path / f"bf16-{seed}", config, np.zeros(3), meta={"start_time": start})
    table = load_runs(tmp_path)
    late = late_judged_runs(registered_hypotheses(), table.runs, table.sessions)
    assert len(late) == 2 and all(line.startswith("bf16-0/run.mcap: started 2026-11-28 20:00:00 UTC, before bf16-")
                                  for line in late)
    unregistered = [Hypothesis(h.claim, h.stage, h.judges, "", "") for h in registered_hypotheses()]
    assert len(late_judged_runs(unregistered, table.runs, table.sessions)) == 4  # a run judged before any commit


def test_the_registry_names_the_commit_that_added_each_id_to_results_md():
    """git log -S<id>: the first commit adding the id to docs/RESULTS.md, and its date (where git is at hand)."""
    import shutil
    import subprocess

    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("no git repository here")
    for hypothesis in (h for h in registered_hypotheses() if h.commit):
        found = subprocess.run(["git", "log", f"-S{hypothesis.claim.registered}", "--format=%H %cI", "--reverse",
                                "--", "docs/RESULTS.md"], cwd=ROOT, capture_output=True, text=True, check=True)
        assert found.stdout.split("\n")[0].split() == [hypothesis.commit, hypothesis.date], hypothesis.claim.registered
    assert REGISTRY.is_file()
