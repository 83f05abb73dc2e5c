"""sweeps/search/storage.py: opening a study storage for writing."""

from __future__ import annotations

import importlib.util
import multiprocessing
import sys
from pathlib import Path

import optuna
import pytest
from searches import fails_with, tiny_search

from sweeps.search.storage import open_storage


@pytest.mark.skipif(importlib.util.find_spec("psycopg2") is None, reason="needs psycopg2 (hersd[cluster])")
def test_an_unreachable_database_is_one_line(tmp_path: Path, capsys) -> None:
    err = fails_with(["search.storage=postgresql://u:secret@127.0.0.1:1/x", *tiny_search(tmp_path)], capsys)
    assert "search.storage: cannot reach the database at postgresql+psycopg2://u:***@127.0.0.1:1/x" in err
    assert "secret" not in err


def test_a_missing_database_driver_is_one_line(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "psycopg2", None)  # import psycopg2 now fails as if not installed
    err = fails_with(["search.storage=postgresql+psycopg2://u@127.0.0.1:1/x", *tiny_search(tmp_path)], capsys)
    assert 'the database driver psycopg2 is not installed; pip install "hersd[cluster]"' in err


def _claim_enqueued(db: str, calls: str) -> None:
    study = optuna.load_study(study_name="queue", storage=open_storage(db))

    def record(trial: optuna.Trial) -> float:
        with open(calls, "a") as out:
            out.write(f"{trial.number}\n")
        return trial.suggest_float("x", 0.0, 1.0)

    study.optimize(record, n_trials=20)


def test_sqlite_workers_never_claim_one_enqueued_trial_twice(tmp_path: Path) -> None:
    """Plain SQLite lets two workers popping the queue at once both take a trial (seen here
    as duplicated numbers and 'Cannot tell a COMPLETE trial' crashes); the claim lock stops it."""
    db, calls = str(tmp_path / "queue.db"), str(tmp_path / "calls.txt")
    study = optuna.create_study(study_name="queue", storage=open_storage(db))
    for i in range(40):
        study.enqueue_trial({"x": i / 40})
    context = multiprocessing.get_context("fork")  # quick to start; the children open their own storage
    processes = [context.Process(target=_claim_enqueued, args=(db, calls)) for _ in range(2)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(timeout=120)
    numbers = Path(calls).read_text().split()
    assert [process.exitcode for process in processes] == [0, 0]
    assert len(numbers) == len(set(numbers)) == 40


def test_a_journal_whose_last_record_is_cut_is_refused_with_the_command_that_cuts_it_off(tmp_path: Path,
                                                                                       capsys) -> None:
    journal = tmp_path / "study.log"
    optuna.create_study(study_name="cut", storage=open_storage(f"journal:{journal}")).enqueue_trial({"x": 0.5})
    whole = journal.stat().st_size
    with open(journal, "rb+") as file:
        file.truncate(whole - 5)  # the last record's end lost: a writer killed mid-record
    before = journal.read_bytes()
    err = fails_with([f"search.storage=journal:{journal}", *tiny_search(tmp_path)], capsys)
    assert f"the last record of the journal {journal} is cut" in err
    size = int(err.split("truncate -s ")[1].split()[0])
    assert journal.read_bytes() == before and before[size - 1:size] == b"\n" and b"\n" not in before[size:]
    with open(journal, "rb+") as file:  # the fix the line gives: the whole records stay readable and writable
        file.truncate(size)
    study = optuna.load_study(study_name="cut", storage=open_storage(f"journal:{journal}"))
    study.enqueue_trial({"x": 0.25})
    assert len(optuna.load_study(study_name="cut", storage=open_storage(f"journal:{journal}")).trials) == 1  # the new one
