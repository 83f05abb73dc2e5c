"""Run logs -> tidy tables.

:func:`load_runs` reads every ``run.mcap`` below a folder into a :class:`RunTable`:

- ``runs``: one row per run (columns: :data:`RUN_COLUMNS`);
- ``epochs``: one row per run x completed epoch: the run's columns, then every field of
  :data:`hersd.runlog.EPOCH_FIELDS`.

A run's *configuration* label (column ``config``) names what its seeds have in common, so
seeds are grouped by ``(task, config)``; see :func:`config_label`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from hersd.config import ScheduleConfig
from hersd.runlog import EPOCH_FIELDS, LOG_NAME, RunLogError, read_records
from hersd.runstore import NOT_HASHED
from hersd.schedules import SCHEDULE_KINDS, schedule_mean_rate
from hersd.tasks import task_rank

RUN_COLUMNS = (
    "run",            # 0-based index of the run in this table
    "task",           # config.task.name
    "config",         # configuration label (ordered categorical, see config_label)
    "algo",           # config.algo.name
    "learner",        # config.learner.name: ddpg (the paper's and every run before learners were a setting) | td3 | sac
    "schedule",       # config.schedule.kind: constant | linear | exponential
    "eps", "beta1", "beta2",
    "lambda_r", "lambda_h",
    "mep",            # config.algo.mep.enabled
    "seed",
    "total_epochs",   # K: config.epochs
    "mu_eps",         # eq. 10 over the run's K (eps itself for constant; the mean logged rate for success)
    "epochs_done",    # completed epochs in the log
    "complete",       # the log says the run finished
    "damaged",        # the file has no valid end (killed or still running)
    "run_id",         # 8-hex config hash written by training
    "path",           # the log's path relative to the loaded folder
)

# Config fields that change neither what a run computes nor which configuration it belongs to.
_NOT_CONFIGURATION = ("seed", *NOT_HASHED)
_SCHEDULE_ORDER = {kind: rank for rank, kind in enumerate(SCHEDULE_KINDS)}


class ReportInputError(ValueError):
    """The input cannot make a report (no logs, nothing readable, filters match nothing)."""


@dataclass
class RunTable:
    """Loaded runs; ``skipped`` holds one ``"<path>: <reason>"`` line per unreadable file."""

    runs: pd.DataFrame
    epochs: pd.DataFrame
    skipped: list[str] = field(default_factory=list)


def schedule_label(schedule: str, eps: float, beta1: float, beta2: float) -> str:
    """e.g. ``constant eps=0.8``, ``linear b1=0.25``, ``exp b1=0.5 b2=-0.5``, ``success b1=0.25``."""
    if schedule == "constant":
        return f"constant eps={eps:g}"
    if schedule == "success":
        return f"success b1={beta1:g}"
    return f"linear b1={beta1:g}" if schedule == "linear" else f"exp b1={beta1:g} b2={beta2:g}"


def config_label(schedule: str, eps: float, beta1: float, beta2: float,
                 lambda_r: float, lambda_h: float, mep: bool, learner: str = "ddpg") -> str:
    """Name of a configuration, e.g. ``HER``, ``ARCHER``, ``linear b1=0.25``,
    ``exp b1=0.5 b2=0.5``, ``HER-MEP``, ``linear b1=0.5 λh=0.5``, ``TD3 HER`` (learners other
    than the paper's DDPG lead the label).

    Constant schedules are HER (lambda_r = lambda_h = 1) or ARCHER (lambda_r = 1,
    lambda_h = 0.5), with ``eps=`` appended when eps != 0.8; other reward weights are
    appended as ``λr=`` / ``λh=``.
    """
    weights = (1.0, 1.0), (1.0, 0.5)
    if schedule == "constant":
        name = "ARCHER" if (lambda_r, lambda_h) == weights[1] else "HER"
        qualifiers = [f"eps={eps:g}"] if eps != 0.8 else []
        if (lambda_r, lambda_h) in weights:
            lambda_r = lambda_h = 1.0  # already said by the name
    else:
        name, qualifiers = schedule_label(schedule, eps, beta1, beta2), []
    if lambda_r != 1.0:
        qualifiers.append(f"λr={lambda_r:g}")
    if lambda_h != 1.0:
        qualifiers.append(f"λh={lambda_h:g}")
    prefix = [] if learner == "ddpg" else [learner.upper()]
    return " ".join(prefix + [name + ("-MEP" if mep else "")] + qualifiers)


def _config_order(run: dict[str, Any]) -> tuple:
    """Sort key: HER, ARCHER and other constants first, then linear, then exponential."""
    baseline_rank = 0 if (run["lambda_r"], run["lambda_h"]) == (1.0, 1.0) else 1
    return (run["learner"] != "ddpg", run["learner"], _SCHEDULE_ORDER.get(run["schedule"], len(SCHEDULE_KINDS)),
            run["mep"], baseline_rank, run["lambda_r"],
            -run["lambda_h"], run["eps"], run["beta1"], run["beta2"])


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[prefix + key] = value
    return flat


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


def _run_row(meta: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """One run's columns from its metadata, and its configuration-defining settings."""
    config = meta["config"]
    schedule = ScheduleConfig(**config["schedule"])
    row = {
        "task": config["task"]["name"],
        "algo": config["algo"]["name"],
        "learner": str(config.get("learner", {}).get("name", "ddpg")),
        "schedule": schedule.kind,
        "eps": float(schedule.eps),
        "beta1": float(schedule.beta1),
        "beta2": float(schedule.beta2),
        "lambda_r": float(config["algo"]["lambda_r"]),
        "lambda_h": float(config["algo"]["lambda_h"]),
        "mep": bool(config["algo"]["mep"]["enabled"]),
        "seed": int(meta.get("seed", config["seed"])),
        "total_epochs": int(config["epochs"]),
        "mu_eps": schedule_mean_rate(schedule, int(config["epochs"])),
        "run_id": str(meta["run_id"]),
    }
    settings = {key: value for key, value in _flatten(config).items()
                if key not in _NOT_CONFIGURATION}
    return row, settings


def _epoch_columns(records: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """EPOCH_FIELDS name -> array over ``records``: int64 for integer fields, float64 (null -> NaN) otherwise."""
    return {name: np.array([record.get(name) for record in records],
                           dtype=np.int64 if kind == "integer" else np.float64)
            for name, (kind, _) in EPOCH_FIELDS.items()}


def find_logs(folder: Path) -> list[Path]:
    """Every run log below ``folder``, in path order."""
    return sorted(Path(folder).rglob(LOG_NAME))


def load_runs(folder: str | Path, tasks: Iterable[str] | None = None,
              algos: Iterable[str] | None = None) -> RunTable:
    """Read every ``run.mcap`` below ``folder`` (see the module doc for the tables).

    A damaged log contributes its completed epochs; an unreadable one is skipped and named
    in ``skipped``. ``tasks`` / ``algos`` keep only runs whose config.task.name /
    config.algo.name is listed. Raises :class:`ReportInputError` when nothing is left.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ReportInputError(f"{folder} is not a folder")
    paths = find_logs(folder)
    if not paths:
        raise ReportInputError(f"no {LOG_NAME} files under {folder}")
    rows: list[dict[str, Any]] = []
    settings: list[dict[str, Any]] = []
    records: list[list[dict[str, Any]]] = []
    skipped: list[str] = []
    for path in paths:
        shown = path.relative_to(folder).as_posix()
        try:
            log = read_records(path)
            row, run_settings = _run_row(log.meta)
        except RunLogError as err:
            skipped.append(f"{shown}: {str(err).removeprefix(f'{path}: ')}")
            continue
        except (KeyError, TypeError, ValueError) as err:
            skipped.append(f"{shown}: run metadata lacks or mistypes a config field ({err})")
            continue
        row.update(epochs_done=len(log.records), complete=log.complete, damaged=log.damaged, path=shown)
        if row["schedule"] == "success" and log.records:  # placed by the rate it realised
            row["mu_eps"] = float(np.mean([record["relabel_rate"] for record in log.records]))
        rows.append(row)
        settings.append(run_settings)
        records.append(log.records)
    if not rows:
        raise ReportInputError(f"none of the {len(paths)} {LOG_NAME} files under {folder} is readable")

    keep = [i for i, row in enumerate(rows)
            if (tasks is None or row["task"] in tasks) and (algos is None or row["algo"] in algos)]
    if not keep:
        found_tasks = sorted({row["task"] for row in rows})
        found_algos = sorted({row["algo"] for row in rows})
        raise ReportInputError(f"no run matches the filters (tasks present: {', '.join(found_tasks)}; "
                               f"algos present: {', '.join(found_algos)})")
    rows = [rows[i] for i in keep]
    settings = [settings[i] for i in keep]
    records = [records[i] for i in keep]

    labels = [config_label(r["schedule"], r["eps"], r["beta1"], r["beta2"], r["lambda_r"], r["lambda_h"], r["mep"],
                           r["learner"]) for r in rows]
    # Within a task, seeds of one label must share every setting; where they do not, say what
    # differs. Across tasks a label may differ in budget (epochs, cycles): tasks are strata.
    labels = _distinguish(labels, settings, [(r["task"], label) for r, label in zip(rows, labels)])
    for row, label in zip(rows, labels):
        row["config"] = label

    order = sorted({row["config"]: row for row in rows}.values(), key=lambda r: (_config_order(r), r["config"]))
    runs = pd.DataFrame.from_records(rows)
    runs.insert(0, "run", range(len(runs)))
    runs = runs[list(RUN_COLUMNS)]
    runs["config"] = pd.Categorical(runs["config"], categories=[r["config"] for r in order], ordered=True)

    run_of_row = runs["run"].to_numpy().repeat([len(run_records) for run_records in records])
    epochs = runs.take(run_of_row).reset_index(drop=True)
    for name, values in _epoch_columns([record for run_records in records for record in run_records]).items():
        epochs[name] = values
    return RunTable(runs=runs, epochs=epochs, skipped=skipped)

