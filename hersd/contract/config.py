"""Typed configuration of one training run.

The YAML files under ``conf/`` are merged onto these dataclasses (registered in Hydra's
ConfigStore by :func:`hersd.contract.compose.register_train_schema`), so a wrong type or an unknown
key fails at composition. Range checks live in ``__post_init__`` and run when
:func:`to_train_config` turns the composed config into objects; they raise
:class:`ConfigError` whose message is one line naming the field and the allowed values.

Every default is the seed paper's appendix setting (which follows the reference HER code).
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from dataclasses import asdict, dataclass, field
from typing import Any, List, Optional

from omegaconf import DictConfig, OmegaConf

from hersd.contract.checks import (HORIZON_LIMIT, LR_LIMIT, SCALE_LIMIT, check, check_number, is_finite,
                                   settings_of)
from hersd.contract.errors import ConfigError
from hersd.contract.learner_registry import learner_class, recorded_name
from hersd.contract.learners import package_cards
# TD3's and SAC's settings were defined here before the cards: users' learners still import them from here.
from hersd.contract.learners.sac import SACConfig  # noqa: F401
from hersd.contract.learners.td3 import TD3Config  # noqa: F401
from hersd.contract.schedules import Schedule, schedule_from_config, settle
from hersd.contract.schedules.registry import raised
from hersd.contract.tasks import CUSTOM, CUSTOM_CYCLES_PER_EPOCH, TASKS
from hersd.contract.tensorboard_events import require_tensorboard

GOAL_STRATEGIES = ("future", "final", "episode")
DEVICES = ("auto", "cpu", "cuda")
PRECISIONS = ("fp32", "bf16")
UPDATES = ("autograd", "fast")
# rank ** (1/temperature) stays below float64's 1.8e308 summed over n episodes while
# (1 + 1/temperature) * ln(n) < 709.8: with temperature >= 0.05, for n < 4e14 episodes (any memory).
MEP_MIN_TEMPERATURE = 0.05
MAX_THREADS = 1024  # threads=N at most: torch takes a C int, and no machine here has more cores


@dataclass
class TaskConfig:
    name: str = "push"  # a task of hersd/contract/tasks.py (reach, push, ... hand_block), or custom (with task.env_id)
    env_id: Optional[str] = None  # gymnasium-robotics env id; null: the task's; task=custom: any goal-conditioned env
    cycles_per_epoch: Optional[int] = None  # rollout+update cycles per epoch; null: the task's (50; FetchReach 10)
    # Success radius in metres; null keeps the env's own (0.05 m for every v4 Fetch task).
    # The paper's text states 0.07 m (Push, PickAndPlace) and 0.20 m (Slide).
    distance_threshold: Optional[float] = None

    def __post_init__(self) -> None:
        if self.name == CUSTOM:
            check(bool(self.env_id), "task=custom needs task.env_id=<a goal-conditioned gymnasium-robotics env id>")
        else:
            check(self.name in TASKS or (self.env_id and self.name == self.env_id),  # a resolved custom task
                  f"task={self.name!r} is not a known task; choose one of: {', '.join([*TASKS, CUSTOM])}")
            expected = TASKS[self.name].env_id if self.name in TASKS else self.name
            check(self.env_id in (None, expected),
                  f"task.env_id={self.env_id!r} does not match task={self.name!r} ({expected}); "
                  f"for another env use task=custom task.env_id={self.env_id}")
        check(self.cycles_per_epoch is None or self.cycles_per_epoch >= 1,
              f"task.cycles_per_epoch must be >= 1, got {self.cycles_per_epoch}")
        if self.distance_threshold is not None:
            check(is_finite(self.distance_threshold) and self.distance_threshold > 0,
                  f"task.distance_threshold must be a positive number of metres or null, got {self.distance_threshold}")

    def resolve(self) -> None:
        """Fill the null env_id and cycles_per_epoch from the task table; a custom task takes its
        env id as its name (by the training config, not here: the schema's own default instance
        must stay unresolved)."""
        if self.name in TASKS:
            self.env_id = self.env_id or TASKS[self.name].env_id
            self.cycles_per_epoch = self.cycles_per_epoch or TASKS[self.name].cycles_per_epoch
        else:
            self.name = self.env_id
            self.cycles_per_epoch = self.cycles_per_epoch or CUSTOM_CYCLES_PER_EPOCH


@dataclass
class MEPConfig:
    # MEP (Zhao et al. 2019; hersd/engine/replay/mep.py, docs/MEP.md): from epoch 2 on, episodes are drawn by the
    # rarity of their achieved-goal trajectory under a density model refit once per epoch.
    enabled: bool = False  # sample episodes by trajectory rarity instead of uniformly
    temperature: float = 1.0  # p ~ rank(rarity) ** (1 / temperature), rank 1 = most common; larger is flatter
    n_components: int = 3  # components of the Bayesian Gaussian mixture (Dirichlet weight prior)
    fit_subsample: int = 2000  # each epoch's fit uses at most this many stored trajectories, drawn uniformly
    max_iter: int = 100  # EM iterations per fit at most (fits after the first start from the last one)

    def __post_init__(self) -> None:
        check(is_finite(self.temperature) and self.temperature >= MEP_MIN_TEMPERATURE,
              f"algo.mep.temperature must be a number >= {MEP_MIN_TEMPERATURE:g} (rank ** (1 / temperature) "
              f"overflows below), got {self.temperature}")
        check(self.n_components >= 1, f"algo.mep.n_components must be >= 1, got {self.n_components}")
        check(self.fit_subsample >= self.n_components,
              f"algo.mep.fit_subsample must be >= algo.mep.n_components, got {self.fit_subsample}")
        check(self.max_iter >= 1, f"algo.mep.max_iter must be >= 1, got {self.max_iter}")


@dataclass
class AlgoConfig:
    name: str = "her"  # label used in run names and reports
    lambda_r: float = 1.0  # weight of real rewards (eq. 7); HER: 1, ARCHER: 1
    lambda_h: float = 1.0  # weight of hindsight rewards (eq. 8); HER: 1, ARCHER: 0.5
    goal_strategy: str = "future"  # where hindsight goals come from: future | final | episode
    mep: MEPConfig = field(default_factory=MEPConfig)

    def __post_init__(self) -> None:
        check(self.goal_strategy in GOAL_STRATEGIES,
              f"algo.goal_strategy={self.goal_strategy!r} is unknown; choose one of: {', '.join(GOAL_STRATEGIES)}")
        for name in ("lambda_r", "lambda_h"):
            check_number(f"algo.{name}", getattr(self, name), 1 / SCALE_LIMIT, SCALE_LIMIT)


@dataclass
class DDPGConfig:
    hidden_layers: int = 3  # actor and critic: this many hidden layers ...
    hidden_units: int = 256  # ... of this many ReLU units
    actor_lr: float = 1e-3  # Adam learning rate of the actor
    critic_lr: float = 1e-3  # Adam learning rate of the critic
    buffer_size: int = 1_000_000  # replay capacity in transitions (stored as whole episodes)
    polyak: float = 0.95  # target <- polyak * target + (1 - polyak) * online, once per cycle
    action_l2: float = 1.0  # weight of mean((pi / max_u)^2) in the actor loss
    clip_obs: float = 200.0  # raw observations and goals are clipped to [-clip_obs, clip_obs]
    clip_norm: float = 5.0  # normalised inputs are clipped to [-clip_norm, clip_norm]
    norm_eps: float = 0.01  # lower bound of the normaliser's standard deviation
    batch_size: int = 256  # transitions per update
    rollouts_per_cycle: int = 2  # parallel episodes collected per cycle (the paper's 2 rollouts x 1 worker)
    batches_per_cycle: int = 40  # updates per cycle
    test_rollouts: int = 10  # evaluation rounds per epoch, each of rollouts_per_cycle episodes (= 20 episodes)
    random_eps: float = 0.3  # probability that a training action is uniform random
    noise_eps: float = 0.2  # std of the Gaussian noise added to training actions (times max_u)
    gamma: Optional[float] = None  # discount; null means 1 - 1/T (0.98 for T = 50)

    def __post_init__(self) -> None:
        for name in ("hidden_layers", "hidden_units", "buffer_size", "batch_size", "rollouts_per_cycle",
                     "batches_per_cycle", "test_rollouts"):
            check(getattr(self, name) >= 1, f"ddpg.{name} must be >= 1, got {getattr(self, name)}")
        check(self.batch_size <= self.buffer_size,
              f"ddpg.batch_size must be in [1, ddpg.buffer_size={self.buffer_size}], got {self.batch_size}")
        for name in ("actor_lr", "critic_lr"):
            check_number(f"ddpg.{name}", getattr(self, name), 0.0, LR_LIMIT, low_open=True)
        for name in ("clip_obs", "clip_norm", "norm_eps"):
            check_number(f"ddpg.{name}", getattr(self, name), 1 / SCALE_LIMIT, SCALE_LIMIT)
        for name in ("polyak", "random_eps"):
            check_number(f"ddpg.{name}", getattr(self, name), 0.0, 1.0)
        for name in ("noise_eps", "action_l2"):
            check_number(f"ddpg.{name}", getattr(self, name), 0.0, SCALE_LIMIT)
        if self.gamma is not None:
            check(is_finite(self.gamma) and 0.0 < self.gamma <= 1.0 - 1.0 / HORIZON_LIMIT,
                  f"ddpg.gamma must be in (0, {1.0 - 1.0 / HORIZON_LIMIT:.6f}] (1/(1-gamma) <= {HORIZON_LIMIT:g}) "
                  f"or null, got {self.gamma}")


# The package's learners (hersd/engine/learners/), read from their cards (hersd/contract/learners/) without
# importing torch: name -> the settings class its class declares, and the names that have an update=fast. Any
# other learner (an entry point, learner._target_=<module>.<Class>) is imported to ask its class.
PAPER_LEARNER = "ddpg"  # the seed paper's learner: the default, and that of every run made before learners existed
PACKAGE_LEARNERS: dict[str, Optional[type]] = {name: card.settings for name, card in package_cards().items()}
FAST_UPDATE_LEARNERS = tuple(name for name, card in package_cards().items() if card.fast_update)


def no_fast_update(name: str) -> str:
    """The line refusing ``update=fast`` for learner ``name``, which has no hand-written update."""
    return f"update=fast: learner {name} has no fast update ({' and '.join(FAST_UPDATE_LEARNERS)} have one); " \
           "use update=autograd"


LEARNER_TARGET_KEY = "_target_"


def learner_key(name: str) -> str:
    """The config key of a learner's settings, ``learner.<key>.*``: its name, or for a class recorded by its
    import path, the class name in lower case (``my_pkg.TD3Late`` -> ``td3late``); also its folder's prefix."""
    return name.rpartition(".")[2].lower() if "." in name else name


def learner_settings_class(name: str) -> tuple[str, Optional[type]]:
    """(the name a run records, the settings dataclass its class declares) of a learner= name or class path."""
    if name in PACKAGE_LEARNERS:
        return name, PACKAGE_LEARNERS[name]
    cls = learner_class(name, known=tuple(PACKAGE_LEARNERS))  # imports the class's module (and torch)
    recorded = recorded_name(cls)
    check(cls.SETTINGS is None or learner_key(recorded) not in ("name", LEARNER_TARGET_KEY),
          f"learner {recorded}: its settings would be learner.{learner_key(recorded)}.*, which is learner's own "
          f"key; rename the class or give it NAME = \"<another name>\"")
    return recorded, cls.SETTINGS


def parent_keys(name: str) -> set[str]:
    """The settings keys (``learner.<key>``) of the learner classes the learner ``name``'s class extends: ``td3``
    for a subclass of TD3; none for the package's learners (whose parents have no settings)."""
    if name in PACKAGE_LEARNERS:
        return set()
    cls = learner_class(name, known=tuple(PACKAGE_LEARNERS))
    return {learner_key(recorded_name(base)) for base in cls.__mro__[1:] if getattr(base, "SETTINGS", None)}


@dataclass
class LearnerConfig:
    """The off-policy learner and its settings: one object, of the dataclass its class declares (``SETTINGS``),
    the one its ``build`` reads and the run's identity hashes. Every learner also shares ddpg.* (networks,
    optimiser, batch, gamma, polyak once per cycle, normalisation, target clipping) and every other part of a run."""

    name: str = PAPER_LEARNER  # ddpg (the paper's) | td3 | sac | an entry point's name | a class (learner._target_=)
    settings: Any = None  # learner.<name>.*: its class's SETTINGS; None: that class's defaults (or it has none)

    def __post_init__(self) -> None:
        self.name, settings_class = learner_settings_class(self.name)
        if settings_class is None:
            check(self.settings is None, f"learner {self.name} has no settings of its own")
        elif self.settings is None:
            self.settings = settings_class()
        check(self.settings is None or isinstance(self.settings, settings_class),
              f"learner {self.name}: its settings must be a {getattr(settings_class, '__name__', None)}")


def learner_from_config(node: Any) -> LearnerConfig:
    """A config's ``learner`` mapping (``name`` or ``_target_``, its settings under ``learner.<key>``, and other
    package learners' settings, checked and left out, as a sweep over learners carries them, but not those of a
    class it extends, which it does not read) -> its LearnerConfig; ConfigError (one line) otherwise."""
    if isinstance(node, LearnerConfig):
        return node
    sections = dict(node)
    target, name = sections.pop(LEARNER_TARGET_KEY, None), sections.pop("name", None)
    check(not (target and name), f"learner={name} and learner.{LEARNER_TARGET_KEY}={target}: give one of them")
    name, settings_class = learner_settings_class(target or name or PAPER_LEARNER)
    own_key = learner_key(name)
    own = sections.pop(own_key, None)
    parents = parent_keys(name) if sections else set()
    for key, section in sections.items():
        check(key not in parents, f"learner {name} reads learner.{own_key}.*, not learner.{key}.* (its parent's): "
              f"set learner.{own_key}.<setting>; in a sweep beside {key}, give {key}'s settings in a learner "
              f"config of your own (name: {key} and {key}: {{<setting>: <value>}}; docs/LEARNERS.md)")
        check(PACKAGE_LEARNERS.get(key) is not None, no_setting(name, settings_class, key))
        learner_settings(key, PACKAGE_LEARNERS[key], section)
    check(settings_class is not None or not own, f"learner {name} has no settings; drop learner.{learner_key(name)}")
    return LearnerConfig(name, learner_settings(own_key, settings_class, own or {}, name) if settings_class else None)


def no_setting(name: str, settings_class: Optional[type], key: str) -> str:
    """The line refusing ``learner.<key>.*``, which is no setting of the learner ``name``."""
    if settings_class is not None:
        return f"learner.{key} is not a setting of learner {name}; its settings: learner.{learner_key(name)}.*"
    return (f"learner {name} has no settings, so learner.{key}.* sets nothing; to sweep a learner of your own with "
            f"its settings beside {name}, put them in a learner config of your own (<folder>/learner/<choice>.yaml "
            f"holding _target_: <module>.<Class> and {key}: {{<setting>: <value>}}; "
            f"hydra.searchpath=[file:///<folder>] learner={name if '.' not in name else '<its choice>'},<choice>; "
            "docs/LEARNERS.md \"Add a learner\")")


def learner_settings(key: str, settings_class: type, section: Any, name: Optional[str] = None) -> Any:
    """``settings_class(**section)``; ConfigError (one line) for a key it lacks, a section that is no mapping, or
    an error other than ConfigError its ``__post_init__`` raises (naming the learner ``name``, else ``key``)."""
    fields = [item.name for item in dataclasses.fields(settings_class)]
    check(isinstance(section, dict), f"learner.{key} must hold settings ({', '.join(fields)}), got {section!r}")
    unknown = sorted(set(section) - set(fields))
    check(not unknown, f"learner.{key}.{unknown[0] if unknown else ''} is not a setting; "
          f"its settings: {', '.join(fields) or 'none'}")
    types = _field_types(settings_class)
    values = {field_name: _typed(f"learner.{key}.{field_name}", types.get(field_name), value)
              for field_name, value in section.items()}
    try:
        with settings_of(key):  # the class's own range checks name this key (setting_name)
            return settings_class(**values)
    except ConfigError:
        raise
    except Exception as err:  # noqa: BLE001 - a user's __post_init__: one line naming it, before any work
        given = " ".join(f"learner.{key}.{field_name}={value}" for field_name, value in section.items())
        raise ConfigError(f"learner {name or key}: its settings refused {given or 'their defaults'}: {raised(err)}") \
            from None


def _field_types(settings_class: type) -> dict[str, Any]:
    """Each field's declared type, resolved field by field: one whose annotation does not resolve here (a name
    imported for type checkers only) is left to the class's own checks, the others keep theirs."""
    try:
        return typing.get_type_hints(settings_class)
    except (NameError, TypeError):
        pass
    types: dict[str, Any] = {}
    for cls in reversed(settings_class.__mro__):
        namespace = vars(sys.modules[cls.__module__]) if cls.__module__ in sys.modules else {}
        for field_name, annotation in vars(cls).get("__annotations__", {}).items():
            try:
                types[field_name] = eval(annotation, namespace, dict(vars(cls))) if isinstance(annotation, str) \
                    else annotation  # what typing.get_type_hints does for each
            except Exception:  # noqa: BLE001 - this field's annotation only
                types.pop(field_name, None)
    return types


def _typed(name: str, declared: Any, value: Any) -> Any:
    """A learner setting as its declared type (int, float, bool, or Optional of one): 2.0 is 2 for an int, 1 is 1.0
    for a float, so one setting is one run folder; ConfigError (one line) for a value of another type."""
    args = typing.get_args(declared)
    if value is None and type(None) in args:
        return None
    members = [arg for arg in args if arg is not type(None)]
    is_optional = typing.get_origin(declared) is typing.Union and len(members) == 1
    kind = members[0] if is_optional else declared  # List[int], Union[int, str]: another type
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is float and number and (isinstance(value, float) or abs(value) <= sys.float_info.max):
        return float(value)
    if kind is int and (isinstance(value, int) and number or isinstance(value, float) and value.is_integer()):
        return int(value)
    if kind is bool and isinstance(value, bool):
        return value
    if kind not in (int, float, bool):  # another type: the class's own checks
        return value
    wanted = {int: "a whole number", float: "a number", bool: "true or false"}[kind]
    raise ConfigError(f"{name} must be {wanted}, got {value!r}")


def learner_record(learner: LearnerConfig) -> dict[str, Any]:
    """The learner as a log's config holds it and the run's identity hashes it: ``name`` and its settings
    under that name (none for a learner without settings)."""
    own = {} if learner.settings is None else {learner.name: dataclasses.asdict(learner.settings)}
    return {"name": learner.name, **own}


def learner_node(record: dict[str, Any]) -> dict[str, Any]:
    """A log's learner record (:func:`learner_record`) -> the ``learner`` config node it was composed from: a
    class recorded by its path keeps its settings under :func:`learner_key` (``learner.td3late.*``)."""
    node, name = dict(record), record.get("name", "")
    if name in node and learner_key(name) != name:
        node[learner_key(name)] = node.pop(name)
    return node


@dataclass
class BiasConfig:
    # The critic against the truth (hersd/engine/bias.py, docs/ARCHITECTURE.md "Bias evaluation"): after the
    # chosen epochs, Q(s_t, pi(s_t, g), g) against the discounted return the deterministic policy obtains
    # from s_t for g, on an env and random stream of its own: not part of the run's identity or metrics.
    epochs: List[int] = field(default_factory=lambda: [1, 2, 5, 10, 20, 30, 50, 75, 100, 150, 200])  # [] never
    episodes: int = 4  # real-goal test episodes per evaluation; each of their states s_t (t < T) is valued
    hindsight_pairs: int = 16  # (s_t, future achieved goal) pairs per evaluation, each valued by a rollout of its own
    # More such pairs, drawn among those whose goal lies beyond the success radius of ag_t (the object moved)
    moved_pairs: int = 16
    # Rewards summed into each return: the critic bootstraps through the time limit T, so returns run past
    # it (T + 250 for Fetch's T = 50); the tail left out weighs gamma^return_steps (0.98^300 = 0.0023).
    return_steps: int = 300

    def __post_init__(self) -> None:
        check(all(isinstance(k, int) and k >= 1 for k in self.epochs),
              f"bias.epochs must be a list of epochs >= 1 ([] for never), got {list(self.epochs)}")
        check(self.episodes >= 1, f"bias.episodes must be >= 1, got {self.episodes}")
        check(self.hindsight_pairs >= 0, f"bias.hindsight_pairs must be >= 0, got {self.hindsight_pairs}")
        check(self.moved_pairs >= 0, f"bias.moved_pairs must be >= 0, got {self.moved_pairs}")
        check(self.return_steps >= 1, f"bias.return_steps must be >= 1, got {self.return_steps}")


@dataclass
class TrainConfig:
    task: TaskConfig = field(default_factory=TaskConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    # The relabel-rate schedule: kind=<name> (or _target_=<module>.<Class>) and that kind's settings
    # (hersd-train --help lists them); a hersd.contract.schedules.Schedule once the config is built. {}: HER's constant.
    schedule: Any = field(default_factory=dict)
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    # The learner: learner=<name> or learner._target_=<module>.<Class>, its settings learner.<name>.* (docs/LEARNERS.md)
    learner: Any = field(default_factory=dict)
    bias: BiasConfig = field(default_factory=BiasConfig)
    seed: int = 0  # one seed, one result (every RNG is derived from it)
    epochs: int = 200  # K in eq. 9 (the paper trains 200 epochs)
    results_dir: str = "results"  # run directories are created below this folder
    run_dir: Optional[str] = None  # null: derived from the config (see hersd.contract.runstore.run_dir)
    checkpoint_every: int = 1  # save an exact-resume checkpoint every N epochs (0: never)
    keep_checkpoint: bool = False  # keep the checkpoint after the run completes (it can be large)
    quiet: bool = False  # no per-epoch progress lines (sweeps)
    # Animate the deterministic policy (2 test episodes, <run dir>/policy/epoch_<k>.gif, hersd/engine/render.py)
    # every N epochs and at the last one (0: never); a few seconds each, not part of the run's identity.
    render_every: int = 50
    # Intra-op threads of the run's updates: auto = this machine's cores / runs sharing it (a lone
    # run: all cores; sweeps and searches divide the cores among their runs); or a number in [1, 1024].
    # Thread counts can change floating-point sums: logged, not part of the run's identity.
    threads: str = "auto"
    device: str = "auto"  # where networks and updates run: auto (cuda if available, else cpu) | cpu | cuda[:N]
    # The updates' matrix products: fp32 | bf16 (hidden layers in bfloat16, all else float32; docs/LEARNERS.md,
    # "Precision"; a CPU without bf16 instructions refuses it). Part of the run's identity (fp32 adds nothing).
    precision: str = "fp32"
    # The updates' passes: autograd | fast (forward and backward written by hand, ddpg and td3, at either precision:
    # with bf16, bf16 copies of float32 master weights; other sums' order than autograd's, so not bit-identical to
    # it; docs/LEARNERS.md, "The fast update"). Part of the run's identity (autograd adds nothing).
    update: str = "autograd"
    # Treat denormal floats (|x| < 1.2e-38) as zero in the run's torch work (updates, acting, bias evaluation,
    # animations; every intra-op thread; the physics stays IEEE), as the reference's TensorFlow does for its
    # kernels (hersd/engine/denormals.py). Adam's moments of units whose gradient died decay through the denormal
    # range for thousands of steps, and some x86 CPUs (Intel Xeon here, not AMD EPYC) compute on them many
    # times slower. false retraces runs made without it. Changes floating-point results as a CPU type does:
    # logged, not part of the run's identity.
    flush_denormal: bool = True
    # Also write TensorBoard event files, <run dir>/tensorboard/, one step per epoch as it ends (every /epoch
    # number, the settings as text and hparams; hersd/contract/tensorboard_events.py). Needs the tensorboard
    # package (pip install -e ".[tensorboard]"); not part of the run's identity.
    tensorboard: bool = False

    def __post_init__(self) -> None:
        check(self.epochs >= 1, f"epochs must be >= 1, got {self.epochs}")
        if self.tensorboard:
            require_tensorboard()
        check(self.seed >= 0, f"seed must be >= 0, got {self.seed}")
        check(self.checkpoint_every >= 0, f"checkpoint_every must be >= 0, got {self.checkpoint_every}")
        check(self.render_every >= 0, f"render_every must be >= 0 (0: never), got {self.render_every}")
        check(self.threads == "auto" or (self.threads.isdigit() and 1 <= int(self.threads) <= MAX_THREADS),
              f"threads must be auto or a whole number in [1, {MAX_THREADS}], got {self.threads!r}")
        check(self.device.split(":")[0] in DEVICES and (self.device.count(":") == 0 or (
            self.device.startswith("cuda:") and self.device[5:].isdigit())),
            f"device must be auto, cpu, cuda or cuda:N, got {self.device!r}")
        check(self.precision in PRECISIONS, f"precision must be fp32 or bf16, got {self.precision!r}")
        self.task.resolve()
        self.learner = learner_from_config(self.learner)
        check(self.update in UPDATES, f"update must be autograd or fast, got {self.update!r}")
        check(self.update == "autograd" or self.learner.name in FAST_UPDATE_LEARNERS,
              no_fast_update(self.learner.name))
        if isinstance(self.schedule, Schedule):
            self.schedule = settle(self.schedule, self.epochs)
        else:
            self.schedule = schedule_from_config(self.schedule, self.epochs)


def config_record(cfg: TrainConfig) -> dict[str, Any]:
    """The config as a nested dict, as a log's ``/run/meta`` holds it: the schedule as its record
    (:meth:`hersd.contract.schedules.Schedule.record`)."""
    return {**asdict(cfg), "schedule": cfg.schedule.record(), "learner": learner_record(cfg.learner)}


def added_keys(node: DictConfig, prefix: str = "") -> list[str]:
    """The dotted keys a ``+key=value`` override put in a node of the schema that has no such field (OmegaConf
    would drop them unseen); the open nodes, ``schedule`` and ``learner``, check their keys themselves."""
    schema = OmegaConf.get_type(node)
    if not OmegaConf.is_struct(node) or not dataclasses.is_dataclass(schema):
        return []
    names = {item.name for item in dataclasses.fields(schema)}
    added = []
    for key in node:
        child = node._get_node(key)
        if key not in names:
            added.append(f"{prefix}{key}")
        elif isinstance(child, DictConfig):
            added += added_keys(child, f"{prefix}{key}.")
    return added


def to_train_config(cfg: DictConfig) -> TrainConfig:
    """Composed Hydra config -> validated :class:`TrainConfig` (raises :class:`ConfigError`)."""
    from omegaconf.errors import OmegaConfBaseException

    if added := added_keys(cfg):
        raise ConfigError(f"{added[0]} is not a config field (the + added it, and no part of a run reads it); "
                          "see --help")
    try:
        obj = OmegaConf.to_object(cfg)
    except OmegaConfBaseException as err:
        # OmegaConf wraps exceptions raised in __post_init__; surface ours unchanged.
        cause = err.__cause__ or err.__context__
        while cause is not None and not isinstance(cause, ConfigError):
            cause = cause.__cause__ or cause.__context__
        if cause is not None:
            raise cause from None
        raise ConfigError(str(err).splitlines()[0]) from None
    if not isinstance(obj, TrainConfig):
        raise ConfigError("the composed config is not a training config (conf/train.yaml must list train_schema)")
    return obj
