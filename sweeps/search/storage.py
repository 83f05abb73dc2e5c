"""Where a study lives: storage specs, SQLite with a lock around Optuna's queue claim, journal
files, and other databases through SQLAlchemy (RDB).

A spec is ``journal:<file>``, a SQLAlchemy URL (``sqlite:///<file>``, ``postgresql://...``,
``mysql+pymysql://...``), or a plain path: ``*.log`` / ``*.journal`` a journal, anything else
a SQLite file. :func:`resolve_storage` checks a spec without connecting; :func:`open_storage`
opens it. Both raise :class:`hersd.config.ConfigError` with one line (passwords hidden).
"""

from __future__ import annotations

import fcntl
import importlib.util
from pathlib import Path
from typing import Any

from optuna.storages import BaseStorage, JournalStorage, RDBStorage
from optuna.trial import TrialState

from hersd.config import ConfigError

JOURNAL_PREFIX = "journal:"
JOURNAL_SUFFIXES = (".log", ".journal")
SQLITE_PREFIX = "sqlite:///"
SEARCH_FOLDER = "search"  # <results_dir>/search/: default storages (<study>.db) and <study>/ folders
SQLITE_TIMEOUT_SECONDS = 60  # how long a writer waits for SQLite's lock before failing
CONNECT_TIMEOUT_SECONDS = 10  # how long to wait for a PostgreSQL server
DRIVER_HINTS = {"postgresql": 'pip install "hersd[cluster]" (the psycopg2 driver)'}
SCHEMES = "use sqlite:///<file>, postgresql://..., another SQLAlchemy URL, or journal:<file>"
MESSAGE_LIMIT = 200  # characters of a database's own error message kept in ours


def _one_line(error: BaseException | str) -> str:
    """An error message on one line, at most MESSAGE_LIMIT characters."""
    return " ".join(str(error).split())[:MESSAGE_LIMIT]


def storage_location(spec: str) -> tuple[str, str]:
    """A storage spec -> ("journal", absolute file path) or ("rdb", SQLAlchemy URL)."""
    if spec.startswith(JOURNAL_PREFIX):
        path = spec[len(JOURNAL_PREFIX):]
        if not path:
            raise ConfigError("search.storage=journal:<path> needs a file path after 'journal:'")
        return "journal", str(Path(path).expanduser().resolve())
    if "://" in spec:
        return "rdb", spec
    path = Path(spec).expanduser().resolve()
    return ("journal", str(path)) if path.suffix in JOURNAL_SUFFIXES else ("rdb", f"{SQLITE_PREFIX}{path}")


def storage_file(spec: str) -> Path | None:
    """The journal or SQLite file a storage spec names; None for a database server."""
    kind, location = storage_location(spec)
    if kind == "journal":
        return Path(location)
    return Path(location[len(SQLITE_PREFIX):]) if location.startswith(SQLITE_PREFIX) else None


def shown(url: str) -> str:
    """A storage spec for messages: a URL's password hidden."""
    from sqlalchemy import make_url

    if "://" not in url:
        return url
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - not a URL: show what follows the credentials
        return url.split("@")[-1]


def _installed(module: str) -> bool:
    """Whether ``module`` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or blocked package
        return False


def _postgresql_driver() -> str:
    """psycopg2 when it is installed and psycopg (SQLAlchemy's default for postgresql://) is not."""
    installed = {name for name in ("psycopg", "psycopg2") if _installed(name)}
    return "psycopg2" if installed == {"psycopg2"} else "psycopg"


def _database_url(spec: str) -> Any:
    """A SQLAlchemy URL string -> a checked ``sqlalchemy.URL`` (absolute SQLite path, installed PostgreSQL driver)."""
    # ConfigError for a malformed URL, in-memory SQLite, an unknown scheme or a missing driver,
    # all found by creating an engine, which imports the driver but does not connect.
    import sqlalchemy
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        url = sqlalchemy.make_url(spec)
    except (ArgumentError, ValueError) as err:
        raise ConfigError(f"search.storage={shown(spec)}: not a storage URL ({_one_line(err)}); {SCHEMES}") from None
    backend = url.get_backend_name()
    if backend == "sqlite":
        if url.database in (None, "", ":memory:"):
            raise ConfigError("search.storage: an in-memory SQLite database can be neither shared by workers nor "
                              "resumed; name a file: sqlite:///<file>")
        url = url.set(database=str(Path(url.database).expanduser().resolve()))
    if backend == "postgresql" and "+" not in url.drivername:
        url = url.set(drivername=f"postgresql+{_postgresql_driver()}")
    try:
        sqlalchemy.create_engine(url).dispose()
    except NoSuchModuleError:
        raise ConfigError(f"search.storage={shown(spec)}: unknown database scheme {url.drivername!r}; "
                          f"{SCHEMES}") from None
    except ImportError as err:
        hint = DRIVER_HINTS.get(backend, "install it, or name an installed driver (<database>+<driver>://...)")
        raise ConfigError(f"search.storage={shown(spec)}: the database driver {err.name or _one_line(err)} is not "
                          f"installed; {hint}") from None
    return url


def resolve_storage(spec: str) -> str:
    """Check a storage spec without connecting -> the spec workers open (``journal:<absolute path>`` or a URL)."""
    kind, location = storage_location(spec)
    if kind == "journal":
        return f"{JOURNAL_PREFIX}{location}"
    return _database_url(location).render_as_string(hide_password=False)


class SQLiteStorage(RDBStorage):
    """RDBStorage on a local SQLite file, with queue claims serialised by a file lock.

    Optuna pops an enqueued trial by reading it as WAITING and then setting it RUNNING; SQLite
    (through Python's sqlite3) reads outside the write transaction, so two workers popping at
    the same moment can both claim one trial, and both train it. Holding ``<db>.lock`` around
    the WAITING -> RUNNING step makes the second claimant see RUNNING and move on.
    """

    def __init__(self, path: Path) -> None:
        """Open (creating) the SQLite file at ``path``; its claim lock is ``<path>.lock``."""
        super().__init__(f"{SQLITE_PREFIX}{path}",
                         engine_kwargs={"connect_args": {"timeout": SQLITE_TIMEOUT_SECONDS}})
        self.claim_lock_path = path.with_name(path.name + ".lock")

    def set_trial_state_values(self, trial_id: int, state: TrialState, values=None) -> bool:
        """Optuna's state change; the change to RUNNING (a claim) under the file lock."""
        if state != TrialState.RUNNING:
            return super().set_trial_state_values(trial_id, state, values)
        with open(self.claim_lock_path, "a") as lock_file:
            fcntl.flock(lock_file, fcntl.LOCK_EX)
            return super().set_trial_state_values(trial_id, state, values)


def open_storage(spec: str) -> BaseStorage:
    """Open (creating a missing file or Optuna's tables) the storage ``spec`` names; ConfigError if it cannot."""
    from sqlalchemy.exc import SQLAlchemyError

    kind, location = storage_location(spec)
    path = storage_file(spec)
    where = str(path) if path is not None else shown(location)
    try:
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
        if kind == "journal":
            from optuna.storages.journal import JournalFileBackend

            return JournalStorage(JournalFileBackend(str(path)))
        return SQLiteStorage(path) if path is not None else _open_database(location)
    except OSError as err:
        raise ConfigError(f"search.storage: cannot open {where} ({err.strerror or _one_line(err)})") from None
    except SQLAlchemyError as err:
        reason = _one_line(getattr(err, "orig", None) or err)
        raise ConfigError(f"search.storage: cannot reach the database at {where} ({reason})") from None
    except (RuntimeError, ValueError, KeyError) as err:  # another Optuna schema version; a damaged journal
        raise ConfigError(f"search.storage: cannot use {where} as an Optuna storage ({_one_line(err)})") from None


def _open_database(location: str) -> RDBStorage:
    """An RDBStorage at a SQLAlchemy URL (connections checked before use; PostgreSQL: a connect timeout).

    Two processes creating Optuna's tables at once make one fail; it opens the tables the other made."""
    url = _database_url(location)
    options: dict[str, Any] = {"pool_pre_ping": True}
    if url.get_backend_name() == "postgresql" and url.get_driver_name() in ("psycopg2", "psycopg"):
        options["connect_args"] = {"connect_timeout": CONNECT_TIMEOUT_SECONDS}
    from sqlalchemy.exc import IntegrityError, ProgrammingError

    try:
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)
    except (IntegrityError, ProgrammingError):  # another worker created Optuna's tables at the same moment
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)
