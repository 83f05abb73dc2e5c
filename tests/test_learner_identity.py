"""A run's identity covers exactly the settings its learner trains with: for every learner, the package's and a
subclass of TD3 that inherits ``TD3.build`` under a name of its own (issue 51's pitfall), changing any learner
setting, its own or another learner's, changes the run's hash exactly when it changes what the learner trains (the
subclass refuses its parent's key, learner.td3.*, which it does not read)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from helpers import GOAL, OBS, batch, tiny_spec

from hersd.contract.compose import compose_train
from hersd.contract.config import PACKAGE_LEARNERS
from hersd.contract.learners.td3 import TD3Config
from hersd.contract.errors import ConfigError
from hersd.engine.learners import LEARNERS, learner_class
from hersd.engine.learners.td3 import TD3
from hersd.contract.runstore import config_hash

TINY_NETWORKS = ["task=reach", "ddpg.hidden_layers=2", "ddpg.hidden_units=16"]
# learner.<key>.* of the package's learners with settings (their cards')
SECTIONS = {name: settings for name, settings in PACKAGE_LEARNERS.items() if settings}


@pytest.fixture
def td3late():
    """TD3 under the name ``td3late``, inheriting every method (``build`` too); unregistered afterwards."""
    cls = type("TD3Late", (TD3,), {"NAME": "td3late", "__module__": __name__})
    yield cls
    LEARNERS.pop("td3late", None)


def trained(overrides: list[str]) -> tuple[str, list[torch.Tensor]]:
    """(the run's hash, every network's parameters after three updates on fixed batches) of a tiny learner."""
    cfg = compose_train([*TINY_NETWORKS, *overrides])
    torch.manual_seed(0)
    agent = learner_class(cfg.learner.name).build(cfg, tiny_spec(), 0.98, (-50.0, 0.0), torch.device("cpu"))
    rng = np.random.default_rng(0)
    agent.update_normalizers(rng.normal(size=(100, OBS)), rng.normal(size=(100, GOAL)))
    for seed in (1, 2, 3):
        agent.update(batch(seed=seed))
    names = [*agent.networks(tiny_spec()), *(f"{name}_target" for name in agent.TARGETS)]
    return config_hash(cfg), [p.detach().clone() for name in names for p in getattr(agent, name).parameters()]


def changed(value):
    """Another valid value of a learner setting: whole numbers + 3, numbers halved, null -> -1.0."""
    if value is None:
        return -1.0
    return value + 3 if isinstance(value, int) else value / 2


def setting_changes(sections: dict[str, type]) -> list[str]:
    """One override per setting of each section: ``learner.<key>.<setting>=<another value>``."""
    return [f"learner.{key}.{item.name}={changed(getattr(settings(), item.name))}"
            for key, settings in sections.items() for item in dataclasses.fields(settings)]


@pytest.mark.parametrize("name", [*PACKAGE_LEARNERS, "td3late"])
def test_a_learner_setting_changes_the_runs_hash_exactly_when_it_changes_what_the_learner_trains(name, td3late):
    sections = {**SECTIONS, **({"td3late": TD3Config} if name == "td3late" else {})}
    selected = [f"learner.name={name}"]
    base_hash, base_parameters = trained(selected)
    for override in setting_changes(sections):
        if name == "td3late" and override.startswith("learner.td3."):  # its parent's key: refused, not ignored
            with pytest.raises(ConfigError, match=r"^learner td3late reads learner\.td3late\.\*, not learner\.td3\.\*"):
                trained([*selected, override])
            continue
        new_hash, parameters = trained([*selected, override])
        same_training = all(torch.equal(a, b) for a, b in zip(base_parameters, parameters))
        what = "what it trains but not the run's hash" if new_hash == base_hash else "the run's hash but not what it trains"
        assert (new_hash == base_hash) == same_training, f"learner {name}: {override} changes {what}"


def test_the_configs_table_of_the_package_learners_settings_is_what_their_classes_declare():
    assert {name: learner_class(name).SETTINGS for name in PACKAGE_LEARNERS} == PACKAGE_LEARNERS
