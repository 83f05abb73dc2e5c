"""The training run end to end: determinism, resume, the log contract, bad input, learning."""

import os
import shlex
import signal
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import TINY as TINY_RUN, metrics, train_killed_at_epoch

import hersd.engine.resources as resources
from hersd.engine.cli import main
from hersd.contract.compose import compose_train as compose
from hersd.contract.cores import available_cores
from hersd.contract.runlog import read_run
from hersd.contract.runstore import RunFolder, RunLockedError, run_dir
from hersd.engine.train import train

TINY = [*TINY_RUN, "quiet=true", "threads=1"]


def test_same_seed_gives_identical_metrics(tmp_path):
    first = train(compose([*TINY, "epochs=2", "seed=3", f"results_dir={tmp_path / 'a'}"]))
    second = train(compose([*TINY, "epochs=2", "seed=3", f"results_dir={tmp_path / 'b'}"]))
    other_seed = train(compose([*TINY, "epochs=2", "seed=4", f"results_dir={tmp_path / 'a'}"]))
    pd.testing.assert_frame_equal(metrics(first), metrics(second))
    assert not metrics(first).equals(metrics(other_seed))


def test_log_holds_metadata_and_every_epoch(tmp_path):
    cfg = compose([*TINY, "epochs=3", "schedule=linear", "schedule.beta1=0.5", f"results_dir={tmp_path}"])
    log = read_run(train(cfg, command="hersd-train test"))
    assert log.complete and not log.damaged
    assert list(log.epochs["epoch"]) == [1, 2, 3]
    assert np.allclose(log.epochs["relabel_rate"], [1 - 0.5 / 3, 1 - 1 / 3, 0.5])
    shares = log.epochs[["share_hindsight", "share_real_success", "share_real_failure"]].sum(axis=1)
    assert np.allclose(shares, 1.0)
    assert ((log.epochs["test_distance"] > 0) & (log.epochs["test_distance"] < 1)).all()  # metres on FetchReach
    assert list(log.epochs["env_steps"]) == [200, 400, 600]  # 2 cycles x 2 episodes x 50 steps
    assert list(log.epochs["updates"]) == [10, 20, 30]
    assert log.meta["config"]["schedule"] == {"kind": "linear", "eps": 0.8, "beta1": 0.5, "beta2": 0.0,
                                              "mean_rate": None, "window": 10, "eps_min": 0.0}
    assert log.meta["command"] == "hersd-train test"
    assert {"python", "torch", "mujoco", "gymnasium_robotics", "hersd"} <= set(log.meta["versions"])
    assert log.meta["threads"] == 1 and log.meta["device"] == "cpu"
    assert log.meta["machine"]["cpu_model"] and log.meta["machine"]["torch_cpu_capability"]
    assert log.meta["effective"]["gamma"] == pytest.approx(0.98)
    assert not (log.path.parent / "checkpoint.pt").exists()  # removed once complete


def test_rerunning_a_complete_run_does_nothing(tmp_path):
    cfg = compose([*TINY, "epochs=1", f"results_dir={tmp_path}"])
    log_path = train(cfg)
    before = log_path.read_bytes()
    assert train(cfg) == log_path and log_path.read_bytes() == before


def test_a_checkpoint_left_beside_a_complete_log_goes_at_the_next_run(tmp_path):
    """A run killed after its completion marker, before removing its checkpoint: the same command removes it."""
    cfg = compose([*TINY, "epochs=1", f"results_dir={tmp_path}"])
    log_path = train(cfg)
    checkpoint = log_path.parent / "checkpoint.pt"
    checkpoint.write_bytes(b"left behind")
    before = log_path.read_bytes()
    assert train(cfg) == log_path and log_path.read_bytes() == before and not checkpoint.exists()
    kept = compose([*TINY, "epochs=1", "keep_checkpoint=true", f"results_dir={tmp_path / 'kept'}"])
    kept_checkpoint = train(kept).parent / "checkpoint.pt"
    assert kept_checkpoint.exists() and train(kept) and kept_checkpoint.exists()


class StopHere(Exception):
    pass


def test_interrupted_run_resumes_to_the_uninterrupted_metrics(tmp_path):
    reference = train(compose([*TINY, "epochs=4", f"results_dir={tmp_path / 'ref'}"]))
    cfg = compose([*TINY, "epochs=4", f"results_dir={tmp_path / 'cut'}"])

    def stop_after_epoch_2(record):
        if record["epoch"] == 2:
            raise StopHere

    with pytest.raises(StopHere):
        train(cfg, on_epoch=stop_after_epoch_2)
    interrupted = read_run(next((tmp_path / "cut").rglob("run.mcap")))
    assert not interrupted.complete and list(interrupted.epochs["epoch"]) == [1, 2]
    resumed = train(cfg)
    log = read_run(resumed)
    assert log.complete and [s["resumed_from_epoch"] for s in log.sessions] == [0, 2]
    pd.testing.assert_frame_equal(metrics(resumed), metrics(reference))


def test_kill_9_then_same_command_finishes_with_uninterrupted_metrics(tmp_path):
    args = [*TINY, "epochs=3", f"results_dir={tmp_path / 'cut'}", "quiet=false"]
    train_killed_at_epoch(args)
    log_path = next((tmp_path / "cut").rglob("run.mcap"))
    killed = read_run(log_path)
    assert not killed.complete and 2 <= len(killed.epochs) <= 3
    subprocess.run([sys.executable, "-m", "hersd.engine.cli", *args], check=True, capture_output=True)
    reference = train(compose([*TINY, "epochs=3", f"results_dir={tmp_path / 'ref'}"]))
    assert read_run(log_path).complete
    pd.testing.assert_frame_equal(metrics(log_path), metrics(reference))


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["ctrl_c", "kill"])
def test_ctrl_c_ends_a_run_with_one_line_and_exit_130_then_the_same_command_resumes(tmp_path, stop):
    """Ctrl-C, or ``kill PID`` (SIGTERM, as a supervisor stops it): one line, exit 130, no temporary file left."""
    args = [*TINY, "epochs=3", f"results_dir={tmp_path / 'cut'}", "quiet=false"]
    proc = subprocess.Popen([sys.executable, "-m", "hersd.engine.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    for line in proc.stdout:
        if line.startswith("epoch") and line.split()[1].startswith("1/"):
            proc.send_signal(stop)
            break
    _, err = proc.communicate(timeout=120)
    log_path = next((tmp_path / "cut").rglob("run.mcap"))
    assert proc.returncode == 130 and not list(tmp_path.rglob("*.tmp"))
    assert err.strip() == (f"hersd-train: interrupted; the finished epochs are kept in {log_path.parent}: "
                           "re-run the same command to resume")
    assert 1 <= len(read_run(log_path).epochs) <= 3
    subprocess.run([sys.executable, "-m", "hersd.engine.cli", *args], check=True, capture_output=True)
    reference = train(compose([*TINY, "epochs=3", f"results_dir={tmp_path / 'ref'}"]))
    pd.testing.assert_frame_equal(metrics(log_path), metrics(reference))


def test_ctrl_c_while_the_checkpoint_is_written_is_the_same_one_line_with_exit_130(tmp_path, capsys, monkeypatch):
    """A Ctrl-C in the middle of torch.save's write ends in torch's zip-writer RuntimeError, the KeyboardInterrupt
    only its context: still the run's one line and exit 130, no temporary file, and the run resumes to the
    uninterrupted metrics."""
    import io

    import torch

    import hersd.engine.train as train_module

    save, run_epoch, at = torch.save, train_module.run_epoch, {"epoch": 0}

    class CutStream(io.RawIOBase):
        """Takes some bytes of the write, then the Ctrl-C."""

        def __init__(self, stream):
            super().__init__()
            self.stream, self.written = stream, 0

        def writable(self) -> bool:
            return True

        def write(self, data) -> int:
            if self.written > 4096:
                raise KeyboardInterrupt
            self.written += len(data)
            return self.stream.write(data)

    def counting_run_epoch(state, epoch, rate=None):
        at["epoch"] = epoch
        return run_epoch(state, epoch, rate)

    def cut_save(obj, f, *args, **kwargs):
        return save(obj, CutStream(f) if at["epoch"] == 2 and isinstance(f, io.BufferedWriter) else f, *args, **kwargs)

    monkeypatch.setattr(train_module, "run_epoch", counting_run_epoch)
    monkeypatch.setattr(torch, "save", cut_save)
    args = [*TINY, "epochs=3", f"results_dir={tmp_path / 'cut'}"]
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    monkeypatch.undo()
    directory = run_dir(compose(args))
    assert exit_info.value.code == 130
    assert capsys.readouterr().err.strip() == (f"hersd-train: interrupted; the finished epochs are kept in "
                                               f"{directory}: re-run the same command to resume")
    assert sorted(path.name for path in directory.iterdir()) == ["checkpoint.pt", "run.lock", "run.mcap"]  # no .tmp
    main(args)
    reference = train(compose([*TINY, "epochs=3", f"results_dir={tmp_path / 'ref'}"]))
    pd.testing.assert_frame_equal(metrics(directory / "run.mcap"), metrics(reference))


class _Loading(types.ModuleType):
    """A module whose names are never there: a Ctrl-C while it loads (torch, under hersd.engine.train)."""

    def __getattr__(self, name: str):
        raise KeyboardInterrupt


@pytest.mark.parametrize("where", ["composing", "loading torch"])
def test_ctrl_c_before_training_begins_is_one_line_with_exit_130(tmp_path, capsys, monkeypatch, where):
    import hersd.contract.compose

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    if where == "composing":
        monkeypatch.setattr(hersd.contract.compose, "compose", interrupted)
    else:
        monkeypatch.setitem(sys.modules, "hersd.engine.train", _Loading("hersd.engine.train"))
    try:
        main([*TINY, f"results_dir={tmp_path}"])
    except SystemExit as exited:
        code = exited.code
    except KeyboardInterrupt:
        code = "a KeyboardInterrupt's traceback"
    assert code == 130
    assert capsys.readouterr().err == ("hersd-train: interrupted before training began; re-run the same command "
                                       "to start\n")


def test_the_commands_module_loads_only_the_standard_library_so_ctrl_c_is_caught_from_its_start():
    code = ("import sys, hersd.engine.cli; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'numpy', 'pandas', 'omegaconf', 'hydra', 'torch', 'mujoco', 'mcap'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]"


def _stopped_after_epoch_1(tmp_path: Path) -> tuple[list[str], Path]:
    """A run of 3 epochs stopped after epoch 1 (log + checkpoint on disk) -> (its args, its directory)."""
    args = [*TINY, "epochs=3", f"results_dir={tmp_path}"]

    def stop(record):
        raise StopHere

    with pytest.raises(StopHere):
        train(compose(args), on_epoch=stop)
    return args, next(tmp_path.rglob("run.mcap")).parent


def test_damaged_checkpoint_is_one_line_with_exit_2_and_keeps_the_log(tmp_path, capsys):
    args, directory = _stopped_after_epoch_1(tmp_path)
    checkpoint = directory / "checkpoint.pt"
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    log_before = (directory / "run.mcap").read_bytes()
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "checkpoint.pt is unreadable" in err and "move it aside" in err
    assert (directory / "run.mcap").read_bytes() == log_before


def test_unreadable_log_without_checkpoint_is_kept_aside_and_the_run_starts_afresh(tmp_path):
    args, directory = _stopped_after_epoch_1(tmp_path)
    (directory / "checkpoint.pt").unlink()
    (directory / "run.mcap").write_bytes(b"not an mcap file")
    log = read_run(train(compose(args)))
    assert log.complete and list(log.epochs["epoch"]) == [1, 2, 3]
    kept = list(directory.glob("run.unreadable-*.mcap"))
    assert len(kept) == 1 and kept[0].read_bytes() == b"not an mcap file"


def test_checkpoint_without_log_is_kept_aside_and_the_run_starts_afresh(tmp_path, capsys):
    args, directory = _stopped_after_epoch_1(tmp_path)
    checkpoint_bytes = (directory / "checkpoint.pt").read_bytes()
    (directory / "run.mcap").unlink()
    log = read_run(train(compose([*args, "quiet=false"])))
    assert log.complete and list(log.epochs["epoch"]) == [1, 2, 3] and len(log.sessions) == 1
    kept = list(directory.glob("checkpoint.orphan-*.pt"))
    assert len(kept) == 1 and kept[0].read_bytes() == checkpoint_bytes
    assert "without its log" in capsys.readouterr().out


def test_a_locked_run_is_not_run_twice(tmp_path):
    cfg = compose([*TINY, "epochs=1", f"results_dir={tmp_path}"])
    run_dir(cfg).mkdir(parents=True)
    with RunFolder(run_dir(cfg)).lock():
        with pytest.raises(RunLockedError):
            train(cfg)
    assert not (run_dir(cfg) / "run.mcap").exists()


@pytest.mark.parametrize("override, field", [
    ("schedule.beta1=1.5", "schedule.beta1"),
    ("schedule.beta1=-0.1", "schedule.beta1"),
    ("schedule.beta1=nan", "schedule.beta1"),
    ("schedule.beta2=inf", "schedule.beta2"),
    ("schedule.beta2=800", "schedule.beta2"),  # exp(800) overflows
    ("schedule=exponential schedule.mean_rate=0.9 schedule.beta2=-1e308", "schedule.beta2"),
    ("schedule.mean_rate=0.9", "schedule.mean_rate"),  # only for decaying schedules
    ("seed=-1", "seed"),
    ("task.cycles_per_epoch=0", "task.cycles_per_epoch"),
    ("task.distance_threshold=-1", "task.distance_threshold"),
    ("algo.lambda_h=0", "algo.lambda_h"),
    ("algo.mep.temperature=0", "algo.mep.temperature"),
    ("ddpg.batch_size=0", "ddpg.batch_size"),
    ("ddpg.gamma=1", "ddpg.gamma"),
    ("ddpg.polyak=1.5", "ddpg.polyak"),
    ("threads=0", "threads"),
    ("threads=many", "threads"),
    ("device=tpu", "device"),
    ("device=cuda:x", "device"),
    ("ddpg.buffer_size=100000000000", "ddpg.buffer_size"),  # more memory than any machine here has
    ("ddpg.hidden_units=200000", "ddpg.hidden_units"),
    ("task=custom", "task.env_id"),
    ("task.env_id=HandReach-v3", "task=custom"),
    ("task=cartpole", "task"),
    ("task=null", "task=null is not a known task; choose one of: custom"),
    ("learner=NULL", "learner=null is not a known learner; choose one of: ddpg"),
    ("algo.goal_strategy=nearest", "algo.goal_strategy"),
    ("schedule=sawtooth", "table, or a class of your own: schedule._target_=<module>.<Class>"),
    ("schedule=my_pkg.steps.Step", "names a class, which no config of the schedule group holds; type "
                                   "schedule._target_=my_pkg.steps.Step"),
    ("schedule.kind=sawtooth", "schedule.kind"),
    ("schedule._target_=no_such_module.Step", "no_such_module.Step"),
    ("schedule=constant schedule.beta1=0.5", "schedule.beta1"),  # not a setting of constant
    ("schedule=table schedule.rates=[0.9,0.8] epochs=3", "epochs=3"),  # one rate per epoch
    ("schedule=table", "schedule.rates"),
    ("schedule=cosine schedule.end=2", "schedule.end"),
    ("epochs=0", "epochs"),
    ("epochs=ten", "epochs"),
    ("no_such_key=1", "no_such_key"),
])
def test_bad_input_is_one_line_naming_the_field_with_exit_2(tmp_path, capsys, override, field):
    with pytest.raises(SystemExit) as exit_info:
        main([*override.split(), f"results_dir={tmp_path}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err, err
    assert not any(tmp_path.iterdir())  # nothing written


def test_unknown_choice_lists_the_valid_ones(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["task=cartpole", f"results_dir={tmp_path}"])
    assert "pick_and_place, push, reach, slide" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["/tmp/é", "a#b", "it's#"])  # Hydra's grammar reads none of these unquoted
def test_a_value_hydras_grammar_cannot_read_is_one_line_saying_how_to_quote_it(tmp_path, capsys, value):
    with pytest.raises(SystemExit) as exit_info:
        main([f"results_dir={value}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cannot read this value unquoted; quote it: " in err, err
    typed = shlex.split(err.split("quote it: ")[1])  # as the shell hands it over
    assert compose(typed).results_dir == value


def test_unwritable_results_dir_fails_before_work(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, f"results_dir={blocker}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "results_dir" in err and len(err.strip().splitlines()) == 1
    assert blocker.read_text() == "not a folder"


def test_a_file_where_the_run_folder_goes_under_results_dir_is_one_line_with_exit_2(tmp_path, capsys):
    blocker = tmp_path / "reach"  # where <results_dir>/<task>/... goes
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, "task=reach", f"results_dir={tmp_path}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"hersd-train: error: results_dir: {blocker} is a file"), err
    assert err.endswith("pass results_dir=<another folder>") and blocker.read_text() == "not a folder"


@pytest.mark.parametrize("inside", ["", "run"])
def test_an_unusable_run_dir_is_one_line_naming_run_dir_with_exit_2(tmp_path, capsys, inside):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, f"run_dir={blocker / inside}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("hersd-train: error: run_dir: cannot write to "), err
    assert err.endswith("pass run_dir=<a writable folder>") and blocker.read_text() == "not a folder"


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fetch_reach_learns_within_5_epochs(tmp_path, seed):
    """Paper settings on FetchReach (10 cycles/epoch): test success >= 0.9 within 5 epochs. No bias
    evaluation: it changes no metric (tests/test_bias.py) and costs time."""
    log = read_run(train(compose(["task=reach", "epochs=5", f"seed={seed}", "quiet=true", "bias.epochs=[]",
                                  f"results_dir={tmp_path}"])))
    assert log.epochs["test_success"].max() >= 0.9, log.epochs["test_success"].tolist()
    # FetchReach counts a success within 5 cm: all-successful epochs end closer than that on average
    solved = log.epochs["test_success"] == 1.0
    assert (log.epochs.loc[solved, "test_distance"] < 0.05).all(), log.epochs["test_distance"].tolist()
    assert log.epochs["test_distance"].min() < log.epochs["test_distance"].iloc[0]


def test_device_cpu_and_auto_give_identical_metrics_on_a_cpu_machine(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("device=auto is CUDA on this machine")
    on_cpu = train(compose([*TINY, "epochs=2", "device=cpu", f"results_dir={tmp_path / 'cpu'}"]))
    on_auto = train(compose([*TINY, "epochs=2", "device=auto", f"results_dir={tmp_path / 'auto'}"]))
    pd.testing.assert_frame_equal(metrics(on_cpu), metrics(on_auto))
    assert read_run(on_auto).meta["device"] == "cpu"


def test_threads_auto_gives_a_lone_run_every_core_and_same_threads_same_metrics(tmp_path, idle_machine):
    args = [*TINY_RUN, "quiet=true", "epochs=1", "threads=auto"]
    first = train(compose([*args, f"results_dir={tmp_path / 'a'}"]))
    second = train(compose([*args, f"results_dir={tmp_path / 'b'}"]))
    assert read_run(first).meta["threads"] == available_cores()
    assert run_dir(compose([*args, f"results_dir={tmp_path / 'a'}"])) == \
        run_dir(compose([*TINY, "epochs=1", f"results_dir={tmp_path / 'a'}"]))  # threads: not the run's identity
    pd.testing.assert_frame_equal(metrics(first), metrics(second))


def test_help_is_generated_from_the_schema(capsys):
    main(["--help"])
    out = capsys.readouterr().out
    assert "schedule.beta1=0.0" in out and "eq. 9: final drop of the rate" in out
    assert "ddpg.polyak=0.95" in out and "threads=auto" in out and "task=custom|hand_block|hand_reach|pick_and_place|push|reach|slide" in out


@pytest.mark.parametrize("has_bf16, bf16_runs", [(True, "yes"), (False, "no: this CPU has no bf16 instructions")])
def test_help_says_which_update_paths_this_cpu_runs(capsys, monkeypatch, has_bf16, bf16_runs):
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: has_bf16)
    main(["--help"])
    lines = {line.split()[0] + " " + line.split()[1]: line for line in capsys.readouterr().out.splitlines()
             if line.startswith(("  fp32 ", "  bf16 "))}
    assert set(lines) == {"fp32 autograd", "fp32 fast", "bf16 autocast", "bf16 fast"}
    assert lines["fp32 fast"].endswith("yes") and "update=fast (ddpg, td3)" in lines["fp32 fast"]
    assert bf16_runs in lines["bf16 fast"] and "precision=bf16 update=fast" in lines["bf16 fast"]
    assert bf16_runs in lines["bf16 autocast"]


def test_the_commit_is_dirty_for_changed_code_not_for_changed_results(tmp_path, monkeypatch):
    """A run records ``<commit>-dirty`` when tracked code differs from the commit; run logs and reports
    below results/ are data the runs write, so a checkout whose only changes are there is clean."""
    import hersd
    from hersd.engine import train as train_module

    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    for name in ("hersd/__init__.py", "results/push/run.mcap"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("0")
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    monkeypatch.setattr(hersd, "__file__", str(tmp_path / "hersd" / "__init__.py"))
    clean = train_module._git_commit()
    assert clean and len(clean) == 40
    (tmp_path / "results/push/run.mcap").write_text("1")
    assert train_module._git_commit() == clean
    (tmp_path / "hersd/__init__.py").write_text("1")
    assert train_module._git_commit() == clean + "-dirty"


def test_dry_run_prints_the_resolved_run_and_writes_nothing(tmp_path, capsys):
    args = [*TINY, "epochs=3", "schedule=linear", "schedule.beta1=0.25", f"results_dir={tmp_path / 'runs'}"]
    main([*args, "--dry-run"])
    lines = capsys.readouterr().out.splitlines()
    cfg = compose(args)
    assert lines[:3] == [f"run: {run_dir(cfg)} (new)", f"identity: {run_dir(cfg).name.split('-')[-1]}", "settings:"]
    assert {"  epochs=3", "  schedule.kind=linear", "  schedule.beta1=0.25", "  quiet=true"} <= set(lines[3:])
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("overrides", ["results_dir={tmp}/file", "device=cuda results_dir={tmp}/runs"])
def test_dry_run_refuses_what_the_real_command_refuses_with_its_one_line_and_writes_nothing(
        tmp_path, capsys, monkeypatch, overrides):
    """An unwritable results_dir, a device this machine lacks: the dry run printed ``(new)``, exit 0."""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)  # a machine without CUDA
    (tmp_path / "file").write_text("not a folder")
    args = [*TINY, *overrides.format(tmp=tmp_path).split()]
    errors = []
    for dry_run in (["--dry-run"], []):
        with pytest.raises(SystemExit) as exit_info:
            main([*args, *dry_run])
        assert exit_info.value.code == 2
        errors.append(capsys.readouterr().err)
        if dry_run:
            assert [path.name for path in tmp_path.iterdir()] == ["file"]
    assert errors[0] == errors[1] and errors[0].count("\n") == 1, errors


def test_dry_run_shows_a_run_stopped_by_an_error_as_failed_as_a_sweeps_dry_run_does(tmp_path, capsys):
    """A run whose error.log is newer than its log (hersd-sweep --dry-run: ``failed``): it showed ``(resumable)``."""
    args, directory = _stopped_after_epoch_1(tmp_path)
    (directory / "error.log").write_text('Traceback (most recent call last):\n  File "x.py", line 1, in <module>\n'
                                         "    boom()\nRuntimeError: boom at epoch 2\n")
    main([*args, "--dry-run"])
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith(f"run: {directory} (failed: RuntimeError: boom at epoch 2, epoch 1 of 3, "), first


@pytest.mark.parametrize("option", ["--bogus", "--dry-run=1"])
def test_an_unknown_option_is_one_line_naming_it_and_what_the_command_takes_with_exit_2(tmp_path, capsys, option):
    """It reached Hydra's override parser: ``LexerNoViableAltException: --bogus ^ See https://hydra.cc/...``."""
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, f"results_dir={tmp_path}", "--dry-run", option])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (f"hersd-train: error: unknown option {option}; hersd-train takes -h, --help, "
                                       "--dry-run and KEY=VALUE overrides (hersd-train --help lists them)\n")


def _fill_the_disk_at_epoch_3(monkeypatch, where: str) -> None:
    """From epoch 3 on the disk is full: the log's write (its fsync, where a full disk can first show) or the
    checkpoint's torch.save (some bytes written, then torch's RuntimeError raised while its OSError is handled,
    as torch does) fails with ENOSPC."""
    import contextlib
    import errno
    import io

    import torch

    import hersd.engine.train as train_module

    full = {"on": False}
    run_epoch, fsync, save = train_module.run_epoch, os.fsync, torch.save

    def filling_run_epoch(state, epoch, rate=None):
        full["on"] = epoch >= 3
        return run_epoch(state, epoch, rate)

    def full_fsync(fd):
        if full["on"]:
            raise OSError(errno.ENOSPC, "No space left on device")
        fsync(fd)

    def full_save(obj, f, *args, **kwargs):
        if not full["on"] or not isinstance(f, (str, os.PathLike, io.BufferedWriter)):  # a counter stores nothing
            return save(obj, f, *args, **kwargs)
        with open(f, "wb") if isinstance(f, (str, os.PathLike)) else contextlib.nullcontext(f) as stream:
            stream.write(b"\0" * 512)
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError:
            raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 704 vs 598")

    monkeypatch.setattr(train_module, "run_epoch", filling_run_epoch)
    monkeypatch.setattr(os, "fsync", full_fsync) if where == "log" else monkeypatch.setattr(torch, "save", full_save)


@pytest.mark.parametrize("where, name", [("log", "run.mcap"), ("checkpoint", "checkpoint.pt")])
def test_a_full_disk_is_one_line_with_exit_2_keeps_the_last_epoch_checkpointed_and_the_run_resumes(
        tmp_path, capsys, monkeypatch, where, name):
    args = [*TINY, "epochs=4", f"results_dir={tmp_path / 'cut'}"]
    _fill_the_disk_at_epoch_3(monkeypatch, where)
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    monkeypatch.undo()  # space freed
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    directory = run_dir(compose(args))
    assert err.startswith(f"hersd-train: error: no space left on the device of {directory / name}: writing it needs ")
    assert len(err.splitlines()) == 1 and err.endswith("the run keeps epochs 1-2: free some and run the same command "
                                                       "again to resume at epoch 3")
    assert sorted(path.name for path in directory.iterdir()) == ["checkpoint.pt", "run.lock", "run.mcap"]  # no .tmp
    assert list(read_run(directory).epochs["epoch"]) == ([1, 2] if where == "log" else [1, 2, 3])
    main(args)
    reference = train(compose([*TINY, "epochs=4", f"results_dir={tmp_path / 'ref'}"]))
    log = read_run(directory)
    assert log.complete and [s["resumed_from_epoch"] for s in log.sessions] == [0, 2]
    pd.testing.assert_frame_equal(metrics(directory / "run.mcap"), metrics(reference))


def test_a_spec_edited_after_it_was_resolved_is_refused_before_any_work(tmp_path):
    """``spec.config.seed = 7`` after ``resolve`` trained seed 7 into seed 0's folder, its log naming seed 0's
    hash: the spec's identity, hash and folder are checked against its config first."""
    from hersd.contract.errors import ConfigError
    from hersd.contract.runspec import resolve

    spec = resolve(compose([*TINY, "epochs=1", f"results_dir={tmp_path}"]))
    spec.config.seed = 7
    with pytest.raises(ConfigError, match=r"changed after it was resolved \(seed\)"):
        train(spec)
    assert not list(tmp_path.iterdir())  # nothing written
