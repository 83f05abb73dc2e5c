"""Shared fixtures: tiny run settings, an idle machine, a private temporary folder, folders of synthetic
run logs and study storages. Plain values and functions the tests import are in helpers.py."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from helpers import TINY


@pytest.fixture
def tiny(tmp_path) -> list[str]:
    """TINY overrides writing below this test's temporary folder."""
    return [*TINY, "quiet=true", f"results_dir={tmp_path / 'results'}"]


@pytest.fixture
def idle_machine(monkeypatch):
    """threads=auto sees every core idle (in this process): its thread count no longer depends on
    what else the machine (e.g. another test worker) is doing."""
    from hersd.contract import cores

    monkeypatch.setattr(cores, "idle_cores", lambda seconds=0.0: float(cores.available_cores()))


@pytest.fixture(scope="module")
def private_tempdir(tmp_path_factory):
    """The process's temporary folder is one of pytest's while a module runs: gymnasium-robotics' maze
    envs write their model file (``ant_maze<time>.xml``) beside a temporary directory and never remove it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tempfile, "tempdir", str(tmp_path_factory.mktemp("tempdir")))
        yield


# Folders of synthetic run logs for the tests of analysis/ (their curves: tests/analysis_logs.py).

@pytest.fixture(scope="module")
def hand_sized(tmp_path_factory) -> Path:
    """HER_SUCCESS (5 seeds) and LINEAR_SUCCESS (2 seeds) on push, 6 epochs each."""
    import numpy as np

    from analysis.synthetic import write_run
    from analysis_logs import HER_SUCCESS, LINEAR_SUCCESS, make_config
    from hersd.contract.schedules import Linear

    folder = tmp_path_factory.mktemp("hand_sized")
    for seed, curve in enumerate(HER_SUCCESS):
        write_run(folder / f"her/{seed}", make_config(seed=seed), np.array(curve))
    for seed, curve in enumerate(LINEAR_SUCCESS):
        write_run(folder / f"linear/{seed}", make_config(schedule=Linear(beta1=0.5), seed=seed),
                  np.array(curve))
    return folder


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    """Two tasks x (HER, ARCHER, two decays with each weight, HER-MEP, linear-MEP) x 2 seeds x 8 epochs."""
    import numpy as np

    from analysis.synthetic import write_run
    from analysis_logs import make_config
    from hersd.contract.schedules import Constant, Exponential, Linear

    folder = tmp_path_factory.mktemp("sweep")
    variants = [(Constant(), 1.0, False), (Constant(), 0.5, False), (Constant(), 1.0, True),
                (Linear(beta1=0.5), 1.0, True)]
    variants += [(schedule, lambda_h, False) for lambda_h in (1.0, 0.5)
                 for schedule in (Linear(beta1=0.25), Exponential(beta1=0.5, beta2=0.5))]
    rng = np.random.default_rng(1)
    for task in ("push", "slide"):
        for index, (schedule, lambda_h, mep) in enumerate(variants):
            for seed in range(2):
                config = make_config(task, schedule, seed, epochs=8, lambda_h=lambda_h, mep=mep)
                curve = np.clip(np.linspace(0.0, 1.0, 8) * rng.uniform(0.5, 1.0) + rng.normal(0, 0.05, 8), 0, 1)
                write_run(folder / task / f"{index}-{seed}", config, curve)
    return folder


@pytest.fixture(scope="module")
def push_paper(tmp_path_factory) -> Path:
    """The shape of conf/grid/push_paper.yaml: FetchPush HER, linear b1=0.25 and the constant
    control at the linear schedule's mean rate, 3 seeds x 150 epochs (PUSH_STEPS curves)."""
    from unittest import mock

    import numpy as np

    from analysis.synthetic import write_run
    from analysis_logs import HER_SHARES_150, PUSH_EPOCHS, PUSH_SCHEDULES, PUSH_STEPS, make_config

    folder = tmp_path_factory.mktemp("push_paper")
    with mock.patch("os.fsync"):  # the writer's crash safety is not under test; the bytes are the same
        for label, steps in PUSH_STEPS.items():
            for seed, step in enumerate(steps):
                curve = (np.arange(1, PUSH_EPOCHS + 1) > step).astype(float)
                shares = {}
                if label == "HER":
                    success, hindsight, failure = HER_SHARES_150[seed]
                    shares = dict(share_real_success=np.full(PUSH_EPOCHS, success),
                                  share_hindsight=np.full(PUSH_EPOCHS, hindsight),
                                  share_real_failure=np.full(PUSH_EPOCHS, failure))
                write_run(folder / label / str(seed), make_config(schedule=PUSH_SCHEDULES[label], seed=seed,
                                                                  epochs=PUSH_EPOCHS), curve, **shares)
    return folder


@pytest.fixture(scope="module")
def push_analysis(push_paper) -> "analysis.metrics.Analysis":
    """push_paper analysed with the paper's 50-epoch moving average."""
    from analysis import metrics as analysis_metrics
    from analysis.load import load_runs

    table = load_runs(push_paper)
    return analysis_metrics.analyse(table.runs, table.epochs, window=50)


def _make_study(storage, name: str) -> None:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name=name, storage=storage, direction="maximize")
    study.enqueue_trial({"beta1": 0.25, "beta2": 0.0})
    study.optimize(lambda trial: trial.suggest_float("beta1", 0, 1) + trial.suggest_float("beta2", -1, 1), n_trials=3)


@pytest.fixture(scope="module")
def storages(tmp_path_factory) -> Path:
    """study.db (SQLite, study "in_sqlite"), study.log (journal, "in_journal"), no_study.db (Optuna's
    tables, no study), plain.db (a SQLite file of another program), notes.log (not a journal)."""
    import optuna
    import sqlite3
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    folder = tmp_path_factory.mktemp("storages")
    _make_study(f"sqlite:///{folder / 'study.db'}", "in_sqlite")
    _make_study(JournalStorage(JournalFileBackend(str(folder / "study.log"))), "in_journal")
    optuna.storages.RDBStorage(f"sqlite:///{folder / 'no_study.db'}").remove_session()
    with sqlite3.connect(folder / "plain.db") as connection:
        connection.execute("CREATE TABLE notes (text)")
    (folder / "notes.log").write_text("not a journal\n")
    return folder
