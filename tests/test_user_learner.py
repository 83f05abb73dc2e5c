"""A learner of the user's own, in a module outside hersd, with a settings dataclass of its own: by its class
path (``learner._target_``) through training, a sweep and the report, each a fresh process with the module on
PYTHONPATH; and by an entry point of the group ``hersd.learners``."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest
from helpers import TINY, command
from user_learners import LATE

from hersd.contract.errors import ConfigError
from hersd.contract.runlog import read_run


def test_a_learner_outside_the_package_trains_sweeps_and_is_reported(tmp_path):
    (tmp_path / "user_late.py").write_text(LATE)
    results = tmp_path / "results"
    run = [*TINY, "epochs=1", f"results_dir={results}", "learner._target_=user_late.TD3Late", "threads=1"]
    trained = command("hersd.engine.cli:main", [*run, "learner.td3late.actor_start=2", "quiet=true"], tmp_path)
    log_path = Path(trained.stdout.strip().splitlines()[-1])
    assert log_path.parent.parent.parent.name == "td3late-her"
    settings = {"policy_noise": 0.2, "noise_clip": 0.5, "policy_delay": 2, "actor_start": 2}
    assert read_run(log_path).meta["config"]["learner"] == {"name": "user_late.TD3Late", "user_late.TD3Late": settings}

    command("sweeps.launch:main", [*run, "seeds=1", "learner.td3late.actor_start=2,3", "hydra.launcher.n_jobs=1"],
            tmp_path)
    assert len(list(results.glob("reach/td3late-her/*/seed0-*/run.mcap"))) == 2  # actor_start=2 was done: skipped

    command("analysis.report:main", [str(results)], tmp_path)
    runs = pd.read_csv(results / "report" / "tables" / "runs.csv")
    assert list(runs["learner"]) == ["user_late.TD3Late"] * 2 and runs["complete"].all()
    assert all(label.startswith("TD3Late HER") for label in runs["config"])  # its class name, not its path
    assert sorted(label.rpartition(" (")[2] for label in runs["config"]) == \
        ["learner.td3late.actor_start=2)", "learner.td3late.actor_start=3)"]  # the settings as one types them


@pytest.fixture
def user_late(tmp_path, monkeypatch):
    """The user's module importable in this process; forgotten (and its learner unregistered) afterwards."""
    from hersd.engine.learners import LEARNERS

    (tmp_path / "user_late.py").write_text(LATE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    LEARNERS.pop("late", None)
    sys.modules.pop("user_late", None)


def declare_entry_point(folder: Path) -> None:
    """An installed distribution in ``folder`` declaring RegisteredLate as the learner ``late``."""
    dist = folder / "user_late-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: user-late\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[hersd.learners]\nlate = user_late:RegisteredLate\n")


def test_a_learner_declared_by_an_entry_point_is_selected_by_its_name(user_late):
    from hersd.contract.config import TrainConfig

    declare_entry_point(user_late)
    learner = TrainConfig(learner={"name": "late", "late": {"actor_start": 7}}).learner
    assert (learner.name, learner.settings.actor_start, learner.settings.policy_delay) == ("late", 7, 2)


def test_a_learner_declared_by_an_entry_point_is_a_choice_of_the_learner_group(user_late):
    """``learner=late`` as ``learner=td3``: in hersd-train (and its --help) and in a sweep beside DDPG."""
    from hydra.core.config_store import ConfigStore

    from hersd.engine.cli import usage
    from hersd.contract.compose import compose_train

    declare_entry_point(user_late)
    try:
        learner = compose_train(["task=reach", "learner=late", "learner.late.actor_start=7"]).learner
        assert (learner.name, learner.settings.actor_start) == ("late", 7)
        assert "  learner=ddpg|late|sac|td3" in usage().splitlines()
    finally:
        ConfigStore.instance().repo["learner"].pop("late.yaml", None)  # the entry point leaves with the folder
    swept = command("sweeps.launch:main", ["task=reach", "seeds=1", "learner=ddpg,late", "--dry-run",
                                           f"results_dir={user_late / 'results'}"], user_late)
    assert [line.split()[1].split("/")[-3] for line in swept.stdout.splitlines() if line.startswith("  new ")] == [
        "her", "late-her"]


def test_a_class_given_as_a_learner_choice_is_one_line_saying_what_to_type(user_late, monkeypatch, capsys):
    """``learner=<module>.<Class>`` names no config of the group: hersd-train, hersd-sweep and hersd-search each
    say in one line (exit 2) what selects it, and what they say does."""
    from hersd.engine.cli import main as train_main
    from sweeps.launch import main as sweep_main
    from sweeps.search.cli import main as search_main

    def one_line(run) -> str:
        with pytest.raises(SystemExit) as end:
            run()
        err = capsys.readouterr().err
        assert end.value.code == 2 and err.count("\n") == 1, err
        return err.strip()

    said = "names a class, which no config of the learner group holds; type"
    assert one_line(lambda: train_main(["task=reach", "learner=user_late.TD3Late"])) == (
        f"hersd-train: error: learner=user_late.TD3Late {said} learner._target_=user_late.TD3Late")
    assert one_line(lambda: search_main(["task=reach", "learner=user_late.TD3Late"])) == (
        f"hersd-search: error: learner=user_late.TD3Late {said} learner._target_=user_late.TD3Late")
    monkeypatch.setattr(sys, "argv", ["hersd-sweep", "task=reach", "learner=ddpg,user_late.TD3Late"])
    assert one_line(sweep_main) == (
        f"hersd-sweep: error: learner=ddpg,user_late.TD3Late {said} learner.name=ddpg,user_late.TD3Late")
    assert one_line(lambda: train_main(["task=reach", "learner=mytd3"])) == (
        "hersd-train: error: learner=mytd3 is not a known learner; choose one of: ddpg, sac, td3, "
        "or a class of your own: learner._target_=<module>.<Class>")

    swept = command("sweeps.launch:main", ["task=reach", "seeds=1", "learner.name=ddpg,user_late.TD3Late",
                                           "--dry-run", f"results_dir={user_late / 'results'}"], user_late)
    assert [line.split()[1].split("/")[-3] for line in swept.stdout.splitlines() if line.startswith("  new ")] == [
        "her", "td3late-her"]


def test_a_setting_the_learner_lacks_is_one_line(user_late):
    from hersd.contract.config import TrainConfig
    from hersd.contract.errors import ConfigError

    with pytest.raises(ConfigError, match=r"^learner\.td3late\.start is not a setting; its settings: policy_noise, "
                                          r"noise_clip, policy_delay, actor_start$"):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3late": {"start": 1}})
    with pytest.raises(ConfigError, match=r"^learner\.td3lat is not a setting of learner user_late\.TD3Late; "):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3lat": {"actor_start": 1}})


def test_train_help_lists_the_settings_of_the_learner_the_command_names(user_late, capsys):
    """``learner._target_=<module>.<Class> --help``: its settings under its own key, the inherited ones with their
    parent's documentation; a learner that cannot be found is one line and exit 2."""
    from hersd.engine.cli import main as train_main

    train_main(["learner._target_=user_late.TD3Late", "--help"])
    shown = capsys.readouterr().out.split("learners named on the command line (their settings):\n")[1].splitlines()
    assert shown[0] == "  user_late.TD3Late:"
    assert shown[1].split() == ["learner.td3late.policy_noise=0.2", "std", "of", "the", "Gaussian", "noise", "on",
                                "target", "actions,", "as", "a", "share", "of", "max", "action"]
    assert shown[4].split()[:2] == ["learner.td3late.actor_start=4", "the"]
    with pytest.raises(SystemExit) as ended:
        train_main(["learner._target_=nosuch.X", "--help"])
    assert ended.value.code == 2 and capsys.readouterr().err.startswith("hersd-train: error: learner class nosuch.X")


def test_train_help_lists_a_learner_config_of_ones_own_and_its_settings(user_late, capsys):
    """``learner=mylate hydra.searchpath=[file://<folder>]``, the route docs/LEARNERS.md gives for a learner of
    one's own beside the package's in a sweep: --help said "learner='mylate' is unknown"."""
    from hersd.engine.cli import main as train_main

    (user_late / "conf" / "learner").mkdir(parents=True)
    (user_late / "conf" / "learner" / "mylate.yaml").write_text("_target_: user_late.TD3Late\ntd3late: {actor_start: 2}\n")
    train_main(["learner=mylate", f"hydra.searchpath=[file://{user_late / 'conf'}]", "--help"])
    out = capsys.readouterr().out
    assert "|mylate|" in next(line for line in out.splitlines() if line.startswith("  learner="))
    shown = out.split("learners named on the command line (their settings):\n")[1].splitlines()
    assert shown[0] == "  user_late.TD3Late:" and any(line.split()[0] == "learner.td3late.actor_start=4"
                                                      for line in shown[1:])


def test_a_class_chosen_by_its_path_that_declares_a_name_nothing_finds_is_refused(user_late):
    """RegisteredLate declares NAME = "late": chosen by its path its logs would record "late", which a fresh
    process (hersd-render of its runs) finds only through its entry point."""
    from hersd.contract.learner_registry import learner_class

    with pytest.raises(ConfigError, match=r"^learner user_late\.RegisteredLate declares NAME='late', which a later"):
        learner_class("user_late.RegisteredLate")
    assert learner_class("user_late.TD3Late").__name__ == "TD3Late"  # no NAME: recorded by its path
    assert learner_class("hersd.engine.learners.td3.TD3").NAME == "td3"  # the package's, found by its name
    declare_entry_point(user_late)
    assert learner_class("user_late.RegisteredLate").__name__ == "RegisteredLate"


# A TD3 subclass whose settings do not extend TD3's: TD3's code (target_action) reads policy_noise from them.
LATE_ONLY = '''

@dataclass
class LateOnly:
    actor_start: int = 4


class TD3LateOnly(TD3):
    SETTINGS = LateOnly
'''


def test_a_td3_subclass_reads_its_own_key_only_and_its_range_errors_name_it(user_late):
    """learner.td3.* beside a TD3 subclass would be checked and left out (it trains at its own key's values): it is
    refused in one line; TD3's range checks name the subclass's key. A sweep's other learners' sections still pass."""
    from hersd.contract.config import TrainConfig

    with pytest.raises(ConfigError, match=r"^learner user_late\.TD3Late reads learner\.td3late\.\*, not "
                                          r"learner\.td3\.\*"):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3": {"policy_delay": 5}})
    with pytest.raises(ConfigError, match=r"^learner\.td3late\.policy_delay must be >= 1, got 0$"):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3late": {"policy_delay": 0}})
    with pytest.raises(ConfigError, match=r"^learner\.td3late\.noise_clip must be a number in \[0, "):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3late": {"noise_clip": -1.0}})
    with pytest.raises(ConfigError, match=r"^learner\.td3\.policy_delay must be >= 1, got 0$"):
        TrainConfig(learner={"name": "td3", "td3": {"policy_delay": 0}})
    for name in ("ddpg", "sac", "td3"):  # a sweep over learner.name=ddpg,sac,td3 carries every section
        learner = TrainConfig(learner={"name": name, "td3": {"policy_delay": 5}, "sac": {"init_alpha": 0.5}}).learner
        assert learner.name == name and (name != "td3" or learner.settings.policy_delay == 5)
    sweep = ["task=reach", "seeds=1", "learner.name=ddpg,td3", "learner.td3.policy_delay=5", "--dry-run"]
    swept = command("sweeps.launch:main", [*sweep, f"results_dir={user_late / 'results'}"], user_late)
    assert [line.split()[1].split("/")[-3] for line in swept.stdout.splitlines() if line.startswith("  new ")] == [
        "her", "td3-her"]


def test_a_subclass_whose_settings_do_not_extend_its_parents_is_refused_before_any_run(user_late, capsys):
    """TD3LateOnly's SETTINGS lacks TD3's: it used to pass every check and stop mid-run (AttributeError in td3.py),
    leaving a run folder."""
    from hersd.contract.config import TrainConfig
    from hersd.engine.cli import main as train_main

    (user_late / "user_late.py").write_text(LATE + LATE_ONLY)
    with pytest.raises(ConfigError, match=r"^learner user_late\.TD3LateOnly extends TD3, whose code reads TD3Config: "
                                          r"its SETTINGS \(LateOnly\) must be TD3Config or a subclass of it"):
        TrainConfig(learner={"_target_": "user_late.TD3LateOnly"})
    results = user_late / "results"
    with pytest.raises(SystemExit) as ended:
        train_main([*TINY, "epochs=1", f"results_dir={results}", "learner._target_=user_late.TD3LateOnly"])
    err = capsys.readouterr().err
    assert ended.value.code == 2 and err.count("\n") == 1 and "must be TD3Config or a subclass" in err
    assert not results.exists()


def test_settings_of_your_own_learner_beside_ddpg_say_ddpg_has_none_and_what_to_do(user_late):
    """``learner.name=ddpg,user_late.TD3Late learner.td3late.actor_start=2``: the ddpg run has no settings (it used to
    say "its settings: learner.ddpg.*"); the line names the learner config of your own that sweeps them."""
    from hersd.contract.config import TrainConfig

    with pytest.raises(ConfigError, match=r"^learner ddpg has no settings, so learner\.td3late\.\* sets nothing; .*"
                                          r"<folder>/learner/<choice>\.yaml holding _target_: <module>\.<Class> and "
                                          r"td3late: .*hydra\.searchpath=\[file:///<folder>\] learner=ddpg,<choice>"):
        TrainConfig(learner={"name": "ddpg", "td3late": {"actor_start": 2}})


# A learner whose settings check themselves with an error of their own (not ConfigError), and with a ConfigError.
LATE_CHECKED = '''

@dataclass
class CheckedSettings(TD3Config):
    x: int = 0

    def __post_init__(self):
        super().__post_init__()
        if self.x >= 1:
            raise ValueError("x must be\\n< 1")
        if self.x < -5:
            raise ConfigError(f"learner.checkedlate.x must be >= -5, got {self.x}")


class CheckedLate(TD3):
    SETTINGS = CheckedSettings


@dataclass
class NeverSettings(TD3Config):
    def __post_init__(self):
        raise RuntimeError("not today")


class NeverLate(TD3):
    SETTINGS = NeverSettings
'''


def test_an_error_of_its_own_in_the_settings_check_is_one_line_naming_the_learner(user_late, capsys):
    """A ValueError in the settings' __post_init__ was a traceback (exit 1); a ConfigError passes as written."""
    from hersd.contract.config import TrainConfig
    from hersd.engine.cli import main as train_main

    (user_late / "user_late.py").write_text(LATE + LATE_CHECKED)
    with pytest.raises(ConfigError) as refused:
        TrainConfig(learner={"_target_": "user_late.CheckedLate", "checkedlate": {"x": 2, "policy_delay": 3}})
    assert str(refused.value) == ("learner user_late.CheckedLate: its settings refused learner.checkedlate.x=2 "
                                  "learner.checkedlate.policy_delay=3: ValueError: x must be < 1")
    with pytest.raises(ConfigError, match=r"^learner\.checkedlate\.x must be >= -5, got -9$"):
        TrainConfig(learner={"_target_": "user_late.CheckedLate", "checkedlate": {"x": -9}})
    with pytest.raises(ConfigError, match=r"^learner user_late\.NeverLate: its settings refused their defaults: "
                                          r"RuntimeError: not today$"):
        TrainConfig(learner={"_target_": "user_late.NeverLate"})
    assert TrainConfig(learner={"_target_": "user_late.CheckedLate", "checkedlate": {"x": 0}}).learner.settings.x == 0

    results = user_late / "results"
    with pytest.raises(SystemExit) as ended:
        train_main([*TINY, "epochs=1", f"results_dir={results}", "learner._target_=user_late.CheckedLate",
                    "learner.checkedlate.x=2"])
    assert ended.value.code == 2 and capsys.readouterr().err == (
        "hersd-train: error: learner user_late.CheckedLate: its settings refused learner.checkedlate.x=2: ValueError: "
        "x must be < 1\n")
    assert not results.exists()


NAMED = '''

class Name(TD3):
    SETTINGS = LateSettings
'''

# Settings whose module resolves annotations lazily and imports one type for type checkers only.
HINTED = '''
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

from hersd.contract.learners.td3 import TD3Config
from hersd.engine.learners.td3 import TD3

if TYPE_CHECKING:
    from pathlib import Path


@dataclass
class HintedSettings(TD3Config):
    actor_start: int = 4
    notes: Optional[Path] = None


class Hinted(TD3):
    SETTINGS = HintedSettings
'''


def test_a_learner_whose_settings_key_would_be_learners_own_is_refused_in_one_line(user_late):
    """A class named Name would read learner.name.*, which is the learner's name: it could never be set."""
    from hersd.contract.config import TrainConfig

    (user_late / "user_late.py").write_text(LATE + NAMED)
    with pytest.raises(ConfigError, match=r"^learner user_late\.Name: its settings would be learner\.name\.\*, "
                                          r"which is learner's own key; rename the class or give it NAME"):
        TrainConfig(learner={"_target_": "user_late.Name"})


def test_one_annotation_that_does_not_resolve_leaves_the_other_settings_typed(tmp_path, monkeypatch):
    """Path is imported for type checkers only, so notes' annotation does not resolve: actor_start is still an
    int setting (2.0 is 2: one run folder; a word is one line), and notes is left to the class."""
    from hersd.contract.config import TrainConfig

    (tmp_path / "user_hinted.py").write_text(HINTED)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        settings = TrainConfig(learner={"_target_": "user_hinted.Hinted", "hinted": {"actor_start": 2.0}}).learner.settings
        assert settings.actor_start == 2 and isinstance(settings.actor_start, int)
        with pytest.raises(ConfigError, match=r"^learner\.hinted\.actor_start must be a whole number, got 'abc'$"):
            TrainConfig(learner={"_target_": "user_hinted.Hinted", "hinted": {"actor_start": "abc"}})
        assert TrainConfig(learner={"_target_": "user_hinted.Hinted",
                                    "hinted": {"notes": "x"}}).learner.settings.notes == "x"
    finally:
        sys.modules.pop("user_hinted", None)
