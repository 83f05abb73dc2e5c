"""analysis/search_figures.py: the study figures command; a search over any settings, drawn and tabled."""

from __future__ import annotations

import sys

import numpy as np
import optuna
import pandas as pd
import pytest
from analysis_logs import make_config
from helpers import full_disk_writes
from matplotlib.text import Text
from user_schedules import MODULE, write_module

from analysis.figures import SMALLEST_FONT
from analysis.report import DPI, build_report
from analysis.synthetic import write_run
from hersd.contract.study import KIND_ATTR, SETTINGS_ATTR, StudySettings


def test_the_search_figures_command_reports_a_bad_storage_in_one_line(storages, tmp_path, capsys):
    from analysis.search_figures import main as search_figures_main

    assert search_figures_main([str(storages / "plain.db"), str(tmp_path)]) == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path), "--study", "other"]) == 2
    assert capsys.readouterr().err.count("\n") == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path)]) == 0


def test_the_search_figures_command_on_a_full_disk_is_one_line_naming_the_file_and_its_size(storages, tmp_path,
                                                                                            capsys, monkeypatch):
    from analysis.search_figures import main as search_figures_main
    from hersd.contract.errors import DiskFullError

    assert search_figures_main([str(storages / "study.db"), str(tmp_path / "whole")]) == 0
    table = tmp_path / "whole" / "in_sqlite_best_trials.csv"
    full_disk_writes(monkeypatch, "*best_trials.csv*")  # the table or its temporary file
    capsys.readouterr()
    assert search_figures_main([str(storages / "study.db"), str(tmp_path / "full")]) == 2
    err = capsys.readouterr().err
    needs = str(DiskFullError(tmp_path / "full" / table.name, table.stat().st_size)).rsplit(", ", 1)[0]
    assert err.count("\n") == 1 and err.startswith(f"error: {needs}, "), err
    assert sorted(path.name for path in (tmp_path / "full").iterdir()) == ["in_sqlite_beta_plane.png"]


@pytest.fixture
def newcomer_steps(tmp_path, monkeypatch):
    """tests/user_schedules.py's module importable in this process (KStep: ``low`` and whole-number ``k0``
    searched); forgotten afterwards."""
    write_module(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield f"{MODULE}.KStep"
    sys.modules.pop(MODULE, None)


def _search(storage: str, name: str, draw, first: tuple[dict, ...] = ()) -> None:
    """A study of six trials, ``draw(trial)`` drawing each one's settings -> its value (a seeded sampler; the
    first trials take the ``first`` parameters, e.g. one of each kind); trial 3 fails, trial 4 is pruned at its
    first report."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name=name, storage=storage, direction="maximize",
                                sampler=optuna.samplers.RandomSampler(seed=0))
    for params in first:
        study.enqueue_trial(params)

    def objective(trial: optuna.Trial) -> float:
        value = draw(trial)
        if trial.number == 3:
            raise RuntimeError("a run failed")
        if trial.number == 4:
            trial.report(value, step=1)
            raise optuna.TrialPruned()
        return value

    study.optimize(objective, n_trials=6, catch=(RuntimeError,))


def test_a_search_of_an_outside_schedule_is_drawn_against_each_setting_and_tabled_with_them(newcomer_steps, tmp_path):
    from analysis.search_figures import read_study
    from analysis.studies import open_study_storage

    def draw(trial):
        trial.set_user_attr(KIND_ATTR, newcomer_steps)
        return trial.suggest_float("low", 0.0, 1.0) + trial.suggest_int("k0", 1, 20) / 20

    (tmp_path / "search").mkdir()
    storage = f"sqlite:///{tmp_path / 'search' / 'kstep.db'}"
    _search(storage, "kstep", draw)
    write_run(tmp_path / "run", make_config(), np.linspace(0, 1, 6))
    build_report(tmp_path, tmp_path / "out", log=lambda line: None)

    assert sorted(path.name for path in (tmp_path / "out" / "search").iterdir()) == [
        "kstep_best_trials.csv", "kstep_best_trials.md", "kstep_settings.png"]
    study = optuna.load_study(study_name="kstep", storage=storage)
    best = pd.read_csv(tmp_path / "out" / "search" / "kstep_best_trials.csv")
    assert list(best.columns[:6]) == ["rank", "trial", "value", "kind", "low", "k0"]
    assert "beta1" not in best and (best["kind"] == newcomer_steps).all() and len(best) == 4
    assert best.iloc[0][["trial", "low", "k0"]].tolist() == pytest.approx(
        [study.best_trial.number, study.best_params["low"], study.best_params["k0"]])
    assert "| low | k0 |" in (tmp_path / "out" / "search" / "kstep_best_trials.md").read_text()
    page = (tmp_path / "out" / "index.html").read_text(encoding="utf-8")
    assert "kstep: trials against low, k0" in page and "(β1, β2)" not in page

    summary = read_study(open_study_storage(tmp_path / "search" / "kstep.db").storage, "kstep")
    assert str(summary.trials["k0"].dtype) == "Int64"  # drawn as whole numbers, tabled as them
    assert summary.value_label == "objective"  # a study without stored settings
    study.set_user_attr(SETTINGS_ATTR, vars(StudySettings("auc", "test_success", 3, 0, 50, "reach", "her", "ab")))
    assert read_study(open_study_storage(tmp_path / "search" / "kstep.db").storage, "kstep").value_label == \
        "auc of test_success, mean of 3 seed(s)"
    axes = [ax for ax in summary.figure().axes if ax.get_visible()]
    assert [ax.get_xlabel() for ax in axes] == ["low", "k0"]  # a panel per searched setting, no plane
    low, k0 = axes
    assert k0.get_xlim()[0] < 1 and k0.get_xlim()[1] > 20 and low.get_xlim()[0] < 0 < 1 < low.get_xlim()[1]
    complete_dots = low.collections[0].get_offsets()
    assert len(complete_dots) == 4 and sorted(complete_dots[:, 1]) == pytest.approx(sorted(best["value"]))


def test_an_outside_schedule_with_eq_9s_setting_names_is_tabled_and_drawn_with_both(newcomer_steps, tmp_path):
    """A class of one's own searching settings named beta1 and beta2 (not eq. 9's decay, so off the plane): both
    are columns of the best trials and a panel each; a one-setting study's legend stays inside its figure."""
    from analysis.search_figures import read_study
    from analysis.studies import open_study_storage

    def warp(trial):
        trial.set_user_attr(KIND_ATTR, f"{MODULE}.Warp")
        return trial.suggest_float("beta1", 0.3, 0.6) + trial.suggest_float("beta2", 0.0, 1.0)

    def low_only(trial):
        trial.set_user_attr(KIND_ATTR, newcomer_steps)
        return trial.suggest_float("low", 0.0, 1.0)

    _search(f"sqlite:///{tmp_path / 'own.db'}", "warp", warp)
    _search(f"sqlite:///{tmp_path / 'own.db'}", "low", low_only)
    storage = open_study_storage(tmp_path / "own.db").storage
    summary = read_study(storage, "warp")
    assert summary.best[["beta1", "beta2"]].notna().all().all() and len(summary.best) == 4
    assert [ax.get_xlabel() for ax in summary.figure().axes if ax.get_visible()] == ["beta1", "beta2"]
    figure = read_study(storage, "low").figure()
    figure.canvas.draw()
    box, edges = figure.legends[0].get_window_extent(), figure.bbox
    assert edges.x0 <= box.x0 and box.x1 <= edges.x1, (box, edges)


def test_a_search_of_decays_and_other_settings_draws_the_plane_above_a_panel_for_each_other(tmp_path):
    from analysis.search_figures import StudySummary, read_study
    from analysis.studies import open_study_storage

    def draw(trial):
        kind = trial.suggest_categorical("kind", ["constant", "linear", "exponential"])
        value = trial.suggest_float("eps", 0.5, 1.0) if kind == "constant" else trial.suggest_float("beta1", 0, 1)
        value += trial.suggest_float("beta2", -2, 2) if kind == "exponential" else 0.0
        return value + trial.suggest_float("lambda_h", 0.25, 1.0)

    _search(f"sqlite:///{tmp_path / 'mixed.db'}", "mixed", draw,
            first=({"kind": "exponential"}, {"kind": "linear"}, {"kind": "constant"}))  # every kind completes
    _search(f"sqlite:///{tmp_path / 'mixed.db'}", "decays", lambda trial: trial.suggest_float("beta1", 0, 1)
            + trial.suggest_float("beta2", -2, 2))
    storage = open_study_storage(tmp_path / "mixed.db").storage
    mixed: StudySummary = read_study(storage, "mixed")
    assert (mixed.settings, mixed.panels, mixed.figure_name) == (["beta1", "beta2", "eps", "lambda_h"],
                                                                ["eps", "lambda_h"], "settings")
    assert mixed.figure_title == "trials in the (β1, β2) plane and against eps, lambda_h"
    figure = mixed.figure()
    labels = [ax.get_xlabel() for ax in figure.axes if ax.get_visible() and ax.get_label() != "<colorbar>"]
    assert labels[0].startswith(r"$\beta_1$") and labels[1:] == ["eps", "lambda_h"]
    texts = [text for text in figure.findobj(Text) if text.get_text() and text.get_visible()]
    assert min(text.get_fontsize() for text in texts) >= SMALLEST_FONT  # legible at the page's width:
    assert figure.get_figwidth() * DPI <= 1248  # shown unscaled in a 1280-px window

    decays = read_study(storage, "decays")  # eq. 9's decays alone: the plane, as before
    assert (decays.panels, decays.figure_name) == ([], "beta_plane")
    assert decays.figure_title == "trials in the (β1, β2) plane"
    assert list(decays.best.columns[:6]) == ["rank", "trial", "value", "kind", "beta1", "beta2"]


@pytest.mark.parametrize("rates, says", [
    ((), "objective; searched settings: k0."),
    (("mu_eps",), "objective; searched settings: k0; mu_eps exact over the study's epochs (eq. 10)."),
    (("mu_eps_approx",), "objective; searched settings: k0; mu_eps by eq. 11."),
    (("mu_eps", "mu_eps_approx"), "objective; searched settings: k0; mu_eps exact over the study's epochs (eq. 10) "
                                  "and by eq. 11."),
])
def test_the_best_trials_header_names_only_the_mean_rates_its_table_has(rates, says):
    from analysis.search_figures import StudySummary

    best = pd.DataFrame({"rank": [1], "trial": [0], "value": [0.5], "kind": ["my_pkg.Step"], "k0": [3],
                         **{name: [0.8] for name in rates}})
    summary = StudySummary(name="s", trials=best, best=best, value_label="objective", beta2_range=(-2.0, 2.0),
                           settings=["k0"])
    assert summary.best_markdown().split("\n")[2] == says
