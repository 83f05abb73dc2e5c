"""hersd/__init__.py's table of moved modules: every path from before the split into hersd/contract and hersd/engine
that users' code, the docs, the conf YAMLs and the committed logs name imports, with a FutureWarning naming its new
path, as the very object of its new path (a package: a stand-in whose names are the new package's, the new package
unchanged); no new log names an old path; a run's folder does not depend on the path its schedule is named by;
checkpoints name no module of hersd."""

from __future__ import annotations

import importlib
import io
import pickle
import pickletools
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from helpers import TINY

import hersd
from hersd import MOVED, moved_to
from hersd.contract.compose import compose_train
from hersd.contract.runlog import CHANNELS
from hersd.contract.runstore import config_hash, run_dir
from hersd.contract.schedules import Schedule, schedule_from_config
from hersd.contract.schedules.linear import Linear

ROOT = Path(__file__).resolve().parent.parent
# What README.md and docs/ named by the old paths before the split (they name the new ones now).
DOCUMENTED = """hersd.bias.restore hersd.config.ConfigError hersd.config.PACKAGE_LEARNERS hersd.config.TD3Config
hersd.config.TrainConfig hersd.config.learner_record hersd.envs.goal_envs.goal_reward hersd.envs.make.env_spec
hersd.envs.tasks.TASKS hersd.envs.tasks.task_title hersd.learners.learner_class hersd.learners.td3.TD3
hersd.resources hersd.run_state.check_memory hersd.run_state.discounting hersd.runlog.EPOCH_FIELDS
hersd.runlog.read_records hersd.runlog.read_run hersd.runlog.replace_file hersd.runstore.HASHED_UNLESS
hersd.runstore.NOT_HASHED hersd.runstore.RunFolder.animations hersd.runstore.RunFolder.holder
hersd.runstore.RunLockedError hersd.runstore.run_identity hersd.schedules.Constant hersd.schedules.MU_EPS_BAND
hersd.schedules.SCHEDULES hersd.schedules.Schedule hersd.schedules.param hersd.train.train
hersd.schedules.base.Schedule hersd.schedules.linear.Linear hersd.schedules.exponential.Exponential""".split()
# What the schemas of logs written before the change name (every committed log has been rewritten since).
OLD_LOGS = "hersd.runstore.config_hash hersd.run_state.RunState.effective_totals hersd.resources.machine_info".split()


def committed_names() -> set[str]:
    """The old paths the committed run logs (their schemas' descriptions) and the conf YAMLs (``_target_``) name."""
    listed = subprocess.run(["git", "ls-files", "-z", "--", "results/*run.mcap", "conf/*.yaml"], cwd=ROOT,
                            capture_output=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout")
    names = set()
    for name in listed.stdout.decode().split("\0"):
        if name:
            names |= set(re.findall(r"hersd(?:\.\w+)+", (ROOT / name).read_bytes().decode("latin-1")))
    return {name for name in names if moved_to(name)}


def every_old_module() -> list[str]:
    """The old path of every module of the moved modules and packages."""
    old_of = {new: old for old, new in MOVED.items()}
    found = []
    for path in sorted((ROOT / "hersd").rglob("*.py")):
        new = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        prefix = max((p for p in old_of if new == p or new.startswith(p + ".")), key=len, default=None)
        if prefix:
            found.append(old_of[prefix] + new[len(prefix):])
    return found


def resolved(dotted: str):
    """The object a dotted name names: its longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            target = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attribute in parts[cut:]:
            target = getattr(target, attribute)
        return target
    raise ImportError(dotted)


def old_names(text: str) -> set[str]:
    """The paths from before the split ``text`` names, dotted (``hersd.runstore.config_hash``) or as a file
    (``hersd/config.py``)."""
    dotted = set(re.findall(r"hersd(?:\.\w+)+", text))
    files = {name.replace("/", ".").removesuffix(".py") for name in re.findall(r"hersd(?:/\w+)+(?:\.py)?", text)}
    return {name for name in dotted | files if moved_to(name)}


@pytest.mark.filterwarnings("ignore::FutureWarning")
@pytest.mark.parametrize("old", sorted({*DOCUMENTED, *OLD_LOGS, *every_old_module(), *committed_names()}))
def test_an_old_path_gives_the_object_of_its_new_path(old):
    """A module or a name in one is the very object; an old package is a stand-in giving the new package's names."""
    got, new = resolved(old), resolved(moved_to(old))
    if hasattr(new, "__path__"):
        names = [name for name in dir(new) if not name.startswith("__")]
        assert names and all(getattr(got, name) is getattr(new, name) for name in names)
    else:
        assert got is new


def test_an_old_path_warns_naming_its_new_path_and_changes_no_new_package():
    """In a fresh interpreter: a FutureWarning at the importing line for each old path, naming the new one and the
    release that drops it; after ``import hersd.envs`` and its contract child, ``hersd.engine.envs`` holds no
    ``tasks`` (the contract's) and the finder is asked after the path finder (only of names the tree lacks)."""
    code = """import sys, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    import hersd.runlog
    import hersd.envs.tasks
    from hersd.learners import td3
import hersd, hersd.engine.envs, hersd.contract.tasks, hersd.engine.learners.td3
assert hersd.envs.tasks is hersd.contract.tasks and td3 is hersd.engine.learners.td3
assert not hasattr(hersd.engine.envs, "tasks"), "the engine's package was changed"
from importlib.machinery import PathFinder
finder = next(finder for finder in sys.meta_path if type(finder).__name__ == "OldPaths")
assert sys.meta_path.index(finder) > sys.meta_path.index(PathFinder), "asked before the tree's own modules"
for warning in caught:
    print(warning.category.__name__, warning.filename, warning.lineno, warning.message)"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    removed = f"the old path goes in hersd {hersd.OLD_PATHS_REMOVED_IN}"
    moves = [(4, "hersd.runlog", "hersd.contract.runlog"), (5, "hersd.envs", "hersd.engine.envs"),
             (5, "hersd.envs.tasks", "hersd.contract.tasks"), (6, "hersd.learners", "hersd.engine.learners"),
             (6, "hersd.learners.td3", "hersd.engine.learners.td3")]
    assert done.stdout.splitlines() == [f"FutureWarning <string> {line} {old} is {new} now: import {new} ({removed})"
                                        for line, old, new in moves]


def test_a_new_logs_schemas_name_no_old_path():
    """What a new log holds besides its records: its channels' JSON schemas, their descriptions included."""
    assert CHANNELS and not [old_names(schema.decode()) for _name, schema in CHANNELS.values() if
                             old_names(schema.decode())]


def test_the_committed_logs_and_configs_name_no_old_path():
    """The committed logs' schemas name the modules by their new paths: landed again after the change
    (scripts/land.py writes the current schemas, every message unchanged), as the conf YAMLs' ``_target_``s do."""
    assert committed_names() == set()


def test_an_old_path_imported_first_in_a_fresh_interpreter_is_the_module_of_its_new_path():
    code = """import pickle, sys, warnings
warnings.simplefilter("ignore", FutureWarning)
import hersd.schedules.linear as old
from hersd.schedules.base import Schedule
import hersd.contract.schedules.linear as new
assert old is new and new.__spec__.name == "hersd.contract.schedules.linear" and issubclass(new.Linear, Schedule)
assert pickle.loads(b"chersd.schedules.linear\\nLinear\\n.") is new.Linear
files = [module.__file__ for module in set(sys.modules.values()) if getattr(module, "__file__", None)]
assert len(files) == len(set(files)), "a module executed twice"
print("ok")"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.stdout.strip() == "ok", done.stderr


@pytest.mark.filterwarnings("ignore::FutureWarning")
def test_a_schedule_subclassed_through_an_old_path_is_one_of_the_new():
    base = importlib.import_module("hersd.schedules.base")

    class Half(base.Schedule):
        def rate(self, k, total_epochs, train_success=()):
            return 0.5

    assert isinstance(Half(), Schedule) and isinstance(Linear(), base.Schedule)


@pytest.mark.filterwarnings("ignore::FutureWarning")
@pytest.mark.parametrize("target", ["hersd.schedules.linear.Linear", "hersd.contract.schedules.linear.Linear"])
def test_a_schedule_named_by_either_path_keeps_the_runs_folder(target):
    """A run's identity holds the kind a schedule declares, not its module: naming the class by its old or new path
    (a YAML's or a log's ``_target_``) gives the folder ``schedule=linear`` gives."""
    assert schedule_from_config({"_target_": target, "beta1": 0.25}, 200).record()["kind"] == "linear"
    by_path = compose_train(["task=push", "schedule=linear", "schedule.beta1=0.5", f"schedule._target_={target}"])
    by_kind = compose_train(["task=push", "schedule=linear", "schedule.beta1=0.5"])
    assert (run_dir(by_path), config_hash(by_path)) == (run_dir(by_kind), config_hash(by_kind))


def test_a_checkpoint_names_no_module_of_hersd(tmp_path):
    """What a checkpoint pickles (networks, optimisers, buffer, RNG states, MEP's fitted mixture) names torch, numpy
    and scikit-learn only, so a checkpoint written under one layout of hersd resumes under another; the run's new
    log names no old path."""
    from hersd.engine.train import train

    class Stop(Exception):
        pass

    def stop_after_2(record):
        if record["epoch"] == 2:
            raise Stop

    cfg = compose_train([*TINY, "epochs=3", "quiet=true", "threads=1", "algo=her_mep", "learner=td3",
                         f"results_dir={tmp_path}"])
    with pytest.raises(Stop):
        train(cfg, on_epoch=stop_after_2)
    with zipfile.ZipFile(run_dir(cfg) / "checkpoint.pt") as checkpoint:
        data = checkpoint.read(next(name for name in checkpoint.namelist() if name.endswith("data.pkl")))
    globals_ = [arg for op, arg, _ in pickletools.genops(io.BytesIO(data)) if op.name == "GLOBAL"]
    assert globals_ and not [name for name in globals_ if name.split()[0].split(".")[0] == "hersd"], globals_
    assert any(name.startswith("sklearn") for name in globals_)  # MEP's mixture, fitted at epoch 2
    assert not old_names((run_dir(cfg) / "run.mcap").read_bytes().decode("latin-1"))  # a new log names no old path


def test_every_old_module_imports_by_from_its_parent_and_runs_by_python_m():
    """``from hersd.envs import tasks`` (a child whose parent moved elsewhere: hersd.envs went to hersd.engine.envs,
    its tasks to hersd.contract.tasks) as well as ``import hersd.envs.tasks``, in a fresh interpreter; and
    ``python -m`` of an old command module."""
    pairs = [old.rpartition(".") for old in sorted(MOVED) if "." in old]
    code = "\n".join(f"from {parent} import {leaf}" for parent, _, leaf in pairs)
    code += "\nimport hersd.contract.tasks\nassert tasks is hersd.contract.tasks"
    result = subprocess.run([sys.executable, "-c", f"from hersd.envs import tasks\n{code}"], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    shown = subprocess.run([sys.executable, "-m", "hersd.cli", "--help"], capture_output=True, text=True, timeout=300)
    assert shown.returncode == 0 and "hersd-train" in shown.stdout, shown.stderr[-2000:]
