"""One training run: Algorithm 1 of the seed paper (DDPG + HER with a relabel-rate schedule).

``hersd-train task=push schedule=linear schedule.beta1=0.25 seed=0 epochs=50`` composes
``conf/train.yaml`` with Hydra, runs (or resumes) the run and prints its log's path. The
loop in :func:`train` reads top to bottom like Algorithm 1: per epoch k, fix eps(k); per
cycle, collect episodes, store them, update the normalisers, take ``batches_per_cycle``
updates on freshly relabelled minibatches, then move the targets; test at the epoch end.
"""

from __future__ import annotations

import fcntl
import os
import platform
import subprocess
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch

import hersd
from hersd.config import ConfigError, TrainConfig, register_schemas, to_train_config
from hersd.ddpg import DDPG
from hersd.envs import EnvSpec, env_spec, goal_reward, make_env
from hersd.mep import EpisodePrioritizer
from hersd.replay import EpisodeBuffer, Episodes, sample_transitions
from hersd.runlog import LOG_NAME, RunLogError, RunLogWriter, read_run
from hersd.runs import config_hash, run_dir
from hersd.schedules import relabel_rate

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"
CHECKPOINT_NAME = "checkpoint.pt"


class RunLockedError(RuntimeError):
    """Another process is running the same configuration."""


class RunStateError(RuntimeError):
    """A run directory holds a checkpoint or log that cannot be read; the message says what to do."""


# --------------------------------------------------------------------------- rollouts
def run_episodes(envs: list, agent: DDPG, horizon: int, explore: bool,
                 rng: np.random.Generator) -> tuple[Episodes, np.ndarray]:
    """One episode in each env, stepped in lockstep -> (Episodes of n = len(envs), success (n,) bool)."""
    n = len(envs)
    first = [env.reset()[0] for env in envs]
    obs = np.empty((n, horizon + 1, first[0]["observation"].shape[0]), np.float32)
    achieved = np.empty((n, horizon + 1, first[0]["achieved_goal"].shape[0]), np.float32)
    goal = np.stack([o["desired_goal"] for o in first]).astype(np.float32)
    actions = np.empty((n, horizon, envs[0].action_space.shape[0]), np.float32)
    obs[:, 0] = [o["observation"] for o in first]
    achieved[:, 0] = [o["achieved_goal"] for o in first]
    success = np.zeros(n, bool)
    for t in range(horizon):
        actions[:, t] = agent.act(obs[:, t], goal, explore, rng)
        for i, env in enumerate(envs):
            step_obs, _reward, _terminated, _truncated, info = env.step(actions[i, t])
            obs[i, t + 1] = step_obs["observation"]
            achieved[i, t + 1] = step_obs["achieved_goal"]
            success[i] = info["is_success"] > 0
    goals = np.repeat(goal[:, None], horizon, axis=1)
    return Episodes(obs, achieved, goals, actions), success


# --------------------------------------------------------------------------- run metadata
def _git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(CONF_DIR.parent), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(CONF_DIR.parent), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return out + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def _versions() -> dict[str, str]:
    import gymnasium
    import gymnasium_robotics
    import mujoco

    return {"python": platform.python_version(), "hersd": hersd.__version__, "torch": torch.__version__,
            "mujoco": mujoco.__version__, "gymnasium": gymnasium.__version__,
            "gymnasium_robotics": gymnasium_robotics.__version__, "numpy": np.__version__}


def _effective_totals(cfg: TrainConfig, spec: EnvSpec, gamma: float, q_min: float) -> dict[str, Any]:
    """Totals that make runs comparable whatever the worker layout."""
    d = cfg.ddpg
    steps_per_cycle = d.rollouts_per_cycle * spec.horizon
    return {"horizon": spec.horizon, "gamma": gamma, "q_target_range": [q_min, 0.0],
            "distance_threshold": spec.distance_threshold, "batch_size": d.batch_size,
            "env_steps_per_epoch": cfg.task.cycles_per_epoch * steps_per_cycle,
            "updates_per_epoch": cfg.task.cycles_per_epoch * d.batches_per_cycle,
            "updates_per_env_step": d.batches_per_cycle / steps_per_cycle,
            "test_episodes_per_epoch": d.test_rollouts * d.rollouts_per_cycle,
            "buffer_episodes": max(1, d.buffer_size // spec.horizon)}


# --------------------------------------------------------------------------- checkpoints
def _save_checkpoint(path: Path, state: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


@contextmanager
def _run_lock(directory: Path) -> Iterator[None]:
    with open(directory / "run.lock", "w") as lock_file:
        try:
            fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunLockedError(f"{directory} is being run by another process") from None
        yield


# --------------------------------------------------------------------------- the run
def train(cfg: TrainConfig, command: str = "", on_epoch: Callable[[dict], None] | None = None) -> Path:
    """Run (or resume, or find complete) the run of ``cfg``; returns the path of its log.

    ``on_epoch(record)`` is called after each epoch's record is logged (and checkpointed);
    an exception it raises stops the run there, leaving it resumable.
    """
    directory = run_dir(cfg)
    directory.mkdir(parents=True, exist_ok=True)
    log_path = directory / LOG_NAME
    checkpoint_path = directory / CHECKPOINT_NAME
    with _run_lock(directory):
        previous = _read_previous_log(cfg, log_path, checkpoint_path)
        if previous is not None and previous.complete:
            _say(cfg, f"{log_path}: already complete ({len(previous.epochs)} epochs), nothing to do")
            return log_path
        checkpoint = _load_checkpoint(checkpoint_path) if checkpoint_path.exists() else None
        if previous is not None and checkpoint is None:
            stale = _keep_aside(log_path, "partial")
            _say(cfg, f"{log_path}: incomplete and without checkpoint; kept as {stale.name}, starting afresh")
            previous = None
        _train_loop(cfg, directory, log_path, checkpoint_path, previous, checkpoint, command, on_epoch)
    return log_path


def _keep_aside(log_path: Path, kind: str) -> Path:
    """Rename run.mcap to run.<kind>-<time>.mcap next to it; returns the new path."""
    kept = log_path.with_name(f"run.{kind}-{time.strftime('%Y%m%d-%H%M%S')}.mcap")
    os.replace(log_path, kept)
    return kept


def _read_previous_log(cfg: TrainConfig, log_path: Path, checkpoint_path: Path):
    """The run's existing log (None if there is none). A log too damaged to hold even the run's
    metadata holds no epochs either: it is kept aside and the run starts afresh, unless a
    checkpoint claims finished epochs, which needs a person to decide."""
    if not log_path.exists():
        return None
    try:
        return read_run(log_path)
    except RunLogError as err:
        if checkpoint_path.exists():
            raise RunStateError(f"{err}, but {checkpoint_path.name} next to it says epochs were finished; "
                                f"move both aside to start this run afresh") from None
        kept = _keep_aside(log_path, "unreadable")
        _say(cfg, f"{log_path}: unreadable, without checkpoint; kept as {kept.name}, starting afresh")
        return None


def _load_checkpoint(path: Path) -> dict:
    try:
        return torch.load(path, weights_only=False)
    except Exception as err:  # torch raises RuntimeError, EOFError or UnpicklingError on a damaged file
        raise RunStateError(f"{path} is unreadable ({type(err).__name__}); move it aside to restart this run "
                            f"from epoch 1 (the epochs in its log are then kept as run.partial-*.mcap)") from None


def _say(cfg: TrainConfig, line: str) -> None:
    if not cfg.quiet:
        print(line, flush=True)


def _train_loop(cfg: TrainConfig, directory: Path, log_path: Path, checkpoint_path: Path, previous, checkpoint,
                command: str, on_epoch: Callable[[dict], None] | None) -> None:
    torch.set_num_threads(1)
    d = cfg.ddpg
    seeds = np.random.SeedSequence(cfg.seed).spawn(4)  # sampling/exploration, torch, train envs, test envs
    rng = np.random.default_rng(seeds[0])
    torch.manual_seed(int(seeds[1].generate_state(1)[0]))
    train_envs = [make_env(cfg.task) for _ in range(d.rollouts_per_cycle)]
    test_envs = [make_env(cfg.task) for _ in range(d.rollouts_per_cycle)]
    for envs, seq in ((train_envs, seeds[2]), (test_envs, seeds[3])):
        for env, env_seed in zip(envs, seq.generate_state(len(envs))):
            env.reset(seed=int(env_seed))
    spec = env_spec(train_envs[0])
    horizon = spec.horizon
    gamma = d.gamma if d.gamma is not None else 1.0 - 1.0 / horizon
    q_min = -max(cfg.algo.lambda_r, cfg.algo.lambda_h) / (1.0 - gamma)
    agent = DDPG(d, spec.obs_dim, spec.goal_dim, spec.action_dim, spec.max_action, gamma, q_min)
    buffer = EpisodeBuffer(d.buffer_size, horizon, spec.obs_dim, spec.goal_dim, spec.action_dim)
    # MEP: episodes drawn by trajectory rarity instead of uniformly (hersd/mep.py).
    prioritizer = EpisodePrioritizer(cfg.algo.mep, buffer.capacity) if cfg.algo.mep.enabled else None

    def reward_fn(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        return goal_reward(achieved, goal, spec.distance_threshold)

    env_steps = updates = 0
    start_epoch = 1
    if checkpoint is not None:
        agent.load_state_dict(checkpoint["agent"])
        buffer.load_state_dict({k: v.numpy() if torch.is_tensor(v) else v for k, v in checkpoint["buffer"].items()})
        rng.bit_generator.state = checkpoint["rng"]
        torch.set_rng_state(checkpoint["torch_rng"])
        for env, state in zip(train_envs + test_envs, checkpoint["env_rngs"]):
            env.np_random.bit_generator.state = state
        env_steps, updates = checkpoint["env_steps"], checkpoint["updates"]
        if prioritizer is not None:
            prioritizer.load_state_dict(checkpoint["mep"])
        start_epoch = checkpoint["epoch"] + 1
        previous.epochs = previous.epochs[previous.epochs["epoch"] < start_epoch]

    meta = {"run_id": config_hash(cfg), "config": asdict(cfg), "seed": cfg.seed, "versions": _versions(),
            "git_commit": _git_commit(), "command": command, "start_time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "resumed_from_epoch": start_epoch - 1, "effective": _effective_totals(cfg, spec, gamma, q_min)}
    log = RunLogWriter(log_path, meta, previous)
    _say(cfg, f"run {directory} ({'resuming at epoch ' + str(start_epoch) if start_epoch > 1 else 'new'})")
    try:
        for epoch in range(start_epoch, cfg.epochs + 1):
            epoch_start = time.perf_counter()
            eps = relabel_rate(cfg.schedule, epoch, cfg.epochs)
            mep_fit_seconds = None
            if prioritizer is not None:  # refit the density on the episodes stored so far (none in epoch 1)
                tic = time.perf_counter()
                prioritizer.fit(buffer.stored().achieved, rng)
                mep_fit_seconds = time.perf_counter() - tic
            rollout_seconds = update_seconds = 0.0
            train_successes = []
            sums = np.zeros(4)  # critic loss, actor loss, Q mean, Q^2 mean, summed over updates
            relabelled = real_success = sampled = 0
            for _cycle in range(cfg.task.cycles_per_epoch):
                tic = time.perf_counter()
                episodes, success = run_episodes(train_envs, agent, horizon, explore=True, rng=rng)
                train_successes.append(success)
                env_steps += len(train_envs) * horizon
                slots = buffer.store(episodes)
                if prioritizer is not None:
                    prioritizer.score_new(slots, episodes.achieved)
                # The normaliser sees the new episodes' transitions, relabelled as training will see them.
                fresh = sample_transitions(episodes, horizon * len(train_envs), eps, rng, reward_fn,
                                           strategy=cfg.algo.goal_strategy)
                agent.update_normalizers(fresh.obs, fresh.goal)
                toc = time.perf_counter()
                rollout_seconds += toc - tic
                stored = buffer.stored()
                episode_probs = prioritizer.probs(buffer.size) if prioritizer is not None else None
                for _batch in range(d.batches_per_cycle):
                    batch = sample_transitions(stored, d.batch_size, eps, rng, reward_fn, cfg.algo.lambda_r,
                                               cfg.algo.lambda_h, cfg.algo.goal_strategy,
                                               episode_probs=episode_probs)
                    sums += agent.update(batch)
                    relabelled += int(batch.relabelled.sum())
                    real_success += int(batch.real_success.sum())
                    sampled += d.batch_size
                agent.update_targets()
                updates += d.batches_per_cycle
                update_seconds += time.perf_counter() - toc

            tic = time.perf_counter()
            test_success = np.concatenate([run_episodes(test_envs, agent, horizon, explore=False, rng=rng)[1]
                                           for _ in range(d.test_rollouts)])
            eval_seconds = time.perf_counter() - tic
            n_updates = cfg.task.cycles_per_epoch * d.batches_per_cycle
            critic_loss, actor_loss, q_mean, q_sq_mean = sums / n_updates
            record = {
                "epoch": epoch, "relabel_rate": eps, "test_success": float(test_success.mean()),
                "train_success": float(np.concatenate(train_successes).mean()),
                "q_mean": q_mean, "q_std": float(np.sqrt(max(q_sq_mean - q_mean ** 2, 0.0))),
                "critic_loss": critic_loss, "actor_loss": actor_loss,
                "share_hindsight": relabelled / sampled, "share_real_success": real_success / sampled,
                "share_real_failure": (sampled - relabelled - real_success) / sampled,
                "env_steps": env_steps, "updates": updates, "episodes_stored": buffer.size,
                "rollout_seconds": rollout_seconds, "update_seconds": update_seconds, "eval_seconds": eval_seconds,
                "epoch_seconds": time.perf_counter() - epoch_start, "mep_fit_seconds": mep_fit_seconds,
                "priority_entropy": prioritizer.entropy(buffer.size) if prioritizer is not None else None,
            }
            log.write_epoch(record)
            _say(cfg, f"epoch {epoch:>4}/{cfg.epochs}  eps {eps:.3f}  test {record['test_success']:.2f}  "
                      f"train {record['train_success']:.2f}  Q {q_mean:7.2f}  {record['epoch_seconds']:.1f}s")
            if cfg.checkpoint_every and (epoch % cfg.checkpoint_every == 0 or epoch == cfg.epochs):
                _save_checkpoint(checkpoint_path, {
                    "epoch": epoch, "agent": agent.state_dict(),
                    "buffer": {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v
                               for k, v in buffer.state_dict().items()},
                    "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                    "env_rngs": [env.np_random.bit_generator.state for env in train_envs + test_envs],
                    "env_steps": env_steps, "updates": updates,
                    **({"mep": prioritizer.state_dict()} if prioritizer is not None else {})})
            if on_epoch is not None:
                on_epoch(record)
        log.finish(cfg.epochs)
        if checkpoint_path.exists() and not cfg.keep_checkpoint:
            checkpoint_path.unlink()
    finally:
        log.close()
        for env in train_envs + test_envs:
            env.close()


# --------------------------------------------------------------------------- command line
def compose(overrides: list[str]) -> TrainConfig:
    """``conf/train.yaml`` with Hydra command-line overrides -> validated TrainConfig."""
    from hydra import compose as hydra_compose, initialize_config_dir

    register_schemas()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3", job_name="hersd-train"):
        return to_train_config(hydra_compose(config_name="train", overrides=overrides))


def explain_config_error(err: Exception) -> str:
    """Hydra/OmegaConf composition errors -> one line naming the field and the choices."""
    from hydra.errors import MissingConfigException

    if isinstance(err, MissingConfigException) and err.missing_cfg_file and err.options is not None:
        group, _, value = err.missing_cfg_file.partition("/")
        return f"{group}={value} is not a known {group}; choose one of: {', '.join(sorted(err.options))}"
    if isinstance(err, MissingConfigException) and err.missing_cfg_file:
        group = err.missing_cfg_file.split("/")[0]
        choices = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml")) if (CONF_DIR / group).is_dir() else []
        return f"{err.missing_cfg_file} is unknown" + (f"; choose one of: {', '.join(choices)}" if choices else "")
    from omegaconf.errors import ConfigAttributeError, ConfigKeyError, ValidationError

    cause = err.__cause__ if err.__cause__ is not None else err
    key = getattr(cause, "full_key", None)
    if isinstance(cause, (ConfigAttributeError, ConfigKeyError)) and key:
        return f"{key} is not a config field; see hersd-train --help and hersd/config.py"
    if isinstance(cause, ValidationError) and key:
        return f"{key}: {str(cause).splitlines()[0]}"
    return " ".join(str(err).split())


def check_writable(directory: Path) -> None:
    """Fail early (ConfigError) if ``directory`` cannot be created or written."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:
        raise ConfigError(f"results_dir: cannot write to {directory} ({err.strerror}); "
                          f"pass results_dir=<a writable folder>") from None


USAGE = """usage: hersd-train [KEY=VALUE ...]

Runs one DDPG+HER training run and prints the path of its MCAP log; re-running the same
command resumes an interrupted run from its last checkpoint.

  task=reach|push|pick_and_place|slide     schedule=constant|linear|exponential|paper_linear_025|...|paper_exp_100
  algo=her|archer|her_mep|archer_mep      (*_mep: MEP prioritisation, see docs/MEP.md)
  schedule.beta1=0.25 schedule.beta2=0.5   schedule.mean_rate=0.85 (solves beta1 by eq. 10)
  seed=0   epochs=200   results_dir=results   quiet=true   checkpoint_every=1
  ddpg.<field>=...  (see hersd/config.py; defaults are the paper's appendix settings)
"""


def main(argv: list[str] | None = None) -> None:
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    argv = sys.argv[1:] if argv is None else argv
    if any(arg in ("-h", "--help") for arg in argv):
        print(USAGE)
        return
    try:
        cfg = compose(argv)
        check_writable(run_dir(cfg))
    except ConfigError as err:
        print(f"hersd-train: error: {err}", file=sys.stderr)
        sys.exit(2)
    except (HydraException, OmegaConfBaseException) as err:
        print(f"hersd-train: error: {explain_config_error(err)}", file=sys.stderr)
        sys.exit(2)
    try:
        log_path = train(cfg, command=" ".join(["hersd-train", *argv]))
    except RunLockedError as err:
        print(f"hersd-train: error: {err}; wait for it to finish", file=sys.stderr)
        sys.exit(2)
    except RunStateError as err:
        print(f"hersd-train: error: {err}", file=sys.stderr)
        sys.exit(2)
    print(log_path)


if __name__ == "__main__":
    main()
