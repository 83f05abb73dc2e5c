"""TensorBoard event files of a run, from its log: what ``tensorboard=true`` writes as a run trains and
``hersd-report FOLDER --tensorboard DIR`` writes from logs already made (docs/ANALYSIS.md, "TensorBoard").

One step per epoch k: every number of its ``/epoch`` record (:data:`hersd.contract.runlog.EPOCH_FIELDS`; the
bias evaluation's at the epochs that have one) as a scalar tagged ``<group>/<field>`` (:func:`epoch_tag`), with
the field's description: a float32, the one scalar type TensorBoard's default (Rust) loader reads, so the log's
value rounded to float32 (counts exact up to 2**24); at step 0 the run's first
session's settings (``/run/meta`` ``config``, flattened to dotted keys) as a text table ``settings`` and as
the hparams plugin's session start, so runs compare by setting. Files are written with the tensorboard
package's own ``EventFileWriter`` (no TensorFlow, no torch); the package is an optional extra, imported here
only when files are written: :func:`require_tensorboard` is the one-line error without it.

Writing a run's folder first removes the event files in it and writes the log's epochs so far, then
appends one step per epoch as each ends, flushed: a resumed run continues without a repeated or missing
step, a killed one leaves files readable up to its last logged epoch, and a conversion run twice replaces.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from hersd.contract.errors import ConfigError
from hersd.contract.runlog import EPOCH_FIELDS, RunRecords, read_records

EVENTS_DIR = "tensorboard"  # <run dir>/tensorboard/: a live run's event files, beside its run.mcap
EVENT_FILES = "events.out.tfevents.*"  # the names TensorBoard's writers give their files
SETTINGS_TAG = "settings"  # the text summary of the run's settings
UNWRITTEN_SETTINGS = ("results_dir", "run_dir")  # where a run was written, not what it is: left out of the hparams
# (group, field names ending so / starting so): the first that matches a field names its tag's group
GROUPS = (("time", ("_seconds",), ()), ("bias", (), ("bias_", "return_")),
          ("relabel", (), ("relabel_", "share_")), ("success", ("_success", "_distance"), ()),
          ("critic", ("_loss", "alpha", "policy_entropy"), ("q_",)))
OTHER_GROUP = "progress"  # env_steps, updates, episodes_stored, priority_entropy
INSTALL = 'pip install tensorboard (or pip install -e ".[tensorboard]")'


def require_tensorboard(asked_by: str = "tensorboard=true") -> None:
    """ConfigError (one line) unless the tensorboard package's writer imports."""
    try:
        from tensorboard.summary.writer.event_file_writer import EventFileWriter  # noqa: F401
    except ImportError:
        raise ConfigError(f"{asked_by} writes TensorBoard event files, but the tensorboard package is not "
                          f"installed: {INSTALL}, or leave it out") from None


def epoch_tag(name: str) -> str:
    """An /epoch field's scalar tag, ``<group>/<field>``: ``success/test_success``, ``time/epoch_seconds``."""
    for group, endings, starts in GROUPS:
        if name.endswith(endings or ("\0",)) or name.startswith(starts or ("\0",)):
            return f"{group}/{name}"
    return f"{OTHER_GROUP}/{name}"


def flat_settings(config: dict[str, Any], prefix: str = "") -> dict[str, bool | float | str]:
    """A log's nested config -> {dotted key: bool, number or string} (lists as JSON, null as ``null``)."""
    flat: dict[str, bool | float | str] = {}
    for key, value in config.items():
        if isinstance(value, dict):
            flat |= flat_settings(value, f"{prefix}{key}.")
        elif isinstance(value, (bool, int, float)) or value is None or isinstance(value, str):
            flat[f"{prefix}{key}"] = "null" if value is None else value
        else:
            flat[f"{prefix}{key}"] = json.dumps(value)
    return flat


class RunEvents:
    """One run's event files in ``folder``, started from its log (``records``): the files there removed, the
    settings and every logged epoch written; then :meth:`write_epoch` per epoch as it ends."""

    def __init__(self, folder: str | Path, records: RunRecords) -> None:
        require_tensorboard()
        from tensorboard.summary.writer.event_file_writer import EventFileWriter

        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        for old in self.folder.glob(EVENT_FILES):
            old.unlink()
        self._writer = EventFileWriter(str(self.folder), max_queue_size=1000, flush_secs=3600)
        self._described: set[str] = set()  # tags whose plugin metadata this file holds (written with a tag's first value)
        times = {message.payload["epoch"]: message.log_time / 1e9 for message in records.messages
                 if message.topic == "/epoch"}  # an epoch written twice (a resume): its last write
        start = next((message.log_time / 1e9 for message in records.messages), None)
        self._write_settings(records.meta["config"], start)
        for record in records.records:
            self.write_epoch(record, times.get(record["epoch"]), flush=False)
        self._writer.flush()

    def _add(self, values: list, step: int, wall_time: float | None) -> None:
        import time

        from tensorboard.compat.proto import event_pb2, summary_pb2

        self._writer.add_event(event_pb2.Event(wall_time=wall_time or time.time(), step=step,
                                               summary=summary_pb2.Summary(value=values)))

    def _write_settings(self, config: dict[str, Any], wall_time: float | None) -> None:
        """The settings at step 0: a markdown table (text plugin) and the hparams plugin's session start."""
        from tensorboard.compat.proto import summary_pb2
        from tensorboard.plugins.hparams import metadata, plugin_data_pb2
        from tensorboard.plugins.text.summary_v2 import text_pb

        settings = flat_settings(config)
        table = "| setting | value |\n| --- | --- |\n" + "".join(
            f"| {key} | {json.dumps(value) if isinstance(value, bool) else value} |\n"
            for key, value in settings.items())
        start = plugin_data_pb2.SessionStartInfo(start_time_secs=wall_time or 0.0)
        for key, value in settings.items():
            if key in UNWRITTEN_SETTINGS:
                continue
            if isinstance(value, bool):
                start.hparams[key].bool_value = value
            elif isinstance(value, (int, float)):
                start.hparams[key].number_value = value
            else:
                start.hparams[key].string_value = value
        content = plugin_data_pb2.HParamsPluginData(session_start_info=start, version=metadata.PLUGIN_DATA_VERSION)
        hparams = summary_pb2.Summary.Value(tag=metadata.SESSION_START_INFO_TAG, tensor=metadata.NULL_TENSOR,
                                            metadata=metadata.create_summary_metadata(content))
        self._add([*text_pb(SETTINGS_TAG, table).value, hparams], 0, wall_time)

    def write_epoch(self, record: dict[str, Any], wall_time: float | None = None, flush: bool = True) -> None:
        """Epoch ``record["epoch"]``'s step: a float32 scalar per number the record holds (None: not written)."""
        from tensorboard.compat.proto import summary_pb2, tensor_pb2, types_pb2
        from tensorboard.plugins.scalar.metadata import create_summary_metadata

        values = []
        for name in EPOCH_FIELDS:
            if name == "epoch" or record.get(name) is None:
                continue
            value = summary_pb2.Summary.Value(
                tag=epoch_tag(name), tensor=tensor_pb2.TensorProto(dtype=types_pb2.DT_FLOAT,
                                                                   float_val=[float(record[name])]))
            if name not in self._described:
                value.metadata.CopyFrom(create_summary_metadata(display_name=name, description=EPOCH_FIELDS[name][1]))
                self._described.add(name)
            values.append(value)
        self._add(values, int(record["epoch"]), wall_time)
        if flush:
            self._writer.flush()

    def close(self) -> None:
        self._writer.close()


def write_run_events(log: str | Path, folder: str | Path) -> int:
    """The event files of the run log ``log`` (its file or folder) in ``folder``, replacing any there;
    returns the epochs written."""
    records = read_records(log)
    events = RunEvents(folder, records)
    events.close()
    return len(records.records)
