"""Drawing: each figure builder takes an :class:`analysis.metrics.Analysis` and returns the
figures the data allows (none when the data for one is missing) as :class:`ReportFigure`\\ s.
Choosing what to draw is cheap and done at once; the drawing itself is ``ReportFigure.draw()``,
which the report runs in worker processes, one per core.

:data:`FIGURE_BUILDERS` lists the builders in report order; a new figure (e.g. an Optuna
study's) is one more function appended there.
"""

from __future__ import annotations

import functools
import textwrap
from dataclasses import dataclass
from functools import partial
from typing import Callable

import matplotlib

matplotlib.use("Agg")

import pandas as pd  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from analysis import metrics  # noqa: E402
from analysis.critic import critic_curves  # noqa: E402
from analysis.load import HER_EPS, HER_WEIGHTS, PAPER_EPOCHS, is_archer  # noqa: E402
from analysis.metrics import Analysis  # noqa: E402
from hersd.contract.errors import ConfigError  # noqa: E402
from hersd.contract.schedules import MU_EPS_BAND, Schedule, schedule_class, schedule_rank  # noqa: E402
from hersd.contract.tasks import task_rank, task_title  # noqa: E402

SHARE_STYLE = {  # column -> (legend, colour), stacked bottom to top
    "share_real_success": ("real, successful", "tab:blue"),
    "share_real_failure": ("real, unsuccessful", "tab:red"),
    "share_hindsight": ("hindsight (relabelled)", "tab:purple"),
}
# Saturated, mutually distinct colours for decay schedules (grey and black are the baselines').
PALETTE = [*colormaps["tab10"].colors[:7], *colormaps["tab10"].colors[8:], *colormaps["Dark2"].colors]
PANEL_SIZE = (4.4, 3.0)  # inches per panel
MAX_COLUMNS = 2  # at 100 dpi a figure of two panels and its legend is ~1250-1350 px wide: legible in a 1280-px page
ALTERNATE_DASHES = [":", (0, (6, 2, 1, 2, 1, 2)), (0, (10, 3))]  # for configs whose usual style is taken
LEGEND_WIDTH = 2.3  # inches reserved right of the panels for a figure legend, at least
LEGEND_CHARACTERS = 34  # legend entries are wrapped to lines of at most this many characters
HANDLE_LENGTH = 3.0  # em: a legend's line samples long enough to show one period of every dash pattern
GLYPH_WIDTH = 0.6  # average width of a DejaVu Sans glyph, in em: how many characters fit a width
TITLE_SIZE, PANEL_TITLE_SIZE, LEGEND_SIZE = 12, 10, 8  # points
SMALLEST_FONT = LEGEND_SIZE  # points: no text of a figure is smaller (tests/test_figures.py, test_report_browser.py)
EPOCH_TICKS = 4  # intervals between epoch ticks, at most
IN_PROGRESS = " (in progress)"  # appended to a config's legend label for its unfinished runs
FAILED = " (failed)"  # appended instead for its runs that stopped with an error
IN_PROGRESS_STYLE = {"linewidth": 0.8, "alpha": 0.7}  # thin, in the config's colour and dashes, each run on its own


@dataclass
class ReportFigure:
    """One figure of the report: ``name`` is the file stem, ``caption`` says what is drawn,
    ``draw()`` makes the matplotlib figure (a new one on every call)."""

    name: str
    title: str
    caption: str
    draw: Callable[[], Figure]


def ordered_tasks(tasks) -> list[str]:
    """Tasks in the order of hersd.contract.tasks.TASKS (the paper's first), others after, alphabetically."""
    return sorted(set(tasks), key=task_rank)


def wrap(text: str, characters: int) -> str:
    """``text`` broken at spaces into lines of at most ``characters`` (a longer word stays whole)."""
    return "\n".join(textwrap.wrap(text, characters, break_long_words=False)) or text


def _fitting(text: str, inches: float, fontsize: float) -> str:
    """``text`` wrapped to fit ``inches`` at ``fontsize`` points."""
    return wrap(text, max(10, int(inches * 72 / (GLYPH_WIDTH * fontsize))))


def _lines(text: str) -> int:
    return text.count("\n") + 1


def _config_table(analysis: Analysis) -> pd.DataFrame:
    """One row per config (its schedule and reward weights), in config order."""
    return (analysis.runs.drop_duplicates("config").set_index("config")
            .loc[:, ["algo", "schedule", "schedule_tag", "constant_rate", "adaptive", "eps", "beta1", "beta2", "lambda_r",
                     "lambda_h", "mep", "total_epochs"]]
            .sort_index())


@functools.cache
def _class_of(kind: str) -> type[Schedule] | None:
    """The schedule class of ``kind``, None when it cannot be imported here (its runs are read from their logs)."""
    try:
        return schedule_class(kind)
    except ConfigError:
        return None


def kind_title(kind: str) -> str:
    """A panel's title for schedules of ``kind``: the class's title, else the kind (a class not importable here:
    its class name)."""
    cls = _class_of(kind)
    if cls is None:
        return kind.rpartition(".")[2]
    return cls.title or kind


def decay_kinds(table: pd.DataFrame) -> list[str]:
    """The kinds of ``table``'s schedules (columns schedule, constant_rate) that are not constant, in registry order."""
    return sorted(set(table.loc[~table["constant_rate"].astype(bool), "schedule"]), key=lambda k: (schedule_rank(k), k))


def _has_weights(table: pd.DataFrame, weights: tuple[float, float]) -> pd.Series:
    """Rows of ``table`` (columns lambda_r, lambda_h) with these reward weights."""
    return (table["lambda_r"] == weights[0]) & (table["lambda_h"] == weights[1])


def schedule_colours(table: pd.DataFrame) -> dict[str, tuple | str]:
    """Colour of each schedule (by its tag) in ``table`` (columns schedule, schedule_tag, constant_rate, eps,
    beta1, beta2).

    Constant HER_EPS black, other constants brown; other schedules take PALETTE in order
    within their kind, so each panel (one kind) uses the most distinct colours.
    """
    colours: dict[str, tuple | str] = {}
    count: dict[str, int] = {}
    rows = table[["schedule", "schedule_tag", "constant_rate", "eps", "beta1", "beta2"]].drop_duplicates("schedule_tag")
    rows = rows.assign(order=rows["schedule"].map(schedule_rank))
    for row in rows.sort_values(["order", "beta1", "beta2", "eps", "schedule_tag"]).itertuples(index=False):
        key = row.schedule_tag
        if row.constant_rate:
            colours[key] = "black" if row.eps == HER_EPS else "tab:brown"
        else:
            colours[key] = PALETTE[count.setdefault(row.schedule, 0) % len(PALETTE)]
            count[row.schedule] += 1
    return colours


def config_styles(analysis: Analysis) -> dict[str, dict]:
    """Line style of every config, the same in every figure: the schedule's colour (ARCHER
    grey instead of black), dashed with MEP, else the kind's own (Schedule.line: dash-dot for
    exponential decays, so kinds stay apart where they share a panel). Configs that would still look alike (same
    schedule, differing in another setting such as epochs or learner) get dotted, then other dash patterns, then,
    those taken too, the next PALETTE colour: no two configs share colour and line style (:func:`_free_style`)."""
    configs = _config_table(analysis)
    colours = schedule_colours(configs)
    styles = {}
    used: set[tuple] = set()
    for config, row in configs.iterrows():
        colour = colours[row["schedule_tag"]]
        if row["constant_rate"] and is_archer(row["algo"]):
            colour = "0.55"
        linestyle = "--" if row["mep"] else getattr(_class_of(row["schedule"]), "line", "-")
        colour, linestyle = _free_style(colour, linestyle, used)
        used.add((colour, linestyle))
        styles[config] = {"color": colour, "linestyle": linestyle, "linewidth": 1.5}
    return styles


def _free_style(colour, linestyle, used: set[tuple]) -> tuple:
    """The first (colour, line style) no config has taken (``used``): ``colour`` with ``linestyle``, then with each
    of ALTERNATE_DASHES, then each PALETTE colour with them."""
    dashes = [linestyle, *(dash for dash in ALTERNATE_DASHES if dash != linestyle)]
    candidates = [(colour, dash) for dash in dashes] + [(other, dash) for other in PALETTE for dash in dashes]
    return next((candidate for candidate in candidates if candidate not in used), candidates[-1])


def _epochs_of(analysis: Analysis) -> dict[str, int]:
    """K of each configuration (a label names one K)."""
    runs = analysis.runs.drop_duplicates("config")
    return dict(zip(runs["config"].astype(str), runs["total_epochs"].astype(int)))


def _task_epoch_panels(tasks_configs: pd.DataFrame, epochs_of: dict[str, int]) -> list[tuple[str, int]]:
    """One panel per task and K of ``tasks_configs`` (columns task, config): tasks in order, the paper's K first."""
    pairs = {(task, epochs_of[str(config)]) for task, config in zip(tasks_configs["task"], tasks_configs["config"])}
    return sorted(pairs, key=lambda pair: (task_rank(pair[0]), pair[1] != PAPER_EPOCHS, pair[1]))


def _panel_title(task: str, total: int, several: bool) -> str:
    """A panel's title: the task's, with its K when the figure's panels differ in K."""
    return task_title(task) + (f", K = {total}" if several else "")


# --- layout ------------------------------------------------------------------------------------------------------

def _panels(count: int, title: str, legend_width: float = 0.0, sharey: bool = True, title_lines: int = 1,
            sharex: bool = True):
    """A figure of ``count`` panels in rows of at most MAX_COLUMNS, laid out with fixed margins in
    inches (``legend_width`` kept free on the right, ``title_lines`` lines above each panel for its
    title); the figure title is wrapped to the figure's width. Inner panels share the x axis (with ``sharex``,
    else each has its x tick labels) and the y axis (with ``sharey``), and show tick labels only on the outside.
    Returns (figure, axes)."""
    columns = min(count, MAX_COLUMNS)
    rows = -(-count // columns)
    panel_width, panel_height = PANEL_SIZE
    left, right, bottom = 0.95, 0.15, 0.55
    gap_width = 0.25 if sharey else 0.6
    gap_height = 0.3 + 0.2 * title_lines + (0.0 if sharex else 0.25)
    width = left + columns * panel_width + (columns - 1) * gap_width + legend_width + right
    title = _fitting(title, width - 0.2, TITLE_SIZE)
    top = 0.25 + 0.22 * _lines(title) + 0.2 * title_lines
    height = bottom + rows * panel_height + (rows - 1) * gap_height + top
    figure = Figure(figsize=(width, height))
    grid = figure.add_gridspec(rows, columns, left=left / width, right=1 - (legend_width + right) / width,
                               bottom=bottom / height, top=1 - top / height, wspace=gap_width / panel_width,
                               hspace=gap_height / panel_height)
    axes = []
    for index in range(count):  # only the panels drawn: an empty grid cell costs as much as a panel
        shared = axes[0] if axes else None
        axis = figure.add_subplot(grid[index // columns, index % columns], sharex=shared if sharex else None,
                                  sharey=shared if sharey else None)
        axis.grid(alpha=0.3)
        axis.tick_params(labelbottom=index + columns >= count or not sharex,
                         labelleft=index % columns == 0 or not sharey)
        axes.append(axis)
    figure.suptitle(title, fontsize=TITLE_SIZE, y=1 - 0.08 / height, va="top")
    return figure, axes


def _set_title(axis, text: str, fontsize: float = PANEL_TITLE_SIZE) -> None:
    """A panel title at a fixed place (y=1 plus the usual pad): matplotlib's automatic placement
    measures the tick labels of the shared axes of every panel, a large share of the drawing time."""
    axis.set_title(text, fontsize=fontsize, y=1.0)


def _label_outer(axes, ylabel: str, xlabel: str = "epoch") -> None:
    """x label under the bottom panel of each column, y label left of each row; epochs get few whole-number ticks
    (each tick costs drawing time in every panel)."""
    columns = min(len(axes), MAX_COLUMNS)
    for index, axis in enumerate(axes):
        if xlabel.startswith("epoch"):  # whole epochs, at most ~5 ticks (0, 50, ..., 200 for the paper's K)
            axis.xaxis.set_major_locator(MaxNLocator(nbins=EPOCH_TICKS, integer=True, steps=[1, 2, 2.5, 5, 10]))
        if index % columns == 0:
            axis.set_ylabel(ylabel)
        if index + columns >= len(axes):
            axis.set_xlabel(xlabel)


def _legend_label(text: str) -> str:
    return wrap(str(text), LEGEND_CHARACTERS)


def _legend_width(labels, fontsize: float = LEGEND_SIZE) -> float:
    """Inches a figure legend of these labels needs (handle plus wrapped text), at least LEGEND_WIDTH."""
    longest = max((len(line) for label in labels for line in _legend_label(label).splitlines()), default=0)
    return max(LEGEND_WIDTH, 0.7 + longest * GLYPH_WIDTH * fontsize / 72)


def _figure_legend(figure: Figure, axes, legend_width: float, order: list[str] | None = None, **options) -> None:
    """One legend for the figure in the space _panels kept on the right; one entry per label (in the order of
    ``order``'s labels, wrapped as the legend wraps them, when given). A legend taller or wider than that space
    grows the figure (:func:`_keep_inside`): no legend runs off the canvas."""
    entries = {}
    for axis in axes:
        for handle, label in zip(*axis.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    if order is not None:
        entries = {_legend_label(label): entries[_legend_label(label)] for label in order}
    width, _ = figure.get_size_inches()
    top = axes[0].get_position().y1
    options = {"fontsize": LEGEND_SIZE, "handlelength": HANDLE_LENGTH, **options}
    legend = figure.legend(list(entries.values()), list(entries), loc="upper left", frameon=False,
                           bbox_to_anchor=(1 - (legend_width + 0.05) / width, top), **options)
    _keep_inside(figure, legend)


EDGE = 0.1  # inches kept free between a legend and the figure's edge


def _keep_inside(figure: Figure, legend) -> None:
    """Grow ``figure`` down and to the right by what ``legend`` (measured as drawn) overruns of it, keeping every
    panel, the title and the legend where they are in inches."""
    box = legend.get_window_extent(FigureCanvasAgg(figure).get_renderer())
    width, height = figure.get_size_inches()
    below = max(0.0, EDGE - box.y0 / figure.dpi)
    beyond = max(0.0, box.x1 / figure.dpi + EDGE - width)
    if not below and not beyond:
        return
    new_width, new_height = width + beyond, height + below

    def moved(x: float, y: float) -> tuple[float, float]:  # a point in figure fractions, kept in place in inches
        return x * width / new_width, (y * height + below) / new_height

    figure.set_size_inches(new_width, new_height)
    for axis in figure.axes:
        position = axis.get_position()
        x0, y0 = moved(position.x0, position.y0)
        axis.set_position([x0, y0, position.width * width / new_width, position.height * height / new_height])
    if figure._suptitle is not None:
        figure._suptitle.set_y(moved(0.0, figure._suptitle.get_position()[1])[1])
    anchor = legend.get_bbox_to_anchor().transformed(figure.transFigure.inverted())
    legend.set_bbox_to_anchor(moved(anchor.x0, anchor.y1), transform=figure.transFigure)


def _draw_curve(axis, medians: pd.DataFrame, in_progress: pd.DataFrame, config: str, style: dict) -> None:
    """Median line and min-max band of one config's complete runs (``medians``: one task's median
    curves), then each of its runs in progress (or failed) on its own, thin, in the config's colour and dashes
    (``in_progress``: their smoothed curves, column failed; one of a single epoch, which a line cannot show, as a
    dot)."""
    curve = medians[medians["config"] == config]
    if not curve.empty:
        axis.fill_between(curve["epoch"], curve["low"], curve["high"], color=style["color"], alpha=0.12, linewidth=0)
        axis.plot(curve["epoch"], curve["median"], label=_legend_label(config), **style)
    unfinished = in_progress[in_progress["config"] == config]
    for _, run in unfinished.groupby("run") if not unfinished.empty else ():  # a groupby costs ms, even empty
        suffix = FAILED if run["failed"].iloc[0] else IN_PROGRESS
        axis.plot(run["epoch"], run["smoothed"], label=_legend_label(config + suffix),
                  **{**style, **IN_PROGRESS_STYLE}, marker="o" if len(run) == 1 else "None", markersize=3)


def _in_progress(analysis: Analysis) -> pd.DataFrame:
    """The smoothed curves of the runs not complete, column failed: the run stopped with an error."""
    unfinished = analysis.curves[~analysis.curves["complete"]]
    failed = analysis.runs.loc[analysis.runs["error"] != "", "run"]
    return unfinished.assign(failed=unfinished["run"].isin(failed))


def _legend_labels(configs: list[str], in_progress: pd.DataFrame) -> list[str]:
    """The legend labels of these configs: each, and ``<config> (in progress)`` / ``(failed)`` for those with runs
    in progress or failed."""
    running, failed = (set(in_progress.loc[in_progress["failed"] == stopped, "config"]) for stopped in (False, True))
    return [*configs, *(config + IN_PROGRESS for config in configs if config in running),
            *(config + FAILED for config in configs if config in failed)]


def _in_progress_note(in_progress: pd.DataFrame) -> str:
    """The caption's sentence about runs in progress (none: empty)."""
    return (" Thin lines: runs still in progress (or failed: stopped with an error), each seed's own moving average "
            "in its configuration's colour and dashes (a dot: its first epoch alone); they enter neither the median, "
            "the band nor any table." if not in_progress.empty else "")


def _success_ylabel(window: int) -> str:
    return f"test success (median over seeds\nof {window}-epoch moving average)"


# --- Fig. 1: schedules -------------------------------------------------------------------------------------------

def schedules_figure(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 1: eps(k) of every schedule of the runs (:func:`analysis.metrics.schedule_curves`) as a step per
    epoch, one panel per kind that is not constant, each line its own colour."""
    curves = metrics.schedule_curves(analysis.runs, analysis.epochs)
    if curves.empty:
        return []
    caption = ("The probability ε(k) that a sampled transition's goal is replaced by a hindsight goal, one step per "
               "epoch k (drawn over k − 1 to k), for each schedule of the loaded runs, one colour per line, as their "
               "logs recorded it (eq. 9 for the paper's decays; past the last epoch a run in progress has logged, the "
               "schedule's class where it gives the logged rates), the configurations that share a schedule and K "
               "named together; a schedule that adapts to the run (the success-driven one) by the rates its runs "
               "realised, per task (the logs' relabel rate, median over seeds). "
               f"Constant schedules (HER and ARCHER use ε = {HER_EPS:g}) are dashed and drawn in every panel.")
    colours = _line_colours(curves, config_styles(analysis))
    return [ReportFigure("schedules", "Relabel-rate schedules (Fig. 1)", caption,
                         partial(_draw_schedules, curves, colours))]


def _line_colours(curves: pd.DataFrame, styles: dict[str, dict]) -> dict[str, tuple | str]:
    """Each line's colour (``curves``: schedule_curves; ``styles``: config_styles, in configuration order): its
    first configuration's, or where a line earlier in configuration order took that, the first PALETTE colour no
    line has. Returns the lines in the legend's order (the configurations')."""
    lines = curves[["line", "configs"]].drop_duplicates("line")
    rank = {config: index for index, config in enumerate(styles)}
    colours: dict[str, tuple | str] = {}
    for line, config in sorted(lines.itertuples(index=False), key=lambda item: rank[item[1]]):
        colour = styles[config]["color"]
        if colour in colours.values():
            colour = next((c for c in PALETTE if c not in colours.values()), colour)
        colours[line] = colour
    return colours


def _schedule_panels(curves: pd.DataFrame) -> list[tuple[str, int]]:
    """Fig. 1's panels: one per decay kind and K of ``curves`` (schedule_curves), the paper's K first, then one
    per K that has only constant rates."""
    decays = curves[~curves["constant_rate"].astype(bool)]
    panels = sorted(set(zip(decays["schedule"], decays["total_epochs"])),
                    key=lambda panel: (schedule_rank(panel[0]), panel[0], panel[1] != PAPER_EPOCHS, panel[1]))
    constant_only = sorted(set(curves["total_epochs"]) - {total for _, total in panels},
                           key=lambda total: (total != PAPER_EPOCHS, total))
    return panels + [(curves.loc[curves["total_epochs"] == total, "schedule"].iloc[0], total) for total in constant_only]


def _draw_schedules(curves: pd.DataFrame, colours: dict[str, tuple | str]) -> Figure:
    panels = _schedule_panels(curves)
    several_k = curves["total_epochs"].nunique() > 1
    legend_width = _legend_width(colours)
    figure, axes = _panels(len(panels), "Relabel-rate schedules ε(k)", legend_width=legend_width,
                           sharex=not several_k)
    for axis, (kind, total) in zip(axes, panels):
        shown = curves[(curves["total_epochs"] == total)
                       & (curves["constant_rate"].astype(bool) | (curves["schedule"] == kind))]
        for line, curve in shown.groupby("line", sort=False):
            epoch = curve["epoch"].to_numpy()
            axis.stairs(curve["eps"].to_numpy(), edges=[*(epoch - 1), epoch[-1]], baseline=None, color=colours[line],
                        linewidth=1.5, linestyle="--" if curve["constant_rate"].iloc[0] else "-",
                        label=_legend_label(line))
        _set_title(axis, kind_title(kind) + (f", K = {total}" if several_k else ""))
        axis.set_ylim(-0.02, 1.02)
    _label_outer(axes, "relabel rate ε(k)\n(share of goals relabelled)", xlabel="epoch k")
    _figure_legend(figure, axes, legend_width, order=list(colours))
    return figure


# --- Fig. 2: minibatch composition -------------------------------------------------------------------------------

def _composition_configs(configs: pd.DataFrame, present: set[str]) -> list[str]:
    """Configs to show minibatch composition for: without MEP; only HER's reward weights
    when some decay schedule was run with them."""
    candidates = configs.loc[[c for c in configs.index if c in present and not configs.loc[c, "mep"]]]
    her_weights = candidates[_has_weights(candidates, HER_WEIGHTS)]
    if (~her_weights["constant_rate"]).any():
        candidates = her_weights
    return list(candidates.index)


def composition_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 2: per task, stacked minibatch shares over epochs, HER beside each decay schedule."""
    configs = _config_table(analysis)
    found = []
    for task in ordered_tasks(analysis.shares["task"]):
        task_shares = analysis.shares[analysis.shares["task"] == task]
        shown = _composition_configs(configs, set(task_shares["config"]))
        if not shown:
            continue
        marked = (metrics.PAPER_COMPOSITION_EPOCH if task == metrics.PAPER_COMPOSITION_TASK
                  and task_shares["epoch"].max() >= metrics.PAPER_COMPOSITION_EPOCH else None)
        caption = (f"{task_title(task)}: share of each kind of transition in the sampled minibatches, per epoch: real "
                   "transitions whose reward says success (blue) or failure (red), and transitions whose goal was "
                   "relabelled in hindsight (purple). Median over the complete seeds of each share, rescaled to sum "
                   "to 1; epoch k's shares drawn over k − 1 to k, each panel over its configuration's K epochs."
                   + (f" The black line marks epoch {marked}, where the paper gives HER's composition (table "
                      "below)." if marked else ""))
        found.append(ReportFigure(f"composition_{task}", f"{task_title(task)}: minibatch composition (Fig. 2)",
                                  caption, partial(_draw_composition, task, task_shares, shown, marked)))
    return found


def _draw_composition(task: str, shares: pd.DataFrame, shown: list[str], marked: int | None) -> Figure:
    titles = [_fitting(config, PANEL_SIZE[0], PANEL_TITLE_SIZE) for config in shown]
    spans = {config: (shares.loc[shares["config"] == config, "epoch"].min(),
                      shares.loc[shares["config"] == config, "epoch"].max()) for config in shown}
    figure, axes = _panels(len(shown), f"{task_title(task)}: minibatch composition (median over seeds)",
                           legend_width=LEGEND_WIDTH, title_lines=max(map(_lines, titles)),
                           sharex=len(set(spans.values())) == 1)
    for axis, config, title in zip(axes, shown, titles):
        panel = shares[shares["config"] == config]
        # epoch k's shares drawn over (k - 1, k], as Fig. 1 draws its rate: a step schedule's step stays a step
        steps = pd.concat([panel.iloc[:1].assign(epoch=panel["epoch"].iloc[0] - 1), panel])
        axis.stackplot(steps["epoch"], *(steps[column] for column in metrics.SHARE_COLUMNS), step="pre",
                       labels=[SHARE_STYLE[c][0] for c in metrics.SHARE_COLUMNS],
                       colors=[SHARE_STYLE[c][1] for c in metrics.SHARE_COLUMNS], alpha=0.8, linewidth=0)
        if marked is not None and panel["epoch"].max() >= marked:
            axis.axvline(marked, color="black", linewidth=1.0)
        _set_title(axis, title)
        axis.set_ylim(0, 1)
        axis.set_xlim(spans[config][0] - 1, spans[config][1])
    axes[0].set_yticks([0, 0.5, 1])  # shared by every panel: three ticks instead of six to draw in each
    _label_outer(axes, "share of the minibatch")
    _figure_legend(figure, axes[:1], LEGEND_WIDTH, reverse=True, fontsize=9)
    return figure


# --- Figs. 4-9: learning curves ----------------------------------------------------------------------------------

def _weights_text(lambda_r: float, lambda_h: float) -> str:
    return f"λr={lambda_r:g}, λh={lambda_h:g}"


def _learning_panels(present: pd.DataFrame) -> list[tuple[tuple | None, list[tuple[str, list[str]]]]]:
    """How to split one task's configs into learning-curve figures: [(weights, [(panel title, configs)])].

    One figure per reward weights (lambda_r, lambda_h) of the non-constant schedules without
    MEP, each with a panel per schedule kind holding the constant baselines of the same weights
    and the schedules of that kind. Without those: one figure, one panel, every config.
    """
    plain = present[~present["mep"]]
    decays = plain[~plain["constant_rate"]]
    weight_groups = list(dict.fromkeys(zip(decays["lambda_r"], decays["lambda_h"])))
    if not weight_groups:
        return [(None, [("all configurations", list(present.index))])]
    figures = []
    for weights in weight_groups:
        same = plain[_has_weights(plain, weights)]
        baselines = list(same.index[same["constant_rate"]])
        panels = [(kind_title(kind), baselines + list(same.index[same["schedule"] == kind])) for kind in decay_kinds(same)]
        figures.append((weights, panels))
    return figures


def _split_by_epochs(panels: list[tuple[str, list[str]]], epochs_of: dict[str, int], constants: set[str]
                     ) -> list[tuple[str, list[str]]]:
    """Learning-curve panels with one K each (one x axis per K): each panel split by its configs' K, ``, K = <K>``
    added to its title when they differ (the paper's K first); a K with only constant rates (``constants``) gets
    one panel of them."""
    totals = sorted({epochs_of[config] for _, shown in panels for config in shown},
                    key=lambda total: (total != PAPER_EPOCHS, total))
    if len(totals) <= 1:
        return panels
    split = []
    for total in totals:
        at_k = [(title, [config for config in shown if epochs_of[config] == total]) for title, shown in panels]
        with_decay = [(f"{title}, K = {total}", shown) for title, shown in at_k if set(shown) - constants]
        if with_decay:
            split += with_decay
        else:
            split.append((f"constant rates, K = {total}", list(dict.fromkeys(c for _, shown in at_k for c in shown))))
    return split


def learning_curve_figures(analysis: Analysis) -> list[ReportFigure]:
    """Figs. 4-9: per task and reward weights, the decay schedules against the constant
    baseline with the same weights (HER or ARCHER), one panel per decay kind."""
    configs = _config_table(analysis)
    styles = config_styles(analysis)
    epochs_of = _epochs_of(analysis)
    found = []
    unfinished = _in_progress(analysis)
    for task in ordered_tasks(analysis.curves["task"]):
        medians = analysis.medians[analysis.medians["task"] == task]
        in_progress = unfinished[unfinished["task"] == task]
        run_configs = set(analysis.curves.loc[analysis.curves["task"] == task, "config"])
        present = configs.loc[[c for c in configs.index if c in run_configs]]
        for weights, panels in _learning_panels(present):
            panels = _split_by_epochs(panels, epochs_of, set(present.index[present["constant_rate"].astype(bool)]))
            if weights is None:
                name, title = f"curves_{task}", f"{task_title(task)}: learning curves"
            else:
                baselines = [c for c in panels[0][1] if configs.loc[c, "constant_rate"]]
                versus = (" and ".join(baselines) if len(baselines) <= 2 else  # learner variants: one line of title
                          f"{baselines[0]} and {len(baselines) - 1} other constant rates") if baselines \
                    else "each other (no constant baseline)"
                name = f"curves_{task}_lr{weights[0]:g}_lh{weights[1]:g}"
                title = f"{task_title(task)}: decay schedules vs {versus} ({_weights_text(*weights)})"
            caption = (f"{title}. Each seed's test success is smoothed by a trailing {analysis.window}-epoch moving "
                       "average (the first epochs average the epochs so far); lines are the median over the "
                       "complete seeds, shaded bands their range (min to max)." + _in_progress_note(in_progress))
            one_k = len({epochs_of[config] for _, shown in panels for config in shown}) == 1
            draw = partial(_draw_learning_curves, title, medians, in_progress, panels, styles, analysis.window, one_k)
            found.append(ReportFigure(name, f"{title} (Figs. 4-9)", caption, draw))
    return found


def _draw_learning_curves(title: str, medians: pd.DataFrame, in_progress: pd.DataFrame,
                          panels: list[tuple[str, list[str]]], styles: dict[str, dict], window: int,
                          sharex: bool = True) -> Figure:
    """One learning-curve figure; ``sharex``: its panels share one K (else each has its own x axis)."""
    legend_width = _legend_width(_legend_labels([config for _, shown in panels for config in shown], in_progress))
    figure, axes = _panels(len(panels), title, legend_width=legend_width, sharex=sharex)
    for axis, (panel_title, shown) in zip(axes, panels):
        for config in shown:
            _draw_curve(axis, medians, in_progress, config, styles[config])
        _set_title(axis, panel_title)
        axis.set_ylim(-0.02, 1.02)
    _label_outer(axes, _success_ylabel(window))
    _figure_legend(figure, axes, legend_width)
    return figure


# --- Fig. 10: mean Q ---------------------------------------------------------------------------------------------

def q_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 10: mean Q over epochs per task, HER against the decay schedules with HER's weights."""
    configs = _config_table(analysis)
    shown = list(configs.index[~configs["mep"] & _has_weights(configs, HER_WEIGHTS)])
    q_values = analysis.q_means[analysis.q_means["config"].isin(shown)]
    if q_values.empty or not (~configs.loc[shown, "constant_rate"]).any():
        return []
    caption = ("Mean of the critic's Q(s, a) over each epoch's training batches, averaged over the complete seeds, "
               "for HER and the "
               "schedules with the same reward weights (λr = λh = 1); linear decays solid, exponential "
               "dash-dot. An early overestimate that falls sooner means the critic is corrected sooner.")
    return [ReportFigure("q_mean", "Mean Q-value during training (Fig. 10)", caption,
                         partial(_draw_q, q_values, config_styles(analysis), _epochs_of(analysis)))]


def _draw_q(q_values: pd.DataFrame, styles: dict[str, dict], epochs_of: dict[str, int]) -> Figure:
    """Fig. 10: a panel per task and K (one x axis each; ``epochs_of``: each config's K)."""
    panels = _task_epoch_panels(q_values, epochs_of)
    several = len({total for _, total in panels}) > 1
    legend_width = _legend_width(q_values["config"].unique())
    figure, axes = _panels(len(panels), "Mean critic Q(s, a) over training batches (mean over seeds)",
                           legend_width=legend_width, sharey=False, sharex=not several)
    for axis, (task, total) in zip(axes, panels):
        for config, curve in q_values[q_values["task"] == task].groupby("config", observed=True):
            if epochs_of[str(config)] == total:
                axis.plot(curve["epoch"], curve["q_mean"], label=_legend_label(config),
                          **{**styles[config], "linewidth": 1.1})
        _set_title(axis, _panel_title(task, total, several))
    _label_outer(axes, "mean Q(s, a)")
    _figure_legend(figure, axes, legend_width)
    return figure


def critic_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 10 measured: per task, the critic's bias against the policy's true return (real and hindsight
    goals) and the mean Q of real-goal and relabelled training rows, median over complete seeds with the
    interquartile band, for every configuration whose logs hold bias evaluations."""
    complete = analysis.epochs[analysis.epochs["complete"]]
    curves = critic_curves(complete)
    curves = curves[curves["n_seeds"] > 0]
    if curves.empty:
        return []
    caption = ("Top: the critic's Q(s, π(s, g), g) minus the discounted return the deterministic policy obtains "
               "from s for g (hersd/engine/bias.py; returns run 300 steps, past the 50-step limit the critic bootstraps "
               "through), for the episodes' real goals and for hindsight goals (future achieved goals, each "
               "valued by a rollout from the restored state). Middle: the bias for hindsight goals the object "
               "was moved to (farther than the success radius from where it was at s; logged from 2026-11-27, "
               "empty where no pair had moved it), and the share of the hindsight pairs whose return is exactly 0 "
               "(their goal held from s on: near 1, the hindsight bias says little). Bottom: mean Q(s, a) over "
               "each epoch's training rows that kept their real goal and over the relabelled rows. Median over "
               "complete seeds, band: interquartile range. Positive bias is overestimation.")
    return [ReportFigure("critic_bias", "The critic against the true return (Fig. 10, measured)", caption,
                         partial(_draw_critic, curves, config_styles(analysis), _epochs_of(analysis)))]


# A row of panels per pair; a task's row is left out when neither of its columns has a value (older logs).
CRITIC_ROWS = ((("bias_real_mean", "bias, real goals (Q − return)"),
                ("bias_hindsight_mean", "bias, hindsight goals (Q − return)")),
               (("bias_moved_mean", "bias, goals the object was moved to (Q − return)"),
                ("bias_hindsight_zero_share", "hindsight pairs whose return is exactly 0 (share)")),
               (("q_real_mean", "mean Q, real-goal training rows"),
                ("q_hindsight_mean", "mean Q, relabelled training rows")))


def _draw_critic(curves: pd.DataFrame, styles: dict[str, dict], epochs_of: dict[str, int]) -> Figure:
    """Fig. 10 measured: CRITIC_ROWS' rows of panels per task and K (one x axis each; ``epochs_of``: each
    config's K)."""
    curves = curves.assign(total_epochs=curves["config"].astype(str).map(epochs_of))
    pairs = _task_epoch_panels(curves, epochs_of)
    several = len({total for _, total in pairs}) > 1
    legend_width = _legend_width(curves["config"].unique())
    panels = [(task, total, column, title) for task, total in pairs for row in CRITIC_ROWS
              if curves.loc[(curves["task"] == task) & (curves["total_epochs"] == total),
                            [f"{column}_median" for column, _ in row]].notna().any(axis=None)
              for column, title in row]
    figure, axes = _panels(len(panels), "The critic's bias and its Q by row type "
                           "(median over seeds, interquartile band)", legend_width=legend_width, sharey=False,
                           sharex=not several)
    for axis, (task, total, column, title) in zip(axes, panels):
        shown = curves[(curves["task"] == task) & (curves["total_epochs"] == total)]
        for config, curve in shown.groupby("config", observed=True):
            curve = curve.dropna(subset=[f"{column}_median"])
            style = styles[config]
            axis.plot(curve["epoch"], curve[f"{column}_median"], label=_legend_label(config),
                      **{**style, "linewidth": 1.1}, marker="." if column.startswith("bias") else None)
            axis.fill_between(curve["epoch"], curve[f"{column}_q25"], curve[f"{column}_q75"],
                              color=style.get("color"), alpha=0.15, linewidth=0)
        if column.endswith("_share"):
            axis.set_ylim(-0.02, 1.02)
        elif column.startswith("bias"):
            axis.axhline(0.0, color="0.5", linewidth=0.6)
        _set_title(axis, f"{_panel_title(task, total, several)}: {title}")
    _label_outer(axes, "Q")
    _figure_legend(figure, axes, legend_width)
    return figure


# --- Fig. 11: MEP ------------------------------------------------------------------------------------------------

def mep_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 11: per task, each MEP configuration beside the same configuration without MEP."""
    configs = _config_table(analysis)
    mep_configs = configs[configs["mep"]]
    settings = ["schedule_tag", "lambda_r", "lambda_h", "total_epochs"]
    partners = {config for config, row in configs[~configs["mep"]].iterrows()
                if (mep_configs[settings] == row[settings]).all(axis=1).any()}
    shown = [c for c in configs.index if c in partners or c in mep_configs.index]
    curves = analysis.curves[analysis.curves["config"].isin(shown)]
    if not curves["config"].isin(mep_configs.index).any():
        return []
    medians, in_progress = analysis.medians[analysis.medians["config"].isin(shown)], _in_progress(analysis)
    in_progress = in_progress[in_progress["config"].isin(shown)]
    caption = ("Configurations with MEP (dashed) beside the same configuration without it: median over seeds of "
               f"the {analysis.window}-epoch moving average of test success, range over seeds shaded."
               + _in_progress_note(in_progress))
    epochs_of = _epochs_of(analysis)
    panels = _task_epoch_panels(curves[curves["config"].isin(mep_configs.index)], epochs_of)
    return [ReportFigure("mep", "MEP comparison (Fig. 11)", caption,
                         partial(_draw_mep, panels, curves, medians, in_progress, shown, config_styles(analysis),
                                 analysis.window, epochs_of))]


def _draw_mep(panels: list[tuple[str, int]], curves: pd.DataFrame, medians: pd.DataFrame, in_progress: pd.DataFrame,
              shown: list[str], styles: dict[str, dict], window: int, epochs_of: dict[str, int]) -> Figure:
    """Fig. 11: a panel per task and K with a MEP configuration (``panels``), one x axis each."""
    several = len({total for _, total in panels}) > 1
    legend_width = _legend_width(_legend_labels(shown, in_progress))
    figure, axes = _panels(len(panels), "Episode prioritisation (MEP) with and without relabel-rate decay",
                           legend_width=legend_width, sharex=not several)
    for axis, (task, total) in zip(axes, panels):
        present = set(curves.loc[curves["task"] == task, "config"])
        for config in [c for c in shown if c in present and epochs_of[c] == total]:
            _draw_curve(axis, medians[medians["task"] == task], in_progress[in_progress["task"] == task], config,
                        styles[config])
        _set_title(axis, _panel_title(task, total, several))
        axis.set_ylim(-0.02, 1.02)
    _label_outer(axes, _success_ylabel(window))
    _figure_legend(figure, axes, legend_width)
    return figure


# --- Fig. 12: outcome against the mean relabel rate -------------------------------------------------------------

MEAN_RATE_PANELS = ((metrics.RUN_AUC, "AUC: mean raw test success over the K epochs", "AUC"),
                    ("epochs_to_0.5", "first epoch the moving average reaches 0.5 success", "epoch"))
MEAN_RATE_MARKERS = {"constant rate": "s", "fixed": "o", "adaptive": "D"}
# Arms whose colour and kind would look alike (e.g. linear and exponential decays, each its kind's first colour;
# the curves tell them apart by line style, a marker has none) take these shapes in turn.
REPEAT_MARKERS = ("^", "v", "P", "X", "h", "<", ">")
DODGE = 0.025  # arms at one mu_eps are drawn side by side, this share of the x axis apart


def mean_rate_figures(analysis: Analysis) -> list[ReportFigure]:
    """Fig. 12 from outcomes: per task with complete runs, every configuration's seeds (raw AUC, smoothed epochs
    to 0.5) against its mu_eps, the median over seeds and their range, the paper's band shaded."""
    seeds, arms = metrics.mean_rate_outcomes(analysis.runs, analysis.outcomes)
    styles = config_styles(analysis)
    found = []
    for task in ordered_tasks(seeds["task"]):
        caption = (f"{task_title(task)}: each configuration's outcome against its mean relabel rate "
                   "μ_ε = (1/K) Σ ε(k) of the logged rates: eq. 10 exactly for schedules of the epoch "
                   "(squares: constant rates, HER at 0.8; circles: "
                   "decays), the realised mean of the logged rates for adaptive ones (diamonds: each seed at its "
                   "own, the marker at their median, the horizontal bar their range). Left: the mean raw test "
                   "success over the K epochs (higher is better); right: the first epoch the "
                   f"{analysis.window}-epoch moving average reaches 0.5 (lower is better; a seed that never does "
                   "is drawn at K + 1, above the dotted line at K). Small dots: the seeds; large markers: the median "
                   "over seeds, the vertical bar their range; triangles and other shapes mark a configuration whose "
                   "colour and kind match an earlier one's. Configurations at the same μ_ε are drawn side by "
                   f"side. Grey band: the paper's best fixed ε of HER, μ_ε in [{MU_EPS_BAND[0]}, {MU_EPS_BAND[1]}]. "
                   "Complete runs only.")
        found.append(ReportFigure(f"mean_rate_{task}", f"{task_title(task)}: outcome against μ_ε (Fig. 12)", caption,
                                  partial(_draw_mean_rate, task, seeds[seeds["task"] == task],
                                          arms[arms["task"] == task], styles)))
    return found


def _dodged(arms: pd.DataFrame, span: float) -> pd.Series:
    """x of each arm (rows of ``arms``, column mu_eps): its mu_eps, moved sideways by DODGE x ``span`` steps when
    other arms share it (within metrics.EQUAL_MU_TOLERANCE of the next lower), the group centred on it."""
    ascending = arms["mu_eps"].sort_values()
    shared = arms.groupby((ascending.diff() >= metrics.EQUAL_MU_TOLERANCE).cumsum().reindex(arms.index))["mu_eps"]
    rank, count = shared.cumcount(), shared.transform("size")
    return arms["mu_eps"] + (rank - (count - 1) / 2) * DODGE * span


def _markers(arms: pd.DataFrame) -> list[str]:
    """Marker of each arm (rows of ``arms``, columns kind, colour): its kind's, or, for the second and later arms
    of one kind and colour, the next of REPEAT_MARKERS, so no two arms look alike in the legend."""
    seen: dict[tuple, int] = {}
    markers = []
    for kind, colour in zip(arms["kind"], arms["colour"]):
        repeats = seen.get((kind, colour), 0)
        seen[(kind, colour)] = repeats + 1
        markers.append(REPEAT_MARKERS[(repeats - 1) % len(REPEAT_MARKERS)] if repeats else MEAN_RATE_MARKERS[kind])
    return markers


def _draw_mean_rate(task: str, seeds: pd.DataFrame, arms: pd.DataFrame, styles: dict[str, dict]) -> Figure:
    legend_width = _legend_width([*arms["config"].astype(str), "the paper's best fixed ε"])
    figure, axes = _panels(len(MEAN_RATE_PANELS), f"{task_title(task)}: outcome against the mean relabel rate μ_ε",
                           legend_width=legend_width, sharey=False)
    low, high = min(MU_EPS_BAND[0], arms["mu_low"].min()), max(MU_EPS_BAND[1], arms["mu_high"].max())
    span = max(high - low, 0.05)
    arms = arms.assign(x=_dodged(arms, span), colour=[styles[config]["color"] for config in arms["config"]])
    arms = arms.assign(marker=_markers(arms))
    seeds = seeds.merge(arms[["config", "x", "colour"]].assign(shift=arms["x"] - arms["mu_eps"]), on="config")
    for axis, (outcome, title, ylabel) in zip(axes, MEAN_RATE_PANELS):
        _mean_rate_panel(axis, seeds, arms, outcome)
        axis.set_xlim(low - 0.1 * span, high + 0.1 * span)
        _set_title(axis, _fitting(title, PANEL_SIZE[0], PANEL_TITLE_SIZE))
        axis.set_ylabel(ylabel)
        axis.set_xlabel("μ_ε (mean relabel rate over the K epochs)")
    if seeds["never"].any():
        axes[1].axhline(seeds["total_epochs"].max(), color="0.4", linewidth=0.8, linestyle=":")
    axes[0].set_ylim(-0.02, 1.02)
    for arm in arms.itertuples(index=False):  # legend entries only: empty lines cost nothing to draw
        axes[0].plot([], [], marker=arm.marker, markersize=7, color=arm.colour, linestyle="none",
                     markeredgecolor="black", markeredgewidth=0.6, label=_legend_label(arm.config))
    _figure_legend(figure, axes, legend_width)
    return figure


def _mean_rate_panel(axis, seeds: pd.DataFrame, arms: pd.DataFrame, outcome: str) -> None:
    """One panel of Fig. 12: the band, every seed's ``outcome`` at its (dodged) mu_eps, and each arm's median
    marker with a vertical bar over its seeds' range (an adaptive arm also a horizontal one over their mu_eps);
    one artist per kind of mark (gid: seeds, range, mu_range, median), not one per arm: fewer to draw."""
    axis.axvspan(*MU_EPS_BAND, color="0.88", zorder=0, linewidth=0, label="the paper's best fixed ε")
    axis.scatter(seeds["mu_eps"] + seeds["shift"], seeds[outcome], s=12, c=list(seeds["colour"]), alpha=0.5,
                 linewidths=0, zorder=2, gid="seeds")
    axis.vlines(arms["x"], arms[f"{outcome}_low"], arms[f"{outcome}_high"], colors=list(arms["colour"]), linewidth=1.2,
                zorder=2, gid="range")
    adaptive = arms[arms["kind"] == "adaptive"]
    if not adaptive.empty:
        shift = adaptive["x"] - adaptive["mu_eps"]
        axis.hlines(adaptive[outcome], adaptive["mu_low"] + shift, adaptive["mu_high"] + shift,
                    colors=list(adaptive["colour"]), linewidth=1.2, zorder=2, gid="mu_range")
    for marker, group in arms.groupby("marker", sort=False):
        axis.scatter(group["x"], group[outcome], s=50, c=list(group["colour"]), marker=marker,
                     edgecolors="black", linewidths=0.6, zorder=3, gid="median")


FIGURE_BUILDERS: list[Callable[[Analysis], list[ReportFigure]]] = [
    schedules_figure,
    composition_figures,
    learning_curve_figures,
    q_figures,
    critic_figures,
    mep_figures,
    mean_rate_figures,
]


def all_figures(analysis: Analysis) -> list[ReportFigure]:
    """Every figure the data allows, in report order (not drawn yet: call each one's ``draw()``)."""
    return [figure for build in FIGURE_BUILDERS for figure in build(analysis)]
