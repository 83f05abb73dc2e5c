"""Plain functions the tests of sweeps/search/ import (tests/test_search_*.py): tiny searches, their study
and runs read back, hersd-search's one-line errors, a read-only peek at a SQLite study being written."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import optuna
import pytest
from helpers import TINY
from optuna.trial import TrialState

from hersd.contract.runlog import read_run
from sweeps.search import cli
from sweeps.search.storage import open_storage

FINISHED = (TrialState.COMPLETE, TrialState.PRUNED)


def tiny_search(results: Path, *extra: str, epochs: int = 4) -> list[str]:
    return [*TINY, f"epochs={epochs}", f"results_dir={results}", *extra]


def load(storage: str) -> optuna.Study:
    names = optuna.get_all_study_names(open_storage(storage))
    assert len(names) == 1
    return optuna.load_study(study_name=names[0], storage=open_storage(storage))


def only_db(results: Path) -> str:
    (db,) = (results / "search").glob("*.db")
    return str(db)


def run_meta(run: str) -> dict:
    return read_run(Path(run) / "run.mcap").meta


def fails_with(argv: list[str], capsys) -> str:
    """hersd-search's one stderr line for ``argv`` (asserting exit code 2 and one line)."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert err.count("\n") == 1 and err.startswith("hersd-search: error: "), err
    return err


def _trial_numbers(db: Path, states: tuple[str, ...]) -> list[int]:
    """Read-only peek at a study being written (no optuna: it would create tables) -> numbers of trials in ``states``."""
    marks = ", ".join("?" * len(states))
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30) as connection:
            rows = connection.execute(f"SELECT number FROM trials WHERE state IN ({marks})", states).fetchall()
    except sqlite3.OperationalError:  # not created yet
        return []
    return sorted(number for (number,) in rows)


def _count_finished(db: Path) -> int:
    return len(_trial_numbers(db, ("COMPLETE", "PRUNED")))
