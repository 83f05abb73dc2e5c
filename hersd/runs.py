"""Where a run lives: a readable directory name derived from its config plus a short hash.

``results/<task>/<algo>/<schedule>/seed<N>-<hash>/run.mcap``; the hash covers every field
that changes what the run computes, so two configs never share a directory and the same
config always maps to the same one (which is what lets sweeps skip and resume runs).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

from hersd.config import ScheduleConfig, TrainConfig

# Fields that change where or how loudly a run is written, not what it computes.
_NOT_HASHED = ("results_dir", "run_dir", "quiet", "checkpoint_every", "keep_checkpoint")


def schedule_tag(schedule: ScheduleConfig) -> str:
    """e.g. ``constant-0.8``, ``linear-b1_0.25``, ``exponential-b1_0.5-b2_-1``."""
    if schedule.kind == "constant":
        return f"constant-{schedule.eps:g}"
    if schedule.kind == "linear":
        return f"linear-b1_{schedule.beta1:g}"
    return f"exponential-b1_{schedule.beta1:g}-b2_{schedule.beta2:g}"


def config_hash(cfg: TrainConfig) -> str:
    """8 hex digits identifying everything that determines the run's result."""
    content = {k: v for k, v in asdict(cfg).items() if k not in _NOT_HASHED}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:8]


def run_dir(cfg: TrainConfig) -> Path:
    """The run's directory: ``cfg.run_dir`` if set, else derived from the config."""
    if cfg.run_dir is not None:
        return Path(cfg.run_dir)
    return (Path(cfg.results_dir) / cfg.task.name / cfg.algo.name / schedule_tag(cfg.schedule)
            / f"seed{cfg.seed}-{config_hash(cfg)}")
