"""Policy animations (hersd/engine/render.py) and hersd-render (hersd/engine/render_cli.py): rendering changes
nothing a run computes, the GIF shows the scene, hersd-render draws a checkpoint's epoch as training did, a run
stopped while rendering draws that animation when resumed, and every failure is one line leaving no file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import TINY, command, full_disk_writes, metrics
from PIL import Image, ImageSequence
from user_learners import LATE

import hersd.engine.render
import hersd.engine.train
from hersd.contract.compose import compose_train
from hersd.contract.errors import DiskFullError
from hersd.contract.runlog import read_run
from hersd.engine.render import RenderError, close_render_env, headless_backend, make_render_env, renders_at
from hersd.engine.render_cli import main
from hersd.contract.runstore import CHECKPOINT_NAME, RunFolder, run_dir
from hersd.engine.train import train

RUN = [*(o for o in TINY if o != "render_every=0"), "epochs=2", "seed=5", "quiet=true", "threads=1"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """The same tiny FetchReach run rendering after every epoch (checkpoint kept) and never -> their logs."""
    root = tmp_path_factory.mktemp("render")
    return {every: train(compose_train([*RUN, f"render_every={every}", "keep_checkpoint=true",
                                        f"results_dir={root / f'every{every}'}"]))
            for every in ("1", "0")}


def gif_frames(path: Path) -> list[np.ndarray]:
    """Every frame of a GIF as (H, W, 3) uint8."""
    with Image.open(path) as image:
        return [np.array(frame.convert("RGB")) for frame in ImageSequence.Iterator(image)]


def test_rendering_changes_no_metric_and_no_run_folder(runs):
    rendered, plain = runs["1"], runs["0"]
    pd.testing.assert_frame_equal(metrics(rendered), metrics(plain))
    assert rendered.relative_to(rendered.parents[4]) == plain.relative_to(plain.parents[4])  # <task>/.../seedN-<hash>
    assert list(RunFolder(rendered.parent).animations()) == [1, 2]
    assert RunFolder(plain.parent).animations() == {}


def test_the_animation_shows_the_scene_moving(runs):
    path = RunFolder(runs["1"].parent).animation(2)
    frames = gif_frames(path)
    assert frames[0].shape == (hersd.engine.render.HEIGHT, hersd.engine.render.WIDTH, 3)
    assert len(frames) == 2 * (50 // hersd.engine.render.FRAME_STEP + 1)  # 2 episodes: the start and every 2nd step
    assert all(frame.std() > 20 for frame in frames[::10])  # not blank: table, robot, floor
    assert all(frame.std() > 20 for frame in gif_frames(RunFolder(runs["1"].parent).animation(1))[::10])
    assert np.abs(frames[0].astype(int) - frames[len(frames) // 4]).mean() > 0.5  # the arm moved
    assert 20_000 < path.stat().st_size < 400_000


def test_hersd_render_draws_the_checkpoints_epoch_as_training_did(runs, tmp_path, capsys):
    directory = runs["1"].parent
    out = tmp_path / "again.gif"
    assert main([str(directory), "--epoch", "2", "--out", str(out)]) == 0
    assert out.read_bytes() == RunFolder(directory).animation(2).read_bytes()
    assert f"{out} (epoch 2, 52 frames" in capsys.readouterr().out


def test_hersd_render_draws_a_run_of_an_outside_learner_with_settings_of_its_own(tmp_path):
    """Its log records the settings under the class path; the run is configured by ``learner.td3late.*``."""
    (tmp_path / "user_late.py").write_text(LATE)
    trained = command("hersd.engine.cli:main", [*RUN, "epochs=1", "keep_checkpoint=true", f"results_dir={tmp_path}",
                                                 "learner._target_=user_late.TD3Late", "learner.td3late.actor_start=2"],
                      tmp_path)
    directory = Path(trained.stdout.strip().splitlines()[-1]).parent
    drawn = command("hersd.engine.render_cli:main", [str(directory), "--out", str(tmp_path / "late.gif")], tmp_path)
    assert f"{tmp_path / 'late.gif'} (epoch 1, 52 frames" in drawn.stdout


def exit_code(args: list[str]) -> int:
    """hersd-render's exit status for ``args`` (argparse's errors exit through SystemExit)."""
    try:
        return main(args)
    except SystemExit as exited:
        return exited.code


@pytest.mark.parametrize("args, expected", [
    (["--epoch", "1"], "only the checkpoint's epoch, 2, can be rendered (asked for epoch 1)"),
    (["--episodes", "0"], "--episodes must be at least 1, got 0"),
])
def test_hersd_render_refuses_another_epoch_in_one_line(runs, capsys, args, expected):
    assert exit_code([str(runs["1"].parent), *args]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1, err


def test_hersd_render_refuses_an_out_it_cannot_write_in_one_line(runs, tmp_path, capsys):
    (tmp_path / "file").write_text("")
    for out, expected in ((tmp_path, f"--out {tmp_path} is a folder"), (tmp_path / "file" / "x.gif", "cannot write")):
        assert exit_code([str(runs["1"].parent), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err
    assert sorted(path.name for path in tmp_path.iterdir()) == ["file"]


def test_hersd_render_on_a_full_disk_is_one_line_naming_the_gif_and_its_size_and_leaves_no_file(
        runs, tmp_path, monkeypatch, capsys):
    full_disk_writes(monkeypatch, "*.gif.partial")  # after the GIF's first bytes
    out = tmp_path / "full.gif"
    assert exit_code([str(runs["1"].parent), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    size = runs["1"].parent.joinpath("policy", "epoch_2.gif").stat().st_size  # the same epoch's GIF, drawn in training
    needs = str(DiskFullError(out, size)).rsplit(", ", 1)[0]  # "... of <out>: writing it needs <size>"
    assert err.startswith(f"hersd-render: error: {needs}, ") and needs.endswith(("bytes", "KB"))
    assert err.count("\n") == 1 and err.endswith("free; free some and run the same command again\n")
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_while_training_renders_is_a_warning_naming_the_gif_and_its_size_and_leaves_no_file(
        tmp_path, monkeypatch, capsys):
    full_disk_writes(monkeypatch, "*.gif.partial")
    log = train(compose_train([*RUN, "epochs=1", "render_every=1", f"results_dir={tmp_path}"]))
    err = capsys.readouterr().err
    gif = RunFolder(log.parent).animation(1)
    assert err.count("\n") == 1 and f"epoch 1: no policy animation: no space left on the device of {gif}: " \
                                     f"writing it needs " in err and " free; " in err
    assert list(gif.parent.iterdir()) == [] and read_run(log).complete  # the run went on


def test_a_run_stopped_while_rendering_draws_that_animation_when_resumed(runs, tmp_path, monkeypatch):
    """Killed during epoch 1's render (after its checkpoint), a 0-byte ``epoch_1.gif.partial`` left: the resumed
    run removes it and draws epoch 1's animation first, the same GIF an uninterrupted run drew."""
    class Killed(BaseException):
        pass

    def killed(agent, cfg, epoch, path, *args):
        Path(f"{path}.partial").parent.mkdir(parents=True, exist_ok=True)
        Path(f"{path}.partial").write_bytes(b"")
        raise Killed

    args = [*RUN, "render_every=1", "keep_checkpoint=true", f"results_dir={tmp_path}"]
    monkeypatch.setattr(hersd.engine.train, "render_policy", killed)
    with pytest.raises(Killed):
        train(compose_train(args))
    folder = RunFolder(runs["1"].parent)
    resumed = RunFolder(run_dir(compose_train(args)))
    assert [path.name for path in resumed.animation(1).parent.iterdir()] == ["epoch_1.gif.partial"]
    monkeypatch.undo()
    train(compose_train(args))
    assert sorted(path.name for path in resumed.animation(1).parent.iterdir()) == ["epoch_1.gif", "epoch_2.gif"]
    assert all(resumed.animation(k).read_bytes() == folder.animation(k).read_bytes() for k in (1, 2))
    pd.testing.assert_frame_equal(metrics(resumed.log), metrics(folder.log))


def test_hersd_render_needs_a_run_with_a_checkpoint(tmp_path, capsys):
    assert exit_code([str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"hersd-render: error: {tmp_path}: not a run directory (no run.mcap)\n"
    log = train(compose_train([*RUN, "epochs=1", "render_every=0", f"results_dir={tmp_path}"]))
    assert not (log.parent / CHECKPOINT_NAME).exists()
    assert exit_code([str(log.parent)]) == 2
    err = capsys.readouterr().err
    assert f"{log.parent}: no checkpoint.pt to render from" in err and err.count("\n") == 1


def test_a_failed_render_is_a_warning_and_the_run_goes_on(tmp_path, monkeypatch, capsys):
    def fail(*args, **kwargs):
        raise RenderError("no headless OpenGL for MuJoCo (EGL and OSMesa both failed); apt-get install libosmesa6")

    monkeypatch.setattr(hersd.engine.train, "render_policy", fail)
    log = train(compose_train([*RUN, "epochs=1", "render_every=1", f"results_dir={tmp_path}"]))
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "epoch 1: no policy animation: no headless OpenGL" in err
    assert metrics(log)["epoch"].tolist() == [1] and RunFolder(log.parent).animations() == {}


def test_headless_rendering_picks_egl_then_osmesa_else_names_the_packages(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "unset below")
    monkeypatch.delenv("MUJOCO_GL")
    monkeypatch.delenv("DISPLAY", raising=False)
    for works, expected in ((lambda backend: True, "egl"), (lambda backend: backend == "osmesa", "osmesa")):
        hersd.engine.render._first_working_backend.cache_clear()
        monkeypatch.setattr(hersd.engine.render, "_backend_works", works)
        assert headless_backend() == expected == hersd.engine.render.os.environ.pop("MUJOCO_GL")
    hersd.engine.render._first_working_backend.cache_clear()
    monkeypatch.setattr(hersd.engine.render, "_backend_works", lambda backend: False)
    with pytest.raises(RenderError, match="apt-get install libegl1 libgl1-mesa-dri .EGL. or libosmesa6"):
        headless_backend()
    hersd.engine.render._first_working_backend.cache_clear()
    monkeypatch.setenv("MUJOCO_GL", "osmesa")  # the user's choice is kept
    assert headless_backend() == "osmesa"


def test_renders_at_every_nth_epoch_and_the_last():
    assert [k for k in range(1, 121) if renders_at(50, k, 120)] == [50, 100, 120]
    assert [k for k in range(1, 4) if renders_at(0, k, 3)] == []


def test_a_render_env_collected_late_leaves_later_renders_alone():
    """close_render_env frees the viewer's GL objects in its own context: a closed env the garbage collector
    frees while another render's context is current must not blank that render's frames."""
    headless_backend()
    task = compose_train(["task=reach"]).task
    closed: list = []
    for _ in range(3):
        env = make_render_env(task)
        closed.clear()  # the previous env, closed already, freed now while this one's context is current
        assert np.array(env.render()).std() > 20
        close_render_env(env)
        closed.append(env)
        del env


def test_every_committed_log_gives_back_the_config_of_its_folder():
    """hersd-render reads a run's config from its log: for every committed log (the paper's kinds log the flat
    schema's fields besides their own) that config maps to the log's own folder."""
    from hersd.engine.render_cli import config_from_log
    from hersd.contract.runlog import read_run
    from hersd.contract.runstore import run_dir

    results = Path(__file__).resolve().parent.parent / "results"
    logs = sorted(results.rglob("run.mcap"))
    assert logs
    for log in logs:
        cfg = config_from_log(read_run(log).meta["config"])
        cfg.results_dir = str(results)
        assert run_dir(cfg) == log.parent, log
