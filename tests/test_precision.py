"""precision=bf16 (hersd/engine/learners/base.py, docs/LEARNERS.md "Precision"): the hidden layers of an update's
passes run in bfloat16 and change its numbers, fp32 runs float32 throughout; a CPU without bf16
instructions refuses it; bf16 is another run's identity, fp32 every earlier run's."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from helpers import GOAL, OBS, batch, tiny_spec
from torch import nn

import hersd.engine.resources as resources
from hersd.contract.compose import compose_train
from hersd.contract.config import DDPGConfig, LearnerConfig, TrainConfig, config_record
from hersd.contract.errors import ConfigError
from hersd.engine.envs.make import env_spec, make_env
from hersd.engine.learners import learner_class
from hersd.engine.run_state import discounting
from hersd.contract.runlog import read_run
from hersd.contract.runstore import config_hash, run_identity
from hersd.engine.train import train

LEARNERS = ("ddpg", "td3", "sac")


@pytest.fixture
def bf16_cpu(monkeypatch):
    """Whatever this CPU lists, let bf16 through (torch emulates it where it has no instructions)."""
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: True)


def learner(name: str, precision: str):
    """A tiny learner ``name`` at ``precision`` from torch seed 0, its normalisers fed 100 random rows."""
    cfg = TrainConfig(ddpg=DDPGConfig(hidden_layers=2, hidden_units=16), learner=LearnerConfig(name=name),
                      precision=precision)
    torch.manual_seed(0)
    agent = learner_class(name).build(cfg, tiny_spec(), 0.98, (-50.0, 0.0), torch.device("cpu"))
    rng = np.random.default_rng(0)
    agent.update_normalizers(rng.normal(size=(100, OBS)), rng.normal(size=(100, GOAL)))
    return agent


def run_sizes(cfg: TrainConfig) -> tuple:
    """(spec, gamma, q_range) of ``cfg``'s task."""
    env = make_env(cfg.task)
    spec = env_spec(env)
    env.close()
    return (spec, *discounting(cfg, spec))


def linear_output_dtypes(agent) -> dict[str, set[torch.dtype]]:
    """One update of ``agent``: the dtypes its hidden and output Linear layers gave ("hidden", "output")."""
    seen: dict[str, set[torch.dtype]] = {"hidden": set(), "output": set()}
    hooks = []
    for module in vars(agent).values():
        if isinstance(module, nn.Sequential):
            for index, layer in enumerate(module):
                if isinstance(layer, nn.Linear):
                    kind = "output" if index == len(module) - 1 else "hidden"
                    hooks.append(layer.register_forward_hook(lambda _m, _i, out, kind=kind: seen[kind].add(out.dtype)))
    agent.update(batch())
    for hook in hooks:
        hook.remove()
    return seen


@pytest.mark.parametrize("name", LEARNERS)
def test_bf16_runs_the_hidden_layers_in_bfloat16_and_fp32_runs_float32_throughout(name, bf16_cpu):
    assert linear_output_dtypes(learner(name, "fp32")) == {"hidden": {torch.float32}, "output": {torch.float32}}
    assert linear_output_dtypes(learner(name, "bf16")) == {"hidden": {torch.bfloat16}, "output": {torch.float32}}


@pytest.mark.parametrize("name", LEARNERS)
def test_bf16_starts_from_the_same_networks_and_changes_the_updates_numbers_a_little(name, bf16_cpu):
    fp32, bf16 = learner(name, "fp32"), learner(name, "bf16")
    assert all(torch.equal(p, q) for p, q in zip(fp32.critic.parameters(), bf16.critic.parameters()))
    torch.manual_seed(1)
    fp32_stats = fp32.update(batch())
    torch.manual_seed(1)
    bf16_stats = bf16.update(batch())
    assert bf16_stats.critic_loss != fp32_stats.critic_loss
    assert bf16_stats.critic_loss == pytest.approx(fp32_stats.critic_loss, rel=0.05)
    moved = [(p - q).abs().max().item() for p, q in zip(fp32.critic.parameters(), bf16.critic.parameters())]
    assert 0 < max(moved) < 1e-2  # Adam moves each weight by about lr = 1e-3 per step


def test_fp32_checkpoints_load_into_a_bf16_learner(bf16_cpu):
    fp32 = learner("ddpg", "fp32")
    bf16 = learner("ddpg", "bf16")
    fp32.update(batch())
    bf16.load_state_dict(copy.deepcopy(fp32.state_dict()))
    assert all(torch.equal(p, q) for p, q in zip(fp32.actor.parameters(), bf16.actor.parameters()))


def test_a_cpu_without_bf16_instructions_refuses_bf16_in_one_line(monkeypatch):
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: False)
    with pytest.raises(ConfigError, match="no bf16 instructions.*use precision=fp32"):
        learner("ddpg", "bf16")
    learner("ddpg", "fp32")


def test_an_unknown_precision_is_refused():
    with pytest.raises(ConfigError, match="precision must be fp32 or bf16"):
        compose_train(["task=push", "precision=fp16"])


def test_bf16_is_another_runs_identity_and_fp32_that_of_runs_made_before_the_setting():
    fp32 = compose_train(["task=push"])
    assert config_hash(compose_train(["task=push", "precision=bf16"])) != config_hash(fp32)
    before = config_record(fp32)
    del before["precision"]
    assert run_identity(before) == run_identity(fp32) and "precision" not in run_identity(fp32)


@pytest.mark.slow
@pytest.mark.skipif(not resources.cpu_has_bf16(), reason="this CPU has no bf16 instructions: hersd refuses bf16 here")
def test_bf16_ddpg_learns_fetch_reach(tmp_path):
    """Paper settings on FetchReach, seed 0, precision=bf16: test success >= 0.9 within 5 epochs, as fp32
    (docs/LEARNERS.md, "Precision", gives both runs epoch by epoch)."""
    log = read_run(train(compose_train(["task=reach", "precision=bf16", "epochs=5", "seed=0", "quiet=true",
                                        "threads=1", "bias.epochs=[]", f"results_dir={tmp_path}"])))
    assert log.epochs["test_success"].max() >= 0.9, log.epochs["test_success"].tolist()


def test_a_bf16_runs_policy_renders_on_a_cpu_without_bf16_instructions(monkeypatch):
    """hersd-render builds the run's learner only to act, which is float32 at either precision."""
    from hersd.engine.render_cli import policy_from_checkpoint

    cfg = compose_train(["task=reach", "precision=bf16"])
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: True)
    trained = learner_class("ddpg").build(cfg, *run_sizes(cfg), torch.device("cpu"))
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: False)
    agent = policy_from_checkpoint(cfg, {"agent": trained.state_dict()})
    assert all(torch.equal(p, q) for p, q in zip(agent.actor.parameters(), trained.actor.parameters()))
