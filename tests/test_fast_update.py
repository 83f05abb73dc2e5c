"""update=fast (hersd/engine/learners/fast.py, docs/LEARNERS.md "The fast update"): DDPG's and TD3's update with the
networks' passes written by hand. Its gradients are autograd's to 1e-5 relative and its steps follow the default
update's within rounding; it is another run's identity, the default (autograd) every earlier run's; SAC, bf16 and
unknown values are refused in one line."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest
import torch
from helpers import TINY, metrics

import hersd.engine.learners.fast as fast_module
import hersd.engine.resources as resources
from hersd.contract.compose import compose_train
from hersd.contract.config import DDPGConfig, LearnerConfig, TrainConfig, config_record
from hersd.contract.errors import ConfigError
from hersd.engine.envs.make import EnvSpec
from hersd.engine.learners import learner_class
from hersd.engine.learners.fast import FastDDPG, FastTD3, HandMLPBF16, fast_learner_class
from hersd.engine.replay.buffer import TransitionBatch
from hersd.contract.runlog import read_run
from hersd.engine.run_state import make_agent
from hersd.contract.runstore import config_hash, run_identity
from hersd.engine.train import train

LEARNERS = ("ddpg", "td3")
# (obs, goal, action, hidden layers, units, batch): FetchPush's sizes at the paper's settings, and a tiny net
SIZES = {"push": (25, 3, 4, 3, 256, 256), "tiny": (5, 3, 2, 2, 16, 16)}
# update=fast precision=bf16: each parameter's gradient within this fraction of its largest element of the float32
# autograd update's (docs/LEARNERS.md, "Precision"; bf16 autocast's error, measured up to 0.11 on first layers)
BF16_GRADIENT_BOUND = 0.15


@pytest.fixture
def bf16_cpu(monkeypatch):
    """Whatever this CPU lists, let bf16 through (torch emulates it where it has no instructions)."""
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: True)


def learner_pair(name: str, size: str, precisions: tuple[str, str] = ("fp32", "fp32")):
    """The autograd learner ``name`` and its fast twin at these precisions, both from torch seed 0 (the same
    networks), their normalisers fed the same 1000 random rows."""
    obs, goal, action, layers, units, _ = SIZES[size]
    spec = EnvSpec(obs_dim=obs, goal_dim=goal, action_dim=action, horizon=50, max_action=1.0,
                   distance_threshold=0.05, reward_range=(-1.0, 0.0))
    pair = []
    for cls, precision in zip((learner_class(name), fast_learner_class(learner_class(name))), precisions):
        cfg = TrainConfig(ddpg=DDPGConfig(hidden_layers=layers, hidden_units=units), learner=LearnerConfig(name=name),
                          precision=precision)
        torch.manual_seed(0)
        agent = cls.build(cfg, spec, 0.98, (-50.0, 0.0), torch.device("cpu"))
        rng = np.random.default_rng(0)
        agent.update_normalizers(rng.normal(size=(1000, obs)), rng.normal(size=(1000, goal)))
        pair.append(agent)
    return pair


def random_batch(size: str, seed: int) -> TransitionBatch:
    """A batch of ``size``'s shape: random states, goals and actions, rewards -1 or 0, 80 % relabelled."""
    obs, goal, action, _, _, rows = SIZES[size]
    rng = np.random.default_rng(seed)
    f32 = np.float32
    return TransitionBatch(obs=rng.normal(size=(rows, obs)).astype(f32), next_obs=rng.normal(size=(rows, obs)).astype(f32),
                           goal=rng.normal(size=(rows, goal)).astype(f32),
                           action=rng.uniform(-1, 1, size=(rows, action)).astype(f32),
                           reward=-rng.integers(0, 2, rows).astype(f32), relabelled=rng.random(rows) < 0.8,
                           real_success=np.zeros(rows, bool), episode=np.zeros(rows, int), t=np.zeros(rows, int))


def autograd_gradients(agent, data: TransitionBatch) -> tuple[float, float]:
    """The autograd update's losses and, in each parameter's ``.grad``, its gradient (``DDPG.update`` less its step)."""
    with agent.matmul_context():  # bf16: autocast (the forward passes only, as DDPG.update runs them)
        inputs = agent._inputs(data.obs, data.goal)
        action = agent.tensor(data.action) / agent.max_action
        target = agent.target_q(agent._inputs(data.next_obs, data.goal), agent.tensor(data.reward).unsqueeze(1))
        critic_loss, _ = agent.critic_loss(torch.cat([inputs, action], dim=1), target)
        actor_loss = agent.actor_loss(inputs)
    agent.optimizer.zero_grad(set_to_none=True)
    (critic_loss + actor_loss).backward()
    return critic_loss.item(), actor_loss.item()


def parameters(agent) -> dict[str, torch.Tensor]:
    """Every online network's parameters by name (``critic.0.weight``, ...)."""
    return {f"{net}.{name}": p for net in ("actor", *agent.CRITICS) for name, p in getattr(agent, net).named_parameters()}


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", LEARNERS)
def test_its_gradients_are_autogradss_to_1e_5_relative(name, size, monkeypatch):
    """Same networks and batch: each parameter's gradient of the critic loss (critics) and of the actor loss
    (actor) differs from autograd's by at most 1e-5 of that gradient's largest element; the losses too."""
    reference, fast = learner_pair(name, size)
    data = random_batch(size, 1)
    torch.manual_seed(5)  # TD3's target noise: both draw it alike
    critic_loss, actor_loss = autograd_gradients(reference, data)
    monkeypatch.setattr(fast.optimizer, "step", lambda: None)
    monkeypatch.setattr(fast, "_direct_adam", False)  # the step is Adam.step, here none: the gradients stay
    torch.manual_seed(5)
    stats = fast.update(data)
    assert stats.critic_loss == pytest.approx(critic_loss, rel=1e-5)
    assert stats.actor_loss == pytest.approx(actor_loss, rel=1e-5)
    fast_parameters = parameters(fast)
    for key, p in parameters(reference).items():
        error = (fast_parameters[key].grad - p.grad).abs().max().item()
        assert error <= 1e-5 * p.grad.abs().max().item(), (key, error)


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", LEARNERS)
def test_its_updates_follow_the_autograd_updates_within_rounding(name, size):
    """Three full updates (TD3: the actor steps on the first and third): every parameter within 5e-5 of the
    default update's, 5 % of one Adam step (lr = 1e-3), and the same stats within rounding. Adam divides each
    gradient element by its own running scale, so a rounding difference of 1e-6 of a layer's largest gradient
    (oneDNN's products sum in another order than MKL's) moves a small element's step by up to a few percent
    (measured 1.2e-5 at FetchPush's sizes); a wrong update moves weights by whole steps."""
    reference, fast = learner_pair(name, size)
    for seed in range(3):
        data = random_batch(size, seed)
        torch.manual_seed(seed)
        expected = reference.update(data)
        torch.manual_seed(seed)
        stats = fast.update(data)
        numbers = [(got, want) for got, want in zip(stats, expected) if want is not None]  # no entropy: not SAC
        assert np.allclose(*zip(*numbers), rtol=1e-5, atol=1e-6), (stats, expected)
        fast_parameters = parameters(fast)
        for key, p in parameters(reference).items():
            assert torch.allclose(fast_parameters[key], p, rtol=0, atol=5e-5), key
    assert fast.optimizer.state_dict()["state"].keys() == reference.optimizer.state_dict()["state"].keys()


def test_without_onednn_the_fast_update_runs_torchs_own_products_to_the_same_gradients(monkeypatch):
    """Where torch has no oneDNN (or on another device) the hidden products run in torch.nn.functional.linear:
    the gradients stay autograd's within 1e-5 of each one's largest element."""
    monkeypatch.setattr(fast_module, "ONEDNN", False)
    reference, fast = learner_pair("ddpg", "push")
    calls = []
    monkeypatch.setattr(torch.ops.mkldnn, "_linear_pointwise", lambda *args: calls.append(args))
    data = random_batch("push", 0)
    torch.manual_seed(0)
    reference.update(data)
    torch.manual_seed(0)
    fast.update(data)
    assert not calls and max(gradient_errors(reference, fast).values()) < 1e-5


def gradient_errors(reference, agent) -> dict[str, float]:
    """Per parameter: max abs(agent's .grad - reference's) / max abs(reference's .grad)."""
    theirs = parameters(agent)
    return {key: ((theirs[key].grad - p.grad).abs().max() / p.grad.abs().max()).item()
            for key, p in parameters(reference).items()}


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", LEARNERS)
def test_bf16_gradients_are_float32_autogradss_within_the_bound_and_as_close_as_autocasts(name, size, monkeypatch,
                                                                                             bf16_cpu):
    """Same networks and batch: with precision=bf16 each parameter's gradient lies within BF16_GRADIENT_BOUND of
    its largest element from the float32 autograd update's, within 1.25x (+ 1e-3) of bf16 autocast's own error,
    and not at float32's (the products do run in bf16); the losses within 1e-3."""
    reference, fast = learner_pair(name, size, ("fp32", "bf16"))
    autocast = learner_pair(name, size, ("bf16", "bf16"))[0]
    data = random_batch(size, 1)
    torch.manual_seed(5)
    critic_loss, actor_loss = autograd_gradients(reference, data)
    torch.manual_seed(5)
    autograd_gradients(autocast, data)
    monkeypatch.setattr(fast, "_direct_adam", False)
    monkeypatch.setattr(fast.optimizer, "step", lambda: None)
    torch.manual_seed(5)
    stats = fast.update(data)
    assert stats.critic_loss == pytest.approx(critic_loss, rel=1e-3)
    assert stats.actor_loss == pytest.approx(actor_loss, rel=1e-3, abs=1e-4)
    errors, autocast_errors = gradient_errors(reference, fast), gradient_errors(reference, autocast)
    assert max(errors.values()) <= BF16_GRADIENT_BOUND, errors
    assert all(errors[key] <= 1.25 * autocast_errors[key] + 1e-3 for key in errors), (errors, autocast_errors)
    assert max(errors.values()) > 1e-3


def test_bf16_runs_the_hidden_products_on_bf16_copies_refreshed_after_each_move(bf16_cpu):
    """The hidden activations are bf16 and the outputs float32; the bf16 weight copies equal the float32 master
    weights rounded after an update (the online networks), a polyak move (the targets) and a checkpoint load."""
    _, fast = learner_pair("td3", "tiny", ("fp32", "bf16"))

    def rounded_alike() -> bool:
        return all(torch.equal(low, master.to(torch.bfloat16)) for hand in fast.hand.values()
                   for low, master in zip(hand.low_weights + hand.low_biases, hand.weights[:-1] + hand.biases[:-1]))

    assert all(isinstance(hand, HandMLPBF16) for hand in fast.hand.values())
    fast.update(random_batch("tiny", 0))
    assert fast.hand["critic"].hidden[0].dtype == torch.bfloat16 and fast.hand["critic"].buffers.output.dtype == torch.float32
    assert rounded_alike()
    fast.update_targets()
    assert rounded_alike()
    other = learner_pair("td3", "tiny", ("fp32", "bf16"))[1]
    other.update(random_batch("tiny", 1))
    fast.load_state_dict(copy.deepcopy(other.state_dict()))
    assert rounded_alike()


@torch.no_grad()
def test_bf16_relu_and_its_mask_on_int16_bits_are_bf16s_own(bf16_cpu):
    """A forward and backward of the bf16 hand passes give the numbers of bf16 ``relu_`` and
    ``threshold_backward`` (plain bf16 kernels, redone here), negative zeros and values near 0 included, and the
    bias gradients float32 sums of the bf16 gradient."""
    _, fast = learner_pair("ddpg", "push", ("fp32", "bf16"))
    hand = fast.hand["critic"]
    inputs = torch.randn(64, hand.weights[0].shape[1])
    inputs[0, :] = -0.0
    output = hand.forward(inputs).clone()
    h = inputs.to(torch.bfloat16)
    activations = []
    for weight, bias in zip(hand.low_weights, hand.low_biases):
        h = torch.addmm(bias, h, weight.t()).relu_()
        activations.append(h)
    assert all(torch.equal(a.view(torch.int16), b.view(torch.int16)) for a, b in zip(hand.hidden, activations))
    assert torch.equal(output, torch.addmm(hand.biases[-1], h.float(), hand.weights[-1].t()))
    assert any(bool((a == 0).any()) for a in activations) and any(bool((a > 0).any()) for a in activations)
    grad_output = torch.randn(64, 1)
    hand.backward(grad_output, 64)
    g = torch.mm(grad_output, hand.weights[-1]).to(torch.bfloat16)
    g = torch.ops.aten.threshold_backward(g, activations[-1], 0)
    assert torch.equal(hand.biases[-2].grad, g.float().sum(0))
    g = torch.ops.aten.threshold_backward(torch.mm(g, hand.low_weights[-1]), activations[-2], 0)
    assert torch.equal(hand.biases[-3].grad, g.float().sum(0))


def test_a_cpu_without_bf16_instructions_refuses_the_fast_bf16_update_in_one_line(monkeypatch):
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: False)
    with pytest.raises(ConfigError, match="^precision=bf16: this CPU has no bf16 instructions.*use precision=fp32$"):
        learner_pair("ddpg", "tiny", ("fp32", "bf16"))


def test_fast_bf16_is_a_run_of_its_own():
    hashes = {config_hash(compose_train(["task=push", *overrides]))
              for overrides in ([], ["update=fast"], ["precision=bf16"], ["update=fast", "precision=bf16"])}
    assert len(hashes) == 4


class StopHere(Exception):
    pass


def test_an_interrupted_fast_bf16_run_resumes_to_the_uninterrupted_metrics(tmp_path, bf16_cpu):
    """The checkpoint holds the float32 master weights; the resumed run rounds its bf16 copies from them as the
    uninterrupted run did after its last step and target move, so it retraces it."""
    args = [*TINY, "update=fast", "precision=bf16", "epochs=3", "quiet=true", "threads=1"]
    reference = train(compose_train([*args, f"results_dir={tmp_path / 'ref'}"]))
    cfg = compose_train([*args, f"results_dir={tmp_path / 'cut'}"])

    def stop_after_epoch_1(record):
        if record["epoch"] == 1:
            raise StopHere

    with pytest.raises(StopHere):
        train(cfg, on_epoch=stop_after_epoch_1)
    resumed = train(cfg)
    assert [s["resumed_from_epoch"] for s in read_run(resumed).sessions] == [0, 1]
    pd.testing.assert_frame_equal(metrics(resumed), metrics(reference))


@pytest.mark.slow
@pytest.mark.skipif(not resources.cpu_has_bf16(), reason="this CPU has no bf16 instructions: hersd refuses bf16 here")
def test_fast_bf16_ddpg_learns_fetch_reach(tmp_path):
    """Paper settings on FetchReach, seed 0, update=fast precision=bf16: test success >= 0.9 within 5 epochs."""
    log = read_run(train(compose_train(["task=reach", "update=fast", "precision=bf16", "epochs=5", "seed=0",
                                        "quiet=true", "threads=1", "bias.epochs=[]", f"results_dir={tmp_path}"])))
    assert log.epochs["test_success"].max() >= 0.9, log.epochs["test_success"].tolist()


def test_td3s_actor_stands_still_between_its_steps():
    reference, fast = learner_pair("td3", "tiny")
    fast.update(random_batch("tiny", 0))
    actor = {key: p.clone() for key, p in parameters(fast).items() if key.startswith("actor.")}
    steps = [fast.optimizer.state[p]["step"].item() for p in fast.actor.parameters()]
    fast.update(random_batch("tiny", 1))  # policy_delay 2: the critics step, the actor not
    assert all(torch.equal(p, actor[key]) for key, p in parameters(fast).items() if key.startswith("actor."))
    assert [fast.optimizer.state[p]["step"].item() for p in fast.actor.parameters()] == steps
    assert fast.update_count == 2


@pytest.mark.parametrize("name", LEARNERS)
def test_checkpoints_load_across_the_two_updates(name):
    """The fast learner's checkpoint is the autograd one's (same parts, same optimiser state), either way."""
    reference, fast = learner_pair(name, "tiny")
    fast.update(random_batch("tiny", 0))
    reference.load_state_dict(copy.deepcopy(fast.state_dict()))
    assert all(torch.equal(p, q) for p, q in zip(parameters(reference).values(), parameters(fast).values()))
    reference.update(random_batch("tiny", 1))
    fast.load_state_dict(copy.deepcopy(reference.state_dict()))
    fast.update(random_batch("tiny", 2))  # the loaded Adam state is the one it steps
    assert all(fast.optimizer.state[p]["step"].item() == 3 for p in fast.critic.parameters())


def test_update_fast_builds_the_fast_learner_and_the_default_the_autograd_one():
    cfg = compose_train(["task=reach", "update=fast"])
    spec = EnvSpec(obs_dim=10, goal_dim=3, action_dim=4, horizon=50, max_action=1.0, distance_threshold=0.05,
                   reward_range=(-1.0, 0.0))
    assert type(make_agent(cfg, spec, 0.98, (-50.0, 0.0), torch.device("cpu"))) is FastDDPG
    cfg = compose_train(["task=reach", "update=fast", "learner=td3"])
    assert type(make_agent(cfg, spec, 0.98, (-50.0, 0.0), torch.device("cpu"))) is FastTD3
    cfg = compose_train(["task=reach"])
    assert type(make_agent(cfg, spec, 0.98, (-50.0, 0.0), torch.device("cpu"))) is learner_class("ddpg")


def test_fast_is_another_runs_identity_and_autograd_that_of_runs_made_before_the_setting():
    default = compose_train(["task=push"])
    assert config_hash(default) == "64e236fe"  # tests/test_configs.py's golden hash
    assert config_hash(compose_train(["task=push", "update=fast"])) != config_hash(default)
    before = config_record(default)
    del before["update"]
    assert run_identity(before) == run_identity(default) and "update" not in run_identity(default)


def test_what_has_no_fast_update_is_refused_in_one_line():
    with pytest.raises(ConfigError, match="update=fast: learner sac has no fast update .*use update=autograd"):
        compose_train(["task=push", "update=fast", "learner=sac"])


def test_an_unknown_update_is_refused():
    with pytest.raises(ConfigError, match="update must be autograd or fast, got 'quick'"):
        compose_train(["task=push", "update=quick"])


def test_a_tiny_fast_run_trains_and_logs(tmp_path):
    log = train(compose_train([*TINY, "update=fast", "epochs=2", "quiet=true", "threads=1",
                               f"results_dir={tmp_path}"]))
    assert len(metrics(log)) == 2 and np.isfinite(metrics(log)["critic_loss"]).all()


def test_the_contracts_fast_learners_are_the_names_of_fast_classes_keys_and_its_refusal_lists_them():
    """hersd.contract.config cannot import the engine: FAST_UPDATE_LEARNERS, read from the learners' cards
    (``fast_update``), restates FAST_CLASSES, checked here; the config's refusal and fast_learner_class's are one
    line, the same."""
    from hersd.contract.config import FAST_UPDATE_LEARNERS, TrainConfig
    from hersd.engine.learners import fast

    assert FAST_UPDATE_LEARNERS == tuple(cls.NAME for cls in fast.FAST_CLASSES)
    with pytest.raises(ConfigError, match=r"^update=fast: learner sac has no fast update \(ddpg and td3 have one\)") \
            as engine:
        fast_learner_class(learner_class("sac"))
    with pytest.raises(ConfigError) as config:
        TrainConfig(learner={"name": "sac"}, update="fast")
    assert str(config.value) == str(engine.value)
