"""The DDPG core's update rules on tiny networks and hand-made batches (no env)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from helpers import BATCH, batch, tiny_learner


def tiny_agent(**changes):
    """A tiny DDPG with these ``ddpg.*`` changes."""
    return tiny_learner("ddpg", ddpg=changes)


@pytest.mark.parametrize("reward, bound", [(1e6, 0.0), (-1e6, -50.0)])
def test_target_q_is_clipped_to_its_range(reward, bound):
    agent = tiny_agent()
    data = batch()
    next_inputs = agent._inputs(data.next_obs, data.goal)
    target = agent.target_q(next_inputs, torch.full((BATCH, 1), reward))
    assert torch.all(target == bound)
    unclipped = agent.target_q(next_inputs, torch.full((BATCH, 1), -1.0))
    assert torch.all((unclipped < 0) & (unclipped > -50))  # in range: untouched by the clip


@pytest.mark.parametrize("learner", ["ddpg", "td3"])
@pytest.mark.parametrize("reward, bound", [(1e6, 50.0), (-1e6, 0.0)])
def test_target_q_of_rewards_0_or_1_is_clipped_to_0_and_q_max(learner, reward, bound):
    """The mazes' range (rewards 0 or 1): target Q in [0, 1 / (1 - gamma)] (hersd.engine.run_state.discounting)."""
    agent = tiny_learner(learner, q_range=(0.0, 50.0))
    data = batch()
    target = agent.target_q(agent._inputs(data.next_obs, data.goal), torch.full((BATCH, 1), reward))
    assert torch.all(target == bound)


def test_polyak_moves_targets_by_one_minus_polyak_towards_the_online_networks():
    agent = tiny_agent(polyak=0.95)
    with torch.no_grad():
        for online, target in ((agent.actor, agent.actor_target), (agent.critic, agent.critic_target)):
            for p in online.parameters():
                p.fill_(1.0)
            for p in target.parameters():
                p.fill_(0.0)
    agent.update_targets()
    for target in (agent.actor_target, agent.critic_target):
        for p in target.parameters():
            assert torch.allclose(p, torch.full_like(p, 0.05))


def test_the_actor_loss_leaves_the_critic_alone_and_each_loss_moves_its_own_network():
    agent = tiny_agent()
    before = copy.deepcopy(agent)
    data = batch()
    agent.update(data)
    # The critic's gradient in the joint update equals that of the critic loss alone ...
    inputs = before._inputs(data.obs, data.goal)
    target = before.target_q(before._inputs(data.next_obs, data.goal), torch.from_numpy(data.reward).unsqueeze(1))
    critic_loss = torch.mean(torch.square(target - before.critic(torch.cat([inputs, torch.from_numpy(data.action)], 1))))
    critic_loss.backward()
    for joint, alone in zip(agent.critic.parameters(), before.critic.parameters()):
        assert torch.allclose(joint.grad, alone.grad, atol=1e-7)
    # ... and the actor's that of the actor loss alone (the critic seen through frozen weights).
    before.actor.zero_grad()
    policy = torch.tanh(before.actor(inputs))
    actor_loss = -before.critic(torch.cat([inputs, policy], 1)).mean() + torch.mean(torch.square(policy))
    actor_loss.backward()
    for joint, alone in zip(agent.actor.parameters(), before.actor.parameters()):
        assert torch.allclose(joint.grad, alone.grad, atol=1e-7)
    assert any(not torch.equal(a, b) for a, b in zip(agent.critic.parameters(), before.critic.parameters()))


def test_exploration_clips_to_the_action_range_and_test_actions_are_deterministic():
    agent = tiny_agent(noise_eps=5.0, random_eps=0.0)
    data = batch()
    explored = agent.act(data.obs, data.goal, explore=True, rng=np.random.default_rng(0))
    assert np.all(np.abs(explored) <= 1.0) and np.any(np.abs(explored) == 1.0)
    first = agent.act(data.obs, data.goal, explore=False, rng=np.random.default_rng(0))
    assert np.array_equal(first, agent.act(data.obs, data.goal, explore=False, rng=np.random.default_rng(9)))


def test_state_dict_round_trip_gives_the_same_next_update():
    agent = tiny_agent()
    agent.update(batch(seed=2))
    clone = tiny_agent(polyak=0.95)
    clone.load_state_dict(copy.deepcopy(agent.state_dict()))
    for seed in (3, 4, 5):  # the stats are computed before the step: later updates show Adam's state and the targets
        assert agent.update(batch(seed=seed)) == clone.update(batch(seed=seed))
    modules = [name for name in agent.PARTS if isinstance(getattr(agent, name), torch.nn.Module)]
    assert {"actor", "critic"} <= set(modules)
    for name in modules:  # the weights after the steps: Adam's moments and step counts were carried over too
        for mine, theirs in zip(getattr(agent, name).parameters(), getattr(clone, name).parameters()):
            assert torch.equal(mine, theirs), name
