"""The Optuna study: the contract between ``hersd-search``, which writes studies, and
``hersd-report``, which reads them (as :mod:`hersd.runlog` is the run log's).

- Where a study lives. A storage spec is ``journal:<file>``, a SQLAlchemy URL
  (``sqlite:///<file>``, ``postgresql://...``, ``mysql+pymysql://...``) or a plain path:
  ``*.log`` / ``*.journal`` a journal, anything else a SQLite file. :func:`open_storage` opens
  one for writing (the search), :func:`open_study_storage` read-only (the report); every
  failure is a :class:`StudyStorageError` with one line, passwords hidden.
- What a trial is: its parameters (:data:`KIND_PARAMS`), how Optuna stores them
  (:func:`stored_params`, :func:`trial_params`), and the schedule and run config they stand
  for (:func:`schedule_config`, :func:`trial_config`).
- What the search writes into the study and its trials for the report to read: the user
  attributes below and :class:`StudySettings`.

Light: Optuna and SQLAlchemy are imported only inside the functions that open storages.
"""

from __future__ import annotations

import fcntl
import functools
import importlib.util
import json
import shlex
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterator

from hersd.config import ConfigError, ScheduleConfig, TrainConfig
from hersd.schedules import FIXED_KINDS, schedule_mean_rates

JOURNAL_PREFIX = "journal:"
JOURNAL_SUFFIXES = (".log", ".journal")
SQLITE_PREFIX = "sqlite:///"
SQLITE_SUFFIXES = (".db", ".sqlite", ".sqlite3")
STORAGE_SUFFIXES = SQLITE_SUFFIXES + JOURNAL_SUFFIXES  # the files in <folder>/search/ the report reads by itself
SEARCH_FOLDER = "search"  # <results_dir>/search/: default storages (<study>.db), found by the report
SQLITE_TIMEOUT_SECONDS = 60  # how long a writer waits for SQLite's lock before failing
CONNECT_TIMEOUT_SECONDS = 10  # how long to wait for a PostgreSQL server
# backend -> how to get its driver (the extra's psycopg2 serves a bare postgresql:// when psycopg is missing)
DRIVER_HINTS = {"postgresql": 'pip install "hersd[cluster]" (psycopg2, which postgresql:// and '
                              'postgresql+psycopg2:// URLs then use)'}
SCHEMES = "use sqlite:///<file>, postgresql://..., another SQLAlchemy URL, or journal:<file>"
MESSAGE_LIMIT = 200  # characters of a database's own error message kept in ours

# The schedule kinds a search draws (eq. 9's, known before the run) and each one's parameters.
KIND_PARAMS = {"constant": ("eps",), "linear": ("beta1",), "exponential": ("beta1", "beta2")}
assert tuple(KIND_PARAMS) == FIXED_KINDS
PARAM_NAMES = ("kind", "beta1", "beta2", "eps", "lambda_h")  # every parameter a trial may have

# User attributes hersd-search writes and hersd-report reads. The search's own bookkeeping
# (trial attributes worker, heartbeat, interrupted, refused, lost, pruned_reason, mu_eps,
# mu_eps_approx) is not read by the report.
SETTINGS_ATTR = "settings"  # study: StudySettings as a dict, set when the study is created
TRAIN_OVERRIDES_ATTR = "train_overrides"  # study: the search command's training overrides
RUN_DIRS_ATTR = "run_dirs"  # trial: its runs' directories, one per seed, set as each run starts
RETRY_OF_ATTR = "retry_of"  # trial: the number of the lost or interrupted trial whose parameters it retries


class StudyStorageError(ConfigError):
    """A study storage cannot be opened or read; the message is one line for the user."""


# --------------------------------------------------------------------------- storage specs

def one_line(error: BaseException | str) -> str:
    """An error message on one line, at most MESSAGE_LIMIT characters."""
    return " ".join(str(error).split())[:MESSAGE_LIMIT]


def storage_location(spec: str) -> tuple[str, str]:
    """A storage spec -> ("journal", file path) or ("rdb", SQLAlchemy URL); paths ``~``-expanded, nothing checked."""
    if spec.startswith(JOURNAL_PREFIX):
        return "journal", str(Path(spec[len(JOURNAL_PREFIX):]).expanduser())
    if "://" in spec:
        return "rdb", spec
    path = Path(spec).expanduser()
    return ("journal", str(path)) if path.suffix in JOURNAL_SUFFIXES else ("rdb", f"{SQLITE_PREFIX}{path}")


def storage_file(spec: str) -> Path | None:
    """The journal or SQLite file a storage spec names, absolute; None for a database server."""
    kind, location = storage_location(spec)
    if kind == "rdb" and not location.startswith(SQLITE_PREFIX):
        return None
    return Path(location.removeprefix(SQLITE_PREFIX).partition("?")[0]).resolve()


def shown(url: str) -> str:
    """A storage spec for messages: a URL's password hidden."""
    if "://" not in url:
        return url
    from sqlalchemy import make_url

    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - not a URL: show what follows the credentials
        return url.split("@")[-1]


def storage_name(spec: str) -> str:
    """How messages name a storage: its file (absolute) or its URL (password hidden)."""
    path = storage_file(spec)
    return str(path) if path is not None else shown(spec)


def default_storage(results_dir: str | Path, study_name: str) -> str:
    """The storage of a study without ``search.storage``: ``sqlite:///<results_dir>/search/<study>.db``."""
    return f"{SQLITE_PREFIX}{Path(results_dir).resolve() / SEARCH_FOLDER / study_name}.db"


def find_study_storages(folder: str | Path) -> list[Path]:
    """The SQLite and journal files directly in ``folder/search/`` (the report reads these by itself), sorted."""
    search = Path(folder) / SEARCH_FOLDER
    if not search.is_dir():
        return []
    return sorted(path for path in search.iterdir() if path.is_file() and path.suffix in STORAGE_SUFFIXES)


def report_command(results_dir: str | Path, spec: str) -> str:
    """The ``hersd-report`` command that draws the runs of ``results_dir`` and the studies of storage ``spec``
    (``--storage`` only when the report would not find the storage itself)."""
    results = Path(results_dir).resolve()
    command = ["hersd-report", str(results)]
    path = storage_file(spec)
    if path is None or path.parent != results / SEARCH_FOLDER or path.suffix not in STORAGE_SUFFIXES:
        command += ["--storage", shown(spec)]  # a password shows as ***: libpq also reads PGPASSWORD
    return shlex.join(command)


# --------------------------------------------------------------------------- databases (both ways)

def _installed(module: str) -> bool:
    """Whether ``module`` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or blocked package
        return False


def _with_driver(url: Any) -> Any:
    """A bare ``postgresql://`` sqlalchemy URL with the psycopg driver that is installed: psycopg2 when it
    is and psycopg (SQLAlchemy's default) is not."""
    if url.get_backend_name() != "postgresql" or "+" in url.drivername:
        return url
    installed = {name for name in ("psycopg", "psycopg2") if _installed(name)}
    return url.set(drivername="postgresql+psycopg2" if installed == {"psycopg2"} else "postgresql+psycopg")


def _connect_args(url: Any, read_only: bool) -> dict[str, Any]:
    """libpq's settings for PostgreSQL through psycopg: a connect timeout, and read-only transactions if asked."""
    if url.get_backend_name() != "postgresql" or url.get_driver_name() not in ("psycopg2", "psycopg"):
        return {}
    args: dict[str, Any] = {"connect_timeout": CONNECT_TIMEOUT_SECONDS}
    if read_only:
        args["options"] = "-c default_transaction_read_only=on"
    return args


# --------------------------------------------------------------------------- opening for writing (the search)

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
    url = _with_driver(url)
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

            return JournalStorage(JournalFileBackend(str(path)))
        return _sqlite_storage_class()(path) if path is not None else _open_database(location)
    except OSError as err:
        raise StudyStorageError(f"search.storage: cannot open {where} ({err.strerror or one_line(err)})") from None
    except SQLAlchemyError as err:
        reason = one_line(getattr(err, "orig", None) or err)
        raise StudyStorageError(f"search.storage: cannot reach the database at {where} ({reason})") from None
    except (RuntimeError, ValueError, KeyError) as err:  # another Optuna schema version; a damaged journal
        raise StudyStorageError(f"search.storage: cannot use {where} as an Optuna storage ({one_line(err)})") from None


def _open_database(location: str) -> Any:
    """An RDBStorage at a SQLAlchemy URL (connections checked before use; PostgreSQL: a connect timeout).

    Two processes creating Optuna's tables at once make one fail; it opens the tables the other made."""
    from optuna.storages import RDBStorage
    from sqlalchemy.exc import IntegrityError, ProgrammingError

    url = _writable_url(location)
    options: dict[str, Any] = {"pool_pre_ping": True}
    if connect_args := _connect_args(url, read_only=False):
        options["connect_args"] = connect_args
    try:
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)
    except (IntegrityError, ProgrammingError):  # another worker created Optuna's tables at the same moment
        return RDBStorage(url.render_as_string(hide_password=False), engine_kwargs=options)


# --------------------------------------------------------------------------- opening read-only (the report)

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
        url = _with_driver(sqlalchemy.make_url(location))
    except (ArgumentError, ValueError) as err:
        raise StudyStorageError(f"{name}: not a storage URL ({one_line(err)})") from None
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        path = Path(url.database.removeprefix("file:")).resolve()
        url = url.set(database=f"file:{path}", query={"mode": "ro", "uri": "true"})
    options = {"connect_args": args} if (args := _connect_args(url, read_only=True)) else {}
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
        raise StudyStorageError(f"cannot reach the database at {name} "
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


# --------------------------------------------------------------------------- trials

def stored_params(params: dict[str, Any], kinds: list[str]) -> dict[str, Any]:
    """A trial's parameters as Optuna stores them: ``kind`` only when several kinds are searched
    (with one, it is not drawn)."""
    return dict(params) if len(kinds) > 1 else {name: value for name, value in params.items() if name != "kind"}


def trial_params(stored: dict[str, Any]) -> dict[str, Any]:
    """A trial's parameters as Optuna stored them -> with ``kind``: stored, else the kind whose
    parameters they are (None if none fits)."""
    if "kind" in stored:
        return dict(stored)
    names = set(stored) - {"lambda_h"}
    kind = next((kind for kind, params in KIND_PARAMS.items() if set(params) == names), None)
    return {"kind": kind, **stored}


def schedule_config(params: dict[str, Any]) -> ScheduleConfig:
    """A trial's schedule: its kind, with that kind's parameters given in ``params`` (ScheduleConfig's checks run)."""
    kind = params["kind"]
    return ScheduleConfig(kind=kind, **{name: float(params[name]) for name in KIND_PARAMS[kind] if name in params})


def trial_config(base: TrainConfig, params: dict[str, Any], seed: int, threads: str | None = None) -> TrainConfig:
    """One run of a trial: ``base`` with the trial's schedule (and lambda_h), ``seed`` and ``threads``."""
    algo = replace(base.algo, lambda_h=float(params["lambda_h"])) if "lambda_h" in params else base.algo
    return replace(base, schedule=schedule_config(params), algo=algo, seed=seed, threads=threads or base.threads)


def param_overrides(params: dict[str, Any]) -> list[str]:
    """A trial's parameters as ``hersd-train`` overrides (floats written exactly): the same run as :func:`trial_config`."""
    kind = params["kind"]
    overrides = [f"schedule={kind}"] + [f"schedule.{name}={float(params[name])!r}" for name in KIND_PARAMS[kind]]
    return overrides + ([f"algo.lambda_h={float(params['lambda_h'])!r}"] if "lambda_h" in params else [])


def mean_rates(params: dict[str, Any], epochs: int) -> tuple[float, float]:
    """mu_eps of a trial's schedule: exact over its epochs (eq. 10) and the approximation (eq. 11)."""
    return schedule_mean_rates(params["kind"], params.get("eps"), params.get("beta1"), params.get("beta2"), epochs)


# --------------------------------------------------------------------------- the study's settings

@dataclass(frozen=True)
class StudySettings:
    """What a study's objective depends on (user attribute ``settings``): a search that loads the
    study checks them; the report labels the trials' values with them."""

    objective: str  # auc: mean of the metric over epochs; final: its value at the last epoch
    metric: str  # the per-epoch field (hersd.runlog.EPOCH_FIELDS) the objective is made of, maximised
    seeds: int  # runs per trial
    first_seed: int  # the seed of a trial's first run
    epochs: int  # K, the epochs of every run
    task: str  # the task's name
    algo: str  # the algo's name
    train_config: str  # hersd.runstore.config_hash of the training config, searched fields neutral

    @classmethod
    def of(cls, user_attrs: dict[str, Any]) -> StudySettings | None:
        """A study's stored settings, or None when it has none (or of another form)."""
        try:
            return cls(**user_attrs[SETTINGS_ATTR])
        except (KeyError, TypeError):
            return None

    def value_label(self) -> str:
        """What a trial's value is, e.g. ``auc of test_success, mean of 3 seed(s)``."""
        return f"{self.objective} of {self.metric}, mean of {self.seeds} seed(s)"
