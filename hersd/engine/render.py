"""Animations of a policy: deterministic test episodes rendered headless into a small GIF.

Training writes ``<run dir>/policy/epoch_<k>.gif`` every ``render_every`` epochs and at the
last one (:func:`renders_at`), after the epoch is logged and checkpointed; a run resumed after
a stop during that render draws it first (:func:`owed_animation`). ``hersd-render RUN_DIR``
renders from a run's checkpoint (:mod:`hersd.engine.render_cli`). A render has its own env
(``render_mode="rgb_array"``, a camera framed on the table) and its own random stream (a
Generator seeded from the run's seed and the epoch): the run's envs, its RNGs and the torch RNG
are untouched, so a run's metrics do not depend on whether it renders. The same run and epoch
give the same episodes, whether training or ``hersd-render`` draws them.

Without ``MUJOCO_GL`` and without a display, :func:`headless_backend` picks EGL, else OSMesa,
each tried first in a short subprocess: PyOpenGL's platform cannot change once it is loaded.
"""

from __future__ import annotations

import functools
import io
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from PIL import Image

from hersd.contract.config import TaskConfig, TrainConfig
from hersd.contract.errors import DiskFullError, full_disk
from hersd.contract.runlog import replace_file
from hersd.contract.runstore import POLICY_DIR, RunFolder
from hersd.engine.denormals import denormals_flushed
from hersd.engine.envs.make import env_spec, make_env, step_success
from hersd.engine.learners import GoalConditionedLearner

DEFAULT_EPISODES = 2
WIDTH, HEIGHT = 240, 180  # pixels of a frame
FRAME_STEP = 2  # one frame every 2nd env step: the GIF plays in real time at the env's dt (Fetch: 80 ms a frame)
END_PAUSE_MS = 800  # the last frame of an episode stays this long
PALETTE_COLOURS = 64  # one palette for the whole GIF, no dithering: flat colours compress well
STATUS_ROWS = 4  # pixel rows at the bottom of a frame: green while the goal is reached, grey otherwise
STATUS_COLOURS = {True: (40, 170, 60), False: (150, 150, 150)}
RENDER_SALT = 0x676966  # keeps the render stream apart from any other stream of the run's seed
# The free camera of each env family (the longest matching prefix of the env id wins); other envs keep theirs.
CAMERAS = {"Fetch": {"lookat": (1.3, 0.75, 0.5), "distance": 1.1, "azimuth": 160.0, "elevation": -35.0},
           "FetchSlide": {"lookat": (1.45, 0.75, 0.42), "distance": 1.5, "azimuth": 180.0, "elevation": -45.0}}
GL_PACKAGES = "apt-get install libegl1 libgl1-mesa-dri (EGL) or libosmesa6 (OSMesa)"


class RenderError(RuntimeError):
    """The policy could not be rendered; the message is one line saying why (and what to install)."""


class GifDiskFullError(DiskFullError, RenderError):
    """A GIF its disk had no room for, in one line (the GIF, the bytes it needs, those free): a full disk (exit 2 of
    ``hersd-render``) and a failed render (one warning line while training, which goes on)."""


@dataclass
class Animation:
    """A written GIF: its path, the seconds the render took, its frames and each episode's success."""

    path: Path
    seconds: float
    frames: int
    successes: list[bool]


def renders_at(render_every: int, epoch: int, epochs: int) -> bool:
    """Whether training animates the policy after ``epoch`` of ``epochs`` (every N-th and the last; 0: never)."""
    return render_every > 0 and (epoch % render_every == 0 or epoch == epochs)


def partial_path(path: Path) -> Path:
    """Where a GIF is written before it is renamed to ``path``: ``policy/epoch_<k>.gif.partial``."""
    return path.with_name(path.name + ".partial")


def owed_animation(folder: RunFolder, render_every: int, epochs_done: int, epochs: int) -> int | None:
    """The epoch whose animation a run resumed after ``epochs_done`` still owes (it was stopped while rendering it,
    after the epoch's checkpoint), or None; removes the GIFs a stopped render left half written."""
    for stale in (folder.path / POLICY_DIR).glob("epoch_*.gif.partial"):
        stale.unlink(missing_ok=True)
    owed = epochs_done > 0 and renders_at(render_every, epochs_done, epochs)
    return epochs_done if owed and not folder.animation(epochs_done).exists() else None


# --------------------------------------------------------------------------- headless OpenGL
def _backend_works(backend: str) -> bool:
    """Whether MuJoCo can open an OpenGL context with ``backend`` (tried in a subprocess)."""
    code = f"from mujoco.{backend} import GLContext; GLContext(8, 8).free()"
    try:
        return subprocess.run([sys.executable, "-c", code], env={**os.environ, "MUJOCO_GL": backend},
                              capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


@functools.cache
def _first_working_backend() -> str | None:
    return next((backend for backend in ("egl", "osmesa") if _backend_works(backend)), None)


def headless_backend() -> str | None:
    """Set MUJOCO_GL before MuJoCo's GL loads: kept if set; unset with a display (gymnasium tries GLFW
    first); else egl or osmesa, whichever works. Returns it; RenderError when neither works."""
    if os.environ.get("MUJOCO_GL") or os.environ.get("DISPLAY"):
        return os.environ.get("MUJOCO_GL")
    backend = _first_working_backend()
    if backend is None:
        raise RenderError(f"no headless OpenGL for MuJoCo (EGL and OSMesa both failed); {GL_PACKAGES}")
    os.environ["MUJOCO_GL"] = backend
    return backend


# --------------------------------------------------------------------------- frames
def camera_config(env_id: str) -> dict[str, Any] | None:
    """The free camera (lookat, distance, azimuth, elevation) for ``env_id``, or None (the env's own)."""
    prefixes = [prefix for prefix in CAMERAS if env_id.startswith(prefix)]
    if not prefixes:
        return None
    camera = CAMERAS[max(prefixes, key=len)]
    return {**camera, "lookat": np.array(camera["lookat"])}


def make_render_env(task: TaskConfig) -> Any:
    """The task's env drawing ``(HEIGHT, WIDTH, 3)`` frames from :func:`camera_config`, its viewer opened
    (RenderError, one line, when OpenGL fails)."""
    camera = camera_config(task.env_id)
    env = make_env(task, render_mode="rgb_array", width=WIDTH, height=HEIGHT,
                   **({"default_camera_config": camera} if camera else {}))
    try:
        env.reset(seed=0)
        env.render()
    except Exception as err:  # GL errors come as ImportError, RuntimeError, mujoco.FatalError, OpenGL errors
        close_render_env(env)
        first_line = (str(err).strip().splitlines() or [""])[0][:160]
        raise RenderError(f"MuJoCo cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL')} "
                          f"({type(err).__name__}: {first_line}); {GL_PACKAGES}") from None
    return env


def close_render_env(env: Any) -> None:
    """Free the viewer's MuJoCo GL objects in its own OpenGL context, then close the env. (Left to the garbage
    collector, they are freed in whatever context is current then: a later render's, whose frames turn black.)"""
    viewer = getattr(getattr(env, "mujoco_renderer", None), "viewer", None)
    if viewer is not None and getattr(viewer, "con", None) is not None:
        viewer.make_context_current()
        viewer.con.free()
    env.close()


def _frame(env: Any, success: bool) -> np.ndarray:
    """The env's current image (HEIGHT, WIDTH, 3) uint8 with the status rows at its bottom."""
    frame = np.array(env.render(), dtype=np.uint8)
    frame[-STATUS_ROWS:] = STATUS_COLOURS[success]
    return frame


def episode_frames(env: Any, agent: GoalConditionedLearner, horizon: int, seed: int,
                   rng: np.random.Generator, flush_denormal: bool) -> tuple[list[np.ndarray], bool]:
    """One deterministic test episode from ``env.reset(seed=seed)`` -> (its frames: the start, then every
    FRAME_STEP-th step and the last, each (HEIGHT, WIDTH, 3) uint8; success at the last step). The policy
    acts with denormals flushed to zero as in the run (``flush_denormal``)."""
    obs = env.reset(seed=seed)[0]
    success = False
    frames = [_frame(env, success)]
    for step in range(1, horizon + 1):
        with denormals_flushed(flush_denormal):
            action = agent.act(obs["observation"][None].astype(np.float32),
                               obs["desired_goal"][None].astype(np.float32), explore=False, rng=rng)[0]
        obs, _reward, _terminated, _truncated, info = env.step(action)
        success = step_success(info)
        if step % FRAME_STEP == 0 or step == horizon:
            frames.append(_frame(env, success))
    return frames, success


def render_frames(agent: GoalConditionedLearner, cfg: TrainConfig, epoch: int,
                  episodes: int = DEFAULT_EPISODES) -> tuple[np.ndarray, list[int], list[bool]]:
    """``episodes`` deterministic test episodes of the policy after ``epoch`` -> (frames (n, HEIGHT, WIDTH, 3)
    uint8, each frame's duration in ms (n,), each episode's success). The env seeds come from a Generator
    of (RENDER_SALT, cfg.seed, epoch): the run's own streams are not touched."""
    headless_backend()
    rng = np.random.default_rng([RENDER_SALT, cfg.seed, epoch])
    env = make_render_env(cfg.task)
    try:
        horizon = env_spec(env).horizon
        frame_ms = round(1000 * float(getattr(env, "dt", 0.04)) * FRAME_STEP)
        frames, durations, successes = [], [], []
        for seed in rng.integers(2**31, size=episodes):
            episode, success = episode_frames(env, agent, horizon, int(seed), rng, cfg.flush_denormal)
            frames += episode
            durations += [frame_ms] * (len(episode) - 1) + [END_PAUSE_MS]
            successes.append(success)
    finally:
        close_render_env(env)
    return np.stack(frames), durations, successes


def write_gif(frames: np.ndarray, durations: Sequence[int], path: Path) -> int:
    """Frames (n, H, W, 3) uint8 -> a looping GIF at ``path`` (encoded in memory, written whole to its
    :func:`partial_path`, then renamed into place: a write that fails leaves no file; on a full disk it raises
    :class:`GifDiskFullError`, one line naming ``path`` and the bytes the GIF needs; another OSError names
    ``path``); one palette of PALETTE_COLOURS for every frame. Returns its size in bytes."""
    sample = frames[:: max(1, len(frames) // 8)]  # the palette from a few frames spread over the episodes
    palette = Image.fromarray(sample.reshape(-1, frames.shape[2], 3)).quantize(
        PALETTE_COLOURS, method=Image.Quantize.FASTOCTREE)  # keeps the small red goal red
    images = [Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE) for frame in frames]
    encoded = io.BytesIO()
    images[0].save(encoded, format="GIF", save_all=True, append_images=images[1:], duration=list(durations), loop=0)
    data = encoded.getvalue()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        replace_file(path, data, temporary=partial_path(path), sync=False)
    except (OSError, DiskFullError) as err:
        if full_disk(err):
            raise GifDiskFullError(path, len(data)) from None
        raise OSError(err.errno, err.strerror or str(err), str(path)) from None
    return len(data)


def render_policy(agent: GoalConditionedLearner, cfg: TrainConfig, epoch: int, path: Path,
                  episodes: int = DEFAULT_EPISODES) -> Animation:
    """Render ``episodes`` test episodes of ``agent`` (the policy after ``epoch``) into the GIF ``path``."""
    start = time.perf_counter()
    frames, durations, successes = render_frames(agent, cfg, epoch, episodes)
    write_gif(frames, durations, path)
    return Animation(path, time.perf_counter() - start, len(frames), successes)
