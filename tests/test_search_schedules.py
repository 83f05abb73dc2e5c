"""hersd-search over any schedule's settings, with a newcomer's classes (tests/user_schedules.py): whole numbers
drawn as such, ranges from the command line as docs/SEARCH.md shows them, a search whose trials all fail,
workers of separate commands on one study, a trial whose run another worker holds, the study's identity."""

from __future__ import annotations

import logging
import shlex
from pathlib import Path

import optuna
import pytest
from optuna.trial import TrialState
from searches import load, only_db, run_meta, tiny_search
from user_schedules import CRASH_MODULE, MODULE, start, write_module

from hersd.contract.runstore import RunFolder, run_dir
from hersd.contract.study import trial_config
from sweeps.search import cli
from sweeps.search.config import compose_search
from sweeps.search.plan import make_plan

DOCS = Path(__file__).resolve().parents[1] / "docs" / "SEARCH.md"


@pytest.fixture
def newcomer(tmp_path, monkeypatch) -> str:
    """The newcomer's module importable here -> its KStep's class path."""
    monkeypatch.syspath_prepend(str(write_module(tmp_path)))
    return f"{MODULE}.KStep"


def test_a_whole_number_setting_is_drawn_as_one_within_its_range(tmp_path, newcomer) -> None:
    cli.main([f"search.space.kinds=[{newcomer}]", "search.space.ranges.k0={low: 1, high: 3}", "search.n_trials=2",
              "search.pruner.kind=none", "threads=1", *tiny_search(tmp_path, epochs=1)])
    trials = load(only_db(tmp_path)).trials
    assert [trial.state for trial in trials] == [TrialState.COMPLETE] * 2
    for trial in trials:
        k0 = trial.params["k0"]
        assert isinstance(k0, int) and 1 <= k0 <= 3
        assert run_meta(trial.user_attrs["run_dirs"][0])["config"]["schedule"]["k0"] == k0


def test_a_search_whose_trials_all_fail_exits_non_zero_naming_the_first_error(tmp_path, newcomer, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli.main([f"search.space.kinds=[{MODULE}.KStep]", "search.n_trials=2", "search.pruner.kind=none",
                  f"learner._target_={CRASH_MODULE}.Crash", "threads=1", *tiny_search(tmp_path, epochs=2)])
    assert exit_info.value.code == 1
    assert [trial.state for trial in load(only_db(tmp_path)).trials] == [TrialState.FAIL] * 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        "hersd-search: error: every trial of this search failed; the first, trial 0: RuntimeError: boom at epoch 2")


def test_the_sets_the_search_enqueues_count_among_its_trials(tmp_path, newcomer, capsys) -> None:
    """The default search enqueues the paper's two sets before its trials were counted, so those were not the
    command's: two failed trials exited 0 without the error line, and two complete trials then a failed one
    ended "every trial of this search failed", exit 1."""
    crash = ["search.pruner.kind=none", "threads=1", f"learner._target_={CRASH_MODULE}.Crash"]
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["search.n_trials=2", *crash, *tiny_search(tmp_path / "all", epochs=2)])
    assert exit_info.value.code == 1 and capsys.readouterr().err.splitlines()[-1] == (
        "hersd-search: error: every trial of this search failed; the first, trial 0: RuntimeError: boom at epoch 2")
    cli.main(["search.n_trials=3", *crash[:-1], f"learner._target_={CRASH_MODULE}.CrashThird",
              *tiny_search(tmp_path / "third", epochs=2)])  # no SystemExit: done
    trials = load(only_db(tmp_path / "third")).trials
    assert [trial.state for trial in trials] == [TrialState.COMPLETE] * 2 + [TrialState.FAIL]
    assert "every trial" not in capsys.readouterr().err


def docs_command(marker: str) -> list[str]:
    """The arguments of the one ``hersd-search`` command in docs/SEARCH.md that holds ``marker``."""
    (line,) = [line for line in DOCS.read_text().splitlines() if line.startswith("hersd-search ") and marker in line]
    return shlex.split(line)[1:]


def test_the_docs_range_examples_run(tmp_path) -> None:
    args = docs_command("search.space.ranges=")
    cli.main([*args, "search.n_trials=2", "search.pruner.kind=none", "threads=1", *tiny_search(tmp_path, epochs=1)])
    trials = load(only_db(tmp_path)).trials
    assert [trial.state for trial in trials] == [TrialState.COMPLETE] * 2
    assert all(0.8 <= trial.params["start"] <= 1.0 for trial in trials)
    one_setting = compose_search("default", [arg for arg in docs_command("search.space.ranges.") if arg.startswith("search.")])
    assert (one_setting.space.ranges["start"].low, one_setting.space.ranges["start"].high) == (0.8, 1.0)


def test_two_commands_on_one_study_draw_distinct_parameters_and_fail_no_trial(tmp_path) -> None:
    args = [f"search.space.kinds=[{MODULE}.KStep]", "search.space.ranges.k0={low: 1, high: 1000}", "search.n_trials=4",
            "search.pruner.kind=none", "threads=1", *tiny_search(tmp_path, epochs=1)]
    commands = [start("sweeps.search.cli:main", args, write_module(tmp_path)) for _ in range(2)]
    outputs = [command.communicate(timeout=600) for command in commands]
    assert [command.returncode for command in commands] == [0, 0], outputs
    trials = load(only_db(tmp_path)).trials
    assert len(trials) >= 4 and all(trial.state == TrialState.COMPLETE for trial in trials), outputs
    drawn = [tuple(sorted(trial.params.items())) for trial in trials]
    assert len(set(drawn)) == len(drawn), drawn


def test_a_trial_whose_run_another_worker_holds_is_skipped_in_one_line(tmp_path, capsys, caplog) -> None:
    args = ["search.space.kinds=[linear]", "search.enqueue=[{beta1: 0.25}]", "search.n_trials=1", "threads=1",
            *tiny_search(tmp_path, epochs=1)]
    plan = make_plan(compose_search("default", ["search.space.kinds=[linear]"]), args[4:])
    held = RunFolder(run_dir(trial_config(plan.base, {"kind": "linear", "beta1": 0.25}, 0)))
    held.path.mkdir(parents=True)
    optuna.logging.enable_propagation()  # Optuna's lines to caplog
    try:
        with held.lock(), caplog.at_level(logging.INFO, logger="optuna"):  # another worker trains this run
            cli.main(args)
    finally:
        optuna.logging.disable_propagation()
    (trial,) = load(only_db(tmp_path)).trials
    assert trial.state == TrialState.PRUNED and "is being run by another process" in trial.user_attrs["skipped"]
    assert "trials: 0 complete, 0 pruned, 0 fail, 1 skipped" in capsys.readouterr().out
    trial_lines = [record for record in caplog.records if "Trial 0" in record.getMessage()]
    # one line, however many handlers an earlier test in this worker left on the way to caplog
    (message,) = {record.getMessage() for record in trial_lines}
    assert message.startswith("Trial 0 pruned. skipped: ") and "\n" not in message
    assert all(record.exc_info is None for record in trial_lines)


def test_the_study_name_covers_the_search_space_not_the_trial_count(tmp_path) -> None:
    def name(*overrides: str) -> str:
        return make_plan(compose_search("default", list(overrides)), tiny_search(tmp_path)).study_name

    assert name() == name("search.n_trials=7") != name("search.space.beta2.low=-1")
    assert name("search.space.kinds=[cosine]") != name("search.space.kinds=[cosine]",
                                                      "search.space.ranges.start={low: 0.8, high: 1.0}")
