"""Every file under conf/ composes into a valid config; the schema's defaults are the paper's."""

from __future__ import annotations

import subprocess
from dataclasses import asdict
from pathlib import Path

import pytest

from hersd.compose import compose, compose_train, group_options
from hersd.config import TrainConfig
from hersd.runlog import read_run
from hersd.runstore import config_hash
from hersd.schedules import schedule_from_record
from hersd.envs.tasks import CUSTOM, TASKS
from sweeps.launch import register_schemas


@pytest.mark.parametrize("group", ["task", "algo", "schedule", "learner"])
def test_every_group_option_composes(group):
    assert group_options(group)
    for option in group_options(group):
        extra = {CUSTOM: ["task.env_id=HandManipulateEgg-v1"], "table": ["epochs=2", "schedule.rates=[0.9,0.8]"]}
        extra = extra.get(option, []) if group in ("task", "schedule") else []
        cfg = compose_train([f"{group}={option}", *extra])
        assert isinstance(cfg, TrainConfig)


def test_task_files_name_the_tasks_of_the_table_and_take_its_settings():
    assert group_options("task") == sorted([*TASKS, CUSTOM])
    for name, task in TASKS.items():
        cfg = compose_train([f"task={name}"])
        assert (cfg.task.name, cfg.task.env_id, cfg.task.cycles_per_epoch) == (name, task.env_id, task.cycles_per_epoch)
    assert compose_train(["task=reach"]).task.cycles_per_epoch == 10


def test_defaults_are_the_papers_appendix_settings():
    cfg = compose_train([])
    d = cfg.ddpg
    assert (d.hidden_layers, d.hidden_units, d.actor_lr, d.critic_lr) == (3, 256, 1e-3, 1e-3)
    assert (d.buffer_size, d.polyak, d.action_l2, d.clip_obs, d.clip_norm, d.norm_eps) == (10**6, 0.95, 1.0, 200, 5, 0.01)
    assert (d.batch_size, d.rollouts_per_cycle, d.batches_per_cycle, d.test_rollouts) == (256, 2, 40, 10)
    assert (d.random_eps, d.noise_eps, d.gamma) == (0.3, 0.2, None)
    assert (cfg.epochs, cfg.schedule.kind, cfg.schedule.eps, cfg.algo.goal_strategy) == (200, "constant", 0.8, "future")
    assert (cfg.algo.lambda_r, cfg.algo.lambda_h) == (1.0, 1.0)
    assert compose_train(["algo=archer"]).algo.lambda_h == 0.5


@pytest.mark.parametrize("preset, kind, beta1, beta2", [
    ("linear", "linear", 0.25, 0.0), ("paper_linear_025", "linear", 0.25, 0.0), ("paper_linear_100", "linear", 1.0, 0.0),
    ("exponential", "exponential", 0.25, 0.25), ("paper_exp_050", "exponential", 0.5, 0.5),
])
def test_schedule_presets_hold_the_papers_values(preset, kind, beta1, beta2):
    schedule = compose_train([f"schedule={preset}"]).schedule
    assert (schedule.kind, schedule.beta1, schedule.beta2) == (kind, beta1, beta2)


def test_mep_algos_are_their_base_algo_with_mep_on():
    for mep, base in (("her_mep", "her"), ("archer_mep", "archer")):
        with_mep, without = compose_train([f"algo={mep}"]).algo, compose_train([f"algo={base}"]).algo
        assert with_mep.mep.enabled and not without.mep.enabled
        assert (with_mep.lambda_r, with_mep.lambda_h) == (without.lambda_r, without.lambda_h)


def sweep_config(overrides: list[str]):
    register_schemas()
    return compose("sweep", overrides, job_name="test", with_hydra=True)


@pytest.mark.parametrize("grid", group_options("grid"))
def test_every_grid_composes_as_a_multirun_grid(grid):
    cfg = sweep_config([f"+grid={grid}"])
    assert cfg.hydra.mode.name == "MULTIRUN" and cfg.hydra.sweeper.params, grid


@pytest.mark.parametrize("launcher", [*group_options("hydra/launcher"), "joblib", "submitit_local"])
def test_every_launcher_composes_with_the_sweep(launcher):
    cfg = sweep_config(["+grid=smoke", f"hydra/launcher={launcher}"])
    assert cfg.hydra.launcher._target_.startswith("hydra_plugins.")
    if launcher == "slurm":
        assert cfg.hydra.launcher._target_.endswith("SlurmLauncher")
        assert (cfg.hydra.launcher.cpus_per_task, cfg.hydra.launcher.timeout_min) == (1, 240)


def test_mean_rate_solves_beta1_by_eq10():
    from hersd.schedules import mean_rate_exact

    cfg = compose_train(["schedule=exponential", "schedule.mean_rate=0.85", "schedule.beta2=0.5", "epochs=200"])
    assert mean_rate_exact(cfg.schedule.beta1, 0.5, 200) == pytest.approx(0.85, abs=1e-5)


# A schema change must not silently move every run to a new directory: these hashes are the
# directories of runs made before (results/ holds the campaign's; the 20-epoch exponential one was in results/
# until df66795).
@pytest.mark.parametrize("overrides, golden", [
    (["task=push"], "64e236fe"),
    (["task=push", "schedule=paper_linear_025"], "252651aa"),
    (["task=push", "schedule=constant_mu_linear_025"], "96c926ed"),
    (["task=push", "epochs=20", "seed=1", "schedule=paper_exp_050"], "fc3f22b1"),  # push_demo's, retired
    (["task=reach", "epochs=3"], "620575b7"),
    (["task=push", "algo=her_mep", "schedule=linear", "epochs=3", "task.cycles_per_epoch=5", "seed=2"], "30f49fa1"),
])
def test_golden_config_hash(overrides, golden):
    assert config_hash(compose_train(overrides)) == golden


def committed_logs() -> list[Path]:
    """The run logs committed under results/ (skips outside a git checkout)."""
    root = Path(__file__).resolve().parent.parent
    listed = subprocess.run(["git", "ls-files", "-z", "--", "results/*run.mcap"], cwd=root, capture_output=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout")
    return [root / name for name in listed.stdout.decode().split("\0") if name]


def test_every_committed_log_keeps_its_directory():
    """The hash recomputed from the config in a log's metadata is its folder's: a schema change moved no run."""
    logs = committed_logs()
    assert logs
    for path in logs:
        meta = read_run(path).meta
        recomputed = config_hash(meta["config"])
        assert (path.parent.name, meta["run_id"]) == (f"seed{meta['seed']}-{recomputed}", recomputed), path


def test_every_committed_log_keeps_its_tag_and_identity_through_its_schedule_class():
    """A log's schedule record read back as its kind's class gives the same record (so a new config of that run
    hashes as the log does) and the folder tag the log lies in."""
    for path in committed_logs():
        config = read_run(path).meta["config"]
        schedule = schedule_from_record(config["schedule"])
        assert schedule.tag() == path.parent.parent.name, path
        assert config_hash({**config, "schedule": schedule.record()}) == config_hash(config), path


@pytest.mark.parametrize("preset", group_options("schedule"))
def test_the_paper_kinds_presets_keep_their_tags_and_records(preset):
    """Tags of the conf/schedule presets, as the flat schema made them (a record holds every flat field)."""
    golden = {"constant": "constant-0.8", "constant_mu_linear_025": "constant-0.874375",
              "exponential": "exponential-b1_0.25-b2_0.25", "linear": "linear-b1_0.25", "success": "success-b1_0.25-w10",
              "cosine": "cosine-1_0.5", "table": None}
    golden.update({f"paper_{shape}_{n:03d}": f"linear-b1_{n / 100:g}" if shape == "linear"
                   else f"exponential-b1_{n / 100:g}-b2_{n / 100:g}" for shape in ("linear", "exp") for n in (25, 50, 75, 100)})
    if golden[preset] is None:  # a table needs its rates
        return
    schedule = compose_train([f"schedule={preset}"]).schedule
    assert schedule.tag() == golden[preset]
    if preset != "cosine":
        assert set(schedule.record()) == {"kind", "eps", "beta1", "beta2", "mean_rate", "window", "eps_min"}


def test_a_custom_task_is_named_by_its_env_id():
    cfg = compose_train(["task=custom", "task.env_id=HandManipulateEgg-v1"])
    assert (cfg.task.name, cfg.task.env_id, cfg.task.cycles_per_epoch) == ("HandManipulateEgg-v1",) * 2 + (50,)
    assert config_hash(cfg) == config_hash(compose_train(["task=custom", "task.env_id=HandManipulateEgg-v1"]))


def _leaves(node, path: tuple = ()) -> dict[tuple, object]:
    """A YAML mapping's values by their key path (lists are values)."""
    if isinstance(node, dict):
        return {leaf: value for key, child in node.items() for leaf, value in _leaves(child, (*path, key)).items()}
    return {path: node}


@pytest.mark.parametrize("name", sorted(path.stem for path in (Path(__file__).resolve().parent.parent
                                                                 / "conf" / "search").glob("*.yaml")))
def test_search_files_state_only_what_differs_from_the_schema(name):
    import yaml

    from sweeps.search.config import SearchConfig

    root = Path(__file__).resolve().parent.parent
    stated = yaml.safe_load((root / "conf" / "search" / f"{name}.yaml").read_text(encoding="utf-8"))
    stated.pop("defaults")
    schema = _leaves(asdict(SearchConfig()))
    restated = [".".join(key) for key, value in _leaves(stated).items() if key in schema and schema[key] == value]
    assert not restated, f"conf/search/{name}.yaml restates the schema's defaults: {restated}"
