"""sweeps/search/study.py: the study in its storage and the recovery of lost trials."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from optuna.trial import TrialState
from searches import FINISHED, _count_finished, load, tiny_search

from hersd.contract.runlog import read_run
from sweeps.search import cli


def _finished_trials(storage: str) -> dict[int, tuple]:
    study = load(storage)
    return {t.number: (t.state, t.value, tuple(sorted(t.params.items()))) for t in study.get_trials(states=FINISHED)}


def _running_trials(db: Path) -> dict[int, tuple[int | None, bool]]:
    """The RUNNING trials: number -> (last epoch reported or None, whether it names its worker)."""
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30) as connection:
            rows = connection.execute(
                "SELECT t.number, (SELECT MAX(v.step) FROM trial_intermediate_values v WHERE v.trial_id = t.trial_id), "
                "EXISTS (SELECT 1 FROM trial_user_attributes a WHERE a.trial_id = t.trial_id AND a.key = 'worker') "
                "FROM trials t WHERE t.state = 'RUNNING'").fetchall()
    except sqlite3.OperationalError:  # not created yet
        return {}
    return {number: (last, bool(named)) for number, last, named in rows}


def _killable_mid_trial(db: Path, epochs: int) -> bool:
    """Whether a kill now lands mid-trial: a trial is finished, one RUNNING has at least 2 of its
    ``epochs`` to go, and every RUNNING trial names its worker (one killed before that stays
    RUNNING until search.stale_after_minutes, since nothing tells whose it was)."""
    running = _running_trials(db)
    return (_count_finished(db) >= 1 and all(named for _, named in running.values())
            and any(last is None or last <= epochs - 2 for last, _ in running.values()))


def test_resume_after_sigkill_loses_and_repeats_nothing(tmp_path: Path) -> None:
    args = ["search=ci", "search.n_trials=4", "search.pruner.kind=none", *tiny_search(tmp_path)]
    code = "import sys; from sweeps.search.cli import main; main(sys.argv[1:])"
    with open(tmp_path / "first.log", "w") as first_log:
        first = subprocess.Popen([sys.executable, "-c", code, *args], start_new_session=True, stdout=first_log,
                                 stderr=subprocess.STDOUT)
    db = None
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and first.poll() is None:
            db = next((tmp_path / "search").glob("*.db"), None) if (tmp_path / "search").exists() else None
            if db is not None and _killable_mid_trial(db, epochs=4):
                break
            time.sleep(0.2)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    assert db is not None and first.returncode == -signal.SIGKILL, (tmp_path / "first.log").read_text()[-2000:]
    storage = str(db)
    before = _finished_trials(storage)
    assert 1 <= len(before) < 4
    killed = sorted(number for number, (_, named) in _running_trials(db).items() if named)
    assert killed, (tmp_path / "first.log").read_text()[-2000:]

    cli.main(args)  # the same command again

    study = load(storage)
    after = _finished_trials(storage)
    assert {n: after[n] for n in before} == before  # nothing finished was lost or changed
    assert len(after) == 4
    lost = [t for t in study.trials if "lost" in t.user_attrs]
    assert [t.number for t in lost] == killed and all(t.state == TrialState.FAIL for t in lost)
    retries = {t.user_attrs["retry_of"]: t for t in study.get_trials(states=FINISHED) if "retry_of" in t.user_attrs}
    assert sorted(retries) == sorted(t.number for t in lost)  # each lost trial re-run exactly once
    for trial in lost:
        assert retries[trial.number].params.items() >= trial.params.items()  # (killed mid-suggest: the rest is new)
        if trial.intermediate_values:  # it had finished an epoch: the re-run resumed its run there
            (run,) = retries[trial.number].user_attrs["run_dirs"]
            resumed = max(s["resumed_from_epoch"] for s in read_run(Path(run) / "run.mcap").sessions)
            last = max(trial.intermediate_values)
            assert resumed >= last or last == 4  # (or the run had just completed when the worker died)
    params = [p for _, _, p in after.values()]
    assert len(set(params)) == len(params)  # no trial repeated
