"""The run log: one MCAP file per training run, the contract between training and analysis.

Channels (all JSON, each with a JSON schema so any MCAP tool can read them):

- ``/run/meta``   one message per session (the first start, then one per resume): the
  resolved config, seed, versions, git commit, command line, start time, and
  ``resumed_from_epoch`` (0 for the first session);
- ``/epoch``      one message per completed epoch (fields: :data:`EPOCH_FIELDS`);
- ``/run/status`` ``{"status": "complete", ...}`` once the last epoch is written.

The writer does not chunk and flushes after every message, so a killed run leaves a
file whose every completed epoch reads back (:func:`read_run` stops at the damage).
This module needs only the standard library, mcap and pandas: reports are made without
torch or MuJoCo.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import pandas as pd
from mcap.reader import NonSeekingReader
from mcap.writer import Writer

LOG_NAME = "run.mcap"

# name -> (JSON type, description). Optional fields (MEP) may be null.
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
    "mep_fit_seconds": ("number", "seconds spent fitting the MEP density model (null without MEP)"),
    "priority_entropy": ("number", "entropy of the episode sampling distribution in nats (null without MEP)"),
    "test_distance": ("number", "mean distance ||achieved - desired goal|| at the last step of the test episodes "
                                "(in the goal's units; null in logs written before it was recorded)"),
    "alpha": ("number", "SAC's entropy temperature at the end of the epoch (null for other learners)"),
    "policy_entropy": ("number", "SAC: mean -log pi(a|s) of the actor's sampled actions over this epoch's updates "
                                 "(null for other learners)"),
    "q_real_mean": ("number", "mean critic Q(s, a) over this epoch's training rows that kept the episode's real goal "
                              "(null if none, or in logs written before it was recorded)"),
    "q_hindsight_mean": ("number", "mean critic Q(s, a) over this epoch's training rows whose goal was relabelled "
                                   "(null if none, or in logs written before it was recorded)"),
    **{f"{part}_{goal}_{stat}": ("integer" if stat == "count" else "number", f"bias evaluation ({goal} goals): {doc} "
                                 "(hersd/bias.py; null at epochs without one)")
       for goal in ("real", "hindsight")
       for part, stat, doc in (("bias", "mean", "mean of Q(s, pi(s, g), g) minus the policy's discounted return"),
                               ("bias", "std", "standard deviation of Q minus return"),
                               ("bias", "count", "(state, goal) pairs evaluated"),
                               ("return", "mean", "mean discounted return the policy obtains for g"))},
    "bias_seconds": ("number", "seconds spent on the bias evaluation this epoch (null at epochs without one)"),
}
# Fields a record may lack (logged as null): MEP's, SAC's, and those added after logs were first written.
OPTIONAL_EPOCH_FIELDS = tuple(name for name in EPOCH_FIELDS if name not in (
    "epoch", "relabel_rate", "test_success", "train_success", "q_mean", "q_std", "critic_loss", "actor_loss",
    "share_hindsight", "share_real_success", "share_real_failure", "env_steps", "updates", "episodes_stored",
    "rollout_seconds", "update_seconds", "eval_seconds", "epoch_seconds"))


def _schema(title: str, properties: dict[str, Any], required: Iterable[str]) -> bytes:
    return json.dumps({"title": title, "type": "object", "properties": properties,
                       "required": list(required)}).encode()


EPOCH_SCHEMA = _schema(
    "hersd.Epoch",
    {name: {"type": [kind, "null"] if name in OPTIONAL_EPOCH_FIELDS else kind, "description": doc}
     for name, (kind, doc) in EPOCH_FIELDS.items()},
    [name for name in EPOCH_FIELDS if name not in OPTIONAL_EPOCH_FIELDS],
)
META_SCHEMA = _schema(
    "hersd.RunMeta",
    {"run_id": {"type": "string"}, "config": {"type": "object"}, "seed": {"type": "integer"},
     "versions": {"type": "object"}, "git_commit": {"type": ["string", "null"]},
     "command": {"type": "string"}, "start_time": {"type": "string"},
     "resumed_from_epoch": {"type": "integer"}, "effective": {"type": "object"}},
    ["run_id", "config", "seed", "versions", "command", "start_time", "resumed_from_epoch"],
)
STATUS_SCHEMA = _schema(
    "hersd.RunStatus",
    {"status": {"type": "string"}, "end_time": {"type": "string"}, "epochs": {"type": "integer"}},
    ["status", "epochs"],
)


def _json_safe(value: Any) -> Any:
    """NaN and infinities are not JSON: store them as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


class RunLogWriter:
    """Appends one run's messages to ``path``; every message is flushed to disk at once.

    ``previous_epochs`` (from a run being resumed) are written first, after the sessions'
    metadata, so the new file holds the whole history. The file is built under a
    temporary name and renamed into place, so the old log survives a crash mid-copy.
    """

    def __init__(self, path: Path, meta: dict[str, Any], previous: "RunLog | None" = None) -> None:
        self.path = Path(path)
        tmp_path = self.path.with_name(self.path.name + ".tmp")
        self._file = open(tmp_path, "wb")
        self._writer = Writer(self._file, use_chunking=False)
        self._writer.start(profile="", library="hersd")
        self._channels = {}
        for topic, title, schema in (("/run/meta", "hersd.RunMeta", META_SCHEMA),
                                     ("/epoch", "hersd.Epoch", EPOCH_SCHEMA),
                                     ("/run/status", "hersd.RunStatus", STATUS_SCHEMA)):
            schema_id = self._writer.register_schema(name=title, encoding="jsonschema", data=schema)
            self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json",
                                                                  schema_id=schema_id)
        self._sequence = 0
        if previous is not None:
            for session in previous.sessions:
                self._write("/run/meta", session)
            for record in previous.epochs.to_dict("records"):
                self._write("/epoch", {k: v for k, v in record.items() if k in EPOCH_FIELDS})
        self._write("/run/meta", meta)
        os.replace(tmp_path, self.path)

    def _write(self, topic: str, payload: dict[str, Any]) -> None:
        now = time.time_ns()
        self._sequence += 1
        self._writer.add_message(channel_id=self._channels[topic], log_time=now, publish_time=now,
                                 sequence=self._sequence, data=json.dumps(_json_safe(payload)).encode())
        self._file.flush()
        os.fsync(self._file.fileno())

    def write_epoch(self, record: dict[str, Any]) -> None:
        missing = [name for name in EPOCH_FIELDS if name not in record and name not in OPTIONAL_EPOCH_FIELDS]
        if missing:
            raise ValueError(f"epoch record lacks fields: {missing}")
        self._write("/epoch", {name: record.get(name) for name in EPOCH_FIELDS})

    def finish(self, epochs: int) -> None:
        """Mark the run complete and close the file with a valid MCAP footer."""
        self._write("/run/status", {"status": "complete", "epochs": epochs,
                                    "end_time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
        self.close()

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()


@dataclass
class RunRecords:
    """One run's messages as read back: ``records`` has one dict per completed epoch, in
    epoch order (for an epoch written twice, by a resumed run, the last write)."""

    path: Path
    sessions: list[dict[str, Any]]
    records: list[dict[str, Any]]
    complete: bool
    damaged: bool  # the file has no valid end (a killed or still-running writer); complete epochs are kept

    @property
    def meta(self) -> dict[str, Any]:
        """The first session's metadata."""
        return self.sessions[0]


@dataclass
class RunLog:
    """One run's log as read back, epochs as a DataFrame.

    ``epochs`` has one row per completed epoch (columns: :data:`EPOCH_FIELDS`), sorted by
    epoch; ``meta`` is the first session's metadata; ``sessions`` lists every session's.
    """

    path: Path
    meta: dict[str, Any]
    epochs: pd.DataFrame
    complete: bool
    sessions: list[dict[str, Any]] = field(default_factory=list)
    damaged: bool = False  # the file has no valid end (a killed or still-running writer); complete epochs are kept


class RunLogError(ValueError):
    """The file is not a readable hersd run log."""


def read_records(path: str | Path) -> RunRecords:
    """Read a run log's messages; a truncated file yields every epoch written before the damage."""
    path = Path(path)
    sessions: list[dict[str, Any]] = []
    by_epoch: dict[int, dict[str, Any]] = {}
    complete = damaged = False
    try:
        with open(path, "rb") as stream:
            try:
                for _schema_record, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                    payload = json.loads(message.data)
                    if channel.topic == "/epoch":
                        by_epoch[payload["epoch"]] = payload
                    elif channel.topic == "/run/meta":
                        sessions.append(payload)
                    elif channel.topic == "/run/status":
                        complete = payload.get("status") == "complete"
            except Exception:  # noqa: BLE001 - any decoding failure means the rest of the file is damaged
                damaged = True
    except OSError as err:
        raise RunLogError(f"{path}: cannot open ({err.strerror})") from None
    if not sessions:
        raise RunLogError(f"{path}: not a hersd run log (no run metadata found)")
    return RunRecords(path=path, sessions=sessions, records=[by_epoch[k] for k in sorted(by_epoch)],
                      complete=complete, damaged=damaged)


def read_run(path: str | Path) -> RunLog:
    """Read a run log into a DataFrame of its epochs (see :func:`read_records`)."""
    raw = read_records(path)
    epochs = pd.DataFrame.from_records(raw.records, columns=list(EPOCH_FIELDS))
    epochs = epochs.astype({name: "float64" for name, (kind, _) in EPOCH_FIELDS.items() if kind == "number"})
    epochs = epochs.astype({name: "int64" if name not in OPTIONAL_EPOCH_FIELDS else "float64"
                            for name, (kind, _) in EPOCH_FIELDS.items() if kind == "integer"})
    return RunLog(path=raw.path, meta=raw.meta, epochs=epochs, complete=raw.complete, sessions=raw.sessions,
                  damaged=raw.damaged)
