"""The critic against the truth: how far Q(s_t, pi(s_t, g), g) lies from the discounted return the
deterministic policy actually obtains from s_t when it pursues g (the seed paper's Fig. 10 question,
measured as the TD3 paper's Fig. 1 measures overestimation).

After each epoch of ``bias.epochs`` (:class:`hersd.config.BiasConfig`), :meth:`BiasEvaluator.evaluate`:

1. runs ``bias.episodes`` deterministic-policy episodes from fresh resets, each for T - 1 +
   ``return_steps`` steps under its real goal g; every state s_t with t < T is valued, and its
   return is the episode's own continuation: sum_{j < return_steps} gamma^j r_{t+j};
2. draws ``bias.hindsight_pairs`` (s_t, g') pairs from those episodes, g' an achieved goal of
   the episode's future (ag_{t'}, t' uniform in t+1..T, HER's ``future``); restores the
   simulator to s_t (MuJoCo's full integration state), sets the goal to g' and rolls the policy,
   now conditioned on g', for ``return_steps`` steps. The recorded continuation was driven by g,
   so its rewards under g' are not the policy's return for g'.

Rewards are the env's own (lambda = 1: for ARCHER the critic's hindsight targets are scaled by
lambda_h by design). The critic bootstraps through the time limit (no done mask), so for a policy
that never succeeds its fixed point is -1 / (1 - gamma) = -50, while 50 steps of -1 sum to -18.9:
returns therefore run ``return_steps`` (default 300 = T + 250) steps past s_t, leaving out a tail of
weight gamma^300 = 0.0023 (at most 0.12 of -50).

The evaluation has its own envs and its own random stream (seeded from the run's seed and the
epoch), and only reads the agent: the run's envs, RNGs, torch's RNG and metrics do not depend on
it, and the same run and epoch give the same evaluation, resumed or not. Its torch work runs with
the run's ``flush_denormal``; the physics never does.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Protocol

import mujoco
import numpy as np

from hersd.config import BiasConfig, TaskConfig
from hersd.denormals import denormals_flushed
from hersd.envs.make import make_env

BIAS_SALT = 0x62696173  # keeps the evaluation's stream apart from any other stream of the run's seed
GOAL_TYPES = ("real", "hindsight")
MJ_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # qpos, qvel, act, ctrl, mocap, warm start, time: a step's inputs
RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


class Policy(Protocol):
    """What the evaluation reads of a learner (:class:`hersd.learners.GoalConditionedLearner`)."""

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: Any) -> np.ndarray: ...

    def policy_value(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray: ...


def bias_fields(samples: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, float | int | None]:
    """Per goal type, (Q (n,), return (n,)) -> the log's ``bias_<type>_mean/std/count`` and ``return_<type>_mean``."""
    fields: dict[str, float | int | None] = {}
    for goal_type in GOAL_TYPES:
        q, returns = samples.get(goal_type, (np.zeros(0), np.zeros(0)))
        bias = q - returns
        empty = bias.size == 0
        fields |= {f"bias_{goal_type}_mean": None if empty else float(bias.mean()),
                   f"bias_{goal_type}_std": None if empty else float(bias.std()),
                   f"bias_{goal_type}_count": int(bias.size),
                   f"return_{goal_type}_mean": None if empty else float(returns.mean())}
    return fields


def discounted_returns(rewards: np.ndarray, gamma: float, steps: int) -> np.ndarray:
    """rewards (n, L) -> (n, L - steps + 1): entry t is sum_{j < steps} gamma^j rewards[:, t + j]."""
    weights = gamma ** np.arange(steps)
    windows = np.lib.stride_tricks.sliding_window_view(rewards.astype(np.float64), steps, axis=1)
    return windows @ weights


class BiasEvaluator:
    """The evaluation's own envs (made at the first evaluation) and the run's constants."""

    def __init__(self, cfg: BiasConfig, task: TaskConfig, seed: int, horizon: int, gamma: float, reward: RewardFn,
                 flush_denormal: bool = True):
        self.cfg, self.task, self.seed, self.horizon, self.gamma = cfg, task, seed, horizon, gamma
        self.reward, self.flush_denormal = reward, flush_denormal
        self.envs: list[Any] = []

    def due(self, epoch: int) -> bool:
        return epoch in self.cfg.epochs

    def evaluate(self, agent: Policy, epoch: int) -> dict[str, float | int | None]:
        """The log fields of the evaluation after ``epoch`` (:func:`bias_fields` and ``bias_seconds``)."""
        tic = time.perf_counter()
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, BIAS_SALT, epoch]))
        self.envs += [make_env(self.task) for _ in range(max(self.cfg.episodes, self.cfg.hindsight_pairs) - len(self.envs))]
        envs, T = self.envs[:self.cfg.episodes], self.horizon
        for env, env_seed in zip(envs, rng.integers(2 ** 31, size=len(envs))):
            env.reset(seed=int(env_seed))
        goal = np.array([env._get_obs()["desired_goal"] for env in envs], np.float32)
        obs, achieved, states = self._rollout(agent, envs, goal, T - 1 + self.cfg.return_steps, kept_states=T)
        returns = self._returns(achieved, goal)  # (episodes, T)
        q = self._value(agent, obs[:, :T].reshape(len(envs) * T, -1), np.repeat(goal, T, axis=0))
        samples = {"real": (q, returns.reshape(-1))}
        if self.cfg.hindsight_pairs:
            samples["hindsight"] = self._hindsight(agent, rng, obs, achieved, states)
        return bias_fields(samples) | {"bias_seconds": time.perf_counter() - tic}

    def _hindsight(self, agent: Policy, rng: np.random.Generator, obs: np.ndarray, achieved: np.ndarray,
                   states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q (pairs,), return (pairs,)) of pairs (s_t, ag_{t'}), t' in t+1..T, each rolled out from the restored s_t."""
        pairs, T = self.cfg.hindsight_pairs, self.horizon
        episode = rng.integers(obs.shape[0], size=pairs)
        t = rng.integers(T, size=pairs)
        future = t + 1 + (rng.random(pairs) * (T - t)).astype(int)  # uniform in t+1..T
        goals = achieved[episode, future]
        envs = self.envs[:pairs]
        for env, state, hindsight_goal in zip(envs, states[episode, t], goals):
            mujoco.mj_setState(env.model, env.data, state, MJ_STATE)
            mujoco.mj_forward(env.model, env.data)
            env.goal = hindsight_goal.astype(np.float64)
        _, rolled, _ = self._rollout(agent, envs, goals, self.cfg.return_steps, kept_states=0)
        return self._value(agent, obs[episode, t], goals), self._returns(rolled, goals)[:, 0]

    def _returns(self, achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Achieved goals (n, L+1, goal_dim) of rollouts pursuing goal (n, goal_dim) -> the discounted return
        from each of their first L - return_steps + 1 states (n, L - return_steps + 1)."""
        rewards = self.reward(achieved[:, 1:], np.broadcast_to(goal[:, None], achieved[:, 1:].shape))
        return discounted_returns(rewards, self.gamma, self.cfg.return_steps)

    def _rollout(self, agent: Policy, envs: list, goal: np.ndarray, steps: int,
                 kept_states: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The deterministic policy pursuing goal (n, goal_dim) for ``steps`` steps in each env from where it
        stands -> obs (n, steps+1, obs_dim), achieved (n, steps+1, goal_dim) and the MuJoCo state before each
        of the first ``kept_states`` steps (n, kept_states, state_size)."""
        current = [env._get_obs() for env in envs]
        n = len(envs)
        obs = np.empty((n, steps + 1, current[0]["observation"].shape[0]), np.float32)
        achieved = np.empty((n, steps + 1, goal.shape[1]), np.float32)
        states = np.empty((n, kept_states, mujoco.mj_stateSize(envs[0].model, MJ_STATE)))
        obs[:, 0] = [o["observation"] for o in current]
        achieved[:, 0] = [o["achieved_goal"] for o in current]
        for step in range(steps):
            if step < kept_states:
                for i, env in enumerate(envs):
                    mujoco.mj_getState(env.model, env.data, states[i, step], MJ_STATE)
            with denormals_flushed(self.flush_denormal):
                actions = agent.act(obs[:, step], goal, explore=False, rng=None)
            for i, env in enumerate(envs):
                step_obs = env.step(actions[i])[0]
                obs[i, step + 1] = step_obs["observation"]
                achieved[i, step + 1] = step_obs["achieved_goal"]
        return obs, achieved, states

    def _value(self, agent: Policy, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        with denormals_flushed(self.flush_denormal):
            return agent.policy_value(obs, goal)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []
