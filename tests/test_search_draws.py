"""What a search draws, checked before and during it: the start check over the searched box (its corners and a grid),
a draw that still gives no schedule pruned in one line, ranges in Hydra's own dict syntax, failed trials in one line
each, a class's field without param() refused, rates in messages rounded."""

from __future__ import annotations

import logging
import re
import sys

import optuna
import pytest
from optuna.trial import TrialState
from searches import fails_with, load, only_db, tiny_search
from user_schedules import CRASH_MODULE, MODULE, command, write_module

from hersd.contract.errors import ConfigError
from hersd.contract.schedules import schedule_class
from hersd.contract.schedules.base import ScheduleRateError
from sweeps.search import cli
from sweeps.search.config import compose_search
from sweeps.search.plan import make_plan
from sweeps.search.space import Bounds, axis_values
from sweeps.search.storage import open_storage
from sweeps.search.study import open_study

DRAWS = "search_draws"
# Ramp leaves [0, 1] only at the box's corner (drop=1, k_step=1), neither at its all-low nor all-high ends; Hump
# inside it (drop near 0.5), at neither corner; Spike in a sliver (drop within 1e-7 of 0.123456789) no grid meets;
# Drop's rate at drop=0.95 is 0.9 - 0.95 (-0.04999999999999993); Plain has a field made without param().
SOURCE = '''
from dataclasses import dataclass

from hersd.contract.schedules import Schedule, param


@dataclass
class Ramp(Schedule):
    searched = ("drop", "k_step")

    drop: float = param(0.5, 0.0, 1.0, "the drop")
    k_step: int = param(2, 1, 3, "its divisor", integer=True)

    def rate(self, k, total_epochs, train_success=()):
        return 0.9 - 1.1 * self.drop * (k / total_epochs) / self.k_step


@dataclass
class Hump(Schedule):
    searched = ("drop",)

    drop: float = param(0.0, 0.0, 1.0, "the hump's place")

    def rate(self, k, total_epochs, train_success=()):
        return 1.0 - 4.8 * self.drop * (1.0 - self.drop) * k / total_epochs


@dataclass
class Spike(Schedule):
    searched = ("drop",)

    drop: float = param(0.5, 0.0, 1.0, "anything but 0.123456789")

    def rate(self, k, total_epochs, train_success=()):
        return -0.5 if abs(self.drop - 0.123456789) < 1e-7 else 0.9


@dataclass
class Drop(Schedule):
    drop: float = param(0.5, 0.0, 1.0, "the drop")

    def rate(self, k, total_epochs, train_success=()):
        return 0.9 - self.drop


@dataclass
class Plain(Schedule):
    searched = ("low",)

    low: float = param(0.5, 0.0, 1.0, "the rate")
    width: int = 3

    def rate(self, k, total_epochs, train_success=()):
        return self.low
'''


@pytest.fixture
def draws(tmp_path, monkeypatch):
    """The module ``search_draws`` importable here; forgotten afterwards."""
    (tmp_path / f"{DRAWS}.py").write_text(SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop(DRAWS, None)


def test_the_start_check_names_a_corner_of_the_box_neither_end_reaches(draws, tmp_path, capsys) -> None:
    """drop in [0, 1] and k_step in [1, 3] passed (the all-low and all-high ends); a trial then drew k_step=1 with a
    drop near 1, a rate below 0, and stopped the search after trials had completed."""
    err = fails_with([f"search.space.kinds=[{DRAWS}.Ramp]", "search.n_trials=1", "search.pruner.kind=none",
                      *tiny_search(tmp_path / "results")], capsys)
    assert err == (f"hersd-search: error: search.space: {DRAWS}.Ramp at drop=1, k_step=1, within the searched ranges: "
                   "schedule ramp drop=1 k_step=1: its rate at epoch 4 of 4 is -0.2, not in [0, 1]; fix "
                   f"{DRAWS}.Ramp.rate; narrow search.space.ranges to settings it accepts together\n")
    assert not (tmp_path / "results").exists()  # before any study or trial


@pytest.mark.parametrize("given, shown", [("{low: 0, high: 3}", "low=0: schedule.k_step must be a whole number in "
                                                                 "[1, 3], got 0"),
                                          ("{low: 1, high: 1e9}", "high=1000000000: schedule.k_step must be a whole "
                                                                  "number in [1, 3], got 1000000000")])
def test_a_whole_number_range_outside_is_said_as_given(given, shown, draws, tmp_path, capsys) -> None:
    """The typed range holds 0 as 0.0: the message said "k_step.low=0.0 ... got 0.0" for the 0 the user typed."""
    err = fails_with([f"search.space.kinds=[{DRAWS}.Ramp]", f"search.space.ranges.k_step={given}",
                      *tiny_search(tmp_path / "results")], capsys)
    assert err == f"hersd-search: error: search.space.ranges.k_step.{shown}\n"


@pytest.mark.parametrize("given, said", [
    ("search.enqueue=[{drop: 0.123456789}]", "search.enqueue[0]: schedule spike drop=0.123457: its rate at epoch 1 "
                                              "of 4 is -0.5, not in [0, 1]; fix search_draws.Spike.rate, or change "
                                              "search.enqueue[0]"),
    ("search.space.ranges.drop={low: 0.123456789, high: 0.5}", "search.space (search_draws.Spike, low ends): schedule "
     "spike drop=0.123457: its rate at epoch 1 of 4 is -0.5, not in [0, 1]; fix search_draws.Spike.rate, or change "
     "search.space.ranges")])
def test_a_rate_outside_at_the_given_settings_names_them_as_a_remedy(given, said, draws, tmp_path, capsys) -> None:
    """Spike's rate leaves [0, 1] at one setting only: changing the enqueued set or the range mends it as well."""
    err = fails_with([f"search.space.kinds=[{DRAWS}.Spike]", given, *tiny_search(tmp_path / "results")], capsys)
    assert err == f"hersd-search: error: {said}\n"


def test_the_start_check_finds_a_combination_inside_the_box(draws, tmp_path, capsys) -> None:
    err = fails_with([f"search.space.kinds=[{DRAWS}.Hump]", "search.n_trials=1", "search.pruner.kind=none",
                      *tiny_search(tmp_path / "results")], capsys)
    drop = float(re.search(rf"{DRAWS}\.Hump at drop=([0-9.]+), within the searched ranges: ", err).group(1))
    assert 4.8 * drop * (1 - drop) > 1 and "not in [0, 1]" in err  # the named point is one that leaves [0, 1]
    # narrowed to where it holds, the same search passes the check
    make_plan(compose_search("default", [f"search.space.kinds=[{DRAWS}.Hump]", "search.space.ranges.drop={low: 0, "
                                         "high: 0.25}"]), tiny_search(tmp_path / "results"))


def test_the_grid_takes_whole_numbers_at_their_values_and_the_ends_exactly() -> None:
    assert axis_values(Bounds(1, 3), whole=True, count=5) == [1, 2, 3]
    assert axis_values(Bounds(1.5, 9.5), whole=True, count=3) == [2, 6, 9]
    assert axis_values(Bounds(1, 10_000), whole=True, count=4) == [1, 3334, 6667, 10_000]
    assert axis_values(Bounds(0.1, 0.7), whole=False, count=3) == pytest.approx([0.1, 0.4, 0.7])
    assert axis_values(Bounds(0.01, 1.0, log=True), whole=False, count=3) == pytest.approx([0.01, 0.1, 1.0])


def test_a_draw_that_still_gives_no_schedule_is_pruned_in_one_line_and_the_search_goes_on(draws, tmp_path,
                                                                                         caplog) -> None:
    """Spike passes the start check (its sliver lies between the grid's points); its draw there was Optuna's
    "The value nan is not acceptable" and the search's end with exit 2."""
    args = [f"search.space.kinds=[{DRAWS}.Spike]", "search.n_trials=2", "search.pruner.kind=none", "threads=1",
            *tiny_search(tmp_path, epochs=1)]
    plan = make_plan(compose_search("default", args[:3]), args[3:])
    study = open_study(plan, open_storage(plan.storage))
    study.enqueue_trial({"drop": 0.123456789})  # as if TPE drew it
    optuna.logging.enable_propagation()  # Optuna's lines to caplog
    try:
        with caplog.at_level(logging.INFO, logger="optuna"):
            cli.main(args)
    finally:
        optuna.logging.disable_propagation()
    spiked, drawn = load(only_db(tmp_path)).trials
    assert spiked.state == TrialState.PRUNED and drawn.state == TrialState.COMPLETE
    reason = spiked.user_attrs["pruned_reason"]
    assert reason.startswith("no schedule at kind=search_draws.Spike, drop=0.123457: schedule spike drop=0.123457: "
                             "its rate at epoch 1 of 1 is -0.5, not in [0, 1]")
    (line,) = {record.getMessage() for record in caplog.records if "Trial 0 " in record.getMessage()}
    assert line == f"Trial 0 pruned. {reason}" and "\n" not in line
    assert "value nan" not in caplog.text


def test_ranges_in_hydras_own_dict_syntax(tmp_path) -> None:
    write_module(tmp_path)
    sys.path.insert(0, str(tmp_path))
    try:
        for given in ("search.space.ranges.k0={low:1,high:2}", "+search.space.ranges.k0={low: 1, high: 2}",
                      "search.space.ranges={k0:{low:1,high:2}}"):
            space = compose_search("default", [f"search.space.kinds=[{MODULE}.KStep]", given]).space
            assert (space.ranges["k0"].low, space.ranges["k0"].high, space.ranges["k0"].log) == (1, 2, False), given
        assert compose_search("default", ["search.space.ranges.eps={low:1e-2,high:1,log:true}",
                                          "search.space.kinds=[constant]"]).space.ranges["eps"] == Bounds(0.01, 1, True)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop(MODULE, None)


def test_a_search_whose_trials_all_fail_prints_one_line_per_trial(tmp_path) -> None:
    """Each failed trial was Optuna's traceback and a "failed with value None" line (89 lines for three)."""
    done = command("sweeps.search.cli:main", [f"search.space.kinds=[{MODULE}.KStep]", "search.n_trials=2",
                                              f"learner._target_={CRASH_MODULE}.Crash", "search.pruner.kind=none",
                                              "threads=1", *tiny_search(tmp_path, epochs=2)],
                   write_module(tmp_path), code=1)
    assert "Traceback" not in done.stderr, done.stderr
    for number in (0, 1):
        (line,) = [line for line in done.stderr.splitlines() if f"Trial {number} " in line]
        assert "failed with parameters" in line and "boom at epoch 2" in line
    assert done.stderr.splitlines()[-1] == ("hersd-search: error: every trial of this search failed; the first, "
                                            "trial 0: RuntimeError: boom at epoch 2")


def test_a_field_of_a_class_made_without_param_is_one_line(draws) -> None:
    with pytest.raises(ConfigError) as refused:
        schedule_class(f"{DRAWS}.Plain")
    assert str(refused.value) == (f"schedule {DRAWS}.Plain: its field width is no setting; declare it with "
                                  "param(default, low, high, \"doc\") (from hersd.contract.schedules import param), or "
                                  "with field(init=False) if it is not one")


def test_a_rate_outside_is_printed_rounded(draws) -> None:
    schedule = schedule_class(f"{DRAWS}.Drop")(drop=0.95)
    assert schedule.rate(1, 1) == -0.04999999999999993
    with pytest.raises(ScheduleRateError, match=r"its rate at epoch 1 of 1 is -0.05, not in \[0, 1\]"):
        schedule.checked_rate(1, 1)
