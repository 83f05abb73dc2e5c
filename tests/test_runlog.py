"""Run logs open in third-party readers, complete, killed mid-run or still running.

- Node's official ``@mcap/core`` (from npm, via tests/mcap_readers.js) reads every committed log
  and a log killed mid-run with its indexed reader (McapIndexedReader) and its streaming reader
  (McapStreamReader) and sees every epoch. Needs ``node`` and ``npm`` (Debian: ``nodejs npm``);
  without them the test skips, with CI=true it fails. The packages are installed once into
  ``~/.cache/hersd/mcap-node``.
- Python's ``mcap.reader.make_reader`` (summary-based) reads a log whose writer was killed with
  SIGKILL at random moments: no acknowledged epoch is lost.
- Every schema uses only the JSON-schema types Foxglove's parser accepts (Lichtblick's
  ``parseJsonSchema.ts``: ``boolean``, ``string``, ``number``, ``integer``, ``object`` with
  ``properties``, ``array`` of those; no ``null``, no unions), and every field written is declared.
- Logs in the earlier format (unchunked, nullable types, no footer while running) read back,
  resume into the current format and convert with ``scripts/convert_logs.py``, every record identical.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from hersd.contract.runlog import CHANNELS, LIBRARY, META_FIELDS, RunLogError, RunLogWriter, read_records, read_run, rewritten
from runlogs import META, epoch_record, write_old_format
from servers import unavailable

REPOSITORY = Path(__file__).resolve().parent.parent
COMMITTED = sorted((REPOSITORY / "results").rglob("run.mcap"))
NODE_PACKAGES = ("@mcap/core@2.2.2", "@mcap/nodejs@1.0.2")
FOXGLOVE_TYPES = {"boolean", "string", "number", "integer", "object", "array"}
FOXGLOVE_ITEM_TYPES = {"boolean", "string", "number", "integer", "object"}

sys.path.insert(0, str(REPOSITORY / "scripts"))
import convert_logs  # noqa: E402  (scripts/ is not a package)


# --------------------------------------------------------------------------- logs to read
WRITER = f"""
import sys
from pathlib import Path
sys.path.insert(0, {str(Path(__file__).parent)!r})
from runlogs import META, epoch_record
from hersd.contract.runlog import RunLogWriter
writer = RunLogWriter(Path(sys.argv[1]), META)
for epoch in range(1, 100000):
    writer.write_epoch(epoch_record(epoch))
    print(epoch, flush=True)
"""


def killed_log(path: Path, after: int, rng: random.Random) -> int:
    """Write a log in a subprocess and SIGKILL it a random moment after it acknowledged ``after`` epochs
    -> the last epoch it acknowledged (the file may hold more)."""
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True,
                            cwd=REPOSITORY)
    acknowledged = 0
    for line in proc.stdout:
        acknowledged = int(line)
        if acknowledged >= after:
            break
    time.sleep(rng.uniform(0, 0.01))  # lands anywhere in the next epoch's rewrite
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return acknowledged


# --------------------------------------------------------------------------- @mcap/core (Node)
@pytest.fixture(scope="module")
def node_path() -> str:
    """NODE_PATH of @mcap/core and @mcap/nodejs, installed with npm once into ~/.cache/hersd/mcap-node."""
    missing = [name for name in ("node", "npm") if shutil.which(name) is None]
    if missing:
        unavailable(f"{', '.join(missing)} not found; install the Debian packages: apt-get install nodejs npm")
    folder = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hersd" / "mcap-node"
    modules = folder / "node_modules"
    if not all((modules / package.rsplit("@", 1)[0] / "package.json").exists() for package in NODE_PACKAGES):
        folder.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(["npm", "install", "--prefix", str(folder), "--no-audit", "--no-fund",
                               "--no-save", *NODE_PACKAGES], capture_output=True, text=True, timeout=600)
        if done.returncode:
            unavailable(f"npm install {' '.join(NODE_PACKAGES)} failed: {done.stderr.strip()[-300:]}")
    return str(modules)


def read_with_mcap_core(node_path: str, paths: list[Path]) -> dict[str, dict]:
    done = subprocess.run(["node", str(Path(__file__).with_name("mcap_readers.js")), *map(str, paths)],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "NODE_PATH": node_path})
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_mcap_core_reads_every_committed_log_and_a_killed_one_indexed_and_streaming(node_path, tmp_path):
    assert COMMITTED, "no committed logs under results/"
    killed = tmp_path / "killed" / "run.mcap"
    killed.parent.mkdir()
    acknowledged = killed_log(killed, 12, random.Random(0))
    results = read_with_mcap_core(node_path, [*COMMITTED, killed])
    wrong = []
    for path in [*COMMITTED, killed]:
        records = read_records(path)
        epochs = [record["epoch"] for record in records.records]
        expected = {"/run/meta": len(records.sessions)} | ({"/epoch": len(epochs)} if epochs else {}) | (
            {"/run/status": 1} if records.complete else {})  # a topic without messages is not counted
        for reader in ("indexed", "stream"):
            got = results[str(path)][reader]
            if got.get("error") or got["topics"] != expected or sorted(got["epochs"]) != epochs:
                shown = got.get("error") or f"topics {got['topics']}, expected {expected}"
                wrong.append(f"{path.relative_to(REPOSITORY) if path.is_relative_to(REPOSITORY) else 'killed'}: "
                             f"{reader}: {shown}")
    assert not wrong, "\n".join(wrong)
    assert len(read_records(killed).records) >= acknowledged


# --------------------------------------------------------------------------- kill -9
def test_kill_9_at_random_moments_loses_no_acknowledged_epoch(tmp_path):
    """The summary-based reader (make_reader) opens the file after each kill and sees every epoch acknowledged."""
    rng = random.Random(1)
    for attempt in range(6):
        path = tmp_path / f"run{attempt}" / "run.mcap"
        path.parent.mkdir()
        acknowledged = killed_log(path, rng.randint(1, 30), rng)
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            assert reader.get_header().library == LIBRARY
            epochs = [json.loads(message.data)["epoch"] for _, _, message in reader.iter_messages(topics=["/epoch"])]
            assert reader.get_summary().statistics.message_count == len(epochs) + 1
        assert epochs == list(range(1, len(epochs) + 1)) and len(epochs) >= acknowledged
        assert not read_records(path).damaged


# --------------------------------------------------------------------------- schemas
def foxglove_rejects(schema: dict, where: str) -> list[str]:
    """What Foxglove's JSON-schema parser would refuse in ``schema`` (an object schema), one line each."""
    if schema.get("type") != "object" or not isinstance(schema.get("properties"), dict):
        return [f"{where}: not an object with properties"]
    problems = []
    for name, field in schema["properties"].items():
        kind = field.get("type")
        if not isinstance(kind, str) or kind not in FOXGLOVE_TYPES:
            problems.append(f"{where}.{name}: type {json.dumps(kind)}")
        elif kind == "string" and field.get("contentEncoding") not in (None, "base64"):
            problems.append(f"{where}.{name}: contentEncoding {field['contentEncoding']}")
        elif kind == "object":
            problems += foxglove_rejects(field, f"{where}.{name}")
        elif kind == "array":
            items = field.get("items") or {}
            if not isinstance(items.get("type"), str) or items["type"] not in FOXGLOVE_ITEM_TYPES:
                problems.append(f"{where}.{name}[]: item type {json.dumps(items.get('type'))}")
            elif items["type"] == "object":
                problems += foxglove_rejects(items, f"{where}.{name}[]")
    return problems


def test_every_schema_uses_only_types_foxglove_accepts():
    problems = [line for topic, (_, schema) in CHANNELS.items() for line in foxglove_rejects(json.loads(schema), topic)]
    for path in COMMITTED:
        shown = path.relative_to(REPOSITORY)
        try:
            with open(path, "rb") as stream:
                summary = make_reader(stream).get_summary()
        except Exception as err:  # noqa: BLE001  (a log without footer or summary)
            problems.append(f"{shown}: no summary ({type(err).__name__})")
            continue
        problems += [f"{shown}: {line}" for schema in summary.schemas.values()
                     for line in foxglove_rejects(json.loads(schema.data), schema.name)]
    assert not problems, "\n".join(problems)
    assert foxglove_rejects({"type": "object", "properties": {"x": {"type": ["number", "null"]}}}, "t") == [
        't.x: type ["number", "null"]']  # what Foxglove refused in the earlier format


def undeclared(value: dict, schema: dict, where: str) -> list[str]:
    """Keys of ``value`` its schema does not declare, and null field values (an object's nulls are missing keys)."""
    problems = []
    for key, item in value.items():
        field = schema["properties"].get(key)
        if field is None:
            problems.append(f"{where}.{key}: not declared")
        elif item is None:
            problems.append(f"{where}.{key}: null")
        elif field.get("type") == "object" and field.get("properties"):
            problems += undeclared(item, field, f"{where}.{key}")
    return problems


def test_every_field_a_committed_log_holds_is_declared_and_none_is_null():
    problems = []
    for path in COMMITTED:
        with open(path, "rb") as stream:
            for schema, channel, message in make_reader(stream).iter_messages():
                shown = f"{path.relative_to(REPOSITORY)}: {channel.topic}"
                problems += undeclared(json.loads(message.data), json.loads(schema.data), shown)
    assert not problems, "\n".join(sorted(set(problems))[:20])
    assert set(META_FIELDS) >= set(META)


# --------------------------------------------------------------------------- old format, resume, conversion
def messages_as_stored(path: Path) -> list[tuple]:
    """(topic, log_time, publish_time, sequence, payload with null object keys dropped) of every message."""
    return [(m.topic, m.log_time, m.publish_time, m.sequence, m.payload) for m in read_records(path).messages]


def test_a_run_is_read_by_its_folder_as_by_its_log(tmp_path):
    log = COMMITTED[0]
    by_folder, by_file = read_run(log.parent), read_run(log)
    assert by_folder.path == by_file.path == log
    assert by_folder.epochs.equals(by_file.epochs) and len(by_folder.epochs) > 0
    with pytest.raises(RunLogError, match=f"^{tmp_path / 'run.mcap'}: cannot open \\(No such file or directory\\)$"):
        read_run(tmp_path)


def test_old_format_logs_read_resume_and_convert_with_every_record_identical(tmp_path, capsys):
    complete, running = tmp_path / "a" / "run.mcap", tmp_path / "b" / "run.mcap"
    for path in (complete, running):
        path.parent.mkdir()
    write_old_format(complete, 6, complete=True, sessions=2)
    write_old_format(running, 5, complete=False)
    before = {path: (read_records(path), messages_as_stored(path), path.read_bytes()) for path in (complete, running)}
    assert before[running][0].damaged and not before[complete][0].damaged
    assert before[complete][0].records[0]["bias_real_mean"] is None and before[complete][0].meta["git_commit"] is None

    # a run in progress under the old writer resumes under this one: the earlier messages keep content and times
    resumed = tmp_path / "c" / "run.mcap"
    resumed.parent.mkdir()
    shutil.copy(running, resumed)
    previous = read_run(resumed)
    writer = RunLogWriter(resumed, {**META, "resumed_from_epoch": 5}, previous=previous)
    writer.write_epoch(epoch_record(6))
    writer.finish(6)
    after = messages_as_stored(resumed)
    assert after[:6] == before[running][1] and [m[0] for m in after[6:]] == ["/run/meta", "/epoch", "/run/status"]
    assert read_records(resumed).records[:5] == before[running][0].records
    with open(resumed, "rb") as stream:
        assert len(list(make_reader(stream).iter_messages(topics=["/epoch"]))) == 6

    # conversion: every message identical in content, times and order; a second pass changes nothing
    assert convert_logs.main([str(tmp_path)]) == 0
    first = capsys.readouterr().out
    for path in (complete, running):
        records = read_records(path)
        assert messages_as_stored(path) == before[path][1] and not records.damaged
        assert (records.sessions, records.records, records.complete) == (
            before[path][0].sessions, before[path][0].records, before[path][0].complete)
        assert path.read_bytes() == rewritten(path) != before[path][2]
    converted = {path: path.read_bytes() for path in (complete, running, resumed)}
    assert convert_logs.main([str(tmp_path)]) == 0
    assert {path: path.read_bytes() for path in converted} == converted
    second = capsys.readouterr().out
    assert first.count("converted") == 2 and second.count("unchanged") == 3 and "converted" not in second


def test_converting_what_is_no_folder_is_one_line_and_exit_2(tmp_path, capsys):
    """A mistyped folder (or a log given as a folder) converts nothing: it says so, not a silent success."""
    log = tmp_path / "run.mcap"
    write_old_format(log, 2, complete=True)
    for wrong in (tmp_path / "nowhere", log):
        with pytest.raises(SystemExit) as stop:
            convert_logs.main([str(tmp_path), str(wrong)])
        assert stop.value.code == 2
        assert capsys.readouterr().err == f"scripts/convert_logs.py: error: no folder {wrong}\n"
    assert log.read_bytes() != rewritten(log)  # nothing converted before the refusal


def test_a_resume_keeps_the_log_times_of_earlier_epochs(tmp_path):
    path = tmp_path / "run.mcap"
    writer = RunLogWriter(path, META)
    for epoch in (1, 2, 3):
        writer.write_epoch(epoch_record(epoch))
    writer.close()
    first = messages_as_stored(path)
    previous = read_run(path)
    previous.epochs = previous.epochs[previous.epochs["epoch"] <= 2]  # the checkpoint was at epoch 2
    writer = RunLogWriter(path, {**META, "resumed_from_epoch": 2}, previous=previous)
    writer.write_epoch(epoch_record(3))
    after = messages_as_stored(path)
    assert after[:3] == first[:3] and after[3][0] == "/run/meta" and after[4][1] > first[3][1]
    assert [record["epoch"] for record in read_records(path).records] == [1, 2, 3]


class StopHere(Exception):
    pass


def test_a_run_stopped_under_the_earlier_format_resumes_into_the_current_one(tmp_path):
    """A training run whose log is in the earlier format (killed: no footer) resumes with the current hersd:
    the log becomes the current format with every earlier message identical in content and times."""
    from hersd.contract.compose import compose_train
    from hersd.engine.train import train

    args = ["task=reach", "task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1",
            "ddpg.batch_size=64", "epochs=3", "quiet=true", "threads=1", "render_every=0", "bias.epochs=[]",
            f"results_dir={tmp_path}"]

    def stop(record):
        if record["epoch"] == 2:
            raise StopHere

    with pytest.raises(StopHere):
        train(compose_train(args), on_epoch=stop)
    path = next(tmp_path.rglob("run.mcap"))
    stored = read_records(path).messages
    write_old_format(path, 0, complete=False, messages=[(m.topic, m.log_time, m.payload) for m in stored])
    before = read_records(path)
    assert before.damaged and len(before.records) == 2
    assert train(compose_train(args)) == path
    after = read_records(path)
    assert after.complete and not after.damaged and [r["epoch"] for r in after.records] == [1, 2, 3]
    assert [(m.topic, m.log_time, m.payload) for m in after.messages[:3]] == [
        (m.topic, m.log_time, m.payload) for m in before.messages]
    assert after.records[:2] == before.records and after.sessions[1]["resumed_from_epoch"] == 2
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().library == LIBRARY and reader.get_summary().statistics.message_count == 6


def test_truncated_log_reads_back_its_complete_epochs(tmp_path, tiny):
    import pandas as pd

    from hersd.contract.compose import compose_train
    from hersd.engine.train import train

    log_path = train(compose_train([*tiny, "threads=1", "epochs=3"]))
    data = log_path.read_bytes()
    full = read_run(log_path)
    # cut inside the last epoch's record: the status message and footer follow it
    cut = log_path.with_name("cut.mcap")
    last_epoch_at = data.rfind(b'{"epoch": 3')
    cut.write_bytes(data[:last_epoch_at + 20])
    damaged = read_run(cut)
    assert damaged.damaged and not damaged.complete
    pd.testing.assert_frame_equal(damaged.epochs, full.epochs.iloc[:2])


def test_log_is_standard_mcap_whose_messages_follow_their_json_schemas(tmp_path, tiny):
    """Generic MCAP readers (summary-based, not hersd's) read the log; every message validates."""
    import jsonschema

    from hersd.contract.compose import compose_train
    from hersd.engine.train import train

    log_path = train(compose_train([*tiny, "threads=1", "epochs=2"]))
    with open(log_path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 4  # meta, 2 epochs, status
        topics = []
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            topics.append(channel.topic)
    assert topics == ["/run/meta", "/epoch", "/epoch", "/run/status"]
