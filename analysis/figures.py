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

import pandas as pd  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from analysis import metrics  # noqa: E402
from analysis.metrics import Analysis  # noqa: E402
from hersd.schedules import MU_EPS_BAND as OPTIMAL_BAND  # noqa: E402
from hersd.schedules import SCHEDULE_KINDS  # noqa: E402
from hersd.tasks import task_rank, task_title  # noqa: E402

SCHEDULE_RANK = {kind: rank for rank, kind in enumerate(SCHEDULE_KINDS)}
DECAY_PANEL_TITLES = {"linear": "linear decay (β2 = 0)", "exponential": "exponential decay",
                      "success": "success-driven rate"}
SHARE_STYLE = {  # column -> (legend, colour), stacked bottom to top
    "share_real_success": ("real, successful", "tab:blue"),
    "share_real_failure": ("real, unsuccessful", "tab:red"),
    "share_hindsight": ("hindsight (relabelled)", "tab:purple"),
}
# Saturated, mutually distinct colours for decay schedules (grey and black are the baselines').
PALETTE = [*colormaps["tab10"].colors[:7], *colormaps["tab10"].colors[8:], *colormaps["Dark2"].colors]
PANEL_SIZE = (4.4, 3.0)  # inches per panel
MAX_COLUMNS = 4
ALTERNATE_DASHES = [":", (0, (6, 2, 1, 2, 1, 2)), (0, (10, 3))]  # for configs whose usual style is taken
LEGEND_WIDTH = 2.3  # inches reserved right of the panels for a figure legend


@dataclass
class ReportFigure:
    """One figure of the report: ``name`` is the file stem, ``caption`` says what is drawn."""

    name: str
    title: str
    caption: str
    figure: Figure


def ordered_tasks(tasks) -> list[str]:
    """Tasks in the paper's order (reach, push, pick_and_place, slide), others after, alphabetically."""
    return sorted(set(tasks), key=task_rank)


def _config_table(analysis: Analysis) -> pd.DataFrame:
    """One row per config (its schedule and reward weights), in config order."""
    return (analysis.runs.drop_duplicates("config").set_index("config")
            .loc[:, ["schedule", "eps", "beta1", "beta2", "lambda_r", "lambda_h", "mep", "total_epochs", "mu_eps"]]
            .sort_index())


def schedule_colours(table: pd.DataFrame) -> dict[tuple, tuple | str]:
    """Colour of each schedule (kind, eps, beta1, beta2) in ``table`` (columns schedule, eps, beta1, beta2).

    Constant eps 0.8 black, other constants brown; decay schedules take PALETTE in order
    within their kind, so each panel (one kind) uses the most distinct colours.
    """
    colours: dict[tuple, tuple | str] = {}
    count = {"linear": 0, "exponential": 0}
    rows = table[["schedule", "eps", "beta1", "beta2"]].drop_duplicates()
    rows = rows.assign(order=rows["schedule"].map(SCHEDULE_RANK))
    for row in rows.sort_values(["order", "beta1", "beta2", "eps"]).itertuples(index=False):
        key = (row.schedule, row.eps, row.beta1, row.beta2)
        if row.schedule == "constant":
            colours[key] = "black" if row.eps == 0.8 else "tab:brown"
        else:
            colours[key] = PALETTE[count.setdefault(row.schedule, 0) % len(PALETTE)]
            count[row.schedule] += 1
    return colours


def config_styles(analysis: Analysis) -> dict[str, dict]:
    """Line style of every config, the same in every figure: the schedule's colour (ARCHER
    grey instead of black), dashed with MEP, dash-dot for exponential decays (so the two
    kinds stay apart where they share a panel). Configs that would still look alike (same
    schedule, differing in another setting such as epochs) get dotted, then other dash patterns."""
    configs = _config_table(analysis)
    colours = schedule_colours(configs)
    styles = {}
    used: dict[tuple, int] = {}
    for config, row in configs.iterrows():
        colour = colours[(row["schedule"], row["eps"], row["beta1"], row["beta2"])]
        if row["schedule"] == "constant" and (row["lambda_r"], row["lambda_h"]) == (1.0, 0.5):
            colour = "0.55"
        linestyle = "--" if row["mep"] else ("-." if row["schedule"] == "exponential" else "-")
        repeats = used.get((colour, linestyle), 0)
        used[(colour, linestyle)] = repeats + 1
        if repeats:
            linestyle = ALTERNATE_DASHES[(repeats - 1) % len(ALTERNATE_DASHES)]
        styles[config] = {"color": colour, "linestyle": linestyle, "linewidth": 1.5}
    return styles


def _panels(count: int, title: str, legend_width: float = 0.0, sharey: bool = True, title_lines: int = 1):
    """A figure of ``count`` panels in rows of at most MAX_COLUMNS, laid out with fixed
    margins in inches (``legend_width`` inches kept free on the right). Returns (figure, axes)."""
    columns = min(count, MAX_COLUMNS)
    rows = -(-count // columns)
    panel_width, panel_height = PANEL_SIZE
    left, right, bottom = 0.95, 0.15, 0.55
    top = 0.45 + 0.2 * title_lines
    gap_width = 0.25 if sharey else 0.6
    gap_height = 0.3 + 0.2 * title_lines
    width = left + columns * panel_width + (columns - 1) * gap_width + legend_width + right
    height = bottom + rows * panel_height + (rows - 1) * gap_height + top
    figure = Figure(figsize=(width, height))
    axes = figure.subplots(rows, columns, sharex=True, sharey=sharey, squeeze=False, gridspec_kw={
        "left": left / width, "right": 1 - (legend_width + right) / width, "bottom": bottom / height,
        "top": 1 - top / height, "wspace": gap_width / panel_width, "hspace": gap_height / panel_height}).ravel()
    for extra in axes[count:]:
        extra.set_visible(False)
    for axis in axes[:count]:
        axis.grid(alpha=0.3)
    figure.suptitle(title, fontsize=12, y=1 - 0.08 / height, va="top")
    return figure, axes[:count]


def _legend_width(labels, fontsize: float = 8) -> float:
    """Inches a figure legend of these labels needs (handle plus text), at least LEGEND_WIDTH."""
    longest = max((len(str(label)) for label in labels), default=0)
    return max(LEGEND_WIDTH, 0.7 + 0.075 * longest * fontsize / 8)


def _figure_legend(figure: Figure, axes, legend_width: float, **options) -> None:
    """One legend for the figure in the space _panels kept on the right; one entry per label."""
    entries = {}
    for axis in axes:
        for handle, label in zip(*axis.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    width, height = figure.get_size_inches()
    top = axes[0].get_position().y1
    options = {"fontsize": 8, **options}
    figure.legend(list(entries.values()), list(entries), loc="upper left", frameon=False,
                  bbox_to_anchor=(1 - (legend_width + 0.05) / width, top), **options)


def _label_outer(axes, ylabel: str, xlabel: str = "epoch") -> None:
    """x label under the bottom panel of each column, y label left of each row; epochs get whole-number ticks."""
    for axis in axes:
        if xlabel.startswith("epoch"):
            axis.xaxis.set_major_locator(MaxNLocator(integer=True))
        spec = axis.get_subplotspec()
        if spec.is_first_col():
            axis.set_ylabel(ylabel)
        bottom_of_column = spec.is_last_row() or not any(
            other.get_subplotspec().colspan == spec.colspan and other.get_subplotspec().rowspan.start > spec.rowspan.start
            for other in axes)
        if bottom_of_column:
            axis.set_xlabel(xlabel)
            axis.xaxis.set_tick_params(labelbottom=True)


def _draw_curve(axis, medians: pd.DataFrame, config: str, style: dict) -> None:
    """Median line and min-max band of one config (``medians``: one task's median curves)."""
    curve = medians[medians["config"] == config]
    axis.fill_between(curve["epoch"], curve["low"], curve["high"], color=style["color"], alpha=0.12, linewidth=0)
    axis.plot(curve["epoch"], curve["median"], label=config, **style)


def _success_ylabel(window: int) -> str:
    return f"test success (median over seeds\nof {window}-epoch moving average)"


def schedules_figure(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 1: eps(k) of every schedule present, one panel per decay kind."""
    curves = metrics.schedule_curves(analysis.runs)
    colours = schedule_colours(curves.rename(columns={"eps": "eps_k", "eps_setting": "eps"}))
    kinds = [kind for kind in ("linear", "exponential") if kind in set(curves["schedule"])] or ["constant"]
    figure, axes = _panels(len(kinds), "Relabel-rate schedules ε(k) = 1 − β1·(k/K)^exp(β2)")
    for axis, kind in zip(axes, kinds):
        shown = curves[curves["schedule"].isin(["constant", kind])]
        for (label, total_epochs), curve in shown.groupby(["label", "total_epochs"], sort=False):
            first = curve.iloc[0]
            colour = colours[(first["schedule"], first["eps_setting"], first["beta1"], first["beta2"])]
            several_k = curves["total_epochs"].nunique() > 1
            axis.plot(curve["epoch"], curve["eps"], color=colour, linewidth=1.5,
                      linestyle="--" if first["schedule"] == "constant" else "-",
                      label=label + (f" (K={total_epochs})" if several_k else ""))
        axis.set_title({"constant": "constant", "linear": "linear decay (β2 = 0)",
                        "exponential": "exponential decay"}[kind], fontsize=10)
        axis.set_ylim(-0.02, 1.02)
        axis.legend(fontsize=7, loc="lower left")
    _label_outer(axes, "relabel rate ε(k)\n(share of goals relabelled)", xlabel="epoch k")
    caption = ("The probability ε(k) that a sampled transition's goal is replaced by a hindsight goal, per epoch, "
               "for each schedule of the loaded runs (eq. 9; several configurations may share a schedule). "
               "Constant schedules (HER and ARCHER use ε = 0.8) are dashed and drawn in every panel.")
    return [ReportFigure("schedules", "Relabel-rate schedules (Fig. 1)", caption, figure)]


def _composition_configs(configs: pd.DataFrame, present: set[str]) -> list[str]:
    """Configs to show minibatch composition for: without MEP; only HER's reward weights
    when some decay schedule was run with them."""
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
    for task in ordered_tasks(shares["task"]):
        task_shares = shares[shares["task"] == task]
        shown = _composition_configs(configs, set(task_shares["config"]))
        if not shown:
            continue
        figure, axes = _panels(len(shown), f"{task_title(task)}: minibatch composition (median over seeds)",
                               legend_width=LEGEND_WIDTH)
        for axis, config in zip(axes, shown):
            panel = task_shares[task_shares["config"] == config]
            axis.stackplot(panel["epoch"], *(panel[column] for column in metrics.SHARE_COLUMNS),
                           labels=[SHARE_STYLE[c][0] for c in metrics.SHARE_COLUMNS],
                           colors=[SHARE_STYLE[c][1] for c in metrics.SHARE_COLUMNS], alpha=0.8, linewidth=0)
            axis.set_title(config, fontsize=10)
            axis.set_ylim(0, 1)
            if panel["epoch"].max() > panel["epoch"].min():
                axis.set_xlim(panel["epoch"].min(), panel["epoch"].max())
        _label_outer(axes, "share of the minibatch")
        _figure_legend(figure, axes[:1], LEGEND_WIDTH, reverse=True, fontsize=9)
        caption = (f"{task_title(task)}: share of each kind of transition in the sampled minibatches, per epoch: real "
                   "transitions whose reward says success (blue) or failure (red), and transitions whose goal was "
                   "relabelled in hindsight (purple). Median over seeds of each share, rescaled to sum to 1.")
        found.append(ReportFigure(f"composition_{task}", f"{task_title(task)}: minibatch composition (Fig. 2)",
                                  caption, figure))
    return found


def _weights_text(lambda_r: float, lambda_h: float) -> str:
    return f"λr={lambda_r:g}, λh={lambda_h:g}"


def _learning_panels(present: pd.DataFrame) -> list[tuple[tuple | None, list[tuple[str, list[str]]]]]:
    """How to split one task's configs into learning-curve figures.

    One figure per reward weights (lambda_r, lambda_h) of the decay schedules without MEP,
    each with a panel per decay kind holding the constant baselines of the same weights and
    the decays of that kind. Without decays: one figure, one panel, every config.
    """
    plain = present[~present["mep"]]
    decays = plain[plain["schedule"] != "constant"]
    weight_groups = list(dict.fromkeys(zip(decays["lambda_r"], decays["lambda_h"])))
    if not weight_groups:
        return [(None, [("all configurations", list(present.index))])]
    figures = []
    for weights in weight_groups:
        same = plain[(plain["lambda_r"] == weights[0]) & (plain["lambda_h"] == weights[1])]
        baselines = list(same.index[same["schedule"] == "constant"])
        panels = [(DECAY_PANEL_TITLES[kind], baselines + list(same.index[same["schedule"] == kind]))
                  for kind in SCHEDULE_KINDS[1:] if (same["schedule"] == kind).any()]
        figures.append((weights, panels))
    return figures


def learning_curve_figures(analysis: Analysis) -> list[ReportFigure]:
    """Figs. 4-9: per task and reward weights, the decay schedules against the constant
    baseline with the same weights (HER or ARCHER), one panel per decay kind."""
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    found = []
    for task in ordered_tasks(analysis.medians["task"]):
        medians = analysis.medians[analysis.medians["task"] == task]
        present = configs.loc[[c for c in configs.index if c in set(medians["config"])]]
        for weights, panels in _learning_panels(present):
            if weights is None:
                name, title = f"curves_{task}", f"{task_title(task)}: learning curves"
            else:
                baselines = [c for c in panels[0][1] if configs.loc[c, "schedule"] == "constant"]
                versus = " and ".join(baselines) if baselines else "each other (no constant baseline)"
                name = f"curves_{task}_lr{weights[0]:g}_lh{weights[1]:g}"
                title = f"{task_title(task)}: decay schedules vs {versus} ({_weights_text(*weights)})"
            legend_width = _legend_width(config for _, shown in panels for config in shown)
            figure, axes = _panels(len(panels), title, legend_width=legend_width)
            for axis, (panel_title, shown) in zip(axes, panels):
                for config in shown:
                    _draw_curve(axis, medians, config, styles[config])
                axis.set_title(panel_title, fontsize=10)
                axis.set_ylim(-0.02, 1.02)
            _label_outer(axes, _success_ylabel(analysis.window))
            _figure_legend(figure, axes, legend_width)
            caption = (f"{title}. Each seed's test success is smoothed by a trailing {analysis.window}-epoch moving "
                       "average (the first epochs average the epochs so far); lines are the median over seeds, "
                       "shaded bands the range (min to max) over seeds.")
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
    tasks = ordered_tasks(q_values["task"])
    legend_width = _legend_width(q_values["config"].unique())
    figure, axes = _panels(len(tasks), "Mean critic Q(s, a) over training batches (mean over seeds)",
                           legend_width=legend_width, sharey=False)
    for axis, task in zip(axes, tasks):
        for config, curve in q_values[q_values["task"] == task].groupby("config", observed=True):
            axis.plot(curve["epoch"], curve["q_mean"], label=config, **{**styles[config], "linewidth": 1.1})
        axis.set_title(task_title(task), fontsize=10)
    _label_outer(axes, "mean Q(s, a)")
    _figure_legend(figure, axes, legend_width)
    caption = ("Mean of the critic's Q(s, a) over each epoch's training batches, averaged over seeds, for HER and the "
               "decay schedules with the same reward weights (λr = λh = 1); linear decays solid, exponential "
               "dash-dot. An early overestimate that falls sooner means the critic is corrected sooner.")
    return [ReportFigure("q_mean", "Mean Q-value during training (Fig. 10)", caption, figure)]


def mep_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 11: per task, each MEP configuration beside the same configuration without MEP."""
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    mep_configs = configs[configs["mep"]]
    settings = ["schedule", "eps", "beta1", "beta2", "lambda_r", "lambda_h", "total_epochs"]
    partners = {config for config, row in configs[~configs["mep"]].iterrows()
                if (mep_configs[settings] == row[settings]).all(axis=1).any()}
    shown = [c for c in configs.index if c in partners or c in mep_configs.index]
    medians = analysis.medians[analysis.medians["config"].isin(shown)]
    tasks = ordered_tasks(medians.loc[medians["config"].isin(mep_configs.index), "task"])
    if not tasks:
        return []
    legend_width = _legend_width(shown)
    figure, axes = _panels(len(tasks), "Episode prioritisation (MEP) with and without relabel-rate decay",
                           legend_width=legend_width)
    for axis, task in zip(axes, tasks):
        task_medians = medians[medians["task"] == task]
        for config in [c for c in shown if c in set(task_medians["config"])]:
            _draw_curve(axis, task_medians, config, styles[config])
        axis.set_title(task_title(task), fontsize=10)
        axis.set_ylim(-0.02, 1.02)
    _label_outer(axes, _success_ylabel(analysis.window))
    _figure_legend(figure, axes, legend_width)
    caption = ("Configurations with MEP (dashed) beside the same configuration without it: median over seeds of "
               f"the {analysis.window}-epoch moving average of test success, range over seeds shaded.")
    return [ReportFigure("mep", "MEP comparison (Fig. 11)", caption, figure)]


def mean_rate_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 12: per task, mu_eps against beta1 for each beta2 present (eq. 10 and 11), the
    optimal band shaded, one marker per decay configuration coloured by its final median success."""
    configs = _config_table(analysis)
    summary = analysis.summary.merge(configs.reset_index(), on="config")
    decays = summary[summary["schedule"] != "constant"]
    if decays.empty:
        return []
    success_colours = colormaps["viridis"]
    norm = Normalize(0.0, 1.0)
    beta2_colours = {beta2: PALETTE[i % len(PALETTE)] for i, beta2 in enumerate(sorted(set(decays["beta2"])))}
    legend_width = LEGEND_WIDTH + 1.0  # the legend, then the colour bar
    found = []
    for task in ordered_tasks(decays["task"]):
        points = decays[decays["task"] == task]
        variants = list(dict.fromkeys(zip(points["lambda_r"], points["lambda_h"], points["mep"])))
        figure, axes = _panels(len(variants), f"{task_title(task)}: mean relabel rate μ_ε of the decay schedules",
                               legend_width=legend_width, title_lines=2)
        for axis, (lambda_r, lambda_h, mep) in zip(axes, variants):
            group = points[(points["lambda_r"] == lambda_r) & (points["lambda_h"] == lambda_h) & (points["mep"] == mep)]
            total_epochs = int(group["total_epochs"].mode().iloc[0])
            axis.axhspan(*OPTIMAL_BAND, color="0.85", zorder=0, label=f"best fixed ε of HER, {OPTIMAL_BAND[0]}-{OPTIMAL_BAND[1]}")
            for beta2, line in metrics.mean_rate_lines(list(group["beta2"]), total_epochs).groupby("beta2"):
                axis.plot(line["beta1"], line["exact"], color=beta2_colours[beta2], linewidth=1.4, label=f"β2 = {beta2:g}")
                axis.plot(line["beta1"], line["approx"], color=beta2_colours[beta2], linewidth=1.0, linestyle=":")
            axis.scatter(group["beta1"], group["mu_eps"], c=group["final_median"], cmap=success_colours, norm=norm,
                         s=70, edgecolors="black", linewidths=0.8, zorder=3)
            baselines = summary[(summary["task"] == task) & (summary["schedule"] == "constant")
                                & (summary["lambda_r"] == lambda_r) & (summary["lambda_h"] == lambda_h)
                                & (summary["mep"] == mep)]
            reference = ", ".join(f"{row.config} {row.final_median:.2f}" for row in baselines.itertuples())
            axis.set_title(_weights_text(lambda_r, lambda_h) + (", with MEP" if mep else "") + f" (K={total_epochs})"
                           + (f"\nfinal success of {reference}" if reference else ""), fontsize=9)
            axis.set_xlim(-0.02, 1.02)
            axis.set_ylim(0.0, 1.02)
        _label_outer(axes, "μ_ε (mean relabel rate\nover the K epochs)", xlabel="β1")
        axes[0].plot([], [], color="black", linewidth=1.4, label="eq. 10: exact mean")
        axes[0].plot([], [], color="black", linewidth=1.0, linestyle=":", label="eq. 11: 1 − β1/(1 + e^β2)")
        _figure_legend(figure, axes, legend_width)
        width, height = figure.get_size_inches()
        bottom, top = axes[-1].get_position().y0, axes[0].get_position().y1
        colour_axis = figure.add_axes(((width - 1.0) / width, bottom, 0.15 / width, top - bottom))
        colourbar = figure.colorbar(ScalarMappable(norm=norm, cmap=success_colours), cax=colour_axis)
        colourbar.set_label("final median test success")
        caption = (f"{task_title(task)}: mean relabel rate μ_ε over training against β1, one line per β2 of the runs "
                   "(solid: exact mean over K epochs, eq. 10; dotted: continuous approximation, eq. 11). The grey "
                   "band is the best fixed ε of HER, 0.8 to 0.889. Each marker is one decay configuration, "
                   "coloured by its final median test success (see the summary table).")
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
