"""Commands joined on one study: search.enqueue on an existing study (each set tried once), and two hersd-search
commands on one journal that stop at search.n_trials in total and print one summary."""

from __future__ import annotations

import json
from pathlib import Path

from optuna.trial import TrialState
from searches import FINISHED, load, only_db, tiny_search
from user_schedules import start

from sweeps.search import cli
from sweeps.search.study import ENQUEUED_ATTR, SKIPPED_ATTR

SET = {"beta1": 0.7, "beta2": 0.3}


def _search(tmp_path: Path, n_trials: int, *extra: str) -> None:
    cli.main([f"search.n_trials={n_trials}", "search.pruner.kind=none", "threads=1", *extra,
              *tiny_search(tmp_path, epochs=1)])


def test_a_set_given_on_an_existing_study_is_enqueued_once(tmp_path: Path, capsys) -> None:
    """It was dropped in silence: the next trial drew other values."""
    _search(tmp_path, 1, "search.enqueue=[]")
    _search(tmp_path, 2, "search.enqueue=[{beta1: 0.7, beta2: 0.3}]")
    assert load(only_db(tmp_path)).trials[1].params == SET
    capsys.readouterr()
    _search(tmp_path, 3, "search.enqueue=[{beta1: 0.7, beta2: 0.3}]")  # the same command again: not a second time
    assert ("search.enqueue[0] {'beta1': 0.7, 'beta2': 0.3}: the study holds it already (trial 1); not enqueued "
            "again\n") in capsys.readouterr().out
    study = load(only_db(tmp_path))
    assert len(study.trials) == 3 and study.trials[2].params != SET
    # two commands that enqueued one set at the same moment: the later copy is skipped when a worker takes it
    again = {"beta1": 0.6, "beta2": 0.1}
    for _ in range(2):
        study.enqueue_trial(again, user_attrs={ENQUEUED_ATTR: json.dumps(again, sort_keys=True)})
    _search(tmp_path, 5, "search.enqueue=[]")
    first, copy = load(only_db(tmp_path)).trials[3:]
    assert first.state == TrialState.COMPLETE and first.params == again
    assert copy.state == TrialState.PRUNED and copy.user_attrs[SKIPPED_ATTR] == ("trial 3 tries the same "
                                                                                 "search.enqueue set")


def test_a_set_the_study_has_no_room_for_is_not_enqueued_in_one_line(tmp_path: Path, capsys) -> None:
    """A set given to a study whose search.n_trials were finished waited in silence, and a later command with a
    higher n_trials then tried it instead of its own set."""
    _search(tmp_path, 1, "search.enqueue=[]")
    capsys.readouterr()
    _search(tmp_path, 1, "search.enqueue=[{beta1: 0.9, beta2: 0.1}]")
    assert ("search.enqueue[0] {'beta1': 0.9, 'beta2': 0.1}: not enqueued, search.n_trials=1 leaves no room for "
            "it; raise search.n_trials to try it\n") in capsys.readouterr().out
    _search(tmp_path, 2, "search.enqueue=[{beta1: 0.7, beta2: 0.3}]")
    study = load(only_db(tmp_path))
    assert len(study.trials) == 2 and study.trials[1].params == SET


def test_two_commands_on_one_journal_stop_at_n_trials_and_agree(tmp_path: Path) -> None:
    """Two commands asked for 6 trials ran 7 and summarised "7 complete" and "6 complete". Both enqueue
    default.yaml's two paper points, each tried once."""
    journal = tmp_path / "shared" / "study.log"
    args = ["search.n_trials=5", "search.pruner.kind=none", "threads=1", f"search.storage=journal:{journal}",
            *tiny_search(tmp_path, epochs=1)]
    commands = [start("sweeps.search.cli:main", args, tmp_path) for _ in range(2)]
    outputs = [command.communicate(timeout=600) for command in commands]
    assert [command.returncode for command in commands] == [0, 0], outputs
    study = load(f"journal:{journal}")
    finished = [trial for trial in study.get_trials(states=FINISHED) if SKIPPED_ATTR not in trial.user_attrs]
    assert len(finished) == 5, [(trial.number, trial.state, trial.user_attrs) for trial in study.trials]
    assert all(trial.state in FINISHED for trial in study.trials)
    summaries = [[line for line in out.splitlines() if line.startswith("trials: ")] for out, _ in outputs]
    assert summaries[0] == summaries[1] and len(summaries[0]) == 1, outputs
    paper = [trial.params for trial in finished if trial.params in ({"beta1": 0.25, "beta2": 0.25},
                                                                    {"beta1": 0.5, "beta2": 0.5})]
    assert len(paper) == 2, paper
