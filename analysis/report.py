"""``hersd-report FOLDER``: run logs (and Optuna studies) -> tables, figures and one self-contained HTML page.

Output (``<FOLDER>/report`` unless ``--out``)::

    index.html                   tables, figures (embedded), policy animations (linked) and the list of runs
    figures/<name>.<format>      every figure
    figures/animations/*.gif     per task, each configuration's policy animation (when the runs have some)
    tables/summary.csv|.md       per task x configuration
    tables/aggregate.csv|.md     per configuration across tasks
    tables/composition_150.csv|.md  FetchPush HER's minibatch at epoch 150 beside the paper's (when run that long)
    tables/permutation_tests.csv|.md  per task, one-sided permutation tests between configurations' seeds
    tables/equal_mu_tests.csv|.md  per task, each decay against the constant rate at its mu_eps, both directions
    tables/variant_tests.csv|.md  per task, each variant (precision=bf16, update=fast) against its configuration at
                                 the defaults, both directions
    tables/runs.csv              the runs behind them
    tables/runs_provenance.csv|.md  per run, from its log: commits, machine, threads, flush setting, resumes, dates,
                                 hours of epochs at their median pace and wall clock, the bias evaluations' share
    tables/bias_evaluations.csv  per run, every bias evaluation its log holds (epoch, bias per goal type, seconds)
    tables/per_seed.csv          per run, its outcomes and its values at fixed epochs (analysis.seeds): the
                                 per-seed tables of docs/RESULTS.md
    search/<study>_*             each Optuna study's beta-plane figure and best trials

``hersd-report FOLDER --tensorboard DIR`` writes the runs' TensorBoard event files to DIR instead
(analysis.tensorboard_export; docs/ANALYSIS.md, "TensorBoard").

Needs neither torch nor MuJoCo. Bad input is one line on stderr and exit status 2. The logs
are read, and the figures drawn, in worker processes, one per core (analysis.workers); the
modules that compute and draw (scipy, matplotlib) are imported while the logs are read, and the statistics
and table files are computed and written while the figures are drawn. Figure and table files an earlier
report left in figures/ and tables/ that this one did not write are deleted (only where a report was).
"""

from __future__ import annotations

import argparse
import base64
import html
import io
import os
import shutil
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator, Sequence

import pandas as pd

from analysis.animations import (FOLDER as ANIMATIONS, animations_html, choose_animations, file_name,
                                 place_after_curves)
from analysis.claims import full_claims_table
from analysis.critic import GOAL_TYPES, bias_evaluations, bias_tests, integrated_bias
from analysis.load import ReportInputError, RunTable, checked_folder, start_reading
from analysis.metrics import (GROUP, PAPER_COMPOSITION_EPOCH, PAPER_COMPOSITION_TASK, RUN_OUTCOME_COLUMNS, run_state,
                              run_states)
from analysis.provenance import provenance_html, provenance_table, run_cost
from analysis.seeds import seed_values
from analysis.studies import StudyStorage, open_study_storage
from hersd.contract.study import StudyStorageError, find_study_storages
from analysis.tables import RUN_COLUMNS, html_table, markdown_table
from analysis.tensorboard_export import export_events
from hersd.contract.errors import ConfigError, DiskFullError, block_bytes, full_disk, sigterm_as_ctrl_c
from hersd.contract.runlog import replace_file, temporary_file
from analysis.workers import ForkedMap, WorkerLostError
from hersd.contract.tasks import task_rank, task_title

if TYPE_CHECKING:
    from analysis.figures import ReportFigure
    from analysis.metrics import Analysis
    from analysis.search_figures import StudySummary

DEFAULT_WINDOW = 50
FORMATS = ("png", "svg", "pdf")
REPORT_TITLE = "<title>hersd report</title>"  # the page's title, which marks a folder as a report's
DPI = 100
FAST_PNG = {"compress_level": 1}  # zlib level 1: files ~15 % larger than the default 6, encoded several times faster
MIME = {"png": "image/png", "svg": "image/svg+xml"}
PAGE_TEST_ROWS = 60  # more permutation tests than this stay in their table files
# the page's run list, one table per task x configuration (its <details> summary names them)
RUN_PAGE_COLUMNS = ["run_folder", "seed", "state", *RUN_OUTCOME_COLUMNS, "seconds_per_epoch", "cpu"]
TABLE_NOTES = {
    "claims": ("The seed paper's claims, each against hersd's measurement on the complete runs here "
               "(analysis/claims.py): the statistic of both configurations, their seeds, the exact permutation "
               "test and its p (with the smallest p the seed counts allow), and the verdict those numbers support "
               "at the 5 % level; the medians and the seeds' means the test compares; each hypothesis registered "
               "before its runs (docs/registered.csv) with the commit that registered it; the paper's claims no run "
               f"measures yet. tables/claims.csv; docs/RESULTS.md opens with the same tables."),
    "summary": ("One row per task and configuration, with its number of epochs K (runs of different K are "
                "different configurations: their labels say K where the runs differ in it, but for the paper's 200). "
                "Only complete runs enter this and every "
                "other table: <b>complete seeds</b> counts them, <b>runs in progress</b> the runs left out (not "
                "complete: running or stopped; they are drawn on their own in the learning curves); a configuration "
                "whose runs are all in progress has 0 complete seeds and no statistics yet. "
                "Medians and means of success are exact (each rate is a fraction of the test episodes). "
                "<b>Test success at epoch K</b>: median over seeds of each seed's test success at its last epoch "
                "K, smoothed (the moving average of the first line). "
                "<b>Area under the median curve</b>: mean over epochs 1..K of the median smoothed curve "
                "(normalised to [0, 1]). "
                "<b>Epochs to 0.5 / 0.9 success</b>: first epoch the median smoothed curve (or the median of the "
                "raw test success) reaches 0.5 / 0.9 (empty: never). "
                "<b>IQM</b>: interquartile mean over seeds of final success, with its 95 % percentile-bootstrap "
                "interval (seeded, 2000 resamples). <b>P(improvement over HER)</b>: P(X &gt; Y) + "
                "0.5 P(X = Y) for X a seed's final success and Y a seed's of HER (eps = 0.8, no MEP) with the same "
                "learner, number of epochs K and variant (precision=bf16, update=fast), over all pairs. Column names of tables/summary.csv: "
                "docs/ANALYSIS.md."),
    "aggregate": ("One row per configuration (one K) across the tasks it was run on: IQM of all its seeds' final "
                  "success; the bootstrap resamples seeds within each task (stratified); P(improvement over HER) is "
                  "the mean over tasks of the per-task probability of improvement."),
    "runs": ("Every run, in progress or complete, one table per task and configuration (click to open), with its "
             "own numbers: <b>test success at its last epoch</b>, smoothed, so far for a run in progress; "
             "<b>epochs to 0.5 / 0.9 success</b>, the first epoch its smoothed curve and its raw test success reach "
             "them (empty: not reached); <b>seconds per epoch</b>, the median of its epochs' wall-clock time; "
             "<b>CPU</b>, the CPU its log records (empty for logs that predate it). <b>State</b>: complete, or in "
             "progress (epoch N of K): its log has no completion marker yet (the run is running, or stopped; "
             "re-running its command resumes it); \"log without a valid end\": the file ends before its footer (a "
             "log in the earlier format of a run running or killed, or a file cut short), its epochs before the "
             "cut are read. The run folder's whole path is its cell's tooltip, and in tables/runs.csv with every "
             "setting."),
    "tests": ("One row per ordered pair of configurations of a task with the same learner and K, each with at "
              "least two complete seeds: each <b>p</b> is a one-sided permutation-test p-value "
              "(difference of the means over seeds) that the <b>configuration</b> "
              "does better than the <b>versus configuration</b>: higher final success, fewer epochs to a "
              "threshold (a seed that never reaches it counts as K + 1). Exact: every split of the "
              "two sides' seeds (5 against 5: 252, so the smallest p is 1/252; 10 against 10: 184,756), or "
              "9999 seeded random splits beyond a million. Each line is one test; reading many at once, expect some small p by chance."),
    "equal_mu": ("Each schedule that decays against the constant rate at the same mean rate μ_ε (same task, learner, "
                 "K, reward weights and MEP; paired automatically): does the decay help, or only relabelling more? One "
                 "row per outcome of each seed (final success, epochs to 0.5 / 0.9 smoothed and raw, a seed that "
                 "never reaches one counted as K + 1, and the mean raw test success over the K epochs): each side's "
                 "mean over seeds, and the one-sided permutation-test p-values in both directions (difference of the "
                 "means, exact up to a million splits). <b>Smallest p the seeds allow</b>: 1 over the "
                 "<b>splits of the seeds</b>, C(n1 + n2, n1) (1/252 at 5 against 5, 1/184,756 at 10 against 10; "
                 "1/10000 beyond a million splits, drawn at random): no result can be more significant."),
    "variants": ("Each configuration run at a variant (a setting added after the first runs, at other than its "
                 "earlier value: precision=bf16, update=fast) against the same configuration at the defaults (every "
                 "other setting equal; paired automatically): does it learn the same? The outcomes, means, p-values "
                 "and smallest p as in the table above; a large p in both directions says the seeds do not separate "
                 "them, not that they are equal."),
    "critic_tests": ("The critic's bias (Q minus the discounted return the policy obtains, figure above) of each "
                     "complete run, averaged over epochs 1-50 (trapezoids over its evaluated epochs), for real and "
                     "for hindsight goals: the configuration's and the versus configuration's means over runs, "
                     "their difference, and a two-sided permutation-test p-value "
                     "of that difference (exact up to a million splits). Positive bias is "
                     "overestimation."),
    "composition": (f"Shares of the sampled minibatch at epoch {PAPER_COMPOSITION_EPOCH} on "
                    f"{task_title(PAPER_COMPOSITION_TASK)} with HER: the paper's numbers (Fig. 2, Sec. III) beside "
                    f"this data's median over the seeds that reached epoch {PAPER_COMPOSITION_EPOCH}, rescaled to "
                    "sum to 1, as drawn in the figure above (black line)."),
}
PAGE_STYLE = ("body{font-family:sans-serif;max-width:1400px;margin:auto;padding:1em}"
              # a cell wraps between words only: numbers never, text (labels, headers) at its spaces
              "table.data{border-collapse:collapse;font-size:0.85em;font-variant-numeric:tabular-nums}"
              "table.data td,table.data th{padding:2px 5px;border-bottom:1px solid #ddd;text-align:right;"
              "overflow-wrap:normal;word-break:normal}"
              "table.data td{white-space:nowrap}"
              "table.data th{vertical-align:bottom;font-weight:600;max-width:9em}"
              "table.data td.text{text-align:left;white-space:normal;max-width:24em}table.data th.text{text-align:left}"
              "table.data span.word{white-space:nowrap}"
              "details.runs{margin:0.3em 0}details.runs>summary{cursor:pointer;padding:2px 0}"
              "details.runs>table{margin:0.3em 0 1em 1.2em}"
              "img{max-width:100%}figure{margin:2em 0}figcaption{color:#333;max-width:60em}")


@dataclass
class ReportResult:
    """What a report run wrote, and the wall seconds of its stages, one after another: load (which includes
    ``imports``, done while worker processes read the logs when there are many), metrics (the curves the figures
    draw), figures (from the first figure's drawing to the last's; it includes ``statistics`` and ``tables``,
    the statistics tables computed and the table files written meanwhile), writing (the page)."""

    index: Path
    figures: list[Path]
    tables: list[Path]
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class Studies:
    """The Optuna studies of the report: ``read`` (file stem -> study) and ``skipped`` lines."""

    read: dict[str, StudySummary] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" + ("" if number == 1 else "s")


def _open_given_storages(specs: Sequence[str]) -> list[StudyStorage]:
    """The ``--storage`` storages, opened; a bad one stops the report (ReportInputError)."""
    try:
        return [open_study_storage(spec) for spec in specs]
    except StudyStorageError as err:
        raise ReportInputError(f"--storage {err}") from None


def _read_studies(given: list[StudyStorage], folder: Path) -> Studies:
    """Every study of the given storages and of the storages in ``folder/search/``; a found
    storage that cannot be read is skipped with a line in ``skipped``."""
    found = find_study_storages(folder)
    studies = Studies()
    if not given and not found:
        return studies
    from analysis.search_figures import read_study  # imports optuna: only when there are studies

    opened = list(given)
    for path in found:
        try:
            opened.append(open_study_storage(path))
        except StudyStorageError as err:
            studies.skipped.append(str(err))
    for storage in opened:
        for name in storage.study_names:
            stem = name if name not in studies.read else f"{name}-{len(studies.read) + 1}"  # same name elsewhere
            studies.read[stem] = read_study(storage.storage, name)
    return studies


def write_whole(path: Path, data: bytes | str) -> Path:
    """Write one of the report's files whole (a temporary file renamed into place): a write that fails leaves no
    temporary file, and on a full disk raises :class:`DiskFullError` naming ``path`` and the bytes it needs."""
    replace_file(path, data.encode() if isinstance(data, str) else data, sync=False)
    return path


def _saved(figure: Any, fmt: str) -> bytes:
    """A matplotlib figure saved in format ``fmt``, in memory."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format=fmt, dpi=DPI, **({"pil_kwargs": FAST_PNG} if fmt == "png" else {}))
    return buffer.getvalue()


def _render(job: tuple[ReportFigure, Path, str]) -> str:
    """Draw one figure and save it as ``path`` in format ``fmt`` (:func:`write_whole`) -> the ``<img>`` embedding
    it (a PNG rendering for PDF: browsers do not show a PDF in an image)."""
    report_figure, path, fmt = job
    figure = report_figure.draw()
    data = _saved(figure, fmt)
    write_whole(path, data)
    if fmt == "pdf":
        data, fmt = _saved(figure, "png"), "png"
    source = f"data:{MIME[fmt]};base64,{base64.b64encode(data).decode()}"
    return f'<img alt="{html.escape(report_figure.title)}" src="{source}">'


CSV_ONLY = ("runs", "bias_evaluations", "per_seed")  # tables too long to read as markdown
# tables whose numbers are written exactly (shortest round trip), not to 6 significant digits: the logs'
# values, which docs/RESULTS.md rounds itself (analysis.doc_tables)
EXACT = ("bias_evaluations", "per_seed")


def _write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """``<name>.csv`` for each table, and ``<name>.md`` but for those of CSV_ONLY."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, table in tables.items():
        csv = table.to_csv(index=False, float_format=None if name in EXACT else "%.6g")
        written.append(write_whole(folder / f"{name}.csv", csv))
        if name not in CSV_ONLY:
            written.append(write_whole(folder / f"{name}.md", markdown_table(table)))
    return written


def _write_studies(studies: Studies, folder: Path) -> list[Path]:
    """Each study's best trials as ``<stem>_best_trials.csv`` and ``.md``."""
    written = []
    for stem, study in studies.read.items():
        written += [write_whole(folder / f"{stem}_best_trials.csv", study.best.to_csv(index=False)),
                    write_whole(folder / f"{stem}_best_trials.md", study.best_markdown())]
    return written


def _html_figure(figure: ReportFigure, image: str) -> str:
    """One figure of the page: its title, its image (an ``<img>`` or inline SVG) and its caption."""
    return (f'<figure id="{figure.name}"><h3>{html.escape(figure.title)}</h3>{image}'
            f"<figcaption>{html.escape(figure.caption)}</figcaption></figure>")


def _html_page(folder: Path, table: RunTable, analysis: Analysis, images: list[tuple[ReportFigure, str]],
               studies: Studies, study_images: list[str], animations: dict[str, str],
               critic_tests: pd.DataFrame, claims: pd.DataFrame, provenance: pd.DataFrame) -> str:
    """The report page: summary tables, figures (the composition table after its figure, each task's
    policy animations after its learning curves), studies, runs."""
    runs = table.runs
    parts = [f"<h1>hersd report: {html.escape(str(folder))}</h1>",
             f"<p>{_count(len(runs), 'run')} ({_unfinished(runs)}: drawn in the learning "
             "curves only, left out of every table and median), "
             f"{_count(runs['task'].nunique(), 'task')}, {_count(runs['config'].nunique(), 'configuration')}; "
             f"test success smoothed over {_count(analysis.window, 'epoch')}.</p>"]
    skipped = table.warnings() + [f"skipped study storage {line}" for line in studies.skipped]
    if skipped:
        items = "".join(f"<li>{html.escape(line)}</li>" for line in skipped)
        parts.append(f"<p>Logs skipped, damaged, failed or read without their class:</p><ul>{items}</ul>")
    if not claims.empty:
        parts += ["<h2>The paper's claims, measured</h2>", f"<p>{TABLE_NOTES['claims']}</p>", html_table(_titled(claims))]
    parts += ["<h2>Summary per task and configuration</h2>", f"<p>{TABLE_NOTES['summary']}</p>",
              html_table(_titled(_page_summary(analysis.summary)),
                         epochs=_common_epochs(analysis.summary, runs)),
              "<h2>Across tasks</h2>", f"<p>{TABLE_NOTES['aggregate']}</p>",
              html_table(analysis.aggregate), *_tests_html(analysis.tests), *_equal_mu_html(analysis.equal_mu_tests),
              *_variant_html(analysis.variant_tests),
              "<h2>Figures</h2>"]
    placed = place_after_curves([figure.name for figure, _ in images], animations)
    for figure, image in images:
        parts.append(_html_figure(figure, image))
        if figure.name == f"composition_{PAPER_COMPOSITION_TASK}" and not analysis.composition_vs_paper.empty:
            parts += [f"<h3>Minibatch composition at epoch {PAPER_COMPOSITION_EPOCH}: hersd vs paper</h3>",
                      f"<p>{TABLE_NOTES['composition']}</p>", html_table(analysis.composition_vs_paper)]
        if figure.name == "critic_bias" and not critic_tests.empty:
            parts += ["<h3>The critic's bias over epochs 1-50: permutation tests</h3>",
                      f"<p>{TABLE_NOTES['critic_tests']}</p>", html_table(_titled(critic_tests))]
        parts += placed.get(figure.name, [])
    parts += placed.get(None, [])
    if studies.read:
        parts.append("<h2>Optuna searches</h2>")
        for (stem, study), image in zip(studies.read.items(), study_images):
            parts += [f"<figure><h3>{html.escape(stem)}: {html.escape(study.figure_title)}</h3>{image}</figure>",
                      f"<h3>Best trials: {html.escape(stem)}</h3><p>{html.escape(study.value_label)}</p>",
                      html_table(study.best.drop(columns=["run_dirs"], errors="ignore"),  # long: csv only
                                 float_format="{:.4g}")]
    parts += ["<h2>Runs</h2>", f"<p>{TABLE_NOTES['runs']}</p>", *_runs_html(analysis), *provenance_html(provenance)]
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'>{REPORT_TITLE}"
            f"<style>{PAGE_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")


def _page_summary(summary: pd.DataFrame) -> pd.DataFrame:
    """The summary as the page shows it, as wide as the page: without mu_eps (in Fig. 12 and the files), the IQM's
    interval in one column (``[low, high]``)."""
    interval = ["" if pd.isna(low) else f"[{low:.3f}, {high:.3f}]" for low, high in zip(summary["iqm_low"], summary["iqm_high"])]
    table = summary.drop(columns=["mu_eps", "iqm_high"]).rename(columns={"iqm_low": "iqm_interval"})
    return table.assign(iqm_interval=interval)


def _tests_html(tests: pd.DataFrame) -> list[str]:
    """The permutation tests' part of the page: the table when it has at most PAGE_TEST_ROWS rows, else
    where to read it; nothing when no pair of configurations has two seeds each."""
    if tests.empty:
        return []
    parts = ["<h2>Permutation tests between configurations</h2>", f"<p>{TABLE_NOTES['tests']}</p>"]
    if len(tests) <= PAGE_TEST_ROWS:
        return parts + [html_table(_titled(tests))]
    return parts + [f"<p>{len(tests)} tests: too many for this page; they are in tables/permutation_tests.md "
                    "and .csv.</p>"]


def _equal_mu_html(tests: pd.DataFrame) -> list[str]:
    """The decay against the constant rate at its mu_eps (analysis.metrics.equal_mu_tests); nothing without a pair."""
    if tests.empty:
        return []
    return ["<h2>Decay or mean rate: each decay against the constant rate at its μ_ε</h2>",
            f"<p>{TABLE_NOTES['equal_mu']}</p>", html_table(_titled(tests))]


def _variant_html(tests: pd.DataFrame) -> list[str]:
    """Each variant against its configuration at the defaults (analysis.metrics.variant_tests); nothing without."""
    if tests.empty:
        return []
    return ["<h2>Variants: each against its configuration at the defaults</h2>",
            f"<p>{TABLE_NOTES['variants']}</p>", html_table(_titled(tests))]


def _unfinished(runs: pd.DataFrame) -> str:
    """``2 in progress``, or ``1 in progress, 1 failed`` when some run stopped with an error."""
    failed = int((runs["error"] != "").sum())
    text = f"{int((~runs['complete']).sum()) - failed} in progress"
    return text + (f", {failed} failed" if failed else "")


def _run_list(analysis: Analysis) -> pd.DataFrame:
    """The run table with each run's state and own outcomes (:func:`analysis.metrics.run_outcomes`)."""
    runs = analysis.runs
    return runs.assign(state=run_states(runs)).merge(analysis.outcomes, on="run", how="left")


def run_state_words(complete: bool, damaged: bool, done: int, total: int, error: str = "") -> str:
    """A run's state as the page's run list says it: ``complete``, ``failed (epoch N of K): <error>`` for a run that
    stopped with an error, or ``in progress (epoch N of K)`` for a log without its completion marker (a run still
    running, stopped or killed) (:func:`analysis.metrics.run_state`); ``, log without a valid end`` added for a
    damaged log (an earlier-format log of a run running or killed, or a file cut short: the epochs before the cut
    are read)."""
    return run_state(complete, error, done, total) + (", log without a valid end" if damaged else "")


def _titled(table: pd.DataFrame) -> pd.DataFrame:
    """A table for the page: its ``task`` column (if any) as the tasks' titles (``push`` -> FetchPush)."""
    return table.assign(task=table["task"].map(task_title)) if "task" in table.columns else table


def _common_epochs(table: pd.DataFrame, runs: pd.DataFrame) -> int | None:
    """The number of epochs K of every complete run of the table's (task, configuration) rows; None if they differ."""
    keys = table[["task", "config"]].astype(str)
    complete = runs.loc[runs["complete"], ["task", "config", "total_epochs"]].astype({"config": str})
    epochs = complete.merge(keys, on=["task", "config"])["total_epochs"].unique()
    return int(epochs[0]) if len(epochs) == 1 else None


def _runs_html(analysis: Analysis) -> list[str]:
    """The page's run list: per task x configuration a collapsed ``<details>`` whose summary line counts its runs
    and gives its median final success, and whose table has one row per run (RUN_PAGE_COLUMNS)."""
    runs = _run_list(analysis)
    seconds = run_cost(analysis.epochs)["seconds_per_epoch"]
    runs = runs.merge(seconds, left_on="run", right_index=True, how="left").assign(
        run_folder=[Path(path).parent.name for path in runs["path"]],
        state=[run_state_words(*values) for values in
               zip(runs["complete"], runs["damaged"], runs["epochs_done"], runs["total_epochs"], runs["error"])])
    summary = analysis.summary.set_index(["task", "config"])
    ranks = runs["task"].map(lambda task: task_rank(task)[0])  # the paper's tasks first, then by name
    runs = runs.assign(task_order=ranks).sort_values(["task_order", "task", "config", "seed"])  # config: categorical
    parts = []
    for (task, config), group in runs.groupby(["task", "config"], observed=True, sort=False):
        done = int(group["complete"].sum())
        line = f"{task_title(task)} · {config}: {_count(len(group), 'run')}, {done} complete"
        failed = int((group["error"] != "").sum())
        if len(group) > done + failed:
            line += f", {len(group) - done - failed} in progress"
        if failed:
            line += f", {failed} failed"
        if done:
            row = summary.loc[(task, config)]
            line += (f"; test success at epoch {int(group.loc[group['complete'], 'total_epochs'].max())}, median "
                     f"over the complete seeds {row['final_median']:.3f}")
        parts.append(f'<details class="runs"><summary>{html.escape(line)}</summary>'
                     + html_table(group[RUN_PAGE_COLUMNS].reset_index(drop=True), columns=RUN_COLUMNS,
                                  titles={"run_folder": group["path"].reset_index(drop=True)}) + "</details>")
    return parts


def _copy_animations(analysis: Analysis, folder: Path, figures: Path) -> dict[str, str]:
    """Copy each task's chosen policy animations (analysis.animations) into ``figures/animations/`` (emptied
    first) -> task -> its page block, the GIFs linked by paths relative to the page."""
    chosen = choose_animations(analysis, folder)
    shutil.rmtree(figures / ANIMATIONS, ignore_errors=True)
    blocks = {}
    for task, items in chosen.items():
        (figures / ANIMATIONS).mkdir(parents=True, exist_ok=True)
        names = [file_name(index, item) for index, item in enumerate(items)]
        for item, name in zip(items, names):
            write_whole(figures / ANIMATIONS / name, item.source.read_bytes())
        blocks[task] = animations_html(task, items, [f"{figures.name}/{ANIMATIONS}/{name}" for name in names])
    return blocks


def _study_figures(studies: Studies) -> list[ReportFigure]:
    from analysis.figures import ReportFigure

    return [ReportFigure(f"{stem}_{study.figure_name}", f"{stem}: {study.figure_title}", study.value_label,
                         study.figure) for stem, study in studies.read.items()]


def _load(folder: Path, tasks, algos, timings: dict[str, float]) -> RunTable:
    """Read the logs (in worker processes when there are many), importing the modules that compute
    and draw meanwhile; timings gets ``load`` (the whole stage) and ``imports`` (those imports)."""
    start = time.perf_counter()
    reading = start_reading(folder)
    import_start = time.perf_counter()
    import scipy.stats  # noqa: F401  (the IQM and its bootstrap)

    import analysis.figures  # noqa: F401  (matplotlib)

    timings["imports"] = time.perf_counter() - import_start
    table = reading.result(tasks, algos)
    if not (table.runs["epochs_done"] > 0).any():
        raise ReportInputError(f"none of the {len(table.runs)} runs under {folder} has a completed epoch yet")
    timings["load"] = time.perf_counter() - start
    return table


@contextmanager
def _no_temporaries_left(paths: list[Path]) -> Iterator[None]:
    """On an error inside, once the workers have stopped: remove the temporary file of each of ``paths`` (a worker
    stopped in the middle of writing a figure leaves its own)."""
    try:
        yield
    except BaseException:
        for path in paths:
            temporary_file(path).unlink(missing_ok=True)
        raise


def _start_drawing(figures: list[ReportFigure], folders: list[Path], fmt: str) -> tuple[list[Path], ForkedMap]:
    """Start drawing and saving every figure (``figures[i]`` into ``folders[i]``), one worker process per core
    -> (the files, the ForkedMap whose ``results()`` are the ``<img>`` of each)."""
    paths = [folder / f"{figure.name}.{fmt}" for figure, folder in zip(figures, folders)]
    for folder in set(folders):
        folder.mkdir(parents=True, exist_ok=True)
    return paths, ForkedMap(_render, [(figure, path, fmt) for figure, path in zip(figures, paths)])


def _critic_tests(epochs: pd.DataFrame) -> pd.DataFrame:
    """The permutation tests of the critic's bias (analysis.critic) between the complete runs of each task: only
    the epochs with a bias evaluation go in (the others add nothing, and reading each run's rows costs time)."""
    bias = [f"bias_{goal_type}_mean" for goal_type in GOAL_TYPES]
    evaluated = epochs["complete"] & epochs[bias].notna().any(axis=1)
    return bias_tests(integrated_bias(epochs.loc[evaluated, [*GROUP, "run", "epoch", *bias]]))


def _analysis_tables(analysis: Analysis) -> dict[str, pd.DataFrame]:
    """The tables of the statistics by file stem: summary, aggregate, and those the data allows (not empty)."""
    tables = {"summary": analysis.summary, "aggregate": analysis.aggregate,
              f"composition_{PAPER_COMPOSITION_EPOCH}": analysis.composition_vs_paper,
              "permutation_tests": analysis.tests, "equal_mu_tests": analysis.equal_mu_tests,
              "variant_tests": analysis.variant_tests}
    return {name: table for name, table in tables.items() if name in ("summary", "aggregate") or not table.empty}


def _report_tables(table: RunTable, analysis: Analysis) -> tuple[dict[str, pd.DataFrame], pd.DataFrame, pd.DataFrame]:
    """Every table of the report by file stem but the run list, and the critic's bias tests and the claims
    (maybe empty) -> (tables, critic tests, claims)."""
    tables = _analysis_tables(analysis)
    if not (critic_tests := _critic_tests(table.epochs)).empty:
        tables["critic_bias_tests"] = critic_tests
    per_seed = seed_values(table.runs, table.epochs, analysis.curves, analysis.outcomes)
    if not (claims := full_claims_table(analysis.summary, analysis.tests, critic_tests, per_seed)).empty:
        tables["claims"] = claims
    tables["runs_provenance"] = provenance_table(table.runs, table.epochs, table.sessions)
    if not (evaluations := bias_evaluations(table.epochs)).empty:
        tables["bias_evaluations"] = evaluations
    tables["per_seed"] = per_seed
    return tables, critic_tests, claims


def _say_loaded(table: RunTable, seconds: float, log: Callable[[str], None], warn: Callable[[str], None]) -> None:
    """The terminal's account of the logs read: one warning line per log skipped, damaged, failed, read without its
    class or holding other rates than its class gives (:meth:`analysis.load.RunTable.warnings`), then the counts."""
    for line in table.warnings():
        warn(f"warning: {line}")
    runs = table.runs
    failed = int((runs["error"] != "").sum())
    log(f"loaded {_count(len(runs), 'run')} ({int((~runs['complete']).sum())} incomplete"
        f"{f', of which {failed} failed' if failed else ''}, {table.left_out} "
        f"skipped), {_count(len(table.epochs), 'epoch')}, {_count(runs['task'].nunique(), 'task')}, "
        f"{_count(runs['config'].nunique(), 'configuration')} in {seconds:.1f} s")


def build_report(folder: str | Path, out: str | Path | None = None, tasks: Sequence[str] | None = None,
                 algos: Sequence[str] | None = None, window: int = DEFAULT_WINDOW, fmt: str = "png",
                 storages: Sequence[str] = (), log: Callable[[str], None] = print,
                 warn: Callable[[str], None] = lambda line: print(line, file=sys.stderr)) -> ReportResult:
    """Load, compute, draw and write the report; ``log`` receives progress lines, ``warn`` one
    line per skipped log or study storage; ``storages`` (URLs or files) are read besides the
    study storages found in ``folder/search/``.

    Raises :class:`ReportInputError` for input that cannot make a report (checked before any
    log is read for the options and the given storages).
    """
    if fmt not in FORMATS:
        raise ReportInputError(f"unknown figure format {fmt!r}; choose one of: {', '.join(FORMATS)}")
    if window < 1:
        raise ReportInputError(f"--smooth must be at least 1 epoch, got {window}")
    folder = checked_folder(folder)
    out = _checked_out(Path(out) if out is not None else folder / "report")
    given = _open_given_storages(storages)
    timings: dict[str, float] = {}
    table = _load(folder, tasks, algos, timings)
    _say_loaded(table, timings["load"], log, warn)
    runs = table.runs
    studies = _read_studies(given, folder)
    for line in studies.skipped:
        warn(f"warning: skipped study storage {line}")

    from analysis.figures import all_figures
    from analysis.metrics import analyse_curves, with_statistics

    start = time.perf_counter()
    analysis = analyse_curves(runs, table.epochs, window)
    figures, study_figures = all_figures(analysis), _study_figures(studies)
    folders = [out / "figures"] * len(figures) + [out / "search"] * len(study_figures)
    timings["metrics"] = time.perf_counter() - start

    start = time.perf_counter()
    paths, drawing = _start_drawing(figures + study_figures, folders, fmt)
    with _no_temporaries_left(paths), drawing:  # an error below stops the workers, then removes what they left
        analysis = with_statistics(analysis)  # while the workers draw
        timings["statistics"] = time.perf_counter() - start
        tables, critic_tests, claims = _report_tables(table, analysis)
        written = _write_tables({**tables, "runs": _run_list(analysis).drop(columns=["run", "error"])}, out / "tables")
        written += _write_studies(studies, out / "search")
        timings["tables"] = time.perf_counter() - start - timings["statistics"]
        images = drawing.results()
    timings["figures"] = time.perf_counter() - start
    log(f"drew {_count(len(paths), 'figure')} in {timings['figures']:.1f} s")

    start = time.perf_counter()
    index = out / "index.html"
    animations = _copy_animations(analysis, folder, out / "figures")
    _remove_stale(out, [*paths, *written])  # before the page: its title says whether an earlier report was here
    write_whole(index, _html_page(folder, table, analysis, list(zip(figures, images)), studies, images[len(figures):],
                                  animations, critic_tests, claims, tables["runs_provenance"]))
    timings["writing"] = time.perf_counter() - start
    return ReportResult(index=index, figures=paths, tables=written, timings=timings)


def _checked_out(out: Path) -> Path:
    """``out``, or ReportInputError if the report cannot be written into it: a path that is a file or passes
    through one, or under a folder that is not writable; checked before any log is read."""
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ReportInputError(f"cannot write the report to {out}: {existing} is a file, not a folder; "
                               f"give --out a folder (it is created if missing)")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ReportInputError(f"cannot write the report to {out}: {existing} is not writable; "
                               f"give --out a folder you can write to")
    return out


def _is_report(out: Path) -> bool:
    """Whether ``out`` holds a page hersd-report wrote (its title), so its figures/ and tables/ are a report's."""
    page = out / "index.html"
    return page.is_file() and REPORT_TITLE in page.read_text(encoding="utf-8", errors="replace")[:500]


def _remove_stale(out: Path, written: list[Path]) -> None:
    """Delete the figure and table files an earlier report left in ``out``'s figures/ and tables/ that this one
    did not write (a figure of a task filtered out, a table that no longer applies), so every file there is of
    this report; only where an earlier report was (:func:`_is_report`: not a folder of the user's own that
    --out names). search/ is left alone: with ``--out`` at the results folder it holds the study storages."""
    if not _is_report(out):
        return
    kept = set(written)
    for folder in ("figures", "tables"):
        for path in (out / folder).glob("*"):
            if path.is_file() and path.suffix.lstrip(".") in (*FORMATS, "csv", "md") and path not in kept:
                path.unlink()


class _OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line on stderr, exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


@sigterm_as_ctrl_c()  # ``kill PID`` too: one line, exit 130
def main(argv: Sequence[str] | None = None) -> int:
    parser = _OneLineParser(prog="hersd-report",
                            description="Tables, figures and an HTML report from hersd run logs and Optuna studies.")
    parser.add_argument("folder", type=Path, help="folder searched recursively for run.mcap files")
    parser.add_argument("--out", type=Path, help="output folder (default: FOLDER/report)")
    parser.add_argument("--task", nargs="+", help="keep only these tasks (config task.name, e.g. push slide)")
    parser.add_argument("--algo", nargs="+", help="keep only these algorithm names (config algo.name)")
    parser.add_argument("--smooth", type=int, default=DEFAULT_WINDOW, metavar="N",
                        help=f"moving-average window of the learning curves in epochs (default {DEFAULT_WINDOW})")
    parser.add_argument("--format", choices=FORMATS, default="png", help="figure file format (default png)")
    parser.add_argument("--storage", action="append", default=[], metavar="URL",
                        help="also draw the Optuna studies of this storage, opened read-only: a SQLAlchemy URL "
                             "(e.g. postgresql+psycopg2://user@host/db), journal:<file>, or a .db / .log / "
                             ".journal file; repeatable (the storages in FOLDER/search/ are always read)")
    parser.add_argument("--tensorboard", type=Path, metavar="DIR",
                        help="write each run's TensorBoard event files to DIR/<task>/<label>/seed<N> instead of a "
                             "report, replacing earlier ones (needs the tensorboard package; docs/ANALYSIS.md)")
    args = parser.parse_args(argv)
    try:
        return _tensorboard(args) if args.tensorboard is not None else _report(args)
    except WorkerLostError as err:
        print(f"hersd-report: error: {err}; run hersd-report again", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("hersd-report: interrupted; run hersd-report again (the runs' logs are untouched)", file=sys.stderr)
        return 130


def _report(args: argparse.Namespace) -> int:
    """FOLDER's report: tables, figures and index.html in ``--out``."""
    try:
        result = build_report(args.folder, args.out, tasks=args.task, algos=args.algo, window=args.smooth,
                              fmt=args.format, storages=args.storage)
    except ReportInputError as err:
        print(f"hersd-report: error: {err}", file=sys.stderr)
        return 2
    except (DiskFullError, OSError) as err:  # a full disk: one line naming the file and the bytes it needs
        if not full_disk(err):
            return _unwritable(err, args.out if args.out is not None else args.folder / "report")
        if not isinstance(err, DiskFullError):  # a folder it could not make: one block of its device
            path = Path(err.filename or (args.out if args.out is not None else args.folder / "report"))
            err = DiskFullError(path, block_bytes(path))
        print(f"hersd-report: error: {DiskFullError(err.path, err.needed, 'free some and run hersd-report again')}",
              file=sys.stderr)
        return 2
    timings = result.timings
    print(f"report written to {result.index} (load {timings['load']:.1f} s incl. imports {timings['imports']:.1f} s, "
          f"metrics {timings['metrics']:.1f} s, figures {timings['figures']:.1f} s (meanwhile statistics "
          f"{timings['statistics']:.1f} s, tables {timings['tables']:.1f} s), writing {timings['writing']:.1f} s)")
    return 0


def _unwritable(err: BaseException, out: Path) -> int:
    """An OSError on a file but a full disk: one line naming the file, exit 2: written in the report folder ``out``
    (an earlier report's folder read-only, or another user's), or read from a run (its animation unreadable); an
    error naming no file is raised."""
    path = Path(err.filename) if isinstance(err, OSError) and err.filename is not None else None
    if path is None:
        raise err
    if not path.resolve().is_relative_to(out.resolve()):
        print(f"hersd-report: error: cannot read {path}: {err.strerror}; make it readable, or move it out of the "
              "folder", file=sys.stderr)
        return 2
    shown = path.with_name(path.name.removesuffix(".tmp")) if path.suffix == ".tmp" else path
    print(f"hersd-report: error: cannot write the report's file {shown}: {err.strerror}; give --out a folder you "
          "can write to", file=sys.stderr)
    return 2


def _tensorboard(args: argparse.Namespace) -> int:
    """``--tensorboard DIR``: the runs' event files (analysis.tensorboard_export), no report."""
    try:
        written, table = export_events(args.folder, args.tensorboard, tasks=args.task, algos=args.algo)
    except (ReportInputError, ConfigError) as err:
        print(f"hersd-report: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"hersd-report: error: cannot write the event files to {args.tensorboard}: {err.strerror} "
              f"({err.filename}); choose another --tensorboard folder", file=sys.stderr)
        return 2
    for line in table.warnings():  # the logs left out, damaged, failed: as the report names them
        print(f"warning: {line}", file=sys.stderr)
    print(f"TensorBoard event files of {len(written)} runs written to {args.tensorboard} "
          f"(tensorboard --logdir {args.tensorboard})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
