"""analysis/load.py: every run log under a folder -> runs and epochs tables; labels, identities, damaged,
resumed and old logs, reading in worker processes."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import load, metrics, workers
from analysis.figures import config_styles
from analysis.load import config_label, load_runs
from analysis.report import main as report_main
from analysis.synthetic import epoch_records, write_run
from hersd.contract.config import config_record
from hersd.contract.runlog import RunLogWriter, read_run
from hersd.contract.runstore import config_hash
from hersd.contract.schedules import Constant, Cosine, Exponential, Linear, Success

from analysis_logs import WINDOW, make_config


def test_one_row_per_run_and_epoch_with_config_columns(hand_sized):
    table = load_runs(hand_sized)
    assert len(table.runs) == 7 and len(table.epochs) == 42
    assert not table.skipped
    row = table.epochs[(table.epochs["config"] == "linear b1=0.5") & (table.epochs["epoch"] == 6)].iloc[0]
    assert (row["task"], row["schedule"], row["beta1"], row["total_epochs"], row["complete"]) == ("push", "linear", 0.5, 6, True)
    assert row["relabel_rate"] == pytest.approx(0.5)
    assert row["mu_eps"] == pytest.approx(1 - 0.5 * 21 / 36)


@pytest.mark.parametrize("settings, label", [
    ((Constant(eps=0.8), 1.0, 1.0, False), "HER"),
    ((Constant(eps=0.8), 1.0, 0.5, False), "HER λh=0.5"),  # ARCHER by its name only
    ((Constant(eps=0.8), 1.0, 1.0, True), "HER-MEP"),
    ((Constant(eps=0.9), 1.0, 1.0, False), "HER eps=0.9"),
    ((Linear(beta1=0.25), 1.0, 1.0, False), "linear b1=0.25"),
    ((Exponential(beta1=0.5, beta2=-0.5), 1.0, 0.5, False), "exp b1=0.5 b2=-0.5 λh=0.5"),
    ((Linear(beta1=0.5), 1.0, 1.0, True), "linear b1=0.5-MEP"),
    ((Cosine(start=1.0, end=0.5), 1.0, 1.0, False), "cosine 1→0.5"),
    ((Constant(eps=0.8), 1.0, 1.0, False, "td3"), "TD3 HER"),
    # a learner class without a NAME of its own is recorded by its path and labelled by its class name
    ((Constant(eps=0.8), 1.0, 1.0, False, "user_late.TD3Late"), "TD3Late HER"),
    ((Linear(beta1=0.25), 1.0, 1.0, False, "my_pkg.learners.Late", 4), "Late linear b1=0.25 K=4"),
])
def test_config_labels(settings, label):
    assert config_label(*settings) == label


def test_the_run_list_names_the_cpu_a_log_records(tmp_path):
    write_run(tmp_path / "new", make_config(), np.zeros(6), meta={"machine": {"cpu_model": "AMD EPYC", "cpu_cores": 2}})
    write_run(tmp_path / "old", make_config(seed=1), np.zeros(6))  # a log from before the machine was recorded
    assert load_runs(tmp_path).runs.set_index("path")["cpu"].to_dict() == {"new/run.mcap": "AMD EPYC",
                                                                           "old/run.mcap": ""}


def test_runs_sharing_a_label_but_not_their_k_are_labelled_by_k(tmp_path):
    write_run(tmp_path / "a", make_config(epochs=4), np.zeros(4))
    write_run(tmp_path / "b", make_config(epochs=6), np.zeros(6))
    write_run(tmp_path / "c", make_config(seed=1, epochs=6), np.zeros(6))
    labels = load_runs(tmp_path).runs.groupby("config", observed=True)["seed"].apply(list).to_dict()
    assert labels == {"HER K=4": [0], "HER K=6": [0, 1]}


def test_the_papers_k_keeps_its_label_beside_other_ks(tmp_path):
    """HER at K = 200 stays ``HER`` (docs/RESULTS.md and analysis/claims.py quote it) beside HER at K = 4."""
    write_run(tmp_path / "paper", make_config(epochs=load.PAPER_EPOCHS), np.zeros(3), complete=False)
    write_run(tmp_path / "smoke", make_config(task="reach", epochs=4), np.zeros(4))
    runs = load_runs(tmp_path).runs.set_index("path")
    assert runs["config"].astype(str).to_dict() == {"paper/run.mcap": "HER", "smoke/run.mcap": "HER K=4"}


def test_runs_sharing_a_label_and_k_but_not_a_config_are_told_apart(tmp_path):
    write_run(tmp_path / "a", make_config(), np.zeros(6))
    other = make_config(seed=1)
    other.task.cycles_per_epoch += 1
    write_run(tmp_path / "b", other, np.zeros(6))
    labels = set(load_runs(tmp_path).runs["config"])
    assert labels == {f"HER (task.cycles_per_epoch={n})" for n in (other.task.cycles_per_epoch - 1,
                                                                    other.task.cycles_per_epoch)}


def test_a_log_made_before_fields_existed_shares_the_configuration_of_new_logs(tmp_path):
    write_run(tmp_path / "new", make_config(seed=1), np.zeros(6))
    config = config_record(make_config())
    for key in ("learner", "threads", "device"):  # fields added to the schema after runs were made
        del config[key]
    for key in ("window", "eps_min"):
        del config["schedule"][key]
    (tmp_path / "old").mkdir()
    writer = RunLogWriter(tmp_path / "old" / "run.mcap", {
        "run_id": config_hash(config), "config": config, "seed": 0, "versions": {}, "command": "old",
        "start_time": "2024-01-01T00:00:00+0000", "resumed_from_epoch": 0})
    for record in epoch_records(make_config(), np.zeros(6)):
        writer.write_epoch(record)
    writer.finish(6)
    assert config_hash(config) == config_hash(make_config())
    assert list(load_runs(tmp_path).runs["config"]) == ["HER", "HER"]


def test_a_label_spans_tasks_at_one_k_only_and_lookalikes_get_distinct_styles(tmp_path):
    write_run(tmp_path / "reach", make_config(task="reach", epochs=4), np.zeros(4))
    write_run(tmp_path / "push20", make_config(epochs=20), np.zeros(20))
    write_run(tmp_path / "push30", make_config(epochs=30), np.zeros(30))
    table = load_runs(tmp_path)
    labels = table.runs.groupby(["task", "config"], observed=True)["run"].count().to_dict()
    assert labels == {("reach", "HER K=4"): 1, ("push", "HER K=20"): 1, ("push", "HER K=30"): 1}
    assert metrics.analyse(table.runs, table.epochs, WINDOW).aggregate["total_epochs"].tolist() == [4, 20, 30]
    styles = config_styles(metrics.analyse(table.runs, table.epochs, WINDOW))
    looks = {(style["color"], str(style["linestyle"])) for style in styles.values()}
    assert len(looks) == len(styles) == 3


def _truncate_inside_epoch(path: Path, epoch: int) -> None:
    """Cut the file in the middle of the given epoch's message, as a killed writer leaves it."""
    data = path.read_bytes()
    cut = data.index(b'{"epoch": %d,' % epoch) + 8
    path.write_bytes(data[:cut])


def test_truncated_log_keeps_complete_epochs_and_garbage_is_skipped(tmp_path, capsys):
    path = write_run(tmp_path / "cut", make_config(), np.linspace(0, 1, 6))
    _truncate_inside_epoch(path, 4)
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "run.mcap").write_bytes(b"not an mcap file" * 10)
    table = load_runs(tmp_path)
    run = table.runs.iloc[0]
    assert (run["epochs_done"], run["complete"], run["damaged"]) == (3, False, True)
    assert table.epochs["epoch"].tolist() == [1, 2, 3]
    assert table.epochs["test_success"].tolist() == pytest.approx([0.0, 0.2, 0.4])
    assert table.skipped == ["garbage/run.mcap: not a hersd run log (no run metadata found)"]

    assert report_main([str(tmp_path), "--smooth", "2"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    # the terminal names every log skipped or damaged, not only the page (the damaged one was named nowhere else)
    assert err == ["warning: skipped unreadable log garbage/run.mcap: not a hersd run log (no run metadata found)",
                   "warning: damaged log cut/run.mcap: read its 3 epochs before the damage"]


def test_a_label_is_one_setup_across_tasks_but_for_the_tasks_own_settings(tmp_path):
    """The aggregate table pools a label's tasks: HER on push at another actor_lr than HER on slide is two
    labels, each naming its value; a task's own settings (task.*: its budget per epoch) keep one label."""
    import dataclasses
    for seed in (0, 1):
        push = make_config(seed=seed)
        push = dataclasses.replace(push, ddpg=dataclasses.replace(push.ddpg, actor_lr=0.01))
        slide = make_config(task="slide", seed=seed)
        pick = make_config(task="pick_and_place", seed=seed)
        pick = dataclasses.replace(pick, task=dataclasses.replace(pick.task, cycles_per_epoch=7))
        for name, config in (("push", push), ("slide", slide), ("pick", pick)):
            write_run(tmp_path / f"{name}{seed}", config, np.linspace(0, 1, 6))
    runs = load_runs(tmp_path).runs
    labels = runs.groupby("task", observed=True)["config"].agg(lambda names: set(names.astype(str)))
    assert labels.to_dict() == {"push": {"HER (ddpg.actor_lr=0.01)"}, "slide": {"HER (ddpg.actor_lr=0.001)"},
                                "pick_and_place": {"HER (ddpg.actor_lr=0.001)"}}


def test_a_folder_of_unreadable_logs_only_says_why_in_its_one_line(tmp_path, capsys):
    for name in ("empty", "garbage"):
        (tmp_path / name).mkdir()
    (tmp_path / "empty" / "run.mcap").write_bytes(b"")
    (tmp_path / "garbage" / "run.mcap").write_bytes(b"not an mcap file" * 10)
    assert report_main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"hersd-report: error: none of the 2 run.mcap files under {tmp_path}")
    assert "(empty/run.mcap: " in err[0] and "; and 1 more)" in err[0] and err[0].endswith("hersd run logs")
    assert not (tmp_path / "report").exists()


def test_loaded_epochs_of_complete_truncated_and_resumed_logs(tmp_path):
    """Each completed epoch counts once: a truncated log up to its damage, a resumed run's
    rewritten epoch with its later value."""
    write_run(tmp_path / "complete", make_config(epochs=6), np.linspace(0, 1, 6))
    truncated = write_run(tmp_path / "truncated", make_config(epochs=6, seed=1), np.linspace(0, 1, 6))
    _truncate_inside_epoch(truncated, 5)
    config = make_config(epochs=6, seed=2)
    resumed = write_run(tmp_path / "resumed", config, np.linspace(0, 0.5, 4), complete=False)
    previous = read_run(resumed)
    writer = RunLogWriter(resumed, {**previous.meta, "resumed_from_epoch": 3}, previous=previous)
    for record in epoch_records(config, np.linspace(0.1, 1.0, 6))[3:]:  # epoch 4 again, then 5 and 6
        writer.write_epoch(record)
    writer.finish(6)
    table = load_runs(tmp_path)
    runs = table.runs.set_index(table.runs["path"].str.split("/").str[0])
    assert runs.loc[["complete", "truncated", "resumed"], ["epochs_done", "complete", "damaged"]].values.tolist() == [
        [6, True, False], [4, False, True], [6, True, False]]
    resumed_epochs = table.epochs[table.epochs["path"] == "resumed/run.mcap"]
    assert resumed_epochs["epoch"].tolist() == [1, 2, 3, 4, 5, 6]
    assert resumed_epochs["test_success"].iloc[3] == pytest.approx(0.64)  # the rewrite, not 0.5


def test_learners_lead_their_labels_and_success_schedules_sit_at_their_realised_mean_rate(tmp_path):
    from hersd.contract.config import LearnerConfig

    curve = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    write_run(tmp_path / "ddpg", make_config(), curve)
    td3 = make_config()
    td3.learner = LearnerConfig(name="td3")
    write_run(tmp_path / "td3", td3, curve)
    success = make_config(schedule=Success(beta1=0.5, window=1))
    write_run(tmp_path / "success", success, curve)
    runs = load_runs(tmp_path).runs.set_index("config")
    assert list(runs.index) == ["HER", "success b1=0.5", "TD3 HER"]  # DDPG first, schedules in their order
    assert runs.loc["TD3 HER", "learner"] == "td3" and runs.loc["HER", "learner"] == "ddpg"
    logged = read_run(tmp_path / "success" / "run.mcap").epochs["relabel_rate"]
    assert list(logged) == pytest.approx([1.0, 1.0, 0.91, 0.82, 0.73, 0.64])  # 1 - 0.5 * last epoch's train success
    assert runs.loc["success b1=0.5", "mu_eps"] == pytest.approx(logged.mean())


def test_logs_read_in_worker_processes_give_the_same_tables(sweep, monkeypatch, tmp_path):
    here = load_runs(sweep)  # 32 logs: fewer than load.PARALLEL_FROM, read in this process
    monkeypatch.setattr(load, "PARALLEL_FROM", 2)
    monkeypatch.setattr(workers, "available_cores", lambda: 2)  # forks on a 1-core machine too
    read_log = load.read_log

    def read_log_noting_the_process(path, folder):
        (tmp_path / str(os.getpid())).touch()  # a file: a forked reader's note outlives it
        return read_log(path, folder)

    monkeypatch.setattr(load, "read_log", read_log_noting_the_process)
    forked = load_runs(sweep)
    readers = {int(note.name) for note in tmp_path.iterdir()}
    assert readers and os.getpid() not in readers  # every log read in another process
    pd.testing.assert_frame_equal(forked.runs, here.runs)
    pd.testing.assert_frame_equal(forked.epochs, here.epochs)


def test_copies_of_one_run_count_once_the_complete_or_longest_read(tmp_path, capsys):
    """A copied run folder is the same run (run_id, first session), not another seed: one is read, the copies
    named one line per top folder; a run of the same config and seed trained apart is named as that."""
    config = make_config(epochs=6)
    write_run(tmp_path / "a_partial", config, np.linspace(0, 0.5, 4), complete=False)
    write_run(tmp_path / "b_run", config, np.linspace(0, 1, 6))
    for copy in ("c1", "c2"):
        write_run(tmp_path / "c_backup" / copy, config, np.linspace(0, 1, 6))
    write_run(tmp_path / "d_again", config, np.linspace(0, 1, 6), meta={"start_time": "2025-02-01T00:00:00+0000"})
    write_run(tmp_path / "e_other_seed", make_config(epochs=6, seed=1), np.linspace(0, 1, 6))
    table = load_runs(tmp_path)
    assert sorted(table.runs["path"]) == ["b_run/run.mcap", "e_other_seed/run.mcap"]
    assert len(table.epochs) == 12 and not table.skipped and table.left_out == 4
    assert table.copies == [
        f"d_again/run.mcap: another run of the config and seed of b_run/run.mcap (run {table.runs['run_id'][0]}), "
        "trained apart; that one is read, this one left out: report their folders apart to compare them",
        "a_partial/run.mcap: a copy of b_run/run.mcap (the one read), left out",
        "c_backup/: 2 run logs copying runs read elsewhere (e.g. c_backup/c1/run.mcap, a copy of b_run/run.mcap), "
        "left out"]
    assert report_main([str(tmp_path), "--smooth", "2", "--out", str(tmp_path / "report")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"warning: {line}" for line in table.copies]
    assert "c_backup/: 2 run logs copying runs" in (tmp_path / "report" / "index.html").read_text()


def test_a_schedule_class_gone_from_its_module_is_one_warning_saying_to_give_it_back(tmp_path, monkeypatch, capsys):
    """The log names a class its module no longer has (renamed): the fix is the class, not PYTHONPATH or an --out."""
    write_run(tmp_path / "her", make_config(), np.zeros(6))
    record = config_record(make_config())
    record["schedule"] = {"kind": "renamed_steps_load.Step", "k0": 3}
    write_run(tmp_path / "step", make_config(seed=1), np.zeros(6), meta={"config": {**record, "seed": 1}})
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "renamed_steps_load.py").write_text("class NewStep:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    assert report_main([str(tmp_path), "--smooth", "2", "--out", str(tmp_path / "report")]) == 0
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == ("warning: schedule class renamed_steps_load.Step cannot be imported (module 'renamed_steps_load' "
                    "has no attribute 'Step'): 1 run log reported from its logged rates and labelled from the log "
                    "(step/run.mcap); give its module that class again (the log names it as it was) for the class's "
                    "own label and a check of its rates")


def test_a_schedule_module_that_fails_to_import_is_one_warning_saying_to_fix_it(tmp_path, monkeypatch, capsys):
    """A SyntaxError in the class's module was a traceback that stopped the report; then its runs were skipped.
    They are reported from their logs, labelled from their records, with one line saying how to get the class's."""
    write_run(tmp_path / "her", make_config(), np.zeros(6))
    record = config_record(make_config())
    record["schedule"] = {"kind": "broken_steps_load.Step", "k0": 3}
    write_run(tmp_path / "step", make_config(seed=1), np.zeros(6), meta={"config": {**record, "seed": 1}})
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "broken_steps_load.py").write_text("class Step(\n")
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    assert report_main([str(tmp_path), "--smooth", "2", "--out", str(tmp_path / "report")]) == 0
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("warning: schedule class broken_steps_load.Step: importing broken_steps_load raised "
                           "SyntaxError")
    assert line.endswith("1 run log reported from its logged rates and labelled from the log (step/run.mcap); "
                         "fix that module for the class's own label and a check of its rates")
    runs = load_runs(tmp_path).runs.set_index("path")
    assert runs.loc["step/run.mcap", "config"] == "step k0=3" and runs.loc["step/run.mcap", "schedule"] == \
        "broken_steps_load.Step"


def test_a_bf16_run_gets_its_own_configuration_and_hers_label_stays_plain(tmp_path):
    """precision=bf16 runs of HER beside fp32 ones: ``HER`` stays the fp32 runs' label (analysis/claims.py
    looks it up), the others are ``HER precision=bf16``; no seed of one is pooled with the other."""
    write_run(tmp_path / "fp32", make_config(epochs=load.PAPER_EPOCHS), np.zeros(3), complete=False)
    bf16 = make_config(seed=1, epochs=load.PAPER_EPOCHS)
    bf16.precision = "bf16"
    write_run(tmp_path / "bf16", bf16, np.zeros(3), complete=False)
    runs = load_runs(tmp_path).runs.set_index("path")
    assert runs["config"].astype(str).to_dict() == {"fp32/run.mcap": "HER", "bf16/run.mcap": "HER precision=bf16"}


@pytest.mark.parametrize("algo, lambda_h, mep, label", [
    ("archer", 0.5, False, "ARCHER"), ("archer_mep", 0.5, True, "ARCHER-MEP"), ("archer", 0.25, False, "ARCHER λh=0.25"),
    ("her", 0.5, False, "HER λh=0.5"),
])
def test_archer_is_recognised_by_its_logged_name_and_its_weights_read_from_its_preset(algo, lambda_h, mep, label):
    assert load.ARCHER_WEIGHTS == (1.0, 0.5)  # conf/algo/archer.yaml
    assert config_label(Constant(eps=0.8), 1.0, lambda_h, mep, algo=algo) == label


# A newcomer's step schedule as its runs were made (eps 0.9 at epoch 1, 0.5 after: k <= k0) and as edited since
# (k < k0: 0.5 at every epoch), in a module of its own per test (a module is imported once per process).
EDITED_STEP = '''
from dataclasses import dataclass

from hersd.contract.schedules import Schedule, param


@dataclass
class KStep(Schedule):
    high: float = param(0.9, 0.0, 1.0, "the rate until epoch k0")
    low: float = param(0.5, 0.0, 1.0, "the rate after epoch k0")
    k0: int = param(1, 1, 100, "the last epoch at the high rate", integer=True)

    def rate(self, k, total_epochs, train_success=()):
        return self.high if k {compare} self.k0 else self.low
'''


def _write_step_runs(folder: Path, module: str, epochs: int = 2) -> None:
    """Two complete seeds of ``<module>.KStep`` (K = ``epochs``) whose logs recorded 0.9 then 0.5, a HER seed, and
    a third KStep seed in progress at epoch 1 of 3."""
    write_run(folder / "her", make_config(epochs=epochs), np.zeros(epochs))
    for seed, total, done in ((0, epochs, epochs), (1, epochs, epochs), (2, 3, 1)):
        record = config_record(make_config(seed=seed, epochs=total))
        record["schedule"] = {"kind": f"{module}.KStep", "high": 0.9, "low": 0.5, "k0": 1}
        write_run(folder / f"step{seed}", make_config(seed=seed, epochs=total), np.zeros(done), complete=done == total,
                  meta={"config": record, "run_id": f"step{seed}"}, relabel_rate=np.array([0.9, 0.5, 0.5][:done]))


def _rates_of(table, config: str) -> list[float]:
    curves = metrics.schedule_curves(table.runs, table.epochs)
    return curves.loc[curves["configs"] == config, "eps"].tolist()


def test_rates_and_mu_eps_come_from_the_log_and_an_edited_class_is_one_warning_per_configuration(tmp_path,
                                                                                                 monkeypatch):
    """The class was edited after its runs (<= became <): the report drew them as a flat 0.5 and gave mu_eps 0.5,
    silently, though their logs recorded 0.9 then 0.5 (issue 68, item 1)."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "edited_steps_load.py").write_text(EDITED_STEP.replace("{compare}", "<"))
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    _write_step_runs(tmp_path / "runs", "edited_steps_load")
    table = load_runs(tmp_path / "runs")
    steps = table.runs[table.runs["schedule"] == "edited_steps_load.KStep"].set_index("path")
    assert steps.loc[["step0/run.mcap", "step1/run.mcap"], "mu_eps"].tolist() == [0.7, 0.7]
    assert np.isnan(steps.loc["step2/run.mcap", "mu_eps"])  # in progress, its class not giving its rates: unknown
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=2") == [0.9, 0.5]
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=3") == [0.9]  # the class's rates are not drawn
    assert table.rate_mismatches == [
        "configuration kstep high=0.9 low=0.5 k0=1 K=2: schedule class edited_steps_load.KStep today gives other rates "
        "than 2 of its logs (step0/run.mcap, epoch 1: logged 0.9, class 0.5); the report uses the logged rates",
        "configuration kstep high=0.9 low=0.5 k0=1 K=3: schedule class edited_steps_load.KStep today gives other "
        "rates than 1 of its logs (step2/run.mcap, epoch 1: logged 0.9, class 0.5); the report uses the logged rates"]
    assert all(line in table.warnings() for line in table.rate_mismatches)


def test_a_class_that_gives_the_logged_rates_completes_the_curve_of_a_run_in_progress(tmp_path, monkeypatch):
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "kept_steps_load.py").write_text(EDITED_STEP.replace("{compare}", "<="))
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    _write_step_runs(tmp_path / "runs", "kept_steps_load")
    table = load_runs(tmp_path / "runs")
    assert not table.rate_mismatches
    steps = table.runs.set_index("path")
    assert steps.loc["step2/run.mcap", "mu_eps"] == pytest.approx(1.9 / 3)  # 0.9 logged, then the class's 0.5, 0.5
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=3") == [0.9, 0.5, 0.5]


def test_runs_whose_class_cannot_be_imported_are_reported_from_their_logs(tmp_path):
    """Without the module on PYTHONPATH the report skipped these runs, though their logs hold every rate."""
    _write_step_runs(tmp_path, "gone_steps_load")
    table = load_runs(tmp_path)
    steps = table.runs[table.runs["schedule"] == "gone_steps_load.KStep"].set_index("path")
    assert len(steps) == 3 and table.left_out == 0
    assert steps["config"].astype(str).tolist() == ["kstep high=0.9 low=0.5 k0=1 K=2"] * 2 + ["kstep high=0.9 low=0.5 "
                                                                                          "k0=1 K=3"]
    assert steps["schedule_tag"].iloc[0] == "kstep-high_0.9-low_0.5-k0_1"
    assert steps.loc[["step0/run.mcap", "step1/run.mcap"], "mu_eps"].tolist() == [0.7, 0.7]
    assert not steps["adaptive"].any()  # its seeds' logs agree: a fixed schedule
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=2") == [0.9, 0.5]
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=3") == [0.9]  # the logged epoch alone
    (line,) = table.missing_schedules
    assert line.startswith("schedule class gone_steps_load.KStep cannot be imported") and "3 run logs reported" in line
    analysis = metrics.analyse(table.runs, table.epochs, window=1)
    assert "kstep high=0.9 low=0.5 k0=1 K=2" in set(analysis.summary["config"])


def test_a_schedule_module_that_exits_as_it_is_imported_is_one_warning_not_the_reports_end(tmp_path, monkeypatch):
    """A module calling sys.exit() at import (a script) ended the report silently with its exit status, or, with
    the logs read in worker processes, hung it. Its runs are reported from their logs, with the fix-it line."""
    write_run(tmp_path / "her", make_config(), np.zeros(6))
    record = config_record(make_config())
    record["schedule"] = {"kind": "exiting_steps_load.Step", "k0": 3}
    write_run(tmp_path / "step", make_config(seed=1), np.zeros(3), complete=False,  # in progress: its curve asks
              meta={"config": {**record, "seed": 1}})                               # the class for epochs to come
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "exiting_steps_load.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    table = load_runs(tmp_path)
    (line,) = table.missing_schedules
    assert line.startswith("schedule class exiting_steps_load.Step: importing exiting_steps_load raised SystemExit: 3")
    assert line.endswith("fix that module for the class's own label and a check of its rates")
    assert table.runs.set_index("path").loc["step/run.mcap", "config"] == "step k0=3"
    lines = metrics.schedule_curves(table.runs, table.epochs)  # Fig. 1
    assert lines.loc[lines["line"].str.contains("step k0=3"), "epoch"].tolist() == [1, 2, 3]  # the logged epochs
    assert report_main([str(tmp_path), "--smooth", "2", "--out", str(tmp_path / "report")]) == 0  # its figures too


@pytest.mark.parametrize("module, edit, why", [
    ("renamed_setting_load", ("k0", "k1"), "the log's k0: no setting of it; its k1: not in the log"),
    ("added_setting_load", ("    def rate", "    floor: float = param(0.0, 0.0, 1.0, \"the lowest rate\")\n\n"
                                           "    def rate"), "its floor: not in the log"),
])
def test_a_class_whose_settings_changed_since_its_runs_labels_them_from_the_log_in_one_warning(tmp_path, monkeypatch,
                                                                                              module, edit, why):
    """k0 renamed k1 (default 1, the same rates): the runs were labelled ``kstep ... k1=1``, a setting they never
    had, k0 dropped in silence, and the class's rates completed the run in progress (issue 68, item 1)."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / f"{module}.py").write_text(EDITED_STEP.replace("{compare}", "<=").replace(*edit))
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    _write_step_runs(tmp_path / "runs", module)
    table = load_runs(tmp_path / "runs")
    steps = table.runs[table.runs["schedule"] == f"{module}.KStep"].set_index("path")
    assert steps["config"].astype(str).tolist() == ["kstep high=0.9 low=0.5 k0=1 K=2"] * 2 + ["kstep high=0.9 low=0.5 "
                                                                                          "k0=1 K=3"]
    assert np.isnan(steps.loc["step2/run.mcap", "mu_eps"])  # in progress: the class's rates are not its
    assert _rates_of(table, "kstep high=0.9 low=0.5 k0=1 K=3") == [0.9]
    assert table.missing_schedules == [
        f"schedule class {module}.KStep does not take the logged settings high=0.9 low=0.5 k0=1 ({why}): 3 run logs "
        "reported from their logged rates and labelled from the log (step0/run.mcap and others); make its class "
        "accept the logged settings for the class's own label and a check of its rates"]


@pytest.mark.parametrize("module, method, line", [
    ("raising_label_load", "\n    def label(self):\n        raise ValueError(\"label boom\")\n",
     "schedule class raising_label_load.KStep: its label() raised ValueError: label boom: 3 run logs reported from "
     "their logged rates and labelled from the log (step0/run.mcap and others); fix that class for the class's own "
     "label and a check of its rates"),
    ("refusing_step_load", "\n    def __post_init__(self):\n        if self.k0 < 2:\n            raise ValueError("
                           "\"k0 must be >= 2\")\n",
     "schedule class refusing_step_load.KStep refuses the logged settings high=0.9 low=0.5 k0=1 (ValueError: k0 "
     "must be >= 2): 3 run logs reported from their logged rates and labelled from the log (step0/run.mcap and "
     "others); make its class accept the logged settings for the class's own label and a check of its rates"),
], ids=["label_raises", "post_init_refuses"])
def test_a_class_whose_label_raises_or_that_refuses_its_logged_settings_labels_its_runs_from_the_log(
        tmp_path, monkeypatch, module, method, line):
    """A ``label()`` that raises, or a check added to ``__post_init__`` since the runs (k0 >= 2): its runs were
    skipped as unreadable logs ("run metadata lacks or mistypes a config field (label boom)")."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / f"{module}.py").write_text(EDITED_STEP.replace("{compare}", "<=") + method)
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    _write_step_runs(tmp_path / "runs", module)
    table = load_runs(tmp_path / "runs")
    assert table.left_out == 0 and not table.skipped
    steps = table.runs[table.runs["schedule"] == f"{module}.KStep"]
    assert set(steps["config"].astype(str)) == {"kstep high=0.9 low=0.5 k0=1 K=2", "kstep high=0.9 low=0.5 k0=1 K=3"}
    assert table.missing_schedules == [line]


def test_a_folder_named_run_mcap_is_no_log(tmp_path):
    """It was skipped as ``b/run.mcap: .../b/run.mcap/run.mcap: cannot open``, naming a path that does not exist."""
    write_run(tmp_path / "a", make_config(), np.zeros(2))
    (tmp_path / "b" / "run.mcap").mkdir(parents=True)
    assert load.find_logs(tmp_path) == [tmp_path / "a" / "run.mcap"]
    table = load_runs(tmp_path)
    assert len(table.runs) == 1 and not table.skipped and table.left_out == 0
