"""The Optuna study: the contract between ``hersd-search``, which writes studies, and
``hersd-report``, which reads them (as :mod:`hersd.contract.runlog` is the run log's).

- Where a study lives. A storage spec is ``journal:<file>``, a SQLAlchemy URL
  (``sqlite:///<file>``, ``postgresql://...``, ``mysql+pymysql://...``) or a plain path:
  ``*.log`` / ``*.journal`` a journal, anything else a SQLite file. Its users open it:
  ``sweeps.search.storage`` for writing (the search), ``analysis.studies`` read-only (the
  report); every failure is a :class:`StudyStorageError` with one line, passwords hidden.
- What a trial is: its schedule kind's searched parameters (:func:`kind_params`), how Optuna stores them
  (:func:`stored_params`, :func:`trial_params`), and the schedule and run config they stand
  for (:func:`schedule_config`, :func:`trial_config`).
- What the search writes into the study and its trials for the report to read: the user
  attributes below and :class:`StudySettings`.

Light: imports neither Optuna nor SQLAlchemy (tests/test_layers.py), so both layers above share it.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote

from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.schedules import SCHEDULES, Schedule, known_kinds, schedule_class
from hersd.contract.schedules.registry import build

JOURNAL_PREFIX = "journal:"
JOURNAL_SUFFIXES = (".log", ".journal")
SQLITE_PREFIX = "sqlite:///"
SQLITE_SUFFIXES = (".db", ".sqlite", ".sqlite3")
STORAGE_SUFFIXES = SQLITE_SUFFIXES + JOURNAL_SUFFIXES  # the files in <folder>/search/ the report reads by itself
SEARCH_FOLDER = "search"  # <results_dir>/search/: default storages (<study>.db), found by the report
CONNECT_TIMEOUT_SECONDS = 10  # how long to wait for a PostgreSQL server
# backend -> how to get its driver (the extra's psycopg2 serves a bare postgresql:// when psycopg is missing)
DRIVER_HINTS = {"postgresql": 'pip install "hersd[cluster]" (psycopg2, which postgresql:// and '
                              'postgresql+psycopg2:// URLs then use)'}
SCHEMES = "use sqlite:///<file>, postgresql://..., another SQLAlchemy URL, or journal:<file>"
MESSAGE_LIMIT = 200  # characters of a database's own error message kept in ours

REWARD_PARAM = "lambda_h"  # the one setting a search may draw outside the schedule: algo.lambda_h
PAPER_SETTINGS = ("beta1", "beta2", "eps")  # the paper's kinds' searched settings, each ranged by search.space.<name>
PARAM_NAMES = ("kind", *PAPER_SETTINGS, REWARD_PARAM)  # the parameters of the paper's kinds' trials

# User attributes hersd-search writes and hersd-report reads. The search's own bookkeeping
# (trial attributes worker, heartbeat, interrupted, refused, lost, pruned_reason, mu_eps,
# mu_eps_approx) is not read by the report.
SETTINGS_ATTR = "settings"  # study: StudySettings as a dict, set when the study is created
TRAIN_OVERRIDES_ATTR = "train_overrides"  # study: the search command's training overrides
RUN_DIRS_ATTR = "run_dirs"  # trial: its runs' directories, one per seed, set as each run starts
RETRY_OF_ATTR = "retry_of"  # trial: the number of the lost or interrupted trial whose parameters it retries
KIND_ATTR = "kind"  # trial: its schedule's kind (Optuna's parameters hold it only when several kinds are searched)


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
    return ("journal", str(path)) if path.suffix in JOURNAL_SUFFIXES else ("rdb", sqlite_url(path))


def sqlite_url(path: str | Path) -> str:
    """``sqlite:///<path>``, the path percent-quoted as SQLAlchemy reads a URL's database (``sqlalchemy.make_url``
    unquotes it), so a folder named with ``#``, ``%`` or ``?`` is that folder; an ordinary path is unchanged.
    SQLAlchemy's ``URL.create(drivername="sqlite", database=path)`` renders the same; this module imports no
    SQLAlchemy (tests/test_layers.py)."""
    return f"{SQLITE_PREFIX}{quote(str(path), safe='/')}"


def storage_file(spec: str) -> Path | None:
    """The journal or SQLite file a storage spec names, absolute; None for a database server. A SQLite URL's
    path is unquoted, as SQLAlchemy opens it (``%23`` is ``#``)."""
    kind, location = storage_location(spec)
    if kind == "rdb" and not location.startswith(SQLITE_PREFIX):
        return None
    return Path(unquote(location.removeprefix(SQLITE_PREFIX).partition("?")[0])).resolve()


def shown(url: str) -> str:
    """A storage spec for messages: a URL's password hidden (``postgresql://user:***@host/db``)."""
    scheme, separator, rest = url.partition("://")
    credentials, at, host = rest.rpartition("@")
    if not separator or not at:
        return url
    user, colon, _password = credentials.partition(":")
    return f"{scheme}://{user}{':***' if colon else ''}@{host}"


def storage_name(spec: str) -> str:
    """How messages name a storage: its file (absolute) or its URL (password hidden)."""
    path = storage_file(spec)
    return str(path) if path is not None else shown(spec)


def default_storage(results_dir: str | Path, study_name: str) -> str:
    """The storage of a study without ``search.storage``: ``sqlite:///<results_dir>/search/<study>.db``."""
    return sqlite_url(f"{Path(results_dir).resolve() / SEARCH_FOLDER / study_name}.db")


def find_study_storages(folder: str | Path) -> list[Path]:
    """The SQLite and journal files directly in ``folder/search/`` (the report reads these by itself), sorted."""
    search = Path(folder) / SEARCH_FOLDER
    if not search.is_dir():
        return []
    return sorted(path for path in search.iterdir() if path.is_file() and path.suffix in STORAGE_SUFFIXES)


def found_by_report(results_dir: str | Path, spec: str) -> bool:
    """Whether ``hersd-report results_dir`` finds storage ``spec`` by itself (:func:`find_study_storages`)."""
    path = storage_file(spec)
    return path is not None and path.parent == Path(results_dir).resolve() / SEARCH_FOLDER \
        and path.suffix in STORAGE_SUFFIXES


# --------------------------------------------------------------------------- databases (both ways: SQLAlchemy URL objects given)

def _installed(module: str) -> bool:
    """Whether ``module`` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or blocked package
        return False


def with_driver(url: Any) -> Any:
    """A bare ``postgresql://`` sqlalchemy URL with the psycopg driver that is installed: psycopg2 when it
    is and psycopg (SQLAlchemy's default) is not."""
    if url.get_backend_name() != "postgresql" or "+" in url.drivername:
        return url
    installed = {name for name in ("psycopg", "psycopg2") if _installed(name)}
    return url.set(drivername="postgresql+psycopg2" if installed == {"psycopg2"} else "postgresql+psycopg")


def connect_args(url: Any, read_only: bool) -> dict[str, Any]:
    """libpq's settings for PostgreSQL through psycopg: a connect timeout, and read-only transactions if asked."""
    if url.get_backend_name() != "postgresql" or url.get_driver_name() not in ("psycopg2", "psycopg"):
        return {}
    args: dict[str, Any] = {"connect_timeout": CONNECT_TIMEOUT_SECONDS}
    if read_only:
        args["options"] = "-c default_transaction_read_only=on"
    return args


# --------------------------------------------------------------------------- trials

def kind_params(kind: str) -> tuple[str, ...]:
    """The parameters a search draws for schedules of ``kind`` (its class's ``searched``)."""
    return schedule_class(kind).searched


def searchable(kind: str) -> bool:
    """Whether a search can draw schedules of ``kind``: it has searched parameters and does not adapt to the
    run (an adaptive schedule's rate is known only once run)."""
    cls = schedule_class(kind)
    return bool(cls.searched) and not cls.adaptive


def stored_params(params: dict[str, Any], kinds: list[str]) -> dict[str, Any]:
    """A trial's parameters as Optuna stores them: ``kind`` only when several kinds are searched
    (with one, it is not drawn)."""
    return dict(params) if len(kinds) > 1 else {name: value for name, value in params.items() if name != "kind"}


def trial_params(stored: dict[str, Any], kind: str | None = None) -> dict[str, Any]:
    """A trial's parameters as Optuna stored them -> with ``kind``: stored, else ``kind`` (the trial's KIND_ATTR),
    else the registered kind whose searched parameters they are (None if none fits: trials of earlier searches)."""
    if "kind" in stored:
        return dict(stored)
    names = set(stored) - {REWARD_PARAM}
    kind = kind or next((kind for kind in known_kinds() if set(kind_params(kind)) == names), None)
    return {"kind": kind, **stored}


def schedule_config(params: dict[str, Any]) -> Schedule:
    """A trial's schedule: its kind, with that kind's parameters given in ``params`` (the class's checks run)."""
    kind = params["kind"]
    return build(schedule_class(kind), {name: float(params[name]) for name in kind_params(kind) if name in params}, kind)


def trial_config(base: TrainConfig, params: dict[str, Any], seed: int, threads: str | None = None) -> TrainConfig:
    """One run of a trial: ``base`` with the trial's schedule (and lambda_h), ``seed`` and ``threads``."""
    algo = replace(base.algo, lambda_h=float(params[REWARD_PARAM])) if REWARD_PARAM in params else base.algo
    return replace(base, schedule=schedule_config(params), algo=algo, seed=seed, threads=threads or base.threads)


def param_overrides(params: dict[str, Any]) -> list[str]:
    """A trial's parameters as ``hersd-train`` overrides (floats written exactly): the same run as :func:`trial_config`.
    The package's kinds by their preset (conf/schedule/<kind>.yaml), others by ``schedule.kind=<name or class path>``."""
    kind = params["kind"]
    chosen = f"schedule={kind}" if kind in SCHEDULES else f"schedule.kind={kind}"
    overrides = [chosen] + [f"schedule.{name}={float(params[name])!r}" for name in kind_params(kind)]
    return overrides + ([f"algo.{REWARD_PARAM}={float(params[REWARD_PARAM])!r}"] if REWARD_PARAM in params else [])


def mean_rates(params: dict[str, Any], epochs: int) -> tuple[float, float]:
    """mu_eps of a trial's schedule: exact over its epochs and as K -> infinity (eq. 10 and 11 for eq. 9's kinds);
    NaN where the schedule does not know it."""
    schedule = schedule_config(params)
    exact, limit = schedule.exact_mean_rate(epochs), schedule.limit_mean_rate()
    return (float("nan") if exact is None else exact), (float("nan") if limit is None else limit)


# --------------------------------------------------------------------------- the study's settings

@dataclass(frozen=True)
class StudySettings:
    """What a study's objective depends on (user attribute ``settings``): a search that loads the
    study checks them; the report labels the trials' values with them."""

    objective: str  # auc: mean of the metric over epochs; final: its value at the last epoch
    metric: str  # the per-epoch field (hersd.contract.runlog.EPOCH_FIELDS) the objective is made of, maximised
    seeds: int  # runs per trial
    first_seed: int  # the seed of a trial's first run
    epochs: int  # K, the epochs of every run
    task: str  # the task's name
    algo: str  # the algo's name
    train_config: str  # hersd.contract.runstore.config_hash of the training config, searched fields neutral

    @classmethod
    def of(cls, user_attrs: dict[str, Any]) -> StudySettings | None:
        """A study's stored settings, or None when it has none (or of another form)."""
        try:
            return cls(**user_attrs[SETTINGS_ATTR])
        except (KeyError, TypeError):
            return None
