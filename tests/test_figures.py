"""analysis/figures.py: what the figures draw (curves, bands, markers, legends) and that their labels stay
inside them."""

from __future__ import annotations

import matplotlib.colors
import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from analysis import metrics
from matplotlib.patches import StepPatch
from matplotlib.text import Text

from analysis.figures import SMALLEST_FONT, all_figures, kind_title
from analysis.figures import LEGEND_CHARACTERS, mean_rate_figures, composition_figures, learning_curve_figures, mep_figures, q_figures
from analysis.load import load_runs
from analysis.report import main as report_main
from analysis.synthetic import write_run
from hersd.contract.schedules import Constant, Exponential, Linear, Success

from analysis_logs import PUSH_STEPS, WINDOW, make_config, write_campaign_midway
from analysis_logs import run_tables as _tables


def test_runs_in_progress_are_drawn_apart_and_labelled_in_the_run_list(tmp_path):
    write_campaign_midway(tmp_path)
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    (figure,) = learning_curve_figures(analysis)
    assert "Thin lines: runs still in progress" in figure.caption
    linear_panel, exp_panel = figure.draw().axes
    lines = {line.get_label(): line for line in linear_panel.get_lines()}
    assert set(lines) == {"HER", "HER (in progress)", "linear b1=0.5", "linear b1=0.5 (in progress)"}
    assert lines["HER (in progress)"].get_ydata().tolist() == [1.0] * 4  # the run's own moving average
    assert lines["HER (in progress)"].get_linewidth() < lines["HER"].get_linewidth()
    # in its configuration's colour and dashes: two configurations of one colour stay apart in progress too
    assert (lines["HER (in progress)"].get_color(), lines["HER (in progress)"].get_linestyle()) == \
        (lines["HER"].get_color(), lines["HER"].get_linestyle())
    assert lines["HER (in progress)"].get_marker() == "None"  # a line of 4 epochs needs no dots
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


def test_a_run_in_progress_of_one_epoch_is_a_dot(tmp_path):
    """A run that has just started (one epoch logged) is seen: a line through one point draws nothing."""
    schedule = Linear(beta1=0.5)
    write_run(tmp_path / "done", make_config(schedule=schedule, seed=0, epochs=4), [0.1, 0.3, 0.5, 0.7])
    write_run(tmp_path / "started", make_config(schedule=schedule, seed=1, epochs=4), [0.2], complete=False)
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    (figure,) = learning_curve_figures(analysis)
    lines = {line.get_label(): line for line in figure.draw().axes[0].get_lines()}
    started = lines["linear b1=0.5 (in progress)"]
    assert started.get_xdata().tolist() == [1] and started.get_marker() == "o"
    assert lines["linear b1=0.5"].get_marker() == "None"


def test_no_figure_without_its_data(hand_sized):
    table = load_runs(hand_sized)
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    assert mep_figures(analysis) == []  # no MEP run
    assert len(q_figures(analysis)) == 1
    her_only = metrics.analyse(table.runs[table.runs["config"] == "HER"],
                               table.epochs[table.epochs["config"] == "HER"], WINDOW)
    assert q_figures(her_only) == []  # nothing to compare HER with


def _arm_marks(axis) -> dict[str, list]:
    """Fig. 12's marks of a panel by gid: median -> [(x, y)], range / mu_range -> [(low, high)], seeds -> [(x, y)]."""
    marks = {"median": [], "range": [], "mu_range": [], "seeds": []}
    for collection in axis.collections:
        if collection.get_gid() in ("median", "seeds"):
            marks[collection.get_gid()] += [tuple(point) for point in collection.get_offsets()]
        elif collection.get_gid() in ("range", "mu_range"):
            axis_index = 1 if collection.get_gid() == "range" else 0
            marks[collection.get_gid()] += [tuple(sorted(segment[:, axis_index]))
                                            for segment in collection.get_segments()]
    return marks


def test_fig12_draws_each_configuration_at_its_mean_rate_with_the_median_and_range_of_its_seeds(tmp_path):
    """HER (mu_eps 0.8), linear b1=0.5 (eq. 10 over K = 6: 17/24) and the constant 17/24, side by side, and a
    success-driven rate at the median of its complete seeds' realised mean rates (an unfinished seed left out)."""
    arms = {"her": Constant(), "linear": Linear(beta1=0.5),
            "control": Constant(eps=17 / 24), "success": Success(beta1=0.5, window=1)}
    curves = [[0.0] * 6, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], [1.0] * 6]  # raw AUC 0, 0.5, 1; reach 0.5: never, 5, 1
    for name, schedule in arms.items():
        for seed, curve in enumerate(curves):
            write_run(tmp_path / f"{name}{seed}", make_config(schedule=schedule, seed=seed), np.array(curve))
    write_run(tmp_path / "success3", make_config(schedule=arms["success"], seed=3), np.ones(3), complete=False)
    analysis = metrics.analyse(*_tables(tmp_path), WINDOW)
    (report_figure,) = mean_rate_figures(analysis)
    assert report_figure.name == "mean_rate_push"
    figure = report_figure.draw()
    auc_axis, epochs_axis = figure.axes
    rates = analysis.runs[analysis.runs["complete"] & (analysis.runs["schedule"] == "success")]["mu_eps"]
    auc, epochs = _arm_marks(auc_axis), _arm_marks(epochs_axis)
    # the arms in configuration order: the control (17/24), HER, linear (17/24), success-driven
    (control_x, control_y), her, (linear_x, linear_y), (success_x, success_y) = auc["median"]
    assert her == (0.8, 0.5) and control_y == linear_y == 0.5  # raw AUC 0, 0.5, 1: median 0.5
    assert auc["range"] == [(0.0, 1.0)] * 4
    assert epochs["median"][1] == (0.8, 5) and epochs["range"][1] == (1, 7)  # a seed never at 0.5: K + 1
    assert control_x < linear_x and (linear_x + control_x) / 2 == pytest.approx(17 / 24)  # side by side
    assert success_x == pytest.approx(rates.median()) and auc["mu_range"] == [pytest.approx((rates.min(), rates.max()))]
    assert len(auc["seeds"]) == 12  # each configuration's three complete seeds
    band = [patch for patch in auc_axis.patches if patch.get_label() == "the paper's best fixed ε"]
    assert len(band) == 1 and band[0].get_path().get_extents(band[0].get_patch_transform()).x0 == pytest.approx(0.8)
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert labels == ["the paper's best fixed ε", "HER eps=0.708333", "HER", "linear b1=0.5", "success b1=0.5"]


def test_fig12_gives_decays_of_one_colour_and_kind_their_own_marker(tmp_path):
    """Linear and exponential decays each take their kind's first colour: the curves part them by line style,
    Fig. 12 by marker, in the panels and in the legend alike."""
    arms = {"her": Constant(), "linear": Linear(beta1=0.25),
            "exp": Exponential(beta1=0.25, beta2=0.25)}
    for name, schedule in arms.items():
        for seed in range(2):
            write_run(tmp_path / f"{name}{seed}", make_config(schedule=schedule, seed=seed), np.linspace(0, 1, 6))
    (report_figure,) = mean_rate_figures(metrics.analyse(*_tables(tmp_path), WINDOW))
    figure = report_figure.draw()
    legend = {text.get_text(): handle for text, handle in zip(figure.legends[0].get_texts(),
                                                               figure.legends[0].legend_handles)}
    linear, exp = legend["linear b1=0.25"], legend["exp b1=0.25 b2=0.25"]
    assert matplotlib.colors.same_color(linear.get_color(), exp.get_color())  # one colour: the marker must differ
    assert (linear.get_marker(), exp.get_marker(), legend["HER"].get_marker()) == ("o", "^", "s")
    medians = [collection for collection in figure.axes[0].collections if collection.get_gid() == "median"]
    assert len(medians) == 3  # squares, circles, triangles: one scatter per marker


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


def test_long_labels_are_wrapped_and_stay_inside_the_figure(tmp_path):
    for threshold in (None, 0.07):
        for schedule in (Constant(), Linear(beta1=0.25)):
            config = make_config(schedule=schedule, epochs=6)
            config.task.distance_threshold = threshold
            write_run(tmp_path / f"{threshold}-{schedule.kind}", config, np.linspace(0, 1, 6))
    analysis = metrics.analyse(*_tables(tmp_path), window=WINDOW)
    assert "linear b1=0.25 (task.distance_threshold=0.07)" in set(analysis.runs["config"])
    for report_figure in learning_curve_figures(analysis) + composition_figures(analysis) + mean_rate_figures(analysis):
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


def _schedule_campaign(folder) -> metrics.Analysis:
    """FetchPush HER (K = 6 and K = 4), ARCHER at K = 6, linear b1=0.5 at K = 2 and K = 3, a success-driven
    schedule (two seeds, one in progress) and an exponential decay: the schedules of Fig. 1."""
    success = Success(beta1=0.5)
    runs = {"her6": make_config(), "her4": make_config(epochs=4), "archer": make_config(lambda_h=0.5),
            "lin2": make_config(schedule=Linear(beta1=0.5), epochs=2),
            "lin3": make_config(schedule=Linear(beta1=0.5), epochs=3),
            "exp": make_config(schedule=Exponential(beta1=0.5, beta2=0.5)),
            "success0": make_config(schedule=success), "success1": make_config(schedule=success, seed=1)}
    for name, config in runs.items():
        curve = np.linspace(0, 1 if name != "success1" else 0.5, config.epochs)
        write_run(folder / name, config, curve[:4] if name == "success1" else curve, complete=name != "success1")
    return metrics.analyse(*_tables(folder), WINDOW)


def test_fig1_draws_every_schedule_as_steps_of_its_epoch_rates_one_colour_per_line(tmp_path):
    analysis = _schedule_campaign(tmp_path)
    (figure,) = [figure for figure in all_figures(analysis) if figure.name == "schedules"]
    drawn = figure.draw()
    steps = {patch.get_label(): patch for axis in drawn.axes for patch in axis.patches if isinstance(patch, StepPatch)}
    assert set(steps) == {"HER K=6, ARCHER", "HER K=4", "linear b1=0.5 K=2", "linear b1=0.5 K=3",
                          "exp b1=0.5 b2=0.5", "success b1=0.5 on push (realised,\nmedian over seeds)"}
    linear = steps["linear b1=0.5 K=3"].get_data()
    assert linear.edges.tolist() == [0, 1, 2, 3]  # epoch k's rate drawn over (k - 1, k]: a step per epoch
    assert linear.values.tolist() == pytest.approx(Linear(beta1=0.5).epoch_rates(3).tolist())
    realised = analysis.epochs[analysis.epochs["schedule"] == "success"].groupby("epoch")["relabel_rate"].median()
    success = steps["success b1=0.5 on push (realised,\nmedian over seeds)"].get_data()
    assert success.values.tolist() == realised.tolist() and len(realised) == 6  # seed 1 to epoch 4, seed 0 to 6
    colours = {label: matplotlib.colors.to_hex(patch.get_edgecolor()) for label, patch in steps.items()}
    assert len(set(colours.values())) == len(colours)  # K = 2 and K = 3 apart too
    # a panel per kind and K (x: that K's epochs), K = 4's constant rate in its own
    assert [axis.get_title() for axis in drawn.axes] == [
        f"{kind_title(kind)}, K = {total}" for kind, total in (("linear", 2), ("linear", 3), ("exponential", 6),
                                                              ("success", 6), ("constant", 4))]
    for axis, total in zip(drawn.axes, (2, 3, 6, 6, 4)):
        assert {patch.get_data().edges[-1] for patch in axis.patches} == {total}


def test_every_figure_keeps_its_text_legible_at_the_pages_width(tmp_path):
    """Every text of every figure is at least SMALLEST_FONT points, and no figure (four composition panels
    included) is so wide that a 1280-px page shrinks that text below 9 px: PNG at 100 dpi, scaled to 1248 px."""
    analysis = _schedule_campaign(tmp_path)
    for figure in all_figures(analysis):
        drawn = figure.draw()
        drawn.canvas = FigureCanvasAgg(drawn)
        drawn.canvas.draw()
        sizes = [text.get_fontsize() for text in drawn.findobj(Text) if text.get_visible() and text.get_text()]
        assert min(sizes) >= SMALLEST_FONT, figure.name
        width = drawn.get_size_inches()[0] * 100
        assert min(1.0, 1248 / width) * SMALLEST_FONT * 100 / 72 >= 9, (figure.name, width)


# --- a deliberately mixed folder (issue 68): three tasks, K = 2, 3 and 200, two outside schedule classes, six learners

def _mixed_run(folder, name: str, task: str, epochs: int, seed: int = 0, done: int | None = None,
               schedule: dict | None = None, learner: dict | None = None) -> None:
    """One synthetic run: HER unless ``schedule`` (a record: an outside class's) or ``learner`` (a record) is given;
    ``done`` epochs of ``epochs`` logged (all: complete); its rates those of the schedule's class."""
    from hersd.contract.config import config_record
    from hersd.contract.schedules import schedule_from_record

    done = epochs if done is None else done
    config = make_config(task=task, seed=seed, epochs=epochs)
    record = config_record(config)
    fields, meta = {}, {"config": record, "run_id": name}
    if schedule is not None:
        record["schedule"] = schedule
        fields["relabel_rate"] = schedule_from_record(schedule).epoch_rates(epochs)[:done]
        fields["share_hindsight"] = fields["relabel_rate"]
    if learner is not None:
        record["learner"] = learner
    write_run(folder / name, config, np.linspace(0, 1, epochs)[:done], complete=done == epochs, meta=meta, **fields)


def _mixed_folder(folder) -> None:
    k_step = {"kind": "newcomer_steps.KStep", "high": 0.9, "low": 0.5, "k0": 1}
    warp = {"kind": "newcomer_steps.Warp", "beta1": 0.4, "beta2": 0.5}
    for seed in (0, 1):
        _mixed_run(folder, f"push_her200_{seed}", "push", 200, seed)
        _mixed_run(folder, f"push_step2_{seed}", "push", 2, seed, schedule=k_step)
        _mixed_run(folder, f"reach_her3_{seed}", "reach", 3, seed)
        _mixed_run(folder, f"reach_step3_{seed}", "reach", 3, seed, schedule={**k_step, "k0": 2})
        _mixed_run(folder, f"reach_warp3_{seed}", "reach", 3, seed, schedule=warp)
        _mixed_run(folder, f"slide_her2_{seed}", "slide", 2, seed)
        _mixed_run(folder, f"slide_warp200_{seed}", "slide", 200, seed, schedule=warp)
    _mixed_run(folder, "push_linear200", "push", 200, done=60,
               schedule={"kind": "linear", "eps": 0.8, "beta1": 0.25, "beta2": 0.0, "mean_rate": None, "window": 10,
                         "eps_min": 0.0})
    learners = [{"name": "td3"}, {"name": "sac"}, {"name": "newcomer_learners.DDPGTN", "newcomer_learners.DDPGTN":
                {"warm": 0, "tau_scale": 1.0}}, {"name": "newcomer_learners.DDPGTN", "newcomer_learners.DDPGTN":
                {"warm": 5, "tau_scale": 2.0}},
                {"name": "newcomer_learners.TD3Scaled", "newcomer_learners.TD3Scaled": {"noise_scale": 1.0}}]
    for index, learner in enumerate(learners):  # with ddpg's runs above: six learner variants of HER at K = 2 and 3
        _mixed_run(folder, f"push_learner{index}", "push", 2, learner=learner)
        for seed, done in ((0, 3), (1, 2)):  # on reach a seed of each in progress too: a long legend
            _mixed_run(folder, f"reach_learner{index}_{seed}", "reach", 3, seed, done=done, learner=learner)
    _mixed_run(folder, "push_her2", "push", 2)


def _dash(artist) -> tuple:
    """An artist's line style as drawn: its dash pattern (offset, on-off lengths), None when solid."""
    offset, dashes = artist._unscaled_dash_pattern
    return (offset, tuple(dashes)) if dashes else None


def _configuration(label: str) -> str:
    """The configuration a legend label names (unwrapped): without `` (in progress)`` or `` (failed)``."""
    label = " ".join(label.split())
    for suffix in (" (in progress)", " (failed)"):
        label = label.removesuffix(suffix)
    return label


def _panel_items(axis) -> list[tuple[str, np.ndarray, tuple]]:
    """(label, x values, (colour, dash)) of each labelled line and step of a panel; its filled areas' x values with
    label ""."""
    items = [(line.get_label(), np.asarray(line.get_xdata(), float),
              (matplotlib.colors.to_hex(line.get_color()), _dash(line)))
             for line in axis.get_lines() if len(line.get_xdata()) and not line.get_label().startswith("_")]
    items += [(patch.get_label(), np.asarray(patch.get_data().edges, float),
               (matplotlib.colors.to_hex(patch.get_edgecolor()), _dash(patch)))
              for patch in axis.patches if isinstance(patch, StepPatch)]
    items += [("", np.concatenate([path.vertices[:, 0] for path in collection.get_paths()]), None)
              for collection in axis.collections if collection.get_paths() and collection.get_gid() is None]
    return items


def test_every_figure_of_a_mixed_folder_stays_legible(tmp_path, monkeypatch):
    """Mixed K cut the composition panels to epochs 1-2 (the last set_xlim won on a shared axis), legends ran off
    the canvas, two configurations were drawn in one black style, 3-epoch runs squashed on a 0-200 axis."""
    from user_schedules import write_module

    (tmp_path / "mods").mkdir()
    monkeypatch.syspath_prepend(str(write_module(tmp_path / "mods")))
    _mixed_folder(tmp_path / "runs")
    table = load_runs(tmp_path / "runs")
    assert set(table.runs["task"]) == {"push", "reach", "slide"} and set(table.runs["total_epochs"]) == {2, 3, 200}
    assert table.runs["learner"].nunique() == 5 and not table.rate_mismatches  # ddpg, td3, sac and two outside
    analysis = metrics.analyse(table.runs, table.epochs, WINDOW)
    figures = all_figures(analysis)
    assert {"schedules", "composition_push", "q_mean", "mean_rate_push"} <= {figure.name for figure in figures}
    for report_figure in figures:
        figure = report_figure.draw()
        canvas = FigureCanvasAgg(figure)
        canvas.print_png(tmp_path / f"{report_figure.name}.png")  # as the report saves it: the artists' final places
        renderer = canvas.get_renderer()
        for legend in figure.legends:
            box = legend.get_window_extent(renderer)
            assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= figure.bbox.x1 and box.y1 <= figure.bbox.y1, \
                (report_figure.name, box, figure.bbox)
        for axis in figure.axes:
            items = _panel_items(axis)
            low, high = axis.get_xlim()
            for label, x, _ in items:  # the panel's x range covers every run it draws
                assert low - 1e-9 <= x.min() and x.max() <= high + 1e-9, (report_figure.name, axis.get_title(), label)
            if not report_figure.name.startswith("mean_rate"):  # one K per panel: its complete lines end at K, which
                complete = [x for label, x, _ in items if " ".join(label.split()) == _configuration(label)]  # fills it
                ends = {x.max() for x in complete}
                assert len(ends) <= 1 and (not ends or max(ends) - low >= 0.9 * (high - low)), \
                    (report_figure.name, axis.get_title(), ends, (low, high))
            styles: dict[tuple, set[str]] = {}
            for label, _, style in items:
                if style is not None:
                    styles.setdefault(style, set()).add(_configuration(label))
            shared = {style: configs for style, configs in styles.items() if len(configs) > 1}
            assert not shared, (report_figure.name, axis.get_title(), shared)
    composition = next(figure for figure in figures if figure.name == "composition_push").draw()
    her200 = next(axis for axis in composition.axes if axis.get_title() == "HER")
    assert her200.get_xlim() == (0.0, 200.0) and [line.get_xdata()[0] for line in her200.get_lines()] == [150]
    step = next(axis for axis in composition.axes if axis.get_title().startswith("kstep"))
    hindsight = step.collections[-1].get_paths()[0].vertices  # the top band, drawn as steps: its lower edge jumps at
    assert step.get_xlim() == (0.0, 2.0)
    assert len({round(y, 6) for x, y in hindsight if x == 1.0 and y < 0.999}) == 2  # epoch 1
