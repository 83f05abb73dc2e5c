"""analysis/: loading, metrics against hand-computed values, figures (what they draw), study storages,
the report command."""

from __future__ import annotations

import dataclasses
import itertools
import math
import subprocess
import sys
from fractions import Fraction
from pathlib import Path
from unittest import mock

import matplotlib.colors
import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from analysis import load, metrics
from analysis.figures import (LEGEND_CHARACTERS, mean_rate_figures, composition_figures, config_styles, learning_curve_figures,
                              mep_figures, q_figures)
from analysis.load import config_label, load_runs
from analysis.report import main as report_main
from analysis.synthetic import epoch_records, write_run
from analysis.tables import html_table, markdown_table
from analysis.workers import ForkedMap
from hersd.config import AlgoConfig, MEPConfig, ScheduleConfig, TaskConfig, TrainConfig
from hersd.runlog import RunLogWriter, read_run
from hersd.runstore import config_hash
from analysis.studies import open_study_storage
from hersd.study import StudyStorageError

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


def make_config(task: str = "push", schedule: ScheduleConfig | None = None, seed: int = 0, epochs: int = 6,
                lambda_h: float = 1.0, mep: bool = False) -> TrainConfig:
    return TrainConfig(task=TaskConfig(name=task),
                       algo=AlgoConfig(name="archer" if lambda_h != 1.0 else "her", lambda_h=lambda_h,
                                       mep=MEPConfig(enabled=mep)),
                       schedule=schedule or ScheduleConfig(), seed=seed, epochs=epochs)


@pytest.fixture(scope="module")
def hand_sized(tmp_path_factory) -> Path:
    """HER_SUCCESS (5 seeds) and LINEAR_SUCCESS (2 seeds) on push, 6 epochs each."""
    folder = tmp_path_factory.mktemp("hand_sized")
    for seed, curve in enumerate(HER_SUCCESS):
        write_run(folder / f"her/{seed}", make_config(seed=seed), np.array(curve))
    for seed, curve in enumerate(LINEAR_SUCCESS):
        write_run(folder / f"linear/{seed}", make_config(schedule=ScheduleConfig("linear", beta1=0.5), seed=seed),
                  np.array(curve))
    return folder


@pytest.fixture(scope="module")
def analysed(hand_sized) -> metrics.Analysis:
    table = load_runs(hand_sized)
    return metrics.analyse(table.runs, table.epochs, WINDOW)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    """Two tasks x (HER, ARCHER, two decays with each weight, HER-MEP, linear-MEP) x 2 seeds x 8 epochs."""
    folder = tmp_path_factory.mktemp("sweep")
    variants = [(ScheduleConfig(), 1.0, False), (ScheduleConfig(), 0.5, False), (ScheduleConfig(), 1.0, True),
                (ScheduleConfig("linear", beta1=0.5), 1.0, True)]
    variants += [(schedule, lambda_h, False) for lambda_h in (1.0, 0.5)
                 for schedule in (ScheduleConfig("linear", beta1=0.25), ScheduleConfig("exponential", beta1=0.5, beta2=0.5))]
    rng = np.random.default_rng(1)
    for task in ("push", "slide"):
        for index, (schedule, lambda_h, mep) in enumerate(variants):
            for seed in range(2):
                config = make_config(task, schedule, seed, epochs=8, lambda_h=lambda_h, mep=mep)
                curve = np.clip(np.linspace(0.0, 1.0, 8) * rng.uniform(0.5, 1.0) + rng.normal(0, 0.05, 8), 0, 1)
                write_run(folder / task / f"{index}-{seed}", config, curve)
    return folder


# --- metrics on hand-computed values ---------------------------------------------------------------------------

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


def write_campaign_midway(folder: Path, in_progress: bool = True) -> None:
    """Two complete seeds each of HER and linear b1=0.5; with ``in_progress``, besides them a HER
    seed that succeeds at once (4 of 6 epochs), a linear seed that never does (5 of 6 epochs) and
    a configuration with only an unfinished run (exp, 3 of 6 epochs)."""
    linear, exponential = ScheduleConfig("linear", beta1=0.5), ScheduleConfig("exponential", beta1=0.5, beta2=0.5)
    for seed in (0, 1):
        write_run(folder / f"her{seed}", make_config(seed=seed), np.array(HER_SUCCESS[seed]))
        write_run(folder / f"linear{seed}", make_config(schedule=linear, seed=seed), np.array(LINEAR_SUCCESS[seed]))
    if in_progress:
        write_run(folder / "her2", make_config(seed=2), np.ones(4), complete=False)
        write_run(folder / "linear2", make_config(schedule=linear, seed=2), np.zeros(5), complete=False)
        write_run(folder / "exp0", make_config(schedule=exponential), np.ones(3), complete=False)


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
    assert list(summary.index) == ["HER", "linear b1=0.5"]  # exp has no complete run: no row
    assert summary["seeds"].tolist() == [2, 2] and summary["in_progress"].tolist() == [1, 1]
    assert summary.loc["HER", "final_median"] == pytest.approx((0.8 + 2.6 / 3) / 2)  # seeds 0 and 1 at epoch 6
    assert summary.loc["linear b1=0.5", "p_improve_HER"] == pytest.approx(2 / 4)  # 0.95 beats both, 0.2 neither
    assert list(midway.aggregate["config"]) == ["HER", "linear b1=0.5"]
    assert midway.tests[["config", "versus", "seeds", "versus_seeds"]].values.tolist() == [
        ["HER", "linear b1=0.5", 2, 2], ["linear b1=0.5", "HER", 2, 2]]
    for name in ("summary", "aggregate", "medians", "shares", "q_means", "tests"):
        pd.testing.assert_frame_equal(_comparable(getattr(midway, name)), _comparable(getattr(alone, name)))
    assert (midway.medians["n_seeds"] == 2).all()


def _comparable(table: pd.DataFrame) -> pd.DataFrame:
    """A table without what names the runs left out (their count, the categories of their labels)."""
    return table.drop(columns="in_progress", errors="ignore").astype({"config": str}, errors="ignore")


def test_runs_in_progress_are_drawn_apart_and_labelled_in_the_run_list(tmp_path):
    write_campaign_midway(tmp_path)
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    (figure,) = learning_curve_figures(analysis)
    assert "Thin dashed lines: runs still in progress" in figure.caption
    linear_panel, exp_panel = figure.draw().axes
    lines = {line.get_label(): line for line in linear_panel.get_lines()}
    assert set(lines) == {"HER", "HER (in progress)", "linear b1=0.5", "linear b1=0.5 (in progress)"}
    assert lines["HER (in progress)"].get_ydata().tolist() == [1.0] * 4  # the run's own moving average
    assert lines["HER (in progress)"].get_linewidth() < lines["HER"].get_linewidth()
    assert lines["HER (in progress)"].get_linestyle() == "--"
    assert lines["HER"].get_ydata()[-1] == pytest.approx((0.8 + 2.6 / 3) / 2)  # the complete seeds' median
    exp_lines = {line.get_label() for line in exp_panel.get_lines()}
    assert exp_lines == {"HER", "HER (in progress)", "exp b1=0.5 b2=0.5 (in progress)"}  # drawn, and marked

    assert report_main([str(tmp_path), "--out", str(tmp_path / "report"), "--smooth", str(WINDOW)]) == 0
    runs = pd.read_csv(tmp_path / "report" / "tables" / "runs.csv").set_index("path")
    assert runs.loc["her0/run.mcap", "state"] == "complete"
    assert runs.loc["her2/run.mcap", "state"] == "in progress (epoch 4 of 6)"
    # each run's own numbers, in progress too: her2 succeeds from its first epoch, linear2 never
    assert runs.loc["her2/run.mcap", ["final", "epochs_to_0.9", "raw_epochs_to_0.9"]].tolist() == [1.0, 1, 1]
    assert runs.loc["linear2/run.mcap", ["final", "epochs_to_0.5"]].fillna(-1).tolist() == [0.0, -1]
    assert runs.loc["her0/run.mcap", ["final", "epochs_to_0.5", "raw_epochs_to_0.5"]].tolist() == [0.8, 5, 4]
    page = (tmp_path / "report" / "index.html").read_text(encoding="utf-8")
    assert "in progress (epoch 3 of 6)" in page and "7 runs (3 in progress" in page


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


def test_aggregate_pools_tasks(analysed):
    her = analysed.aggregate[analysed.aggregate["config"] == "HER"].iloc[0]
    assert her["tasks"] == 1 and her["seeds"] == 5
    assert her["iqm"] == pytest.approx((0.5 + 0.8 + 2.6 / 3) / 3)


def test_mean_rate_lines_use_eq10_and_eq11():
    lines = metrics.mean_rate_lines([0.0], total_epochs=4, points=3)  # beta1 = 0, 0.5, 1
    assert lines["exact"].tolist() == pytest.approx([1.0, 1 - 0.5 * (1 + 2 + 3 + 4) / 16, 1 - 10 / 16])
    assert lines["approx"].tolist() == pytest.approx([1.0, 0.75, 0.5])


# --- loading ----------------------------------------------------------------------------------------------------

def test_one_row_per_run_and_epoch_with_config_columns(hand_sized):
    table = load_runs(hand_sized)
    assert len(table.runs) == 7 and len(table.epochs) == 42
    assert not table.skipped
    row = table.epochs[(table.epochs["config"] == "linear b1=0.5") & (table.epochs["epoch"] == 6)].iloc[0]
    assert (row["task"], row["schedule"], row["beta1"], row["total_epochs"], row["complete"]) == ("push", "linear", 0.5, 6, True)
    assert row["relabel_rate"] == pytest.approx(0.5)
    assert row["mu_eps"] == pytest.approx(1 - 0.5 * 21 / 36)


@pytest.mark.parametrize("settings, label", [
    (("constant", 0.8, 0, 0, 1.0, 1.0, False), "HER"),
    (("constant", 0.8, 0, 0, 1.0, 0.5, False), "ARCHER"),
    (("constant", 0.8, 0, 0, 1.0, 1.0, True), "HER-MEP"),
    (("constant", 0.9, 0, 0, 1.0, 1.0, False), "HER eps=0.9"),
    (("linear", 0.8, 0.25, 0, 1.0, 1.0, False), "linear b1=0.25"),
    (("exponential", 0.8, 0.5, -0.5, 1.0, 0.5, False), "exp b1=0.5 b2=-0.5 λh=0.5"),
    (("linear", 0.8, 0.5, 0, 1.0, 1.0, True), "linear b1=0.5-MEP"),
])
def test_config_labels(settings, label):
    assert config_label(*settings) == label


def test_the_run_list_names_the_cpu_a_log_records(tmp_path):
    write_run(tmp_path / "new", make_config(), np.zeros(6), meta={"machine": {"cpu_model": "AMD EPYC", "cpu_cores": 2}})
    write_run(tmp_path / "old", make_config(seed=1), np.zeros(6))  # a log from before the machine was recorded
    assert load_runs(tmp_path).runs.set_index("path")["cpu"].to_dict() == {"new/run.mcap": "AMD EPYC",
                                                                           "old/run.mcap": ""}


def test_runs_sharing_a_label_but_not_a_config_are_told_apart(tmp_path):
    write_run(tmp_path / "a", make_config(epochs=4), np.zeros(4))
    write_run(tmp_path / "b", make_config(epochs=6), np.zeros(6))
    write_run(tmp_path / "c", make_config(seed=1, epochs=6), np.zeros(6))
    labels = load_runs(tmp_path).runs.groupby("config", observed=True)["seed"].apply(list).to_dict()
    assert labels == {"HER (epochs=4)": [0], "HER (epochs=6)": [0, 1]}


def test_a_log_made_before_fields_existed_shares_the_configuration_of_new_logs(tmp_path):
    write_run(tmp_path / "new", make_config(seed=1), np.zeros(6))
    config = dataclasses.asdict(make_config())
    for key in ("learner", "threads", "device"):  # fields added to the schema after runs were made
        del config[key]
    for key in ("window", "eps_min"):
        del config["schedule"][key]
    (tmp_path / "old").mkdir()
    writer = RunLogWriter(tmp_path / "old" / "run.mcap", {
        "run_id": config_hash(config), "config": config, "seed": 0, "versions": {}, "command": "old",
        "start_time": "2024-01-01T00:00:00+0000", "resumed_from_epoch": 0})
    for record in epoch_records(make_config(), np.zeros(6)):
        writer.write_epoch(record)
    writer.finish(6)
    assert config_hash(config) == config_hash(make_config())
    assert list(load_runs(tmp_path).runs["config"]) == ["HER", "HER"]


def test_a_label_spans_tasks_with_different_budgets_and_lookalikes_get_distinct_styles(tmp_path):
    write_run(tmp_path / "reach", make_config(task="reach", epochs=4), np.zeros(4))
    write_run(tmp_path / "push20", make_config(epochs=20), np.zeros(20))
    write_run(tmp_path / "push30", make_config(epochs=30), np.zeros(30))
    table = load_runs(tmp_path)
    labels = table.runs.groupby(["task", "config"], observed=True)["run"].count().to_dict()
    assert labels == {("reach", "HER"): 1, ("push", "HER (epochs=20)"): 1, ("push", "HER (epochs=30)"): 1}
    styles = config_styles(metrics.analyse(table.runs, table.epochs, WINDOW))
    looks = {(style["color"], str(style["linestyle"])) for style in styles.values()}
    assert len(looks) == len(styles) == 3


def _truncate_inside_epoch(path: Path, epoch: int) -> None:
    """Cut the file in the middle of the given epoch's message, as a killed writer leaves it."""
    data = path.read_bytes()
    cut = data.index(b'{"epoch": %d,' % epoch) + 8
    path.write_bytes(data[:cut])


def test_truncated_log_keeps_complete_epochs_and_garbage_is_skipped(tmp_path, capsys):
    path = write_run(tmp_path / "cut", make_config(), np.linspace(0, 1, 6))
    _truncate_inside_epoch(path, 4)
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "run.mcap").write_bytes(b"not an mcap file" * 10)
    table = load_runs(tmp_path)
    run = table.runs.iloc[0]
    assert (run["epochs_done"], run["complete"], run["damaged"]) == (3, False, True)
    assert table.epochs["epoch"].tolist() == [1, 2, 3]
    assert table.epochs["test_success"].tolist() == pytest.approx([0.0, 0.2, 0.4])
    assert table.skipped == ["garbage/run.mcap: not a hersd run log (no run metadata found)"]

    assert report_main([str(tmp_path), "--smooth", "2"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: skipped unreadable log garbage/run.mcap: not a hersd run log (no run metadata found)"]


def test_loaded_epochs_of_complete_truncated_and_resumed_logs(tmp_path):
    """Each completed epoch counts once: a truncated log up to its damage, a resumed run's
    rewritten epoch with its later value."""
    config = make_config(epochs=6)
    write_run(tmp_path / "complete", config, np.linspace(0, 1, 6))
    truncated = write_run(tmp_path / "truncated", config, np.linspace(0, 1, 6))
    _truncate_inside_epoch(truncated, 5)
    resumed = write_run(tmp_path / "resumed", config, np.linspace(0, 0.5, 4), complete=False)
    previous = read_run(resumed)
    writer = RunLogWriter(resumed, {**previous.meta, "resumed_from_epoch": 3}, previous=previous)
    for record in epoch_records(config, np.linspace(0.1, 1.0, 6))[3:]:  # epoch 4 again, then 5 and 6
        writer.write_epoch(record)
    writer.finish(6)
    table = load_runs(tmp_path)
    runs = table.runs.set_index(table.runs["path"].str.split("/").str[0])
    assert runs.loc[["complete", "truncated", "resumed"], ["epochs_done", "complete", "damaged"]].values.tolist() == [
        [6, True, False], [4, False, True], [6, True, False]]
    resumed_epochs = table.epochs[table.epochs["path"] == "resumed/run.mcap"]
    assert resumed_epochs["epoch"].tolist() == [1, 2, 3, 4, 5, 6]
    assert resumed_epochs["test_success"].iloc[3] == pytest.approx(0.64)  # the rewrite, not 0.5


# --- the command ------------------------------------------------------------------------------------------------

def test_empty_folder_is_one_line_error_exit_2(tmp_path, capsys):
    assert exit_status([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no run.mcap files under" in err


def exit_status(arguments: list[str]) -> int:
    """hersd-report's exit status, whether main returns it or argparse exits with it."""
    try:
        return report_main(arguments)
    except SystemExit as exited:
        return exited.code


@pytest.mark.parametrize("arguments, message", [
    (["--smooth", "0"], "--smooth must be at least 1"),
    (["--task", "reach"], "no run matches the filters"),
    (["--format", "gif"], "invalid choice"),
])
def test_bad_options_are_one_line_errors(hand_sized, capsys, tmp_path, arguments, message):
    assert exit_status([str(hand_sized), "--out", str(tmp_path), *arguments]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_report_writes_tables_figures_and_self_contained_html(sweep, tmp_path, capsys):
    out = tmp_path / "report"
    assert report_main([str(sweep), "--out", str(out), "--smooth", "3"]) == 0
    printed = capsys.readouterr().out
    assert "loaded 32 runs (0 incomplete, 0 skipped)" in printed and str(out / "index.html") in printed
    figures = sorted(path.stem for path in (out / "figures").glob("*.png"))
    assert figures == sorted(["schedules", "composition_push", "composition_slide", "curves_push_lr1_lh1",
                              "curves_push_lr1_lh0.5", "curves_slide_lr1_lh1", "curves_slide_lr1_lh0.5", "q_mean",
                              "mep", "mean_rate_push", "mean_rate_slide"])
    page = (out / "index.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == len(figures)
    assert "<img" in page and 'src="figures/' not in page
    summary = pd.read_csv(out / "tables" / "summary.csv")
    assert len(summary) == 2 * 8 and set(summary["seeds"]) == {2}
    assert (out / "tables" / "summary.md").read_text(encoding="utf-8").startswith("| task | config |")
    runs = pd.read_csv(out / "tables" / "runs.csv")
    assert len(runs) == 32 and page.count("run.mcap") >= 32
    tests = pd.read_csv(out / "tables" / "permutation_tests.csv")
    assert len(tests) == 2 * 8 * 7  # per task, every ordered pair of its 8 configurations
    assert "112 tests: too many for this page; they are in tables/permutation_tests.md" in page


def test_the_report_page_shows_a_short_list_of_permutation_tests(tmp_path):
    write_campaign_midway(tmp_path / "logs")
    assert report_main([str(tmp_path / "logs"), "--out", str(tmp_path / "report")]) == 0
    page = (tmp_path / "report" / "index.html").read_text(encoding="utf-8")
    assert "<h2>Permutation tests between configurations</h2>" in page and "<th>p_final</th>" in page
    tests = (tmp_path / "report" / "tables" / "permutation_tests.md").read_text(encoding="utf-8")
    assert tests.splitlines()[2].startswith("| push | HER | linear b1=0.5 | 2 | 2 |")


def test_report_filters_and_svg(sweep, tmp_path):
    out = tmp_path / "svg"
    assert report_main([str(sweep), "--out", str(out), "--task", "slide", "--algo", "her", "--format", "svg"]) == 0
    assert {path.suffix for path in (out / "figures").iterdir()} == {".svg"}
    summary = pd.read_csv(out / "tables" / "summary.csv")
    assert set(summary["task"]) == {"slide"}
    assert not summary["config"].str.contains("λh").any() and "ARCHER" not in set(summary["config"])
    assert "data:image/svg+xml;base64," in (out / "index.html").read_text(encoding="utf-8")


def test_no_figure_without_its_data(hand_sized):
    table = load_runs(hand_sized)
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    assert mep_figures(analysis) == []  # no MEP run
    assert len(q_figures(analysis)) == 1
    her_only = metrics.analyse(table.runs[table.runs["config"] == "HER"],
                               table.epochs[table.epochs["config"] == "HER"], WINDOW)
    assert q_figures(her_only) == []  # nothing to compare HER with


def test_report_runs_without_torch_mujoco_or_the_sweeps_layer(sweep, tmp_path):
    # A finder that refuses these packages, in this process and in the report's forked workers:
    # importing one anywhere fails the report. (Setting sys.modules['torch'] = None would also
    # block the import, but scipy's array-API helpers then trip over the None entry.)
    script = (
        "import sys\n"
        "BLOCKED = ('torch', 'mujoco', 'gymnasium_robotics', 'gymnasium', 'sweeps')\n"
        "class Refuse:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in BLOCKED:\n"
        "            raise ImportError(f'{name} is blocked in this test')\n"
        "sys.meta_path.insert(0, Refuse())\n"
        "import analysis.report\n"
        f"sys.exit(analysis.report.main([{str(sweep)!r}, '--out', {str(tmp_path / 'out')!r}, '--task', 'push']))\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert len(list((tmp_path / "out" / "figures").glob("*.png"))) == 7  # drawn in forked workers too


def test_importing_the_report_loads_neither_the_sweeps_layer_nor_heavy_modules():
    code = ("import sys, analysis, analysis.report\n"
            "print(sorted(m for m in ('sweeps', 'torch', 'mujoco', 'optuna', 'matplotlib', 'scipy.stats') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"  # optuna, matplotlib and scipy.stats come only when drawing or computing


def test_learners_lead_their_labels_and_success_schedules_sit_at_their_realised_mean_rate(tmp_path):
    from hersd.config import LearnerConfig

    curve = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    write_run(tmp_path / "ddpg", make_config(), curve)
    td3 = make_config()
    td3.learner = LearnerConfig(name="td3")
    write_run(tmp_path / "td3", td3, curve)
    success = make_config(schedule=ScheduleConfig(kind="success", beta1=0.5, window=1))
    write_run(tmp_path / "success", success, curve)
    runs = load_runs(tmp_path).runs.set_index("config")
    assert list(runs.index) == ["HER", "success b1=0.5", "TD3 HER"]  # DDPG first, schedules in their order
    assert runs.loc["TD3 HER", "learner"] == "td3" and runs.loc["HER", "learner"] == "ddpg"
    logged = read_run(tmp_path / "success" / "run.mcap").epochs["relabel_rate"]
    assert list(logged) == pytest.approx([1.0, 1.0, 0.91, 0.82, 0.73, 0.64])  # 1 - 0.5 * last epoch's train success
    assert runs.loc["success b1=0.5", "mu_eps"] == pytest.approx(logged.mean())


@pytest.mark.parametrize("with_success", [False, True])
def test_the_mean_rate_figure_names_the_marker_kinds_it_draws(tmp_path, with_success):
    curve = np.linspace(0.0, 1.0, 6)
    write_run(tmp_path / "her", make_config(), curve)
    write_run(tmp_path / "linear", make_config(schedule=ScheduleConfig("linear", beta1=0.5)), curve)
    if with_success:
        write_run(tmp_path / "success", make_config(schedule=ScheduleConfig(kind="success", beta1=0.5)), curve)
    table = load_runs(tmp_path)
    figure = mean_rate_figures(metrics.analyse(table.runs, table.epochs, WINDOW))[0].draw()
    labels = [text.get_text().replace("\n", " ") for text in figure.legends[0].get_texts()]
    markers = [label for label in labels if label.startswith(("decay schedule", "success-driven"))]
    assert markers == ["decay schedule (eq. 10 μ_ε)"] + (
        ["success-driven rate (median over seeds of μ_ε)"] if with_success else [])
    drawn = [collection for collection in figure.axes[0].collections if len(collection.get_offsets())]
    assert [len(collection.get_offsets()) for collection in drawn] == [1] * (1 + with_success)  # circles, diamonds


def test_the_success_driven_rate_sits_at_the_median_of_its_complete_seeds_mean_rates(tmp_path):
    """Each seed of a success-driven rate logs its own rates; the diamond sits at the median over
    the complete seeds of each seed's mean rate, an unfinished seed left out."""
    success = ScheduleConfig(kind="success", beta1=0.5, window=1)
    curves = {0: [0.0] * 6, 1: [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], 2: [1.0] * 6}
    for seed, curve in curves.items():
        write_run(tmp_path / f"success{seed}", make_config(schedule=success, seed=seed), np.array(curve))
    write_run(tmp_path / "success3", make_config(schedule=success, seed=3), np.ones(3), complete=False)
    table = load_runs(tmp_path)
    rates = table.runs.set_index("seed")["mu_eps"]
    assert rates[0] > rates[1] > rates[2] and rates[3] < rates[1]  # the seeds' rates differ
    figure = mean_rate_figures(metrics.analyse(table.runs, table.epochs, WINDOW))[0].draw()
    drawn = [collection for collection in figure.axes[0].collections if len(collection.get_offsets())]
    assert [tuple(point) for point in drawn[0].get_offsets()] == [(0.5, pytest.approx(rates[1]))]




def test_each_config_is_compared_with_the_her_runs_of_its_own_learner_and_k(tmp_path):
    """A folder holding HER at K = 6 and K = 8 (labels "HER (epochs=6)", "HER (epochs=8)") and TD3
    runs: each configuration's P(improve on HER) uses the HER seeds of the same learner and K."""
    from hersd.config import LearnerConfig

    def td3(config: TrainConfig) -> TrainConfig:
        config.learner = LearnerConfig(name="td3")
        return config

    linear = ScheduleConfig("linear", beta1=0.5)
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
    assert p_improve["HER (epochs=8)"] == 0.5 and p_improve["TD3 HER"] == 0.5
    assert analysis.aggregate.set_index("config")["p_improve_HER"]["linear b1=0.5"] == 1.0

# --- the FetchPush comparison of the paper (Figs. 2, 4, 10 and the summary) ---------------------------------------

# Test success per seed: 0 until the step epoch, 1 after it, so the 50-epoch moving average at epoch
# k > step is min(k - step, 50) / 50 (the window holds k - step successes).
PUSH_STEPS = {"HER": (50, 60, 80), "linear b1=0.25": (40, 50, 120), "HER eps=0.874375": (45, 55, 70)}
PUSH_SCHEDULES = {"HER": ScheduleConfig(), "linear b1=0.25": ScheduleConfig("linear", beta1=0.25),
                  "HER eps=0.874375": ScheduleConfig(eps=0.874375)}
# HER's minibatch shares at epoch 150 per seed (real successful, hindsight, real unsuccessful):
# medians 0.06, 0.80, 0.14, which already sum to 1.
HER_SHARES_150 = [(0.02, 0.80, 0.18), (0.06, 0.80, 0.14), (0.09, 0.80, 0.11)]
PUSH_EPOCHS = 150


@pytest.fixture(scope="module")
def push_paper(tmp_path_factory) -> Path:
    """The shape of conf/grid/push_paper.yaml: FetchPush HER, linear b1=0.25 and the constant
    control at the linear schedule's mean rate, 3 seeds x 150 epochs (PUSH_STEPS curves)."""
    folder = tmp_path_factory.mktemp("push_paper")
    with mock.patch("os.fsync"):  # the writer's crash safety is not under test; the bytes are the same
        for label, steps in PUSH_STEPS.items():
            for seed, step in enumerate(steps):
                curve = (np.arange(1, PUSH_EPOCHS + 1) > step).astype(float)
                shares = {}
                if label == "HER":
                    success, hindsight, failure = HER_SHARES_150[seed]
                    shares = dict(share_real_success=np.full(PUSH_EPOCHS, success),
                                  share_hindsight=np.full(PUSH_EPOCHS, hindsight),
                                  share_real_failure=np.full(PUSH_EPOCHS, failure))
                write_run(folder / label / str(seed), make_config(schedule=PUSH_SCHEDULES[label], seed=seed,
                                                                  epochs=PUSH_EPOCHS), curve, **shares)
    return folder


@pytest.fixture(scope="module")
def push_analysis(push_paper) -> metrics.Analysis:
    table = load_runs(push_paper)
    return metrics.analyse(table.runs, table.epochs, window=50)


def test_fig4_draws_the_median_of_50_epoch_averages_and_the_range_over_seeds(push_analysis):
    (figure,) = learning_curve_figures(push_analysis)
    assert figure.name == "curves_push_lr1_lh1" and "vs HER and HER eps=0.874375" in figure.title
    axes = figure.draw().axes
    assert len(axes) == 1 and axes[0].get_title() == "linear decay (β2 = 0)"
    axis = axes[0]
    lines = {line.get_label(): line for line in axis.get_lines()}
    assert set(lines) == {"HER", "HER eps=0.874375", "linear b1=0.25"}
    her = lines["HER"]
    # Epoch 100: HER's seeds (steps 50, 60, 80) average 50/50, 40/50 and 20/50 over epochs 51..100.
    assert her.get_xdata()[99] == 100 and her.get_ydata()[99] == pytest.approx(0.8)
    band = next(c for c in axis.collections if np.allclose(c.get_facecolor()[0][:3], matplotlib.colors.to_rgb(
        her.get_color())))
    at_100 = band.get_paths()[0].vertices
    assert sorted(set(np.round(at_100[at_100[:, 0] == 100][:, 1], 9))) == pytest.approx([0.4, 1.0])


def test_fig10_draws_the_mean_q_over_seeds(push_analysis):
    (figure,) = q_figures(push_analysis)
    axis = figure.draw().axes[0]
    her = next(line for line in axis.get_lines() if line.get_label() == "HER")
    # Synthetic q_mean is -10 (1 - success) - 1: at epoch 70 two HER seeds succeed (-1), one not (-11).
    assert her.get_ydata()[69] == pytest.approx(-13 / 3)
    assert {line.get_label() for line in axis.get_lines()} == set(PUSH_STEPS)


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


def test_permutation_tests_pair_configurations_with_two_seeds_of_one_learner_and_k(tmp_path):
    """HER and linear at K = 6 (two seeds each), HER at K = 8 (two seeds), linear at K = 8 (one seed):
    only the two K = 6 configurations are tested, against each other."""
    linear = ScheduleConfig("linear", beta1=0.5)
    for seed in (0, 1):
        write_run(tmp_path / f"her6-{seed}", make_config(seed=seed), np.full(6, 0.2 + 0.1 * seed))
        write_run(tmp_path / f"linear6-{seed}", make_config(schedule=linear, seed=seed), np.full(6, 0.9))
        write_run(tmp_path / f"her8-{seed}", make_config(seed=seed, epochs=8), np.full(8, 1.0))
    write_run(tmp_path / "linear8", make_config(schedule=linear, epochs=8), np.full(8, 0.9))
    tests = metrics.analyse(*_tables(tmp_path), WINDOW).tests.set_index(["config", "versus"])
    assert list(tests.index) == [("HER (epochs=6)", "linear b1=0.5 (epochs=6)"),
                                 ("linear b1=0.5 (epochs=6)", "HER (epochs=6)")]
    # 0.9, 0.9 against 0.2, 0.3: of the 6 splits only the observed one is as favourable.
    assert tests.loc[("linear b1=0.5 (epochs=6)", "HER (epochs=6)"), "p_final"] == pytest.approx(1 / 6)
    assert tests.loc[("HER (epochs=6)", "linear b1=0.5 (epochs=6)"), "p_final"] == pytest.approx(1.0)


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


def stats_trim_mean(values: list[float]) -> float:
    """IQM by hand: drop floor(n / 4) values at each end, average the rest."""
    cut = len(values) // 4
    return float(np.mean(sorted(values)[cut:len(values) - cut]))


def test_composition_at_epoch_150_beside_the_papers(push_paper, tmp_path):
    out = tmp_path / "report"
    assert report_main([str(push_paper), "--out", str(out)]) == 0
    table = pd.read_csv(out / "tables" / "composition_150.csv")
    assert list(table.columns) == ["source", "config", "seeds", "epoch", "share_real_success", "share_hindsight",
                                   "share_real_failure"]
    paper, ours = table.to_dict("records")
    assert (paper["source"], paper["config"], paper["epoch"]) == ("paper (Fig. 2)", "HER", 150)
    assert [paper[c] for c in table.columns[4:]] == pytest.approx([0.053, 0.80, 0.147])
    assert (ours["source"], ours["config"], ours["seeds"], ours["epoch"]) == ("hersd", "HER", 3, 150)
    assert [ours[c] for c in table.columns[4:]] == pytest.approx([0.06, 0.80, 0.14])  # medians of HER_SHARES_150
    page = (out / "index.html").read_text(encoding="utf-8")
    figure_at, table_at = page.index('id="composition_push"'), page.index("epoch 150: hersd vs paper")
    assert figure_at < table_at < page.index("<figure", figure_at + 1)  # right after its figure
    (composition,) = composition_figures(metrics.analyse(*_tables(push_paper), window=50))
    her_panel = composition.draw().axes[0]
    assert her_panel.get_title() == "HER" and [150, 150] in [list(line.get_xdata()) for line in her_panel.get_lines()]


def _tables(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    table = load_runs(folder)
    return table.runs, table.epochs


def test_no_composition_table_without_her_runs_that_reached_epoch_150(push_paper, sweep, tmp_path):
    assert report_main([str(sweep), "--out", str(tmp_path / "short"), "--task", "push"]) == 0  # 8 epochs
    assert not (tmp_path / "short" / "tables" / "composition_150.csv").exists()
    runs, epochs = _tables(push_paper)
    others = metrics.analyse(runs[runs["config"] != "HER"], epochs[epochs["config"] != "HER"], window=50)
    assert others.composition_vs_paper.empty  # the constant control (eps 0.874375) is not HER


# --- readability ----------------------------------------------------------------------------------------------------

def test_long_labels_are_wrapped_and_stay_inside_the_figure(tmp_path):
    for threshold in (None, 0.07):
        for schedule in (ScheduleConfig(), ScheduleConfig("linear", beta1=0.25)):
            config = make_config(schedule=schedule, epochs=6)
            config.task.distance_threshold = threshold
            write_run(tmp_path / f"{threshold}-{schedule.kind}", config, np.linspace(0, 1, 6))
    analysis = metrics.analyse(*_tables(tmp_path), window=WINDOW)
    assert "linear b1=0.25 (task.distance_threshold=0.07)" in set(analysis.runs["config"])
    for report_figure in learning_curve_figures(analysis) + composition_figures(analysis):
        figure = report_figure.draw()
        canvas = FigureCanvasAgg(figure)  # what savefig draws on
        canvas.draw()
        renderer = canvas.get_renderer()
        texts = [text for legend in figure.legends for text in legend.get_texts()]
        texts += [axis.title for axis in figure.axes] + [figure._suptitle]
        for text in texts:
            box = text.get_window_extent(renderer)
            assert 0 <= box.x0 and box.x1 <= figure.bbox.x1, (report_figure.name, text.get_text())
        assert all(len(line) <= LEGEND_CHARACTERS for legend in figure.legends for text in legend.get_texts()
                   for line in text.get_text().splitlines())
        for axis in figure.axes:  # a panel title no wider than its panel and the gaps beside it
            assert axis.title.get_window_extent(renderer).width <= 1.1 * axis.get_window_extent(renderer).width


def test_tables_leave_missing_values_empty():
    table = pd.DataFrame({"config": ["HER"], "epochs_to_0.9": pd.array([pd.NA], dtype="Int64"), "auc": [float("nan")],
                          "iqm": [0.12345]})
    assert markdown_table(table).splitlines()[2] == "| HER |  |  | 0.123 |"
    assert html_table(table).count("<td></td>") == 2 and "NA" not in html_table(table)
    assert "<td class=text>HER</td>" in html_table(table)


# --- worker processes -------------------------------------------------------------------------------------------

def test_forked_jobs_give_the_results_in_order_and_raise_their_errors():
    items = list(range(12))
    assert ForkedMap(lambda x: x * x, items, workers=2).results() == [x * x for x in items]
    assert ForkedMap(lambda x: x + 1, items, workers=1).results() == [x + 1 for x in items]  # in this process
    with pytest.raises(ZeroDivisionError):
        ForkedMap(lambda x: 1 / (x - 3), items, workers=2).results()


def test_logs_read_in_worker_processes_give_the_same_tables(sweep, monkeypatch):
    here = load_runs(sweep)  # 32 logs: fewer than load.PARALLEL_FROM, read in this process
    monkeypatch.setattr(load, "PARALLEL_FROM", 2)
    forked = load_runs(sweep)
    pd.testing.assert_frame_equal(forked.runs, here.runs)
    pd.testing.assert_frame_equal(forked.epochs, here.epochs)


# --- Optuna study storages --------------------------------------------------------------------------------------

def _make_study(storage, name: str) -> None:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name=name, storage=storage, direction="maximize")
    study.enqueue_trial({"beta1": 0.25, "beta2": 0.0})
    study.optimize(lambda trial: trial.suggest_float("beta1", 0, 1) + trial.suggest_float("beta2", -1, 1), n_trials=3)


@pytest.fixture(scope="module")
def storages(tmp_path_factory) -> Path:
    """study.db (SQLite, study "in_sqlite"), study.log (journal, "in_journal"), no_study.db (Optuna's
    tables, no study), plain.db (a SQLite file of another program), notes.log (not a journal)."""
    import optuna
    import sqlite3
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    folder = tmp_path_factory.mktemp("storages")
    _make_study(f"sqlite:///{folder / 'study.db'}", "in_sqlite")
    _make_study(JournalStorage(JournalFileBackend(str(folder / "study.log"))), "in_journal")
    optuna.storages.RDBStorage(f"sqlite:///{folder / 'no_study.db'}").remove_session()
    with sqlite3.connect(folder / "plain.db") as connection:
        connection.execute("CREATE TABLE notes (text)")
    (folder / "notes.log").write_text("not a journal\n")
    return folder


def _bad_storages(folder: Path) -> list[tuple[str, str]]:
    cases = [("foo://nowhere", "foo://nowhere: not a storage URL"),
             ("/no/such/study.db", "/no/such/study.db: no such study storage"),
             (f"sqlite:///{folder / 'no_study.db'}", "no Optuna study in this storage"),
             (str(folder / "plain.db"), f"{folder / 'plain.db'}: no Optuna study in this storage"),
             (f"journal:{folder / 'notes.log'}", "not a readable Optuna journal")]
    return cases


@pytest.mark.parametrize("case", range(5))
def test_a_bad_storage_is_one_line_and_exit_2_before_any_log_is_read(hand_sized, storages, tmp_path, capsys, case):
    storage, message = _bad_storages(storages)[case]
    assert report_main([str(hand_sized), "--out", str(tmp_path / "out"), "--storage", storage]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hersd-report: error: --storage ") and message in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("url", ["postgresql+psycopg2://user:secret@127.0.0.1:1/none",
                                 "postgresql://user:secret@127.0.0.1:1/none"])  # psycopg2 for the bare scheme
def test_an_unreachable_database_is_one_line_without_its_password(hand_sized, tmp_path, capsys, monkeypatch, url):
    pytest.importorskip("psycopg2")  # hersd[cluster]
    monkeypatch.setitem(sys.modules, "psycopg", None)  # SQLAlchemy's default driver for postgresql://, not installed
    assert report_main([str(hand_sized), "--out", str(tmp_path), "--storage", url]) == 2  # nothing listens on port 1
    err = capsys.readouterr().err
    shown = url.replace("secret", "***")
    assert err.count("\n") == 1 and f"cannot reach the database at {shown} (connection to server" in err, err
    assert "secret" not in err


def test_a_missing_database_driver_says_what_to_install(hand_sized, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "psycopg2", None)  # as if not installed
    assert report_main([str(hand_sized), "--out", str(tmp_path), "--storage", "postgresql+psycopg2://u@db/x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and 'the database driver is missing (psycopg2); pip install "hersd[cluster]"' in err


def _files(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {path.name: (path.read_bytes(), path.stat().st_mtime_ns) for path in folder.iterdir()}


def test_storages_are_opened_read_only(storages):
    before = _files(storages)
    for spec in ("study.db", "study.log"):
        opened = open_study_storage(storages / spec)
        assert opened.study_names == ["in_sqlite" if spec.endswith(".db") else "in_journal"]
        import optuna

        assert len(optuna.load_study(study_name=opened.study_names[0], storage=opened.storage).trials) == 3
    with pytest.raises(StudyStorageError):  # refused before Optuna could create its tables
        open_study_storage(storages / "plain.db")
    assert _files(storages) == before  # not a byte, not a time stamp, no new file (no -journal, -wal, .lock)


def test_given_storages_are_drawn(hand_sized, storages, tmp_path, capsys):
    out = tmp_path / "out"
    assert report_main([str(hand_sized), "--out", str(out), "--storage", f"sqlite:///{storages / 'study.db'}",
                        "--storage", f"journal:{storages / 'study.log'}"]) == 0
    assert sorted(path.name for path in (out / "search").iterdir()) == sorted(
        f"{name}_{suffix}" for name in ("in_sqlite", "in_journal")
        for suffix in ("beta_plane.png", "best_trials.csv", "best_trials.md"))
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "Optuna searches" in page and "Best trials: in_journal" in page and "Best trials: in_sqlite" in page
    assert capsys.readouterr().err == ""


def test_storages_in_the_search_folder_are_found_and_a_bad_one_is_skipped(storages, tmp_path, capsys):
    write_run(tmp_path / "run", make_config(), np.linspace(0, 1, 6))
    (tmp_path / "search").mkdir()
    for name in ("study.db", "study.log", "plain.db"):
        (tmp_path / "search" / name).write_bytes((storages / name).read_bytes())
    assert report_main([str(tmp_path), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err.splitlines()
    plain = tmp_path / "search" / "plain.db"
    assert err == [f"warning: skipped study storage {plain}: no Optuna study in this storage"]
    assert {path.name for path in (tmp_path / "out" / "search").glob("*.png")} == {
        "in_sqlite_beta_plane.png", "in_journal_beta_plane.png"}
    assert "study storage" in (tmp_path / "out" / "index.html").read_text(encoding="utf-8")


def test_the_search_figures_command_reports_a_bad_storage_in_one_line(storages, tmp_path, capsys):
    from analysis.search_figures import main as search_figures_main

    assert search_figures_main([str(storages / "plain.db"), str(tmp_path)]) == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path), "--study", "other"]) == 2
    assert capsys.readouterr().err.count("\n") == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path)]) == 0
