"""A learner of the user's own, in a module outside hersd, with a settings dataclass of its own: by its class
path (``learner._target_``) through training, a sweep and the report, each a fresh process with the module on
PYTHONPATH; and by an entry point of the group ``hersd.learners``."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest
from helpers import TINY, command

from hersd.contract.runlog import read_run

# A user's module: TD3 whose actor waits ``actor_start`` updates, its settings TD3's and that one.
LATE = '''
from dataclasses import dataclass

from hersd.contract.config import ConfigError, TD3Config
from hersd.engine.learners.td3 import TD3


@dataclass
class LateSettings(TD3Config):
    actor_start: int = 4  # the actor steps only after this many updates

    def __post_init__(self):
        super().__post_init__()
        if self.actor_start < 0:
            raise ConfigError(f"learner.td3late.actor_start must be >= 0, got {self.actor_start}")


class TD3Late(TD3):
    SETTINGS = LateSettings

    def actor_step_due(self):
        return super().actor_step_due() and self.update_count > self.td3.actor_start


class RegisteredLate(TD3Late):
    NAME = "late"
'''


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


@pytest.fixture
def user_late(tmp_path, monkeypatch):
    """The user's module importable in this process; forgotten (and its learner unregistered) afterwards."""
    from hersd.engine.learners import LEARNERS

    (tmp_path / "user_late.py").write_text(LATE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    LEARNERS.pop("late", None)
    sys.modules.pop("user_late", None)


def test_a_learner_declared_by_an_entry_point_is_selected_by_its_name(user_late):
    from hersd.contract.config import TrainConfig

    dist = user_late / "user_late-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: user-late\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[hersd.learners]\nlate = user_late:RegisteredLate\n")
    learner = TrainConfig(learner={"name": "late", "late": {"actor_start": 7}}).learner
    assert (learner.name, learner.settings.actor_start, learner.settings.policy_delay) == ("late", 7, 2)


def test_a_setting_the_learner_lacks_is_one_line(user_late):
    from hersd.contract.config import ConfigError, TrainConfig

    with pytest.raises(ConfigError, match=r"^learner\.td3late\.start is not a setting; its settings: policy_noise, "
                                          r"noise_clip, policy_delay, actor_start$"):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3late": {"start": 1}})
    with pytest.raises(ConfigError, match=r"^learner\.td3lat is not a setting of learner user_late\.TD3Late; "):
        TrainConfig(learner={"_target_": "user_late.TD3Late", "td3lat": {"actor_start": 1}})
