"""What every learner shares, and what the rest of a run asks of a learner.

A learner is a subclass of :class:`GoalConditionedLearner`, in a module of this package or anywhere
(an entry point of the group ``hersd.learners``, or ``learner._target_=<module>.<Class>``). Its class
declares everything the run needs to know about it, and nothing outside the learner's own module
names it (:mod:`hersd.engine.run_state` and :mod:`hersd.engine.train` look it up by name, :func:`learner_class`):

- ``NAME``: the value of ``learner.name`` that selects it; defining it registers the class;
- ``SETTINGS``: its settings dataclass; the config holds one object of it, the one ``build`` reads and
  the run's identity hashes (:class:`hersd.contract.config.LearnerConfig`);
- a class of this package takes both from its card (:mod:`hersd.contract.learners`, which the config reads
  without torch): ``class TD3(DDPG, card=CARD)``;
- :meth:`~GoalConditionedLearner.build`: the learner of a run from its config, env spec, discount,
  target range and device;
- :meth:`~GoalConditionedLearner.networks`, ``CRITICS``, ``TARGETS``: its networks (name -> input
  and output sizes, in the order they are made), which of them are critics, which have a target
  copy ``<name>_target``; the constructor builds them and the memory check sizes them from these;
- ``UPDATE_PASSES``: network passes of one update (the memory check's minibatch);
- ``target_range``: the clip of its critics' target (``None``: not clipped);
- ``LOSS_SETTINGS``: the settings of its own that scale its losses (named when they turn non-finite);
- ``PARTS``: its checkpointed attributes (the checkpoint's keys: never renamed, so old checkpoints load).

Shared here: :class:`RunningNormalizer`, :func:`mlp`, :class:`UpdateStats`, :func:`frozen_q` (a
critic through detached parameters, for actor losses), and in :class:`GoalConditionedLearner` the
normalised inputs, the critics' loss and the minimum of their targets (one critic: DDPG; twins:
TD3, SAC), the polyak move of the targets, ``policy_value`` and the checkpoint of ``PARTS``; and
``precision`` (docs/LEARNERS.md, "Precision"): ``matmul_context``, where ``update`` runs its passes
(bf16 autocast or nothing), and float32 output layers (:class:`FullPrecisionLinear`) under bf16.
"""

from __future__ import annotations

import contextlib
import copy
from functools import reduce
from typing import TYPE_CHECKING, ClassVar, NamedTuple, Optional

import numpy as np
import torch
from torch import nn

from hersd.contract import learner_registry as registry
from hersd.contract.config import DDPGConfig, TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.learners import LearnerCard
from hersd.engine.replay.buffer import TransitionBatch
from hersd.engine.resources import check_precision

if TYPE_CHECKING:
    from hersd.engine.envs.make import EnvSpec

TWIN_CRITICS = ("critic", "critic2")  # TD3's and SAC's critics: the target takes their minimum


def learner_class(name: str) -> type["GoalConditionedLearner"]:
    """The learner class of ``learner=name`` (:func:`hersd.contract.learner_registry.learner_class`), checked to be a
    :class:`GoalConditionedLearner`; ConfigError (one line) otherwise."""
    cls = registry.learner_class(name)  # the package's are registered: hersd.engine.learners imported this module
    if not issubclass(cls, GoalConditionedLearner):
        raise ConfigError(f"learner {name} is not a hersd.engine.learners.GoalConditionedLearner subclass")
    return cls


class RunningNormalizer:
    """Running mean/std of vectors of size dim, from sums kept in float64."""

    def __init__(self, dim: int, eps: float, clip: float, device: torch.device):
        self.eps, self.clip, self.device = eps, clip, device
        self.total = np.zeros(dim)
        self.total_sq = np.zeros(dim)
        self.count = 0
        self.mean = torch.zeros(dim, device=device)
        self.std = torch.ones(dim, device=device)

    def update(self, values: np.ndarray) -> None:
        """Add values (n, dim) to the statistics and recompute mean and std."""
        values = values.reshape(-1, self.total.shape[0]).astype(np.float64)
        self.total += values.sum(axis=0)
        self.total_sq += np.square(values).sum(axis=0)
        self.count += values.shape[0]
        mean = self.total / self.count
        std = np.sqrt(np.maximum(self.eps ** 2, self.total_sq / self.count - np.square(mean)))
        self.mean = torch.as_tensor(mean, dtype=torch.float32, device=self.device)
        self.std = torch.as_tensor(std, dtype=torch.float32, device=self.device)

    def __call__(self, values: torch.Tensor) -> torch.Tensor:
        return torch.clamp((values - self.mean) / self.std, -self.clip, self.clip)

    def state_dict(self) -> dict:
        return {"total": self.total.copy(), "total_sq": self.total_sq.copy(), "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.total, self.total_sq, self.count = state["total"].copy(), state["total_sq"].copy(), state["count"]
        if self.count:
            self.update(np.zeros((0, self.total.shape[0])))


class FullPrecisionLinear(nn.Linear):
    """A linear layer that runs in float32 under autocast (precision=bf16's output layers): (B, in) -> (B, out)."""

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        with torch.autocast(inputs.device.type, enabled=False):
            return super().forward(inputs.float())


def mlp(in_dim: int, out_dim: int, hidden_layers: int, hidden_units: int,
        output_layer: type[nn.Linear] = nn.Linear) -> nn.Sequential:
    """ReLU MLP; ``output_layer`` the class of its last layer (same parameters and initialisation)."""
    layers: list[nn.Module] = []
    for _ in range(hidden_layers):  # in-place ReLU: Linear's backward does not need its output
        layers += [nn.Linear(in_dim, hidden_units), nn.ReLU(inplace=True)]
        in_dim = hidden_units
    layers.append(output_layer(in_dim, out_dim))
    return nn.Sequential(*layers)


def mlp_parameters(in_dim: int, out_dim: int, hidden_layers: int, hidden_units: int) -> int:
    """The number of weights and biases of :func:`mlp` with these sizes (without building it)."""
    hidden = (hidden_layers - 1) * (hidden_units * hidden_units + hidden_units)
    return in_dim * hidden_units + hidden_units + hidden + hidden_units * out_dim + out_dim


class UpdateStats(NamedTuple):
    """Per-update scalars: losses, the mean and mean square of Q(s, a) over the batch, (SAC only) the
    mean -log pi(a|s) of the actor's sampled actions, and Q(s, a) summed over the batch's real-goal and
    relabelled rows (the Q split by row type)."""

    critic_loss: float
    actor_loss: float
    q_mean: float
    q_sq_mean: float
    entropy: Optional[float] = None
    q_real_sum: float = 0.0
    q_hindsight_sum: float = 0.0

    @classmethod
    def of(cls, critic_loss: float, actor_loss: float, q: torch.Tensor, batch: TransitionBatch,
           entropy: Optional[float] = None) -> "UpdateStats":
        """The stats of an update whose critic gave q (B, 1), detached, on ``batch``."""
        relabelled = torch.from_numpy(batch.relabelled).to(q.device)
        q_rows = q.squeeze(1).double()
        return cls(critic_loss, actor_loss, q.mean().item(), torch.square(q).mean().item(), entropy,
                   q_rows[~relabelled].sum().item(), q_rows[relabelled].sum().item())


def frozen_q(critic: nn.Module, inputs: torch.Tensor) -> torch.Tensor:
    """Q of critic inputs (B, in_dim + action_dim) -> (B, 1) through detached parameters: gradients
    reach the inputs (the actor's action), never the critic."""
    frozen = {name: p.detach() for name, p in critic.named_parameters()}
    return torch.func.functional_call(critic, frozen, (inputs,))


class GoalConditionedLearner:
    """The input normalisers, networks and plumbing of a learner. A subclass sets the class facts below,
    builds its optimisers after calling this constructor and defines ``build``, ``act`` and ``update``."""

    NAME: ClassVar[str]  # learner=NAME selects the class; set in its body or by its card, it registers the class
    # Its settings, learner.<name>.*: a dataclass whose fields are the settings (range checks in __post_init__,
    # ConfigError), or None. The config holds one object of it (cfg.learner.settings): the one build reads, the
    # one the run's identity hashes. A subclass inherits it, under its own name.
    SETTINGS: ClassVar[Optional[type]] = None
    CRITICS: ClassVar[tuple[str, ...]] = ("critic",)  # the critics among the networks; the first is the one reported
    TARGETS: ClassVar[tuple[str, ...]] = ()  # networks with a target copy <name>_target, moved by update_targets
    PARTS: ClassVar[tuple[str, ...]] = ()  # attributes with state_dict/load_state_dict: the checkpoint's keys
    LOSS_SETTINGS: ClassVar[str] = ""  # its own settings that scale its losses (beyond the shared ddpg.* ones)
    UPDATE_PASSES: ClassVar[int] = 0  # network passes of one update on a minibatch (sizes its activations)
    target_range: Optional[tuple[float, float]] = None  # the clip of the critics' target; None: not clipped

    def __init_subclass__(cls, card: Optional[LearnerCard] = None, **kwargs) -> None:
        """A class given its ``card`` (a learner of this package: ``class TD3(DDPG, card=CARD)``) takes its NAME and
        SETTINGS from it and declares neither itself (TypeError); a class with a NAME is registered under it."""
        super().__init_subclass__(**kwargs)
        if card is not None:
            if {"NAME", "SETTINGS"} & set(cls.__dict__):
                raise TypeError(f"{cls.__name__} takes its NAME and SETTINGS from its card ({card.name}): "
                                "declare them there only")
            cls.NAME, cls.SETTINGS = card.name, card.settings
        if "NAME" in cls.__dict__:
            if cls.NAME in registry.LEARNERS:
                raise TypeError(f"two learners named {cls.NAME!r}: {registry.LEARNERS[cls.NAME].__name__} and "
                                f"{cls.__name__}")
            registry.LEARNERS[cls.NAME] = cls

    @classmethod
    def build(cls, cfg: TrainConfig, spec: "EnvSpec", gamma: float, q_range: tuple[float, float],
              device: torch.device) -> "GoalConditionedLearner":
        """The run's learner: from its config, the env's sizes, the discount, the range a discounted sum
        of the run's rewards lies in (:func:`hersd.engine.run_state.discounting`) and the device."""
        raise NotImplementedError

    @classmethod
    def networks(cls, spec: "EnvSpec") -> dict[str, tuple[int, int]]:
        """The online networks, name -> (inputs, outputs), in the order they are made (one torch RNG
        stream): an actor on the normalised (obs, goal), then each critic on (obs, goal, action)."""
        in_dim = spec.obs_dim + spec.goal_dim
        return {"actor": (in_dim, spec.action_dim), **dict.fromkeys(cls.CRITICS, (in_dim + spec.action_dim, 1))}

    @classmethod
    def network_bytes(cls, cfg: DDPGConfig, spec: "EnvSpec") -> int:
        """Bytes of the float32 networks: each online one with its gradient and two Adam moments, and the targets."""
        sizes = {name: mlp_parameters(*shape, cfg.hidden_layers, cfg.hidden_units)
                 for name, shape in cls.networks(spec).items()}
        return 4 * (4 * sum(sizes.values()) + sum(sizes[name] for name in cls.TARGETS))

    def __init__(self, cfg: DDPGConfig, spec: "EnvSpec", gamma: float, device: torch.device, precision: str = "fp32"):
        check_precision(precision, device.type)
        self.cfg, self.max_action, self.gamma, self.device = cfg, spec.max_action, gamma, device
        self.precision = precision
        self.obs_norm = RunningNormalizer(spec.obs_dim, cfg.norm_eps, cfg.clip_norm, device)
        self.goal_norm = RunningNormalizer(spec.goal_dim, cfg.norm_eps, cfg.clip_norm, device)
        output_layer = nn.Linear if precision == "fp32" else FullPrecisionLinear
        for name, (inputs, outputs) in self.networks(spec).items():
            setattr(self, name, mlp(inputs, outputs, cfg.hidden_layers, cfg.hidden_units, output_layer).to(device))
        for name in self.TARGETS:
            setattr(self, f"{name}_target", copy.deepcopy(getattr(self, name)).requires_grad_(False))

    def matmul_context(self) -> contextlib.AbstractContextManager:
        """Where an update's forward passes run: as they are (fp32), or under bf16 autocast (bf16: hidden
        layers in bfloat16; output layers, losses, targets and normalisers stay float32)."""
        if self.precision == "fp32":
            return contextlib.nullcontext()
        return torch.autocast(self.device.type, dtype=torch.bfloat16)

    def tensor(self, array: np.ndarray) -> torch.Tensor:
        """A host numpy array as a tensor on the agent's device (no copy on the CPU)."""
        return torch.from_numpy(array).to(self.device)

    def _inputs(self, obs: np.ndarray, goal: np.ndarray) -> torch.Tensor:
        """Raw obs (B, obs_dim) and goal (B, goal_dim) -> normalised actor input (B, obs_dim + goal_dim)."""
        clip = self.cfg.clip_obs
        obs_t = self.tensor(np.clip(obs, -clip, clip, dtype=np.float32))
        goal_t = self.tensor(np.clip(goal, -clip, clip, dtype=np.float32))
        return torch.cat([self.obs_norm(obs_t), self.goal_norm(goal_t)], dim=1)

    def update_normalizers(self, obs: np.ndarray, goal: np.ndarray) -> None:
        clip = self.cfg.clip_obs
        self.obs_norm.update(np.clip(obs, -clip, clip))
        self.goal_norm.update(np.clip(goal, -clip, clip))

    def critic_loss(self, inputs: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Sum over the critics of mean (target - Q_i(inputs))^2 for inputs (B, in_dim + action_dim) and
        target (B, 1): each critic regresses to the one target. Returns it and the first critic's Q (B, 1)."""
        qs = [getattr(self, name)(inputs) for name in self.CRITICS]
        return reduce(torch.add, (torch.mean(torch.square(target - q)) for q in qs)), qs[0]

    @torch.no_grad()
    def min_target_q(self, inputs: torch.Tensor) -> torch.Tensor:
        """The minimum over the critics' targets of Q'(inputs): (B, in_dim + action_dim) -> (B, 1)."""
        return reduce(torch.minimum, (getattr(self, f"{name}_target")(inputs) for name in self.CRITICS))

    @torch.no_grad()
    def polyak(self, *pairs: tuple[nn.Module, nn.Module]) -> None:
        """target <- polyak * target + (1 - polyak) * online for each (online, target) pair."""
        for online, target in pairs:
            torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), 1.0 - self.cfg.polyak)

    def update_targets(self) -> None:
        """target <- polyak * target + (1 - polyak) * online for every network in ``TARGETS``."""
        self.polyak(*((getattr(self, name), getattr(self, f"{name}_target")) for name in self.TARGETS))

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions (n, action_dim) for obs (n, obs_dim) and goal (n, goal_dim), float64; explore: training's."""
        raise NotImplementedError

    @torch.no_grad()
    def policy_value(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Q(s, pi(s, g), g) of the deterministic policy for obs (n, obs_dim), goal (n, goal_dim) -> (n,)
        float64, by ``self.critic`` (the critic the actor climbs; TD3's and SAC's first twin)."""
        action = self.act(obs, goal, explore=False, rng=None) / self.max_action
        inputs = torch.cat([self._inputs(obs, goal), self.tensor(action.astype(np.float32))], dim=1)
        return self.critic(inputs).squeeze(1).cpu().numpy().astype(np.float64)

    def update(self, batch: TransitionBatch) -> UpdateStats:
        raise NotImplementedError

    def state_dict(self) -> dict:
        return {name: getattr(self, name).state_dict() for name in self.PARTS}

    def load_state_dict(self, state: dict) -> None:
        for name, value in state.items():
            getattr(self, name).load_state_dict(value)
