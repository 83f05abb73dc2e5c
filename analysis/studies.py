"""Optuna study storages, opened read-only: the report reads what ``hersd-search`` wrote
without importing the search (data flows search -> storage -> analysis).

A storage is named by

- a SQLAlchemy URL: ``sqlite:///<file>``, ``postgresql+psycopg2://user@host/db``, ``mysql://...``;
- ``journal:<file>``, or a file path: ``*.log`` / ``*.journal`` an Optuna journal, any other a
  SQLite file (``hersd-search`` writes ``<results_dir>/search/<study>.db`` by default).

:func:`open_study_storage` creates and changes nothing: SQLite is opened in SQLite's read-only
mode, PostgreSQL (psycopg drivers) in read-only transactions, journals by a backend that only
reads; a database without Optuna's tables is refused before Optuna could create them. Anything
it cannot read raises :class:`StudyStorageError`, whose message is one line naming the storage
(passwords hidden). Optuna and SQLAlchemy are imported only when a storage is opened.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

JOURNAL_PREFIX = "journal:"
JOURNAL_SUFFIXES = (".log", ".journal")
SQLITE_SUFFIXES = (".db", ".sqlite", ".sqlite3")
SEARCH_FOLDER = "search"  # hersd-search's storages and figures: <results_dir>/search/
DRIVER_HINTS = {"postgresql": 'pip install "hersd[cluster]"'}  # dialect -> how to install its driver
CONNECT_TIMEOUT_SECONDS = 10
MESSAGE_LIMIT = 160  # characters of a database's own error message kept in ours


class StudyStorageError(ValueError):
    """A study storage cannot be read; the message is one line for the user."""


@dataclass
class StudyStorage:
    """An opened storage: ``shown`` names it in messages (no password), ``study_names`` sorted."""

    shown: str
    storage: Any  # optuna.storages.BaseStorage
    study_names: list[str]


def find_study_storages(folder: Path) -> list[Path]:
    """The SQLite and journal files directly in ``folder/search/`` (where hersd-search puts them), sorted."""
    search = Path(folder) / SEARCH_FOLDER
    if not search.is_dir():
        return []
    return sorted(path for path in search.iterdir()
                  if path.is_file() and path.suffix in SQLITE_SUFFIXES + JOURNAL_SUFFIXES)


def open_study_storage(spec: str | Path) -> StudyStorage:
    """Open the storage named by ``spec`` (a URL, ``journal:<file>`` or a file path) to read its studies.

    Raises :class:`StudyStorageError` for an unknown URL scheme, a missing database driver, an
    unreachable database, a missing or unreadable file, or a storage holding no study.
    """
    spec = str(spec)
    if spec.startswith(JOURNAL_PREFIX) or ("://" not in spec and Path(spec).suffix in JOURNAL_SUFFIXES):
        opened = _open_journal(Path(spec.removeprefix(JOURNAL_PREFIX)).expanduser())
    elif "://" not in spec:
        path = Path(spec).expanduser()
        if not path.is_file():
            raise StudyStorageError(f"{path}: no such study storage")
        opened = _open_database(f"sqlite:///{path.resolve()}", shown=str(path))
    else:
        opened = _open_database(spec)
    if not opened.study_names:
        raise StudyStorageError(f"{opened.shown}: no Optuna study in this storage")
    return opened


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())[:MESSAGE_LIMIT]


class ReadOnlyJournal:
    """An Optuna journal backend that reads a journal file and refuses to write.

    Optuna's own file backend opens the file for appending (creating it when missing); this one
    only reads. A last line without its newline is a write in progress and is not read yet.
    """

    def __init__(self, path: Path) -> None:
        self.path = path

    def read_logs(self, log_number_from: int) -> Iterator[dict[str, Any]]:
        lines = self.path.read_bytes().split(b"\n")[:-1]  # the part after the last newline is incomplete
        for line in lines[log_number_from:]:
            yield json.loads(line)

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        raise StudyStorageError(f"{self.path}: opened read-only")


def _open_journal(path: Path) -> StudyStorage:
    if not path.is_file():
        raise StudyStorageError(f"{path}: no such study storage")
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import BaseJournalBackend

    BaseJournalBackend.register(ReadOnlyJournal)  # the journal interface, without inheriting a writer
    try:
        storage = JournalStorage(ReadOnlyJournal(path))
        names = sorted(optuna.get_all_study_names(storage))
    except (OSError, ValueError, KeyError, TypeError) as err:  # unreadable, not JSON, not Optuna's records
        raise StudyStorageError(f"{path}: not a readable Optuna journal ({_one_line(err)})") from None
    return StudyStorage(shown=str(path), storage=storage, study_names=names)


def _read_only_url(url):
    """``url`` (a sqlalchemy URL) made read-only where the driver allows it -> (url, engine options).
    A bare ``postgresql://`` gets the psycopg driver that is installed."""
    options: dict[str, Any] = {}
    backend = url.get_backend_name()
    if backend == "sqlite" and url.database not in (None, "", ":memory:"):
        path = Path(url.database.removeprefix("file:"))
        if not path.is_file():
            raise StudyStorageError(f"{path}: no such study storage")
        url = url.set(database=f"file:{path.resolve()}", query={"mode": "ro", "uri": "true"})
    if backend == "postgresql" and "+" not in url.drivername:
        url = url.set(drivername=f"postgresql+{_postgresql_driver()}")
    if backend == "postgresql" and url.get_driver_name() in ("psycopg2", "psycopg"):  # libpq's settings
        options["connect_args"] = {"connect_timeout": CONNECT_TIMEOUT_SECONDS,
                                   "options": "-c default_transaction_read_only=on"}
    return url, options


def _postgresql_driver() -> str:
    """psycopg2 when it is installed and psycopg (SQLAlchemy's default for postgresql://) is not."""
    import importlib.util

    installed = {name for name in ("psycopg", "psycopg2") if importlib.util.find_spec(name) is not None}
    return "psycopg2" if installed == {"psycopg2"} else "psycopg"


def _open_database(spec: str, shown: str | None = None) -> StudyStorage:
    """A SQLAlchemy URL's storage; ``shown`` names it in messages (default: the URL, password hidden)."""
    import sqlalchemy
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError, SQLAlchemyError

    try:
        url = sqlalchemy.make_url(spec)
    except (ArgumentError, ValueError) as err:
        raise StudyStorageError(f"{spec.split('@')[-1]}: not a storage URL ({_one_line(err)})") from None
    shown = shown or url.render_as_string(hide_password=True)
    url, options = _read_only_url(url)
    try:
        engine = sqlalchemy.create_engine(url, **options)
    except (NoSuchModuleError, ArgumentError) as err:  # an unknown scheme or dialect
        raise StudyStorageError(f"{shown}: not a storage URL ({_one_line(err)})") from None
    except ImportError as err:
        hint = DRIVER_HINTS.get(url.get_backend_name(), f"install the Python package {err.name}")
        raise StudyStorageError(f"{shown}: the database driver is missing ({err.name or _one_line(err)}); "
                                f"{hint}") from None
    try:
        with engine.connect() as connection:
            is_optuna = sqlalchemy.inspect(connection).has_table("studies")
    except SQLAlchemyError as err:
        raise StudyStorageError(f"cannot reach the database at {shown} "
                                f"({_one_line(getattr(err, 'orig', None) or err)})") from None
    finally:
        engine.dispose()
    if not is_optuna:
        raise StudyStorageError(f"{shown}: no Optuna study in this storage")
    return _open_optuna_database(url, options, shown)


def _open_optuna_database(url, options: dict[str, Any], shown: str) -> StudyStorage:
    import optuna
    from optuna.storages import RDBStorage
    from sqlalchemy.exc import SQLAlchemyError

    try:
        storage = RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options,
                             skip_table_creation=True)
        names = sorted(optuna.get_all_study_names(storage))
    except (SQLAlchemyError, RuntimeError) as err:  # e.g. a schema of another Optuna version
        raise StudyStorageError(f"{shown}: cannot read its studies ({_one_line(err)})") from None
    return StudyStorage(shown=shown, storage=storage, study_names=names)
