"""Opening a study storage read-only: the report's side of the study contract (:mod:`hersd.contract.study`
names storages and encodes trials; ``sweeps.search.storage`` opens them for writing).

:func:`open_study_storage` creates and changes nothing: SQLite in its read-only mode, PostgreSQL
in read-only transactions, journals through a backend that only reads. Every failure is a
:class:`hersd.contract.study.StudyStorageError` with one line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator
from urllib.parse import quote

from hersd.contract.study import DRIVER_HINTS, StudyStorageError, connect_args, one_line, storage_file, storage_location, \
    storage_name, with_driver


@dataclass
class StudyStorage:
    """A storage opened read-only: ``shown`` names it in messages (no password), ``study_names`` sorted."""

    shown: str
    storage: Any  # optuna.storages.BaseStorage
    study_names: list[str]


def open_study_storage(spec: str | Path) -> StudyStorage:
    """Open the storage ``spec`` names to read its studies, creating and changing nothing.

    SQLite is opened in SQLite's read-only mode, PostgreSQL (psycopg drivers) in read-only
    transactions, journals by a backend that only reads; a database without Optuna's tables is
    refused before Optuna could create them. Raises :class:`StudyStorageError` for an unknown
    URL scheme, a missing driver, an unreachable database, a missing or unreadable file, or a
    storage holding no study.
    """
    spec = str(spec)
    kind, location = storage_location(spec)
    path, name = storage_file(spec), storage_name(spec)
    if path is not None and not path.is_file():
        raise StudyStorageError(f"{name}: no such study storage")
    opened = _read_journal(path) if kind == "journal" else _read_database(location, name)
    if not opened.study_names:
        raise StudyStorageError(f"{opened.shown}: no Optuna study in this storage")
    return opened


class ReadOnlyJournal:
    """An Optuna journal backend that reads a journal file and refuses to write.

    Optuna's own file backend opens the file for appending (creating it when missing); this one
    only reads. A last line without its newline is a write in progress and is not read yet.
    """

    def __init__(self, path: Path) -> None:
        """A backend reading the journal at ``path``."""
        self.path = path

    def read_logs(self, log_number_from: int) -> Iterator[dict[str, Any]]:
        """The journal's records from number ``log_number_from`` on."""
        lines = self.path.read_bytes().split(b"\n")[:-1]  # the part after the last newline is incomplete
        for line in lines[log_number_from:]:
            yield json.loads(line)

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        """Refuse: the journal is opened read-only."""
        raise StudyStorageError(f"{self.path}: opened read-only")


def _read_journal(path: Path) -> StudyStorage:
    """The studies of the journal file at ``path``."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import BaseJournalBackend

    BaseJournalBackend.register(ReadOnlyJournal)  # the journal interface, without inheriting a writer
    try:
        storage = JournalStorage(ReadOnlyJournal(path))
        names = sorted(optuna.get_all_study_names(storage))
    except (OSError, ValueError, KeyError, TypeError) as err:  # unreadable, not JSON, not Optuna's records
        raise StudyStorageError(f"{path}: not a readable Optuna journal ({one_line(err)})") from None
    return StudyStorage(shown=str(path), storage=storage, study_names=names)


def _read_only_engine(location: str, name: str) -> tuple[Any, dict[str, Any]]:
    """An engine on the database at URL ``location``, read-only where the driver allows -> (engine, its options)."""
    import sqlalchemy
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        url = with_driver(sqlalchemy.make_url(location))
    except (ArgumentError, ValueError) as err:
        raise StudyStorageError(f"{name}: not a storage URL ({one_line(err)})") from None
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        path = Path(url.database.removeprefix("file:")).resolve()
        url = url.set(database=f"file:{quote(str(path), safe='/')}",  # a URI: '#', '%', '?' quoted
                      query={"mode": "ro", "uri": "true"})
    options = {"connect_args": args} if (args := connect_args(url, read_only=True)) else {}
    try:
        return sqlalchemy.create_engine(url, **options), options
    except (NoSuchModuleError, ArgumentError) as err:  # an unknown scheme or dialect
        raise StudyStorageError(f"{name}: not a storage URL ({one_line(err)})") from None
    except ImportError as err:
        hint = DRIVER_HINTS.get(url.get_backend_name(), f"install the Python package {err.name}")
        raise StudyStorageError(f"{name}: the database driver is missing ({err.name or one_line(err)}); "
                                f"{hint}") from None


def _read_database(location: str, name: str) -> StudyStorage:
    """The studies of the database at URL ``location`` (``name`` names it in messages)."""
    import optuna
    import sqlalchemy
    from optuna.storages import RDBStorage
    from sqlalchemy.exc import SQLAlchemyError

    engine, options = _read_only_engine(location, name)
    try:
        with engine.connect() as connection:
            is_optuna = sqlalchemy.inspect(connection).has_table("studies")
    except SQLAlchemyError as err:
        raise StudyStorageError(f"{name}: cannot reach the database "
                                f"({one_line(getattr(err, 'orig', None) or err)})") from None
    finally:
        engine.dispose()
    if not is_optuna:
        raise StudyStorageError(f"{name}: no Optuna study in this storage")
    try:
        storage = RDBStorage(engine.url.render_as_string(hide_password=False), engine_kwargs=options,
                             skip_table_creation=True)
        names = sorted(optuna.get_all_study_names(storage))
    except (SQLAlchemyError, RuntimeError) as err:  # e.g. a schema of another Optuna version
        raise StudyStorageError(f"{name}: cannot read its studies ({one_line(err)})") from None
    return StudyStorage(shown=name, storage=storage, study_names=names)
