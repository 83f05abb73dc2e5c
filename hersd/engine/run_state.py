"""One run's state: the agent, the replay buffer, the MEP prioritiser, the RNGs, the envs and
the counters, with :meth:`RunState.state_dict` / :meth:`RunState.load_state_dict` as the one
checkpoint format (an exact resume: the next epoch gives the numbers an uninterrupted run gives).

Randomness comes from one ``SeedSequence(seed)`` spawned four ways: the sampling and
exploration Generator, torch (network initialisation), the training envs and the test envs.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError, DiskFullError, full_disk, interrupted
from hersd.engine.envs.make import EnvSpec, check_success_reported, env_spec, make_env
from hersd.engine.envs.goal_envs import vectorised_reward
from hersd.engine.learners import GoalConditionedLearner, learner_class
from hersd.engine.learners.fast import fast_learner_class
from hersd.engine.replay.buffer import EpisodeBuffer
from hersd.engine.resources import available_memory_bytes


class RunState:
    """Everything one training run changes as it goes; built from its config alone.

    ``epochs_done`` counts finished epochs; ``env_steps`` and ``updates`` are cumulative;
    ``train_success`` holds each finished epoch's train success (a success schedule's input).
    ``spec`` holds what the task's env gives (sizes, horizon, reward range); ``gamma`` and
    ``q_range`` (the clip of target Q, :func:`discounting`) follow from it and the config.
    """

    def __init__(self, cfg: TrainConfig, device: torch.device = torch.device("cpu")):
        self.cfg = cfg
        d = cfg.ddpg
        seeds = np.random.SeedSequence(cfg.seed).spawn(4)  # sampling/exploration, torch, train envs, test envs
        self.rng = np.random.default_rng(seeds[0])
        torch.manual_seed(int(seeds[1].generate_state(1)[0]))
        first_env = make_env(cfg.task)  # the task's sizes: the memory check runs before the other envs exist
        self.spec = spec = env_spec(first_env)
        check_memory(cfg, spec, env_bytes(first_env))
        check_success_reported(first_env, cfg.task)
        self.train_envs = [first_env] + [make_env(cfg.task) for _ in range(d.rollouts_per_cycle - 1)]
        self.test_envs = [make_env(cfg.task) for _ in range(d.rollouts_per_cycle)]
        for envs, seq in ((self.train_envs, seeds[2]), (self.test_envs, seeds[3])):
            for env, env_seed in zip(envs, seq.generate_state(len(envs))):
                env.reset(seed=int(env_seed))
        self._reward = vectorised_reward(self.train_envs[0])
        self.gamma, self.q_range = discounting(cfg, spec)
        self.agent = make_agent(cfg, spec, self.gamma, self.q_range, device)
        self.buffer = EpisodeBuffer(d.buffer_size, spec.horizon, spec.obs_dim, spec.goal_dim, spec.action_dim)
        # MEP: episodes drawn by trajectory rarity instead of uniformly (hersd/engine/replay/mep.py; imported
        # only for MEP runs: its scikit-learn and SciPy take over a second to import).
        self.prioritizer = None
        if cfg.algo.mep.enabled:
            from hersd.engine.replay.mep import EpisodePrioritizer
            self.prioritizer = EpisodePrioritizer(cfg.algo.mep, self.buffer.capacity)
        self.epochs_done = self.env_steps = self.updates = 0
        self.train_success: list[float] = []

    def reward(self, achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The env's reward for achieved and desired goals (..., goal_dim) -> (...,) float32."""
        return self._reward(achieved, goal)

    def effective_totals(self) -> dict[str, Any]:
        """Totals that make runs comparable whatever the worker layout (logged with the run)."""
        cfg, d, horizon = self.cfg, self.cfg.ddpg, self.spec.horizon
        steps_per_cycle = d.rollouts_per_cycle * horizon
        # q_target_range: the clip of target Q (an infinite bound, logged as null, is none); null: none at all
        target_range = self.agent.target_range
        q_target_range = None if target_range is None else list(target_range)
        return {"horizon": horizon, "gamma": self.gamma, "q_target_range": q_target_range,
                "distance_threshold": self.spec.distance_threshold, "batch_size": d.batch_size,
                "env_steps_per_epoch": cfg.task.cycles_per_epoch * steps_per_cycle,
                "updates_per_epoch": cfg.task.cycles_per_epoch * d.batches_per_cycle,
                "updates_per_env_step": d.batches_per_cycle / steps_per_cycle,
                "test_episodes_per_epoch": d.test_rollouts * d.rollouts_per_cycle,
                "buffer_episodes": self.buffer.capacity}

    def state_dict(self) -> dict[str, Any]:
        """The checkpoint: buffer arrays as tensors, RNG states, counters (``epoch`` = epochs done)."""
        state = {"epoch": self.epochs_done, "agent": self.agent.state_dict(),
                 "buffer": {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v
                            for k, v in self.buffer.state_dict().items()},
                 "rng": self.rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                 "env_rngs": [env.np_random.bit_generator.state for env in self.train_envs + self.test_envs],
                 "env_steps": self.env_steps, "updates": self.updates, "train_success": list(self.train_success)}
        if self.prioritizer is not None:
            state["mep"] = self.prioritizer.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict`; the run continues with epoch ``state["epoch"] + 1``."""
        self.agent.load_state_dict(state["agent"])
        self.buffer.load_state_dict({k: v.numpy() if torch.is_tensor(v) else v for k, v in state["buffer"].items()})
        self.rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        for env, env_rng in zip(self.train_envs + self.test_envs, state["env_rngs"]):
            env.np_random.bit_generator.state = env_rng
        self.epochs_done, self.env_steps, self.updates = state["epoch"], state["env_steps"], state["updates"]
        self.train_success = list(state.get("train_success", []))  # absent from checkpoints of hersd <= 0.1
        if self.prioritizer is not None:
            self.prioritizer.load_state_dict(state["mep"])

    def close(self) -> None:
        for env in self.train_envs + self.test_envs:
            env.close()


def discounting(cfg: TrainConfig, spec: EnvSpec) -> tuple[float, tuple[float, float]]:
    """(gamma, (q_low, q_high)): ``ddpg.gamma`` (null: 1 - 1/T) and the range target Q is clipped to.

    A discounted sum of rewards r in [r_low, r_high] (``spec.reward_range``), each weighted by
    lambda_r (real) or lambda_h (hindsight), lies in
    [min(0, lambda r_low) / (1 - gamma), max(0, lambda r_high) / (1 - gamma)] over both lambdas.
    Fetch and Hand (rewards -1 or 0): [-max(lambda_r, lambda_h) / (1 - gamma), 0], the reference
    code's clip; the mazes (0 or 1): [0, max(lambda) / (1 - gamma)]; an infinite reward bound
    (dense Fetch and Hand rewards below, an unknown env's both sides) leaves that side unclipped.
    """
    gamma = cfg.ddpg.gamma if cfg.ddpg.gamma is not None else 1.0 - 1.0 / spec.horizon
    r_low, r_high = spec.reward_range
    lambdas = (cfg.algo.lambda_r, cfg.algo.lambda_h)
    q_low = min(0.0, *(lam * r_low for lam in lambdas)) / (1.0 - gamma)
    q_high = max(0.0, *(lam * r_high for lam in lambdas)) / (1.0 - gamma)
    return gamma, (q_low, q_high)


def make_agent(cfg: TrainConfig, spec: EnvSpec, gamma: float, q_range: tuple[float, float],
               device: torch.device) -> GoalConditionedLearner:
    """The learner of ``cfg.learner.name``: a :class:`GoalConditionedLearner` (act, update, update_targets, ...),
    built by its class (hersd/engine/learners/), which decides whether its target is clipped to ``q_range``; with
    ``update=fast`` its hand-written update's subclass (hersd/engine/learners/fast.py)."""
    cls = learner_class(cfg.learner.name)
    return (fast_learner_class(cls) if cfg.update == "fast" else cls).build(cfg, spec, gamma, q_range, device)


def env_bytes(env: Any) -> int:
    """Bytes of one MuJoCo env's model, data and arena (0 for an env without them)."""
    model, data = getattr(env, "model", None), getattr(env, "data", None)
    return sum(int(getattr(obj, name, 0)) for obj, name in ((model, "nbuffer"), (data, "nbuffer"), (data, "narena")))


def memory_parts(cfg: TrainConfig, spec: EnvSpec, one_env_bytes: int) -> dict[str, int]:
    """Bytes a run allocates, by the part that allocates them (the names the memory check reports)."""
    d, horizon, learner = cfg.ddpg, spec.horizon, learner_class(cfg.learner.name)
    episode_floats = (horizon + 1) * (spec.obs_dim + spec.goal_dim) + horizon * (spec.goal_dim + spec.action_dim)
    episodes = max(1, d.buffer_size // horizon)
    # One update: the sampled rows on the host and the device (copies, clips, concatenations), and each
    # network pass's saved float32 activations and their gradients (the learner's UPDATE_PASSES).
    activations = 2 * learner.UPDATE_PASSES * 4 * d.hidden_layers * d.hidden_units
    row_bytes = 16 * (spec.obs_dim + spec.goal_dim + spec.action_dim + 2) + 24 + activations
    parts = {"replay buffer": episodes * episode_floats * 4,
             "networks": learner.network_bytes(d, spec),  # online, gradient, two Adam moments; targets
             "minibatch": d.batch_size * row_bytes,
             "envs": 2 * d.rollouts_per_cycle * one_env_bytes}
    if cfg.algo.mep.enabled:
        mep, features = cfg.algo.mep, (horizon + 1) * spec.goal_dim
        rows = min(mep.fit_subsample, episodes)
        # the mixture's covariances, precisions and their Cholesky factors; the fit's rows and responsibilities
        parts["MEP density"] = 8 * (3 * mep.n_components * features ** 2 + rows * (features + 2 * mep.n_components))
    return parts


# The settings that size each part of memory_parts, named when the run does not fit.
MEMORY_SETTINGS = {"replay buffer": "ddpg.buffer_size", "networks": "ddpg.hidden_units or ddpg.hidden_layers",
                   "minibatch": "ddpg.batch_size, ddpg.hidden_units or ddpg.hidden_layers",
                   "envs": "ddpg.rollouts_per_cycle",
                   "MEP density": "algo.mep.n_components or algo.mep.fit_subsample"}


def check_memory(cfg: TrainConfig, spec: EnvSpec, one_env_bytes: int) -> None:
    """ConfigError (one line) when the run cannot fit in this machine's available memory; it names the
    settings of the largest part."""
    parts, available = memory_parts(cfg, spec, one_env_bytes), available_memory_bytes()
    needed = sum(parts.values())
    if available is not None and needed > available:
        shown = ", ".join(f"{name} {size / 2**30:.1f}" for name, size in parts.items())
        raise ConfigError(f"this run needs {needed / 2**30:.1f} GiB ({shown}) but {available / 2**30:.1f} GiB are "
                          f"available; lower {MEMORY_SETTINGS[max(parts, key=parts.get)]}")


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write a state dict atomically (a temporary file renamed into place). A write that fails leaves ``path``
    as it was and no temporary file; on a full disk it raises :class:`DiskFullError` (one line: the file, the
    bytes it needs, those free), after a Ctrl-C KeyboardInterrupt. Written through a Python stream, whose
    OSError (or KeyboardInterrupt) torch keeps as the context of its own RuntimeError (a path given to
    torch.save fails with an ``enforce fail`` alone)."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as stream:
            torch.save(state, stream)
        os.replace(tmp, path)
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        if full_disk(err):
            raise DiskFullError(path, serialized_bytes(state)) from None
        if interrupted(err):  # a Ctrl-C during the write: the run's own Ctrl-C line, not torch's zip error
            raise KeyboardInterrupt from None
        raise


class _ByteCount(io.RawIOBase):
    """A stream that keeps nothing and counts the bytes written to it (``size``)."""

    def __init__(self) -> None:
        super().__init__()
        self.size = 0

    def writable(self) -> bool:
        return True

    def write(self, data: bytes) -> int:
        self.size += len(data)
        return len(data)


def serialized_bytes(state: dict[str, Any]) -> int:
    """The size of ``state``'s checkpoint file, serialized into a counter (nothing is stored)."""
    counter = _ByteCount()
    torch.save(state, counter)
    return counter.size


def load_checkpoint(path: Path, device: torch.device) -> dict[str, Any]:
    """Read a state dict, tensors of the networks and optimiser onto ``device``.

    Raises the underlying error (RuntimeError, EOFError, UnpicklingError) on a damaged file.
    """
    state = torch.load(path, weights_only=False, map_location=device)
    state["torch_rng"] = state["torch_rng"].cpu()  # the CPU generator's state stays on the CPU
    state["buffer"] = {k: v.cpu() if torch.is_tensor(v) else v for k, v in state["buffer"].items()}
    return state
