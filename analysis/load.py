"""Run logs -> tidy tables.

:func:`load_runs` reads every ``run.mcap`` below a folder (in worker processes, one per core,
when there are many: :func:`start_reading`) into a :class:`RunTable`:

- ``runs``: one row per run (columns: :data:`RUN_COLUMNS`);
- ``epochs``: one row per run x completed epoch: the run's columns, then every field of
  :data:`hersd.contract.runlog.EPOCH_FIELDS`;
- ``sessions``: one row per run x training session: its commit, machine, threads, times
  (:func:`analysis.provenance.session_table`).

A run's *configuration* label (column ``config``) names what its seeds have in common, so seeds are
grouped by ``(task, config)``; see :func:`config_label`. A label's runs share their number of epochs K:
where the loaded runs of one label differ in K, K is appended but for the paper's (``HER`` at K = 200,
``HER K=4``), so runs of different K are never pooled, across tasks neither. Runs that share a label
but not their identity less the seed (:func:`hersd.contract.runstore.run_identity`, the run store's
own rule) are told apart by the settings that differ.

What a run's log recorded is the truth about it: its relabel rates (the ``/epoch`` records' ``relabel_rate``) give
its ``mu_eps`` and Fig. 1's lines (:func:`analysis.metrics.schedule_curves`); its schedule record gives the kind and
settings. The schedule's class is imported only for its label, tag and title, and to check it: where today's class
gives other rates than a log (an edited ``rate``), one warning line per configuration names it
(:func:`rate_mismatch_lines`). A log whose class cannot be imported here, refuses or does not take the logged
settings (:func:`unfit_settings`), or cannot name them (:func:`naming_error`) is read all the same, labelled from its
record as a class without a label of its own would be (:class:`LoggedSchedule`), one warning line per class and error.
"""

from __future__ import annotations

import hashlib
import json
import re
from importlib import resources
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, Iterable, NamedTuple, Sequence

import numpy as np
import pandas as pd
import yaml

from analysis.provenance import session_rows, session_table
from analysis.workers import ForkedMap
from hersd.contract.config import PAPER_LEARNER, AlgoConfig, TrainConfig, learner_node
from hersd.contract.errors import ConfigError
from hersd.contract.runlog import EPOCH_FIELDS, LOG_NAME, OPTIONAL_EPOCH_FIELDS, RunLogError, read_records
from hersd.contract.runstore import HASHED_UNLESS, RunFolder, run_identity
from hersd.contract.schedules import Constant, Schedule, kind_name, schedule_from_record, schedule_rank
from hersd.contract.schedules.base import shown_value
from hersd.contract.schedules.registry import raised

RUN_COLUMNS = (
    "run",            # 0-based index of the run in this table
    "task",           # config.task.name
    "config",         # configuration label (ordered categorical, see config_label)
    "algo",           # config.algo.name
    "learner",        # config.learner.name: ddpg (the paper's and every run before learners were a setting) | td3 | sac
    "schedule",       # config.schedule.kind: a name of hersd.contract.schedules' registry, or a schedule class's path
    "schedule_tag",   # the schedule's folder tag (Schedule.tag), one per distinct schedule
    "schedule_label",  # the schedule's name in the report (Schedule.label)
    "schedule_record",  # the schedule's record as JSON (Schedule.record; hersd.contract.schedules.schedule_from_record)
    "constant_rate",  # one rate at every epoch (Schedule.constant_rate): the baselines
    "adaptive",       # the rate follows the run's progress (Schedule.adaptive)
    "eps", "beta1",   # the logged settings of the paper's kinds (NaN for kinds without them)
    "beta2",          # the beta2 of eq. 9 in effect: 0 for linear schedules
    "lambda_r", "lambda_h",
    "mep",            # config.algo.mep.enabled
    "seed",
    "total_epochs",   # K: config.epochs
    "mu_eps",         # the mean of the run's K logged rates (eq. 10 for eq. 9's kinds); a fixed schedule's run in
                      # progress: its logged rates, then its class's for the epochs to come (NaN without a class that
                      # gives the logged rates); an adaptive one's in progress: the mean of the rates logged so far
    "variant",        # the settings it runs at other than their earlier value (variant), e.g. "precision=bf16"; "" if none
    "defaults_id",    # 8 hex digits of its configuration with those settings at their earlier value (defaults_id):
                      # a variant's runs share it with the runs of the configuration they vary
    "epochs_done",    # completed epochs in the log
    "complete",       # the log says the run finished
    "damaged",        # the file has no valid end (cut short, or an earlier-format log of a killed or running writer)
    "run_id",         # 8-hex config hash written by training
    "cpu",            # the CPU the log was started on (metadata machine.cpu_model; empty in logs that predate it)
    "path",           # the log's path relative to the loaded folder
    "error",          # the first line of the error that stopped the run (its error.log), "" if none: a failed run
)



def preset_weights(algo: str) -> tuple[float, float]:
    """(lambda_r, lambda_h) of the preset ``conf/algo/<algo>.yaml`` (the schema's defaults where it sets none)."""
    preset = yaml.safe_load((resources.files("hersd.conf") / "algo" / f"{algo}.yaml").read_text()) or {}
    return float(preset.get("lambda_r", AlgoConfig().lambda_r)), float(preset.get("lambda_h", AlgoConfig().lambda_h))


# The baselines the labels name: HER's relabel rate (the schedule's default), HER's reward weights (the
# schema's) and ARCHER's (conf/algo/archer.yaml: hindsight rewards halved).
HER_EPS = Constant().eps
HER_WEIGHTS = (AlgoConfig().lambda_r, AlgoConfig().lambda_h)
ARCHER = "archer"  # ARCHER's algo preset (conf/algo/archer.yaml), the name its runs log as config.algo.name
ARCHER_WEIGHTS = preset_weights(ARCHER)
PAPER_EPOCHS = TrainConfig().epochs  # K of the paper's runs (the default): the one K a label leaves unsaid
PARALLEL_FROM = 64  # logs: fewer are read in this process (forking costs more than it saves)
READ_BATCHES = 16  # jobs the logs are split into when read in parallel (the cores finish together)


def is_archer(algo: str) -> bool:
    """Whether a run's logged ``algo`` name (config.algo.name) is ARCHER's, with or without MEP."""
    return algo.removesuffix("_mep") == ARCHER


class ReportInputError(ValueError):
    """The input cannot make a report (no logs, nothing readable, filters match nothing, a bad storage)."""


@dataclass
class RunTable:
    """Loaded runs; ``skipped`` holds one ``"<path>: <reason>"`` line per unreadable file."""

    runs: pd.DataFrame
    epochs: pd.DataFrame
    skipped: list[str] = field(default_factory=list)
    sessions: pd.DataFrame = field(default_factory=pd.DataFrame)
    missing_schedules: list[str] = field(default_factory=list)  # one line per class and error of logged_schedule
    copies: list[str] = field(default_factory=list)  # lines naming the second logs of runs read, left out
    left_out: int = 0  # logs found and not read: unreadable or copies
    rate_mismatches: list[str] = field(default_factory=list)  # one line per configuration whose class's rates differ

    def warnings(self) -> list[str]:
        """One line per log left out (unreadable, a copy), per damaged log read up to its damage, per failed run,
        per schedule class that cannot label its logs (its runs read from them: :func:`logged_schedule`) and per
        configuration whose class gives other rates than its logs."""
        runs = self.runs if len(self.runs) else pd.DataFrame(columns=["damaged", "error", "path", "epochs_done"])
        damaged = [f"damaged log {run.path}: read its {run.epochs_done} epochs before the damage"
                   for run in runs[runs["damaged"].astype(bool)].itertuples()]
        failed = [f"failed run {run.path}: {run.error}" for run in runs[runs["error"] != ""].itertuples()]
        return [*(f"skipped unreadable log {line}" for line in self.skipped), *self.copies, *damaged, *failed,
                *self.missing_schedules, *self.rate_mismatches]


class MissingSchedule(NamedTuple):
    """A log whose schedule class cannot label it (:func:`logged_schedule`: a user's module not on PYTHONPATH, say):
    its path (relative to the loaded folder) and the error naming the class."""

    path: str
    error: str


@dataclass
class LoggedSchedule:
    """A schedule known only by a log's record, its class not importable here or unfit (:func:`logged_schedule`):
    named as :meth:`Schedule.label` and :meth:`Schedule.tag` name a class without its own (its class name in lower
    case and every setting); its rates are the logged ones. ``adaptive``: whether its runs' logs disagree
    (:func:`_tables` decides)."""

    record: dict[str, Any]
    adaptive: bool = False
    constant_rate = False

    def settings(self) -> list[tuple[str, Any]]:
        return [(name, value) for name, value in self.record.items() if name != "kind"]

    def short_name(self) -> str:
        """The class name in lower case (``newcomer_steps.KStep`` -> ``kstep``), as the schedules' short_name
        gives it for a class without a kind."""
        return str(self.record["kind"]).rpartition(".")[2].lower()

    def label(self) -> str:
        return " ".join([self.short_name(), *(f"{name}={shown_value(value)}" for name, value in self.settings())])

    def tag(self) -> str:
        words = [self.short_name(), *(f"{name}_{shown_value(value)}" for name, value in self.settings())]
        return re.sub(r"[^A-Za-z0-9._=-]", "_", "-".join(words))


def variant(settings: dict[str, Any]) -> list[str]:
    """A run's top-level settings that came after the first runs (HASHED_UNLESS) where not at their earlier
    value, as ``key=value``, e.g. ``["precision=bf16"]``; ``settings`` as :func:`configuration` gives them."""
    return [f"{key}={settings[key]}" for key, earlier in HASHED_UNLESS.items()
            if "." not in key and settings.get(key, earlier) != earlier]


def defaults_id(settings: dict[str, Any]) -> str:
    """8 hex digits naming a run's configuration (``settings`` as :func:`configuration` gives them) with the
    settings :func:`variant` names at their earlier value: the same for ``HER precision=bf16`` as for ``HER``."""
    defaults = {**settings, **{key: earlier for key, earlier in HASHED_UNLESS.items() if "." not in key}}
    return hashlib.sha256(json.dumps(defaults, sort_keys=True, default=str).encode()).hexdigest()[:8]


def config_label(schedule: Schedule | LoggedSchedule, lambda_r: float, lambda_h: float, mep: bool,
                 learner: str = PAPER_LEARNER, epochs: int = PAPER_EPOCHS, variants: Sequence[str] = (),
                 algo: str = "her") -> str:
    """Name of a configuration, e.g. ``HER``, ``ARCHER``, ``linear b1=0.25``,
    ``exp b1=0.5 b2=0.5``, ``HER-MEP``, ``linear b1=0.5 λh=0.5``, ``TD3 HER`` (learners other
    than the paper's DDPG lead the label: :func:`learner_label`), ``HER precision=bf16``
    (``variants``: :func:`variant`), ``HER K=4`` (``epochs``, K, other than PAPER_EPOCHS).

    Constant-rate schedules are HER or ARCHER by the run's logged ``algo`` name (config.algo.name: archer,
    archer_mep), with ``eps=`` appended when eps != HER_EPS and reward weights other than that algo's preset's;
    others are named by their label (:meth:`Schedule.label`) with reward weights other than HER's appended as
    ``λr=`` / ``λh=``; then K as ``K=``: runs of different K never share a label.
    """
    if schedule.constant_rate:
        eps = schedule.rate(1, 1)
        archer = is_archer(algo)
        name = "ARCHER" if archer else "HER"
        qualifiers = [f"eps={eps:g}"] if eps != HER_EPS else []
        if archer and (lambda_r, lambda_h) == ARCHER_WEIGHTS:
            lambda_r, lambda_h = HER_WEIGHTS  # already said by the name
    else:
        name, qualifiers = schedule.label(), []
    if lambda_r != HER_WEIGHTS[0]:
        qualifiers.append(f"λr={lambda_r:g}")
    if lambda_h != HER_WEIGHTS[1]:
        qualifiers.append(f"λh={lambda_h:g}")
    qualifiers += variants
    if epochs != PAPER_EPOCHS:
        qualifiers.append(f"K={epochs}")
    prefix = [] if learner == PAPER_LEARNER else [learner_label(learner)]
    return " ".join(prefix + [name + ("-MEP" if mep else "")] + qualifiers)


def learner_label(learner: str) -> str:
    """A learner's name in labels: a registered name in capitals (``TD3``, ``SAC``); a class recorded by its
    import path (no ``NAME`` of its own) by its class name as written (``user_late.TD3Late`` -> ``TD3Late``)."""
    return learner.rpartition(".")[2] if "." in learner else learner.upper()


def _config_order(run: dict[str, Any]) -> tuple:
    """Sort key: DDPG first; then HER, ARCHER and other constants, linear, exponential, success and
    the other kinds (hersd.contract.schedules.SCHEDULES' order); MEP after plain; HER's weights first; then by lambda_r,
    lambda_h (higher first), eps, beta1, beta2, K (the paper's first)."""
    weights_rank = 0 if (run["lambda_r"], run["lambda_h"]) == HER_WEIGHTS else 1
    return (run["learner"] != PAPER_LEARNER, run["learner"], schedule_rank(run["schedule"]), run["mep"], weights_rank,
            run["lambda_r"], -run["lambda_h"], run["eps"], run["beta1"], run["beta2"],
            run["total_epochs"] != PAPER_EPOCHS, run["total_epochs"])


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A nested dict -> {"a.b": value}."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[prefix + key] = value
    return flat


def configuration(config: dict[str, Any]) -> dict[str, Any]:
    """The dotted settings that make a run's configuration, as one types them: its identity (as the run store
    hashes it) less the seed, with the fields the identity leaves out at their earlier value shown at that value."""
    identity = {key: value for key, value in run_identity(config).items() if key != "seed"}
    if isinstance(identity.get("learner"), dict):  # a class's settings by the key one types: learner.td3late.*
        identity["learner"] = learner_node(identity["learner"])
    return {**HASHED_UNLESS, **_flatten(identity)}


def _distinguish(labels: list[str], settings: list[dict[str, Any]], groups: list[tuple]) -> list[str]:
    """Within each group of runs sharing a label, append the settings that differ.

    ``settings[i]`` are run i's dotted config fields that define its configuration;
    ``groups[i]`` is the group key of run i. Returns the new labels.
    """
    members: dict[tuple, list[int]] = {}
    for index, group in enumerate(groups):
        members.setdefault(group, []).append(index)
    new_labels = list(labels)
    for indices in members.values():
        keys = sorted({key for i in indices for key in settings[i]})
        differing = [key for key in keys
                     if len({json.dumps(settings[i].get(key)) for i in indices}) > 1]
        for i in indices:
            if differing:
                new_labels[i] += " (" + ", ".join(f"{key}={settings[i].get(key)}" for key in differing) + ")"
    return new_labels


class ReadLog(NamedTuple):
    """One readable log: ``row`` its RUN_COLUMNS values (but run and config), ``settings`` the dotted
    config fields that define its configuration, ``columns`` EPOCH_FIELDS name -> array of shape (epochs,);
    ``missing`` the error naming its schedule class when that cannot label it (:func:`logged_schedule`; "" if it can),
    ``mismatch`` where today's class gives other rates than the log ("" if it gives the logged ones)."""

    row: dict[str, Any]
    settings: dict[str, Any]
    columns: dict[str, np.ndarray]
    sessions: list[dict[str, Any]] = []  # analysis.provenance.session_rows
    missing: str = ""
    mismatch: str = ""


RATE_TOLERANCE = 1e-9  # a class's rate this close to the logged one gives it (the log keeps every float exactly)


def logged_schedule(record: dict[str, Any]) -> tuple[Schedule | LoggedSchedule, str]:
    """The schedule of a log's record and "", or, when its class cannot be imported here, refuses the logged
    settings (a value its ``__post_init__`` now refuses, or settings renamed since: :func:`unfit_settings`) or
    cannot name it (:func:`naming_error`), a :class:`LoggedSchedule` and the error naming the class."""
    try:
        schedule = schedule_from_record(record)
    except ConfigError as err:  # a ValueError, but the cause is the class's module, not the log
        return LoggedSchedule(dict(record)), str(err)
    except Exception as err:  # noqa: BLE001 - a check the class gained since (its __post_init__), not the log's fault
        return (LoggedSchedule(dict(record)),
                f"schedule class {record['kind']} refuses the logged settings {_settings(record)} ({raised(err)})")
    error = unfit_settings(record, schedule) or naming_error(schedule)
    return (LoggedSchedule(dict(record)), error) if error else (schedule, "")


def unfit_settings(record: dict[str, Any], schedule: Schedule) -> str:
    """Why today's class (``schedule``, built from the log's ``record``) does not fit the logged settings: a
    logged one it lacks, or one of its own the log lacks (but a setting added since at its earlier value,
    HASHED_UNLESS); "" where they fit."""
    today = schedule.record()
    earlier = {key.removeprefix("schedule."): value for key, value in HASHED_UNLESS.items()
               if key.startswith("schedule.")}
    extra = [name for name in record if name not in today]
    lacking = [name for name in today if name not in record and (name not in earlier or earlier[name] != today[name])]
    if not extra and not lacking:
        return ""
    why = [*([f"the log's {', '.join(extra)}: no setting of it"] if extra else []),
           *([f"its {', '.join(lacking)}: not in the log"] if lacking else [])]
    return f"schedule class {record['kind']} does not take the logged settings {_settings(record)} ({'; '.join(why)})"


def _settings(record: dict[str, Any]) -> str:
    """A logged schedule's settings as ``name=value`` words, e.g. ``high=0.9 low=0.5 k0=1``."""
    return " ".join(f"{name}={shown_value(value)}" for name, value in record.items() if name != "kind")


def naming_error(schedule: Schedule) -> str:
    """The error naming a class whose ``label()`` or ``tag()`` raises or gives no str; "" where both name it."""
    for method in (schedule.label, schedule.tag):
        where = f"schedule class {kind_name(type(schedule))}: its {method.__name__}()"
        try:
            name = method()
        except Exception as err:  # noqa: BLE001 - a user's method: named in one line, the log's record labels it
            return f"{where} raised {raised(err)}; fix that class"
        if not isinstance(name, str):
            return f"{where} gave {name!r}, a {type(name).__name__}, not a str; fix that class"
    return ""


def _run_row(meta: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any], Schedule | LoggedSchedule, str]:
    """One run's columns from its metadata, its configuration-defining settings, its schedule and the error
    naming the schedule's class when that cannot label it ("" if it can); mu_eps is left to the rates."""
    config = meta["config"]
    schedule, missing = logged_schedule(config["schedule"])
    record = schedule.record if missing else schedule.record()
    row = {
        "task": config["task"]["name"],
        "algo": config["algo"]["name"],
        "learner": str(config.get("learner", {}).get("name", PAPER_LEARNER)),
        "schedule": str(record["kind"]) if missing else kind_name(type(schedule)),
        "schedule_tag": schedule.tag(),
        "schedule_label": schedule.label(),
        "schedule_record": json.dumps(record, sort_keys=not missing),  # a logged record in its order: its label's
        "constant_rate": schedule.constant_rate,
        "adaptive": schedule.adaptive,
        **{name: float(record.get(name, np.nan)) for name in ("eps", "beta1", "beta2")},
        "lambda_r": float(config["algo"]["lambda_r"]),
        "lambda_h": float(config["algo"]["lambda_h"]),
        "mep": bool(config["algo"]["mep"]["enabled"]),
        "seed": int(meta.get("seed", config["seed"])),
        "total_epochs": int(config["epochs"]),
        "run_id": str(meta["run_id"]),
        "cpu": str((meta.get("machine") or {}).get("cpu_model") or ""),
    }
    return row, configuration(config), schedule, missing


def _epoch_columns(records: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """EPOCH_FIELDS name -> array over ``records``: int64 for integer fields every record has, float64
    (null or missing -> NaN) otherwise."""
    return {name: np.array([record.get(name) for record in records],
                           dtype=np.int64 if kind == "integer" and name not in OPTIONAL_EPOCH_FIELDS else np.float64)
            for name, (kind, _) in EPOCH_FIELDS.items()}


def class_rates(schedule: Schedule, epochs: int, total_epochs: int, train_success: np.ndarray) -> np.ndarray:
    """The rates today's class gives epochs 1..``epochs`` of a run of K = ``total_epochs`` (shape (epochs,)),
    an adaptive one from the logged train success (shape (>= epochs - 1,)); raises what the class raises."""
    return np.array([schedule.rate(k, total_epochs, train_success[:k - 1].tolist()) if schedule.adaptive
                     else schedule.rate(k, total_epochs) for k in range(1, epochs + 1)], dtype=float)


def rate_difference(schedule: Schedule, total_epochs: int, columns: dict[str, np.ndarray]) -> str:
    """Where today's class gives other rates than the logged ones (``columns``: the log's epoch columns), e.g.
    ``epoch 1: logged 0.9, class 0.5``; "" where it gives every logged rate (within RATE_TOLERANCE)."""
    logged = columns["relabel_rate"]
    try:
        expected = class_rates(schedule, len(logged), total_epochs, columns["train_success"])
    except Exception as err:  # noqa: BLE001 - a user's rate: named in the line, the log's rates are used
        return f"its rate raised {type(err).__name__}"
    differ = np.flatnonzero(~np.isclose(expected, logged, rtol=0.0, atol=RATE_TOLERANCE))
    if not len(differ):
        return ""
    first = differ[0]
    return f"epoch {first + 1}: logged {logged[first]:.6g}, class {expected[first]:.6g}"


def logged_mean_rate(schedule: Schedule | LoggedSchedule, total_epochs: int, logged: np.ndarray,
                     trusted: bool) -> float:
    """mu_eps of a run from its logged rates (shape (epochs done,)). A fixed schedule's: the exact mean of its K rates
    (summed as fractions, rounded once: K rates of 0.8 give 0.8), for a run in progress its logged rates followed
    by its class's for the epochs to come when the class gives the logged ones (``trusted``), else NaN. An adaptive
    one's: the (floating) mean of the rates logged so far; NaN without any."""
    if schedule.adaptive:
        return float(np.mean(logged)) if len(logged) else float("nan")
    if len(logged) < total_epochs and not trusted:
        return float("nan")
    rates = logged if len(logged) >= total_epochs else [*logged, *schedule.epoch_rates(total_epochs)[len(logged):]]
    return float(sum(map(Fraction, map(float, rates))) / len(rates))


def read_log(path: Path, folder: Path) -> ReadLog | str:
    """One log -> :class:`ReadLog`, or the line saying why it was skipped (``"<path>: <reason>"``, the path
    relative to ``folder``). A damaged log gives the epochs written before the damage; a log whose schedule class
    cannot label it is read all the same (:func:`logged_schedule`)."""
    shown = path.relative_to(folder).as_posix()
    try:
        log = read_records(path)
        row, settings, schedule, missing = _run_row(log.meta)
    except RunLogError as err:
        return f"{shown}: {str(err).removeprefix(f'{path}: ')}"
    except (KeyError, TypeError, ValueError) as err:
        return f"{shown}: run metadata lacks or mistypes a config field ({err})"
    columns = _epoch_columns(log.records)
    mismatch = "" if missing else rate_difference(schedule, row["total_epochs"], columns)
    row.update(epochs_done=len(log.records), complete=log.complete, damaged=log.damaged, path=shown,
               error=("" if log.complete else RunFolder(path.parent).error()) or "",
               mu_eps=logged_mean_rate(schedule, row["total_epochs"], columns["relabel_rate"],
                                       trusted=not missing and not mismatch))
    return ReadLog(row, settings, columns, session_rows(log.sessions, [(m.topic, m.log_time) for m in log.messages]),
                   missing, mismatch)


def find_logs(folder: Path) -> list[Path]:
    """Every run log below ``folder`` (whatever is named ``run.mcap`` but a folder), in path order."""
    return sorted(path for path in Path(folder).rglob(LOG_NAME) if not path.is_dir())


def checked_folder(folder: str | Path) -> Path:
    """``folder`` as a Path; ReportInputError (one line) when it is not a folder: a file, or nothing."""
    folder = Path(folder)
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist"
        raise ReportInputError(f"FOLDER {folder} {what}; give a folder of run logs ({LOG_NAME} files)")
    return folder


class LogReading:
    """The logs below a folder, being read (see :func:`start_reading`)."""

    def __init__(self, folder: Path, paths: list[Path]) -> None:
        self.folder, self.paths = folder, paths
        # Strided batches mix tasks and schedules, so each takes about as long as the others.
        parallel = len(paths) >= PARALLEL_FROM
        self._batches = [paths[i::READ_BATCHES] for i in range(READ_BATCHES)] if parallel else [paths]
        self._reading = ForkedMap(self._read_batch, self._batches)

    def _read_batch(self, paths: list[Path]) -> list[ReadLog | str]:
        return [read_log(path, self.folder) for path in paths]

    def result(self, tasks: Iterable[str] | None = None, algos: Iterable[str] | None = None) -> RunTable:
        """Wait for the logs and make the tables: see :func:`load_runs`."""
        by_path = {path: log for batch, logs in zip(self._batches, self._reading.results())
                   for path, log in zip(batch, logs)}
        logs = [by_path[path] for path in self.paths]
        readable, copies = one_log_per_run([log for log in logs if isinstance(log, ReadLog)])
        if not readable:
            reasons = [log for log in logs if isinstance(log, str)]
            first = f" ({reasons[0]}{f'; and {len(reasons) - 1} more' if len(reasons) > 1 else ''})" if reasons else ""
            raise ReportInputError(f"none of the {len(logs)} {LOG_NAME} files under {self.folder} is readable{first}; "
                                   "give a folder of hersd run logs")
        kept = [log for log in readable
                if (tasks is None or log.row["task"] in tasks) and (algos is None or log.row["algo"] in algos)]
        if not kept:
            found_tasks = sorted({log.row["task"] for log in readable})
            found_algos = sorted({log.row["algo"] for log in readable})
            raise ReportInputError(f"no run matches the filters (tasks present: {', '.join(found_tasks)}; "
                                   f"algos present: {', '.join(found_algos)})")
        table = _tables(kept, skipped=[log for log in logs if isinstance(log, str)])
        table.missing_schedules = missing_schedule_lines([MissingSchedule(log.row["path"], log.missing)
                                                          for log in kept if log.missing])
        table.copies, table.left_out = copies, len(logs) - len(readable)
        return table


def one_log_per_run(logs: list[ReadLog]) -> tuple[list[ReadLog], list[str]]:
    """One log per run (``run_id``: config and seed), so a copied folder is not a second seed: the complete
    one, else the one with the most epochs; and the lines naming those left out: copies (the same first session)
    one line per top folder, other runs of the same config and seed (trained apart) one line each."""
    kept: dict[str, ReadLog] = {}
    for log in sorted(logs, key=lambda log: (not log.row["complete"], -log.row["epochs_done"])):
        kept.setdefault(log.row["run_id"], log)
    copies: dict[str, list[tuple[str, str]]] = {}  # top folder -> (copy, the log read)
    lines = []
    for log in (log for log in logs if kept[log.row["run_id"]] is not log):
        read = kept[log.row["run_id"]]
        if _first_start(log) == _first_start(read):
            copies.setdefault(log.row["path"].split("/")[0], []).append((log.row["path"], read.row["path"]))
        else:
            lines.append(f"{log.row['path']}: another run of the config and seed of {read.row['path']} (run "
                         f"{log.row['run_id']}), trained apart; that one is read, this one left out: report their "
                         "folders apart to compare them")
    for top, pairs in copies.items():
        (path, read), more = pairs[0], len(pairs) - 1
        lines.append(f"{path}: a copy of {read} (the one read), left out" if not more else
                     f"{top}/: {len(pairs)} run logs copying runs read elsewhere (e.g. {path}, a copy of {read}), "
                     "left out")
    return [log for log in logs if kept[log.row["run_id"]] is log], lines


def _first_start(log: ReadLog) -> Any:
    """When the log's first session started (ns), None for a log without sessions."""
    return log.sessions[0]["started"] if log.sessions else None


def missing_schedule_lines(missing: list[MissingSchedule]) -> list[str]:
    """One line per error of :func:`logged_schedule` (naming the class), with the logs read without the class
    (from their rates, labelled from their records) and how to give them the class's own label."""
    paths: dict[str, list[str]] = {}
    for log in missing:
        paths.setdefault(log.error, []).append(log.path)
    fixes = {"; is its module on PYTHONPATH?": "put the folder holding the class's module on PYTHONPATH "
                                               "(PYTHONPATH=<folder> hersd-report ...)",
             "; is the class's name right?": "give its module that class again (the log names it as it was)",
             "; fix that module": "fix that module",  # hersd.contract.plugins.class_at's three endings
             "; fix that class": "fix that class"}  # naming_error's
    lines = []
    for error, shown in paths.items():
        ending = next((end for end in fixes if error.endswith(end)), None)
        lines.append(f"{error.removesuffix(ending or '')}: {len(shown)} run log{'' if len(shown) == 1 else 's'} "
                     f"reported from {'its' if len(shown) == 1 else 'their'} logged rates and labelled from the "
                     f"log ({shown[0]}{' and others' if len(shown) > 1 else ''}); "
                     f"{fixes[ending] if ending else 'make its class accept the logged settings'} for the class's own "
                     "label and a check of its rates")
    return lines


def rate_mismatch_lines(configs: list[str], logs: list[ReadLog]) -> list[str]:
    """One line per configuration (``configs[i]``: log i's label) some of whose logs hold other rates than its
    schedule's class gives today (an edited ``rate``): the report draws and averages the logged ones."""
    found: dict[str, list[ReadLog]] = {}
    for config, log in zip(configs, logs):
        if log.mismatch:
            found.setdefault(config, []).append(log)
    return [f"configuration {config}: schedule class {differing[0].row['schedule']} today gives other rates than "
            f"{len(differing)} of its logs ({differing[0].row['path']}, {differing[0].mismatch}); the report uses "
            "the logged rates" for config, differing in found.items()]


def _settle_logged(rows: list[dict[str, Any]], logs: list[ReadLog]) -> None:
    """Runs whose schedule class cannot label them (:func:`logged_schedule`): adaptive when two logs of one
    schedule and K hold other rates at an epoch both reached (a fixed schedule gives every run the same); then, in
    progress, their mean logged rate so far as mu_eps."""
    groups: dict[tuple, list[int]] = {}
    for index, log in enumerate(logs):
        if log.missing:
            groups.setdefault((rows[index]["schedule_record"], rows[index]["total_epochs"]), []).append(index)
    for members in groups.values():
        rates = [logs[index].columns["relabel_rate"] for index in members]
        reached = min(map(len, rates))
        adaptive = any(not np.allclose(other[:reached], rates[0][:reached], rtol=0.0, atol=RATE_TOLERANCE)
                       for other in rates[1:])
        for index, logged in zip(members, rates):
            rows[index]["adaptive"] = adaptive
            if adaptive and len(logged):
                rows[index]["mu_eps"] = float(np.mean(logged))


def start_reading(folder: str | Path) -> LogReading:
    """Start reading every ``run.mcap`` below ``folder``: in worker processes, one per core, when
    there are PARALLEL_FROM or more, so the caller can do other work meanwhile (the report imports
    its drawing modules); ``.result(tasks, algos)`` waits and gives the :class:`RunTable`.
    Raises :class:`ReportInputError` when the folder has no logs."""
    folder = checked_folder(folder)
    paths = find_logs(folder)
    if not paths:
        raise ReportInputError(f"no {LOG_NAME} files under {folder}")
    return LogReading(folder, paths)


def load_runs(folder: str | Path, tasks: Iterable[str] | None = None,
              algos: Iterable[str] | None = None) -> RunTable:
    """Read every ``run.mcap`` below ``folder`` (see the module doc for the tables).

    A damaged log contributes its completed epochs; an unreadable one is skipped and named
    in ``skipped``. ``tasks`` / ``algos`` keep only runs whose config.task.name /
    config.algo.name is listed. Raises :class:`ReportInputError` when nothing is left.
    """
    return start_reading(folder).result(tasks, algos)


def _tables(logs: list[ReadLog], skipped: list[str]) -> RunTable:
    """The runs and epochs tables of readable logs: labels told apart, configs ordered."""
    rows = [dict(log.row) for log in logs]
    _settle_logged(rows, logs)
    schedules = [LoggedSchedule(json.loads(row["schedule_record"])) if log.missing
                 else schedule_from_record(json.loads(row["schedule_record"])) for row, log in zip(rows, logs)]
    variants = [variant(log.settings) for log in logs]

    def label(index: int, epochs: int = PAPER_EPOCHS) -> str:
        row = rows[index]
        return config_label(schedules[index], row["lambda_r"], row["lambda_h"], row["mep"], row["learner"], epochs,
                            variants[index], row["algo"])

    labels = [label(index) for index in range(len(rows))]
    epochs_of: dict[str, set[int]] = {}
    for row, name in zip(rows, labels):
        epochs_of.setdefault(name, set()).add(row["total_epochs"])
    labels = [label(index, row["total_epochs"]) if len(epochs_of[name]) > 1 else name
              for index, (row, name) in enumerate(zip(rows, labels))]
    # Within a task, seeds of one label must share every setting; where they do not, say what
    # differs. Across tasks a label (K included) may differ in the task's own settings (task.*: its env, its
    # budget per epoch): tasks are strata; in any other setting it may not (the aggregate table pools a label's tasks).
    groups = [(row["task"], label) for row, label in zip(rows, labels)]
    labels = _distinguish(labels, [log.settings for log in logs], groups)
    labels = _distinguish(labels, [{key: value for key, value in log.settings.items() if not key.startswith("task.")}
                                   for log in logs], labels)
    for row, label, log, varied in zip(rows, labels, logs, variants):
        row.update(config=label, variant=" ".join(varied), defaults_id=defaults_id(log.settings))
    order = sorted({row["config"]: row for row in rows}.values(), key=lambda r: (_config_order(r), r["config"]))
    runs = pd.DataFrame.from_records(rows)
    runs.insert(0, "run", range(len(runs)))
    runs = runs[list(RUN_COLUMNS)]
    runs["config"] = pd.Categorical(runs["config"], categories=[r["config"] for r in order], ordered=True)

    run_of_row = runs["run"].to_numpy().repeat([row["epochs_done"] for row in rows])
    epochs = runs.take(run_of_row).reset_index(drop=True)
    for name in EPOCH_FIELDS:
        epochs[name] = np.concatenate([log.columns[name] for log in logs])
    return RunTable(runs=runs, epochs=epochs, skipped=skipped, sessions=session_table([log.sessions for log in logs]),
                    rate_mismatches=rate_mismatch_lines(labels, logs))
