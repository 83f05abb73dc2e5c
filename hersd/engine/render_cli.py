"""``hersd-render RUN_DIR``: a run's policy animated from its checkpoint, as training animates it
(:mod:`hersd.engine.render`), the run's config read back from its log.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path
from typing import Any, Sequence

import torch

from hersd.contract.config import TrainConfig, learner_node, to_train_config
from hersd.contract.errors import ConfigError, DiskFullError
from hersd.contract.runlog import LOG_NAME, RunLogError, read_run
from hersd.contract.runstore import CHECKPOINT_NAME, RunFolder
from hersd.contract.schedules import schedule_from_record
from hersd.engine.denormals import set_intra_op_threads
from hersd.engine.envs.make import env_spec, make_env
from hersd.engine.learners import GoalConditionedLearner
from hersd.engine.render import DEFAULT_EPISODES, RenderError, render_policy
from hersd.engine.run_state import discounting, load_checkpoint, make_agent


class RenderInputError(ValueError):
    """``hersd-render`` was given a folder or epoch it cannot render (one line, exit 2)."""


def config_from_log(config: dict[str, Any]) -> TrainConfig:
    """The TrainConfig of a log's ``/run/meta`` config dict (fields it lacks take their defaults; of its schedule
    record only the settings its kind has: the paper's kinds log the flat schema's other fields too; an outside
    learner's settings under the key it was configured by)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    if config.get("schedule"):
        schedule = schedule_from_record(config["schedule"])
        config = {**config, "schedule": {"kind": config["schedule"]["kind"],
                                         **{item.name: getattr(schedule, item.name) for item in schedule.params()}}}
    if config.get("learner"):
        config = {**config, "learner": learner_node(config["learner"])}
    try:
        return to_train_config(OmegaConf.merge(OmegaConf.structured(TrainConfig), config))
    except OmegaConfBaseException as err:
        raise ConfigError(str(err).splitlines()[0]) from None


def load_run(directory: Path, epoch: int | None) -> tuple[TrainConfig, dict[str, Any]]:
    """A run directory's config (from its log) and checkpoint; RenderInputError (one line) when there is no
    run, no checkpoint, or ``epoch`` is not the checkpoint's."""
    folder = RunFolder(directory)
    log_path, checkpoint_path = folder.log, folder.checkpoint
    if not log_path.is_file():
        raise RenderInputError(f"{directory}: not a run directory (no {LOG_NAME})")
    if not checkpoint_path.is_file():
        raise RenderInputError(f"{directory}: no {CHECKPOINT_NAME} to render from (a run removes it when it "
                               f"completes unless keep_checkpoint=true)")
    try:
        cfg = config_from_log(read_run(log_path).meta["config"])
    except (RunLogError, ConfigError, KeyError) as err:
        raise RenderInputError(f"{log_path}: cannot read the run's config ({err})") from None
    try:
        checkpoint = load_checkpoint(checkpoint_path, torch.device("cpu"))
    except Exception as err:  # torch raises RuntimeError, EOFError or UnpicklingError on a damaged file
        raise RenderInputError(f"{checkpoint_path} is unreadable ({type(err).__name__})") from None
    if epoch is not None and epoch != checkpoint["epoch"]:
        raise RenderInputError(f"{directory}: only the checkpoint's epoch, {checkpoint['epoch']}, can be rendered "
                               f"(asked for epoch {epoch})")
    return cfg, checkpoint


def policy_from_checkpoint(cfg: TrainConfig, checkpoint: dict[str, Any]) -> GoalConditionedLearner:
    """The run's learner on the CPU with the checkpoint's networks and normalisers."""
    env = make_env(cfg.task)
    spec = env_spec(env)
    env.close()
    acting = copy.copy(cfg)
    acting.precision = "fp32"  # acting is float32 at either precision: a bf16 run renders on any CPU
    agent = make_agent(acting, spec, *discounting(cfg, spec), torch.device("cpu"))
    agent.load_state_dict(checkpoint["agent"])
    return agent


class _OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line on stderr, exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv: Sequence[str] | None = None) -> int:
    """``hersd-render RUN_DIR [--epoch K] [--episodes N] [--out GIF]``: exit 0, 2 (bad input, a GIF it cannot
    write: a full disk is one line naming it and the bytes it needs) or 1 (no render)."""
    parser = _OneLineParser(prog="hersd-render", description="Animate a run's policy from its checkpoint: "
                            "deterministic test episodes into RUN_DIR/policy/epoch_<K>.gif.")
    parser.add_argument("run_dir", type=Path, help="a run directory (holding run.mcap and checkpoint.pt)")
    parser.add_argument("--epoch", type=int, help="the checkpoint's epoch (the only one that can be rendered)")
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, help="test episodes to show (default 2)")
    parser.add_argument("--out", type=Path, help="the GIF to write (default RUN_DIR/policy/epoch_<K>.gif)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    if args.out is not None and args.out.is_dir():
        parser.error(f"--out {args.out} is a folder; give the GIF's file name")
    try:
        cfg, checkpoint = load_run(args.run_dir, args.epoch)
        agent = policy_from_checkpoint(cfg, checkpoint)
        set_intra_op_threads(cfg.flush_denormal)
    except (RenderInputError, ConfigError) as err:
        print(f"hersd-render: error: {err}", file=sys.stderr)
        return 2
    epoch = checkpoint["epoch"]
    try:
        animation = render_policy(agent, cfg, epoch, args.out or RunFolder(args.run_dir).animation(epoch), args.episodes)
    except DiskFullError as err:  # one line: the GIF, the bytes it needs, those free
        print(f"hersd-render: error: {err}", file=sys.stderr)
        return 2
    except RenderError as err:
        print(f"hersd-render: error: {err}", file=sys.stderr)
        return 1
    except OSError as err:  # the GIF's folder or file cannot be written
        print(f"hersd-render: error: cannot write {err.filename}: {err.strerror}", file=sys.stderr)
        return 2
    outcomes = ", ".join("success" if success else "failure" for success in animation.successes)
    print(f"{animation.path} (epoch {epoch}, {animation.frames} frames, {animation.path.stat().st_size // 1024} KB, "
          f"{animation.seconds:.1f} s; episodes: {outcomes})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
