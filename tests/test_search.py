"""hersd-search (sweeps/search/): config checks and one-line errors, trial configs equal to
hersd-train's, thread shares, per-epoch reports and pruning, a two-worker search, SLURM
workers through submitit's local executor, resume after SIGKILL.

Every search trains tiny FetchReach runs (a few seconds each) into a temporary results dir.
"""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
import shlex
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import optuna
import pytest
from helpers import TINY, run_command
from optuna.trial import TrialState

import hersd.train
from hersd.compose import compose_train, group_options
from hersd.resources import available_cores, resolve_threads
from hersd.runlog import read_run
from hersd.runstore import config_hash, run_dir
from hersd.study import param_overrides, trial_config
from sweeps.search.storage import open_storage
from sweeps.search import cli, plan as search_plan, workers
from sweeps.search.config import SlurmConfig, compose_search
from sweeps.search.objective import TrialProgress
from sweeps.search.plan import make_plan
from sweeps.search.study import open_study

FINISHED = (TrialState.COMPLETE, TrialState.PRUNED)
CLI = "sweeps.search.cli:main"


def tiny_search(results: Path, *extra: str, epochs: int = 4) -> list[str]:
    return [*TINY, f"epochs={epochs}", f"results_dir={results}", *extra]


def load(storage: str) -> optuna.Study:
    names = optuna.get_all_study_names(open_storage(storage))
    assert len(names) == 1
    return optuna.load_study(study_name=names[0], storage=open_storage(storage))


def only_db(results: Path) -> str:
    (db,) = (results / "search").glob("*.db")
    return str(db)


def run_meta(run: str) -> dict:
    return read_run(Path(run) / "run.mcap").meta


def fails_with(argv: list[str], capsys) -> str:
    """hersd-search's one stderr line for ``argv`` (asserting exit code 2 and one line)."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert err.count("\n") == 1 and err.startswith("hersd-search: error: "), err
    return err


# --------------------------------------------------------------------------- configuration
@pytest.mark.parametrize("name", group_options("search"))
def test_every_search_config_composes_and_plans(name: str, tmp_path: Path) -> None:
    config = compose_search(name, [])
    assert config.space.beta1.low <= config.space.beta1.high
    plan = make_plan(config, tiny_search(tmp_path), name)  # enqueued sets and range ends make valid runs
    assert plan.study_name.startswith(f"reach-her-{name}-") and plan.base.quiet


@pytest.mark.parametrize("override, message", [
    ("search.space.beta2.low=3", "search.space.beta2: low (3.0) must be <= high (2.0)"),
    ("search.space.beta1.high=1.5", "search.space.beta1.high=1.5: schedule.beta1 must be a number in [0, 1]"),
    ("search.space.beta1.low=-0.25", "search.space.beta1.low=-0.25: schedule.beta1 must be a number in [0, 1]"),
    ("search.space.beta2.high=100", "search.space.beta2.high=100.0: schedule.beta2 must be a number in [-50, 50]"),
    ("search.space.beta1.low=nan", "search.space.beta1: bounds must be finite numbers, got [nan, 1.0]"),
    ("search.space.lambda_h={low: 0, high: 1}", "search.space.lambda_h: low must be > 0, got 0.0"),
    ("search.space.kinds=[success]", "search.space.kinds: success cannot be searched"),
    ("search.space.kinds=[sawtooth]", "search.space.kinds: schedule.kind='sawtooth' is unknown"),
    ("search.space.kinds=[]", "search.space.kinds must be a non-empty list of distinct kinds"),
    ("search.space.kinds=[linear,linear]", "search.space.kinds must be a non-empty list of distinct kinds"),
    ("search.space.bogus=1", "search.space.bogus is not a search setting"),
    ("search.objective=best", "search.objective='best' is unknown"),
    ("search.n_trials=-1", "search.n_trials must be >= 1, got -1"),
    ("search.n_trials=1e20", "search.n_trials: Value '1e+20' of type 'float' could not be converted to Integer"),
    ("search.n_jobs=1000000", "search.n_jobs=1000000: local workers are processes of this machine"),
    ("search.seeds=0", "search.seeds must be >= 1, got 0"),
    ("search.first_seed=-1", "search.first_seed must be >= 0, got -1"),
    ("search.stale_after_minutes=0", "search.stale_after_minutes must be > 0"),
    ("search.stale_after_minutes=nan", "search.stale_after_minutes must be > 0"),
    ("search.sampler.seed=-1", "search.sampler.seed must be >= 0, got -1"),
    ("search.enqueue=[{beta1: abc}]", "search.enqueue[0].beta1 must be a finite number, got 'abc'"),
    ("search.enqueue=[{beta1: true}]", "search.enqueue[0].beta1 must be a finite number, got True"),
    ("search.enqueue=[{beta1: 2}]", "search.enqueue[0]: schedule.beta1 must be a number in [0, 1], got 2.0"),
    ("search.enqueue=[{eps: 0.5}]", "search.enqueue[0]: eps not searched for kind exponential"),
    ("search.enqueue=[1]", "search.enqueue must be a list of mappings"),
    ("search.study_name=../x", "search.study_name='../x': use 1-200 letters"),
    ("search.storage=foo://x", "search.storage=foo://x: unknown database scheme 'foo'"),
    ("search.storage=sqlite://", "search.storage: an in-memory SQLite database"),
    ("search.storage=", "search.storage is empty"),
    ("search.storage=journal:", "search.storage=journal:<path> needs a file path"),
    ("search=nope", "search=nope is not a known search; choose one of: ci, default, wide"),
    ("results_dir=/proc/no-such-dir", "results_dir: cannot write to /proc/no-such-dir"),
    ("--report", "--report was removed: hersd-search no longer draws figures; draw the study with hersd-report"),
])
def test_bad_search_settings_fail_at_start(override: str, message: str, tmp_path: Path, capsys) -> None:
    assert message in fails_with([*tiny_search(tmp_path), override], capsys)
    assert not (tmp_path / "search").exists()


@pytest.mark.skipif(importlib.util.find_spec("psycopg2") is None, reason="needs psycopg2 (hersd[cluster])")
def test_an_unreachable_database_is_one_line(tmp_path: Path, capsys) -> None:
    err = fails_with(["search.storage=postgresql://u:secret@127.0.0.1:1/x", *tiny_search(tmp_path)], capsys)
    assert "search.storage: cannot reach the database at postgresql+psycopg2://u:***@127.0.0.1:1/x" in err
    assert "secret" not in err


def test_a_missing_database_driver_is_one_line(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "psycopg2", None)  # import psycopg2 now fails as if not installed
    err = fails_with(["search.storage=postgresql+psycopg2://u@127.0.0.1:1/x", *tiny_search(tmp_path)], capsys)
    assert 'the database driver psycopg2 is not installed; pip install "hersd[cluster]"' in err


@pytest.mark.parametrize("override", ["seed=3", "schedule=linear", "schedule.beta1=0.5", "schedule.mean_rate=0.8",
                                      "run_dir=/tmp/one-dir", "algo.lambda_h=0.5"])
def test_searched_training_keys_are_refused(override: str, tmp_path: Path, capsys) -> None:
    err = fails_with(["search=wide", override, *tiny_search(tmp_path)], capsys)
    assert f"{override.split('=')[0]} is set by the search for each run" in err


def test_command_line_exit_code_is_2(tmp_path: Path) -> None:
    done = run_command(CLI, "search.space.beta2.low=1", "search.space.beta2.high=0", *tiny_search(tmp_path),
                       timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip() == "hersd-search: error: search.space.beta2: low (1.0) must be <= high (0.0)"


def test_help_also_through_the_packages_main(capsys) -> None:
    cli.main(["--help"])
    assert capsys.readouterr().out.startswith("usage: hersd-search")
    done = run_command("sweeps.search:main", "--help", timeout=120)  # the entry point scripts installed so far
    assert done.returncode == 0 and done.stdout.startswith("usage: hersd-search")


def test_the_command_loads_neither_torch_nor_the_analysis() -> None:
    code = ("import sys, sweeps.search.cli; "
            "print(sorted(m for m in ('torch', 'mujoco', 'analysis') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]"


def test_a_mapping_override_sets_a_null_range() -> None:
    space = compose_search("default", ["search.space.lambda_h={low: 0.25, high: 1.0}"]).space
    assert (space.lambda_h.low, space.lambda_h.high, space.lambda_h.log) == (0.25, 1.0, False)


def test_kinds_of_enqueued_sets_are_inferred_when_several_kinds_are_searched(tmp_path: Path) -> None:
    search = compose_search("default", ["search.space.kinds=[linear,exponential]",
                                        "search.enqueue=[{beta1: 0.25, beta2: 0.25}, {kind: linear, beta1: 0.5}]"])
    plan = make_plan(search, tiny_search(tmp_path))
    study = open_study(plan, optuna.storages.InMemoryStorage())
    assert [t.system_attrs["fixed_params"] for t in study.trials] == [
        {"kind": "exponential", "beta1": 0.25, "beta2": 0.25}, {"kind": "linear", "beta1": 0.5}]


# --------------------------------------------------------------------------- trial configs
@pytest.mark.parametrize("params", [
    {"kind": "exponential", "beta1": 0.123456789012345, "beta2": -1.5},
    {"kind": "linear", "beta1": 0.25},
    {"kind": "constant", "eps": 0.8},
    {"kind": "exponential", "beta1": 0, "beta2": 1, "lambda_h": 0.5},  # ints, as an enqueued YAML set gives them
])
def test_a_trials_runs_are_those_of_hersd_train_with_the_equivalent_overrides(params: dict, tmp_path: Path) -> None:
    overrides = tiny_search(tmp_path / "results", "algo=archer")
    plan = make_plan(compose_search("wide", []), overrides, "wide")
    for seed in (0, 3):
        ours = trial_config(plan.base, params, seed, threads="1")
        theirs = compose_train([*overrides, *param_overrides(params), f"seed={seed}"])
        assert run_dir(ours) == run_dir(theirs) and config_hash(ours) == config_hash(theirs)
        assert ours.schedule == theirs.schedule and ours.algo == theirs.algo and ours.threads == "1"


def test_run_threads_share_the_cores_unless_given(idle_machine) -> None:
    base = compose_train(TINY)
    assert search_plan.run_threads(base, 2) == str(resolve_threads("auto", 2))  # 1 each on 2 cores
    assert search_plan.run_threads(base, 1) == str(available_cores())
    assert search_plan.run_threads(compose_train([*TINY, "threads=3"]), 2) == "3"


# --------------------------------------------------------------------------- storage
def _claim_enqueued(db: str, calls: str) -> None:
    study = optuna.load_study(study_name="queue", storage=open_storage(db))

    def record(trial: optuna.Trial) -> float:
        with open(calls, "a") as out:
            out.write(f"{trial.number}\n")
        return trial.suggest_float("x", 0.0, 1.0)

    study.optimize(record, n_trials=20)


def test_sqlite_workers_never_claim_one_enqueued_trial_twice(tmp_path: Path) -> None:
    """Plain SQLite lets two workers popping the queue at once both take a trial (seen here
    as duplicated numbers and 'Cannot tell a COMPLETE trial' crashes); the claim lock stops it."""
    db, calls = str(tmp_path / "queue.db"), str(tmp_path / "calls.txt")
    study = optuna.create_study(study_name="queue", storage=open_storage(db))
    for i in range(40):
        study.enqueue_trial({"x": i / 40})
    context = multiprocessing.get_context("fork")  # quick to start; the children open their own storage
    processes = [context.Process(target=_claim_enqueued, args=(db, calls)) for _ in range(2)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(timeout=120)
    numbers = Path(calls).read_text().split()
    assert [process.exitcode for process in processes] == [0, 0]
    assert len(numbers) == len(set(numbers)) == 40


# --------------------------------------------------------------------------- SLURM settings
def test_slurm_settings_come_from_the_packaged_preset_and_search_slurm() -> None:
    assert workers.slurm_settings(SlurmConfig()) == {"partition": None, "timeout_min": 240, "cpus_per_task": 1,
                                                     "mem_gb": 8}
    settings = workers.slurm_settings(SlurmConfig(partition="cpu", mem_gb=2))
    assert (settings["partition"], settings["mem_gb"], settings["timeout_min"]) == ("cpu", 2, 240)


@pytest.mark.parametrize("sinfo, override, message", [
    ("echo 'sinfo: fatal: no controller' >&2; exit 1", "", "SLURM does not answer here (sinfo: fatal: no controller)"),
    ("printf 'debug*\\ncpu\\n'", "search.slurm.partition=gpu", "search.slurm.partition=gpu: no partition gpu here; "
                                                               "choose among: debug, cpu"),
])
def test_slurm_problems_stop_the_search_at_start(sinfo: str, override: str, message: str, tmp_path: Path,
                                                 capsys, monkeypatch) -> None:
    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "sinfo").write_text(f"#!/bin/sh\n{sinfo}\n")
    (tmp_path / "bin" / "sinfo").chmod(0o755)
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}:{os.environ['PATH']}")
    err = fails_with(["search.launcher=slurm", *([override] if override else []), *tiny_search(tmp_path)], capsys)
    assert message in err
    assert not (tmp_path / "search").exists()


# --------------------------------------------------------------------------- reports, NaN, crashes
def test_nan_objective_prunes_the_trial() -> None:
    study = optuna.create_study(direction="maximize")

    def nan_run(trial: optuna.Trial) -> float:
        progress = TrialProgress(trial, "auc", epochs=3)
        progress.update(0, np.array([0.5]), may_prune=True)
        progress.update(0, np.array([0.5, np.nan]), may_prune=True)
        return 1.0

    study.optimize(nan_run, n_trials=1)
    (trial,) = study.trials
    assert trial.state == TrialState.PRUNED and trial.intermediate_values == {1: 0.5}
    assert "non-finite" in trial.user_attrs["pruned_reason"]


def test_crashed_run_fails_its_trial_and_the_study_goes_on(tmp_path: Path, monkeypatch) -> None:
    real_train, real_compose = hersd.train.train, search_plan.compose_train
    calls, composed = [], []

    def crash_first(cfg, command="", on_epoch=None):
        calls.append(cfg)
        if len(calls) == 1:
            raise RuntimeError("simulated crash")
        return real_train(cfg, command=command, on_epoch=on_epoch)

    monkeypatch.setattr(hersd.train, "train", crash_first)
    monkeypatch.setattr(search_plan, "compose_train", lambda overrides: composed.append(1) or real_compose(overrides))
    cli.main(["search.n_trials=2", "search.pruner.kind=none", "threads=1", *tiny_search(tmp_path, epochs=2)])
    study = load(only_db(tmp_path))
    assert [t.state for t in study.trials] == [TrialState.FAIL, TrialState.COMPLETE]
    assert len(composed) == 1  # the training config is composed once; trials replace fields of it
    meta = run_meta(study.trials[1].user_attrs["run_dirs"][0])
    assert meta["threads"] == 1 and meta["config"]["threads"] == "1"  # threads=N given: kept


def test_a_run_the_training_layer_refuses_stops_the_search_in_one_line(tmp_path: Path, capsys) -> None:
    """A refusal found only when a run starts (here: too little memory) would refuse every trial."""
    err = fails_with(["search.n_trials=3", "ddpg.buffer_size=100000000000", *tiny_search(tmp_path)], capsys)
    assert "GiB are available; lower ddpg.buffer_size" in err
    refused, waiting = load(only_db(tmp_path)).trials  # the second enqueued set waits for the next run
    assert refused.state == TrialState.FAIL and "lower ddpg.buffer_size" in refused.user_attrs["refused"]
    assert waiting.state == TrialState.WAITING


def test_pruning_with_seeds_reported_as_one_rising_step(tmp_path: Path, capsys, idle_machine) -> None:
    """relabel_rate as the metric makes the objectives exact: beta1=0 keeps eps(k)=1, while
    beta1=1, beta2=-2 drops eps(1) of 3 epochs to 1 - (1/3)**exp(-2) = 0.138, so the
    median pruner (one finished trial, no warm-up) must stop trial 1 at its first step."""
    cli.main(["search.n_trials=2", "search.seeds=2", "search.metric=relabel_rate",
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
    # one local worker: its runs use every core, and their logs name the equivalent hersd-train command
    meta = run_meta(first.user_attrs["run_dirs"][0])
    assert meta["threads"] == available_cores() and meta["config"]["threads"] == str(available_cores())
    assert "hersd-train" in meta["command"] and "schedule=exponential schedule.beta1=0.0 schedule.beta2=0.0 seed=0" \
        in meta["command"]
    # the default storage lies where hersd-report looks by itself
    assert f"figures and tables: hersd-report {shlex.quote(str(tmp_path))}\n" in capsys.readouterr().out


# --------------------------------------------------------------------------- whole searches
def test_ci_search_on_two_workers_with_a_journal(tmp_path: Path, capsys) -> None:
    journal = tmp_path / "shared" / "study.log"
    cli.main(["search=ci", f"search.storage=journal:{journal}", *tiny_search(tmp_path)])
    study = load(f"journal:{journal}")
    assert len(study.get_trials(states=FINISHED)) == 6
    assert len({t.user_attrs["worker"] for t in study.trials}) == 2  # two processes shared the study
    for trial in study.get_trials(states=FINISHED):
        (run,) = trial.user_attrs["run_dirs"]
        assert Path(run).is_relative_to(tmp_path / "reach" / "her") and read_run(Path(run) / "run.mcap").epochs.size
        assert 1 <= run_meta(run)["threads"] <= max(1, available_cores() // 2)  # the cores shared by the two workers
    out = capsys.readouterr().out
    counts = [len(study.get_trials(states=(state,))) for state in FINISHED]
    assert f"trials: {counts[0]} complete, {counts[1]} pruned, 0 fail" in out
    assert not (tmp_path / "search").exists()  # the search draws nothing itself

    # the printed command draws the study (hersd-report reads the journal named by --storage)
    (command,) = [line.split(": ", 1)[1] for line in out.splitlines() if line.startswith("figures and tables: ")]
    assert command == shlex.join(["hersd-report", str(tmp_path), "--storage", f"journal:{journal}"])
    report = subprocess.run(shlex.split(command), capture_output=True, text=True, timeout=300)
    assert report.returncode == 0, report.stdout[-2000:] + report.stderr[-2000:]
    assert (tmp_path / "report" / "search" / f"{study.study_name}_beta_plane.png").stat().st_size > 0


def test_slurm_workers_run_as_submitit_jobs_each_on_its_whole_allocation(tmp_path: Path, capsys,
                                                                          monkeypatch) -> None:
    """search.launcher=slurm through submitit's local executor (no SLURM here): the jobs run the
    workers; each job's runs take every core it has (concurrent_runs=1), not a share."""
    import submitit

    real_executor = submitit.AutoExecutor
    monkeypatch.setattr(submitit, "AutoExecutor", lambda folder, cluster: real_executor(folder, cluster="local"))
    monkeypatch.setattr(cli, "check_slurm", lambda slurm: None)
    cli.main(["search.launcher=slurm", "search.n_jobs=2", "search.n_trials=2", "search.pruner.kind=none",
              *tiny_search(tmp_path, epochs=2)])
    assert "submitted SLURM jobs" in capsys.readouterr().out
    db = only_db(tmp_path)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and _count_finished(Path(db)) < 2:
        time.sleep(1.0)
    study = load(db)
    assert [t.state for t in study.trials] == [TrialState.COMPLETE] * 2, list((tmp_path / "search").rglob("*.err"))
    for trial in study.trials:
        assert 1 <= run_meta(trial.user_attrs["run_dirs"][0])["threads"] <= available_cores()


def _finished_trials(storage: str) -> dict[int, tuple]:
    study = load(storage)
    return {t.number: (t.state, t.value, tuple(sorted(t.params.items()))) for t in study.get_trials(states=FINISHED)}


def _trial_numbers(db: Path, states: tuple[str, ...]) -> list[int]:
    """Read-only peek at a study being written (no optuna: it would create tables) -> numbers of trials in ``states``."""
    marks = ", ".join("?" * len(states))
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30) as connection:
            rows = connection.execute(f"SELECT number FROM trials WHERE state IN ({marks})", states).fetchall()
    except sqlite3.OperationalError:  # not created yet
        return []
    return sorted(number for (number,) in rows)


def _count_finished(db: Path) -> int:
    return len(_trial_numbers(db, ("COMPLETE", "PRUNED")))


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
