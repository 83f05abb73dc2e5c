"""The run log: one MCAP file per training run, the contract between training and analysis.

Channels (all JSON, each with a JSON schema of plain types, so any MCAP tool, Foxglove included,
can read and plot them):

- ``/run/meta``   one message per session (the first start, then one per resume): the
  resolved config, seed, versions, git commit, command line, start time,
  ``resumed_from_epoch`` (0 for the first session), effective totals, threads, device and
  machine (fields: :data:`META_FIELDS`);
- ``/epoch``      one message per completed epoch (fields: :data:`EPOCH_FIELDS`);
- ``/run/status`` ``{"status": "complete", ...}`` once the last epoch is written.

A value that does not exist (MEP's fields without MEP, the bias fields at epochs without an
evaluation, a git commit outside a checkout) is a missing key, never null; the reader gives
such epoch fields, and ``git_commit``, back as None. Only the config is stored verbatim (its
nulls are settings: "unset").

The file is chunked (one message per chunk, uncompressed) with a chunk index, statistics and
summary. After every message the writer rewrites the whole log to ``run.mcap.tmp`` next to it,
fsyncs it and renames it over ``run.mcap``: the file on disk is at every moment a complete,
indexed MCAP file holding every completed epoch, so a killed or still-running run opens in
readers that need the summary and index as well as in streaming ones (tested: ``mcap.reader.make_reader``,
``@mcap/core``'s indexed and streaming readers; the schemas use only types Foxglove accepts).
A resumed run's log keeps its earlier messages with their original log times. :func:`read_records`
also reads logs in the earlier format (unchunked, nullable types, no footer while a run was
running), keeping every epoch before a damage; :func:`rewritten` turns one into the current format.
This module needs only the standard library, mcap and pandas: reports are made without
torch or MuJoCo.
"""

from __future__ import annotations

import io
import json
import math
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

import mcap
import pandas as pd
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer

from hersd import __version__
from hersd.contract.errors import DiskFullError, full_disk

LOG_NAME = "run.mcap"
LIBRARY = f"hersd {__version__}; mcap-python {mcap.__version__}"  # the MCAP header's library string

# name -> (JSON type, description). Optional fields are absent where they have no value. The descriptions
# are part of every log's schema and name modules by their paths now; logs written before the split into
# hersd/contract and hersd/engine name the old paths (hersd/__init__.py's MOVED), records unchanged.
EPOCH_FIELDS: dict[str, tuple[str, str]] = {
    "epoch": ("integer", "epoch index k, 1..K"),
    "relabel_rate": ("number", "eps(k): probability that a sampled goal is replaced in hindsight"),
    "test_success": ("number", "share of the test episodes (deterministic policy) successful at the last step"),
    "train_success": ("number", "share of this epoch's exploration episodes successful at the last step"),
    "q_mean": ("number", "mean critic Q(s, a) over this epoch's training batches"),
    "q_std": ("number", "standard deviation of Q(s, a) over this epoch's training batches"),
    "critic_loss": ("number", "mean critic loss over this epoch's updates"),
    "actor_loss": ("number", "mean actor loss over this epoch's updates"),
    "share_hindsight": ("number", "share of sampled transitions whose goal was relabelled"),
    "share_real_success": ("number", "share of sampled transitions kept real with reward 'success'"),
    "share_real_failure": ("number", "share of sampled transitions kept real with reward 'failure'"),
    "env_steps": ("integer", "cumulative environment steps of exploration"),
    "updates": ("integer", "cumulative gradient updates"),
    "episodes_stored": ("integer", "episodes in the replay buffer at the end of the epoch"),
    "rollout_seconds": ("number", "seconds spent collecting exploration episodes this epoch"),
    "update_seconds": ("number", "seconds spent sampling and updating this epoch"),
    "eval_seconds": ("number", "seconds spent on test episodes this epoch"),
    "epoch_seconds": ("number", "wall-clock seconds of the whole epoch"),
    "mep_fit_seconds": ("number", "seconds spent fitting the MEP density model (absent without MEP)"),
    "priority_entropy": ("number", "entropy of the episode sampling distribution in nats (absent without MEP)"),
    "test_distance": ("number", "mean distance ||achieved - desired goal|| at the last step of the test episodes "
                                "(in the goal's units; absent in logs written before it was recorded)"),
    "alpha": ("number", "SAC's entropy temperature at the end of the epoch (absent for other learners)"),
    "policy_entropy": ("number", "SAC: mean -log pi(a|s) of the actor's sampled actions over this epoch's updates "
                                 "(absent for other learners)"),
    "q_real_mean": ("number", "mean critic Q(s, a) over this epoch's training rows that kept the episode's real goal "
                              "(absent if none, or in logs written before it was recorded)"),
    "q_hindsight_mean": ("number", "mean critic Q(s, a) over this epoch's training rows whose goal was relabelled "
                                   "(absent if none, or in logs written before it was recorded)"),
    **{f"{part}_{goal}_{stat}": ("integer" if stat == "count" else "number", f"bias evaluation ({goal} goals): {doc} "
                                 "(hersd/engine/bias.py; absent at epochs without one)")
       for goal in ("real", "hindsight", "moved")
       for part, stat, doc in (("bias", "mean", "mean of Q(s, pi(s, g), g) minus the policy's discounted return"),
                               ("bias", "std", "standard deviation of Q minus return"),
                               ("bias", "count", "(state, goal) pairs evaluated"),
                               ("return", "mean", "mean discounted return the policy obtains for g"))},
    "bias_hindsight_zero_share": ("number", "bias evaluation: share of the hindsight pairs whose return is exactly 0 "
                                            "(goals already achieved; hersd/engine/bias.py; absent at epochs without "
                                            "one)"),
    "bias_seconds": ("number", "seconds spent on the bias evaluation this epoch (absent at epochs without one)"),
}
# Fields a record may lack (absent from the message; read back as None): MEP's, SAC's, and those added
# after logs were first written.
OPTIONAL_EPOCH_FIELDS = tuple(name for name in EPOCH_FIELDS if name not in (
    "epoch", "relabel_rate", "test_success", "train_success", "q_mean", "q_std", "critic_loss", "actor_loss",
    "share_hindsight", "share_real_success", "share_real_failure", "env_steps", "updates", "episodes_stored",
    "rollout_seconds", "update_seconds", "eval_seconds", "epoch_seconds"))


def _object(properties: dict[str, Any], description: str, required: Iterable[str] = ()) -> dict[str, Any]:
    """A JSON-schema object of plain-typed properties (Foxglove's parser needs ``properties``, even empty)."""
    schema = {"type": "object", "description": description, "properties": properties}
    return schema | ({"required": list(required)} if required else {})


def _typed(kind: str, description: str) -> dict[str, Any]:
    return {"type": kind, "description": description}


EPOCH_SCHEMA_DICT = {"title": "hersd.Epoch", **_object(
    {name: _typed(kind, doc) for name, (kind, doc) in EPOCH_FIELDS.items()}, "one completed epoch",
    [name for name in EPOCH_FIELDS if name not in OPTIONAL_EPOCH_FIELDS])}

# name -> JSON schema of every field a /run/meta message may carry (those written before a field existed lack it).
META_FIELDS: dict[str, dict[str, Any]] = {
    "run_id": _typed("string", "the run's hash, hersd.contract.runstore.config_hash(config): its folder name's suffix"),
    "config": _object({}, "the resolved TrainConfig (hersd/contract/config.py) as nested objects, verbatim: its nulls "
                          "are settings left unset; hersd-train --help describes every key"),
    "seed": _typed("integer", "the run's seed"),
    "versions": _object({name: _typed("string", f"{name} version") for name in (
        "python", "hersd", "torch", "mujoco", "gymnasium", "gymnasium_robotics", "numpy")},
        "versions of the software that ran this session"),
    "git_commit": _typed("string", "the commit of the code that ran (-dirty: with uncommitted changes); "
                                   "absent outside a git checkout"),
    "command": _typed("string", "the command line of this session"),
    "start_time": _typed("string", "this session's start, local time, %Y-%m-%dT%H:%M:%S%z"),
    "resumed_from_epoch": _typed("integer", "epochs done before this session (0: the first session)"),
    "effective": _object({
        "horizon": _typed("integer", "steps per episode"),
        "gamma": _typed("number", "discount factor"),
        "q_target_range": {"type": "array", "items": {"type": "number"},
                           "description": "[low, high] clip of the critic's target Q (an infinite bound is null); "
                                          "absent without a clip"},
        "distance_threshold": _typed("number", "success radius of the task (absent if the env has none)"),
        "batch_size": _typed("integer", "minibatch size"),
        "env_steps_per_epoch": _typed("integer", "exploration steps per epoch"),
        "updates_per_epoch": _typed("integer", "gradient updates per epoch"),
        "updates_per_env_step": _typed("number", "gradient updates per exploration step"),
        "test_episodes_per_epoch": _typed("integer", "deterministic test episodes per epoch"),
        "buffer_episodes": _typed("integer", "replay buffer capacity in episodes")},
        "totals that make runs comparable whatever the worker layout "
        "(hersd.engine.run_state.RunState.effective_totals)"),
    "threads": _typed("integer", "torch threads of this session"),
    "device": _typed("string", "torch device of this session, e.g. cpu"),
    "machine": _object({
        "cpu_model": _typed("string", "CPU model name"),
        "cpu_cores": _typed("integer", "cores available to the process"),
        "machine": _typed("string", "machine architecture, e.g. x86_64"),
        "torch_cpu_capability": _typed("string", "instruction set torch's CPU kernels use, e.g. AVX2"),
        "cuda_device": _typed("string", "CUDA device name (absent without CUDA)")},
        "the machine of this session (hersd.engine.resources.machine_info)"),
}
META_REQUIRED = ("run_id", "config", "seed", "versions", "command", "start_time", "resumed_from_epoch")
META_NULLABLE = ("git_commit",)  # read back as None where absent, as the writer was given it
META_SCHEMA_DICT = {"title": "hersd.RunMeta", **_object(META_FIELDS, "one training session", META_REQUIRED)}
STATUS_SCHEMA_DICT = {"title": "hersd.RunStatus", **_object(
    {"status": _typed("string", "complete"), "end_time": _typed("string", "local time the run ended"),
     "epochs": _typed("integer", "epochs of the complete run")}, "the run's completion marker", ["status", "epochs"])}
EPOCH_SCHEMA, META_SCHEMA, STATUS_SCHEMA = (json.dumps(schema).encode() for schema in (
    EPOCH_SCHEMA_DICT, META_SCHEMA_DICT, STATUS_SCHEMA_DICT))
# topic -> (schema name, JSON schema), in the order of their channel ids
CHANNELS: dict[str, tuple[str, bytes]] = {"/run/meta": ("hersd.RunMeta", META_SCHEMA),
                                          "/epoch": ("hersd.Epoch", EPOCH_SCHEMA),
                                          "/run/status": ("hersd.RunStatus", STATUS_SCHEMA)}


def _json_safe(value: Any) -> Any:
    """NaN and infinities are not JSON: store them as null (then dropped where they are a field's value)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def _plain(value: Any, verbatim: bool = False) -> Any:
    """``value`` with every null-valued object key dropped, recursively; a top-level ``config`` is kept as is."""
    if isinstance(value, dict):
        return {k: v if verbatim and k == "config" else _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class LoggedMessage:
    """One message of a run log: its topic, times (ns since the Unix epoch) and JSON payload, nulls dropped."""

    topic: str
    log_time: int
    publish_time: int
    sequence: int
    payload: dict[str, Any]


def encode_log(messages: Iterable[LoggedMessage]) -> bytes:
    """``messages`` (in file order) as a complete MCAP file: chunked (one message per chunk, uncompressed),
    indexed, with statistics, summary and footer. The same messages always give the same bytes."""
    buffer = io.BytesIO()
    writer = Writer(buffer, chunk_size=1, compression=CompressionType.NONE)
    writer.start(profile="", library=LIBRARY)
    channels = {}
    for topic, (title, schema) in CHANNELS.items():
        schema_id = writer.register_schema(name=title, encoding="jsonschema", data=schema)
        channels[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
    for message in messages:
        writer.add_message(channel_id=channels[message.topic], log_time=message.log_time,
                           publish_time=message.publish_time, sequence=message.sequence,
                           data=json.dumps(message.payload).encode())
    writer.finish()
    return buffer.getvalue()


def temporary_file(path: Path) -> Path:
    """The temporary file :func:`replace_file` writes ``path`` through by default: ``<name>.tmp`` beside it."""
    return path.with_name(path.name + ".tmp")


def replace_file(path: Path, data: bytes, temporary: Path | None = None, sync: bool = True) -> None:
    """Write ``data`` to ``path`` atomically: a temporary file next to it (``<name>.tmp`` unless ``temporary`` is
    given), fsync, rename, fsync of the folder (both fsyncs left out with ``sync=False``, for files rewritten whole
    by the next command: a report's). A write that fails leaves ``path`` as it was and no temporary file; on a full
    disk it raises :class:`DiskFullError` (one line: the file, the bytes it needs, those free)."""
    temporary = temporary or temporary_file(path)
    try:
        with open(temporary, "wb") as stream:
            stream.write(data)
            stream.flush()
            if sync:
                os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException as err:
        temporary.unlink(missing_ok=True)
        if full_disk(err):
            raise DiskFullError(path, len(data)) from None
        raise
    if not sync:
        return
    folder = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(folder)
    finally:
        os.close(folder)


class RunLogWriter:
    """Writes one run's log to ``path``; after every message the file is a complete MCAP file on disk.

    ``previous`` (the log of a run being resumed) is carried over first: its sessions' metadata and
    the epochs in ``previous.epochs`` (a resume drops those after its checkpoint), with their original
    log times, so the new file holds the whole history. Each write replaces the file atomically
    (:func:`replace_file`): a crash at any moment leaves the last complete version.
    """

    def __init__(self, path: Path, meta: dict[str, Any], previous: "RunLog | None" = None) -> None:
        self.path = Path(path)
        self._messages: list[LoggedMessage] = _carried_over(previous) if previous is not None else []
        self._closed = self._deferred = False
        self._write("/run/meta", meta)

    def _write(self, topic: str, payload: dict[str, Any]) -> None:
        if self._closed:
            raise ValueError(f"{self.path}: the log writer is closed")
        now = time.time_ns()
        sequence = max((message.sequence for message in self._messages), default=0) + 1
        self._messages.append(LoggedMessage(topic, now, now, sequence, _plain(_json_safe(payload), verbatim=True)))
        if not self._deferred:
            replace_file(self.path, encode_log(self._messages))

    @contextmanager
    def batch(self) -> Iterator["RunLogWriter"]:
        """Messages written inside reach the disk together when it ends (one rewrite, not one per message):
        for logs written at once, e.g. test fixtures (analysis/synthetic.py)."""
        self._deferred = True
        try:
            yield self
        finally:
            self._deferred = False
            replace_file(self.path, encode_log(self._messages))

    def write_epoch(self, record: dict[str, Any]) -> None:
        missing = [name for name in EPOCH_FIELDS if name not in record and name not in OPTIONAL_EPOCH_FIELDS]
        if missing:
            raise ValueError(f"epoch record lacks fields: {missing}")
        self._write("/epoch", {name: record.get(name) for name in EPOCH_FIELDS})

    def finish(self, epochs: int) -> None:
        """Mark the run complete."""
        self._write("/run/status", {"status": "complete", "epochs": epochs,
                                    "end_time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
        self.close()

    def close(self) -> None:
        """No more messages (the file on disk is complete already)."""
        self._closed = True


def _carried_over(previous: "RunLog") -> list[LoggedMessage]:
    """The messages a resumed run's log starts with: every session's metadata and the last write of each epoch
    in ``previous.epochs``, in their file order, with their times."""
    kept = {int(epoch) for epoch in previous.epochs["epoch"]}
    if not previous.messages:  # a RunLog made by hand: its epochs, stamped now
        now = time.time_ns()
        rows = [{k: v for k, v in record.items() if k in EPOCH_FIELDS}
                for record in previous.epochs.to_dict("records")]
        payloads = [("/run/meta", session) for session in previous.sessions] + [("/epoch", row) for row in rows]
        return [LoggedMessage(topic, now, now, index + 1, _plain(_json_safe(payload), verbatim=True))
                for index, (topic, payload) in enumerate(payloads)]
    last = {message.payload["epoch"]: index for index, message in enumerate(previous.messages)
            if message.topic == "/epoch"}
    return [message for index, message in enumerate(previous.messages)
            if message.topic == "/run/meta"
            or (message.topic == "/epoch" and message.payload["epoch"] in kept
                and last[message.payload["epoch"]] == index)]


@dataclass
class RunRecords:
    """One run's messages as read back: ``records`` has one dict per completed epoch, in
    epoch order (for an epoch written twice, by a resumed run, the last write), with every
    :data:`EPOCH_FIELDS` key (None where the message lacks it); ``messages`` is every message
    as stored, in file order."""

    path: Path
    sessions: list[dict[str, Any]]
    records: list[dict[str, Any]]
    complete: bool
    # the file has no valid end (cut, a chunk failing its checksum, or an earlier-format log of a killed or running writer)
    damaged: bool
    messages: list[LoggedMessage] = field(default_factory=list)

    @property
    def meta(self) -> dict[str, Any]:
        """The first session's metadata."""
        return self.sessions[0]


@dataclass
class RunLog:
    """One run's log as read back, epochs as a DataFrame.

    ``epochs`` has one row per completed epoch (columns: :data:`EPOCH_FIELDS`), sorted by
    epoch; ``meta`` is the first session's metadata; ``sessions`` lists every session's;
    ``messages`` every message as stored (what a resume carries over).
    """

    path: Path
    meta: dict[str, Any]
    epochs: pd.DataFrame
    complete: bool
    sessions: list[dict[str, Any]] = field(default_factory=list)
    # the file has no valid end (cut, a chunk failing its checksum, or an earlier-format log of a killed or running writer)
    damaged: bool = False
    messages: list[LoggedMessage] = field(default_factory=list)


class RunLogError(ValueError):
    """The file is not a readable hersd run log."""


def log_path(path: str | Path) -> Path:
    """A run's log file from the file itself or the run's folder holding it."""
    path = Path(path)
    return path / LOG_NAME if path.is_dir() else path


def read_messages(path: str | Path) -> tuple[list[LoggedMessage], bool]:
    """Every readable message of a run log (``path``: the file, or the run's folder holding it) in file order
    (payload nulls dropped) and whether the file was damaged (no valid end, or a chunk whose checksum fails:
    the messages before the damage are returned)."""
    path = log_path(path)
    messages: list[LoggedMessage] = []
    damaged = False
    try:
        with open(path, "rb") as stream:
            try:
                reader = NonSeekingReader(stream, validate_crcs=True)
                for _schema, channel, message in reader.iter_messages(log_time_order=False):
                    if channel.topic in CHANNELS:
                        messages.append(LoggedMessage(channel.topic, message.log_time, message.publish_time,
                                                      message.sequence,
                                                      _plain(json.loads(message.data), verbatim=True)))
            except Exception:  # noqa: BLE001 - any decoding failure means the rest of the file is damaged
                damaged = True
    except OSError as err:
        raise RunLogError(f"{path}: cannot open ({err.strerror})") from None
    return messages, damaged


def read_records(path: str | Path) -> RunRecords:
    """Read a run log's messages (any format); a damaged file yields every epoch written before the damage."""
    path = log_path(path)
    messages, damaged = read_messages(path)
    sessions = [{**{name: None for name in META_NULLABLE}, **message.payload}
                for message in messages if message.topic == "/run/meta"]
    if not sessions:
        raise RunLogError(f"{path}: not a hersd run log (no run metadata found)")
    by_epoch = {message.payload["epoch"]: message.payload for message in messages if message.topic == "/epoch"}
    complete = any(message.payload.get("status") == "complete" for message in messages
                   if message.topic == "/run/status")
    records = [{**{name: None for name in EPOCH_FIELDS}, **by_epoch[k]} for k in sorted(by_epoch)]
    return RunRecords(path=path, sessions=sessions, records=records, complete=complete, damaged=damaged,
                      messages=messages)


def rewritten(path: str | Path) -> bytes:
    """The log at ``path`` (any format, damaged or not) in the current format: every readable message, in
    its order, with its times and sequence number (payload nulls dropped); unchanged bytes for a log in the
    current format."""
    records = read_records(path)
    return encode_log(records.messages)


def read_run(path: str | Path) -> RunLog:
    """Read a run log (the file, or the run's folder) into a DataFrame of its epochs (see :func:`read_records`)."""
    raw = read_records(path)
    epochs = pd.DataFrame.from_records(raw.records, columns=list(EPOCH_FIELDS))
    epochs = epochs.astype({name: "float64" for name, (kind, _) in EPOCH_FIELDS.items() if kind == "number"})
    epochs = epochs.astype({name: "int64" if name not in OPTIONAL_EPOCH_FIELDS else "float64"
                            for name, (kind, _) in EPOCH_FIELDS.items() if kind == "integer"})
    return RunLog(path=raw.path, meta=raw.meta, epochs=epochs, complete=raw.complete, sessions=raw.sessions,
                  damaged=raw.damaged, messages=raw.messages)
