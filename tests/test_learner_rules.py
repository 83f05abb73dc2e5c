"""TD3 and SAC beyond tests/test_learners.py: target moves, the SAC target's formula, determinism
under a fixed seed (and which generator each random draw uses), exploration, the reported Q,
the state that a resume needs, and the config range checks. Tiny networks, synthetic batches."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch
from helpers import ACTION, BATCH, batch, tiny_learner

from hersd.contract.learners.sac import SACConfig
from hersd.contract.learners.td3 import TD3Config
from hersd.contract.errors import ConfigError

LEARNERS = ["td3", "sac"]


def make(learner: str, max_action: float = 1.0, seed: int = 0, **settings):
    return tiny_learner(learner, max_action=max_action, seed=seed, **settings)


def params(net: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in net.parameters()]


def same(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a, b))


@pytest.mark.parametrize("learner, pairs", [
    ("td3", [("actor", "actor_target"), ("critic", "critic_target"), ("critic2", "critic2_target")]),
    ("sac", [("critic", "critic_target"), ("critic2", "critic2_target")]),
])
def test_update_targets_moves_every_target_by_one_minus_polyak(learner, pairs):
    agent = make(learner)
    with torch.no_grad():
        for online, target in pairs:
            for p in getattr(agent, online).parameters():
                p.fill_(1.0)
            for p in getattr(agent, target).parameters():
                p.fill_(-1.0)
    agent.update_targets()
    for online, target in pairs:
        assert all(torch.allclose(p, torch.full_like(p, -1.0 + 2 * 0.05)) for p in getattr(agent, target).parameters())
        assert all(torch.equal(p, torch.ones_like(p)) for p in getattr(agent, online).parameters())
    assert learner == "td3" or not hasattr(agent, "actor_target")  # SAC has no actor target


@pytest.mark.parametrize("alpha", [0.1, 10.0])
def test_sac_target_is_the_soft_min_of_the_twin_target_critics(alpha):
    """y = r + gamma (min Q' - alpha log pi), unclipped: at alpha 10 the entropy bonus lifts most
    targets of a reward -1 above 0, where DDPG's clip to [q_min, 0] would pin them."""
    agent = make("sac")
    with torch.no_grad():  # Q2' = Q1' - 1 everywhere
        agent.critic2_target.load_state_dict(agent.critic_target.state_dict())
        agent.critic2_target[-1].bias -= 1.0
        agent.log_alpha.fill_(math.log(alpha))
    data = batch()
    next_inputs = agent._inputs(data.next_obs, data.goal)
    reward = torch.full((BATCH, 1), -1.0)
    torch.manual_seed(3)
    target = agent.target_q(next_inputs, reward)
    torch.manual_seed(3)
    with torch.no_grad():
        mean, log_std = agent.actor(next_inputs).chunk(2, dim=1)
        std = log_std.clamp(-20, 2).exp()
        pre_tanh = mean + std * torch.randn_like(mean)
        action = torch.tanh(pre_tanh)
        log_prob = (torch.distributions.Normal(mean, std).log_prob(pre_tanh)
                    - torch.log(1 - action ** 2 + 1e-6)).sum(1, keepdim=True)
        x = torch.cat([next_inputs, action], 1)
        q1, q2 = agent.critic_target(x), agent.critic2_target(x)
    expected = reward + 0.98 * (q2 - alpha * log_prob)
    assert torch.all(q2 < q1)  # the min decides
    if alpha > 1:  # a clip at 0 would change these
        assert (expected > 1).sum() > BATCH // 2
    else:  # inside [q_min, 0]: a clip would not matter
        assert torch.all((expected < 0) & (expected > -50))
    assert torch.allclose(target, expected, atol=1e-5)


@pytest.mark.parametrize("learner", LEARNERS)
def test_same_seed_gives_the_same_numbers_and_randomness_is_torchs(learner):
    """Two agents from one seed take identical updates; numpy's global RNG plays no part, while the
    torch seed set before the updates does (TD3: target smoothing noise; SAC: policy samples)."""
    def run(torch_seed: int, numpy_seed: int):
        agent = make(learner)
        np.random.seed(numpy_seed)
        torch.manual_seed(torch_seed)
        stats = [agent.update(batch(seed=s)) for s in range(3)]
        return stats, params(agent.actor) + params(agent.critic) + params(agent.critic2)

    stats, weights = run(1, 1)
    stats_again, weights_again = run(1, 2)
    assert stats == stats_again and same(weights, weights_again)
    other_stats, _ = run(2, 1)
    assert [s.critic_loss for s in other_stats] != [s.critic_loss for s in stats]


def test_sac_tests_with_tanh_of_the_mean_and_explores_with_the_given_generator_only():
    agent = make("sac", max_action=2.0)
    data = batch()
    with torch.no_grad():
        mean = agent.actor(agent._inputs(data.obs, data.goal))[:, :ACTION]
    deterministic = agent.act(data.obs, data.goal, False, np.random.default_rng(0))
    assert deterministic.dtype == np.float64 and deterministic.shape == (BATCH, ACTION)
    np.testing.assert_allclose(deterministic, 2.0 * torch.tanh(mean).numpy(), rtol=1e-6)
    torch_state = torch.get_rng_state()
    explored = agent.act(data.obs, data.goal, True, np.random.default_rng(0))
    assert torch.equal(torch.get_rng_state(), torch_state)  # rollouts do not consume torch's generator
    assert np.all(np.abs(explored) <= 2.0) and np.abs(explored).max() > 1.0  # scaled by max_action


def test_sac_log_std_is_clamped_to_its_range():
    agent = make("sac")
    inputs = agent._inputs(batch().obs, batch().goal)
    for bias, expected in ((50.0, math.exp(2.0)), (-50.0, math.exp(-20.0))):
        with torch.no_grad():
            agent.actor[-1].weight[ACTION:].zero_()
            agent.actor[-1].bias[ACTION:].fill_(bias)
        _mean, std = agent.policy(inputs)
        assert torch.allclose(std, torch.full_like(std, expected))


@pytest.mark.parametrize("learner", LEARNERS)
def test_reported_q_is_the_first_online_critics_on_the_batch(learner):
    agent = make(learner)
    with torch.no_grad():
        agent.critic2[-1].bias -= 5.0  # the second critic (and the twins' minimum) would read lower
    data = batch()
    with torch.no_grad():
        q = agent.critic(torch.cat([agent._inputs(data.obs, data.goal), agent.tensor(data.action)], 1))
    stats = agent.update(data)
    assert stats.q_mean == pytest.approx(q.mean().item(), abs=1e-6)
    assert stats.q_sq_mean == pytest.approx(q.square().mean().item(), abs=1e-6)
    assert all(isinstance(value, float) for value in stats[:4])  # plain floats: no tensors kept alive
    assert isinstance(stats.entropy, float) if learner == "sac" else stats.entropy is None


def test_td3_resume_keeps_the_phase_of_the_delayed_actor_steps():
    agent = make("td3", policy_delay=2)
    agent.update(batch(seed=0))
    state = copy.deepcopy(agent.state_dict())
    clone = make("td3", policy_delay=2)
    clone.load_state_dict(state)
    restarted = make("td3", policy_delay=2)  # same weights, but its counter back at 0
    restarted.load_state_dict({**state, "counters": {"update_count": 0, "last_actor_loss": 0.0}})
    moved = []
    for learner in (agent, clone, restarted):
        before = params(learner.actor)
        learner.update(batch(seed=1))
        moved.append(not same(before, params(learner.actor)))
    assert moved[0] == moved[1] != moved[2]


def test_sac_resume_restores_the_temperature_and_its_optimiser():
    agent = make("sac")
    for seed in range(3):
        agent.update(batch(seed=seed))
    clone = make("sac")
    assert clone.alpha != agent.alpha
    clone.load_state_dict(copy.deepcopy(agent.state_dict()))
    assert clone.alpha == agent.alpha
    for seed in (3, 4):
        torch.manual_seed(seed)
        first = agent.update(batch(seed=seed))
        torch.manual_seed(seed)
        assert clone.update(batch(seed=seed)) == first and clone.alpha == agent.alpha


@pytest.mark.parametrize("cfg, settings", [
    (TD3Config, {"policy_noise": -0.1}), (TD3Config, {"noise_clip": -1.0}), (TD3Config, {"policy_delay": 0}),
    (TD3Config, {"policy_noise": float("nan")}), (SACConfig, {"init_alpha": 0.0}), (SACConfig, {"alpha_lr": -3e-4}),
    (SACConfig, {"target_entropy": float("inf")}),
])
def test_out_of_range_settings_are_one_line_config_errors(cfg, settings):
    with pytest.raises(ConfigError) as err:
        cfg(**settings)
    assert "\n" not in str(err.value) and next(iter(settings)) in str(err.value)
