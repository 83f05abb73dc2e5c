"""The policy animations of the report: per task, each configuration's GIF from its seed nearest the
median final success, at matched epochs, placed after the task's learning curves.

Training (``render_every``) and ``hersd-render`` write ``<run dir>/policy/epoch_<k>.gif``
(:func:`hersd.runstore.policy_animations` finds them); this module only finds, chooses and places
those files: it renders nothing and needs neither torch nor MuJoCo.
"""

from __future__ import annotations

import html
import re
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.metrics import Analysis, final_success
from hersd.runstore import policy_animations
from hersd.tasks import task_title

FOLDER = "animations"  # below the report's figures/ folder


@dataclass
class Chosen:
    """One configuration's animation: its seed (the complete run nearest the median final success among
    those with animations), that run's and the median final success, the epoch shown and its GIF."""

    task: str
    config: str
    seed: int
    final: float
    median: float
    epoch: int
    source: Path


def _nearest_median(group: pd.DataFrame, gifs: dict[int, dict[int, Path]]) -> tuple[pd.Series, float] | None:
    """The row (run, seed, final) of ``group`` (one configuration's seeds) nearest their median final success
    among the runs with animations (ties: the lower seed), and the median; None if no run has one."""
    median = float(group["final"].median())
    with_gifs = group[group["run"].map(lambda run: bool(gifs[run]))]
    if with_gifs.empty:
        return None
    order = with_gifs.assign(distance=(with_gifs["final"] - median).abs()).sort_values(["distance", "seed"])
    return order.iloc[0], median


def choose_animations(analysis: Analysis, folder: Path) -> dict[str, list[Chosen]]:
    """Per task (in the report's order), one :class:`Chosen` per configuration with animations, in the
    configurations' order. The epoch is the latest that every one of them has; when they have none in
    common, each shows its own latest."""
    complete = analysis.curves[analysis.curves["complete"]]
    if complete.empty:
        return {}
    run_dirs = {run: (folder / path).parent for run, path in zip(analysis.runs["run"], analysis.runs["path"])}
    gifs = {run: policy_animations(run_dirs[run]) for run in complete["run"].unique()}
    chosen: dict[str, list[Chosen]] = {}
    for task, finals in final_success(complete).groupby("task", observed=True, sort=False):
        picks = [(config, found) for config, group in finals.groupby("config", observed=True, sort=True)
                 if (found := _nearest_median(group, gifs)) is not None]
        if not picks:
            continue
        common = set.intersection(*(set(gifs[row["run"]]) for _, (row, _) in picks))
        chosen[task] = []
        for config, (row, median) in picks:
            epoch = max(common) if common else max(gifs[row["run"]])
            chosen[task].append(Chosen(task, str(config), int(row["seed"]), float(row["final"]), median, epoch,
                                       gifs[row["run"]][epoch]))
    return chosen


def file_name(index: int, chosen: Chosen) -> str:
    """The copy's file name in the report: ``<task>_<n>_<config>_seed<s>_epoch<k>.gif`` (safe characters only)."""
    config = re.sub(r"[^A-Za-z0-9.=-]+", "_", chosen.config).strip("_")
    return f"{chosen.task}_{index}_{config}_seed{chosen.seed}_epoch{chosen.epoch}.gif"


def animations_html(task: str, chosen: list[Chosen], sources: list[str]) -> str:
    """The page's block for one task: each configuration's GIF (``sources[i]``: its path relative to the
    page) with its caption, side by side."""
    epochs = sorted({item.epoch for item in chosen})
    shown = f"epoch {epochs[0]}" if len(epochs) == 1 else "epochs " + ", ".join(map(str, epochs))
    cells = "".join(
        f'<figure style="margin:0"><img alt="{html.escape(f"{item.config}, seed {item.seed}, epoch {item.epoch}")}" '
        f'src="{html.escape(source)}" width="240" height="180"><figcaption>{html.escape(item.config)}: seed '
        f"{item.seed}, epoch {item.epoch}<br>final success {item.final:.2f} (median {item.median:.2f})"
        f"</figcaption></figure>" for item, source in zip(chosen, sources))
    caption = ("Two deterministic test episodes of the policy of each configuration's seed nearest its median "
               "final success (complete runs with animations), at the latest epoch they all have; the bar at the "
               "bottom turns green while the goal is reached. Files: figures/animations/.")
    return (f'<figure id="animations_{html.escape(task)}"><h3>{html.escape(task_title(task))}: the policies, '
            f'{shown}</h3><div style="display:flex;flex-wrap:wrap;gap:1em">{cells}</div>'
            f"<figcaption>{caption}</figcaption></figure>")


def is_curves_of(figure_name: str, task: str) -> bool:
    """Whether a figure is one of ``task``'s learning-curve figures (``curves_<task>`` or ``curves_<task>_lr...``)."""
    return figure_name == f"curves_{task}" or figure_name.startswith(f"curves_{task}_lr")


def place_after_curves(figure_names: list[str], blocks: dict[str, str]) -> dict[str | None, list[str]]:
    """Where each task's block goes: figure name -> the blocks that follow it (after the task's last
    learning-curve figure); key None: blocks of tasks without one, placed after every figure."""
    placed: dict[str | None, list[str]] = {}
    for task, block in blocks.items():
        curves = [name for name in figure_names if is_curves_of(name, task)]
        placed.setdefault(curves[-1] if curves else None, []).append(block)
    return placed
