"""Opening a study storage for writing: the search's side of the study contract (:mod:`hersd.contract.study`
names storages and encodes trials; :mod:`analysis.studies` opens them read-only for the report).

:func:`resolve_storage` checks a spec without connecting; :func:`open_storage` opens it, creating
a missing file or Optuna's tables: a journal file, SQLite with a claim lock, PostgreSQL and other
SQLAlchemy URLs. Every failure is a :class:`hersd.contract.study.StudyStorageError` with one line.
"""

from __future__ import annotations

import fcntl
import functools
import os
import shlex
from pathlib import Path
from typing import Any

from hersd.contract.study import (DRIVER_HINTS, JOURNAL_PREFIX, SCHEMES, StudyStorageError, connect_args, one_line,
                         shown, sqlite_url, storage_file, storage_location, storage_name, with_driver)

SQLITE_TIMEOUT_SECONDS = 60  # how long a writer waits for SQLite's lock before failing


def _writable_url(location: str) -> Any:
    """A SQLAlchemy URL string -> a checked ``sqlalchemy.URL`` (absolute SQLite path, installed PostgreSQL driver)."""
    # StudyStorageError for a malformed URL, in-memory SQLite, an unknown scheme or a missing driver,
    # all found by creating an engine, which imports the driver but does not connect.
    import sqlalchemy
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        url = sqlalchemy.make_url(location)
    except (ArgumentError, ValueError) as err:
        raise StudyStorageError(f"search.storage={shown(location)}: not a storage URL ({one_line(err)}); "
                                f"{SCHEMES}") from None
    backend = url.get_backend_name()
    if backend == "sqlite":
        if url.database in (None, "", ":memory:"):
            raise StudyStorageError("search.storage: an in-memory SQLite database can be neither shared by workers "
                                    "nor resumed; name a file: sqlite:///<file>")
        url = url.set(database=str(Path(url.database).expanduser().resolve()))
    url = with_driver(url)
    try:
        sqlalchemy.create_engine(url).dispose()
    except NoSuchModuleError:
        raise StudyStorageError(f"search.storage={shown(location)}: unknown database scheme {url.drivername!r}; "
                                f"{SCHEMES}") from None
    except ImportError as err:
        hint = DRIVER_HINTS.get(backend, "install it, or name an installed driver (<database>+<driver>://...)")
        raise StudyStorageError(f"search.storage={shown(location)}: the database driver "
                                f"{err.name or one_line(err)} is not installed; {hint}") from None
    return url


def resolve_storage(spec: str) -> str:
    """Check a storage spec without connecting -> the spec workers open (``journal:<absolute path>`` or a URL)."""
    kind, location = storage_location(spec)
    if kind == "journal":
        return f"{JOURNAL_PREFIX}{storage_file(spec)}"
    return _writable_url(location).render_as_string(hide_password=False)


@functools.cache
def _sqlite_storage_class() -> type:
    """The class of :func:`open_storage`'s SQLite storages, made once Optuna is imported."""
    from optuna.storages import RDBStorage
    from optuna.trial import TrialState

    class SQLiteStorage(RDBStorage):
        """RDBStorage on a local SQLite file, with queue claims serialised by a file lock.

        Optuna pops an enqueued trial by reading it as WAITING and then setting it RUNNING; SQLite
        (through Python's sqlite3) reads outside the write transaction, so two workers popping at
        the same moment can both claim one trial, and both train it. Holding ``<db>.lock`` around
        the WAITING -> RUNNING step makes the second claimant see RUNNING and move on.
        """

        def __init__(self, path: Path) -> None:
            """Open (creating) the SQLite file at ``path``; its claim lock is ``<path>.lock``, held while Optuna
            creates its tables too (two commands starting on one new file would both create them)."""
            self.claim_lock_path = path.with_name(path.name + ".lock")
            with open(self.claim_lock_path, "a") as lock_file:
                fcntl.flock(lock_file, fcntl.LOCK_EX)
                super().__init__(sqlite_url(path),
                                 engine_kwargs={"connect_args": {"timeout": SQLITE_TIMEOUT_SECONDS}})

        def set_trial_state_values(self, trial_id: int, state: TrialState, values=None) -> bool:
            """Optuna's state change; the change to RUNNING (a claim) under the file lock."""
            if state != TrialState.RUNNING:
                return super().set_trial_state_values(trial_id, state, values)
            with open(self.claim_lock_path, "a") as lock_file:
                fcntl.flock(lock_file, fcntl.LOCK_EX)
                return super().set_trial_state_values(trial_id, state, values)

    return SQLiteStorage


def open_storage(spec: str) -> Any:
    """Open (creating a missing file or Optuna's tables) the storage ``spec`` names for writing
    -> an ``optuna.storages.BaseStorage``; StudyStorageError if it cannot."""
    from optuna.storages import JournalStorage
    from sqlalchemy.exc import SQLAlchemyError

    kind, location = storage_location(spec)
    path, where = storage_file(spec), storage_name(spec)
    try:
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
        if kind == "journal":
            from optuna.storages.journal import JournalFileBackend

            _check_journal_end(path)
            return JournalStorage(JournalFileBackend(str(path)))
        return _sqlite_storage_class()(path) if path is not None else _open_database(location)
    except StudyStorageError:  # already one line (a cut journal)
        raise
    except OSError as err:
        raise StudyStorageError(f"search.storage: cannot open {where} ({err.strerror or one_line(err)})") from None
    except SQLAlchemyError as err:
        reason = one_line(getattr(err, "orig", None) or err)
        raise StudyStorageError(f"search.storage: cannot reach the database at {where} ({reason})") from None
    except (RuntimeError, ValueError, KeyError) as err:  # another Optuna schema version; a damaged journal
        raise StudyStorageError(f"search.storage: cannot use {where} as an Optuna storage ({one_line(err)})") from None


def _whole_records_size(path: Path, chunk: int = 1 << 16) -> int | None:
    """The size of the journal at ``path`` up to its last newline if its last record is cut (the file does not end
    in one), else None (whole, empty or missing)."""
    if not path.is_file():
        return None
    with open(path, "rb") as file:
        end = position = file.seek(0, os.SEEK_END)
        while position > 0:
            start = max(0, position - chunk)
            file.seek(start)
            read = file.read(position - start)
            if position == end and read.endswith(b"\n"):
                return None
            if (newline := read.rfind(b"\n")) >= 0:
                return start + newline + 1
            position = start
    return 0 if end else None


def _check_journal_end(path: Path) -> None:
    """StudyStorageError if the journal's last record is cut (a writer stopped mid-record): Optuna would append
    after the partial line and could then read none of the journal. Checked under Optuna's own journal lock, so
    a worker writing a record now is not mistaken for one cut."""
    from optuna.storages.journal import JournalFileSymlinkLock

    if not path.is_file():
        return
    lock = JournalFileSymlinkLock(str(path))
    lock.acquire()
    try:
        size = _whole_records_size(path)
    finally:
        lock.release()
    if size is not None:
        raise StudyStorageError(f"search.storage: the last record of the journal {path} is cut (its writer stopped "
                                f"mid-record), and a record written after it would make the journal unreadable; "
                                f"remove that partial last line, keeping every whole record before it: truncate "
                                f"-s {size} {shlex.quote(str(path))}; then re-run")


def _open_database(location: str) -> Any:
    """An RDBStorage at a SQLAlchemy URL (connections checked before use; PostgreSQL: a connect timeout).

    Two processes creating Optuna's tables at once make one fail; it opens the tables the other made."""
    from optuna.storages import RDBStorage
    from sqlalchemy.exc import IntegrityError, ProgrammingError

    url = _writable_url(location)
    options: dict[str, Any] = {"pool_pre_ping": True}
    if args := connect_args(url, read_only=False):
        options["connect_args"] = args
    try:
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)
    except (IntegrityError, ProgrammingError):  # another worker created Optuna's tables at the same moment
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)
