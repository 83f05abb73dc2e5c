"""analysis/metrics.py: smoothing, medians, outcomes, IQM and its bootstrap, probability of improvement,
permutation tests, against hand-computed values on synthetic logs (tests/analysis_logs.py)."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pandas as pd
import pytest

from analysis import metrics
from analysis.load import load_runs
from analysis.synthetic import write_run
from hersd.contract.config import TrainConfig
from hersd.contract.schedules import Constant, Exponential, Linear, Success

from analysis_logs import HER_MEDIAN, PUSH_EPOCHS, PUSH_STEPS, WINDOW, make_config, write_campaign_midway
from analysis_logs import run_tables as _tables


@pytest.fixture(scope="module")
def analysed(hand_sized) -> metrics.Analysis:
    table = load_runs(hand_sized)
    return metrics.analyse(table.runs, table.epochs, WINDOW)


def test_smoothed_median_curve_and_range_equal_hand_values(analysed):
    her = analysed.medians[analysed.medians["config"] == "HER"]
    assert her["epoch"].tolist() == [1, 2, 3, 4, 5, 6]
    assert her["median"].to_numpy() == pytest.approx(HER_MEDIAN)
    assert her["low"].tolist()[-1] == pytest.approx(0.4)
    assert her["high"].tolist()[-1] == pytest.approx(1.0)
    assert her["n_seeds"].tolist() == [5] * 6
    seed1 = analysed.curves[(analysed.curves["config"] == "HER") & (analysed.curves["seed"] == 1)]
    assert seed1["smoothed"].to_numpy() == pytest.approx([0.0, 0.15, 0.3, 1.6 / 3, 2.2 / 3, 2.6 / 3])


def test_summary_row_equals_hand_values(analysed):
    her = analysed.summary[analysed.summary["config"] == "HER"].iloc[0]
    assert her["seeds"] == 5 and her["in_progress"] == 0
    assert her["final_median"] == pytest.approx(0.8)
    assert her["auc"] == pytest.approx(sum(HER_MEDIAN) / 6)  # (0 + .15 + .3 + .5333 + .6 + .8) / 6 = 0.39722
    assert her["auc"] == pytest.approx(0.397222, abs=1e-6)
    assert her["epochs_to_0.5"] == 4
    assert pd.isna(her["epochs_to_0.9"])  # never reached: an empty cell
    # raw medians per epoch: 0, 0.3, 0.6, 0.6, 0.9, 0.9 -> 0.5 first at epoch 3, 0.9 at epoch 5
    assert her["raw_epochs_to_0.5"] == 3 and her["raw_epochs_to_0.9"] == 5
    assert her["iqm"] == pytest.approx((0.5 + 0.8 + 2.6 / 3) / 3)  # drop 0.4 and 1.0
    assert her["iqm_low"] <= her["iqm"] <= her["iqm_high"]
    assert her["p_improve_HER"] == pytest.approx(0.5)
    linear = analysed.summary[analysed.summary["config"] == "linear b1=0.5"].iloc[0]
    assert linear["final_median"] == pytest.approx(0.575)
    assert linear["epochs_to_0.5"] == 1
    # 0.95 beats four of the five HER finals (not 1.0); 0.2 beats none.
    assert linear["p_improve_HER"] == pytest.approx(4 / 10)


def test_each_runs_own_outcomes_equal_hand_values(analysed):
    """Seeds 0, 1 and 3 of HER_SUCCESS: the smoothed values by hand in its comments, the raw ones as written."""
    outcomes = analysed.outcomes.merge(analysed.runs[["run", "config", "seed"]], on="run")
    her = outcomes[outcomes["config"] == "HER"].set_index("seed")
    columns = ["final", "epochs_to_0.5", "epochs_to_0.9", "raw_epochs_to_0.5", "raw_epochs_to_0.9"]
    assert her.loc[0, columns].tolist() == [pytest.approx(0.8), 5, pd.NA, 4, 5]
    assert her.loc[1, columns].tolist() == [pytest.approx(2.6 / 3), 4, pd.NA, 3, 5]
    assert her.loc[3, columns].tolist() == [pytest.approx(1.0), 3, 5, 2, 3]
    assert len(outcomes) == len(analysed.runs)


def test_runs_in_progress_enter_no_statistic(tmp_path):
    """Every table, median and mean equals that of the complete runs alone (a test that fails if an
    unfinished run counted anywhere: each would move the numbers)."""
    write_campaign_midway(tmp_path / "complete", in_progress=False)
    write_campaign_midway(tmp_path / "midway")
    alone, midway = (metrics.analyse(*_tables(tmp_path / name), WINDOW) for name in ("complete", "midway"))
    assert set(midway.curves.loc[~midway.curves["complete"], "config"]) == {"HER", "linear b1=0.5",
                                                                          "exp b1=0.5 b2=0.5"}
    summary = midway.summary.set_index("config")
    assert list(summary.index) == ["HER", "linear b1=0.5", "exp b1=0.5 b2=0.5"]  # exp: its runs all in progress
    assert summary["seeds"].tolist() == [2, 2, 0] and summary["in_progress"].tolist() == [1, 1, 1]
    exp = summary.loc["exp b1=0.5 b2=0.5"]  # its row says it runs, its statistics are empty
    assert exp["total_epochs"] == 6 and exp[metrics.SUMMARY_COLUMNS[6:]].isna().all()
    assert exp["mu_eps"] == pytest.approx(midway.runs.loc[midway.runs["config"] == "exp b1=0.5 b2=0.5", "mu_eps"].iloc[0])
    assert summary.loc["HER", "final_median"] == pytest.approx((0.8 + 2.6 / 3) / 2)  # seeds 0 and 1 at epoch 6
    assert summary.loc["linear b1=0.5", "p_improve_HER"] == pytest.approx(2 / 4)  # 0.95 beats both, 0.2 neither
    assert list(midway.aggregate["config"]) == ["HER", "linear b1=0.5"]
    assert midway.tests[["config", "versus", "seeds", "versus_seeds"]].values.tolist() == [
        ["HER", "linear b1=0.5", 2, 2], ["linear b1=0.5", "HER", 2, 2]]
    with_complete = midway.summary[midway.summary["seeds"] > 0]
    pd.testing.assert_frame_equal(_comparable(with_complete), _comparable(alone.summary))
    for name in ("aggregate", "medians", "shares", "q_means", "tests"):
        pd.testing.assert_frame_equal(_comparable(getattr(midway, name)), _comparable(getattr(alone, name)))
    assert (midway.medians["n_seeds"] == 2).all()


def _comparable(table: pd.DataFrame) -> pd.DataFrame:
    """A table without what names the runs left out (their count, the categories of their labels)."""
    return table.drop(columns="in_progress", errors="ignore").astype({"config": str}, errors="ignore")


def test_probability_of_improvement_counts_ties_half():
    assert metrics.probability_of_improvement(np.array([0.5, 0.8]), np.array([0.5, 0.4, 0.9])) == pytest.approx(3.5 / 6)


def test_first_epoch_reaching_is_nan_when_never_reached():
    epochs = np.array([1, 2, 3])
    assert metrics.first_epoch_reaching(epochs, np.array([0.1, 0.5, 0.7]), 0.5) == 2
    assert math.isnan(metrics.first_epoch_reaching(epochs, np.array([0.1, 0.2, 0.3]), 0.5))


def test_a_smoothed_window_of_exactly_half_successes_reaches_half_at_that_epoch():
    """The first 75 test successes of a FetchPush log (linear 0.25, seed 1) in twentieths (20 test
    episodes): those of epochs 26-75 add up to 25.0, so the 50-epoch mean first reaches 0.5 at epoch 75
    (pandas' running sum alone gives 0.49999999999999994 there, and epoch 76)."""
    twentieths = [1, 3, 3, 2, 0, 1, 1, 0, 0, 2, 2, 1, 2, 2, 2, 1, 2, 0, 0, 1, 1, 0, 4, 1, 3, 1, 4, 2, 2, 1, 1,
                  3, 6, 1, 3, 2, 3, 4, 1, 5, 3, 3, 7, 5, 7, 6, 8, 7, 8, 11, 11, 10, 10, 13, 12, 15, 14, 15,
                  13, 19, 17, 17, 15, 19, 18, 18, 17, 17, 17, 19, 18, 19, 18, 17, 18]
    epochs = pd.DataFrame({"task": "push", "config": "linear b1=0.25", "run": 0, "seed": 1, "complete": False,
                           "epoch": np.arange(1, 76), "test_success": np.array(twentieths) / 20})
    curve = metrics.smoothed_curves(epochs, window=50)
    assert sum(twentieths[25:]) == 500 and curve["smoothed"].iloc[-1] == 0.5
    assert metrics.first_epoch_reaching(curve["epoch"].to_numpy(), curve["smoothed"].to_numpy(), 0.5) == 75


def test_medians_of_an_even_number_of_seeds_straddling_a_threshold_reach_it_exactly(tmp_path):
    """Four seeds whose two middle raw successes are 0.85 and 0.95 from epoch 2 on (17 and 19 of 20 test
    episodes): their median is exactly 0.9, reached at epoch 2 (raw) and 3 (2-epoch average), though the two
    floats average to 0.8999999999999999. Final success and IQM (the middle two) are exactly 0.9 too."""
    for seed, level in enumerate([0.8, 0.85, 0.95, 1.0]):
        write_run(tmp_path / str(seed), make_config(seed=seed, epochs=4), np.array([0.0, level, level, level]))
    assert (0.85 + 0.95) / 2 < 0.9
    summary = metrics.analyse(*_tables(tmp_path), window=2).summary.iloc[0]
    assert summary[["raw_epochs_to_0.9", "epochs_to_0.9"]].fillna(0).tolist() == [2, 3]  # 0: never
    assert summary["final_median"] == 0.9 and summary["iqm"] == 0.9
    assert summary["auc"] == (0.0 + 0.45 + 0.9 + 0.9) / 4  # the median curve: 0, (0.425 + 0.475) / 2, 0.9, 0.9


def test_the_success_grid_is_the_least_common_denominator_of_the_success_rates():
    assert metrics.success_grid(np.array([0.0, 0.05, 0.3, 1.0])) == 20
    assert metrics.success_grid(np.array([0.5, 1 / 3, 0.6000000000000001])) == 30  # np.linspace's 0.6
    assert math.isnan(metrics.success_grid(np.array([0.25, 0.1234567891])))  # not k/n with n <= 10000
    assert metrics.on_grid(np.array([0.8999999999999999, 0.123]), np.array([40.0, np.nan])).tolist() == [0.9, 0.123]
    thirds = np.array([1 / 3] * 3 + [2 / 3] * 3)  # six values on the grid of 1/3 and their mean, 1/2
    assert metrics.grid_mean(thirds, np.full(6, 3.0)) == 0.5
    tenths = np.array([0.1, 0.2, 0.3])
    assert metrics.grid_mean(tenths, np.array([10.0, 5.0, 10.0])) == 0.2 != tenths.mean()  # 0.20000000000000004


def test_bootstrap_interval_is_seeded_and_stratified():
    values = [np.random.default_rng(7).uniform(size=12)]
    first = metrics.iqm_interval(values, seed=3)
    assert metrics.iqm_interval(values, seed=3) == first
    assert metrics.iqm_interval(values, seed=4) != first
    assert first[0] < metrics.interquartile_mean(values[0]) < first[1]
    # Resampling within each task keeps three 0s and three 1s in every pooled sample: IQM always 0.5.
    # Pooling the tasks before resampling would spread the interval.
    assert metrics.iqm_interval([np.zeros(3), np.ones(3)]) == (0.5, 0.5)
    # A task with one seed cannot be resampled and is held fixed.
    low, high = metrics.iqm_interval([np.array([0.2, 0.4]), np.array([1.0])])
    assert 0.2 <= low <= high <= 1.0
    assert all(math.isnan(bound) for bound in metrics.iqm_interval([np.array([0.3])]))


def rliable_library():
    """rliable's bootstrap module, or a skip naming why it does not import: rliable 1.2 pins arch < 8, and arch 7
    cannot be imported under pandas 3 (arch 8 can, but no longer takes the ``random_state`` rliable passes)."""
    try:
        import rliable.library
    except Exception as err:  # noqa: BLE001  (arch 7 under pandas 3 fails with a TypeError at import)
        pytest.skip(f"rliable.library does not import here: {type(err).__name__}: {err}")
    return rliable.library


@pytest.mark.parametrize("runs, tasks", [(5, 1), (4, 3), (10, 4), (3, 2)])
def test_iqm_is_rliables_aggregate_iqm(runs, tasks):
    """The IQM of a (runs x tasks) score matrix pooled, as rliable.metrics.aggregate_iqm computes it (to the last
    bits of a sum in another order: interquartile_mean puts it on the scores' grid)."""
    from rliable.metrics import aggregate_iqm

    scores = np.random.default_rng(runs * tasks).integers(0, 21, size=(runs, tasks)) / 20  # on a 1/20 grid
    assert metrics.interquartile_mean(scores.ravel(), 20) == pytest.approx(aggregate_iqm(scores), abs=1e-12)


def exact_iqm_quantiles(strata: list[np.ndarray], levels: list[float]) -> np.ndarray:
    """Quantiles of the stratified bootstrap's IQM by full enumeration: every stratum's seeds redrawn with replacement
    within it (each of its n^n ordered draws equally likely); a stratum of one seed held fixed."""
    from scipy import stats

    draws = [np.array(list(itertools.product(values, repeat=len(values)))) for values in strata]
    pooled = [np.concatenate(choice) for choice in itertools.product(*draws)]
    return np.quantile(stats.trim_mean(np.array(pooled), 0.25, axis=1), levels)


@pytest.mark.parametrize("strata", [[[0.1, 0.5, 0.9], [0.3, 0.6, 1.0]], [[0.0, 0.2, 0.4, 0.9], [0.5, 0.7, 1.0]],
                                    [[0.1, 0.3, 0.8, 0.8], [0.4]]])
def test_the_stratified_bootstrap_interval_lies_at_the_exact_distributions_quantiles(strata):
    """The 95 % percentile interval of 2,000 resamples, within the exact distribution's 1-4 % and 96-99 % quantiles
    (the Monte Carlo error of a 2.5 % quantile of 2,000 draws is 0.35 %)."""
    strata = [np.array(values) for values in strata]
    low, high = metrics.iqm_interval(strata)
    q01, q04, q96, q99 = exact_iqm_quantiles(strata, [0.01, 0.04, 0.96, 0.99])
    assert q01 <= low <= q04 and q96 <= high <= q99


@pytest.mark.parametrize("strata", [[[0.1, 0.5, 0.9], [0.3, 0.6, 1.0]], [[0.0, 0.2, 0.4, 0.9], [0.5, 0.7, 1.0, 1.0]],
                                    [[0.2, 0.4, 0.5, 0.6, 0.9]]])
def test_the_stratified_bootstrap_is_rliables(strata):
    """rliable's StratifiedBootstrap (runs redrawn within each task, the tasks kept) drawing 20,000 resamples, the
    IQM of each by rliable.metrics.aggregate_iqm: the same percentile interval as iqm_interval's. Its resampler is
    called directly: it reads the global numpy RNG (seeded here), and arch 8 refuses the random_state its
    constructor passes on."""
    from types import SimpleNamespace

    from rliable.metrics import aggregate_iqm

    library = rliable_library()
    scores = np.array(strata).T  # (runs, tasks)
    bootstrap = SimpleNamespace(_num_items=scores.shape[0], _args_shape=scores.shape, _task_bootstrap=False)
    bootstrap._strata_indices = library.StratifiedBootstrap._get_strata_indices(bootstrap)
    np.random.seed(0)
    iqms = [aggregate_iqm(scores[library.StratifiedBootstrap.update_indices(bootstrap)]) for _ in range(20_000)]
    expected = tuple(np.percentile(iqms, [2.5, 97.5]))
    assert metrics.iqm_interval([np.array(values) for values in strata], resamples=20_000) == pytest.approx(expected)


def test_aggregate_pools_tasks(analysed):
    her = analysed.aggregate[analysed.aggregate["config"] == "HER"].iloc[0]
    assert her["tasks"] == 1 and her["seeds"] == 5
    assert her["iqm"] == pytest.approx((0.5 + 0.8 + 2.6 / 3) / 3)


def test_a_variant_of_her_does_not_take_hers_place_as_the_baseline(tmp_path):
    """HER and HER precision=bf16 in one task were two HER baselines, so none: every configuration of the task had
    no P(improve on HER) (docs/RESULTS.md's FetchPush rows), and the aggregate averaged the other tasks alone. Each
    configuration is compared with the HER of its own variant."""
    linear = Linear(beta1=0.5)
    finals = {"her": 0.4, "her_bf16": 1.0, "linear": 0.8, "linear_bf16": 0.8}
    configs = {"her": make_config(), "her_bf16": make_config(), "linear": make_config(schedule=linear),
               "linear_bf16": make_config(schedule=linear)}
    configs["her_bf16"].precision = configs["linear_bf16"].precision = "bf16"
    for name, config in configs.items():
        write_run(tmp_path / name, config, np.full(config.epochs, finals[name]))
    table = load_runs(tmp_path)
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    p_improve = analysis.summary.set_index("config")["p_improve_HER"]
    assert p_improve["linear b1=0.5"] == 1.0  # 0.8 beats HER (0.4)
    assert p_improve["linear b1=0.5 precision=bf16"] == 0.0  # HER in bf16 (1.0), not in fp32
    assert p_improve["HER"] == 0.5 and p_improve["HER precision=bf16"] == 0.5
    assert analysis.aggregate.set_index("config")["p_improve_HER"]["linear b1=0.5"] == 1.0


def test_each_config_is_compared_with_the_her_runs_of_its_own_learner_and_k(tmp_path):
    """A folder holding HER at K = 6 and K = 8 (labels "HER K=6", "HER K=8") and TD3
    runs: each configuration's P(improve on HER) uses the HER seeds of the same learner and K."""
    from hersd.contract.config import LearnerConfig

    def td3(config: TrainConfig) -> TrainConfig:
        config.learner = LearnerConfig(name="td3")
        return config

    linear = Linear(beta1=0.5)
    finals = {"her6": 0.4, "her8": 1.0, "linear6": 0.8, "td3_her6": 1.0, "td3_linear6": 0.8}
    configs = {"her6": make_config(), "her8": make_config(epochs=8), "linear6": make_config(schedule=linear),
               "td3_her6": td3(make_config()), "td3_linear6": td3(make_config(schedule=linear))}
    for name, config in configs.items():
        write_run(tmp_path / name, config, np.full(config.epochs, finals[name]))
    table = load_runs(tmp_path)
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    p_improve = analysis.summary.set_index("config")["p_improve_HER"]
    assert p_improve["linear b1=0.5"] == 1.0  # 0.8 beats HER at K = 6 (0.4), not HER at K = 8 (1.0)
    assert p_improve["TD3 linear b1=0.5"] == 0.0  # TD3's HER (1.0), not DDPG's
    assert p_improve["HER K=8"] == 0.5 and p_improve["TD3 HER"] == 0.5
    assert analysis.aggregate.set_index("config")["p_improve_HER"]["linear b1=0.5"] == 1.0


def test_each_decay_is_tested_in_both_directions_against_the_constant_rate_at_its_mean_rate(tmp_path):
    """linear b1=0.5 over K = 6 relabels at mu_eps = 1 - 0.5 * 3.5 / 6 = 17/24 on average: it is paired with the
    constant rate 17/24 (by value, not by name), not with HER (0.8), an exponential decay or the success-driven
    rate. Three flat seeds (0.9, 0.8, 0.7) against two (0.6, 0.5): of the C(5, 3) = 10 splits only the observed
    one puts the three best on the decay's side."""
    linear, control = Linear(beta1=0.5), Constant(eps=1 - 0.5 * 3.5 / 6)
    others = [Constant(), Exponential(beta1=0.5, beta2=0.5),
              Success(beta1=0.5)]
    for seed, level in enumerate([0.9, 0.8, 0.7]):
        write_run(tmp_path / f"linear{seed}", make_config(schedule=linear, seed=seed), np.full(6, level))
        for index, schedule in enumerate(others):
            write_run(tmp_path / f"other{index}-{seed}", make_config(schedule=schedule, seed=seed), np.full(6, level))
    for seed, level in enumerate([0.6, 0.5]):
        write_run(tmp_path / f"control{seed}", make_config(schedule=control, seed=seed), np.full(6, level))
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    assert analysis.summary.set_index("config")["mu_eps"].to_dict() == pytest.approx({
        "HER": 0.8, "HER eps=0.708333": 17 / 24, "linear b1=0.5": 17 / 24,
        "exp b1=0.5 b2=0.5": analysis.runs.loc[analysis.runs["schedule"] == "exponential", "mu_eps"].iloc[0],
        "success b1=0.5": analysis.runs.loc[analysis.runs["schedule"] == "success", "mu_eps"].median()})
    tests = analysis.equal_mu_tests.set_index("outcome")
    assert set(tests["config"]) == {"linear b1=0.5"} and set(tests["versus"]) == {"HER eps=0.708333"}
    assert list(tests.index) == ["final", "epochs_to_0.5", "epochs_to_0.9", "raw_epochs_to_0.5", "raw_epochs_to_0.9",
                                 "raw_auc"]
    assert tests.loc["final", ["config_mean", "versus_mean"]].tolist() == [0.8, 0.55]  # float sums: 0.8000000000000002
    for outcome in ("final", "raw_auc"):
        assert tests.loc[outcome, ["p_config_better", "p_versus_better"]].tolist() == pytest.approx([1 / 10, 1.0])
    assert tests.loc["epochs_to_0.5", ["config_mean", "p_config_better", "p_versus_better"]].tolist() == [1, 1, 1]
    assert tests.loc["epochs_to_0.9", ["config_mean", "versus_mean"]].tolist() == [5, 7]  # 1, never, never: K + 1
    assert (tests["splits"] == 10).all() and tests["smallest_p"].tolist() == pytest.approx([1 / 10] * 6)


@pytest.mark.parametrize("decay, control", [
    (Linear(mean_rate=0.9), Constant(eps=0.9)),  # beta1 solved to 6 decimals: mu 0.89999975
    (Exponential(beta1=0.25, beta2=0.25), Constant(eps=0.869156)),  # summary's 6 decimals
])
def test_a_decay_meets_its_control_at_the_six_decimals_a_user_types(tmp_path, decay, control):
    """A decay whose mu_eps misses the control's by the rounding of a solved beta1 or of summary.csv's mu_eps
    (< 5e-7) is still paired with it, and Fig. 12 draws the two side by side rather than one on the other."""
    from analysis.figures import DODGE, _dodged

    for seed in range(2):
        write_run(tmp_path / f"decay{seed}", make_config(schedule=decay, seed=seed), np.full(6, 0.9 - seed / 10))
        write_run(tmp_path / f"control{seed}", make_config(schedule=control, seed=seed), np.full(6, 0.5 - seed / 10))
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    mu = analysis.summary.set_index("config")["mu_eps"]
    assert 0 < abs(mu.iloc[0] - mu.iloc[1]) < 5e-7
    assert len(analysis.equal_mu_tests) == len(metrics.EQUAL_MU_OUTCOMES)
    arms = mu.reset_index()
    assert abs(_dodged(arms, 1.0).diff().iloc[1]) == pytest.approx(DODGE, rel=1e-3)


def test_each_variant_is_tested_in_both_directions_against_its_configuration_at_the_defaults(tmp_path):
    """HER at precision=bf16 and at update=fast are each paired with HER (the same settings otherwise), not with
    ARCHER (other reward weights) nor with each other; linear b1=0.5 at bf16 has no configuration at the defaults
    to meet. HER's three flat seeds (0.9, 0.8, 0.7) against bf16's two (0.6, 0.5): of the C(5, 3) = 10 splits only
    the observed one puts the three best on HER's side."""
    import dataclasses

    def at(precision: str = "fp32", update: str = "autograd", **settings) -> TrainConfig:
        return dataclasses.replace(make_config(**settings), precision=precision, update=update)

    linear = Linear(beta1=0.5)
    for seed, level in enumerate([0.9, 0.8, 0.7]):
        write_run(tmp_path / f"her{seed}", at(seed=seed), np.full(6, level))
        write_run(tmp_path / f"archer{seed}", at(seed=seed, lambda_h=0.5), np.full(6, 0.1))
    for seed, level in enumerate([0.6, 0.5]):
        write_run(tmp_path / f"bf16-{seed}", at("bf16", seed=seed), np.full(6, level))
        write_run(tmp_path / f"fast{seed}", at(update="fast", seed=seed), np.full(6, 0.8))
        write_run(tmp_path / f"linear-bf16-{seed}", at("bf16", seed=seed, schedule=linear), np.full(6, 0.9))
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    tests = analysis.variant_tests
    assert list(tests.columns) == metrics.VARIANT_COLUMNS
    pairs = tests[["config", "versus", "variant"]].drop_duplicates().astype(str).values.tolist()
    assert pairs == [["HER precision=bf16", "HER", "precision=bf16"], ["HER update=fast", "HER", "update=fast"]]
    bf16 = tests[tests["variant"] == "precision=bf16"].set_index("outcome")
    assert list(bf16.index) == metrics.EQUAL_MU_OUTCOMES
    assert bf16.loc["final", ["config_mean", "versus_mean"]].tolist() == [0.55, 0.8]
    for outcome in ("final", "raw_auc"):
        assert bf16.loc[outcome, ["p_config_better", "p_versus_better"]].tolist() == pytest.approx([1.0, 1 / 10])
    assert (bf16["splits"] == 10).all() and bf16["smallest_p"].tolist() == pytest.approx([1 / 10] * 6)
    runs = analysis.runs.set_index("path")
    assert runs["defaults_id"].nunique() == 3  # HER (with its variants), ARCHER, linear
    assert runs.loc[runs["config"] == "HER precision=bf16", "variant"].eq("precision=bf16").all()


def test_push_summary_equals_hand_values(push_analysis):
    summary = push_analysis.summary.set_index("config")
    # The median seed's average reaches 0.5 at epoch step + 25: HER's (60) at 85, the linear's (50) at 75.
    assert summary.loc["HER", "epochs_to_0.5"] == 85 and summary.loc["linear b1=0.25", "epochs_to_0.5"] == 75
    # Final (epoch 150) averages: HER 1, 1, 1; linear 1, 1, 0.6 (step at 120: 30 of 50 epochs).
    assert summary.loc["linear b1=0.25", "final_median"] == pytest.approx(1.0)
    assert summary.loc["linear b1=0.25", "iqm"] == pytest.approx(stats_trim_mean([1.0, 1.0, 0.6]))
    assert summary.loc["linear b1=0.25", "p_improve_HER"] == pytest.approx(3 / 9)  # 6 ties of 9 pairs
    her_median = np.median([[min(max(k - step, 0), 50) / 50 for k in range(1, 151)] for step in PUSH_STEPS["HER"]],
                           axis=0)
    assert summary.loc["HER", "auc"] == pytest.approx(her_median.mean())


def stats_trim_mean(values: list[float]) -> float:
    """IQM by hand: drop floor(n / 4) values at each end, average the rest."""
    cut = len(values) // 4
    return float(np.mean(sorted(values)[cut:len(values) - cut]))


def test_permutation_tests_equal_an_enumeration_of_every_split_of_the_seeds(push_analysis):
    """Every ordered pair of the three configurations (3 seeds each: 20 splits), each outcome: the share of
    splits whose difference of means is at least the observed one, "better" meaning higher final success
    and fewer epochs, a seed that never reaches a threshold counted as K + 1 = 151 epochs."""
    outcomes = push_analysis.outcomes.merge(push_analysis.runs[["run", "config"]], on="run")
    columns = ["final", "epochs_to_0.5", "epochs_to_0.9", "raw_epochs_to_0.5", "raw_epochs_to_0.9"]
    signed = {config: np.array([[value if column == "final" else -(PUSH_EPOCHS + 1 if pd.isna(value) else value)
                                 for value in group[column]] for column in columns])
              for config, group in outcomes.groupby("config", observed=True)}
    tests = push_analysis.tests.astype({"config": str, "versus": str}).set_index(["config", "versus"])
    assert len(tests) == 6
    for (config, versus), row in tests.iterrows():
        x, y = signed[config], signed[versus]
        pooled = np.concatenate([x, y], axis=1)
        splits = [np.isin(np.arange(6), chosen) for chosen in itertools.combinations(range(6), x.shape[1])]
        observed = x.mean(axis=1) - y.mean(axis=1)
        differences = np.array([pooled[:, chosen].mean(axis=1) - pooled[:, ~chosen].mean(axis=1) for chosen in splits])
        expected = (differences >= observed - 1e-9).mean(axis=0)
        assert row[[f"p_{column}" for column in columns]].tolist() == pytest.approx(expected.tolist()), (config, versus)
    # By hand: the control's raw 0.5 at epochs 46, 56, 71 against HER's 51, 61, 81; of the 20 ways to
    # pick three of the six, 6 sum to at most 46 + 56 + 71 = 173.
    assert tests.loc[("HER eps=0.874375", "HER"), "p_raw_epochs_to_0.5"] == pytest.approx(6 / 20)
    # Every seed of HER reaches 0.9 on its smoothed curve; none of linear's third (step 120): the
    # "never" (151) makes linear worse, not absent.
    assert tests.loc[("HER", "linear b1=0.25"), "p_epochs_to_0.9"] < tests.loc[("linear b1=0.25", "HER"),
                                                                              "p_epochs_to_0.9"]


def test_permutation_p_values_count_every_split_beyond_the_random_tests_reach():
    """8 seeds against 8 (12,870 splits, more than the PERMUTATION_RESAMPLES random ones a random test would draw):
    each p is the exact share of all splits at least (at most) as extreme, counted in fractions; 10 against 10
    (184,756) reaches p = 1 / 184,756 when the sides do not overlap."""
    rng = np.random.default_rng(3)
    x, y = rng.integers(0, 21, (3, 8)) / 20, rng.integers(0, 21, (3, 8)) / 20  # success rates on the 20-episode grid
    p_greater, p_less = metrics.permutation_p_values(x, y)
    for row in range(3):
        pooled = [Fraction(int(round(value * 20)), 20) for value in [*x[row], *y[row]]]
        observed = sum(pooled[:8])
        sums = [sum(pooled[i] for i in chosen) for chosen in itertools.combinations(range(16), 8)]
        assert p_greater[row] == sum(total >= observed for total in sums) / 12870
        assert p_less[row] == sum(total <= observed for total in sums) / 12870
    apart = metrics.permutation_p_values(np.arange(10.0)[None], np.arange(10.0, 20.0)[None])
    assert (apart[0][0], apart[1][0]) == (1.0, 1 / 184756)
    assert metrics.smallest_p_value(10, 10) == 1 / 184756 and metrics.smallest_p_value(10, 10, True) == 2 / 184756


def test_permutation_p_values_draw_random_splits_beyond_exact_splits():
    """12 against 12 (2,704,156 splits, more than EXACT_SPLITS): PERMUTATION_RESAMPLES seeded random splits, so
    p is (splits as extreme + 1) / 10000, the same for the same seed."""
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=(2, 12)), rng.normal(size=(2, 12))
    p_greater, _ = metrics.permutation_p_values(x, y)
    counts = p_greater * (metrics.PERMUTATION_RESAMPLES + 1)
    assert np.allclose(counts, np.round(counts), rtol=0, atol=1e-6)
    assert np.array_equal(p_greater, metrics.permutation_p_values(x, y)[0])
    assert metrics.smallest_p_value(12, 12) == 1 / (metrics.PERMUTATION_RESAMPLES + 1)


def test_permutation_tests_pair_configurations_with_two_seeds_of_one_learner_and_k(tmp_path):
    """HER and linear at K = 6 (two seeds each), HER at K = 8 (two seeds), linear at K = 8 (one seed):
    only the two K = 6 configurations are tested, against each other."""
    linear = Linear(beta1=0.5)
    for seed in (0, 1):
        write_run(tmp_path / f"her6-{seed}", make_config(seed=seed), np.full(6, 0.2 + 0.1 * seed))
        write_run(tmp_path / f"linear6-{seed}", make_config(schedule=linear, seed=seed), np.full(6, 0.9))
        write_run(tmp_path / f"her8-{seed}", make_config(seed=seed, epochs=8), np.full(8, 1.0))
    write_run(tmp_path / "linear8", make_config(schedule=linear, epochs=8), np.full(8, 0.9))
    tests = metrics.analyse(*_tables(tmp_path), WINDOW).tests.set_index(["config", "versus"])
    assert list(tests.index) == [("HER K=6", "linear b1=0.5 K=6"),
                                 ("linear b1=0.5 K=6", "HER K=6")]
    # 0.9, 0.9 against 0.2, 0.3: of the 6 splits only the observed one is as favourable.
    assert tests.loc[("linear b1=0.5 K=6", "HER K=6"), "p_final"] == pytest.approx(1 / 6)
    assert tests.loc[("HER K=6", "linear b1=0.5 K=6"), "p_final"] == pytest.approx(1.0)


def test_permutation_tests_keep_sides_with_equal_means_tied():
    """HER and linear with the same four final successes in another seed order: each side's p for doing
    better is the exact share of the 70 splits whose difference of means is >= 0, counted in fractions
    (float sums in another order differ by ~1e-17, which would break the ties)."""
    finals = ["0.69", "0.32", "0.61", "0.8"]
    linear_order = [2, 0, 3, 1]
    runs = pd.DataFrame({"task": "push", "run": [f"r{i}" for i in range(8)], "learner": "ddpg", "total_epochs": 6,
                         "complete": True, "config": pd.Categorical(["HER"] * 4 + ["linear b1=0.5"] * 4)})
    values = [float(finals[i]) for i in range(4)] + [float(finals[i]) for i in linear_order]
    outcomes = pd.DataFrame({"run": runs["run"], "final": values, **{column: pd.array([3] * 8, dtype="Int64")
                             for column in metrics.RUN_OUTCOME_COLUMNS[1:]}})
    pooled = [Fraction(value) for value in finals * 2]
    splits = list(itertools.combinations(range(8), 4))
    at_least_tied = sum(sum(pooled[i] for i in chosen) >= sum(pooled[:4]) for chosen in splits)
    tests = metrics.permutation_tests(runs, outcomes)
    assert tests["p_final"].tolist() == [pytest.approx(at_least_tied / 70)] * 2
    assert tests["p_epochs_to_0.5"].tolist() == [1.0, 1.0]  # every seed at epoch 3: every split ties
