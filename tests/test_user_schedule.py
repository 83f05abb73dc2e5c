"""A schedule of the user's own, in a module outside hersd: by its class path (Hydra's ``_target_``
convention) through training, a sweep, a search and the report, each a fresh process with the module
on PYTHONPATH; and by an entry point of the group ``hersd.schedules``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from helpers import TINY, command

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
