"""The provenance table (analysis/provenance.py): one row per run from its log's sessions, a resumed run's
sessions each with their commit and machine, fields early logs lack shown as such and noted once."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.load import load_runs
from analysis.provenance import NO_COMMIT, NOT_LOGGED, provenance_note, provenance_table, session_rows
from analysis.report import build_report
from analysis.synthetic import epoch_records, write_run
from analysis_logs import make_config
from hersd.contract.config import config_record
from hersd.contract.runlog import RunLogWriter, read_run

FIRST = {"git_commit": "a" * 40 + "-dirty", "threads": 1, "machine": {"cpu_model": "CPU A"},
         "start_time": "2026-01-02T03:04:05+0000"}
SECOND = {"git_commit": "b" * 40, "threads": 2, "machine": {"cpu_model": "CPU B"},
          "start_time": "2026-01-05T06:07:08+0100", "resumed_from_epoch": 3}


def write_resumed(folder, config) -> None:
    """A run of 6 epochs in two sessions, as training resumes one: epochs 1-3, then 4-6 and the end marker."""
    path = write_run(folder, config, np.full(3, 0.5), complete=False, meta=FIRST)
    previous = read_run(path)
    writer = RunLogWriter(path, {**previous.meta, **SECOND}, previous=previous)
    with writer.batch():
        for record in epoch_records(config, np.full(6, 0.5))[3:]:
            writer.write_epoch(record)
        writer.finish(6)


def write_early(folder, config) -> None:
    """A run whose log predates the threads, machine and flush_denormal fields, made outside a git checkout."""
    record = {key: value for key, value in config_record(config).items() if key != "flush_denormal"}
    write_run(folder, config, np.full(6, 0.5), meta={"config": record, "start_time": "2026-01-01T00:00:00+0000"})


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A resumed run (seed 0), an early one (seed 1), one in progress (seed 2): the folder and the times around
    the writing (UTC, minutes)."""
    folder = tmp_path_factory.mktemp("provenance")
    before = pd.Timestamp.now(tz="UTC").strftime("%Y-%m-%d %H:%M")
    write_resumed(folder / "resumed", make_config(seed=0))
    write_early(folder / "early", make_config(seed=1))
    write_run(folder / "running", make_config(seed=2), np.full(2, 0.5), complete=False, meta=FIRST)
    return folder, before, pd.Timestamp.now(tz="UTC").strftime("%Y-%m-%d %H:%M")


def provenance(folder) -> pd.DataFrame:
    table = load_runs(folder)
    return provenance_table(table.runs, table.epochs, table.sessions).set_index("seed")


def test_a_resumed_run_shows_each_sessions_commit_machine_and_the_resume_epoch(logs):
    folder, before, after = logs
    row = provenance(folder).loc[0]
    assert (row["folder"], row["epochs_done"], row["complete"], row["sessions"]) == ("resumed", 6, True, 2)
    assert row["resume_epochs"] == "3"
    assert row["commits"] == "aaaaaaaaaaaa-dirty bbbbbbbbbbbb" and row["dirty"]
    assert (row["cpu"], row["threads"], row["flush_denormal"]) == ("CPU A / CPU B", "1 / 2", "true")
    assert row["seconds_per_epoch"] == 45.0  # analysis.synthetic's epochs
    assert row["first_date"] == "2026-01-02 03:04"  # the first session's start_time, in UTC
    assert before <= row["last_date"] <= after  # the log's last message, written just now


def test_a_run_in_progress_has_one_session_and_no_resume(logs):
    folder, _, _ = logs
    row = provenance(folder).loc[2]
    assert (row["epochs_done"], row["total_epochs"], row["complete"]) == (2, 6, False)
    assert (row["sessions"], row["resume_epochs"], row["commits"], row["dirty"]) == (1, "", "aaaaaaaaaaaa-dirty", True)


def test_fields_an_early_log_lacks_read_not_logged_and_the_note_says_so_once(logs):
    folder, _, _ = logs
    table = provenance(folder)
    early = table.loc[1]
    assert (early["cpu"], early["threads"], early["flush_denormal"]) == (NOT_LOGGED,) * 3
    assert early["commits"] == NO_COMMIT and not early["dirty"]
    assert early["first_date"] == "2026-01-01 00:00"
    note = provenance_note(table.reset_index())
    for words in ("the CPU", "the thread count", "the flush_denormal setting"):
        assert f"1 run's log lacks {words}" in note
    assert "flush_denormal=false" in note and "1 run has a session run outside a git checkout" in note
    complete = provenance(folder).loc[[0, 2]].reset_index()
    assert provenance_note(complete) == ""  # every field logged, every session in a checkout


def test_the_report_writes_the_table_and_shows_it_with_its_note_once(logs, tmp_path):
    folder, _, _ = logs
    result = build_report(folder, tmp_path / "report", log=lambda line: None, warn=lambda line: None)
    written = pd.read_csv(tmp_path / "report" / "tables" / "runs_provenance.csv", keep_default_na=False)
    assert sorted(written["seed"]) == [0, 1, 2] and (tmp_path / "report" / "tables" / "runs_provenance.md").exists()
    assert written.set_index("seed").loc[0, "commits"] == "aaaaaaaaaaaa-dirty bbbbbbbbbbbb"
    page = result.index.read_text(encoding="utf-8")
    assert page.count("before hersd recorded the field") == 1 and "<h2>Provenance of the runs</h2>" in page
    assert 'href="tables/runs_provenance.csv"' in page and page.count("CPU A / CPU B") == 1


def test_session_spans_follow_the_metadata_messages():
    sessions = [{"resumed_from_epoch": 0, "start_time": "bad"}, {"resumed_from_epoch": 2}]
    times = [("/run/meta", 10), ("/epoch", 20), ("/epoch", 30), ("/run/meta", 40), ("/epoch", 50), ("/run/status", 60)]
    rows = session_rows(sessions, times)
    assert [(row["started"], row["ended"]) for row in rows] == [(10, 30), (40, 60)]  # no start_time: the log time
    assert rows[1]["git_commit"] is None and rows[1]["cpu"] is None and rows[1]["flush_denormal"] is None


def test_each_runs_cost_and_the_bias_evaluations_share_of_it_come_from_its_epochs(tmp_path):
    bias_seconds = np.array([3.0, 4.5, np.nan, np.nan, 906.0, np.nan])  # at epochs 1, 2 and 5, paused 15 min in 5
    write_run(tmp_path / "evaluated", make_config(seed=0), np.full(6, 0.5), bias_seconds=bias_seconds,
              epoch_seconds=np.array([40.0, 50.0, 45.0, 45.0, 45.0, 945.0]))  # paused 15 min in epoch 6
    write_run(tmp_path / "unevaluated", make_config(seed=1), np.full(6, 0.5))
    table = provenance(tmp_path)
    evaluated, unevaluated = table.loc[0], table.loc[1]
    assert evaluated["epoch_hours"] == pytest.approx(1170 / 3600) and evaluated["seconds_per_epoch"] == 45.0
    assert evaluated["paced_hours"] == pytest.approx(6 * 45 / 3600)  # the pause left out
    assert (evaluated["bias_evaluations"], evaluated["bias_seconds"]) == (3, 913.5)
    assert evaluated["bias_percent"] == pytest.approx(5.0)  # 3 x 4.5 s (the median) of the 270 s at the median pace
    assert (unevaluated["bias_evaluations"], unevaluated["bias_seconds"], unevaluated["bias_percent"]) == (0, 0.0, 0.0)
