"""A schedule of the user's own, in a module outside hersd: by its class path (Hydra's ``_target_``
convention) through training, a sweep, a search and the report, each a fresh process with the module
on PYTHONPATH; and by an entry point of the group ``hersd.schedules``."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import TINY, command
from user_schedules import command as user_command

from hersd.contract.errors import ConfigError
from hersd.contract.runlog import read_run

# A user's module: Step declares no kind, so it is selected and recorded by its path; RegisteredStep is
# the same schedule under the name an entry point gives it.
STEPS = '''
from dataclasses import dataclass

from hersd.contract.schedules import Schedule, param


@dataclass
class Step(Schedule):
    formula = "eps(k) = high for k <= K/2, low after"
    searched = ("low",)

    high: float = param(0.9, 0.0, 1.0, "the rate of the first half")
    low: float = param(0.5, 0.0, 1.0, "the rate of the second half")

    def rate(self, k, total_epochs, train_success=()):
        return self.high if 2 * k <= total_epochs else self.low

    def tag(self):
        return f"step-{self.high:g}_{self.low:g}"

    def label(self):
        return f"step {self.high:g}->{self.low:g}"


@dataclass
class RegisteredStep(Step):
    kind = "step"
'''


def test_a_schedule_outside_the_package_trains_sweeps_is_searched_and_reported(tmp_path):
    (tmp_path / "user_steps.py").write_text(STEPS)
    results = tmp_path / "results"
    run = [*TINY, "epochs=2", f"results_dir={results}", "schedule._target_=user_steps.Step"]
    trained = command("hersd.engine.cli:main", [*run, "schedule.low=0.4", "quiet=true", "threads=1"], tmp_path)
    log = read_run(Path(trained.stdout.strip().splitlines()[-1]))
    assert Path(trained.stdout.strip()).parent.parent.name == "step-0.9_0.4"
    assert log.meta["config"]["schedule"] == {"kind": "user_steps.Step", "high": 0.9, "low": 0.4}
    assert list(log.epochs["relabel_rate"]) == [0.9, 0.4]

    swept = command("sweeps.launch:main", [*run, "seeds=1", "schedule.low=0.3,0.6", "hydra.launcher.n_jobs=1"], tmp_path)
    assert "sweep finished: 2 done" in swept.stdout
    assert (results / "reach" / "her" / "step-0.9_0.3").is_dir() and (results / "reach" / "her" / "step-0.9_0.6").is_dir()

    searched = command("sweeps.search.cli:main", [*TINY, "epochs=2", f"results_dir={results}", "search.n_trials=2",
                                                  "search.space.kinds=[user_steps.Step]"], tmp_path)
    assert "trials: 2 complete" in searched.stdout
    assert len([path for path in (results / "reach" / "her").iterdir() if path.name.startswith("step-")]) == 5

    command("analysis.report:main", [str(results)], tmp_path)
    summary = (results / "report" / "tables" / "summary.md").read_text()
    assert all(f"step 0.9->{low:g}" in summary for low in (0.4, 0.3, 0.6))
    (trials,) = (results / "report" / "search").glob("*_best_trials.csv")
    assert trials.read_text().count("user_steps.Step") == 2  # the study's trials know their kind
    assert "low" in pd.read_csv(trials) and len(list((results / "report" / "search").glob("*_settings.png"))) == 1


def test_a_schedule_declared_by_an_entry_point_is_a_kind(tmp_path, monkeypatch):
    from hersd.contract.config import TrainConfig
    from hersd.contract.schedules import known_kinds

    (tmp_path / "user_steps.py").write_text(STEPS)
    dist = tmp_path / "user_steps-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: user-steps\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[hersd.schedules]\nstep = user_steps:RegisteredStep\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "step" in known_kinds()
    schedule = TrainConfig(schedule={"kind": "step", "low": 0.4}, epochs=4).schedule
    assert list(schedule.epoch_rates(4)) == [0.9, 0.9, 0.4, 0.4]
    assert schedule.record() == {"kind": "step", "high": 0.9, "low": 0.4}


# The schedule's contract with a newcomer's own classes (tests/user_schedules.py), each in a fresh interpreter.

def test_a_rate_outside_0_1_is_refused_in_one_line_before_any_work(tmp_path):
    from user_schedules import MODULE, command, write_module

    refused = command("hersd.engine.cli:main", [*TINY, f"results_dir={tmp_path / 'results'}", f"schedule._target_={MODULE}.Over"],
                      write_module(tmp_path), code=2)
    assert refused.stderr == ("hersd-train: error: schedule over high=1.4 low=0.5 k0=1: its rate at epoch 1 of 200 is "
                              f"1.4, not in [0, 1]; fix {MODULE}.Over.rate\n")
    assert not (tmp_path / "results").exists()


def test_an_adaptive_rate_outside_0_1_stops_its_run_at_that_epoch_keeping_the_finished_ones(tmp_path):
    from user_schedules import MODULE, command, write_module

    results = tmp_path / "results"
    stopped = command("hersd.engine.cli:main", [*TINY, "epochs=3", "quiet=true", "threads=1", f"results_dir={results}",
                                         f"schedule._target_={MODULE}.LateOver"], write_module(tmp_path), code=2)
    assert stopped.stderr.count("\n") == 1 and "its rate at epoch 2 of 3 is 1.4, not in [0, 1]" in stopped.stderr
    (log,) = results.glob("reach/her/lateover/seed0-*/run.mcap")
    assert list(read_run(log).epochs["relabel_rate"]) == [0.9]


def test_an_adaptive_rate_that_raises_stops_its_run_in_one_line_keeping_the_finished_epochs(tmp_path):
    from user_schedules import MODULE, command, write_module

    results = tmp_path / "results"
    stopped = command("hersd.engine.cli:main", [*TINY, "epochs=3", "quiet=true", "threads=1", f"results_dir={results}",
                                         f"schedule._target_={MODULE}.LateRaise"], write_module(tmp_path), code=1)
    (log,) = results.glob("reach/her/lateraise/seed0-*/run.mcap")
    assert stopped.stderr == (f"hersd-train: error: schedule {MODULE}.LateRaise: its rate at epoch 2 of 3 raised "
                              f"ZeroDivisionError: float division by zero; the finished epochs are kept in "
                              f"{log.parent}\n")
    assert list(read_run(log).epochs["relabel_rate"]) == [0.9]


def test_a_subclass_with_a_rate_of_its_own_has_its_own_mean_rate_and_refuses_its_parents_solve():
    """A subclass of exponential whose rate squares eq. 9's: mu_eps is the mean of its own rates, not eq. 10's,
    its limit unknown, and mean_rate (which exponential solves by eq. 10) is one line; a subclass that keeps the
    parent's rate keeps its formulas."""
    from hersd.contract.schedules.exponential import Exponential

    @dataclass
    class Squared(Exponential):
        def rate(self, k, total_epochs, train_success=()):
            return super().rate(k, total_epochs) ** 2

    @dataclass
    class Renamed(Exponential):
        pass

    squared = Squared(beta1=0.5, beta2=0.5)
    assert squared.exact_mean_rate(4) == pytest.approx(np.mean([squared.rate(k, 4) for k in range(1, 5)]))
    assert squared.exact_mean_rate(4) != pytest.approx(Exponential(beta1=0.5, beta2=0.5).exact_mean_rate(4))
    assert squared.limit_mean_rate() is None
    with pytest.raises(ConfigError, match="^schedule.mean_rate: .*Squared has a rate of its own"):
        Squared(beta2=0.5, mean_rate=0.8).resolve(4)
    Squared(beta1=0.5, beta2=0.5).resolve(4)  # nothing to solve: fine
    renamed = Renamed(beta2=0.5, mean_rate=0.8)
    renamed.resolve(4)
    assert renamed.exact_mean_rate(4) == pytest.approx(0.8) and renamed.limit_mean_rate() is not None


def test_tag_and_label_default_to_the_class_name_and_its_settings(tmp_path, monkeypatch):
    from user_schedules import MODULE, write_module

    from hersd.contract.config import TrainConfig
    from hersd.contract.runstore import run_dir

    monkeypatch.syspath_prepend(str(write_module(tmp_path)))
    cfg = TrainConfig(schedule={"_target_": f"{MODULE}.KStep", "low": 0.4, "k0": 3.0}, epochs=4)
    assert (cfg.schedule.tag(), cfg.schedule.label()) == ("kstep-high_0.9-low_0.4-k0_3", "kstep high=0.9 low=0.4 k0=3")
    assert cfg.schedule.record()["k0"] == 3 and isinstance(cfg.schedule.record()["k0"], int)  # 3.0 is 3: one run
    assert run_dir(cfg).parent.name == "kstep-high_0.9-low_0.4-k0_3"


def test_train_help_lists_the_settings_of_the_class_the_command_names(tmp_path):
    from user_schedules import MODULE, command, write_module

    shown = command("hersd.engine.cli:main", [f"schedule._target_={MODULE}.KStep", "--help"], write_module(tmp_path)).stdout
    listed = shown[shown.index(f"  {MODULE}.KStep: eps(k) = high for k <= k0, low after"):]
    assert "schedule.k0=1" in listed and "the last epoch at the high rate" in listed


def test_the_smoke_grid_plans_a_users_schedule_beside_her(tmp_path):
    """The documented way (docs/ARCHITECTURE.md, "Add a schedule"): a preset of one's own in a config folder
    added to Hydra's search path, then swept beside the package's presets."""
    from user_schedules import MODULE, command, write_module

    (tmp_path / "my_conf" / "schedule").mkdir(parents=True)
    (tmp_path / "my_conf" / "schedule" / "kstep.yaml").write_text(f"_target_: {MODULE}.KStep\nk0: 2\n")
    planned = command("sweeps.launch:main", ["+grid=smoke", "schedule=constant,kstep", f"results_dir={tmp_path}",
                                             f"hydra.searchpath=[file://{tmp_path / 'my_conf'}]", "--dry-run"],
                      write_module(tmp_path)).stdout
    assert "sweep: 4 runs" in planned, planned
    for tag in ("constant-0.8", "kstep-high_0.9-low_0.5-k0_2"):
        assert sorted(line.split()[1].rsplit("/", 1)[1][:5] for line in planned.splitlines()
                      if f"/{tag}/" in line) == ["seed0", "seed1"], planned


# A newcomer's schedules that hersd refuses, each in one line before any work: a tag() that is no folder name (or
# raises), settings named as a member of Schedule (schedule.tag would be a number, not the method), and a
# __post_init__ or resolve() raising an error of its own (not ConfigError).
ODD = '''
from dataclasses import dataclass

from hersd.contract.errors import ConfigError
from hersd.contract.schedules import Schedule, param


@dataclass
class Flat(Schedule):
    searched = ("low",)

    low: float = param(0.5, 0.0, 1.0, "the rate")

    def rate(self, k, total_epochs, train_success=()):
        return self.low


@dataclass
class NoTag(Flat):
    def tag(self):
        return None


@dataclass
class EmptyTag(Flat):
    def tag(self):
        return ""


@dataclass
class DotTag(Flat):
    def tag(self):
        return "."


@dataclass
class UpTag(Flat):
    def tag(self):
        return ".."


@dataclass
class Escapes(Flat):
    def tag(self):
        return "../../x"


@dataclass
class Backslash(Flat):
    def tag(self):
        return "a\\\\b"


@dataclass
class NulTag(Flat):
    def tag(self):
        return "a\\0b"


@dataclass
class LongTag(Flat):
    def tag(self):
        return "x" * 256


@dataclass
class TagRaises(Flat):
    def tag(self):
        raise ValueError("no tag\\nfor this")


@dataclass
class TagSetting(Flat):
    tag: float = param(0.5, 0.0, 1.0, "a setting named as the folder method")


@dataclass
class LabelSetting(Flat):
    label: float = param(0.5, 0.0, 1.0, "a setting named as the report's method")


@dataclass
class TitleSetting(Flat):
    title: float = param(0.5, 0.0, 1.0, "a setting named as the report's panel title")


@dataclass
class SettingsField(Flat):
    settings: int = 3


@dataclass
class AnnotatedTitle(Flat):
    title: str = "Flat, annotated"  # a plain field over a class attribute: read as the class's, no setting


@dataclass
class PostValue(Flat):
    def __post_init__(self):
        super().__post_init__()
        if self.low > 0.3:
            raise ValueError("low must be <= 0.3")


@dataclass
class PostConfig(Flat):
    def __post_init__(self):
        super().__post_init__()
        raise ConfigError("schedule.low: the user's own line")


@dataclass
class ResolveValue(Flat):
    def resolve(self, total_epochs):
        raise ValueError("cannot resolve for %d epochs" % total_epochs)
'''


@pytest.fixture
def user_odd(tmp_path, monkeypatch):
    """The module ``user_odd`` importable in this process (ODD); forgotten afterwards."""
    (tmp_path / "user_odd.py").write_text(ODD)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("user_odd", None)


NO_FOLDER = ("not a folder name; fix user_odd.{0}.tag to return a non-empty name of printable characters without / "
             "or \\, not . or .., of at most 255 bytes")


@pytest.mark.parametrize("name, shown", [("NoTag", "None, a NoneType"), ("EmptyTag", "''"), ("DotTag", "'.'"),
                                         ("UpTag", "'..'"), ("Escapes", "'../../x'"), ("Backslash", "'a\\\\b'"),
                                         ("NulTag", "'a\\x00b'"), ("LongTag", repr("x" * 256))])
def test_a_tag_that_is_no_plain_folder_name_is_one_line(user_odd, name, shown):
    """tag() names the level <task>/<algo>/<tag>/ of the run store: None was a traceback in run_dir, '' or '..' or
    '../../x' filed the run elsewhere in (or outside) the results folder."""
    from hersd.contract.config import TrainConfig

    with pytest.raises(ConfigError) as refused:
        TrainConfig(schedule={"_target_": f"user_odd.{name}"}, epochs=2)
    assert str(refused.value) == f"schedule user_odd.{name}: tag() returned {shown}, {NO_FOLDER.format(name)}"


def test_a_tag_that_raises_is_one_line(user_odd):
    from hersd.contract.config import TrainConfig

    with pytest.raises(ConfigError, match=r"^schedule user_odd\.TagRaises: tag\(\) raised ValueError: no tag for "
                                          r"this$"):
        TrainConfig(schedule={"_target_": "user_odd.TagRaises"}, epochs=2)


def test_train_sweep_and_search_refuse_a_tag_in_one_line_before_any_work(tmp_path):
    (tmp_path / "user_odd.py").write_text(ODD)
    results = tmp_path / "results"
    run = [*TINY, "epochs=1", f"results_dir={results}"]
    trained = user_command("hersd.engine.cli:main", [*run, "schedule._target_=user_odd.NoTag"], tmp_path, code=2)
    assert trained.stderr == f"hersd-train: error: schedule user_odd.NoTag: tag() returned None, a NoneType, " \
                             f"{NO_FOLDER.format('NoTag')}\n"
    swept = user_command("sweeps.launch:main", [*run, "seeds=1", "schedule._target_=user_odd.Escapes"], tmp_path, code=2)
    assert swept.stderr.count("\n") == 1 and swept.stderr.startswith("hersd-sweep: error: ")
    assert swept.stderr.endswith(f"schedule user_odd.Escapes: tag() returned '../../x', {NO_FOLDER.format('Escapes')}\n")
    searched = user_command("sweeps.search.cli:main", [*run, "search.n_trials=1", "search.space.kinds=[user_odd.TagRaises]"],
                            tmp_path, code=2)
    assert searched.stderr.count("\n") == 1 and searched.stderr.startswith("hersd-search: error: ")
    assert searched.stderr.endswith("schedule user_odd.TagRaises: tag() raised ValueError: no tag for this\n")
    assert not results.exists() and not (tmp_path / "x").exists()


def test_a_search_refuses_a_range_end_its_post_init_raises_on_in_one_line(tmp_path):
    """The search builds each searched kind at both ends of its ranges before any trial: low=1.0 raises."""
    (tmp_path / "user_odd.py").write_text(ODD)
    run = [*TINY, "epochs=1", f"results_dir={tmp_path / 'results'}", "search.n_trials=1"]
    searched = user_command("sweeps.search.cli:main", [*run, "search.space.kinds=[user_odd.PostValue]"], tmp_path, code=2)
    assert searched.stderr.count("\n") == 1 and searched.stderr.startswith("hersd-search: error: ")
    assert searched.stderr.endswith("schedule user_odd.PostValue: its settings refused schedule.low=1.0: ValueError: "
                                    "low must be <= 0.3\n")
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("name, member, what, used", [("TagSetting", "tag", "setting", "calls"),
                                                      ("LabelSetting", "label", "setting", "calls"),
                                                      ("TitleSetting", "title", "setting", "reads"),
                                                      ("SettingsField", "settings", "field", "calls")])
def test_a_setting_named_as_a_member_of_schedule_is_one_line_saying_to_rename_it(user_odd, name, member, what, used):
    """A setting named tag was a traceback ('float' object is not callable); one named label trained, and
    hersd-report then found none of its logs readable, saying no more."""
    from hersd.contract.schedules import schedule_class

    with pytest.raises(ConfigError) as refused:
        schedule_class(f"user_odd.{name}")
    assert str(refused.value) == (f"schedule user_odd.{name}: its {what} {member} shadows Schedule.{member}, which "
                                  f"hersd {used}; rename the {what}")
    assert schedule_class("user_odd.AnnotatedTitle").title == "Flat, annotated"  # no setting, no method: as before


def test_train_refuses_a_setting_named_label_before_any_work(tmp_path):
    (tmp_path / "user_odd.py").write_text(ODD)
    results = tmp_path / "results"
    refused = user_command("hersd.engine.cli:main", [*TINY, "epochs=1", f"results_dir={results}",
                                                     "schedule._target_=user_odd.LabelSetting"], tmp_path, code=2)
    assert refused.stderr == ("hersd-train: error: schedule user_odd.LabelSetting: its setting label shadows "
                              "Schedule.label, which hersd calls; rename the setting\n")
    assert not results.exists()


def test_an_error_of_its_own_in_post_init_or_resolve_is_one_line_naming_the_schedule(user_odd):
    """A ValueError in a schedule's __post_init__ or resolve() was a traceback (exit 1); a ConfigError passes as
    the user wrote it."""
    from hersd.contract.config import TrainConfig

    with pytest.raises(ConfigError) as refused:
        TrainConfig(schedule={"_target_": "user_odd.PostValue", "low": 0.4}, epochs=2)
    assert str(refused.value) == ("schedule user_odd.PostValue: its settings refused schedule.low=0.4: ValueError: "
                                  "low must be <= 0.3")
    with pytest.raises(ConfigError, match=r"^schedule user_odd\.PostValue: its settings refused their defaults: "):
        TrainConfig(schedule={"_target_": "user_odd.PostValue"}, epochs=2)
    assert TrainConfig(schedule={"_target_": "user_odd.PostValue", "low": 0.2}, epochs=2).schedule.low == 0.2
    with pytest.raises(ConfigError, match=r"^schedule\.low: the user's own line$"):
        TrainConfig(schedule={"_target_": "user_odd.PostConfig"}, epochs=2)
    with pytest.raises(ConfigError, match=r"^schedule user_odd\.ResolveValue: resolve\(\) raised ValueError: cannot "
                                          r"resolve for 2 epochs$"):
        TrainConfig(schedule={"_target_": "user_odd.ResolveValue"}, epochs=2)


def test_train_refuses_a_post_init_error_in_one_line_before_any_work(tmp_path):
    (tmp_path / "user_odd.py").write_text(ODD)
    results = tmp_path / "results"
    refused = user_command("hersd.engine.cli:main", [*TINY, "epochs=1", f"results_dir={results}",
                                                     "schedule._target_=user_odd.PostValue", "schedule.low=0.4"],
                           tmp_path, code=2)
    assert refused.stderr == ("hersd-train: error: schedule user_odd.PostValue: its settings refused schedule.low=0.4: "
                              "ValueError: low must be <= 0.3\n")
    assert not results.exists()
