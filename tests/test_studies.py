"""analysis/studies.py: opening a study storage read-only; a bad storage, an unreachable database or a
missing driver is one line (hersd-report --storage)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from analysis.report import main as report_main
from analysis.studies import open_study_storage
from hersd.contract.study import StudyStorageError


def _bad_storages(folder: Path) -> list[tuple[str, str]]:
    cases = [("foo://nowhere", "foo://nowhere: not a storage URL"),
             ("/no/such/study.db", "/no/such/study.db: no such study storage"),
             (f"sqlite:///{folder / 'no_study.db'}", "no Optuna study in this storage"),
             (str(folder / "plain.db"), f"{folder / 'plain.db'}: no Optuna study in this storage"),
             (f"journal:{folder / 'notes.log'}", "not a readable Optuna journal")]
    return cases


@pytest.mark.parametrize("case", range(5))
def test_a_bad_storage_is_one_line_and_exit_2_before_any_log_is_read(hand_sized, storages, tmp_path, capsys, case):
    storage, message = _bad_storages(storages)[case]
    assert report_main([str(hand_sized), "--out", str(tmp_path / "out"), "--storage", storage]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hersd-report: error: --storage ") and message in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("url", ["postgresql+psycopg2://user:secret@127.0.0.1:1/none",
                                 "postgresql://user:secret@127.0.0.1:1/none"])  # psycopg2 for the bare scheme
def test_an_unreachable_database_is_one_line_without_its_password(hand_sized, tmp_path, capsys, monkeypatch, url):
    pytest.importorskip("psycopg2")  # hersd[cluster]
    monkeypatch.setitem(sys.modules, "psycopg", None)  # SQLAlchemy's default driver for postgresql://, not installed
    assert report_main([str(hand_sized), "--out", str(tmp_path), "--storage", url]) == 2  # nothing listens on port 1
    err = capsys.readouterr().err
    shown = url.replace("secret", "***")
    assert err.count("\n") == 1 and f"--storage {shown}: cannot reach the database (connection to server" in err, err
    assert "secret" not in err


def test_a_missing_database_driver_says_what_to_install(hand_sized, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "psycopg2", None)  # as if not installed
    assert report_main([str(hand_sized), "--out", str(tmp_path), "--storage", "postgresql+psycopg2://u@db/x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and 'the database driver is missing (psycopg2); pip install "hersd[cluster]"' in err


def _files(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {path.name: (path.read_bytes(), path.stat().st_mtime_ns) for path in folder.iterdir()}


def test_storages_are_opened_read_only(storages):
    before = _files(storages)
    for spec in ("study.db", "study.log"):
        opened = open_study_storage(storages / spec)
        assert opened.study_names == ["in_sqlite" if spec.endswith(".db") else "in_journal"]
        import optuna

        assert len(optuna.load_study(study_name=opened.study_names[0], storage=opened.storage).trials) == 3
    with pytest.raises(StudyStorageError):  # refused before Optuna could create its tables
        open_study_storage(storages / "plain.db")
    assert _files(storages) == before  # not a byte, not a time stamp, no new file (no -journal, -wal, .lock)


def test_a_default_storage_under_a_folder_named_with_hash_percent_and_question_mark_is_created_and_found(tmp_path):
    import optuna

    from hersd.contract.study import default_storage, find_study_storages
    from sweeps.search.storage import open_storage

    results = tmp_path / "a#b%41c?d"  # '#' a URL fragment, '%41' an escaped 'A', '?' a query in an unquoted URL
    optuna.create_study(study_name="s", storage=open_storage(default_storage(results, "s")))
    assert [path.name for path in find_study_storages(results)] == ["s.db"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["a#b%41c?d"]  # no database beside it
    assert [open_study_storage(path).study_names for path in find_study_storages(results)] == [["s"]]
