"""Where each run's numbers come from, read from its log: the provenance table of ``hersd-report``.

A run's log holds one ``/run/meta`` message per training session (the first start, then one per
resume; :mod:`hersd.contract.runlog`). :func:`session_rows` keeps what each session says about the code and the
machine that ran it; :func:`provenance_table` makes one row per run of them and of its cost (:func:`run_cost`;
columns: :data:`PROVENANCE_COLUMNS`), written as ``tables/runs_provenance.csv`` and ``.md``. A field a session's
log lacks (logs written before hersd recorded it) reads ``not logged``; :func:`provenance_note` says
once which fields and how many runs.
"""

from __future__ import annotations

import html
from datetime import datetime
from typing import Any

import pandas as pd

from analysis.tables import RUN_COLUMNS, Column, html_table
from hersd.contract.tasks import task_rank, task_title

NOT_LOGGED = "not logged"
NO_COMMIT = "none"  # a session run outside a git checkout
SESSION_SEPARATOR = " / "  # a run's per-session values, in session order, where its sessions differ
START_TIME_FORMAT = "%Y-%m-%dT%H:%M:%S%z"  # hersd.contract.runlog's /run/meta start_time
RUN_LOGS_LACK = {True: "run's log lacks", False: "runs' logs lack"}  # the note's words, by: a single run
# per-session fields that logs of early sessions may lack: column -> what the note calls it
MAYBE_UNLOGGED = {"cpu": "the CPU", "threads": "the thread count", "flush_denormal": "the flush_denormal setting"}
PROVENANCE_COLUMNS = (
    "task", "config", "seed",
    "folder",             # the run's folder relative to the report's folder
    "epochs_done", "total_epochs", "complete",
    "sessions",           # training sessions: the first start, then one per resume
    "resume_epochs",      # epochs done when each later session started (empty: never resumed)
    "commits",            # each session's git commit (12 hex digits; -dirty: with uncommitted changes)
    "dirty",              # a session ran code with uncommitted changes
    "cpu", "threads", "flush_denormal",  # one value, or one per session where they differ
    "seconds_per_epoch",  # median wall-clock seconds of the run's epochs
    "paced_hours",        # the run's cost: its epochs at their median pace (epochs_done x seconds_per_epoch), in hours
    "epoch_hours",        # wall-clock hours of its epochs, summed (epoch_seconds; bias evaluations apart): with
                          # whatever stopped or slowed the process (a paused campaign, other work on its cores)
    "bias_evaluations",   # epochs with a bias evaluation (hersd/engine/bias.py)
    "bias_seconds",       # their wall-clock seconds, summed (bias_seconds): with whatever stopped the process
    "bias_percent",       # bias_evaluations at their median seconds, as a percentage of paced_hours (0 without)
    "first_date", "last_date",  # UTC: the first session's start, the log's last message's time
)
# the page's table: a run named by its task, configuration and seed (its folder the tooltip), then its
# provenance; headers (analysis.tables.Column) short, so the table fits a 1280-px window
PAGE_COLUMNS = {"run": Column("run"), "epochs_done": Column("epochs done"), "sessions": Column("sessions"),
                "resume_epochs": Column("resumed at epochs"), "commits": Column("commit per session"),
                "dirty": Column("dirty"), "cpu": Column("CPU"), "threads": Column("threads"),
                "flush_denormal": Column("flush denormals"), "seconds_per_epoch": RUN_COLUMNS["seconds_per_epoch"],
                "paced_hours": Column("hours at the median pace", "{:.2f}"),
                "bias_percent": Column("bias evaluations (% of those hours)", "{:.2f}"),
                "first_date": Column("first start (UTC)"), "last_date": Column("last log message (UTC)")}
# the columns made from a run's sessions (_run_provenance)
SESSION_CELLS = ("sessions", "resume_epochs", "commits", "dirty", *MAYBE_UNLOGGED, "first_date", "last_date")


def session_rows(sessions: list[dict[str, Any]], message_times: list[tuple[str, int]]) -> list[dict[str, Any]]:
    """One dict per session of a log: its ``resumed_from_epoch``, ``git_commit``, ``threads``, ``cpu``,
    ``flush_denormal`` (None where the session's metadata lacks it), ``started`` and ``ended`` (ns since the
    Unix epoch: its ``start_time``, else its metadata message's log time; the log time of its last message in
    the file before the next session's metadata; logs written before resumes kept the earlier messages' log times give earlier sessions the
    resume's time, but the last session's is exact). ``sessions``: the metadata in file order; ``message_times``:
    (topic, log time) of every message in file order."""
    starts = [index for index, (topic, _) in enumerate(message_times) if topic == "/run/meta"]
    spans = [(message_times[start][1], message_times[end - 1][1])
             for start, end in zip(starts, [*starts[1:], len(message_times)])]
    return [{"resumed_from_epoch": int(meta.get("resumed_from_epoch") or 0),
             "git_commit": meta.get("git_commit"),
             "threads": meta.get("threads"),
             "cpu": (meta.get("machine") or {}).get("cpu_model"),
             "flush_denormal": (meta.get("config") or {}).get("flush_denormal"),
             "started": _start_time(meta.get("start_time"), written), "ended": ended}
            for meta, (written, ended) in zip(sessions, spans)]


def _start_time(start_time: Any, written: int) -> int:
    """A session's ``start_time`` (``%Y-%m-%dT%H:%M:%S%z``) in ns since the Unix epoch; ``written`` (its metadata
    message's log time) if it has none that parses."""
    try:
        return int(datetime.strptime(start_time, START_TIME_FORMAT).timestamp()) * 1_000_000_000
    except (TypeError, ValueError):
        return written


def session_table(per_log: list[list[dict[str, Any]]]) -> pd.DataFrame:
    """The sessions of every loaded log: one row per run x session (columns ``run``, ``session`` (0-based),
    then those of :func:`session_rows`); ``per_log[i]`` is run i's."""
    rows = [{"run": run, "session": index, **session}
            for run, sessions in enumerate(per_log) for index, session in enumerate(sessions)]
    return pd.DataFrame.from_records(rows, columns=["run", "session", "resumed_from_epoch", "git_commit", "threads",
                                                    "cpu", "flush_denormal", "started", "ended"])


def _per_session(values: list[Any]) -> str:
    """One cell from a run's per-session values: the value if every session has it, else each session's in order;
    ``not logged`` for a session without it."""
    words = [NOT_LOGGED if value is None or value != value else str(value).lower() if isinstance(value, bool)
             else f"{value:g}" if isinstance(value, float) else str(value) for value in values]
    return words[0] if len(set(words)) == 1 else SESSION_SEPARATOR.join(words)


def _commit(commit: Any) -> str:
    """A session's commit as its first 12 hex digits (``-dirty`` kept), or ``NO_COMMIT``."""
    if not isinstance(commit, str):
        return NO_COMMIT
    return commit[:12] + ("-dirty" if commit.endswith("-dirty") else "")


def _date(nanoseconds: float) -> str:
    return pd.Timestamp(int(nanoseconds), unit="ns", tz="UTC").strftime("%Y-%m-%d %H:%M")


def _run_provenance(sessions: list[dict[str, Any]]) -> dict[str, Any]:
    """One run's provenance cells from its sessions (rows of the session table, in session order)."""
    commits = [_commit(session["git_commit"]) for session in sessions]
    return {"sessions": len(sessions),
            "resume_epochs": " ".join(str(session["resumed_from_epoch"]) for session in sessions[1:]),
            "commits": " ".join(commits),
            "dirty": any(commit.endswith("-dirty") for commit in commits),
            **{name: _per_session([session[name] for session in sessions]) for name in MAYBE_UNLOGGED},
            "first_date": _date(min(session["started"] for session in sessions)),
            "last_date": _date(max(session["ended"] for session in sessions))}


def run_cost(epochs: pd.DataFrame) -> pd.DataFrame:
    """Per run (index ``run``), from its logged epochs: ``seconds_per_epoch`` (median), ``paced_hours``,
    ``epoch_hours``, ``bias_evaluations``, ``bias_seconds`` and ``bias_percent`` (:data:`PROVENANCE_COLUMNS`). The
    median pace is the cost a reader can plan with: a paused process adds its pause to the epoch or the bias
    evaluation under way (wall-clock ``epoch_seconds``, ``bias_seconds``), which the sums keep and the medians
    ignore, so ``bias_percent`` prices each evaluation at the run's median evaluation."""
    grouped = epochs.groupby("run")
    cost = pd.DataFrame({"seconds_per_epoch": grouped["epoch_seconds"].median(),
                         "epoch_seconds": grouped["epoch_seconds"].sum(), "epochs": grouped.size(),
                         "bias_evaluations": grouped["bias_seconds"].count(),
                         "bias_seconds": grouped["bias_seconds"].sum()})  # sum of none: 0
    paced = cost["epochs"] * cost["seconds_per_epoch"]
    bias_paced = cost["bias_evaluations"] * grouped["bias_seconds"].median().fillna(0.0)
    return cost.assign(paced_hours=paced / 3600, epoch_hours=cost["epoch_seconds"] / 3600,
                       bias_percent=100 * bias_paced / paced).drop(columns=["epoch_seconds", "epochs"])


def provenance_table(runs: pd.DataFrame, epochs: pd.DataFrame, sessions: pd.DataFrame) -> pd.DataFrame:
    """One row per run (columns :data:`PROVENANCE_COLUMNS`), ordered by task (the paper's first), configuration
    and seed: ``runs``, ``epochs`` and ``sessions`` as :class:`analysis.load.RunTable` holds them."""
    by_run: dict[int, list[dict[str, Any]]] = {}
    for session in sessions.sort_values(["run", "session"]).to_dict("records"):
        by_run.setdefault(session["run"], []).append(session)
    cells = pd.DataFrame.from_records([{"run": run, **_run_provenance(rows)} for run, rows in by_run.items()],
                                      columns=["run", *SESSION_CELLS])
    own = runs.drop(columns=[name for name in SESSION_CELLS if name in runs.columns])  # runs.cpu: the first session's
    table = (own.merge(cells, on="run", how="left").merge(run_cost(epochs), left_on="run", right_index=True, how="left")
             .assign(folder=[path.rsplit("/", 1)[0] if "/" in path else "." for path in runs["path"]],
                     task_order=runs["task"].map(lambda task: task_rank(task)[0])))
    table = table.sort_values(["task_order", "task", "config", "seed", "folder"])
    return table[list(PROVENANCE_COLUMNS)].reset_index(drop=True)


def provenance_note(table: pd.DataFrame) -> str:
    """The table's one note on what its logs do not record: per field, how many runs have a session whose log
    lacks it ("" when every log records everything)."""
    lacking = {words: int(table[name].str.contains(NOT_LOGGED).sum()) for name, words in MAYBE_UNLOGGED.items()}
    parts = [f"{count} {RUN_LOGS_LACK[count == 1]} {words} for some or all sessions"
             for words, count in lacking.items() if count]
    if parts:
        parts = [f"\u201c{NOT_LOGGED}\u201d: the session started before hersd recorded the field in its log: "
                 + "; ".join(parts) + "."]
    if lacking[MAYBE_UNLOGGED["flush_denormal"]]:
        parts.append("A session without flush_denormal ran without flushing denormals (as flush_denormal=false does).")
    if outside := int(table["commits"].str.split(" ").map(lambda commits: NO_COMMIT in commits).sum()):
        parts.append(f"Commit \u201c{NO_COMMIT}\u201d: {outside} run{' has' if outside == 1 else 's have'} a session "
                     "run outside a git checkout.")
    return " ".join(parts)


def provenance_html(table: pd.DataFrame) -> list[str]:
    """The report page's provenance section: a heading, then the table (``table``: :func:`provenance_table`'s, its
    :data:`PAGE_COLUMNS`) collapsed, with its note."""
    note = provenance_note(table)
    names = [f"{task_title(task)} \u00b7 {config} \u00b7 seed {seed}"
             for task, config, seed in zip(table["task"], table["config"], table["seed"])]
    shown = table.assign(run=names)[list(PAGE_COLUMNS)]
    return ["<h2>Provenance of the runs</h2>",
            '<details class="provenance"><summary>Per run, from its log: the commit of each session (-dirty: with '
            "uncommitted changes), the CPU, threads and flush_denormal setting, the epochs it was resumed at, its "
            "seconds per epoch, hours of epochs at that pace, the bias evaluations' share of them and dates (click "
            'to open; all columns in <a href="tables/runs_provenance.csv">tables/runs_provenance.csv</a>)</summary>'
            + (f"<p>{html.escape(note)}</p>" if note else "")
            + html_table(shown, columns=PAGE_COLUMNS, titles={"run": table["folder"]}) + "</details>"]
