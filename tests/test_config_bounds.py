"""Every numeric setting at its extremes: out of the range its math needs is one ConfigError line naming
the field (exit 2 from the command, nothing written); the range's own edges are accepted. Also the memory
check's per-update part, and a run whose losses turn non-finite stopping with one line."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import typing
from pathlib import Path

import pytest
from helpers import TINY

import hersd.engine.run_state
import hersd.engine.train
from hersd.engine.cli import main
from hersd.contract.compose import compose_train
from hersd.contract.config import (PACKAGE_LEARNERS, AlgoConfig, BiasConfig, DDPGConfig, MEPConfig, TaskConfig,
                                   TrainConfig)
from hersd.contract.errors import ConfigError
from hersd.engine.envs.make import EnvSpec
from hersd.contract.runlog import read_run
from hersd.contract.runstore import CHECKPOINT_NAME
from hersd.contract.schedules import SCHEDULES, Linear, schedule_class

INF, NAN, HUGE = float("inf"), float("nan"), 1e308
BIG_INT = 10 ** 18


def _reach(**settings) -> TrainConfig:
    return TrainConfig(task=TaskConfig(name="reach"), **settings)


SCHEMAS = {  # the field's owner, built with one setting -> a config object
    "task": lambda **s: TaskConfig(name="reach", **s),
    "algo.mep": MEPConfig, "algo": AlgoConfig, "ddpg": DDPGConfig,
    "schedule": lambda **s: schedule_class(SCHEDULE_OF[next(iter(s))])(**s),
    "schedule.mean_rate": lambda **s: Linear(**s),
    **{f"learner.{name}": settings for name, settings in PACKAGE_LEARNERS.items() if settings},  # their cards'
    "bias": BiasConfig, "": _reach,
}
SCHEDULE_OF = {"eps": "constant", "beta1": "exponential", "beta2": "exponential", "window": "success",
               "eps_min": "success", "start": "cosine", "end": "cosine"}  # a kind with the setting
WEIGHT = ([0.0, -1.0, 9.9e-7, 1.1e6, HUGE, INF, NAN], [1e-6, 1.0, 1e6])  # lambda, alpha: [1e-6, 1e6]
SHARE = ([-0.1, 1.1, HUGE, INF, NAN], [0.0, 1.0])  # probabilities and rates: [0, 1]
RATE = ([0.0, -1e-3, 1.5, HUGE, INF, NAN], [1e-12, 1.0])  # Adam learning rates: (0, 1]
SCALE = ([-1.0, 1.1e6, HUGE, INF, NAN], [0.0, 1e6])  # L2 weight, noise stds: [0, 1e6]
COUNT = ([0, -1], [1, BIG_INT])  # counts without a memory cost: >= 1
SIZED = ([0, -1], [1])  # counts with a memory cost: >= 1 here, the rest is the memory check's
# field -> (invalid values, valid values); the owner is the longest prefix in SCHEMAS
TABLE: dict[str, tuple[list, list]] = {
    "task.cycles_per_epoch": (COUNT[0], [*COUNT[1], None]),
    "task.distance_threshold": ([0.0, -1.0, INF, NAN], [1e-9, HUGE, None]),
    "algo.mep.temperature": ([0.0, -1.0, 0.049, INF, NAN], [0.05, 1.0, HUGE]),
    "algo.mep.n_components": SIZED,
    "algo.mep.fit_subsample": ([0, -1, 2], [3, BIG_INT]),  # >= n_components (3)
    "algo.mep.max_iter": COUNT,
    "algo.lambda_r": WEIGHT, "algo.lambda_h": WEIGHT,
    "schedule.eps": SHARE, "schedule.beta1": SHARE, "schedule.eps_min": SHARE, "schedule.mean_rate": SHARE,
    "schedule.beta2": ([-50.1, 50.1, -HUGE, HUGE, INF, NAN], [-50.0, 0.0, 50.0]),
    "schedule.window": COUNT, "schedule.start": SHARE, "schedule.end": SHARE,
    "ddpg.hidden_layers": SIZED, "ddpg.hidden_units": SIZED, "ddpg.buffer_size": ([0, -1], [256]),
    "ddpg.batch_size": ([0, -1, 10 ** 6 + 1, BIG_INT], [1, 10 ** 6]),  # within buffer_size (10^6)
    "ddpg.rollouts_per_cycle": SIZED, "ddpg.batches_per_cycle": COUNT, "ddpg.test_rollouts": COUNT,
    "ddpg.actor_lr": RATE, "ddpg.critic_lr": RATE,
    "ddpg.polyak": SHARE, "ddpg.random_eps": SHARE, "ddpg.noise_eps": SCALE, "ddpg.action_l2": SCALE,
    "ddpg.clip_obs": WEIGHT, "ddpg.clip_norm": WEIGHT, "ddpg.norm_eps": WEIGHT,
    "ddpg.gamma": ([0.0, -0.5, 0.9999999, 1.0, HUGE, INF, NAN], [1e-300, 0.98, 0.999999, None]),
    "learner.td3.policy_noise": SCALE, "learner.td3.noise_clip": SCALE,
    "learner.td3.policy_delay": COUNT,
    "learner.sac.init_alpha": WEIGHT, "learner.sac.alpha_lr": RATE,
    "learner.sac.target_entropy": ([-1.1e6, 1.1e6, -HUGE, HUGE, INF, -INF, NAN], [-1e6, 0.0, 1e6, None]),
    "bias.epochs": ([[0], [-1], [1, 0]], [[], [1], [1, 2, 200]]),
    "bias.episodes": COUNT, "bias.return_steps": COUNT, "bias.hindsight_pairs": ([-1], [0, 1]),
    "bias.moved_pairs": ([-1], [0, 1]),
    "seed": ([-1], [0, BIG_INT]), "epochs": COUNT, "checkpoint_every": ([-1], [0, BIG_INT]),
    "render_every": ([-1], [0, BIG_INT]),
    "threads": (["0", "1025", "-1", "1e3"], ["auto", "1", "1024"]),
}
CASES = [(field, value, valid) for field, (bad, good) in TABLE.items()
         for valid, values in ((False, bad), (True, good)) for value in values]


def build(field: str, value):
    """The config object of ``field``'s owner with that one setting."""
    owner, _, name = field.rpartition(".")
    owner = field if field in SCHEMAS else owner
    name = "mean_rate" if field == "schedule.mean_rate" else name
    return SCHEMAS[owner](**{name: value})


@pytest.mark.parametrize("field, value, valid", CASES, ids=[f"{f}={v!r}" for f, v, _ in CASES])
def test_each_numeric_setting_is_refused_outside_its_range_by_name(field, value, valid):
    if valid:
        build(field, value)
        return
    with pytest.raises(ConfigError) as err:
        build(field, value)
    message = str(err.value)
    assert "\n" not in message and f"{field} must be" in message and "got" in message, message


def _numeric_fields(schema: type, prefix: str = "") -> list[str]:
    hints = typing.get_type_hints(schema)
    found = []
    for item in dataclasses.fields(schema):
        kind = hints[item.name]
        if dataclasses.is_dataclass(kind):
            found += _numeric_fields(kind, f"{prefix}{item.name}.")
        elif item.name == "threads" or {int, float} & {kind, *typing.get_args(kind)}:
            found.append(f"{prefix}{item.name}")
    return found


def test_the_table_covers_every_numeric_setting_with_a_refused_value():
    schedules = {f"schedule.{item.name}" for cls in SCHEDULES.values() for item in cls.params() if "low" in item.metadata}
    learners = [field for name, cls in PACKAGE_LEARNERS.items() if cls for field in _numeric_fields(cls, f"learner.{name}.")]
    fields = _numeric_fields(TrainConfig) + sorted(schedules) + learners
    assert sorted(fields) == sorted(TABLE)
    assert all(TABLE[field][0] for field in fields)


@pytest.mark.parametrize("override, field", [
    ("algo.lambda_h=1e308", "algo.lambda_h"), ("ddpg.action_l2=1e308", "ddpg.action_l2"),
    ("ddpg.batch_size=1000000000", "ddpg.batch_size"), ("ddpg.gamma=0.99999999", "ddpg.gamma"),
    ("learner.sac.target_entropy=1e308", "learner.sac.target_entropy"),
])
def test_composed_overrides_are_checked_as_the_dataclasses_are(override, field):
    with pytest.raises(ConfigError, match=f"^{field} must be"):
        compose_train(["task=reach", override])


FETCH = EnvSpec(obs_dim=25, goal_dim=3, action_dim=4, horizon=50, max_action=1.0, distance_threshold=0.05,
               reward_range=(-1.0, 0.0))


@pytest.mark.parametrize("overrides, setting", [
    (["ddpg.buffer_size=2000000000", "ddpg.batch_size=1000000000"], "ddpg.batch_size"),
    (["ddpg.hidden_units=100000"], "ddpg.hidden_units"),
    (["ddpg.hidden_layers=100000"], "ddpg.hidden_layers"),
    (["ddpg.rollouts_per_cycle=1000000"], "ddpg.rollouts_per_cycle"),
    (["algo=her_mep", "algo.mep.n_components=100000", "algo.mep.fit_subsample=100000"], "algo.mep.n_components"),
    (["ddpg.buffer_size=100000000000"], "ddpg.buffer_size"),
])
def test_memory_check_counts_each_allocation_and_names_its_setting(monkeypatch, overrides, setting):
    monkeypatch.setattr(hersd.engine.run_state, "available_memory_bytes", lambda: 64 * 2 ** 30)  # a 64 GiB machine
    cfg = compose_train(["task=push", *overrides])
    with pytest.raises(ConfigError) as err:
        hersd.engine.run_state.check_memory(cfg, FETCH, one_env_bytes=23 * 2 ** 20)
    message = str(err.value)
    assert "\n" not in message and setting in message.split(" GiB are available; lower ")[1], message
    hersd.engine.run_state.check_memory(compose_train(["task=push"]), FETCH, one_env_bytes=23 * 2 ** 20)  # defaults fit


def test_a_minibatch_too_large_for_memory_is_refused_at_start_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["task=reach", "ddpg.buffer_size=2000000000", "ddpg.batch_size=1000000000", f"results_dir={tmp_path}"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "lower ddpg.batch_size" in err, err
    assert not any(tmp_path.iterdir())


def test_hersd_train_with_an_overflowing_weight_exits_2_with_one_line_and_writes_nothing(tmp_path):
    results = tmp_path / "results"
    script = Path(sys.executable).with_name("hersd-train")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "hersd.engine.cli"]
    done = subprocess.run([*command, "task=reach", "algo.lambda_h=1e308", f"results_dir={results}"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == "hersd-train: error: algo.lambda_h must be a number in [1e-06, 1e+06], got 1e+308"
    assert done.stdout == "" and not results.exists() and sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning", "ignore:invalid value:RuntimeWarning")
def test_a_run_whose_loss_turns_nan_stops_with_one_line_and_keeps_its_finished_epochs(tmp_path, capsys, monkeypatch):
    run_epoch = hersd.engine.train.run_epoch

    def poisoned(state, epoch, rate=None):  # from epoch 2 on, hindsight rewards of -1e308 (the bounds refuse this)
        if epoch == 2:
            state.cfg.algo.lambda_h = 1e308
        return run_epoch(state, epoch, rate)

    monkeypatch.setattr(hersd.engine.train, "run_epoch", poisoned)
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warnings on the NaN actions to MUJOCO_LOG.TXT here
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, "epochs=3", "quiet=true", "threads=1", f"results_dir={tmp_path / 'results'}"])
    assert exit_info.value.code == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("hersd-train: error: epoch 2: critic_loss=nan"), err
    assert "algo.lambda_h" in err and "ddpg.action_l2" in err
    log_path = next((tmp_path / "results").rglob("run.mcap"))
    run = read_run(log_path)
    assert list(run.epochs["epoch"]) == [1] and not run.complete
    assert (log_path.parent / CHECKPOINT_NAME).exists()
