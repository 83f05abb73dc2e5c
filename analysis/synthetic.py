"""Synthetic run logs with chosen success curves, for tests, benchmarks and demos.

They are written with :class:`hersd.contract.runlog.RunLogWriter`, so they read back exactly like
training's logs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hersd.contract.config import TrainConfig, config_record
from hersd.contract.runlog import LOG_NAME, RunLogWriter
from hersd.contract.runstore import RunFolder, config_hash


def epoch_records(config: TrainConfig, test_success: np.ndarray) -> list[dict[str, Any]]:
    """One record per epoch (every EPOCH_FIELDS field) around a given test-success curve.

    ``test_success`` has shape (n,) with n <= config.epochs; the other fields follow from it
    and the schedule: relabel_rate = share_hindsight = eps(k), the real share split by the
    train success, Q rising from -10 towards 0 with success.
    """
    success = np.asarray(test_success, dtype=float)
    k = np.arange(1, len(success) + 1)
    train_success = 0.9 * success
    rate = np.array([config.schedule.rate(int(epoch), config.epochs, train_success[:int(epoch) - 1]) for epoch in k])
    cycles = config.task.cycles_per_epoch
    mep = config.algo.mep.enabled
    columns = {
        "epoch": k,
        "relabel_rate": rate,
        "test_success": success,
        "train_success": train_success,
        "q_mean": -10.0 * (1.0 - success) - 1.0,
        "q_std": 2.0 + success,
        "critic_loss": 0.1 * (1.0 - success) + 0.01,
        "actor_loss": 10.0 * (1.0 - success) + 1.0,
        "share_hindsight": rate,
        "share_real_success": (1.0 - rate) * 0.5 * train_success,
        "share_real_failure": (1.0 - rate) * (1.0 - 0.5 * train_success),
        "env_steps": k * cycles * config.ddpg.rollouts_per_cycle * 50,
        "updates": k * cycles * config.ddpg.batches_per_cycle,
        "episodes_stored": k * cycles * config.ddpg.rollouts_per_cycle,
        "rollout_seconds": np.full(len(k), 10.0),
        "update_seconds": np.full(len(k), 30.0),
        "eval_seconds": np.full(len(k), 5.0),
        "epoch_seconds": np.full(len(k), 45.0),
        "mep_fit_seconds": np.full(len(k), 2.0 if mep else np.nan),
        "priority_entropy": np.full(len(k), 7.0 if mep else np.nan),
    }
    return [{name: values[i].item() for name, values in columns.items()} for i in range(len(k))]


def write_run(folder: Path, config: TrainConfig, test_success: np.ndarray, complete: bool = True,
              meta: dict | None = None, **fields: np.ndarray) -> Path:
    """Write ``<folder>/run.mcap`` for ``config`` with the given test-success curve; returns its path.

    ``complete`` marks the run finished (the curve should then have config.epochs values);
    ``fields`` replace epoch fields of :func:`epoch_records` (name -> values, shape like the curve),
    e.g. ``share_hindsight=np.full(n, 0.8)``; ``meta`` replaces metadata fields, e.g. ``command``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = {"run_id": config_hash(config), "config": config_record(config), "seed": config.seed,
            "versions": {"hersd": "synthetic"}, "git_commit": None, "command": "analysis.synthetic",
            "start_time": "2025-01-01T00:00:00+0000", "resumed_from_epoch": 0, **(meta or {})}
    writer = RunLogWriter(folder / LOG_NAME, meta)
    records = epoch_records(config, test_success)
    with writer.batch():  # one rewrite of the file, not one per epoch
        for index, record in enumerate(records):
            writer.write_epoch({**record, **{name: np.asarray(values)[index].item() for name, values in fields.items()}})
        if complete:
            writer.finish(len(records))
        else:
            writer.close()
    return folder / LOG_NAME


def write_animation(folder: Path, epoch: int, width: int = 48, height: int = 36, frames: int = 4) -> Path:
    """A small looping GIF standing in for a policy animation, ``<folder>/policy/epoch_<epoch>.gif`` next to a
    run's log (what training's ``render_every`` writes): a square moving across a grey field; returns its path."""
    from PIL import Image  # matplotlib's dependency: only when a test or benchmark wants animations

    images = []
    for index in range(frames):
        pixels = np.full((height, width, 3), 200, np.uint8)
        left = index * (width - height // 2) // max(1, frames - 1)
        pixels[height // 4: 3 * height // 4, left: left + height // 2] = (40, 170, 60)
        images.append(Image.fromarray(pixels).quantize(8))
    path = RunFolder(Path(folder)).animation(epoch)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:], duration=100, loop=0)
    return path
