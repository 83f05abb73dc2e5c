"""TensorBoard event files (hersd/contract/tensorboard_events.py, analysis/tensorboard_export.py): read back with
TensorBoard's own EventAccumulator, every /epoch field of a run at its step, live, after a kill and resume, and
converted from committed logs; the setting without the package, one line and exit 2."""

import json
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY, train_killed_at_epoch
from tensorboard.backend.event_processing import event_accumulator
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
from tensorboard.backend.event_processing.plugin_event_multiplexer import EventMultiplexer
from tensorboard.plugins.hparams import metadata as hparams_metadata
from tensorboard.plugins.hparams import plugin_data_pb2
from tensorboard.util import tensor_util

from analysis.load import find_logs
from analysis.report import main as report_main
from analysis.tensorboard_export import MANIFEST
from hersd.contract.compose import compose_train as compose
from hersd.contract.runlog import read_records
from hersd.contract.runstore import config_hash
from hersd.contract.tensorboard_events import EVENT_FILES, EVENTS_DIR, SETTINGS_TAG, epoch_tag, flat_settings
from hersd.engine.cli import main as train_main
from hersd.engine.train import train

RESULTS = Path(__file__).resolve().parent.parent / "results"
# A short FetchReach run with a bias evaluation after epoch 2 (its fields appear at that step only).
SHORT = [*TINY, "quiet=true", "threads=1", "tensorboard=true", "bias.epochs=[2]", "bias.episodes=1",
         "bias.hindsight_pairs=2", "bias.moved_pairs=2", "bias.return_steps=60"]


def logged_values(folder: Path) -> dict[str, dict[int, float]]:
    """{tag: {step: value}} of every scalar in a folder's event files, as TensorBoard's EventAccumulator reads them."""
    accumulator = event_accumulator.EventAccumulator(str(folder), size_guidance={event_accumulator.TENSORS: 0})
    accumulator.Reload()
    return {tag: {event.step: tensor_util.make_ndarray(event.tensor_proto).item()
                  for event in accumulator.Tensors(tag)}
            for tag in accumulator.Tags()["tensors"] if tag not in (SETTINGS_TAG, hparams_metadata.SESSION_START_INFO_TAG)}


def written_steps(folder: Path) -> Counter:
    """How often each (tag, step) was written, over every event file in ``folder`` (the raw records, unpurged)."""
    counts: Counter = Counter()
    for path in sorted(folder.glob(EVENT_FILES)):
        for event in EventFileLoader(str(path)).Load():
            counts.update((value.tag, event.step) for value in event.summary.value)
    return counts


def assert_holds_the_log(folder: Path, records: list[dict]) -> None:
    """Every number of every /epoch record at its step, as float32 (TensorBoard's scalar type), written once,
    and nothing else but the settings at step 0."""
    expected = {(epoch_tag(name), record["epoch"]): np.float32(value) for record in records
                for name, value in record.items() if name != "epoch" and value is not None}
    found = {(tag, step): value for tag, steps in logged_values(folder).items() for step, value in steps.items()}
    assert found.keys() == expected.keys()
    assert all(np.float32(found[key]) == expected[key] for key in expected), \
        [(key, found[key], expected[key]) for key in expected if np.float32(found[key]) != expected[key]]
    counts = written_steps(folder)
    assert set(counts.values()) == {1}, [key for key, count in counts.items() if count > 1]
    assert set(counts) - set(expected) == {(SETTINGS_TAG, 0), (hparams_metadata.SESSION_START_INFO_TAG, 0)}


def hparams(folder: Path) -> dict:
    """The hparams plugin's session start of the folder's run: {name: value}."""
    accumulator = event_accumulator.EventAccumulator(str(folder))
    accumulator.Reload()
    content = accumulator.SummaryMetadata(hparams_metadata.SESSION_START_INFO_TAG).plugin_data.content
    start = plugin_data_pb2.HParamsPluginData.FromString(content).session_start_info
    return {name: getattr(value, value.WhichOneof("kind")) for name, value in start.hparams.items()}


def test_a_short_run_writes_every_epoch_field_at_its_step(tmp_path):
    cfg = compose([*SHORT, "epochs=3", f"results_dir={tmp_path}"])
    log = train(cfg)
    records = read_records(log)
    assert records.records[1]["bias_real_mean"] is not None and records.records[0]["bias_real_mean"] is None
    folder = log.parent / EVENTS_DIR
    assert_holds_the_log(folder, records.records)
    assert "success/test_success" in logged_values(folder) and "bias/bias_real_mean" in logged_values(folder)
    settings = hparams(folder)
    assert settings["task.name"] == "reach" and settings["epochs"] == 3 and settings["tensorboard"] is True
    assert settings["bias.epochs"] == "[2]" and "results_dir" not in settings


def test_tensorboard_true_on_a_complete_run_writes_its_event_files_from_the_log(tmp_path, capsys):
    """It said "nothing to do" and wrote none."""
    log = train(compose([*SHORT, "epochs=2", "tensorboard=false", "quiet=false", f"results_dir={tmp_path}"]))
    assert not (log.parent / EVENTS_DIR).exists()
    train(compose([*SHORT, "epochs=2", "quiet=false", f"results_dir={tmp_path}"]))
    assert f"already complete (2 epochs), its TensorBoard event files written to {log.parent / EVENTS_DIR}" in \
        capsys.readouterr().out
    assert_holds_the_log(log.parent / EVENTS_DIR, read_records(log).records)


def test_tensorboard_is_no_part_of_the_run_identity():
    assert config_hash(compose([*TINY, "tensorboard=true"])) == config_hash(compose(TINY))


def test_a_killed_run_leaves_readable_files_and_its_resume_continues_them(tmp_path):
    args = [*SHORT, "epochs=3", f"results_dir={tmp_path}", "quiet=false"]
    train_killed_at_epoch(args)
    log = next(tmp_path.rglob("run.mcap"))
    killed = read_records(log)
    assert not killed.complete
    folder = log.parent / EVENTS_DIR
    steps = sorted(logged_values(folder)["success/test_success"])
    assert steps[-1] >= 2 and steps[-1] >= len(killed.records) - 1  # the last epoch logged, or the one before
    assert_holds_the_log(folder, killed.records[:len(steps)])
    subprocess.run([sys.executable, "-m", "hersd.engine.cli", *args], check=True, capture_output=True)
    resumed = read_records(log)
    assert resumed.complete and len(resumed.sessions) == 2 and len(list(folder.glob(EVENT_FILES))) == 1
    assert_holds_the_log(folder, resumed.records)


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    """Every log under results/ converted by hersd-report --tensorboard (twice: the second replaces the first),
    a run folder an earlier conversion wrote, of a run gone since, left there before."""
    out = tmp_path_factory.mktemp("tensorboard")
    stale = out / "FetchPush" / "gone" / "seed0"
    stale.mkdir(parents=True)
    (stale / "events.out.tfevents.1.host").write_bytes(b"")
    (out / MANIFEST).write_text(json.dumps({"FetchPush/gone/seed0": {"task": "push", "algo": "her"}}))
    assert report_main([str(RESULTS), "--tensorboard", str(out)]) == 0
    assert report_main([str(RESULTS), "--tensorboard", str(out)]) == 0
    return out


def test_converted_committed_logs_hold_every_epoch_field_at_its_step(converted):
    log = RESULTS / "push" / "her" / "linear-b1_0.25" / "seed0-252651aa" / "run.mcap"
    folder = converted / "FetchPush" / "linear b1=0.25" / "seed0"
    assert len(list(folder.glob(EVENT_FILES))) == 1
    assert_holds_the_log(folder, read_records(log).records)
    assert hparams(folder) == {key: value for key, value in flat_settings(read_records(log).meta["config"]).items()
                               if key not in ("results_dir", "run_dir")}


def test_tensorboard_lists_one_run_per_log_named_by_the_report_labels(converted):
    multiplexer = EventMultiplexer().AddRunsFromDirectory(str(converted))
    multiplexer.Reload()
    runs = set(multiplexer.Runs())
    assert len(runs) == len(find_logs(RESULTS)) >= 65
    assert {"FetchPush/HER/seed0", "FetchPush/HER eps=0.874375/seed9", "FetchPickAndPlace/exp b1=0.25 b2=0.25/seed4",
            "FetchSlide/linear b1=0.25/seed4"} <= runs
    assert not (converted / "FetchPush" / "gone").exists()


def _copied_logs(folder: Path, *runs: str) -> Path:
    """The committed logs of ``runs`` (paths below results/) copied into ``folder`` -> ``folder``."""
    for run in runs:
        (folder / run).mkdir(parents=True)
        shutil.copy(RESULTS / run / "run.mcap", folder / run / "run.mcap")
    return folder


PUSH_RUN, SLIDE_RUN = "push/her/linear-b1_0.25/seed0-252651aa", "slide/her/constant-0.8/seed0-c2549eae"


def test_a_conversion_removes_only_run_folders_it_wrote_of_the_tasks_it_converts(tmp_path):
    """Every event file below DIR that one conversion did not write was deleted: another tool's runs, the other
    tasks' runs on a filtered conversion. Now only a run folder an earlier conversion wrote goes, once its run is
    gone from a conversion of its task."""
    logs, out = _copied_logs(tmp_path / "logs", PUSH_RUN, SLIDE_RUN), tmp_path / "tb"
    other_tool = out / "sb3" / "PPO_1" / "events.out.tfevents.1.host"
    other_tool.parent.mkdir(parents=True)
    other_tool.write_bytes(b"another tool's run")
    push, slide = out / "FetchPush" / "linear b1=0.25" / "seed0", out / "FetchSlide" / "HER" / "seed0"
    assert report_main([str(logs), "--tensorboard", str(out)]) == 0
    assert report_main([str(logs), "--tensorboard", str(out), "--task", "slide"]) == 0
    assert list(push.glob(EVENT_FILES)) and list(slide.glob(EVENT_FILES)) and other_tool.exists()
    shutil.rmtree(logs / "slide")
    assert report_main([str(logs), "--tensorboard", str(out), "--task", "push"]) == 0  # slide not converted
    assert list(slide.glob(EVENT_FILES))
    assert report_main([str(logs), "--tensorboard", str(out)]) == 0  # slide converted: its run is gone
    assert not (out / "FetchSlide").exists() and list(push.glob(EVENT_FILES)) and other_tool.exists()


def test_converting_a_folder_into_itself_keeps_its_runs_live_event_files(tmp_path):
    logs = _copied_logs(tmp_path / "logs", PUSH_RUN)
    live = logs / PUSH_RUN / EVENTS_DIR / "events.out.tfevents.1.host"
    live.parent.mkdir()
    live.write_bytes(b"written as it trained")
    assert report_main([str(logs), "--tensorboard", str(logs)]) == 0
    assert live.read_bytes() == b"written as it trained"
    assert list((logs / "FetchPush" / "linear b1=0.25" / "seed0").glob(EVENT_FILES))


def test_a_conversion_names_the_logs_it_leaves_out(tmp_path, capsys):
    """It said only how many runs it wrote; the report names every log left out, damaged or failed: so does it."""
    logs = _copied_logs(tmp_path / "logs", PUSH_RUN)
    (logs / "push" / "broken").mkdir()
    (logs / "push" / "broken" / "run.mcap").write_bytes(b"not a log")
    assert report_main([str(logs), "--tensorboard", str(tmp_path / "tb")]) == 0
    err = capsys.readouterr().err
    assert "warning: skipped unreadable log push/broken/run.mcap" in err, err


def test_without_tensorboard_the_setting_and_the_conversion_are_one_line_with_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "tensorboard.summary.writer.event_file_writer", None)  # import fails
    with pytest.raises(SystemExit) as exit_info:
        train_main([*TINY, "tensorboard=true", f"results_dir={tmp_path / 'runs'}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "tensorboard" in err and "pip install" in err, err
    assert not (tmp_path / "runs").exists()  # nothing trained
    logs = tmp_path / "logs" / "run"
    logs.mkdir(parents=True)
    shutil.copy(RESULTS / "push" / "her" / "linear-b1_0.25" / "seed0-252651aa" / "run.mcap", logs)
    assert report_main([str(tmp_path / "logs"), "--tensorboard", str(tmp_path / "tb")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pip install" in err, err


def test_the_package_imports_without_tensorboard():
    code = ("import sys; sys.modules['tensorboard'] = None\n"
            "import hersd.contract.config, hersd.contract.tensorboard_events, hersd.engine.train, analysis.report\n"
            "from hersd.contract.compose import compose_train\n"
            "assert compose_train(['task=reach']).tensorboard is False")
    subprocess.run([sys.executable, "-c", code], check=True)
