"""``hersd-report FOLDER``: run logs -> tables, figures and one self-contained HTML page.

Output (``<FOLDER>/report`` unless ``--out``)::

    index.html                  tables, figures (embedded) and the list of runs
    figures/<name>.<format>     every figure
    tables/summary.csv|.md      per task x configuration
    tables/aggregate.csv|.md    per configuration across tasks
    tables/runs.csv             the runs behind them

Needs neither torch nor MuJoCo. Bad input is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import base64
import html
import io
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import pandas as pd

from analysis.figures import ReportFigure, all_figures
from analysis.load import ReportInputError, load_runs
from analysis.metrics import analyse

DEFAULT_WINDOW = 50
FORMATS = ("png", "svg", "pdf")
DPI = 100
FAST_PNG = {"compress_level": 1}  # zlib level 1: ~15 % larger files, a tenth of the figure stage faster
RUN_LIST_COLUMNS = ["path", "task", "config", "seed", "epochs_done", "total_epochs", "complete", "damaged", "run_id"]
TABLE_NOTES = {
    "summary": ("One row per task and configuration. <b>final_median</b>: median over seeds of each seed's "
                "smoothed success at the horizon (the last epoch all its seeds completed). <b>auc</b>: mean over "
                "epochs 1..horizon of the median smoothed curve (area under it, normalised to [0, 1]). "
                "<b>epochs_to_0.5 / 0.9</b>: first epoch the median smoothed curve reaches 0.5 / 0.9 (empty: never). "
                "<b>iqm</b>: interquartile mean over seeds of final success, with its 95 % percentile-bootstrap "
                "interval [iqm_low, iqm_high] (seeded, 2000 resamples). <b>p_improve_HER</b>: P(X &gt; Y) + "
                "0.5 P(X = Y) for X a seed's final success and Y a HER seed's, over all pairs."),
    "aggregate": ("One row per configuration across the tasks it was run on: IQM of all its seeds' final "
                  "success; the bootstrap resamples seeds within each task (stratified); p_improve_HER is the "
                  "mean over tasks of the per-task probability of improvement."),
}


@dataclass
class ReportResult:
    """What a report run wrote, and the seconds spent per stage (load, metrics, figures, html)."""

    index: Path
    figures: list[Path]
    tables: list[Path]
    timings: dict[str, float] = field(default_factory=dict)


def markdown_table(table: pd.DataFrame) -> str:
    """A GitHub-flavoured Markdown table; numbers to 3 decimals, NaN as an empty cell."""
    cells = [[_cell(value) for value in row] for row in table.itertuples(index=False)]
    lines = ["| " + " | ".join(map(str, table.columns)) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(row) + " |" for row in cells]
    return "\n".join(lines) + "\n"


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" + ("" if number == 1 else "s")


def _cell(value) -> str:
    if value is pd.NA:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.3f}"
    return str(value)


def _write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, table in tables.items():
        table.to_csv(folder / f"{name}.csv", index=False, float_format="%.6g")
        written.append(folder / f"{name}.csv")
        if name != "runs":
            (folder / f"{name}.md").write_text(markdown_table(table), encoding="utf-8")
            written.append(folder / f"{name}.md")
    return written


def _embedded(figure: ReportFigure, fmt: str, saved: Path) -> str:
    """An <img> holding the figure: the saved SVG or PNG, or a PNG rendering when the format is PDF."""
    if fmt == "pdf":
        buffer = io.BytesIO()
        figure.figure.savefig(buffer, format="png", dpi=DPI, pil_kwargs=FAST_PNG)
        data, mime = buffer.getvalue(), "image/png"
    else:
        data, mime = saved.read_bytes(), "image/svg+xml" if fmt == "svg" else "image/png"
    return f'<img alt="{html.escape(figure.title)}" src="data:{mime};base64,{base64.b64encode(data).decode()}">'


def _html_table(table: pd.DataFrame) -> str:
    return table.to_html(index=False, na_rep="", float_format=lambda v: f"{v:.3f}", border=0, classes="data")


def _search_section(folder: Path, out: Path, storages: Sequence[str] = ()) -> tuple[list[Path], list[str]]:
    """Figures and best-trial tables of the Optuna studies under ``folder/search`` (hersd-search's
    default SQLite files, and journal files) and in ``storages`` (URLs or files) -> (files
    written, HTML parts); nothing when there is no study."""
    found = sorted(path for pattern in ("*.db", "*.log", "*.journal") for path in (folder / "search").glob(pattern))
    sources = [str(path) for path in found] + list(storages)
    if not sources:
        return [], []
    from analysis.search_figures import StudyStorageError, study_figures  # imports optuna, only needed here

    written: list[Path] = []
    parts = ["<h2>Optuna searches</h2>"]
    for source in sources:
        try:
            files = study_figures(source, out / "search")
        except StudyStorageError as err:
            raise ReportInputError(f"--storage {source.split('@')[-1]}: {err}") from None
        written += files
        for path in files:
            if path.suffix == ".png":
                parts.append(f'<figure><h3>{html.escape(path.stem)}</h3><img alt="{html.escape(path.stem)}" '
                             f'src="data:image/png;base64,{base64.b64encode(path.read_bytes()).decode()}"></figure>')
            elif path.suffix == ".csv":
                parts += [f"<h3>Best trials: {html.escape(path.stem.removesuffix('_best_trials'))}</h3>",
                          _html_table(pd.read_csv(path))]
    return written, parts


def _html_page(folder: Path, summary: pd.DataFrame, aggregate: pd.DataFrame, runs: pd.DataFrame,
               figures: list[tuple[ReportFigure, str]], window: int, skipped: list[str],
               search_parts: list[str]) -> str:
    incomplete = int((~runs["complete"]).sum())
    parts = [f"<h1>hersd report: {html.escape(str(folder))}</h1>",
             f"<p>{_count(len(runs), 'run')} ({incomplete} incomplete), {_count(runs['task'].nunique(), 'task')}, "
             f"{_count(runs['config'].nunique(), 'configuration')}; test success smoothed over "
             f"{_count(window, 'epoch')}.</p>"]
    if skipped:
        parts.append("<p>Skipped unreadable logs:</p><ul>"
                     + "".join(f"<li>{html.escape(line)}</li>" for line in skipped) + "</ul>")
    parts += ["<h2>Summary per task and configuration</h2>", f"<p>{TABLE_NOTES['summary']}</p>", _html_table(summary),
              "<h2>Across tasks</h2>", f"<p>{TABLE_NOTES['aggregate']}</p>", _html_table(aggregate), "<h2>Figures</h2>"]
    for figure, image in figures:
        parts.append(f'<figure id="{figure.name}"><h3>{html.escape(figure.title)}</h3>{image}'
                     f"<figcaption>{html.escape(figure.caption)}</figcaption></figure>")
    parts += search_parts
    parts += ["<h2>Runs</h2>", _html_table(runs[RUN_LIST_COLUMNS])]
    style = ("body{font-family:sans-serif;max-width:1400px;margin:auto;padding:1em}"
             "table.data{border-collapse:collapse;font-size:0.85em}"
             "table.data td,table.data th{padding:2px 8px;border-bottom:1px solid #ddd;text-align:right}"
             "img{max-width:100%}figure{margin:2em 0}figcaption{color:#333;max-width:60em}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>hersd report</title>"
            f"<style>{style}</style></head><body>{''.join(parts)}</body></html>\n")


def build_report(folder: str | Path, out: str | Path | None = None, tasks: Sequence[str] | None = None,
                 algos: Sequence[str] | None = None, window: int = DEFAULT_WINDOW, fmt: str = "png",
                 log: Callable[[str], None] = print,
                 warn: Callable[[str], None] = lambda line: print(line, file=sys.stderr),
                 storages: Sequence[str] = ()) -> ReportResult:
    """Load, compute, draw and write the report; ``log`` receives progress lines, ``warn``
    one line per skipped log; ``storages`` adds Optuna study storages beyond ``folder/search``.

    Raises :class:`ReportInputError` for input that cannot make a report.
    """
    if fmt not in FORMATS:
        raise ReportInputError(f"unknown figure format {fmt!r}; choose one of: {', '.join(FORMATS)}")
    if window < 1:
        raise ReportInputError(f"--smooth must be at least 1 epoch, got {window}")
    folder = Path(folder)
    out = Path(out) if out is not None else folder / "report"
    timings: dict[str, float] = {}

    start = time.perf_counter()
    table = load_runs(folder, tasks=tasks, algos=algos)
    for line in table.skipped:
        warn(f"warning: skipped unreadable log {line}")
    runs = table.runs
    if not (runs["epochs_done"] > 0).any():
        raise ReportInputError(f"none of the {len(runs)} runs under {folder} has a completed epoch yet")
    timings["load"] = time.perf_counter() - start
    log(f"loaded {_count(len(runs), 'run')} ({int((~runs['complete']).sum())} incomplete, {len(table.skipped)} skipped), "
        f"{_count(len(table.epochs), 'epoch')}, {_count(runs['task'].nunique(), 'task')}, "
        f"{_count(runs['config'].nunique(), 'configuration')} in {timings['load']:.1f} s")

    start = time.perf_counter()
    analysis = analyse(runs, table.epochs, window)
    timings["metrics"] = time.perf_counter() - start

    start = time.perf_counter()
    figures_dir = out / "figures"
    figures_dir.mkdir(parents=True, exist_ok=True)
    drawn = all_figures(analysis)
    saved = []
    embedded = []
    for figure in drawn:
        path = figures_dir / f"{figure.name}.{fmt}"
        figure.figure.savefig(path, format=fmt, dpi=DPI, **({"pil_kwargs": FAST_PNG} if fmt == "png" else {}))
        saved.append(path)
        embedded.append((figure, _embedded(figure, fmt, path)))
    timings["figures"] = time.perf_counter() - start
    log(f"drew {_count(len(drawn), 'figure')} in {timings['figures']:.1f} s")

    start = time.perf_counter()
    tables = _write_tables({"summary": analysis.summary, "aggregate": analysis.aggregate,
                            "runs": runs.drop(columns="run")}, out / "tables")
    search_files, search_parts = _search_section(folder, out, storages)
    saved += [path for path in search_files if path.suffix != ".csv" and path.suffix != ".md"]
    tables += [path for path in search_files if path.suffix in (".csv", ".md")]
    index = out / "index.html"
    index.write_text(_html_page(folder, analysis.summary, analysis.aggregate, runs, embedded, window, table.skipped,
                                search_parts), encoding="utf-8")
    timings["html"] = time.perf_counter() - start
    return ReportResult(index=index, figures=saved, tables=tables, timings=timings)


class _OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line on stderr, exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv: Sequence[str] | None = None) -> int:
    parser = _OneLineParser(prog="hersd-report", description="Tables, figures and an HTML report from hersd run logs.")
    parser.add_argument("folder", type=Path, help="folder searched recursively for run.mcap files")
    parser.add_argument("--out", type=Path, help="output folder (default: FOLDER/report)")
    parser.add_argument("--task", nargs="+", help="keep only these tasks (config task.name, e.g. push slide)")
    parser.add_argument("--algo", nargs="+", help="keep only these algorithm names (config algo.name)")
    parser.add_argument("--smooth", type=int, default=DEFAULT_WINDOW, metavar="N",
                        help=f"moving-average window of the learning curves in epochs (default {DEFAULT_WINDOW})")
    parser.add_argument("--format", choices=FORMATS, default="png", help="figure file format (default png)")
    parser.add_argument("--storage", action="append", default=[], metavar="URL",
                        help="also draw the Optuna studies of this storage (a SQLAlchemy URL such as "
                             "postgresql://..., a .db file or a journal file); repeatable")
    args = parser.parse_args(argv)
    try:
        result = build_report(args.folder, args.out, tasks=args.task, algos=args.algo, window=args.smooth,
                              fmt=args.format, storages=args.storage)
    except ReportInputError as err:
        print(f"hersd-report: error: {err}", file=sys.stderr)
        return 2
    stages = ", ".join(f"{stage} {seconds:.1f} s" for stage, seconds in result.timings.items())
    print(f"report written to {result.index} ({stages})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
