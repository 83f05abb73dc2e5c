"""hersd/engine/denormals.py: denormals flushed to zero in a run's torch work, on every intra-op thread, with the
physics in IEEE arithmetic; off with flush_denormal=false; the default on."""

from __future__ import annotations

import pytest
import torch
from gymnasium_robotics.envs.robot_env import MujocoRobotEnv

from hersd.contract.compose import compose_train
from hersd.contract.config import TrainConfig
from hersd.engine.denormals import denormals_flushed, set_intra_op_threads, thread_flush_states
from hersd.engine.learners.ddpg import DDPG
from hersd.contract.runlog import read_run
from hersd.engine.train import train

DENORMAL = 1e-40  # below float32's smallest normal, 1.18e-38


def flushes_here() -> bool:
    """Whether this thread's arithmetic turns a denormal input to zero."""
    return (torch.tensor([DENORMAL]) * 1.0).item() == 0.0


def denormals_left_by_a_matmul() -> int:
    """Nonzero entries of a (256, 256) denormal matrix times the identity: the BLAS may spread its rows over the
    intra-op threads (it decides how many), and a thread that keeps denormals leaves its share nonzero."""
    return int((torch.full((256, 256), DENORMAL) @ torch.eye(256)).count_nonzero())


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)
    set_intra_op_threads(False)


def test_every_intra_op_thread_follows_the_setting(two_threads):
    set_intra_op_threads(True)
    with denormals_flushed(True):
        assert thread_flush_states() == [True, True]
        assert denormals_left_by_a_matmul() == 0
    assert thread_flush_states() == [False, True]  # the calling thread only inside the block
    set_intra_op_threads(False)
    with denormals_flushed(True):
        assert thread_flush_states() == [True, False]
    assert thread_flush_states() == [False, False] and denormals_left_by_a_matmul() == 256 * 256


def test_the_default_flushes():
    assert TrainConfig().flush_denormal is True


@pytest.mark.parametrize("flush", [True, False])
def test_a_run_flushes_its_torch_work_on_every_thread_and_never_the_physics(tmp_path, monkeypatch, two_threads,
                                                                             tiny, flush):
    """Updates, target moves and acting (rollouts, test episodes, the bias evaluation) see denormals as zero on
    the run's thread and on the intra-op threads, and the physics in between does not; without the setting
    nothing flushes."""
    seen: dict[str, set] = {"update": set(), "update_targets": set(), "act": set(), "physics": set()}

    def probe(name, method):
        def probed(self, *args, **kwargs):
            states = thread_flush_states()
            seen[name].add((flushes_here(), tuple(states[1:]), denormals_left_by_a_matmul() == 0))
            return method(self, *args, **kwargs)
        return probed

    for name in ("update", "update_targets", "act"):
        monkeypatch.setattr(DDPG, name, probe(name, getattr(DDPG, name)))
    physics = MujocoRobotEnv._mujoco_step
    monkeypatch.setattr(MujocoRobotEnv, "_mujoco_step",
                        lambda self, action: (seen["physics"].add(flushes_here()), physics(self, action))[1])
    overrides = [*tiny, "epochs=1", "threads=2", f"flush_denormal={str(flush).lower()}", "bias.epochs=[1]",
                 "bias.episodes=1", "bias.hindsight_pairs=1", "bias.return_steps=60"]
    log = train(compose_train(overrides))
    everywhere = (flush, (flush,), flush)
    assert seen == {"update": {everywhere}, "update_targets": {everywhere}, "act": {everywhere}, "physics": {False}}
    assert not flushes_here()  # back to IEEE after the run
    meta = read_run(log).meta
    assert meta["config"]["flush_denormal"] is flush and meta["threads"] == 2
