"""Drawing: each figure function takes an :class:`analysis.metrics.Analysis` and returns the
figures it can make from the data present (none when that data is missing).

:data:`FIGURE_BUILDERS` lists them in report order; a new figure (e.g. an Optuna study's)
is one more function appended there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from analysis import metrics  # noqa: E402
from analysis.metrics import Analysis  # noqa: E402

TASK_TITLES = {"reach": "FetchReach", "push": "FetchPush", "pick_and_place": "FetchPickAndPlace", "slide": "FetchSlide"}
OPTIMAL_BAND = (0.8, 0.889)  # the best fixed eps of the HER paper; the seed paper's target for mu_eps
SHARE_STYLE = {  # column -> (legend, colour), stacked bottom to top
    "share_real_success": ("real, successful", "tab:blue"),
    "share_real_failure": ("real, unsuccessful", "tab:red"),
    "share_hindsight": ("hindsight (relabelled)", "tab:purple"),
}
PANEL_SIZE = (4.6, 3.3)  # inches per panel
MAX_COLUMNS = 4


@dataclass
class ReportFigure:
    """One figure of the report: ``name`` is the file stem, ``caption`` says what is drawn."""

    name: str
    title: str
    caption: str
    figure: Figure


def task_title(task: str) -> str:
    return TASK_TITLES.get(task, task.replace("_", " ").title())


def _config_table(analysis: Analysis) -> pd.DataFrame:
    """One row per config (its schedule and reward weights), in config order."""
    return (analysis.runs.drop_duplicates("config").set_index("config")
            .loc[:, ["schedule", "eps", "beta1", "beta2", "lambda_r", "lambda_h", "mep", "total_epochs", "mu_eps"]]
            .sort_index())


def config_styles(analysis: Analysis) -> dict[str, dict]:
    """Line style of every config, the same in every figure.

    HER black, ARCHER grey, other constant schedules brown; each decay schedule (kind, beta1,
    beta2) one colour shared by its reward-weight variants; MEP variants dashed.
    """
    configs = _config_table(analysis)
    decays = configs[configs["schedule"] != "constant"]
    schedules = list(dict.fromkeys(zip(decays["schedule"], decays["beta1"], decays["beta2"])))
    palette = colormaps["tab10" if len(schedules) <= 10 else "tab20"].colors
    styles = {}
    for config, row in configs.iterrows():
        if row["schedule"] == "constant":
            archer = (row["lambda_r"], row["lambda_h"]) == (1.0, 0.5)
            color = "0.5" if archer else ("black" if row["eps"] == 0.8 else "tab:brown")
            linestyle = "--" if row["mep"] else "-"
        else:
            index = schedules.index((row["schedule"], row["beta1"], row["beta2"]))
            color = palette[index % len(palette)]
            linestyle = "--" if row["mep"] else ("-", "-.", ":")[(index // len(palette)) % 3]
        styles[config] = {"color": color, "linestyle": linestyle, "linewidth": 1.6}
    return styles


def _panels(count: int, title: str, sharey: bool = True, height_extra: float = 0.0):
    """A figure with ``count`` panels in rows of at most MAX_COLUMNS; returns (figure, flat axes)."""
    columns = min(count, MAX_COLUMNS)
    rows = -(-count // columns)
    figure = Figure(figsize=(PANEL_SIZE[0] * columns + 2.2, PANEL_SIZE[1] * rows + 0.8 + height_extra),
                    layout="constrained")
    axes = figure.subplots(rows, columns, sharex=True, sharey=sharey, squeeze=False).ravel()
    for extra in axes[count:]:
        extra.set_visible(False)
    figure.suptitle(title, fontsize=12)
    return figure, axes[:count]


def _draw_curve(axis, medians: pd.DataFrame, config: str, style: dict) -> None:
    """Median line and min-max band of one config (``medians``: one task's median curves)."""
    curve = medians[medians["config"] == config]
    axis.fill_between(curve["epoch"], curve["low"], curve["high"], color=style["color"], alpha=0.12, linewidth=0)
    axis.plot(curve["epoch"], curve["median"], label=config, **style)


def _success_axes(axis, window: int, ylabel: bool) -> None:
    axis.set_ylim(-0.02, 1.02)
    axis.grid(alpha=0.3)
    axis.set_xlabel("epoch")
    if ylabel:
        axis.set_ylabel(f"test success\n(median of {window}-epoch moving avg.)")


def schedules_figure(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 1: eps(k) of every configuration present, one panel per decay kind."""
    curves = metrics.schedule_curves(analysis.runs)
    styles = config_styles(analysis)
    kinds = [kind for kind in ("linear", "exponential") if kind in set(curves["schedule"])] or ["constant"]
    figure, axes = _panels(len(kinds), "Relabel-rate schedules ε(k) = 1 − β1·(k/K)^exp(β2)")
    for axis, kind in zip(axes, kinds):
        shown = curves[curves["schedule"].isin(["constant", kind])]
        for (config, _), curve in shown.groupby(["config", "total_epochs"], observed=True):
            axis.plot(curve["epoch"], curve["eps"], label=config, **styles[config])
        axis.set_title({"constant": "constant (HER, ARCHER)", "linear": "linear decay (β2 = 0)",
                        "exponential": "exponential decay"}[kind])
        axis.set_xlabel("epoch k")
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
        axis.legend(fontsize=7, loc="lower left")
    axes[0].set_ylabel("relabel rate ε(k)\n(share of goals replaced in hindsight)")
    caption = ("The probability ε(k) that a sampled transition's goal is replaced by a hindsight goal, "
               "per epoch, for the schedules of the loaded runs (eq. 9). Constant schedules (HER, ARCHER) "
               "are drawn in every panel for reference.")
    return [ReportFigure("schedules", "Relabel-rate schedules (Fig. 1)", caption, figure)]


def _composition_configs(configs: pd.DataFrame, present: list[str]) -> list[str]:
    """Configs to show minibatch composition for: without MEP, reward weights of HER if any decay has them."""
    candidates = configs.loc[[c for c in configs.index if c in present and not configs.loc[c, "mep"]]]
    her_weights = candidates[(candidates["lambda_r"] == 1.0) & (candidates["lambda_h"] == 1.0)]
    if (her_weights["schedule"] != "constant").any():
        candidates = her_weights
    return list(candidates.index)


def composition_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 2: per task, stacked minibatch shares over epochs, HER beside each decay schedule."""
    shares = metrics.composition(analysis.epochs)
    configs = _config_table(analysis)
    found = []
    for task, task_shares in shares.groupby("task", sort=True):
        shown = _composition_configs(configs, list(task_shares["config"].unique()))
        if not shown:
            continue
        figure, axes = _panels(len(shown), f"{task_title(task)}: minibatch composition (median over seeds)")
        for index, (axis, config) in enumerate(zip(axes, shown)):
            panel = task_shares[task_shares["config"] == config]
            axis.stackplot(panel["epoch"], *(panel[column] for column in metrics.SHARE_COLUMNS),
                           labels=[SHARE_STYLE[c][0] for c in metrics.SHARE_COLUMNS],
                           colors=[SHARE_STYLE[c][1] for c in metrics.SHARE_COLUMNS], alpha=0.8)
            axis.set_title(config, fontsize=10)
            axis.set_ylim(0, 1)
            axis.set_xlim(panel["epoch"].min(), panel["epoch"].max())
            axis.set_xlabel("epoch")
            if index % MAX_COLUMNS == 0:
                axis.set_ylabel("share of the minibatch")
        handles, labels = axes[0].get_legend_handles_labels()
        figure.legend(handles[::-1], labels[::-1], loc="outside right upper", fontsize=9)
        caption = (f"{task_title(task)}: share of each kind of transition in the sampled minibatches, per epoch: "
                   "real transitions whose reward says success (blue) or failure (red), and transitions whose "
                   "goal was relabelled in hindsight (purple). Median over seeds of each share, rescaled to sum to 1.")
        found.append(ReportFigure(f"composition_{task}", f"{task_title(task)}: minibatch composition (Fig. 2)",
                                  caption, figure))
    return found


def _weights_text(lambda_r: float, lambda_h: float) -> str:
    return f"λr={lambda_r:g}, λh={lambda_h:g}"


def learning_curve_figures(analysis: Analysis) -> list[ReportFigure]:
    """Figs. 4-9: per task and reward weights, the decay schedules against the constant
    baseline with the same weights (HER or ARCHER), one panel per decay kind."""
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    found = []
    for task, medians in analysis.medians.groupby("task", sort=True):
        present = configs.loc[[c for c in configs.index if c in set(medians["config"])]]
        plain = present[~present["mep"]]
        decays = plain[plain["schedule"] != "constant"]
        weight_groups = list(dict.fromkeys(zip(decays["lambda_r"], decays["lambda_h"])))
        if not weight_groups:  # only constant schedules: one panel with all of them
            weight_groups = [None]
        for weights in weight_groups:
            if weights is None:
                panels = [("all configurations", list(present.index))]
                name, title = f"curves_{task}", f"{task_title(task)}: learning curves"
            else:
                same = plain[(plain["lambda_r"] == weights[0]) & (plain["lambda_h"] == weights[1])]
                baselines = list(same.index[same["schedule"] == "constant"])
                panels = [(f"{kind} decay" + (" (β2 = 0)" if kind == "linear" else ""),
                           baselines + list(same.index[same["schedule"] == kind]))
                          for kind in ("linear", "exponential") if (same["schedule"] == kind).any()]
                versus = " and ".join(baselines) if baselines else "no constant baseline"
                name = f"curves_{task}_lr{weights[0]:g}_lh{weights[1]:g}"
                title = f"{task_title(task)}: decay schedules vs {versus} ({_weights_text(*weights)})"
            figure, axes = _panels(len(panels), title)
            for index, (axis, (panel_title, shown)) in enumerate(zip(axes, panels)):
                for config in shown:
                    _draw_curve(axis, medians, config, styles[config])
                axis.set_title(panel_title, fontsize=10)
                _success_axes(axis, analysis.window, ylabel=index % MAX_COLUMNS == 0)
                axis.legend(fontsize=7, loc="upper left")
            caption = (f"{title}. Each seed's test success is smoothed by a trailing {analysis.window}-epoch "
                       "moving average (the first epochs average the epochs so far); lines are the median over "
                       "seeds, shaded bands the range (min to max) over seeds.")
            found.append(ReportFigure(name, f"{title} (Figs. 4-9)", caption, figure))
    return found


def q_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 10: mean Q over epochs per task, HER against the decay schedules with HER's weights."""
    q_values = metrics.mean_q(analysis.epochs)
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    shown = list(configs.index[(~configs["mep"]) & (configs["lambda_r"] == 1.0) & (configs["lambda_h"] == 1.0)])
    q_values = q_values[q_values["config"].isin(shown)]
    if q_values.empty or not (configs.loc[shown, "schedule"] != "constant").any():
        return []
    tasks = sorted(q_values["task"].unique())
    figure, axes = _panels(len(tasks), "Mean critic Q(s, a) over training batches (mean over seeds)", sharey=False)
    for index, (axis, task) in enumerate(zip(axes, tasks)):
        for config, curve in q_values[q_values["task"] == task].groupby("config", observed=True):
            axis.plot(curve["epoch"], curve["q_mean"], label=config, **styles[config])
        axis.set_title(task_title(task), fontsize=10)
        axis.set_xlabel("epoch")
        axis.grid(alpha=0.3)
        if index % MAX_COLUMNS == 0:
            axis.set_ylabel("mean Q(s, a)")
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside right upper", fontsize=8)
    caption = ("Mean of the critic's Q(s, a) over each epoch's training batches, averaged over seeds, for HER "
               "and the decay schedules with the same reward weights (λr = λh = 1). An early overestimate "
               "that falls faster suggests the critic is corrected sooner.")
    return [ReportFigure("q_mean", "Mean Q-value during training (Fig. 10)", caption, figure)]


def mep_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 11: per task, each MEP configuration beside the same configuration without MEP."""
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    mep_configs = configs[configs["mep"]]
    if mep_configs.empty:
        return []
    key = ["schedule", "eps", "beta1", "beta2", "lambda_r", "lambda_h", "total_epochs"]
    partners = set()
    for config, row in mep_configs.iterrows():
        same = (configs[key] == row[key]).all(axis=1) & ~configs["mep"]
        partners.update(configs.index[same])
    shown = [c for c in configs.index if c in partners or c in mep_configs.index]
    medians = analysis.medians[analysis.medians["config"].isin(shown)]
    tasks = sorted(medians.loc[medians["config"].isin(mep_configs.index), "task"].unique())
    if not tasks:
        return []
    figure, axes = _panels(len(tasks), "Episode prioritisation (MEP) with and without relabel-rate decay")
    for index, (axis, task) in enumerate(zip(axes, tasks)):
        task_medians = medians[medians["task"] == task]
        for config in [c for c in shown if c in set(task_medians["config"])]:
            _draw_curve(axis, task_medians, config, styles[config])
        axis.set_title(task_title(task), fontsize=10)
        _success_axes(axis, analysis.window, ylabel=index % MAX_COLUMNS == 0)
        axis.legend(fontsize=7, loc="upper left")
    caption = ("Configurations with MEP (dashed) beside the same configuration without it (solid): median over "
               f"seeds of the {analysis.window}-epoch moving average of test success, range over seeds shaded.")
    return [ReportFigure("mep", "MEP comparison (Fig. 11)", caption, figure)]


def mean_rate_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 12: per task, mu_eps against beta1 for each beta2 present (eq. 10 and 11), the
    optimal band shaded, one marker per decay configuration coloured by its final median success."""
    configs = _config_table(analysis)
    summary = analysis.summary.merge(configs.reset_index(), on="config")
    summary = summary[summary["schedule"] != "constant"]
    if summary.empty:
        return []
    success_colours = colormaps["viridis"]
    norm = Normalize(0.0, 1.0)
    line_colours = colormaps["tab10"].colors
    found = []
    for task, points in summary.groupby("task", sort=True):
        variants = list(dict.fromkeys(zip(points["lambda_r"], points["lambda_h"], points["mep"])))
        figure, axes = _panels(len(variants), f"{task_title(task)}: mean relabel rate μ_ε of the decay schedules")
        baselines = analysis.summary[(analysis.summary["task"] == task)
                                     & analysis.summary["config"].isin(configs.index[configs["schedule"] == "constant"])]
        for index, (axis, (lambda_r, lambda_h, mep)) in enumerate(zip(axes, variants)):
            group = points[(points["lambda_r"] == lambda_r) & (points["lambda_h"] == lambda_h) & (points["mep"] == mep)]
            total_epochs = int(group["total_epochs"].mode().iloc[0])
            lines = metrics.mean_rate_lines(list(group["beta2"]), total_epochs)
            axis.axhspan(*OPTIMAL_BAND, color="0.85", zorder=0, label=f"best fixed ε of HER ({OPTIMAL_BAND[0]}-{OPTIMAL_BAND[1]})")
            for colour_index, (beta2, line) in enumerate(lines.groupby("beta2")):
                colour = line_colours[colour_index % len(line_colours)]
                axis.plot(line["beta1"], line["exact"], color=colour, linewidth=1.4, label=f"β2={beta2:g} (eq. 10, K={total_epochs})")
                axis.plot(line["beta1"], line["approx"], color=colour, linewidth=1.0, linestyle=":")
            axis.scatter(group["beta1"], group["mu_eps"], c=group["final_median"], cmap=success_colours, norm=norm, s=70,
                         edgecolors="black", linewidths=0.8, zorder=3)
            weights = _weights_text(lambda_r, lambda_h) + (", with MEP" if mep else "")
            same_baseline = [f"{row.config} {row.final_median:.2f}" for row in baselines.itertuples()
                             if configs.loc[row.config, "mep"] == mep
                             and (configs.loc[row.config, "lambda_r"], configs.loc[row.config, "lambda_h"]) == (lambda_r, lambda_h)]
            axis.set_title(weights + (f"\nfinal success of {', '.join(same_baseline)}" if same_baseline else ""),
                           fontsize=9)
            axis.set_xlabel("β1")
            axis.set_xlim(-0.02, 1.02)
            axis.set_ylim(0.0, 1.02)
            axis.grid(alpha=0.3)
            if index % MAX_COLUMNS == 0:
                axis.set_ylabel("μ_ε (mean relabel rate over K epochs)")
            axis.legend(fontsize=7, loc="lower left")
        colourbar = figure.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=success_colours), ax=list(axes))
        colourbar.set_label("final median test success")
        caption = (f"{task_title(task)}: mean relabel rate μ_ε over training against β1, one line per β2 of the runs "
                   "(solid: exact mean over K epochs, eq. 10; dotted: continuous approximation 1 − β1/(1 + e^β2), "
                   "eq. 11). The grey band is the best fixed ε of HER, 0.8 to 0.889. Each marker is one decay "
                   "configuration, coloured by its final median test success (see the table).")
        found.append(ReportFigure(f"mean_rate_{task}", f"{task_title(task)}: μ_ε against β1 (Fig. 12)", caption, figure))
    return found


FIGURE_BUILDERS: list[Callable[[Analysis], list[ReportFigure]]] = [
    schedules_figure,
    composition_figures,
    learning_curve_figures,
    q_figures,
    mep_figures,
    mean_rate_figures,
]


def all_figures(analysis: Analysis) -> list[ReportFigure]:
    """Every figure the data allows, in report order."""
    return [figure for build in FIGURE_BUILDERS for figure in build(analysis)]
