"""Run logs written by hand for the run log's tests (tests/test_runlog.py, tests/test_land.py): the
metadata and an epoch record with every field, and a log in the earlier format."""

from __future__ import annotations

import json
from pathlib import Path

from mcap.writer import Writer

from hersd.contract.runlog import EPOCH_FIELDS, OPTIONAL_EPOCH_FIELDS

META = {"run_id": "0badcafe", "config": {"seed": 0, "schedule": {"mean_rate": None}}, "seed": 0,
        "versions": {"hersd": "test"}, "git_commit": None, "command": "test", "start_time": "2026-01-01T00:00:00+0000",
        "resumed_from_epoch": 0, "threads": 1, "device": "cpu",
        "machine": {"cpu_model": "test", "cpu_cores": 1, "machine": "x86_64", "cuda_device": None}}


def epoch_record(epoch: int) -> dict:
    """A record with every required field, MEP's fields None and a bias evaluation at even epochs."""
    record = {name: (epoch if kind == "integer" else epoch / 1000) for name, (kind, _) in EPOCH_FIELDS.items()
              if name not in OPTIONAL_EPOCH_FIELDS}
    record |= {"mep_fit_seconds": None, "priority_entropy": None, "test_distance": 0.25}
    if epoch % 2 == 0:
        record |= {"bias_real_mean": 1.5, "bias_real_count": 100, "bias_seconds": 0.5}
    return record


def write_old_format(path: Path, epochs: int, complete: bool, sessions: int = 1,
                     messages: list[tuple[str, int, dict]] | None = None) -> None:
    """A log as hersd wrote it before this format: unchunked, nullable types, nulls stored, every message
    flushed, no footer while running (``complete=False``: the writer was killed). ``messages``
    ((topic, log_time, payload) each, e.g. a real run's) replace the made-up ones."""
    nullable = {"title": "hersd.Epoch", "type": "object", "properties": {
        name: {"type": [kind, "null"] if name in OPTIONAL_EPOCH_FIELDS else kind} for name, (kind, _) in
        EPOCH_FIELDS.items()}}
    stream = open(path, "wb")
    writer = Writer(stream, use_chunking=False)
    writer.start(profile="", library="hersd")
    channels = {}
    for topic, schema in (("/run/meta", {"title": "hersd.RunMeta", "type": "object", "properties": {
            "git_commit": {"type": ["string", "null"]}}}), ("/epoch", nullable), ("/run/status", {"type": "object"})):
        schema_id = writer.register_schema(name=topic, encoding="jsonschema", data=json.dumps(schema).encode())
        channels[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
    payloads = [("/run/meta", {**META, "resumed_from_epoch": 2 * s}) for s in range(sessions)]
    payloads += [("/epoch", {name: epoch_record(k).get(name) for name in EPOCH_FIELDS}) for k in range(1, epochs + 1)]
    payloads += [("/run/status", {"status": "complete", "epochs": epochs, "end_time": "x"})] if complete else []
    timed = [(topic, 1_000 * sequence, payload) for sequence, (topic, payload) in enumerate(payloads, start=1)]
    for sequence, (topic, log_time, payload) in enumerate(timed if messages is None else messages, start=1):
        if topic == "/epoch":
            payload = {name: payload.get(name) for name in EPOCH_FIELDS}  # nulls stored, as then
        writer.add_message(channel_id=channels[topic], log_time=log_time, publish_time=log_time,
                           sequence=sequence, data=json.dumps(payload).encode())
    stream.flush()
    if complete:
        writer.finish()
    stream.close()
