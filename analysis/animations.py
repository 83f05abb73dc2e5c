"""The policy animations of the report: per task, each configuration's GIFs from its seed nearest the
median final success, side by side at matched epochs (one row per epoch, up to MAX_EPOCHS_SHOWN rows),
placed after the task's learning curves.

Training (``render_every``) and ``hersd-render`` write ``<run dir>/policy/epoch_<k>.gif``
(:meth:`hersd.contract.runstore.RunFolder.animations` finds them); this module only finds, chooses and places
those files: it renders nothing and needs neither torch nor MuJoCo.
"""

from __future__ import annotations

import html
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.metrics import Analysis, final_success
from hersd.contract.runstore import RunFolder
from hersd.contract.tasks import task_title

FOLDER = "animations"  # below the report's figures/ folder
MAX_EPOCHS_SHOWN = 4  # rows of a task's block: the paper's 200 epochs rendered every 50 give 50, 100, 150, 200


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


def shown_epochs(common: set[int]) -> list[int]:
    """Up to MAX_EPOCHS_SHOWN of the epochs every chosen run has, evenly spread from the first to the
    last, in order."""
    epochs = sorted(common)
    if len(epochs) <= MAX_EPOCHS_SHOWN:
        return epochs
    return [epochs[index] for index in np.linspace(0, len(epochs) - 1, MAX_EPOCHS_SHOWN).round().astype(int)]


def choose_animations(analysis: Analysis, folder: Path) -> dict[str, list[Chosen]]:
    """Per task (in the report's order), the :class:`Chosen` GIFs row by row: one row per epoch shown
    (:func:`shown_epochs` of those every chosen run has), in each row one per configuration with
    animations, in the configurations' order. When the runs have no epoch in common, one row: each
    configuration's own latest."""
    complete = analysis.curves[analysis.curves["complete"]]
    if complete.empty:
        return {}
    run_dirs = {run: (folder / path).parent for run, path in zip(analysis.runs["run"], analysis.runs["path"])}
    gifs = {run: RunFolder(run_dirs[run]).animations() for run in complete["run"].unique()}
    chosen: dict[str, list[Chosen]] = {}
    for task, finals in final_success(complete).groupby("task", observed=True, sort=False):
        picks = [(config, found) for config, group in finals.groupby("config", observed=True, sort=True)
                 if (found := _nearest_median(group, gifs)) is not None]
        if not picks:
            continue
        common = set.intersection(*(set(gifs[row["run"]]) for _, (row, _) in picks))
        own_latest = [max(gifs[row["run"]]) for _, (row, _) in picks]
        rows = [[epoch] * len(picks) for epoch in shown_epochs(common)] or [own_latest]
        chosen[task] = [Chosen(task, str(config), int(row["seed"]), float(row["final"]), median, epoch,
                               gifs[row["run"]][epoch])
                        for epochs in rows for (config, (row, median)), epoch in zip(picks, epochs)]
    return chosen


def file_name(index: int, chosen: Chosen) -> str:
    """The copy's file name in the report: ``<task>_<n>_<config>_seed<s>_epoch<k>.gif`` (safe characters only)."""
    config = re.sub(r"[^A-Za-z0-9.=-]+", "_", chosen.config).strip("_")
    return f"{chosen.task}_{index}_{config}_seed{chosen.seed}_epoch{chosen.epoch}.gif"


def animations_html(task: str, chosen: list[Chosen], sources: list[str]) -> str:
    """The page's block for one task: ``chosen`` row by row (as :func:`choose_animations` orders them), each
    configuration's GIF (``sources[i]``: its path relative to the page) with its caption, one row per epoch."""
    per_row = len({item.config for item in chosen})
    epochs = sorted({item.epoch for item in chosen})
    shown = f"epoch {epochs[0]}" if len(epochs) == 1 else "epochs " + ", ".join(map(str, epochs))
    cells = [
        f'<figure style="margin:0"><img alt="{html.escape(f"{item.config}, seed {item.seed}, epoch {item.epoch}")}" '
        f'src="{html.escape(source)}" width="240" height="180"><figcaption>{html.escape(item.config)}: seed '
        f"{item.seed}, epoch {item.epoch}<br>final success {item.final:.2f} (median {item.median:.2f})"
        f"</figcaption></figure>" for item, source in zip(chosen, sources)]
    row_style = "display:flex;flex-wrap:wrap;gap:1em;margin-bottom:1em"
    rows = "".join(f'<div style="{row_style}">{"".join(cells[start:start + per_row])}</div>'
                   for start in range(0, len(cells), per_row))
    caption = ("Two deterministic test episodes of the policy of each configuration's seed nearest its median "
               "final success (complete runs with animations), side by side at the epochs they all have (up to "
               f"{MAX_EPOCHS_SHOWN}, one row each); the bar at the bottom turns green while the goal is reached. "
               "Files: figures/animations/.")
    return (f'<figure id="animations_{html.escape(task)}"><h3>{html.escape(task_title(task))}: the policies, '
            f"{shown}</h3>{rows}<figcaption>{caption}</figcaption></figure>")


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
