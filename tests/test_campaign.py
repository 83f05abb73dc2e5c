"""hersd-campaign: the stage plan, status and land on synthetic logs, start's single instance,
the runner's stage order, bad input. No training: the sweeps are planned or replaced by stand-ins."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from analysis.synthetic import write_run
from hersd.config import TrainConfig
from hersd.runlog import read_records
from hersd.runstore import policy_animation, run_lock
from sweeps import campaign

SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]


@pytest.fixture(scope="module")
def plan(tmp_path_factory) -> list[campaign.PlannedRun]:
    """The push_paper campaign's runs (their paths below a results dir do not depend on it)."""
    return campaign.plan_runs(campaign.load_campaign("push_paper"), tmp_path_factory.mktemp("campaign"))


def write_log(directory: Path, epochs_done: int, complete: bool) -> Path:
    """A synthetic 200-epoch run's log holding ``epochs_done`` epochs."""
    with mock.patch("os.fsync"):  # the writer's crash safety is not under test
        return write_run(directory, TrainConfig(epochs=200), np.linspace(0, 1, epochs_done), complete=complete)


def run_overrides(run: campaign.PlannedRun, results: Path) -> list[str]:
    """The run's one-run sweep command line for the results dir ``results``."""
    return [f"results_dir={results}" if o.startswith("results_dir=") else o for o in run.overrides]


def test_stages_add_seeds_evenly_and_each_run_is_planned_once(plan):
    runs = plan
    assert len({run.relative for run in runs}) == len(runs) == 20
    by_stage = [[(run.arm.removeprefix("push/her/"), run.seed) for run in runs if run.stage == stage]
                for stage in (1, 2, 3, 4)]
    assert by_stage[0] == [(arm, seed) for seed in range(3) for arm in ("constant-0.8", "linear-b1_0.25")]
    assert by_stage[1] == [("constant-0.874375", seed) for seed in range(3)]
    assert by_stage[2] == [("success-b1_0.25-w10", seed) for seed in range(3)]
    assert by_stage[3] == [(arm, seed) for seed in (3, 4) for arm in ("constant-0.8", "linear-b1_0.25")] + \
        [(arm, seed) for arm in ("constant-0.874375", "success-b1_0.25-w10") for seed in (3, 4)]
    # seeds 0-2 of stage 4's grids were planned before: HER and linear 0.25 (the acceptance's 5 seeds) first
    assert {run.epochs for run in runs} == {200}


def test_the_plan_is_hersd_sweeps_own(plan, tmp_path):
    """Each stage's runs are the directories `hersd-sweep ... --dry-run` lists, in its order, with
    the overrides it gives each; those overrides alone make a one-run sweep of the same run."""
    results, runs = tmp_path / "results", plan
    listed: dict[Path, str] = {}
    for stage in campaign.load_campaign("push_paper"):
        for sweep in stage.sweeps:
            out = subprocess.run([*SWEEP, *sweep, f"results_dir={results}", "--dry-run"], capture_output=True,
                                 text=True, check=True, timeout=300).stdout
            for line in out.splitlines():
                if line.startswith("  new "):
                    directory, overrides = line.removeprefix("  new").strip().split("  [")
                    listed.setdefault(Path(directory), overrides.removesuffix("]"))
    assert list(listed) == [results / run.relative for run in runs]
    assert [listed[results / run.relative] for run in runs] == [" ".join(run_overrides(run, results)) for run in runs]
    alone = run_overrides(runs[7], results)  # the control, seed 1: a sweep's job, not the sweep's first
    out = subprocess.run([*SWEEP, *alone, "--dry-run"], capture_output=True, text=True, check=True,
                         timeout=300).stdout
    assert out.splitlines()[-2:] == ["sweep: 1 runs: 0 complete (skipped), 0 to resume, 1 new",
                                     f"  new       {results / runs[7].relative}  [{' '.join(alone)}]"]


def test_status_shows_complete_in_progress_training_and_new_runs(plan, tmp_path, capsys):
    results, runs = tmp_path / "results", plan
    write_log(results / runs[0].relative, 200, complete=True)
    write_log(results / runs[1].relative, 3, complete=False)
    write_log(results / runs[2].relative, 7, complete=False)
    with run_lock(results / runs[2].relative):  # as a training process holds it
        assert campaign.main(["status", "--results-dir", str(results)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"campaign push_paper in {results}: not running; process(es) {os.getpid()} train runs here"
    rows = [line.split(maxsplit=3) for line in lines[2:-1]]
    assert [(int(stage), arm, int(seed)) for stage, arm, seed, _ in rows] == [(r.stage, r.arm, r.seed) for r in runs]
    assert [state for *_, state in rows[:4]] == ["complete", "epoch 3 of 200",  # 45 s per synthetic epoch:
                                                 f"epoch 7 of 200, training (pid {os.getpid()}), 45 s per epoch, "
                                                 f"~2.4 h to go", "new"]  # 193 x 45 s
    assert lines[-1] == "20 planned runs: 1 complete, 2 in progress, 17 new; 1 training now"


def test_pace_is_the_recent_epoch_time_and_the_time_to_go(tmp_path):
    assert campaign.pace(write_log(tmp_path / "late", 195, complete=False), 200) == "45 s per epoch, ~4 min to go"
    assert campaign.pace(write_log(tmp_path / "early", 20, complete=False), 200) == "45 s per epoch, ~2.2 h to go"
    assert campaign.pace(tmp_path / "none" / "run.mcap", 200) == ""


def test_land_copies_every_started_log_and_replaces_older_copies(plan, tmp_path, capsys):
    results, runs = tmp_path / "results", plan
    complete = write_log(results / runs[0].relative, 200, complete=True)
    running = write_log(results / runs[1].relative, 3, complete=False)
    (running.parent / "checkpoint.pt").write_bytes(b"not landed")
    animation = policy_animation(complete.parent, 200)
    animation.parent.mkdir()
    animation.write_bytes(b"GIF89a a policy")
    into = tmp_path / "repo" / "results"
    assert campaign.main(["land", "--results-dir", str(results), "--into", str(into)]) == 0
    out = capsys.readouterr().out
    assert f"landed    {into / runs[0].relative / 'run.mcap'}  complete" in out
    assert f"landed    {into / runs[1].relative / 'run.mcap'}  epoch 3 of 200" in out
    assert "3 file(s) landed" in out and "git add -- " in out
    landed = sorted(p.relative_to(into) for p in into.rglob("*") if p.is_file())
    assert landed == sorted([runs[0].relative / "run.mcap", runs[0].relative / "policy" / "epoch_200.gif",
                             runs[1].relative / "run.mcap"])  # no checkpoint, no temp
    assert (into / runs[0].relative / "run.mcap").read_bytes() == complete.read_bytes()

    write_log(results / runs[1].relative, 5, complete=False)  # the run went on
    stale = policy_animation(into / runs[1].relative, 150)  # drawn by an earlier attempt, which restarted
    stale.parent.mkdir()
    stale.write_bytes(b"GIF89a another policy")
    assert campaign.main(["land", "--results-dir", str(results), "--into", str(into)]) == 0
    out = capsys.readouterr().out
    assert f"unchanged {into / runs[0].relative / 'run.mcap'}  complete" in out
    assert f"landed    {into / runs[1].relative / 'run.mcap'}  epoch 5 of 200" in out
    assert f"removed   {stale}" in out and "1 file(s) landed in" in out and ", 1 removed; commit them" in out
    assert len(read_records(into / runs[1].relative / "run.mcap").records) == 5
    assert not stale.exists() and policy_animation(into / runs[0].relative, 200).exists()


def test_land_never_replaces_a_complete_log_with_an_unfinished_one(plan, tmp_path, capsys):
    """A run imported complete from another machine and trained here as well: land keeps the complete log."""
    results, into, runs = tmp_path / "results", tmp_path / "repo" / "results", plan
    imported = write_log(into / runs[0].relative, 200, complete=True)
    kept = imported.read_bytes()
    write_log(results / runs[0].relative, 4, complete=False)
    assert campaign.main(["land", "--results-dir", str(results), "--into", str(into)]) == 0
    out = capsys.readouterr().out
    assert f"kept      {imported}  complete (the campaign's copy: epoch 4 of 200)" in out
    assert "0 file(s) landed" in out and imported.read_bytes() == kept
    write_log(results / runs[0].relative, 200, complete=True)  # finished here too: a complete log replaces it
    assert campaign.main(["land", "--results-dir", str(results), "--into", str(into)]) == 0
    assert f"landed    {imported}  complete" in capsys.readouterr().out
    assert imported.read_bytes() == (results / runs[0].relative / "run.mcap").read_bytes() != kept


MADE_ELSEWHERE = {"command": "hersd-sweep task=push seed=0 schedule=constant +grid=push_paper seeds=3",
                  "git_commit": "0123abc", "start_time": "2026-11-24T01:02:03+0000",
                  "machine": {"cpu_model": "Other CPU", "cpu_cores": 8}}


def test_import_takes_in_the_complete_logs_of_the_plan_made_elsewhere_and_nothing_else(plan, tmp_path, capsys):
    """Logs found anywhere below the source folder: a complete log of a planned run made by hersd-sweep is
    copied (with its animation) and its provenance printed; every other log is named with the reason."""
    runs, source, into = plan, tmp_path / "shared" / "campaign", tmp_path / "repo" / "results"
    other = source / "machine-b" / "results"  # any layout above the run folders
    with mock.patch("os.fsync"):
        good = write_run(other / runs[0].relative, runs[0].config, np.linspace(0, 1, 200), meta=MADE_ELSEWHERE)
        unfinished = write_run(source / runs[1].relative, runs[1].config, np.linspace(0, 1, 3), complete=False,
                               meta=MADE_ELSEWHERE)
        other_config = write_run(source / runs[2].relative, replace(runs[2].config, seed=9),
                                 np.linspace(0, 1, 200), meta=MADE_ELSEWHERE)
        by_hand = write_run(source / runs[3].relative, runs[3].config, np.linspace(0, 1, 200))
        short = write_run(source / runs[4].relative, runs[4].config, np.linspace(0, 1, 150), meta=MADE_ELSEWHERE)
        unplanned = write_run(source / runs[0].relative.with_name("seed0-0badf00d"), runs[0].config,
                              np.linspace(0, 1, 200), meta=MADE_ELSEWHERE)
        twice = write_run(source / runs[5].relative, runs[5].config, np.linspace(0, 1, 200), meta=MADE_ELSEWHERE)
        ours = write_run(into / runs[5].relative, runs[5].config, np.linspace(0, 0.5, 200))
        finished_there = write_run(source / runs[7].relative, runs[7].config, np.linspace(0, 1, 200),
                                   meta=MADE_ELSEWHERE)
        write_run(into / runs[7].relative, runs[7].config, np.linspace(0, 1, 9), complete=False)  # ours, midway
    damaged = source / runs[6].relative / "run.mcap"
    damaged.parent.mkdir(parents=True)
    damaged.write_bytes(b"not a log")
    animation = policy_animation(good.parent, 200)
    animation.parent.mkdir()
    animation.write_bytes(b"GIF89a a policy")

    assert campaign.main(["import", str(source), "--into", str(into)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert f"imported  {into / runs[0].relative / 'run.mcap'}  from {good}: made on Other CPU (8 cores), " \
           f"commit 0123abc, started 2026-11-24T01:02:03+0000: {MADE_ELSEWHERE['command']}" in lines
    assert f"rejected  {unfinished}: not complete (epoch 3 of 200)" in lines
    assert any(line.startswith(f"rejected  {other_config}: its config is not the plan's (hash ") for line in lines)
    assert f"rejected  {by_hand}: not made by hersd-sweep or hersd-train (command 'analysis.synthetic')" in lines
    assert f"rejected  {short}: 150 epochs, the plan has 200" in lines
    assert f"rejected  {unplanned}: not a run of campaign push_paper (its folder names no planned run)" in lines
    assert f"rejected  {twice}: kept {ours}, a complete log of the run already there" in lines
    assert any(line.startswith(f"rejected  {damaged}: unreadable (") for line in lines)
    assert any(line.startswith(f"imported  {into / runs[7].relative / 'run.mcap'}  from {finished_there}: ")
               for line in lines)  # a complete log replaces an unfinished one
    assert lines[-2] == f"9 log(s) found in {source}; 3 file(s) written to {into}; commit them with:"
    written = sorted(p.relative_to(into) for p in into.rglob("*") if p.is_file())
    assert written == sorted([runs[0].relative / "run.mcap", runs[0].relative / "policy" / "epoch_200.gif",
                              runs[5].relative / "run.mcap", runs[7].relative / "run.mcap"])
    assert (into / runs[0].relative / "run.mcap").read_bytes() == good.read_bytes()
    assert (into / runs[7].relative / "run.mcap").read_bytes() == finished_there.read_bytes()

    assert campaign.main(["import", str(source), "--into", str(into)]) == 0  # again: nothing new
    out = capsys.readouterr().out
    assert f"unchanged {into / runs[0].relative / 'run.mcap'}  from {good}" in out
    assert out.splitlines()[-1] == f"9 log(s) found in {source}; 0 file(s) written to {into}"


def test_import_from_a_missing_folder_is_one_line_and_exit_2(tmp_path, capsys):
    assert campaign.main(["import", str(tmp_path / "none"), "--into", str(tmp_path / "results")]) == 2
    assert capsys.readouterr().err == (f"hersd-campaign: error: no folder {tmp_path / 'none'}; "
                                       "pass the folder holding the other machine's logs\n")
    assert not (tmp_path / "results").exists()


def test_run_reuses_the_complete_runs_landed_in_the_repository_and_nothing_else(plan, tmp_path, monkeypatch,
                                                                                capfd):
    """A fresh machine: complete runs already in the repository's results folder are copied in
    (log and animations) rather than trained again; a run under way, an unfinished landed log
    and a log whose config does not match its folder are left to the sweeps."""
    monkeypatch.setattr(campaign, "SWEEP", [sys.executable, "-c", "pass"])
    results, landed, runs = tmp_path / "results", tmp_path / "repo" / "results", plan
    with mock.patch("os.fsync"):
        reusable = write_run(landed / runs[0].relative, runs[0].config, np.linspace(0, 1, 200))
        write_run(landed / runs[1].relative, runs[1].config, np.linspace(0, 1, 200))
        write_run(landed / runs[2].relative, runs[2].config, np.linspace(0, 1, 3), complete=False)
        write_run(landed / runs[3].relative, replace(runs[3].config, seed=9), np.linspace(0, 1, 200))
    animation = policy_animation(reusable.parent, 200)
    animation.parent.mkdir()
    animation.write_bytes(b"GIF89a a policy")
    under_way = write_log(results / runs[1].relative, 3, complete=False)
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(landed)]) == 0
    assert f"1 complete run(s) landed in {landed} reused, not trained again: {runs[0].relative}" \
        in capfd.readouterr().out
    assert (results / runs[0].relative / "run.mcap").read_bytes() == reusable.read_bytes()
    assert policy_animation(results / runs[0].relative, 200).read_bytes() == b"GIF89a a policy"
    assert len(read_records(under_way).records) == 3
    assert not (results / runs[2].relative).exists() and not (results / runs[3].relative).exists()
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(landed)]) == 0
    assert "reused" not in capfd.readouterr().out  # once copied, a run is the results folder's own


def test_start_detaches_one_campaign_and_refuses_a_second(tmp_path, monkeypatch, capsys):
    # The runner replaced by a sleeper whose command line names the campaign module, as the runner's does.
    monkeypatch.setattr(campaign, "RUNNER", [sys.executable, "-c", "import time; time.sleep(120)", "sweeps.campaign"])
    started = []
    real_popen = subprocess.Popen
    monkeypatch.setattr(subprocess, "Popen", lambda *a, **k: started.append(real_popen(*a, **k)) or started[-1])
    results = tmp_path / "results"
    try:
        assert campaign.main(["start", "--results-dir", str(results)]) == 0
        pid = int((results / campaign.PID_NAME).read_text())
        assert f"started in the background: pid {pid}, log {results / 'campaign.log'}" in capsys.readouterr().out
        assert started[0].pid == pid and os.getsid(pid) == pid  # detached: a session of its own
        assert started[0].args[-2:] == ["--landed", str(Path("results").absolute())]
        assert campaign.main(["start", "--results-dir", str(results)]) == 0
        assert f"campaign already running for {results} (pid {pid})" in capsys.readouterr().out
        assert len(started) == 1
    finally:
        for process in started:
            process.kill()
            process.wait()
    assert campaign.campaign_pid(results) is None  # a pid file naming an ended process does not count


def test_a_started_campaign_of_complete_runs_runs_every_stage_and_ends(plan, tmp_path, monkeypatch, capsys):
    """The real detached runner on a results dir whose runs are all complete: nothing trains,
    the log says so, the pid file goes."""
    results = tmp_path / "results"
    for run in plan:
        write_log(results / run.relative, 200, complete=True)
    started = []
    real_popen = subprocess.Popen
    monkeypatch.setattr(subprocess, "Popen", lambda *a, **k: started.append(real_popen(*a, **k)) or started[-1])
    assert campaign.main(["start", "--results-dir", str(results)]) == 0
    assert started[0].wait(timeout=300) == 0
    log = (results / "campaign.log").read_text()
    assert "20 planned runs: 20 complete, 0 to train" in log and "campaign: training " not in log
    assert "campaign push_paper finished: every stage done" in log
    assert not (results / campaign.PID_NAME).exists()
    capsys.readouterr()
    assert campaign.main(["status", "--results-dir", str(results)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "20 planned runs: 20 complete, 0 in progress, 0 new"


def test_start_leaves_runs_being_trained_by_another_process_alone(plan, tmp_path, capsys):
    results, runs = tmp_path / "results", plan
    (results / runs[5].relative).mkdir(parents=True, exist_ok=True)
    with run_lock(results / runs[5].relative):
        assert campaign.main(["start", "--results-dir", str(results)]) == 1
    assert f"being trained by process(es) {os.getpid()}" in capsys.readouterr().out
    assert not (results / campaign.PID_NAME).exists()


def test_the_runner_keeps_jobs_runs_training_in_plan_order_across_stages(plan, tmp_path, monkeypatch, capfd):
    """Every run not complete is trained as its own one-run sweep, in plan order, ``--jobs`` at a
    time on cores/jobs threads each: a run starts as soon as one ends, also across a stage's end."""
    events = tmp_path / "events"
    stand_in = ("import sys, time; events = open(sys.argv[1], 'a'); run = sys.argv[-1]; "
                "events.write(f'start {run}\\n'); events.flush(); time.sleep(1.0 if 'seed=2' in sys.argv else 0.05); "
                "events.write(f'end {run}\\n'); print('sweep', *sys.argv[2:])")
    monkeypatch.setattr(campaign, "SWEEP", [sys.executable, "-c", stand_in, str(events)])
    monkeypatch.setattr(campaign, "POLL_SECONDS", 0.02)
    monkeypatch.setattr(campaign, "available_cores", lambda: 4)
    results, runs = tmp_path / "results", plan
    for run in runs[:5]:  # complete: not trained again
        write_log(results / run.relative, 200, complete=True)
    write_log(results / runs[5].relative, 3, complete=False)  # interrupted: resumed by its sweep
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(tmp_path / "none"), "--jobs", "2"]) == 0
    out = capfd.readouterr().out
    assert "hersd-campaign: 20 planned runs: 5 complete, 15 to train, 2 at a time" in out
    said = [line.split("hersd-campaign: training ", 1)[1] for line in out.splitlines() if "campaign: training " in line]
    commands = {run.relative: [*run_overrides(run, results), "threads=2"] for run in runs[5:]}  # 4 cores / 2 jobs
    assert said == [f"{relative}: hersd-sweep {' '.join(command)}" for relative, command in commands.items()]
    launched = sorted(line.removeprefix("sweep ") for line in out.splitlines() if line.startswith("sweep "))
    sweeps_dir = results / ".sweeps" / re.search(r"/\.sweeps/(\d{8}-\d{6})/", out).group(1)  # one per start
    assert launched == sorted(" ".join([*command, f"hydra.sweep.dir={sweeps_dir / relative}"])
                              for relative, command in commands.items())
    assert "stage 2/4: the control (constant 0.874375), seeds 0-2" in out
    assert "campaign push_paper finished: every stage done" in out and not (results / campaign.PID_NAME).exists()
    at_once, most, overlapped = set(), 0, []
    for kind, run in (line.split(" ", 1) for line in events.read_text().splitlines()):
        at_once.add(run) if kind == "start" else at_once.discard(run)
        most = max(most, len(at_once))
        overlapped.append(set(at_once))
    assert most == 2
    last_of_stage_2 = str(sweeps_dir / runs[8].relative)  # the control, seed 2 (slow stand-in)
    first_of_stage_3 = str(sweeps_dir / runs[9].relative)
    assert {f"hydra.sweep.dir={last_of_stage_2}", f"hydra.sweep.dir={first_of_stage_3}"} in overlapped
    # one at a time: one run on every core
    assert campaign.main(["run", "--results-dir", str(tmp_path / "other"), "--landed", str(tmp_path / "none"),
                          "--jobs", "1"]) == 0
    said = [line for line in capfd.readouterr().out.splitlines() if "campaign: training " in line]
    assert len(said) == 20 and all(line.endswith(" threads=4") for line in said)


def test_commit_lands_each_run_the_moment_it_completes_and_commits_it_alone(plan, tmp_path, monkeypatch, capfd):
    """--commit: a run whose sweep ends complete is copied into the repository and committed with
    its animation, the user's staged work left staged; an unfinished or failed run is not landed."""
    results, repo, runs = tmp_path / "results", tmp_path / "repo", plan
    landed = repo / "results"
    staging = tmp_path / "made"  # what each stand-in sweep "trains": a complete log, or one of 3 epochs
    for index, run in enumerate(runs[:4]):
        log = write_log(staging / run.relative, 200 if index != 1 else 3, complete=index != 1)
        if index == 0:
            animation = policy_animation(log.parent, 200)
            animation.parent.mkdir()
            animation.write_bytes(b"GIF89a a policy")
    for run in runs[4:]:
        write_log(results / run.relative, 200, complete=True)
    stand_in = ("import shutil, sys; args = dict(a.split('=', 1) for a in sys.argv[2:]); "
                "relative = args['hydra.sweep.dir'].split('/.sweeps/', 1)[1].split('/', 1)[1]; "
                "shutil.copytree(f'{sys.argv[1]}/{relative}', f\"{args['results_dir']}/{relative}\"); "
                "sys.exit(3 if 'seed=1' in sys.argv and 'schedule=constant' in sys.argv else 0)")
    monkeypatch.setattr(campaign, "SWEEP", [sys.executable, "-c", stand_in, str(staging)])
    monkeypatch.setattr(campaign, "POLL_SECONDS", 0.02)
    git = lambda *a: subprocess.run(["git", *a], cwd=repo, check=True, capture_output=True, text=True).stdout
    repo.mkdir()
    git("init", "-q")
    git("config", "user.email", "ci@example.org")
    git("config", "user.name", "CI")
    (repo / "notes.txt").write_text("work of the user's, staged\n")
    git("add", "notes.txt")
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(landed), "--commit"]) == 1
    out = capfd.readouterr().out
    commits = set()
    for commit in git("log", "--format=%H").split():
        subject, _, *files = git("show", "--format=%s", "--name-only", commit).strip().split("\n")
        commits.add((subject, tuple(sorted(files))))
    assert commits == {
        (f"campaign: {runs[0].relative} complete (200 epochs), landed by hersd-campaign",
         (f"results/{runs[0].relative}/policy/epoch_200.gif", f"results/{runs[0].relative}/run.mcap")),
        (f"campaign: {runs[3].relative} complete (200 epochs), landed by hersd-campaign",
         (f"results/{runs[3].relative}/run.mcap",))}
    assert (landed / runs[0].relative / "run.mcap").read_bytes() == (results / runs[0].relative / "run.mcap").read_bytes()
    assert not (landed / runs[1].relative).exists()  # unfinished when its sweep ended
    assert not (landed / runs[2].relative).exists()  # its sweep failed (HER seed 1)
    assert git("diff", "--cached", "--name-only") == "notes.txt\n"  # still staged, not committed
    assert f"landed {runs[0].relative} in {landed} and committed it" in out
    # outside a git work tree: landed all the same, and the line says how to commit
    for run in runs[:4]:
        shutil.rmtree(results / run.relative)
    elsewhere = tmp_path / "plain" / "results"
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(elsewhere), "--commit"]) == 1
    out = capfd.readouterr().out
    assert (elsewhere / runs[3].relative / "run.mcap").exists()
    assert f"landed {runs[3].relative} in {elsewhere}, not committed (git add: " in out
    assert "commit it with: git add -- " in out


def test_a_failed_run_is_reported_and_the_others_go_on(plan, tmp_path, monkeypatch, capfd):
    monkeypatch.setattr(campaign, "SWEEP", [sys.executable, "-c", "import sys; sys.exit('seed=1' in sys.argv)"])
    monkeypatch.setattr(campaign, "POLL_SECONDS", 0.02)
    results = tmp_path / "results"
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(tmp_path / "none")]) == 1
    out = capfd.readouterr().out
    assert out.count("campaign: training ") == 20
    failed = [str(run.relative) for run in plan if run.seed == 1]
    assert f"failed: {failed[0]} (hersd-sweep exit 1; see above)" in out
    assert f"campaign push_paper finished; failed: {', '.join(failed)} (hersd-campaign start retries them)" in out


def test_an_interrupted_runner_lets_its_runs_end_then_says_how_to_resume(tmp_path, monkeypatch, capfd):
    """Ctrl-C while two runs train: the runner waits up to STOP_SECONDS for each (a run saves its
    last epoch and ends on the same Ctrl-C), stops those still running, says how to resume, exit 130."""
    stand_in = "import sys, time; time.sleep(0.3 if 'schedule=constant' in sys.argv else 60)"  # HER ends, linear not
    monkeypatch.setattr(campaign, "SWEEP", [sys.executable, "-c", stand_in])
    monkeypatch.setattr(campaign, "STOP_SECONDS", 3.0)
    started = []
    real_popen = subprocess.Popen
    monkeypatch.setattr(subprocess, "Popen", lambda *a, **k: started.append(real_popen(*a, **k)) or started[-1])

    real_sleep, calls = time.sleep, []

    def interrupt_once(seconds: float) -> None:  # the runner's first wait is cut short by Ctrl-C
        calls.append(seconds)
        if len(calls) == 1:
            raise KeyboardInterrupt
        real_sleep(seconds)

    monkeypatch.setattr(campaign.time, "sleep", interrupt_once)
    results = tmp_path / "results"
    assert campaign.main(["run", "--results-dir", str(results), "--landed", str(tmp_path / "none"), "--jobs", "2"]) == 130
    assert [process.returncode for process in started] == [0, -signal.SIGTERM]
    assert "interrupted; finished runs and epochs are kept: hersd-campaign start resumes the campaign" in \
        capfd.readouterr().out
    assert not (results / campaign.PID_NAME).exists()


@pytest.mark.parametrize("arguments, message", [
    (["stop"], "invalid choice: 'stop'"),
    (["status", "--campaign", "nope"], "unknown campaign 'nope'; choose one of: push_paper"),
    (["start", "--results-dir", "{blocker}/sub"], "cannot create"),
    (["start", "--jobs", "0"], "argument --jobs: must be a whole number >= 1, got '0'"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, arguments, message):
    (tmp_path / "blocker").write_text("a file, not a folder")
    arguments = [a.replace("{blocker}", str(tmp_path / "blocker")) for a in arguments]
    try:
        code = campaign.main(arguments)
    except SystemExit as exited:
        code = exited.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err


def test_status_into_a_reader_that_stops_early_ends_quietly(tmp_path):
    """`hersd-campaign status | head -1`: the reader closes the pipe early; no traceback."""
    read_end, write_end = os.pipe()
    os.close(read_end)  # a reader already gone: the first write meets a closed pipe
    status = subprocess.run([sys.executable, "-m", "sweeps.campaign", "status", "--results-dir", str(tmp_path)],
                            stdout=write_end, stderr=subprocess.PIPE, text=True)
    os.close(write_end)
    assert status.returncode == 141 and status.stderr == ""
