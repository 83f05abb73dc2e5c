"""sweeps/search/objective.py: a trial's runs, its per-epoch reports and pruning."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState
from searches import load, only_db, run_meta, tiny_search
from user_schedules import command

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


def test_a_run_the_training_layer_refuses_stops_the_search_in_one_line(tmp_path: Path) -> None:
    """A refusal found only when a run starts (here: too little memory) would refuse every trial; Optuna's own
    line on the trial (its value NaN, "not acceptable") is dropped: the one line says why. In an interpreter of
    its own, as users run it: Optuna's log handler writes to the stderr it found first."""
    done = command("sweeps.search.cli:main", ["search.n_trials=3", "ddpg.buffer_size=100000000000",
                                              *tiny_search(tmp_path)], tmp_path, code=2)
    lines = [line for line in done.stderr.splitlines() if not line.startswith("[I ")]  # Optuna's info lines
    assert len(lines) == 1 and lines[0].startswith("hersd-search: error: "), done.stderr
    assert "GiB are available; lower ddpg.buffer_size" in lines[0]
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


def test_a_resumed_run_takes_its_earlier_epochs_from_training_and_reads_no_log(tmp_path: Path, monkeypatch) -> None:
    """A run resumed at epoch 3 of 4: epochs 1-2 come from the records training read (``on_logged``), epochs 3-4
    from those it hands the callback; every step is reported once, with the running AUC; no log is read here."""
    import sys
    from types import ModuleType, SimpleNamespace

    from hersd.contract import runlog
    from hersd.contract.runlog import EPOCH_FIELDS
    from sweeps.search import objective

    success = [0.1, 0.2, 0.4, 0.8]
    records = [{**{name: 0.0 for name in EPOCH_FIELDS}, "epoch": k + 1, "test_success": s}
               for k, s in enumerate(success)]

    def resume_at_3(spec, command="", on_epoch=None, on_logged=None):
        on_logged(records[:2])  # epochs 1-2 were logged by an earlier session
        for record in records[2:]:
            on_epoch(record)
        return tmp_path / "run.mcap"

    reads = []
    monkeypatch.setattr(runlog, "read_messages", lambda *args: reads.append(args))
    monkeypatch.setitem(sys.modules, "hersd.engine.train", ModuleType("hersd.engine.train"))
    sys.modules["hersd.engine.train"].train = resume_at_3
    study = optuna.create_study(direction="maximize")
    trial = study.ask()
    plan = SimpleNamespace(search=SimpleNamespace(metric="test_success", seeds=1), epochs=4, train_overrides=[],
                           study_name="test", base=SimpleNamespace(threads="1"))
    spec = SimpleNamespace(folder=tmp_path, config=SimpleNamespace(seed=0, threads="1"))
    progress = TrialProgress(trial, "auc", epochs=4)
    objective.train_seed(trial, plan, progress, {"kind": "constant", "eps": 0.8}, spec, 0)
    assert reads == []
    assert study.trials[0].intermediate_values == pytest.approx(
        {k: float(np.mean(success[:k])) for k in range(1, 5)})
    assert progress.value() == pytest.approx(np.mean(success))


def test_a_trial_validates_each_runs_config_once_and_reads_no_log(tmp_path: Path, monkeypatch, capsys) -> None:
    """A trial of 2 seeds, trained for real: TrainConfig's checks run once per seed (its draw's config, resolved
    once: folder, identity and rates handed to training), and no log is read back (each epoch's record reaches
    the objective from training); a second search finds both runs complete and reads them through training."""
    from hersd.contract import config, runlog

    from sweeps.search import objective

    search = ["search.n_trials=1", "search.seeds=2", "search.enqueue=[{beta1: 0.5, beta2: 0.0}]",
              *tiny_search(tmp_path, epochs=2)]
    validated, reads = [], []
    post_init, read_messages, trial_runs = config.TrainConfig.__post_init__, runlog.read_messages, objective.trial_runs

    def counted_trial_runs(*args, **kwargs):  # the trial's first step: count from here (the plan is made before)
        monkeypatch.setattr(config.TrainConfig, "__post_init__",
                            lambda self: validated.append(self.seed) or post_init(self))
        monkeypatch.setattr(runlog, "read_messages", lambda *a: reads.append(a) or read_messages(*a))
        return trial_runs(*args, **kwargs)

    monkeypatch.setattr(objective, "trial_runs", counted_trial_runs)
    cli.main(search)
    (trial,) = load(only_db(tmp_path)).trials
    assert trial.state == TrialState.COMPLETE, trial.user_attrs
    assert validated == [0, 1] and reads == []
