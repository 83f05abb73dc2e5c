"""The run store: where a run lives and what state it is in, shared by training, sweeps and
the search. Light (no torch): a sweep plans hundreds of runs with it.

``<results_dir>/<task>/<algo>/<schedule>/seed<N>-<hash>/`` (``<learner>-<algo>`` for learners but ddpg) holds

- ``run.mcap``        the run's log (:mod:`hersd.contract.runlog`), the contract with the analysis;
- ``checkpoint.pt``   an exact-resume checkpoint (:mod:`hersd.engine.run_state`), removed when done;
- ``run.lock``        held (``flock``) by the process running it, so a run never runs twice at once;
                      it holds that process's pid while held (:meth:`RunFolder.holder`);
- ``policy/epoch_<k>.gif``  an animation of the policy's test episodes after epoch k (:mod:`hersd.engine.render`);
- ``error.log``       the traceback of a sweep's run that stopped with an error (:meth:`RunFolder.error`);
- ``run.<why>-<time>.mcap`` / ``checkpoint.<why>-<time>.pt``  files kept aside, never deleted.

The hash covers every config field that changes what the run computes
(:data:`NOT_HASHED` lists the others), so two configs never share a directory and the same
config always maps to the same one: that is what lets sweeps skip and resume runs.
:func:`run_identity` is that identity, for a config or for the config a log's metadata holds
(however old the log): the report groups runs with it too.

A run's state as ``hersd-sweep --dry-run`` lists it and ``hersd-train --dry-run`` shows it (:func:`run_status`),
read from these files only, so it works while runs are training:

- ``complete``   the log has its complete marker;
- ``running``    a live process holds the run's lock (the pid it recorded in ``run.lock``):
                 ``epoch N of K``, that pid, the recent pace and the time to go;
- ``failed``     it stopped with an error (``error.log`` newer than its log): the error's first line, the
                 epochs logged; a re-run resumes it (a checkpoint) or starts it afresh;
- ``resumable``  ``epoch N of K`` logged and a checkpoint to resume from;
- ``new``        nothing yet, or a log without checkpoint (set aside when the run starts again).

Runs started by hersd before lock files recorded pids show as ``resumable`` while they train;
the age of their last epoch tells the two apart. A run with logged epochs also shows how it learns: its
mean test success over its last RECENT_EPOCHS.
"""

from __future__ import annotations

import copy
import fcntl
import hashlib
import json
import os
import time
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from itertools import takewhile
from pathlib import Path
from typing import Any, Iterator, NamedTuple, Sequence

from hersd.contract.config import PAPER_LEARNER, TrainConfig, config_record, learner_key
from hersd.contract.errors import ConfigError
from hersd.contract.runlog import LOG_NAME, RunLogError, RunRecords, read_records
from hersd.contract.schedules.base import FLAT_RECORD

CHECKPOINT_NAME = "checkpoint.pt"
LOCK_NAME = "run.lock"
ERROR_NAME = "error.log"  # a failed run's traceback, written by the sweep that ran it
POLICY_DIR = "policy"  # the run's policy animations: policy/epoch_<k>.gif
# Fields that change where, how loudly or how fast a run is written, not what it computes.
NOT_HASHED = ("results_dir", "run_dir", "quiet", "checkpoint_every", "keep_checkpoint", "threads", "device",
              "flush_denormal", "render_every", "bias", "tensorboard")
# Fields added to the schema after runs were made: left out of the hash while they hold this
# value, so every earlier run keeps its directory (dotted path -> the value of earlier runs).
HASHED_UNLESS: dict[str, Any] = {**{f"schedule.{name}": FLAT_RECORD[name] for name in ("window", "eps_min")},
                                 "precision": "fp32", "update": "autograd"}


class RunLockedError(RuntimeError):
    """Another process is running the same configuration."""


def run_identity(config: TrainConfig | dict[str, Any]) -> dict[str, Any]:
    """What identifies a run: its config as a nested dict, less :data:`NOT_HASHED` and the
    :data:`HASHED_UNLESS` defaults; of ``learner`` only the learner in use and its settings (the one object
    its class declares and its ``build`` reads, :class:`hersd.contract.config.LearnerConfig`), and nothing for ddpg (the learner of every run made before learners were a setting).

    ``config`` is a TrainConfig or its dict as a log's ``/run/meta`` holds it; a log written
    before a field existed has the identity of a new log of the same run.
    """
    content = config_record(config) if isinstance(config, TrainConfig) else copy.deepcopy(config)
    content = {key: value for key, value in content.items() if key not in NOT_HASHED}
    learner = content.pop("learner", {"name": PAPER_LEARNER})
    name = learner["name"]
    if name != PAPER_LEARNER:  # its settings are one object, under its name (hersd.contract.config.learner_record)
        content["learner"] = {"name": name, **({name: learner[name]} if name in learner else {})}
    for dotted, earlier_value in HASHED_UNLESS.items():
        *parents, leaf = dotted.split(".")
        node = content
        for key in parents:
            node = node.get(key, {})
        if leaf in node and node[leaf] == earlier_value:
            del node[leaf]
    return content


def identity_hash(identity: dict[str, Any]) -> str:
    """8 hex digits of a run's identity (:func:`run_identity`)."""
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:8]


def config_hash(config: TrainConfig | dict[str, Any]) -> str:
    """8 hex digits identifying everything that determines the run's result (:func:`run_identity`); a run about to
    train has it in its :class:`hersd.contract.runspec.RunSpec`, this is for configs read back from logs."""
    return identity_hash(run_identity(config))


def folder_path(cfg: TrainConfig, run_id: str) -> Path:
    """The directory of the run of ``cfg`` whose hash is ``run_id``: ``cfg.run_dir`` if set, else
    ``<results_dir>/<task>/<algo>/<schedule tag>/seed<N>-<run_id>`` (``<learner>-<algo>`` for learners but ddpg)."""
    if cfg.run_dir is not None:
        return Path(cfg.run_dir)
    algo = cfg.algo.name if cfg.learner.name == PAPER_LEARNER else f"{learner_key(cfg.learner.name)}-{cfg.algo.name}"
    return Path(cfg.results_dir) / cfg.task.name / algo / cfg.schedule.tag() / f"seed{cfg.seed}-{run_id}"


def run_dir(cfg: TrainConfig) -> Path:
    """The run's directory (:func:`folder_path`), its hash computed anew: for a config read back, not a run to train."""
    return folder_path(cfg, config_hash(cfg))


@dataclass(frozen=True)
class RunFolder:
    """One run's directory and its files, as training, rendering, the run store and a sweep's
    status read them: the log, the checkpoint, the lock (and the pid of its holder), the policy
    animations, the run's state and its epochs done."""

    path: Path

    @property
    def log(self) -> Path:
        return self.path / LOG_NAME

    @property
    def checkpoint(self) -> Path:
        return self.path / CHECKPOINT_NAME

    def records(self) -> RunRecords | None:
        """The log read back (every completed epoch, even mid-run), None without a log; RunLogError if unreadable."""
        return read_records(self.log) if self.log.exists() else None

    def error(self) -> str | None:
        """The first line of the error that stopped the run (the exception line of ``error.log``'s traceback),
        None when it has no error log, or when its log was written after it (the run went on since)."""
        path = self.path / ERROR_NAME
        try:
            stopped = path.stat().st_mtime
            text = path.read_text(errors="replace")
        except OSError:
            return None
        if self.log.exists() and self.log.stat().st_mtime > stopped:
            return None
        return error_line(text)

    def state(self) -> str:
        """``complete`` (its log says so), ``resumable`` (a checkpoint exists) or ``new``."""
        try:
            if (records := self.records()) is not None and records.complete:
                return "complete"
        except RunLogError:
            pass
        return "resumable" if self.checkpoint.exists() else "new"

    def animation(self, epoch: int) -> Path:
        """Where the animation of the policy after ``epoch`` lives."""
        return self.path / POLICY_DIR / f"epoch_{epoch}.gif"

    def animations(self) -> dict[int, Path]:
        """The run's policy animations: epoch -> path, in epoch order (none: empty)."""
        found = {}
        for path in (self.path / POLICY_DIR).glob("epoch_*.gif"):
            epoch = path.stem.removeprefix("epoch_")
            if epoch.isdigit():
                found[int(epoch)] = path
        return dict(sorted(found.items()))

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the run's lock for the ``with`` block; :class:`RunLockedError` if another process has it.
        The holder writes its pid into the lock file (:meth:`holder`) and empties it on release."""
        with open(self.path / LOCK_NAME, "a+") as lock_file:  # not "w": that would empty a holder's pid
            try:
                fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = self.holder()
                raise RunLockedError(f"{self.path} is being run by another process"
                                     + (f" (pid {holder})" if holder else "")) from None
            lock_file.truncate(0)
            lock_file.write(f"{os.getpid()}\n")
            lock_file.flush()
            try:
                yield
            finally:
                lock_file.truncate(0)

    def holder(self) -> int | None:
        """The pid of the live process holding the run's lock, as it recorded it; None when none is
        recorded (no lock, released, or taken by hersd before locks recorded pids) or that process is gone."""
        try:
            pid = int((self.path / LOCK_NAME).read_text().strip())
        except (OSError, ValueError):
            return None
        return pid if pid_alive(pid) else None  # killed without releasing (kill -9): the lock is free


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` of this host runs: not gone, and not a zombie (killed, its parent not yet waiting
    for it: its files, and so its locks, are closed); another user's counts as running."""
    try:
        os.kill(pid, 0)  # signal 0: only asks whether the process exists
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except FileNotFoundError:  # no procfs (macOS): the signal's answer; or it ended just now
        return not Path("/proc/self/stat").exists()
    except (OSError, IndexError):
        return False


PACE_EPOCHS = 5  # a run's pace: the mean time of its last this many epochs
RECENT_EPOCHS = 10  # how a run learns at a glance: its mean test success over its last this many epochs


def ago(seconds: float) -> str:
    """``25 s``, ``14 min``, ``3.2 h``."""
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 \
        else f"{seconds / 3600:.1f} h"


class RunStatus(NamedTuple):
    """A run's state and detail (a sweep's listing, hersd-train's dry run), the epochs it has left, and, while it trains,
    its pace (seconds per epoch, the mean of its last PACE_EPOCHS) and the pid holding its lock."""

    state: str
    detail: str
    epochs_left: int
    pace: float | None = None
    holder: int | None = None


def recent_success(records: Sequence[dict]) -> str:
    """``test success 0.35 over its last 10 epochs``: the mean of the last RECENT_EPOCHS epochs' test success
    (``records``: the log's epoch records, at least one)."""
    recent = [record["test_success"] for record in records[-RECENT_EPOCHS:]]
    return f"test success {sum(recent) / len(recent):.2f} over its last {len(recent)} epoch{'s' * (len(recent) > 1)}"


def run_status(directory: Path, epochs: int, now: float | None = None) -> RunStatus:
    """The status of the run in ``directory`` planned for ``epochs`` epochs, e.g. state ``running``, detail
    ``epoch 45 of 200, pid 1701, 31 s per epoch, ~2.7 h to go, last epoch 12 s ago, test success 0.35 over its
    last 10 epochs``, 155 epochs left, pace 31."""
    folder = RunFolder(directory)
    holder = folder.holder()
    done: list = []
    detail = []
    pace = None
    try:
        records = folder.records()
    except RunLogError as err:
        detail.append(f"log unreadable ({str(err).removeprefix(f'{folder.log}: ')})")
    else:
        if records is not None and records.complete:
            return RunStatus("complete", f"{len(records.records)} epochs, {recent_success(records.records)}", 0)
        if records is not None:
            done = records.records
            detail.append(f"epoch {len(done)} of {epochs}")
    if not done and holder is not None and not detail:
        detail.append(f"epoch 0 of {epochs}")
    if holder is not None:
        detail.append(f"pid {holder}")
        recent = [record["epoch_seconds"] for record in done[-PACE_EPOCHS:]]
        if recent:
            pace = sum(recent) / len(recent)
            detail.append(f"{pace:.0f} s per epoch, ~{ago(pace * max(epochs - len(done), 0))} to go")
    if done:
        detail.append(f"last epoch {ago(max(0.0, (now or time.time()) - folder.log.stat().st_mtime))} ago")
        detail.append(recent_success(done))
    left = max(epochs - len(done), 0)
    if holder is not None:
        return RunStatus("running", ", ".join(detail), left, pace, holder)
    if (error := folder.error()) is not None:
        return RunStatus("failed", ", ".join([error, *detail]), left if folder.checkpoint.exists() else epochs)
    if folder.checkpoint.exists():
        return RunStatus("resumable", ", ".join(detail), left)
    if detail:
        detail.append("no checkpoint: starts afresh, the log kept aside")
    return RunStatus("new", ", ".join(detail), epochs)


def error_line(text: str) -> str:
    """The first line of the error a traceback's text ends with (the first line after its last frame's
    ``  File ...`` line and the code lines under it), else the text's first non-empty line; ``unknown error``
    for an empty text."""
    lines = [line for line in text.splitlines() if line.strip()]
    frames = [index for index, line in enumerate(lines) if line.startswith('  File "')]
    after = lines[frames[-1] + 1:] if frames else lines
    error = next((line for line in after if not line.startswith("    ")), "unknown error")  # past code and carets
    return " ".join(error.split())


def remove_if_unused(directory: Path, up_to: Path) -> None:
    """Remove a run directory that holds nothing but its lock file (a run that failed at start),
    then its parents while empty, up to (not including) ``up_to``."""
    if not directory.is_dir() or {p.name for p in directory.iterdir()} - {LOCK_NAME}:
        return
    (directory / LOCK_NAME).unlink(missing_ok=True)
    up_to = up_to.resolve()
    while directory.resolve() != up_to and directory.resolve().is_relative_to(up_to) and not any(directory.iterdir()):
        directory.rmdir()
        directory = directory.parent


def keep_aside(path: Path, why: str) -> Path:
    """Rename ``run.mcap`` to ``run.<why>-<time>.mcap`` (any file likewise) next to it; returns the new path."""
    kept = path.with_name(f"{path.name.split('.')[0]}.{why}-{time.strftime('%Y%m%d-%H%M%S')}{path.suffix}")
    os.replace(path, kept)
    return kept


def check_writable(directory: Path, key: str = "results_dir", keep: bool = True) -> None:
    """Fail early (ConfigError naming the setting ``key``) if ``directory`` cannot be created or written; ``keep``
    False (a dry run): the same check, the folders it created removed again."""
    created = list(takewhile(lambda folder: not folder.exists(), (directory, *directory.parents)))
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:
        raise ConfigError(f"{key}: cannot write to {directory} ({err.strerror}); "
                          f"pass {key}=<a writable folder>") from None
    finally:
        for folder in () if keep else created:  # deepest first
            with suppress(OSError):
                folder.rmdir()


def check_run_path(directory: Path, top: Path, key: str = "results_dir") -> None:
    """Fail early (ConfigError naming ``key``) if a file stands where a folder between ``top`` (checked by
    :func:`check_writable`) and the run's folder ``directory`` below it goes (e.g. ``<results_dir>/reach``)."""
    folder = top
    for part in directory.relative_to(top).parts:
        folder = folder / part
        if folder.exists() and not folder.is_dir():
            raise ConfigError(f"{key}: {folder} is a file, where the run's folder {directory} goes; "
                              f"move that file away or pass {key}=<another folder>")
