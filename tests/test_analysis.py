"""analysis/: loading, metrics against hand-computed values, figures, the report command."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import metrics
from analysis.figures import config_styles, mep_figures, q_figures
from analysis.load import config_label, load_runs
from analysis.report import main as report_main
from analysis.synthetic import epoch_records, write_run
from hersd.config import AlgoConfig, MEPConfig, ScheduleConfig, TaskConfig, TrainConfig
from hersd.runlog import RunLogWriter, read_records, read_run

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
    assert her["seeds"] == 5 and her["complete"] == 5 and her["horizon"] == 6
    assert her["final_median"] == pytest.approx(0.8)
    assert her["auc"] == pytest.approx(sum(HER_MEDIAN) / 6)  # (0 + .15 + .3 + .5333 + .6 + .8) / 6 = 0.39722
    assert her["auc"] == pytest.approx(0.397222, abs=1e-6)
    assert her["epochs_to_0.5"] == 4
    assert pd.isna(her["epochs_to_0.9"])  # never reached: an empty cell
    assert her["iqm"] == pytest.approx((0.5 + 0.8 + 2.6 / 3) / 3)  # drop 0.4 and 1.0
    assert her["iqm_low"] <= her["iqm"] <= her["iqm_high"]
    assert her["p_improve_HER"] == pytest.approx(0.5)
    linear = analysed.summary[analysed.summary["config"] == "linear b1=0.5"].iloc[0]
    assert linear["final_median"] == pytest.approx(0.575)
    assert linear["epochs_to_0.5"] == 1
    # 0.95 beats four of the five HER finals (not 1.0); 0.2 beats none.
    assert linear["p_improve_HER"] == pytest.approx(4 / 10)


def test_unfinished_seed_sets_the_horizon(tmp_path):
    for seed in (0, 1):
        write_run(tmp_path / str(seed), make_config(seed=seed), np.array(HER_SUCCESS[seed]))
    write_run(tmp_path / "2", make_config(seed=2), np.array(HER_SUCCESS[2][:4]), complete=False)  # still running
    table = load_runs(tmp_path)
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    row = analysis.summary.iloc[0]
    assert (row["seeds"], row["complete"], row["horizon"]) == (3, 2, 4)
    assert row["final_median"] == pytest.approx(0.3)  # smoothed at epoch 4: 0.3, 0.5333, 0.1
    assert row["auc"] == pytest.approx((0 + 0 + 0.1 + 0.3) / 4)  # medians 0, 0, 0.1, 0.3
    assert analysis.medians["n_seeds"].tolist() == [3, 3, 3, 3, 2, 2]


def test_probability_of_improvement_counts_ties_half():
    assert metrics.probability_of_improvement(np.array([0.5, 0.8]), np.array([0.5, 0.4, 0.9])) == pytest.approx(3.5 / 6)


def test_first_epoch_reaching_is_nan_when_never_reached():
    epochs = np.array([1, 2, 3])
    assert metrics.first_epoch_reaching(epochs, np.array([0.1, 0.5, 0.7]), 0.5) == 2
    assert math.isnan(metrics.first_epoch_reaching(epochs, np.array([0.1, 0.2, 0.3]), 0.5))


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


def test_runs_sharing_a_label_but_not_a_config_are_told_apart(tmp_path):
    write_run(tmp_path / "a", make_config(epochs=4), np.zeros(4))
    write_run(tmp_path / "b", make_config(epochs=6), np.zeros(6))
    write_run(tmp_path / "c", make_config(seed=1, epochs=6), np.zeros(6))
    labels = load_runs(tmp_path).runs.groupby("config", observed=True)["seed"].apply(list).to_dict()
    assert labels == {"HER (epochs=4)": [0], "HER (epochs=6)": [0, 1]}


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


def test_record_reader_agrees_with_read_run(tmp_path):
    """read_records (used by the loader, no per-file DataFrame) must agree with read_run."""
    config = make_config(epochs=6)
    complete = write_run(tmp_path / "complete", config, np.linspace(0, 1, 6))
    truncated = write_run(tmp_path / "truncated", config, np.linspace(0, 1, 6))
    _truncate_inside_epoch(truncated, 5)
    resumed = write_run(tmp_path / "resumed", config, np.linspace(0, 0.5, 4), complete=False)
    previous = read_run(resumed)
    writer = RunLogWriter(resumed, {**previous.meta, "resumed_from_epoch": 3}, previous=previous)
    for record in epoch_records(config, np.linspace(0.1, 1.0, 6))[3:]:  # epoch 4 again, then 5 and 6
        writer.write_epoch(record)
    writer.finish(6)
    for path in (complete, truncated, resumed):
        expected, got = read_run(path), read_records(path)
        assert (got.meta, got.complete, got.damaged) == (expected.meta, expected.complete, expected.damaged)
        pd.testing.assert_frame_equal(pd.DataFrame.from_records(got.records, columns=expected.epochs.columns)
                                      .astype(expected.epochs.dtypes), expected.epochs)
    assert read_records(resumed).records[3]["test_success"] == pytest.approx(0.64)  # the rewrite, not 0.5


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


def test_report_runs_without_torch_or_mujoco(sweep, tmp_path):
    # A finder that refuses the heavy packages. (Setting sys.modules['torch'] = None would also block
    # the import, but scipy's array-API helpers then trip over the None entry.)
    script = (
        "import sys\n"
        "BLOCKED = ('torch', 'mujoco', 'gymnasium_robotics', 'gymnasium')\n"
        "class Refuse:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in BLOCKED:\n"
        "            raise ImportError(f'{name} is blocked in this test')\n"
        "sys.meta_path.insert(0, Refuse())\n"
        "import analysis.report\n"
        f"status = analysis.report.main([{str(sweep)!r}, '--out', {str(tmp_path / 'out')!r}, '--task', 'push'])\n"
        "assert not any(name.split('.')[0] in BLOCKED for name in sys.modules), 'a blocked package was imported'\n"
        "sys.exit(status)\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "out" / "index.html").exists()


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


@pytest.mark.parametrize("storage, message", [
    ("foo://nowhere", "not a storage URL"),
    ("postgresql+psycopg2://user@127.0.0.1:1/none", "cannot reach the database at 127.0.0.1:1/none"),
    ("/no/such/study.db", "no such study storage"),
])
def test_a_bad_study_storage_is_one_line_with_exit_2(hand_sized, tmp_path, capsys, storage, message):
    import importlib.util

    if storage.startswith("postgresql") and importlib.util.find_spec("psycopg2") is None:
        message = "the database driver is missing"
    assert report_main([str(hand_sized), "--out", str(tmp_path / "out"), "--storage", storage]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err, err


def test_a_study_storage_given_on_the_command_line_is_drawn(hand_sized, tmp_path):
    import optuna

    storage = f"sqlite:///{tmp_path / 'elsewhere.sqlite'}"
    study = optuna.create_study(study_name="given", storage=storage, direction="maximize")
    study.enqueue_trial({"beta1": 0.25, "beta2": 0.0})
    study.optimize(lambda trial: trial.suggest_float("beta1", 0, 1) + trial.suggest_float("beta2", -1, 1), n_trials=3)
    assert report_main([str(hand_sized), "--out", str(tmp_path / "out"), "--storage", storage]) == 0
    assert (tmp_path / "out" / "search" / "given_beta_plane.png").exists()
    assert "given" in (tmp_path / "out" / "index.html").read_text()
