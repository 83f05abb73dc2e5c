"""hersd-search: config checks, per-epoch reports and pruning, a two-worker search, resume after SIGKILL.

Every search trains tiny FetchReach runs (a few seconds each) into a temporary results dir.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

import hersd.train
from hersd.compose import group_options
from hersd.runlog import read_run
from sweeps import search

TINY = ["task=reach", "task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1",
        "ddpg.batch_size=64"]
FINISHED = (TrialState.COMPLETE, TrialState.PRUNED)


def tiny_search(results: Path, *extra: str, epochs: int = 4) -> list[str]:
    return [*TINY, f"epochs={epochs}", f"results_dir={results}", *extra]


def load(storage: str) -> optuna.Study:
    names = optuna.get_all_study_names(search.open_storage(storage))
    assert len(names) == 1
    return optuna.load_study(study_name=names[0], storage=search.open_storage(storage))


def only_db(results: Path) -> str:
    (db,) = (results / "search").glob("*.db")
    return str(db)


# --------------------------------------------------------------------------- configuration
@pytest.mark.parametrize("name", group_options("search"))
def test_every_search_config_composes(name: str) -> None:
    config = search.compose_search([f"+search={name}"])
    assert config.space.beta1.low <= config.space.beta1.high


@pytest.mark.parametrize("override, message", [
    ("search.space.beta2.low=3", "search.space.beta2: low (3.0) must be <= high (2.0)"),
    ("search.space.beta1.high=1.5", "search.space.beta1: bounds must lie in [0, 1], got [0.0, 1.5]"),
    ("search.space.beta1.low=-0.25", "search.space.beta1: bounds must lie in [0, 1], got [-0.25, 1.0]"),
    ("search.objective=best", "search.objective='best' is unknown"),
    ("search.space.bogus=1", "search.space.bogus is not a search setting"),
])
def test_bad_search_settings_fail_at_start(override: str, message: str, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        search.main([override, *tiny_search(tmp_path)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hersd-search: error: ") and message in err
    assert not (tmp_path / "search").exists()


def test_searched_training_keys_are_refused(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        search.main(["seed=3", *tiny_search(tmp_path)])
    assert exit_info.value.code == 2
    assert "seed is chosen by the search" in capsys.readouterr().err


def test_command_line_exit_code_is_2(tmp_path: Path) -> None:
    done = subprocess.run(["hersd-search", "search.space.beta2.low=1", "search.space.beta2.high=0",
                           *tiny_search(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip() == "hersd-search: error: search.space.beta2: low (1.0) must be <= high (0.0)"


def test_figures_module_imports_without_torch() -> None:
    code = "import sys, analysis.search_figures; assert 'torch' not in sys.modules and 'mujoco' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


# --------------------------------------------------------------------------- storage
def _claim_enqueued(db: str, calls: str) -> None:
    study = optuna.load_study(study_name="queue", storage=search.open_storage(db))

    def record(trial: optuna.Trial) -> float:
        with open(calls, "a") as out:
            out.write(f"{trial.number}\n")
        return trial.suggest_float("x", 0.0, 1.0)

    study.optimize(record, n_trials=20)


def test_sqlite_workers_never_claim_one_enqueued_trial_twice(tmp_path: Path) -> None:
    """Plain SQLite lets two workers popping the queue at once both take a trial (seen here
    as duplicated numbers and 'Cannot tell a COMPLETE trial' crashes); the claim lock stops it."""
    db, calls = str(tmp_path / "queue.db"), str(tmp_path / "calls.txt")
    study = optuna.create_study(study_name="queue", storage=search.open_storage(db))
    for i in range(40):
        study.enqueue_trial({"x": i / 40})
    context = multiprocessing.get_context("fork")  # quick to start; the children open their own storage
    workers = [context.Process(target=_claim_enqueued, args=(db, calls)) for _ in range(2)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(timeout=120)
    numbers = Path(calls).read_text().split()
    assert [worker.exitcode for worker in workers] == [0, 0]
    assert len(numbers) == len(set(numbers)) == 40


# --------------------------------------------------------------------------- reports, NaN, crashes
def test_nan_objective_prunes_the_trial() -> None:
    study = optuna.create_study(direction="maximize")

    def nan_run(trial: optuna.Trial) -> float:
        progress = search.TrialProgress(trial, "auc", epochs=3)
        progress.update(0, np.array([0.5]), may_prune=True)
        progress.update(0, np.array([0.5, np.nan]), may_prune=True)
        return 1.0

    study.optimize(nan_run, n_trials=1)
    (trial,) = study.trials
    assert trial.state == TrialState.PRUNED and trial.intermediate_values == {1: 0.5}
    assert "non-finite" in trial.user_attrs["pruned_reason"]


def test_crashed_run_fails_its_trial_and_the_study_goes_on(tmp_path: Path, monkeypatch) -> None:
    real_train = hersd.train.train
    calls = []

    def crash_first(cfg, command="", on_epoch=None):
        calls.append(cfg)
        if len(calls) == 1:
            raise RuntimeError("simulated crash")
        return real_train(cfg, command=command, on_epoch=on_epoch)

    monkeypatch.setattr(hersd.train, "train", crash_first)
    search.main(["search.n_trials=2", "search.pruner.kind=none", *tiny_search(tmp_path, epochs=2)])
    states = [t.state for t in load(only_db(tmp_path)).trials]
    assert states == [TrialState.FAIL, TrialState.COMPLETE]


def test_pruning_with_seeds_reported_as_one_rising_step(tmp_path: Path) -> None:
    """relabel_rate as the metric makes the objectives exact: beta1=0 keeps eps(k)=1, while
    beta1=1, beta2=-2 drops eps(1) of 3 epochs to 1 - (1/3)**exp(-2) = 0.138, so the
    median pruner (one finished trial, no warm-up) must stop trial 1 at its first step."""
    search.main(["search.n_trials=2", "search.seeds=2", "search.metric=relabel_rate",
                 "search.pruner.n_startup_trials=1", "search.pruner.n_warmup_steps=0",
                 "search.enqueue=[{beta1: 0.0, beta2: 0.0}, {beta1: 1.0, beta2: -2.0}]",
                 *tiny_search(tmp_path, epochs=3)])
    first, second = load(only_db(tmp_path)).trials
    assert first.state == TrialState.COMPLETE and first.value == 1.0
    assert sorted(first.intermediate_values) == list(range(1, 7))  # 2 seeds x 3 epochs
    assert len(first.user_attrs["run_dirs"]) == 2
    assert second.state == TrialState.PRUNED and sorted(second.intermediate_values) == [1]
    assert second.value == pytest.approx(1 - (1 / 3) ** np.exp(-2.0))
    (pruned_run,) = second.user_attrs["run_dirs"]
    log = read_run(Path(pruned_run) / "run.mcap")
    assert not log.complete and list(log.epochs["epoch"]) == [1]  # stopped there, resumable

    # hersd-report over the same folder adds the study's figure and best trials
    from analysis.report import build_report

    report = build_report(tmp_path, log=lambda line: None)
    page = report.index.read_text()
    assert "Optuna searches" in page and "beta_plane" in page
    assert any(path.name.endswith("_beta_plane.png") for path in report.figures)
    assert any(path.name.endswith("_best_trials.csv") for path in report.tables)


# --------------------------------------------------------------------------- whole searches
def test_ci_search_on_two_workers_with_a_journal(tmp_path: Path, capsys) -> None:
    journal = tmp_path / "shared" / "study.log"
    search.main(["search=ci", f"search.storage=journal:{journal}", *tiny_search(tmp_path)])
    study = load(f"journal:{journal}")
    assert len(study.get_trials(states=FINISHED)) == 6
    workers = {t.user_attrs["worker"] for t in study.trials}
    assert len(workers) == 2  # two processes shared the study
    for trial in study.get_trials(states=FINISHED):
        (run,) = trial.user_attrs["run_dirs"]
        assert Path(run).is_relative_to(tmp_path / "reach" / "her") and read_run(Path(run) / "run.mcap").epochs.size
    report = tmp_path / "search" / study.study_name
    names = sorted(p.name for p in report.iterdir())
    assert names == sorted(f"{study.study_name}_{suffix}" for suffix in
                           ("beta_plane.png", "best_trials.csv", "best_trials.md"))
    counts = [len(study.get_trials(states=(state,))) for state in FINISHED]
    assert f"trials: {counts[0]} complete, {counts[1]} pruned, 0 fail" in capsys.readouterr().out

    for path in report.iterdir():
        path.unlink()
    search.main(["--report", "search=ci", f"search.storage=journal:{journal}", *tiny_search(tmp_path)])
    assert sorted(p.name for p in report.iterdir()) == names  # redrawn, nothing trained
    assert len(load(f"journal:{journal}").trials) == 6


def test_report_of_a_missing_study_fails_at_start(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        search.main(["--report", *tiny_search(tmp_path)])
    assert exit_info.value.code == 2 and "run the search first" in capsys.readouterr().err
    assert not list((tmp_path / "search").glob("*.db"))


def _finished_trials(storage: str) -> dict[int, tuple]:
    study = load(storage)
    return {t.number: (t.state, t.value, tuple(sorted(t.params.items()))) for t in study.get_trials(states=FINISHED)}


def _count_finished(db: Path) -> int:
    """Read-only peek at a study being written (no optuna: it would create tables)."""
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30) as connection:
            return connection.execute("SELECT count(*) FROM trials WHERE state IN ('COMPLETE', 'PRUNED')").fetchone()[0]
    except sqlite3.OperationalError:  # not created yet
        return 0


def test_resume_after_sigkill_loses_and_repeats_nothing(tmp_path: Path) -> None:
    args = ["search=ci", "search.n_trials=4", "search.pruner.kind=none", *tiny_search(tmp_path)]
    with open(tmp_path / "first.log", "w") as first_log:
        first = subprocess.Popen(["hersd-search", *args], start_new_session=True, stdout=first_log,
                                 stderr=subprocess.STDOUT)
    db = None
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and first.poll() is None:
            db = next((tmp_path / "search").glob("*.db"), None) if (tmp_path / "search").exists() else None
            if db is not None and _count_finished(db) >= 1:
                break
            time.sleep(0.2)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    assert db is not None and first.returncode == -signal.SIGKILL, (tmp_path / "first.log").read_text()[-2000:]
    storage = str(db)
    before = _finished_trials(storage)
    assert 1 <= len(before) < 4

    search.main(args)  # the same command again

    study = load(storage)
    after = _finished_trials(storage)
    assert {n: after[n] for n in before} == before  # nothing finished was lost or changed
    assert len(after) == 4
    lost = [t for t in study.trials if "lost" in t.user_attrs]
    assert lost and all(t.state == TrialState.FAIL for t in lost)
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
