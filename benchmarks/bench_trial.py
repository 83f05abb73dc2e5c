"""Cost of a search trial's per-epoch callback over a 200-epoch run, without training.

:func:`sweeps.search.objective.train_seed` runs one seed of a trial; after each logged epoch its
callback beats the trial's heartbeat, reports the running objective to Optuna (a study in
SQLite, as searches store by default, or in memory: the callback's own work without the
database's) and asks the median pruner. Here ``train`` is
replaced by a stand-in that writes ``--epochs`` synthetic records (a committed log's first
record with epoch and test_success changed) through :class:`hersd.contract.runlog.RunLogWriter`, as
training does, calling the callback after each; only the callback's time is counted.

Printed for each storage: milliseconds per callback at epochs 1, 50, 100, 150, 200, the mean,
and the total over the run, in wall-clock and in this process's CPU time (the SQLite study's
wall-clock is mostly its commits' disk syncs). The callback once re-read the trial's whole log every epoch (a cost growing with the
epoch, so K^2 over the run); it now takes the record it is handed. To measure the earlier code,
run this with ``PYTHONPATH`` set to a checkout of it.

Measured on 2 cores busy with a training campaign (load ~6), 200 epochs, CPU time: with the
study in memory, the callback's own work went from 0.7 ms at epoch 1 growing to 6.2 ms at epoch
200 (0.75 s over the run) to a flat 0.2 ms (0.05 s); with SQLite, 3.1 s -> 2.2 s over the run,
whose wall-clock (11-24 s either way) is the database's commits and varies with the disk's load.

Usage: python benchmarks/bench_trial.py [--epochs 200] [--log results/.../run.mcap]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace

import numpy as np
import optuna

from hersd.contract.runlog import RunLogWriter, read_records

REPOSITORY = Path(__file__).resolve().parent.parent
DEFAULT_LOG = REPOSITORY / "results/push/her/constant-0.8/seed0-64e236fe/run.mcap"


def synthetic_records(template: dict, epochs: int) -> list[dict]:
    """``epochs`` records shaped as ``template``: epoch 1..K, test_success rising from 0 to 0.9."""
    return [{**template, "epoch": k, "test_success": round(0.9 * k / epochs, 4)} for k in range(1, epochs + 1)]


def stand_in_train(meta: dict, records: list[dict], seconds: list[tuple[float, float]]):
    """A ``train`` that logs ``records`` as training does and times each ``on_epoch`` (wall, CPU) into ``seconds``."""
    def train(cfg, command: str = "", on_epoch=None) -> Path:
        log_path = Path(cfg.run_dir) / "run.mcap"
        writer = RunLogWriter(log_path, meta)
        for record in records:
            writer.write_epoch(record)
            tic, cpu = time.perf_counter(), time.process_time()
            on_epoch(record)
            seconds.append((time.perf_counter() - tic, time.process_time() - cpu))
        writer.finish(len(records))
        writer.close()
        return log_path
    return train


def callback_seconds(log: Path, epochs: int, folder: Path, storage: str | None) -> np.ndarray:
    """Seconds of each epoch's callback of one seed's ``train_seed`` -> shape (epochs, 2): wall, CPU."""
    from sweeps.search.objective import TrialProgress, train_seed

    raw = read_records(log)
    seconds: list[tuple[float, float]] = []
    sys.modules["hersd.engine.train"] = ModuleType("hersd.engine.train")  # the stand-in, without torch or MuJoCo
    sys.modules["hersd.engine.train"].train = stand_in_train(raw.meta, synthetic_records(raw.records[0], epochs), seconds)
    study = optuna.create_study(storage=storage, direction="maximize",
                                pruner=optuna.pruners.MedianPruner(n_startup_trials=0, n_warmup_steps=0))
    trial = study.ask()
    plan = SimpleNamespace(search=SimpleNamespace(metric="test_success", seeds=1), epochs=epochs,
                           train_overrides=[], study_name="bench", base=SimpleNamespace(threads="1"))
    cfg = SimpleNamespace(run_dir=str(folder / "run"), seed=0, threads="1")
    (folder / "run").mkdir()
    train_seed(trial, plan, TrialProgress(trial, "auc", epochs), {"kind": "constant", "eps": 0.8}, cfg, 0)
    return np.array(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=200)
    parser.add_argument("--log", type=Path, default=DEFAULT_LOG, help="a committed log: its meta and first record")
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    marks = [1, *range(50, args.epochs + 1, 50)]
    for name in ("sqlite", "memory"):
        with tempfile.TemporaryDirectory() as folder:
            storage = f"sqlite:///{Path(folder) / 'study.db'}" if name == "sqlite" else None
            seconds = callback_seconds(args.log, args.epochs, Path(folder), storage) * 1e3
        for column, clock in enumerate(("wall", "CPU")):
            at = ", ".join(f"{k}: {seconds[k - 1, column]:.1f}" for k in marks)
            print(f"{name:<6} {clock:<4} ms per callback at epoch {at}; mean {seconds[:, column].mean():.1f} ms, "
                  f"total {seconds[:, column].sum() / 1e3:.2f} s over {args.epochs} epochs")

if __name__ == "__main__":
    main()
