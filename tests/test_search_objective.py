"""sweeps/search/objective.py: a trial's runs, its per-epoch reports and pruning."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState
from searches import fails_with, load, only_db, run_meta, tiny_search

from hersd.contract.cores import available_cores
from hersd.contract.runlog import read_run
from sweeps.search import cli
from sweeps.search.objective import TrialProgress


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


def test_a_resumed_run_reads_its_log_once_and_then_takes_each_epochs_record(tmp_path: Path, monkeypatch) -> None:
    """A run resumed at epoch 3 of 4: epochs 1-2 come from its log, once; epochs 3-4 from the records
    training hands the callback; every step is reported once, with the running AUC."""
    import sys
    from types import ModuleType, SimpleNamespace

    from hersd.contract.runlog import EPOCH_FIELDS, RunLogWriter
    from sweeps.search import objective

    success = [0.1, 0.2, 0.4, 0.8]
    records = [{**{name: 0.0 for name in EPOCH_FIELDS}, "epoch": k + 1, "test_success": s}
               for k, s in enumerate(success)]
    log_path = tmp_path / "run" / "run.mcap"
    log_path.parent.mkdir()

    def resume_at_3(cfg, command="", on_epoch=None):
        writer = RunLogWriter(log_path, {"run_id": "resumed"})
        for record in records:
            writer.write_epoch(record)
            if record["epoch"] >= 3:  # epochs 1-2 were logged by an earlier session
                on_epoch(record)
        writer.finish(len(records))
        return log_path

    reads = []
    read_log = objective.metric_values
    monkeypatch.setattr(objective, "metric_values", lambda *args: reads.append(args[2:]) or read_log(*args))
    monkeypatch.setitem(sys.modules, "hersd.engine.train", ModuleType("hersd.engine.train"))
    sys.modules["hersd.engine.train"].train = resume_at_3
    study = optuna.create_study(direction="maximize")
    trial = study.ask()
    plan = SimpleNamespace(search=SimpleNamespace(metric="test_success", seeds=1), epochs=4, train_overrides=[],
                           study_name="test", base=SimpleNamespace(threads="1"))
    cfg = SimpleNamespace(run_dir=str(log_path.parent), seed=0, threads="1")
    progress = TrialProgress(trial, "auc", epochs=4)
    objective.train_seed(trial, plan, progress, {"kind": "constant", "eps": 0.8}, cfg, 0)
    assert reads == [(2,), ()]  # the epochs before the resume, then the whole log once at the end
    assert study.trials[0].intermediate_values == pytest.approx(
        {k: float(np.mean(success[:k])) for k in range(1, 5)})
    assert progress.value() == pytest.approx(np.mean(success))
