"""Every file under conf/ composes into a valid config."""

from pathlib import Path

import pytest

from hersd.config import TASK_ENV_IDS
from hersd.train import CONF_DIR, compose


def options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


@pytest.mark.parametrize("group", ["task", "algo", "schedule"])
def test_every_group_option_composes(group):
    assert options(group)
    for option in options(group):
        cfg = compose([f"{group}={option}"])
        assert getattr(cfg, group) is not None


def test_tasks_match_the_env_table_and_reach_uses_10_cycles():
    assert options("task") == sorted(TASK_ENV_IDS)
    assert compose(["task=reach"]).task.cycles_per_epoch == 10
    assert compose(["task=push"]).task.cycles_per_epoch == 50


def test_defaults_are_the_papers_appendix_settings():
    cfg = compose([])
    d = cfg.ddpg
    assert (d.hidden_layers, d.hidden_units, d.actor_lr, d.critic_lr) == (3, 256, 1e-3, 1e-3)
    assert (d.buffer_size, d.polyak, d.action_l2, d.clip_obs, d.clip_norm, d.norm_eps) == (10**6, 0.95, 1.0, 200, 5, 0.01)
    assert (d.batch_size, d.rollouts_per_cycle, d.batches_per_cycle, d.test_rollouts) == (256, 2, 40, 10)
    assert (d.random_eps, d.noise_eps, d.gamma) == (0.3, 0.2, None)
    assert (cfg.epochs, cfg.schedule.kind, cfg.schedule.eps, cfg.algo.goal_strategy) == (200, "constant", 0.8, "future")
    assert (cfg.algo.lambda_r, cfg.algo.lambda_h) == (1.0, 1.0)
    assert compose(["algo=archer"]).algo.lambda_h == 0.5


def test_every_grid_file_is_a_global_multirun_grid():
    for path in (CONF_DIR / "grid").glob("*.yaml"):
        text = path.read_text()
        assert "# @package _global_" in text.splitlines()[0], path
        assert "sweeper:" in text and "params:" in text, path


def test_mean_rate_solves_beta1_by_eq10():
    from hersd.schedules import mean_rate_exact

    cfg = compose(["schedule=exponential", "schedule.mean_rate=0.85", "schedule.beta2=0.5", "epochs=200"])
    assert mean_rate_exact(cfg.schedule.beta1, 0.5, 200) == pytest.approx(0.85, abs=1e-5)
