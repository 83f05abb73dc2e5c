"""The critic's accuracy from the logs (analysis/critic.py): curves over seeds, the bias averaged over
epochs 1-50 and its permutation tests, on tables whose answers are known, and the figure from real logs."""

import numpy as np
import pandas as pd
import pytest

from analysis.critic import bias_tests, critic_curves, integrated_bias

EVALUATED = [1, 2, 5, 10, 20, 30, 50, 75]


def epochs_table(biases: dict[str, list[float]]) -> pd.DataFrame:
    """Runs of one task: config -> one constant real-goal bias per run (hindsight: minus it; moved: 3 x; half the
    hindsight pairs at a return of 0), evaluated at
    EVALUATED, with an unevaluated epoch 3 (NaN) between; q_real_mean = 10 * run + epoch."""
    rows, run = [], 0
    for config, values in biases.items():
        for value in values:
            for epoch in sorted([*EVALUATED, 3]):
                evaluated = epoch != 3
                rows.append({"task": "push", "config": config, "run": run, "epoch": epoch,
                             "bias_real_mean": value if evaluated else np.nan,
                             "bias_hindsight_mean": -value if evaluated else np.nan,
                             "bias_moved_mean": 3 * value if evaluated else np.nan,
                             "bias_hindsight_zero_share": 0.5 if evaluated else np.nan,
                             "q_real_mean": 10.0 * run + epoch, "q_hindsight_mean": -1.0})
            run += 1
    table = pd.DataFrame(rows)
    table["config"] = pd.Categorical(table["config"], categories=list(biases))
    return table


def test_integrated_bias_is_the_time_average_over_epochs_1_to_50():
    epochs = epochs_table({"HER": [2.0]})
    ramp = epochs["epoch"].where(epochs["epoch"] != 3).astype(float)  # bias = epoch: trapezoids are exact
    epochs["bias_real_mean"] = ramp
    table = integrated_bias(epochs)
    assert table.loc[0, "bias_real"] == pytest.approx((50 ** 2 - 1) / 2 / 49)  # integral of k dk / 49 = 25.5
    assert table.loc[0, "bias_hindsight"] == pytest.approx(-2.0) and table.loc[0, "bias_moved"] == pytest.approx(6.0)
    assert np.isnan(integrated_bias(epochs[epochs["epoch"] != 50]).loc[0, "bias_real"])  # not covered: no value


def test_bias_tests_are_exact_two_sided_permutation_tests():
    table = bias_tests(integrated_bias(epochs_table({"HER": [5.0, 6.0, 7.0], "linear": [1.0, 2.0, 3.0]})))
    real = table[table["goal_type"] == "real"].iloc[0]
    assert (real["config"], real["versus"], real["seeds"], real["versus_seeds"]) == ("HER", "linear", 3, 3)
    assert real["difference"] == pytest.approx(4.0)
    assert real["p_two_sided"] == pytest.approx(2 / 20)  # 20 splits of 6 runs into 3 + 3; the two extremes
    tied = bias_tests(integrated_bias(epochs_table({"HER": [1.0, 2.0], "linear": [2.0, 1.0]})))
    assert tied["p_two_sided"].tolist() == [1.0, 1.0, 1.0]  # real, hindsight and moved goals


def test_critic_curves_give_median_and_quartiles_over_seeds():
    curves = critic_curves(epochs_table({"HER": [1.0, 2.0, 4.0]}))
    first = curves[curves["epoch"] == 1].iloc[0]
    assert (first["bias_real_mean_median"], first["bias_real_mean_q25"], first["bias_real_mean_q75"]) == (2.0, 1.5, 3.0)
    assert first["n_seeds"] == 3 and first["q_real_mean_median"] == 11.0
    assert curves.loc[curves["epoch"] == 3, "n_seeds"].tolist() == [0]  # the Q split alone: no evaluation counted


def test_the_report_draws_the_critic_from_real_logs(tmp_path):
    """Two seeds each of two schedules, with bias evaluations: the figure has a panel per measure."""
    from helpers import TINY

    from analysis.figures import critic_figures
    from analysis.load import load_runs
    from analysis.metrics import analyse
    from hersd.contract.compose import compose_train
    from hersd.engine.train import train

    run = [o for o in TINY if o != "bias.epochs=[]"] + ["epochs=2", "quiet=true", "threads=1", "bias.epochs=[1,2]",
                                                        "bias.episodes=1", "bias.hindsight_pairs=2",
                                                        "bias.moved_pairs=2", "bias.return_steps=60",
                                                        f"results_dir={tmp_path}"]
    for schedule in ("schedule=constant", "schedule=paper_linear_050"):
        for seed in (0, 1):
            train(compose_train([*run, schedule, f"seed={seed}"]))
    table = load_runs(tmp_path)
    figures = critic_figures(analyse(table.runs, table.epochs, window=1))
    assert [figure.name for figure in figures] == ["critic_bias"]
    drawn = figures[0].draw()
    assert len(drawn.axes) == 6
    assert "moved to" in drawn.axes[2].get_title() and drawn.axes[3].get_ylim() == (-0.02, 1.02)
    labels = {line.get_label() for line in drawn.axes[0].get_lines()}
    assert "HER" in labels and any(label.startswith("linear") for label in labels)
    from analysis.report import build_report

    result = build_report(tmp_path, out=tmp_path / "report", log=lambda line: None)
    assert 'id="critic_bias"' in result.index.read_text()
    written = pd.read_csv(tmp_path / "report" / "tables" / "bias_evaluations.csv")  # every evaluation, as logged
    assert len(written) == 8 and written.groupby("path")["epoch"].agg(list).tolist() == [[1, 2]] * 4
    logged = table.epochs.dropna(subset=["bias_seconds"]).set_index(["path", "epoch"])
    for column in ("bias_real_mean", "bias_moved_count", "bias_hindsight_zero_share", "bias_seconds"):
        assert written.set_index(["path", "epoch"])[column].to_numpy() == pytest.approx(
            logged.loc[written.set_index(["path", "epoch"]).index, column].to_numpy(float), rel=1e-5, nan_ok=True)
    cost = pd.read_csv(tmp_path / "report" / "tables" / "runs_provenance.csv")
    assert cost["bias_evaluations"].tolist() == [2] * 4 and (cost["bias_percent"] > 0).all()
