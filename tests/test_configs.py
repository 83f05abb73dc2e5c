"""Every file under conf/ composes into a valid config; the schema's defaults are the paper's."""

from __future__ import annotations

import subprocess
from dataclasses import asdict
from pathlib import Path

import pytest

from hersd.contract.compose import compose, compose_train, group_options, mean_rate
from hersd.contract.config import TrainConfig
from hersd.contract.errors import ConfigError
from hersd.contract.runlog import read_run
from hersd.contract.runstore import config_hash
from hersd.contract.schedules import schedule_from_record
from hersd.contract.tasks import CUSTOM, TASKS
from sweeps.plan import register_schemas


@pytest.mark.parametrize("group, default", [("task", "push"), ("algo", "her"), ("schedule", "constant"),
                                            ("learner", "ddpg")])
def test_every_group_option_composes_and_makes_its_own_run(group, default):
    """Each option composes, and only the default option gives the default run (the choice reaches the config)."""
    assert default in group_options(group)
    default_hash = config_hash(compose_train([]))
    for option in group_options(group):
        extra = {CUSTOM: ["task.env_id=HandManipulateEgg-v1"], "table": ["epochs=2", "schedule.rates=[0.9,0.8]"]}
        extra = extra.get(option, []) if group in ("task", "schedule") else []
        cfg = compose_train([f"{group}={option}", *extra])
        assert isinstance(cfg, TrainConfig) and (config_hash(cfg) == default_hash) == (option == default), option


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
    from hersd.contract.schedules import mean_rate_exact

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
    logs = committed_logs()
    assert logs
    for path in logs:
        config = read_run(path).meta["config"]
        schedule = schedule_from_record(config["schedule"])
        assert schedule.tag() == path.parent.parent.name, path
        assert config_hash({**config, "schedule": schedule.record()}) == config_hash(config), path


@pytest.mark.parametrize("preset", group_options("schedule"))
def test_the_paper_kinds_presets_keep_their_tags_and_records(preset):
    """Tags of the conf/schedule presets, as the flat schema made them (a record holds every flat field)."""
    golden = {"constant": "constant-0.8", "constant_mu_linear_025": "constant-0.874375",
              "exponential": "exponential-b1_0.25-b2_0.25", "linear": "linear-b1_0.25", "success": "success-b1_0.25-w10",
              "cosine": "cosine-1_0.5", "table": "table-506cb7a1", "rising_linear_025": "rising-b1_0.25",
              "constant_075": "constant-0.75"}
    golden.update({f"paper_{shape}_{n:03d}": f"linear-b1_{n / 100:g}" if shape == "linear"
                   else f"exponential-b1_{n / 100:g}-b2_{n / 100:g}" for shape in ("linear", "exp") for n in (25, 50, 75, 100)})
    given = ["epochs=2", "schedule.rates=[0.9,0.8]"] if preset == "table" else []  # a table needs its rates
    schedule = compose_train([f"schedule={preset}", *given]).schedule
    assert schedule.tag() == golden[preset]
    if preset == "table":
        assert schedule.record() == {"kind": "table", "rates": [0.9, 0.8], "file": None, "from_run": None}
    elif preset == "rising_linear_025":  # a kind after the flat schema: its own settings only
        assert schedule.record() == {"kind": "rising", "beta1": 0.25, "beta2": 0.0}
    elif preset != "cosine":
        assert set(schedule.record()) == {"kind", "eps", "beta1", "beta2", "mean_rate", "window", "eps_min"}


def test_a_custom_task_is_named_by_its_env_id():
    cfg = compose_train(["task=custom", "task.env_id=HandManipulateEgg-v1"])
    assert (cfg.task.name, cfg.task.env_id, cfg.task.cycles_per_epoch) == ("HandManipulateEgg-v1",) * 2 + (50,)
    assert config_hash(cfg) == config_hash(compose_train(["task=custom", "task.env_id=HandManipulateEgg-v1"]))


CONF = Path(__file__).resolve().parent.parent / "conf"
RESTATED = "# restated:"  # a line that sets a schema default carries this marker and the reason after it


def conf_files() -> list[str]:
    """Every YAML file under conf/ but Hydra's own launcher configs (conf/hydra/, whose schema is Hydra's)."""
    names = sorted(path.relative_to(CONF).as_posix() for path in CONF.rglob("*.yaml"))
    return [name for name in names if not name.startswith("hydra/")]


def file_schema(name: str) -> tuple[dict, tuple[str, ...]]:
    """The defaults of the schema a conf/ file is merged onto, and the key path the file's keys start at."""
    from sweeps.plan import SweepConfig
    from sweeps.search.config import SearchConfig

    group = name.split("/")[0] if "/" in name else name.removesuffix(".yaml")
    schemas = {"train": (TrainConfig, ()), "sweep": (SweepConfig, ()), "grid": (SweepConfig, ()),  # grids: _global_
               "search": (SearchConfig, ()),
               **{group: (TrainConfig, (group,)) for group in ("task", "algo", "learner", "schedule")}}
    assert group in schemas, f"conf/{name}: which schema is it merged onto? add its group to file_schema"
    schema, at = schemas[group]
    return asdict(schema()), at


def schedule_defaults(stated: dict, name: str) -> dict:
    """The schedule node's defaults: the default kind, and the parameters' defaults of the kind the node selects
    (its own ``kind``, else that of the preset its defaults list builds on, else the default kind's)."""
    import yaml

    from hersd.contract.schedules import DEFAULT, schedule_class

    kind, parents = stated.get("kind"), (stated.get("defaults", []) if name.startswith("schedule/") else [])
    while kind is None and parents:
        parent = yaml.safe_load((CONF / "schedule" / f"{parents[0]}.yaml").read_text(encoding="utf-8")) or {}
        kind, parents = parent.get("kind"), parent.get("defaults", [])
    cls = schedule_class(kind) if kind else DEFAULT
    return {"kind": DEFAULT.kind, **{item.name: item.default for item in cls.params()}}


def restated_keys(stated: dict, schema: dict, path: tuple = ()) -> list[tuple]:
    """Key paths whose stated value is the schema's default there (mappings compared key by key)."""
    found = []
    for key, value in stated.items():
        default = schema.get(key, KeyError) if isinstance(schema, dict) else KeyError
        if isinstance(value, dict) and isinstance(default, dict):
            found += restated_keys(value, default, (*path, key))
        elif default is not KeyError and value == default:
            found.append((*path, key))
    return found


def key_lines(text: str) -> dict[tuple, str]:
    """Each key path of a YAML document -> the line its key is on."""
    import yaml

    source = text.splitlines()

    def walk(node, path: tuple) -> dict[tuple, str]:
        if not isinstance(node, yaml.MappingNode):
            return {}
        return {found: line for key, value in node.value
                for found, line in {(*path, key.value): source[key.start_mark.line],
                                    **walk(value, (*path, key.value))}.items()}

    return walk(yaml.compose(text, Loader=yaml.SafeLoader), ())


@pytest.mark.parametrize("name", conf_files())
def test_config_files_state_only_what_differs_from_the_schema(name):
    """Each key a conf/ file sets differs from its schema's default there (or its line says why it restates it,
    after ``# restated:``): a file reads as what its option changes. Hydra's own ``hydra`` and ``defaults`` nodes
    are not the schema's."""
    import yaml

    text = (CONF / name).read_text(encoding="utf-8")
    stated = yaml.safe_load(text) or {}
    schema, at = file_schema(name)
    for key in at:
        schema = schema[key]
    if at == ("schedule",):
        schema = schedule_defaults(stated, name)
    elif isinstance(stated.get("schedule"), dict):  # a grid's schedule node, on the sweep's default schedule
        schema = {**schema, "schedule": schedule_defaults(stated["schedule"], name)}
    own = {key: value for key, value in stated.items() if key not in ("defaults", "hydra")}
    lines = key_lines(text)
    unexplained = [".".join(key) for key in restated_keys(own, schema)
                   if not lines[key].partition(RESTATED)[2].strip()]
    assert not unexplained, (f"conf/{name} restates the schema's defaults: {unexplained}; leave them out (a comment "
                             f"may say so), or give the reason on the line after '{RESTATED}'")


def test_the_restatement_check_finds_defaults_at_any_depth_and_kind():
    stated = {"seed": 0, "epochs": 50, "ddpg": {"polyak": 0.95, "gamma": 0.9}}
    assert restated_keys(stated, asdict(TrainConfig())) == [("seed",), ("ddpg", "polyak")]
    for stated, restated in (({"kind": "constant", "eps": 0.9}, [("kind",)]), ({"kind": "linear", "beta1": 0.0},
                                                                                 [("beta1",)])):
        assert restated_keys(stated, schedule_defaults(stated, "schedule/x.yaml")) == restated
    assert schedule_defaults({"defaults": ["exponential"]}, "schedule/x.yaml")["beta2"] == 0.0  # the parent's kind
    assert key_lines("a:\n  b: {c: 1}  # restated: why\n")[("a", "b", "c")] == "  b: {c: 1}  # restated: why"


def test_the_control_asks_the_linear_schedule_for_its_mean_rate_over_the_runs_k():
    """conf/schedule/constant_mu_linear_025.yaml types no number: eq. 10 of linear beta1 = 0.25 over K."""
    for epochs in (200, 8):
        control = compose_train(["task=push", "schedule=constant_mu_linear_025", f"epochs={epochs}"]).schedule
        assert control.eps == schedule_from_record({"kind": "linear", "beta1": 0.25}).exact_mean_rate(epochs)
    assert control.eps == 1 - 0.25 * 9 / 16
    with pytest.raises(ConfigError, match="success adapts to the run"):
        mean_rate({"kind": "success", "beta1": 0.25}, 200)


@pytest.mark.parametrize("override", ["+foo=1", "+ddpg.batchsize=64", "+task.foo=1", "+bias.foo=1", "+algo.mep.foo=1"])
def test_a_key_added_with_a_plus_that_is_no_field_is_refused_not_dropped(override):
    """Hydra's + lets a key the schema lacks into the config, where nothing would read it: the run would train at
    the defaults while its command shows the setting. It is refused like the same typo without the +."""
    key = override[1:].split("=")[0]
    with pytest.raises(ConfigError, match=rf"^{key} is not a config field \(the \+ added it"):
        compose_train([override])
    assert compose_train(["learner=td3", "learner.td3.policy_noise=0.1"]).learner.settings.policy_noise == 0.1


def test_a_learner_setting_takes_its_declared_type_or_is_refused_in_one_line():
    """learner.td3.policy_delay=2.0 is 2 and noise_clip=1 is 1.0 (one setting, one run folder); 2.5 or a word for a
    whole number is refused by name before any run (it used to reach the update: update_count % 2.5)."""
    from hersd.contract.runstore import run_dir

    def folder(*overrides):
        return run_dir(compose_train(["learner=td3", *overrides]))

    assert folder("learner.td3.policy_delay=2.0") == folder("learner.td3.policy_delay=2") == folder()
    assert folder("learner.td3.noise_clip=1") == folder("learner.td3.noise_clip=1.0") != folder()
    for value, wanted in (("2.5", "a whole number, got 2.5"), ("abc", "a whole number, got 'abc'")):
        with pytest.raises(ConfigError, match=rf"^learner\.td3\.policy_delay must be {wanted}$"):
            compose_train(["learner=td3", f"learner.td3.policy_delay={value}"])
    with pytest.raises(ConfigError, match=r"^learner\.sac\.target_entropy must be a number, got 'x'$"):
        compose_train(["learner=sac", "learner.sac.target_entropy=x"])
    assert compose_train(["learner=sac", "learner.sac.target_entropy=null"]).learner.settings.target_entropy is None


def test_a_learner_setting_of_another_declared_type_is_left_to_its_class():
    """Only int, float, bool and Optional of one are coerced: List[int] or Union[int, str] values pass as given."""
    from typing import List, Union

    from hersd.contract.config import _typed

    assert _typed("learner.x.widths", List[int], [64, 64]) == [64, 64]
    assert _typed("learner.x.mix", Union[int, float], 0.5) == 0.5
    assert _typed("learner.x.mode", Union[int, str], "abc") == "abc"
    with pytest.raises(ConfigError, match=r"^learner\.x\.scale must be a number, got 1000"):
        _typed("learner.x.scale", float, 10 ** 400)  # too large for a float: one line, not OverflowError


def test_the_papers_learner_has_one_name_the_default_every_reader_asks():
    """PAPER_LEARNER (hersd.contract.config) is the schema's default learner and DDPG's NAME; a config without a
    learner is its, and its runs keep the folder of runs made before learners were a setting."""
    from hersd.contract.config import PACKAGE_LEARNERS, PAPER_LEARNER, LearnerConfig
    from hersd.contract.runstore import run_dir, run_identity
    from hersd.engine.learners.ddpg import DDPG

    assert PAPER_LEARNER == DDPG.NAME == LearnerConfig().name == compose_train([]).learner.name
    assert PACKAGE_LEARNERS[PAPER_LEARNER] is None
    assert "learner" not in run_identity(compose_train([]))
    assert run_dir(compose_train(["task=reach"])).parent.parent.name == "her"
