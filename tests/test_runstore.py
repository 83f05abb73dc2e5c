"""hersd/contract/runstore.py, the run store: a run's identity and hash (a config or a log's config dict, however old),
its directory's name, and RunFolder: state from its files, policy animations, the lock and its holder's pid;
keeping files aside, removing a directory a failed start left, checking results_dir."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from analysis.synthetic import write_run
from hersd.contract.compose import compose_train
from hersd.contract.config import TrainConfig, config_record
from hersd.contract.errors import ConfigError
from hersd.contract.runstore import (CHECKPOINT_NAME, LOCK_NAME, NOT_HASHED, RunFolder, RunLockedError, check_writable,
                            config_hash, keep_aside, remove_if_unused, run_dir, run_identity)


def test_a_config_and_its_logged_dict_have_one_identity_however_old_the_log():
    cfg = compose_train(["task=push", "learner=td3", "schedule=paper_exp_050"])
    assert run_identity(config_record(cfg)) == run_identity(cfg)
    old = config_record(compose_train(["task=push"]))
    for key in ("learner", "threads", "device"):  # fields added to the schema after runs were made
        del old[key]
    for key in ("window", "eps_min"):
        del old["schedule"][key]
    assert run_identity(old) == run_identity(compose_train(["task=push"]))


def test_run_identity_ignores_where_and_how_a_run_is_executed():
    base = compose_train(["task=push"])
    for override in ("results_dir=/elsewhere", "quiet=true", "checkpoint_every=5", "keep_checkpoint=true",
                     "threads=2", "device=cpu", "flush_denormal=true"):
        assert config_hash(compose_train(["task=push", override])) == config_hash(base), override
    assert not set(NOT_HASHED) & set(run_identity(base))
    assert config_hash(compose_train(["task=push", "seed=1"])) != config_hash(base)


def test_only_the_learner_in_use_is_part_of_a_runs_identity():
    ddpg = compose_train(["task=push"])
    assert config_hash(compose_train(["task=push", "learner.td3.policy_delay=3"])) == config_hash(ddpg)
    td3 = compose_train(["task=push", "learner=td3"])
    assert config_hash(td3) != config_hash(ddpg)
    assert config_hash(compose_train(["task=push", "learner=td3", "learner.sac.alpha_lr=0.1"])) == config_hash(td3)
    assert config_hash(compose_train(["task=push", "learner=td3", "learner.td3.policy_delay=3"])) != config_hash(td3)


def test_the_lock_records_its_holders_pid_while_held(tmp_path):
    assert RunFolder(tmp_path).holder() is None
    with RunFolder(tmp_path).lock():
        assert RunFolder(tmp_path).holder() == os.getpid()
        code = f"from hersd.contract.runstore import RunFolder; from pathlib import Path\nwith RunFolder(Path({str(tmp_path)!r})).lock(): pass"
        taken = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert f"being run by another process (pid {os.getpid()})" in taken.stderr  # and it kept the pid
        assert RunFolder(tmp_path).holder() == os.getpid()
    assert RunFolder(tmp_path).holder() is None and (tmp_path / LOCK_NAME).read_text() == ""


def test_a_dead_holders_pid_is_no_holder(tmp_path):
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / LOCK_NAME).write_text(ended.stdout)  # as a holder killed with -9 leaves it
    assert RunFolder(tmp_path).holder() is None


def test_a_killed_holder_its_parent_has_not_reaped_is_no_holder(tmp_path):
    """A holder killed while its parent is not waiting for it stays a zombie: its lock is closed, so no run is
    "running" there (a dry run said so, pid and all, until the parent ended)."""
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / LOCK_NAME).write_text(f"{child.pid}\n")
        assert RunFolder(tmp_path).holder() == child.pid
        os.kill(child.pid, 9)
        for _ in range(100):  # until the kernel has made it a zombie; not reaped: no wait() yet
            if Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                break
            time.sleep(0.05)
        assert RunFolder(tmp_path).holder() is None
    finally:
        child.kill()
        child.wait()


def test_a_run_directory_is_named_by_task_algo_schedule_seed_and_hash():
    cfg = compose_train(["task=push", "seed=3", "results_dir=/results"])
    assert run_dir(cfg) == Path("/results/push/her") / cfg.schedule.tag() / f"seed3-{config_hash(cfg)}"
    assert re.fullmatch(r"[0-9a-f]{8}", config_hash(cfg))
    td3 = compose_train(["task=push", "learner=td3", "results_dir=/results"])
    assert run_dir(td3).parent.parent.name == "td3-her"  # a learner other than DDPG leads the algo's folder
    assert run_dir(compose_train(["task=push", "run_dir=/one/dir"])) == Path("/one/dir")


def test_a_run_folders_state_follows_its_files(tmp_path):
    """new (nothing, or an unreadable log alone), resumable (a checkpoint, whatever the log), complete (its log says so)."""
    folder = RunFolder(tmp_path / "run")
    assert folder.state() == "new" and folder.records() is None  # not even a directory
    with mock.patch("os.fsync"):
        write_run(folder.path, TrainConfig(epochs=4), np.linspace(0, 1, 2), complete=False)
    assert folder.state() == "new" and len(folder.records().records) == 2
    folder.checkpoint.write_bytes(b"")
    assert folder.state() == "resumable" and folder.checkpoint.name == CHECKPOINT_NAME
    with mock.patch("os.fsync"):
        write_run(folder.path, TrainConfig(epochs=4), np.linspace(0, 1, 4))
    assert folder.state() == "complete"
    folder.log.write_bytes(b"not an mcap file" * 10)
    assert folder.state() == "resumable"
    folder.checkpoint.unlink()
    assert folder.state() == "new"


def test_animations_are_listed_in_epoch_order_and_other_files_ignored(tmp_path):
    folder = RunFolder(tmp_path)
    assert folder.animations() == {}
    for name in ("epoch_10.gif", "epoch_2.gif", "epoch_x.gif", "epoch_3.png"):
        (tmp_path / "policy").mkdir(exist_ok=True)
        (tmp_path / "policy" / name).write_bytes(b"")
    assert folder.animations() == {2: folder.animation(2), 10: folder.animation(10)}
    assert list(folder.animations()) == [2, 10] and folder.animation(2) == tmp_path / "policy" / "epoch_2.gif"


def test_a_held_lock_is_refused_in_this_process_too_and_keeps_its_holder(tmp_path):
    with RunFolder(tmp_path).lock():
        with pytest.raises(RunLockedError, match=rf"being run by another process \(pid {os.getpid()}\)"):
            with RunFolder(tmp_path).lock():
                pass
        assert RunFolder(tmp_path).holder() == os.getpid()
    with RunFolder(tmp_path).lock():  # released: free again
        pass


def test_a_file_kept_aside_is_renamed_beside_it_with_the_reason_and_time(tmp_path):
    log = tmp_path / "run.mcap"
    log.write_bytes(b"partial")
    kept = keep_aside(log, "partial")
    assert re.fullmatch(r"run\.partial-\d{8}-\d{6}\.mcap", kept.name) and kept.parent == tmp_path
    assert not log.exists() and kept.read_bytes() == b"partial"


def test_a_directory_holding_only_its_lock_is_removed_with_its_empty_parents(tmp_path):
    failed = tmp_path / "push" / "her" / "constant-0.8" / "seed0-00000000"
    failed.mkdir(parents=True)
    (failed / LOCK_NAME).write_text("")
    (tmp_path / "push" / "other").mkdir()
    remove_if_unused(failed, tmp_path)
    assert not (tmp_path / "push" / "her").exists() and (tmp_path / "push" / "other").is_dir()
    kept = tmp_path / "reach" / "seed0"
    kept.mkdir(parents=True)
    (kept / LOCK_NAME).write_text("")
    (kept / "run.mcap").write_bytes(b"")
    remove_if_unused(kept, tmp_path)
    assert (kept / "run.mcap").exists() and (kept / LOCK_NAME).exists()


def test_an_unwritable_results_dir_is_one_line(tmp_path):
    check_writable(tmp_path / "new" / "folder")  # created
    assert (tmp_path / "new" / "folder").is_dir() and not any((tmp_path / "new" / "folder").iterdir())
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError, match=r"^results_dir: cannot write to .*; pass results_dir=") as raised:
        check_writable(tmp_path / "file" / "below")
    assert "\n" not in str(raised.value)
