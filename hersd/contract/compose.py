"""Hydra composition for the commands that compose configs (hersd-train, -sweep, -search).

The YAML configs ship inside the package as ``hersd.conf`` (the repository's top-level
``conf/``, mapped into the wheel by pyproject.toml), so every command finds them through the
search path :data:`CONFIG_PATH` from any folder, editable install or not. Light: no torch.
"""

from __future__ import annotations

from typing import Any

from omegaconf import DictConfig, OmegaConf

from hersd.contract.config import PACKAGE_LEARNERS, TrainConfig, to_train_config
from hersd.contract.errors import ConfigError
from hersd.contract.learner_registry import TARGET_KEY, entry_point_names, typed_instead
from hersd.contract.schedules import schedule_from_record

CONFIG_MODULE = "hersd.conf"
CONFIG_PATH = f"pkg://{CONFIG_MODULE}"


def mean_rate(schedule: dict[str, Any], epochs: int) -> float:
    """``${hersd_mean_rate:{kind: linear, beta1: 0.25},${epochs}}`` in a YAML file: that schedule's exact mean
    rate over K = ``epochs`` (eq. 10; :meth:`hersd.contract.schedules.Schedule.exact_mean_rate`), e.g. 0.874375 at K = 200:
    a constant control asks the schedule it matches rather than typing its number."""
    rate = schedule_from_record(dict(schedule)).exact_mean_rate(int(epochs))
    if rate is None:
        raise ConfigError(f"hersd_mean_rate: {schedule['kind']} adapts to the run, so it has no mean rate before it")
    return rate


OmegaConf.register_new_resolver("hersd_mean_rate", mean_rate, replace=True)  # on import, as every command composes


def register_schema(name: str, node: Any, group: str | None = None) -> None:
    """Put a dataclass schema in Hydra's ConfigStore, where YAML defaults lists can name it."""
    from hydra.core.config_store import ConfigStore

    ConfigStore.instance().store(name=name, node=node, group=group)


def open_schedule(schema: type) -> DictConfig:
    """A training schema as a config whose ``schedule`` and ``learner`` nodes take any key: each schedule kind and
    each learner has settings of its own, which its class checks when the config is built (:mod:`hersd.contract.schedules`,
    :func:`hersd.contract.config.learner_from_config`)."""
    from omegaconf import OmegaConf

    node = OmegaConf.structured(schema)
    OmegaConf.set_struct(node.schedule, False)
    OmegaConf.set_struct(node.learner, False)
    return node


def register_train_schema() -> None:
    """``train_schema``, which conf/train.yaml lists first; and ``learner=<name>`` for each learner without a
    conf/learner/<name>.yaml: the package's (their cards) and other packages' (entry points of ``hersd.learners``)."""
    register_schema("train_schema", open_schedule(TrainConfig))
    files = set(group_options("learner"))
    for name in learner_names():
        if name not in files:
            register_schema(name, {"name": name}, group="learner")


def learner_names() -> list[str]:
    """The learners selected by name alone: the package's (:data:`PACKAGE_LEARNERS`) and other packages'."""
    return [*PACKAGE_LEARNERS, *entry_point_names()]


def compose(config_name: str | None, overrides: list[str], job_name: str, with_hydra: bool = False) -> DictConfig:
    """The named config (or none: only the overrides' groups) composed with command-line overrides;
    ``with_hydra`` keeps the ``hydra`` node (launcher, sweeper)."""
    from hydra import compose as hydra_compose, initialize_config_module

    if said := null_group(overrides):
        raise ConfigError(said)
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3", job_name=job_name):
        return hydra_compose(config_name=config_name, overrides=overrides, return_hydra_config=with_hydra)


def compose_train(overrides: list[str]) -> TrainConfig:
    """``conf/train.yaml`` with Hydra command-line overrides -> validated TrainConfig."""
    register_train_schema()
    return to_train_config(compose("train", overrides, job_name="hersd-train"))


def group_options(group: str) -> list[str]:
    """The config names of a group, sorted (e.g. ``task`` -> ``[custom, hand_block, hand_reach, pick_and_place, push,
    reach, slide]``)."""
    from importlib.resources import files

    folder = files(CONFIG_MODULE).joinpath(*group.split("/"))
    return sorted(entry.name.removesuffix(".yaml") for entry in folder.iterdir() if entry.name.endswith(".yaml")) \
        if folder.is_dir() else []


def group_choices(group: str) -> list[str]:
    """A group's choices on the command line: its configs, and for ``learner`` every learner selected by name."""
    return sorted({*group_options(group), *(learner_names() if group == "learner" else ())})


def null_group(overrides: list[str]) -> str | None:
    """The line refusing an override that sets a config group to null (``task=null``; Hydra's ValueError names
    neither the group nor its choices), or None."""
    for override in overrides:
        key, _, value = override.partition("=")
        group = key.lstrip("+")
        if value.strip().lower() == "null" and group_options(group):
            return f"{group}=null is not a known {group}; choose one of: {', '.join(group_choices(group))}"
    return None


def quoted_override(override: str) -> str | None:
    """An override Hydra's grammar cannot parse (``results_dir=/data/é``, ``search.storage=sqlite:///x.db?mode=ro``)
    with its value quoted as typed in a shell (``'results_dir="/data/é"'``), if Hydra parses that to the same key
    and value; else None (the key is the trouble, or the value holds both kinds of quotes)."""
    import shlex

    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    key, equals, value = override.partition("=")
    quote = '"' if '"' not in value else "'"
    if not equals or not value or quote in value:
        return None
    try:
        parsed = OverridesParser.create().parse_override(f"{key}={quote}{value}{quote}")
    except HydraException:
        return None
    return shlex.quote(f"{key}={quote}{value}{quote}") if parsed.value() == value else None


def explain_config_error(err: Exception, what: str = "config field", see: str = "hersd-train --help") -> str:
    """Hydra/OmegaConf composition errors -> one line naming the field and the choices."""
    from hydra.errors import MissingConfigException, OverrideParseException
    from omegaconf.errors import ConfigAttributeError, ConfigKeyError, ValidationError

    if isinstance(err, ConfigError):
        return str(err)
    if isinstance(err, OverrideParseException) and (quoted := quoted_override(err.override)):
        return f"{err.override}: Hydra's override grammar cannot read this value unquoted; quote it: {quoted}"
    if isinstance(err, MissingConfigException) and err.missing_cfg_file:
        group, _, value = err.missing_cfg_file.rpartition("/")  # a nested group too: hydra/launcher=<value>
        if not group:
            group, value = value, ""
        if group == "learner" and value and (instead := typed_instead(value)):
            return f"learner={value} names a class, which no config of the learner group holds; type {instead}"
        if group == "schedule" and "." in value:
            return (f"schedule={value} names a class, which no config of the schedule group holds; type "
                    f"schedule._target_={value} (a sweep over several: schedule.kind=<kind or class>,...)")
        choices = sorted(err.options) if err.options is not None else group_options(group)
        own_class = {"learner": TARGET_KEY, "schedule": "schedule._target_"}.get(group)
        return (f"{group}={value} is not a known {group}" if value else f"{err.missing_cfg_file} is unknown") + \
            (f"; choose one of: {', '.join(choices)}" if choices else "") + \
            (f", or a class of your own: {own_class}=<module>.<Class>" if own_class else "")
    cause = err.__cause__ if err.__cause__ is not None else err
    key = getattr(cause, "full_key", None)
    if isinstance(cause, (ConfigAttributeError, ConfigKeyError)) and key:
        return f"{key} is not a {what}; see {see}"
    if isinstance(cause, ValidationError) and key:
        return f"{key}: {str(cause).splitlines()[0]}"
    return " ".join(str(err).split())
