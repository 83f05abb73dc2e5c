"""The critic against the truth: how far Q(s_t, pi(s_t, g), g) lies from the discounted return the
deterministic policy actually obtains from s_t when it pursues g (the seed paper's Fig. 10 question,
measured as the TD3 paper's Fig. 1 measures overestimation).

After each epoch of ``bias.epochs`` (:class:`hersd.contract.config.BiasConfig`), :meth:`BiasEvaluator.evaluate`:

1. runs ``bias.episodes`` deterministic-policy episodes from fresh resets, each for T - 1 +
   ``return_steps`` steps under its real goal g; every state s_t with t < T is valued, and its
   return is the episode's own continuation: sum_{j < return_steps} gamma^j r_{t+j};
2. draws ``bias.hindsight_pairs`` (s_t, g') pairs from those episodes, g' an achieved goal of
   the episode's future (ag_{t'}, t' uniform in t+1..T, HER's ``future``); restores the
   simulator to s_t, sets the goal to g' and rolls the policy, now conditioned on g', for
   ``return_steps`` steps. The recorded continuation was driven by g, so its rewards under g' are
   not the policy's return for g';
3. draws ``bias.moved_pairs`` more pairs the same way among those whose g' lies farther than the
   success radius from ag_t (goals the object was actually moved to: "moved"), valued alike. Most
   ``hindsight`` pairs of an early policy are goals it already achieves (the object never moved),
   whose return is exactly 0 whatever the critic: ``bias_hindsight_zero_share`` logs their share.

Restoring s_t is exact on every task: the env is set to its episode's first state (taken after the
reset, whose ``mj_forward`` leaves every derived quantity current), and the episode's recorded actions
up to t are stepped again (:func:`restore`). Setting s_t's integration state directly is not exact
where a step does not end with ``mj_forward`` (FetchPickAndPlace: the observation and the mocap
target read kinematics one substep old; continuations drifted by up to 5 mm).

Rewards are the env's own (lambda = 1: for ARCHER the critic's hindsight targets are scaled by
lambda_h by design). The critic bootstraps through the time limit (no done mask), so for a policy
that never succeeds its fixed point is -1 / (1 - gamma) = -50, while the discounted -1s left in its
50-step episode sum to -18.9 on average over its states: returns therefore run ``return_steps``
(default 300 = T + 250) steps past s_t, leaving out a tail of weight gamma^300 = 0.0023 (at most
0.12 of -50).

The evaluation has its own envs and its own random stream (seeded from the run's seed and the
epoch), and only reads the agent: the run's envs, RNGs, torch's RNG and metrics do not depend on
it, and the same run and epoch give the same evaluation, resumed or not. Its torch work runs with
the run's ``flush_denormal``; the physics never does.
"""

from __future__ import annotations

import time
from typing import Any, Callable, NamedTuple, Protocol

import mujoco
import numpy as np

from hersd.contract.config import BiasConfig, TaskConfig
from hersd.engine.denormals import denormals_flushed
from hersd.engine.envs.goal_envs import success_radius
from hersd.engine.envs.make import make_env

BIAS_SALT = 0x62696173  # keeps the evaluation's stream apart from any other stream of the run's seed
GOAL_TYPES = ("real", "hindsight", "moved")
MJ_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # qpos, qvel, act, ctrl, mocap, warm start, time: a step's inputs
RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


class Rollout(NamedTuple):
    """n episodes of ``steps`` steps: MuJoCo's integration state at the start (n, state_size), the actions
    taken (n, steps, action_dim), the observations (n, steps+1, obs_dim) and achieved goals (n, steps+1, goal_dim)."""

    start: np.ndarray
    actions: np.ndarray
    obs: np.ndarray
    achieved: np.ndarray


class Policy(Protocol):
    """What the evaluation reads of a learner (:class:`hersd.engine.learners.GoalConditionedLearner`)."""

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: Any) -> np.ndarray: ...

    def policy_value(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray: ...


def bias_fields(samples: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, float | int | None]:
    """Per goal type, (Q (n,), return (n,)) -> the log's ``bias_<type>_mean/std/count`` and ``return_<type>_mean``,
    and ``bias_hindsight_zero_share``, the share of hindsight pairs whose return is exactly 0."""
    hindsight_returns = samples.get("hindsight", (None, np.zeros(0)))[1]
    fields: dict[str, float | int | None] = {
        "bias_hindsight_zero_share": float(np.mean(hindsight_returns == 0)) if hindsight_returns.size else None}
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


def restore(env: Any, start: np.ndarray, actions: np.ndarray) -> None:
    """Put ``env`` exactly where an episode stood after ``actions`` (t, action_dim): its first state ``start``
    (MuJoCo's integration state right after the reset, warm start included), then its actions stepped again."""
    mujoco.mj_setState(env.model, env.data, start, MJ_STATE)
    mujoco.mj_forward(env.model, env.data)
    for action in actions:
        env.step(action)


def draw_pairs(rng: np.random.Generator, achieved: np.ndarray, horizon: int, count: int,
               radius: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` pairs (episode, t, t'), t uniform in 0..T-1 and t' in t+1..T, of episodes' achieved goals
    (n, >= T+1, goal_dim); with ``radius``, uniform among the pairs with ||ag_{t'} - ag_t|| > radius
    (none if there are none) -> three int arrays (count,) or (0,)."""
    T = horizon
    if radius is None:
        episode = rng.integers(achieved.shape[0], size=count)
        t = rng.integers(T, size=count)
        return episode, t, t + 1 + (rng.random(count) * (T - t)).astype(int)  # t' uniform in t+1..T
    goals = achieved[:, :T + 1].astype(np.float64)
    distance = np.linalg.norm(goals[:, None, :, :] - goals[:, :T, None, :], axis=-1)  # (n, t, t')
    later = np.arange(T + 1)[None, :] > np.arange(T)[:, None]  # (t, t'): t' > t
    candidates = np.argwhere((distance > radius) & later)
    if not count or not len(candidates):
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0, int)
    chosen = candidates[rng.integers(len(candidates), size=count)]
    return chosen[:, 0], chosen[:, 1], chosen[:, 2]


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
        cfg, T = self.cfg, self.horizon
        self.envs += [make_env(self.task) for _ in range(max(cfg.episodes, cfg.hindsight_pairs + cfg.moved_pairs)
                                                          - len(self.envs))]
        envs = self.envs[:cfg.episodes]
        for env, env_seed in zip(envs, rng.integers(2 ** 31, size=len(envs))):
            env.reset(seed=int(env_seed))
        goal = np.array([env._get_obs()["desired_goal"] for env in envs], np.float32)
        episodes = self._rollout(agent, envs, goal, T - 1 + cfg.return_steps)
        returns = self._returns(episodes.achieved, goal)  # (episodes, T)
        q = self._value(agent, episodes.obs[:, :T].reshape(len(envs) * T, -1), np.repeat(goal, T, axis=0))
        pairs = {"hindsight": draw_pairs(rng, episodes.achieved, T, cfg.hindsight_pairs),
                 "moved": draw_pairs(rng, episodes.achieved, T, cfg.moved_pairs, success_radius(self.envs[0]))}
        return bias_fields({"real": (q, returns.reshape(-1)), **self._pairs(agent, episodes, pairs)}) | {
            "bias_seconds": time.perf_counter() - tic}

    def _pairs(self, agent: Policy, episodes: Rollout, pairs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]
               ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per kind, (Q (pairs,), return (pairs,)) of its pairs (s_t, ag_{t'}), all rolled out together, each from
        its restored s_t."""
        episode, t, future = (np.concatenate(parts) for parts in zip(*pairs.values()))
        if not episode.size:
            return {}
        goals = episodes.achieved[episode, future]
        envs = self.envs[:episode.size]
        for env, e, steps, pair_goal in zip(envs, episode, t, goals):
            env.goal = pair_goal.astype(np.float64)  # the env's own reward and info read it; the physics does not
            restore(env, episodes.start[e], episodes.actions[e, :steps])
        rolled = self._rollout(agent, envs, goals, self.cfg.return_steps)
        q, returns = self._value(agent, episodes.obs[episode, t], goals), self._returns(rolled.achieved, goals)[:, 0]
        bounds = np.cumsum([0, *(len(kind[0]) for kind in pairs.values())])
        return {kind: (q[a:b], returns[a:b]) for kind, a, b in zip(pairs, bounds[:-1], bounds[1:])}

    def _returns(self, achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Achieved goals (n, L+1, goal_dim) of rollouts pursuing goal (n, goal_dim) -> the discounted return
        from each of their first L - return_steps + 1 states (n, L - return_steps + 1)."""
        rewards = self.reward(achieved[:, 1:], np.broadcast_to(goal[:, None], achieved[:, 1:].shape))
        return discounted_returns(rewards, self.gamma, self.cfg.return_steps)

    def _rollout(self, agent: Policy, envs: list, goal: np.ndarray, steps: int) -> Rollout:
        """The deterministic policy pursuing goal (n, goal_dim) for ``steps`` steps in each env from where it
        stands (:class:`Rollout`)."""
        current = [env._get_obs() for env in envs]
        n = len(envs)
        start = np.empty((n, mujoco.mj_stateSize(envs[0].model, MJ_STATE)))
        for i, env in enumerate(envs):
            mujoco.mj_getState(env.model, env.data, start[i], MJ_STATE)
        obs = np.empty((n, steps + 1, current[0]["observation"].shape[0]), np.float32)
        achieved = np.empty((n, steps + 1, goal.shape[1]), np.float32)
        actions = np.empty((n, steps, envs[0].action_space.shape[0]))
        obs[:, 0] = [o["observation"] for o in current]
        achieved[:, 0] = [o["achieved_goal"] for o in current]
        for step in range(steps):
            with denormals_flushed(self.flush_denormal):
                actions[:, step] = agent.act(obs[:, step], goal, explore=False, rng=None)
            for i, env in enumerate(envs):
                step_obs = env.step(actions[i, step])[0]
                obs[i, step + 1] = step_obs["observation"]
                achieved[i, step + 1] = step_obs["achieved_goal"]
        return Rollout(start, actions, obs, achieved)

    def _value(self, agent: Policy, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        with denormals_flushed(self.flush_denormal):
            return agent.policy_value(obs, goal)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []
