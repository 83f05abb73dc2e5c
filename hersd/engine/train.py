"""One training run: Algorithm 1 of the seed paper (DDPG + HER with a relabel-rate schedule).

:func:`train` finds the run's directory in the run store, resumes it from its checkpoint if
it has one, and runs the epochs left. Each epoch (:func:`run_epoch`) reads like Algorithm 1:
fix eps(k); per cycle, :func:`collect` episodes (store them, update the normalisers) and
:func:`update` on freshly relabelled minibatches, then move the targets; :func:`evaluate`
at the epoch's end. The command line is in :mod:`hersd.engine.cli`.
"""

from __future__ import annotations

import math
import platform
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch

import hersd
from hersd.engine.bias import GOAL_TYPES, BiasEvaluator
from hersd.contract.config import TrainConfig, config_record
from hersd.contract.errors import DiskFullError
from hersd.engine.denormals import denormals_flushed, set_intra_op_threads, thread_flush_states
from hersd.engine.learners import GoalConditionedLearner, UpdateStats, learner_class
from hersd.engine.envs.make import step_success
from hersd.engine.replay.buffer import Episodes, TransitionBatch, sample_transitions
from hersd.engine.render import RenderError, owed_animation, render_policy, renders_at
from hersd.contract.cores import resolve_threads
from hersd.engine.resources import machine_info, resolve_device
from hersd.engine.run_state import RunState, load_checkpoint, save_checkpoint
from hersd.contract.runlog import LOG_NAME, RunLog, RunLogError, RunLogWriter, read_records, read_run
from hersd.contract.runspec import RunSpec, resolve
from hersd.contract.runstore import RunFolder, keep_aside, remove_if_unused
from hersd.contract.tensorboard_events import EVENTS_DIR, RunEvents, write_run_events

EpochCallback = Callable[[dict], None]
LoggedCallback = Callable[[list], None]  # the records a log already holds, once before training


class RunStateError(RuntimeError):
    """A run directory holds a checkpoint or log that cannot be read; the message says what to do."""


class NonFiniteLossError(RuntimeError):
    """An epoch's losses or Q values are NaN or infinite; its record is not logged (one-line message)."""


# The settings that scale every learner's losses, named when they turn non-finite, with the learner's own
# (its class's LOSS_SETTINGS: DDPG's and TD3's action_l2, SAC's temperature settings).
LOSS_SETTINGS = "algo.lambda_r, algo.lambda_h, ddpg.gamma, ddpg.actor_lr, ddpg.critic_lr"


def check_finite(cfg: TrainConfig, record: dict[str, Any]) -> None:
    """NonFiniteLossError naming the epoch, the values and the settings that scale them, if any is NaN or inf."""
    names = ("critic_loss", "actor_loss", "q_mean", "q_std", "alpha", "policy_entropy")
    bad = [f"{name}={record[name]}" for name in names if record[name] is not None and not math.isfinite(record[name])]
    if bad:
        raise NonFiniteLossError(
            f"epoch {record['epoch']}: {', '.join(bad)}; the run stops at its last logged epoch and checkpoint; "
            f"lower {LOSS_SETTINGS}, {learner_class(cfg.learner.name).LOSS_SETTINGS}")


# --------------------------------------------------------------------------- the steps of an epoch
def run_episodes(envs: list, agent: GoalConditionedLearner, horizon: int, explore: bool,
                 rng: np.random.Generator, flush_denormal: bool) -> tuple[Episodes, np.ndarray]:
    """One episode in each env, stepped in lockstep -> (Episodes of n = len(envs), success (n,) bool at the
    last step). Each step's goal is the desired goal of its observation (constant in Fetch, Hand and the
    registered mazes; an env may move it once reached). The policy acts with denormals flushed to zero
    (``flush_denormal``); the physics steps in IEEE arithmetic."""
    n = len(envs)
    first = [env.reset()[0] for env in envs]
    obs = np.empty((n, horizon + 1, first[0]["observation"].shape[0]), np.float32)
    achieved = np.empty((n, horizon + 1, first[0]["achieved_goal"].shape[0]), np.float32)
    goals = np.empty((n, horizon, first[0]["desired_goal"].shape[0]), np.float32)
    actions = np.empty((n, horizon, envs[0].action_space.shape[0]), np.float32)
    obs[:, 0] = [o["observation"] for o in first]
    achieved[:, 0] = [o["achieved_goal"] for o in first]
    desired = [o["desired_goal"] for o in first]
    success = np.zeros(n, bool)
    for t in range(horizon):
        goals[:, t] = desired
        with denormals_flushed(flush_denormal):
            actions[:, t] = agent.act(obs[:, t], goals[:, t], explore, rng)
        for i, env in enumerate(envs):
            step_obs, _reward, _terminated, _truncated, info = env.step(actions[i, t])
            obs[i, t + 1] = step_obs["observation"]
            achieved[i, t + 1] = step_obs["achieved_goal"]
            desired[i] = step_obs["desired_goal"]
            success[i] = step_success(info)
    return Episodes(obs, achieved, goals, actions), success


class EpochStats:
    """What one epoch measures, accumulated as it runs; :meth:`record` makes the log record."""

    def __init__(self, epoch: int, relabel_rate: float):
        self.epoch, self.relabel_rate = epoch, relabel_rate
        self.start = time.perf_counter()
        self.seconds: dict[str, float] = {"rollout": 0.0, "update": 0.0, "eval": 0.0}
        self.train_success: list[np.ndarray] = []  # one (rollouts,) bool array per cycle
        self.critic_loss = self.actor_loss = self.q_sum = self.q_sq_sum = 0.0  # summed over updates
        self.entropy_sum: float | None = None  # summed over updates by learners that report it (SAC)
        self.q_real_sum = self.q_hindsight_sum = 0.0  # Q summed over real-goal / relabelled rows of every update
        self.n_updates = self.sampled = self.relabelled = self.real_success = 0

    @contextmanager
    def timed(self, phase: str) -> Iterator[None]:
        """Add the block's wall-clock seconds to ``seconds[phase]``."""
        tic = time.perf_counter()
        yield
        self.seconds[phase] = self.seconds.get(phase, 0.0) + time.perf_counter() - tic

    def add_update(self, stats: UpdateStats, batch: TransitionBatch) -> None:
        """Count one update's losses and Q statistics and its minibatch's composition."""
        self.critic_loss += stats.critic_loss
        self.actor_loss += stats.actor_loss
        self.q_sum += stats.q_mean
        self.q_sq_sum += stats.q_sq_mean
        if stats.entropy is not None:
            self.entropy_sum = (self.entropy_sum or 0.0) + stats.entropy
        self.q_real_sum += stats.q_real_sum
        self.q_hindsight_sum += stats.q_hindsight_sum
        self.n_updates += 1
        self.sampled += batch.relabelled.shape[0]
        self.relabelled += int(batch.relabelled.sum())
        self.real_success += int(batch.real_success.sum())

    def record(self, state: RunState, test_success: np.ndarray, test_distance: np.ndarray) -> dict[str, Any]:
        """The epoch's log record (fields: :data:`hersd.contract.runlog.EPOCH_FIELDS`)."""
        q_mean, q_sq_mean = self.q_sum / self.n_updates, self.q_sq_sum / self.n_updates
        prioritizer = state.prioritizer
        return {
            "epoch": self.epoch, "relabel_rate": self.relabel_rate, "test_success": float(test_success.mean()),
            "test_distance": float(test_distance.mean()),
            "train_success": float(np.concatenate(self.train_success).mean()),
            "q_mean": q_mean, "q_std": float(np.sqrt(max(q_sq_mean - q_mean ** 2, 0.0))),
            "q_real_mean": _mean_or_none(self.q_real_sum, self.sampled - self.relabelled),
            "q_hindsight_mean": _mean_or_none(self.q_hindsight_sum, self.relabelled),
            "critic_loss": self.critic_loss / self.n_updates, "actor_loss": self.actor_loss / self.n_updates,
            "share_hindsight": self.relabelled / self.sampled,
            "share_real_success": self.real_success / self.sampled,
            "share_real_failure": (self.sampled - self.relabelled - self.real_success) / self.sampled,
            "env_steps": state.env_steps, "updates": state.updates, "episodes_stored": state.buffer.size,
            "rollout_seconds": self.seconds["rollout"], "update_seconds": self.seconds["update"],
            "eval_seconds": self.seconds["eval"], "epoch_seconds": time.perf_counter() - self.start,
            "mep_fit_seconds": self.seconds.get("mep_fit"),
            "priority_entropy": prioritizer.entropy(state.buffer.size) if prioritizer is not None else None,
            "alpha": getattr(state.agent, "alpha", None),  # SAC's temperature; the other learners have none
            "policy_entropy": None if self.entropy_sum is None else self.entropy_sum / self.n_updates,
        }


def _mean_or_none(total: float, count: int) -> float | None:
    return total / count if count else None


def collect(state: RunState, relabel_prob: float, stats: EpochStats) -> None:
    """Run one episode per training env, store them, and update the input normalisers from their
    transitions relabelled as training will see them (the reference code's normaliser update)."""
    cfg, horizon = state.cfg, state.spec.horizon
    episodes, success = run_episodes(state.train_envs, state.agent, horizon, explore=True, rng=state.rng,
                                     flush_denormal=cfg.flush_denormal)
    stats.train_success.append(success)
    state.env_steps += len(state.train_envs) * horizon
    slots = state.buffer.store(episodes)
    if state.prioritizer is not None:
        state.prioritizer.score_new(slots, episodes.achieved)
    fresh = sample_transitions(episodes, horizon * len(state.train_envs), relabel_prob, state.rng, state.reward,
                               strategy=cfg.algo.goal_strategy)
    state.agent.update_normalizers(fresh.obs, fresh.goal)


def update(state: RunState, relabel_prob: float, stats: EpochStats) -> None:
    """``batches_per_cycle`` updates on minibatches relabelled at ``relabel_prob``, then one target move
    (denormals flushed to zero throughout with ``flush_denormal``)."""
    d, algo = state.cfg.ddpg, state.cfg.algo
    stored = state.buffer.stored()
    episode_probs = state.prioritizer.probs(state.buffer.size) if state.prioritizer is not None else None
    with denormals_flushed(state.cfg.flush_denormal):
        for _batch in range(d.batches_per_cycle):
            batch = sample_transitions(stored, d.batch_size, relabel_prob, state.rng, state.reward, algo.lambda_r,
                                       algo.lambda_h, algo.goal_strategy, episode_probs=episode_probs,
                                       success_reward=state.spec.reward_range[1])
            stats.add_update(state.agent.update(batch), batch)
        state.agent.update_targets()
    state.updates += d.batches_per_cycle


def evaluate(state: RunState) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic-policy test episodes -> (success (n,) bool, final distance ||achieved_T - goal|| (n,)),
    n = test_rollouts * rollouts_per_cycle."""
    success, distance = [], []
    for _ in range(state.cfg.ddpg.test_rollouts):
        episodes, episode_success = run_episodes(state.test_envs, state.agent, state.spec.horizon, explore=False,
                                                 rng=state.rng, flush_denormal=state.cfg.flush_denormal)
        success.append(episode_success)
        distance.append(np.linalg.norm(episodes.achieved[:, -1] - episodes.goal[:, -1], axis=-1))
    return np.concatenate(success), np.concatenate(distance)


def run_epoch(state: RunState, epoch: int, rate: float | None = None) -> dict[str, Any]:
    """Epoch k of Algorithm 1 -> its log record; ``rate``: eps(k) as the run's spec resolved it
    (:meth:`hersd.contract.runspec.RunSpec.rate`), None: the schedule's checked rate now."""
    cfg = state.cfg
    if rate is None:
        rate = cfg.schedule.checked_rate(epoch, cfg.epochs, state.train_success)
    stats = EpochStats(epoch, rate)
    if state.prioritizer is not None:  # refit the density on the episodes stored so far (none in epoch 1)
        with stats.timed("mep_fit"):
            state.prioritizer.fit(state.buffer.stored().achieved, state.rng)
    for _cycle in range(cfg.task.cycles_per_epoch):
        with stats.timed("rollout"):
            collect(state, stats.relabel_rate, stats)
        with stats.timed("update"):
            update(state, stats.relabel_rate, stats)
    with stats.timed("eval"):
        test_success, test_distance = evaluate(state)
    record = stats.record(state, test_success, test_distance)
    state.epochs_done = epoch
    state.train_success.append(record["train_success"])
    return record


# --------------------------------------------------------------------------- the run
def train(run: RunSpec | TrainConfig, command: str = "", on_epoch: EpochCallback | None = None,
          on_logged: LoggedCallback | None = None) -> Path:
    """Run (or resume, or find complete) the run of ``run`` (its spec; a config is resolved here, once);
    returns the path of its log.

    ``on_logged(records)`` is called once, before any epoch is trained, with the records the log already holds
    and the run keeps (those up to its checkpoint; all of them for a run found complete; none for a new run).
    ``on_epoch(record)`` is called after each epoch's record is logged (and checkpointed); an exception either
    raises stops the run there, leaving it resumable.
    """
    spec = run if isinstance(run, RunSpec) else resolve(run)
    spec.check_unchanged()
    directory = spec.folder
    created = not directory.exists()
    directory.mkdir(parents=True, exist_ok=True)
    try:
        return _train_in(spec, command, on_epoch, on_logged)
    except BaseException:
        if created:  # failed before writing anything (e.g. too little memory): leave no empty folders
            remove_if_unused(directory, up_to=Path(spec.config.results_dir))
        raise


def _train_in(spec: RunSpec, command: str, on_epoch: EpochCallback | None, on_logged: LoggedCallback | None) -> Path:
    """:func:`train` in its run directory, under the run's lock."""
    cfg, folder = spec.config, RunFolder(spec.folder)
    log_path, checkpoint_path = folder.log, folder.checkpoint
    with folder.lock():
        previous = _read_previous_log(cfg, log_path, checkpoint_path)
        if previous is not None and previous.complete:
            if not cfg.keep_checkpoint:  # left by a run killed between its completion marker and the removal
                checkpoint_path.unlink(missing_ok=True)
            done = "nothing to do"
            if cfg.tensorboard:  # its event files asked for: written from its log, as a live run's would be
                write_run_events(log_path, spec.folder / EVENTS_DIR)
                done = f"its TensorBoard event files written to {spec.folder / EVENTS_DIR}"
            _say(cfg, f"{log_path}: already complete ({len(previous.epochs)} epochs), {done}")
            if on_logged is not None:
                on_logged(previous.epochs.to_dict("records"))
            return log_path
        threads, device = resolve_threads(cfg.threads), resolve_device(cfg.device)
        torch.set_num_threads(threads)
        _flush_intra_op_threads(cfg)
        checkpoint = _read_checkpoint(cfg, checkpoint_path, previous, device)
        if previous is not None and checkpoint is None:
            _say(cfg, f"{log_path}: incomplete and without checkpoint; kept as "
                      f"{keep_aside(log_path, 'partial').name}, starting afresh")
            previous = None
        state = RunState(cfg, device)
        try:
            if checkpoint is not None:
                state.load_state_dict(checkpoint)
                previous.epochs = previous.epochs[previous.epochs["epoch"] <= state.epochs_done]
            if on_logged is not None:
                on_logged([] if previous is None else previous.epochs.to_dict("records"))
            meta = run_metadata(spec, state, command, threads, device)
            _run_epochs(spec, state, RunLogWriter(log_path, meta, previous), checkpoint_path, on_epoch)
        finally:
            state.close()
    return log_path


def _run_epochs(spec: RunSpec, state: RunState, log: RunLogWriter, checkpoint_path: Path,
                on_epoch: EpochCallback | None) -> None:
    """The epochs left, each logged, checkpointed and reported; then the completion marker."""
    cfg = spec.config
    _say(cfg, f"run {checkpoint_path.parent} ({f'resuming at epoch {state.epochs_done + 1}' if state.epochs_done else 'new'})")
    bias = BiasEvaluator(cfg.bias, cfg.task, cfg.seed, state.spec.horizon, state.gamma, state.reward,
                         cfg.flush_denormal)
    saved = state.epochs_done  # the last epoch checkpointed: where a re-run resumes
    # tensorboard=true: the event files restarted from the log as it stands (its epochs so far), then one step per epoch
    events = RunEvents(checkpoint_path.parent / EVENTS_DIR, read_records(log.path)) if cfg.tensorboard else None
    try:
        owed = owed_animation(RunFolder(checkpoint_path.parent), cfg.render_every, state.epochs_done, cfg.epochs)
        if owed is not None:  # stopped while rendering it: the checkpoint holds that epoch's policy
            animate(cfg, state, owed, checkpoint_path.parent)
        for epoch in range(state.epochs_done + 1, cfg.epochs + 1):
            record = run_epoch(state, epoch, spec.rate(epoch, state.train_success))
            check_finite(cfg, record)
            if bias.due(epoch):
                record |= evaluate_bias(cfg, bias, state, epoch)
            log.write_epoch(record)
            if events is not None:
                events.write_epoch(record)
            _say(cfg, f"epoch {epoch:>4}/{cfg.epochs}  eps {record['relabel_rate']:.3f}  test "
                      f"{record['test_success']:.2f}  train {record['train_success']:.2f}  Q {record['q_mean']:7.2f}  "
                      f"{record['epoch_seconds']:.1f}s")
            if record.get("bias_seconds") is not None:
                shown = "  ".join(f"{goal_type} {record[f'bias_{goal_type}_mean']:+.2f}" for goal_type in GOAL_TYPES
                                  if record[f"bias_{goal_type}_mean"] is not None)
                _say(cfg, f"epoch {epoch:>4}/{cfg.epochs}  critic bias (Q - return): {shown}  "
                          f"({record['bias_seconds']:.1f} s)")
            if cfg.checkpoint_every and (epoch % cfg.checkpoint_every == 0 or epoch == cfg.epochs):
                save_checkpoint(checkpoint_path, state.state_dict())
                saved = epoch
            if renders_at(cfg.render_every, epoch, cfg.epochs):
                animate(cfg, state, epoch, checkpoint_path.parent)
            if on_epoch is not None:
                on_epoch(record)
        log.finish(cfg.epochs)
        if checkpoint_path.exists() and not cfg.keep_checkpoint:
            checkpoint_path.unlink()
    except DiskFullError as err:
        raise kept_on_full_disk(err, saved) from None
    finally:
        bias.close()
        log.close()
        if events is not None:
            events.close()


def kept_on_full_disk(err: DiskFullError, saved: int) -> DiskFullError:
    """``err`` saying what the run keeps: its log and checkpoint are whole on disk (each written atomically), and
    a re-run resumes after ``saved``, the last epoch checkpointed (0: none, it starts afresh)."""
    then = (f"the run keeps epochs 1-{saved}: free some and run the same command again to resume at epoch "
            f"{saved + 1}" if saved else "the run keeps no epoch: free some and run the same command again to start it")
    return DiskFullError(err.path, err.needed, then)


def evaluate_bias(cfg: TrainConfig, bias: BiasEvaluator, state: RunState, epoch: int) -> dict[str, Any]:
    """The bias evaluation's log fields after ``epoch`` (hersd.engine.bias); a failure is one warning line on stderr
    and no fields, never an error: training goes on."""
    try:
        fields = bias.evaluate(state.agent, epoch)
    except Exception as err:  # noqa: BLE001  (an env whose state cannot be restored: the run matters more)
        print(f"warning: epoch {epoch}: no bias evaluation: {type(err).__name__}: {' '.join(str(err).split())[:200]}",
              file=sys.stderr, flush=True)
        return {}
    return fields


def animate(cfg: TrainConfig, state: RunState, epoch: int, directory: Path) -> None:
    """Write the policy's animation after ``epoch`` (hersd.engine.render); a failure is one warning line on stderr,
    never an error: training goes on."""
    try:
        animation = render_policy(state.agent, cfg, epoch, RunFolder(directory).animation(epoch))
    except Exception as err:  # noqa: BLE001  (a missing OpenGL, a full disk: the run matters more)
        reason = str(err) if isinstance(err, RenderError) else f"{type(err).__name__}: {str(err).strip()[:200]}"
        print(f"warning: {directory}: epoch {epoch}: no policy animation: {' '.join(reason.split())}",
              file=sys.stderr, flush=True)
        return
    _say(cfg, f"epoch {epoch:>4}/{cfg.epochs}  policy animation {animation.path} ({animation.seconds:.1f} s)")


# --------------------------------------------------------------------------- resume
def _read_previous_log(cfg: TrainConfig, log_path: Path, checkpoint_path: Path) -> RunLog | None:
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
        _say(cfg, f"{log_path}: unreadable, without checkpoint; kept as {keep_aside(log_path, 'unreadable').name}, "
                  f"starting afresh")
        return None


def _read_checkpoint(cfg: TrainConfig, path: Path, previous: RunLog | None, device: torch.device) -> dict | None:
    """The run's checkpoint, or None. One without a log (its epochs' records are gone) is kept aside."""
    if not path.exists():
        return None
    if previous is None:
        _say(cfg, f"{path}: a checkpoint without its log {LOG_NAME}; kept as {keep_aside(path, 'orphan').name}, "
                  f"starting afresh")
        return None
    try:
        return load_checkpoint(path, device)
    except Exception as err:  # torch raises RuntimeError, EOFError or UnpicklingError on a damaged file
        raise RunStateError(f"{path} is unreadable ({type(err).__name__}); move it aside to restart this run "
                            f"from epoch 1 (the epochs in its log are then kept as run.partial-*.mcap)") from None


def _say(cfg: TrainConfig, line: str) -> None:
    if not cfg.quiet:
        print(line, flush=True)


def _flush_intra_op_threads(cfg: TrainConfig) -> None:
    """Every intra-op thread set to the run's ``flush_denormal`` (hersd/engine/denormals.py), then checked on each
    thread: a thread that disagrees (a CPU without FTZ/DAZ, an OpenMP runtime not found) is one warning line."""
    set_intra_op_threads(cfg.flush_denormal)
    with denormals_flushed(cfg.flush_denormal):
        states = thread_flush_states()
    if any(state != cfg.flush_denormal for state in states):
        print(f"warning: flush_denormal={str(cfg.flush_denormal).lower()} holds on {states.count(cfg.flush_denormal)} "
              f"of {len(states)} torch threads of this machine; the run goes on", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- run metadata
def run_metadata(spec: RunSpec, state: RunState, command: str, threads: int, device: torch.device) -> dict:
    """The ``/run/meta`` message of this session (see :mod:`hersd.contract.runlog`)."""
    cfg = spec.config
    return {"run_id": spec.run_id, "config": config_record(cfg), "seed": cfg.seed, "versions": _versions(),
            "git_commit": _git_commit(), "command": command, "start_time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "resumed_from_epoch": state.epochs_done, "effective": state.effective_totals(),
            "threads": threads, "device": str(device), "machine": machine_info()}


def _git_commit() -> str | None:
    """The commit of the code that runs (with ``-dirty`` for uncommitted changes), if it is a git checkout.
    Changes below the checkout's ``results/`` (run logs and their report: data, not code) do not count."""
    source = Path(hersd.__file__).resolve().parent.parent
    try:
        out = subprocess.run(["git", "-C", str(source), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no", "--",
                                ".", ":(exclude)results"], capture_output=True, text=True, timeout=5).stdout.strip()
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
