"""Beyond one machine, against real servers started here (tests/servers.py):

* ``hersd-sweep ... hydra/launcher=slurm`` on a one-node SLURM cluster with accounting:
  killed part-way (sweep process and its jobs), re-submitted, no run lost or run twice;
  a failing run is reported and the sweep exits 1;
* ``hersd-search ... search.storage=postgresql+psycopg2://...`` with two workers on one
  PostgreSQL database: SIGKILLed mid-trial, re-run, no complete trial lost or repeated;
  ``hersd-report --storage <url>`` draws the study from the database.

Marked ``cluster`` (deselect with ``-m 'not cluster'``). Without the servers' binaries the
tests skip, naming the Debian packages to install; with CI=true they fail instead.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from hersd.contract.runlog import read_run
from hersd.contract.runstore import RunFolder
from servers import SlurmCluster, postgres_database, slurm_cluster, wait_until

# One xdist worker runs them all: the SLURM cluster is started once per module and owns system paths.
pytestmark = [pytest.mark.cluster, pytest.mark.xdist_group("servers")]

# Tiny FetchReach runs: 0.1-0.5 s per epoch on one core; no bias evaluation (about 8 s each on FetchReach;
# tests/test_bias.py evaluates). EPOCHS is long enough that a run caught in its first EARLY epochs is still
# part-way after the kill lands (submitit's job trains on until SIGKILL, 2 s after scancel): at 16 epochs and
# 4 early ones, a quiet machine finished the rest before it.
TINY = ["task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1", "ddpg.batch_size=64",
        "bias.epochs=[]"]
EPOCHS = 48
EARLY = EPOCHS // 8
COMMAND_TIMEOUT = 240  # seconds for one sweep or search command


@pytest.fixture(scope="module")
def slurm():
    with slurm_cluster() as cluster:
        yield cluster


def slurm_sweep_args(cluster: SlurmCluster, results: Path, *extra: str) -> list[str]:
    """hersd-sweep's arguments for the SLURM preset on the test cluster (1 GB per job: the
    preset's 8 GB would keep jobs pending on a small machine)."""
    return ["+grid=smoke", "hydra/launcher=slurm", f"hydra.launcher.partition={cluster.partition}",
            "hydra.launcher.mem_gb=1", *TINY, *extra, f"results_dir={results}"]


# threads=1 = the preset's cpus_per_task: without it the sweep gives every job the submitting
# machine's core count (see test_slurm_jobs_train_on_their_allocation), 3x slower here.
ONE_THREAD = "threads=1"


def planned_runs(cluster: SlurmCluster, args: list[str]) -> list[Path]:
    """The run directories of a sweep, from its dry run (nothing is submitted)."""
    listing = subprocess.run(["hersd-sweep", *args, "--dry-run"], env=cluster.env, capture_output=True, text=True,
                             check=True, timeout=COMMAND_TIMEOUT).stdout
    return [Path(line.split()[1]) for line in listing.splitlines() if line.startswith("  new ")]


def kill_group(process: subprocess.Popen) -> None:
    """SIGKILL a command started with start_new_session=True and every process of its group."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:  # it had ended, its group with it
        pass
    process.wait(30)


def accounted_jobs(cluster: SlurmCluster) -> dict[str, str]:
    """Job id -> state of every job (array tasks included) in the cluster's accounting database."""
    out = cluster.run("sacct", "-a", "-X", "-n", "-P", "-o", "JobID,State").stdout
    return dict(line.split("|")[:2] for line in out.splitlines() if line)


def test_slurm_sweep_killed_part_way_resubmits_without_loss_or_repeats(slurm: SlurmCluster, tmp_path: Path):
    results = tmp_path / "results"
    args = slurm_sweep_args(slurm, results, f"epochs={EPOCHS}", ONE_THREAD)
    runs = planned_runs(slurm, args)
    assert len(runs) == 4

    # first attempt: killed once a run is complete and another is part-way (it has a checkpoint)
    first_log = tmp_path / "first.log"
    with open(first_log, "w") as output:
        first = subprocess.Popen(["hersd-sweep", *args], env=slurm.env, stdout=output, stderr=subprocess.STDOUT,
                                 start_new_session=True)

    def part_way() -> bool:
        """One run is complete and another has a checkpoint but is far from done: after scancel,
        submitit ignores SIGTERM and the job trains on until SIGKILL (KillWait=2 s later)."""
        if first.poll() is not None:
            raise AssertionError(f"the sweep ended before the kill:\n{first_log.read_text()[-3000:]}")
        states = {run: RunFolder(run).state() for run in runs}
        early = [run for run, state in states.items()
                 if state == "resumable" and len(read_run(run / "run.mcap").epochs) <= EARLY]
        return "complete" in states.values() and bool(early)

    try:
        wait_until(part_way, COMMAND_TIMEOUT, "one complete and one part-way run", (first_log,))
    finally:
        kill_group(first)
        slurm.cancel_all()  # scancel the killed sweep's jobs; waits until they have left the queue
    at_kill = {run: RunFolder(run).state() for run in runs}
    epochs_at_kill = {run: len(read_run(run / "run.mcap").epochs) for run in runs if at_kill[run] == "resumable"}
    finished = {run: (run / "run.mcap").read_bytes() for run in runs if at_kill[run] == "complete"}
    counts = {state: list(at_kill.values()).count(state) for state in ("complete", "resumable", "new")}
    assert counts["complete"] >= 1 and counts["resumable"] >= 1, at_kill
    jobs_before = accounted_jobs(slurm)
    assert "CANCELLED" in " ".join(jobs_before.values()), jobs_before  # the killed attempt's jobs, by sacct

    # second attempt: the same command finishes what is missing and nothing else
    tic = time.monotonic()
    again = subprocess.run(["hersd-sweep", *args], env=slurm.env, capture_output=True, text=True,
                           timeout=COMMAND_TIMEOUT)
    output = again.stdout + again.stderr
    assert again.returncode == 0, output[-3000:]
    assert (f"sweep: 4 runs: {counts['complete']} complete (skipped), {counts['resumable']} to resume, "
            f"{counts['new']} new") in again.stdout
    assert f"{counts['resumable']} resumed, 0 running elsewhere, 0 failed" in again.stdout, output[-3000:]
    # submitit polls sacct: with accounting on, no "Bypassing sacct error" warnings
    assert "Bypassing sacct error" not in output + first_log.read_text() and "Traceback" not in output
    print(f"re-submitted sweep: {time.monotonic() - tic:.0f} s")

    for run in runs:
        log = read_run(run / "run.mcap")
        assert log.complete and list(log.epochs["epoch"]) == list(range(1, EPOCHS + 1)), run
        starts = [session["resumed_from_epoch"] for session in log.sessions]
        if at_kill[run] == "complete":
            assert (run / "run.mcap").read_bytes() == finished[run]  # not run again
            assert starts == [0]
        elif at_kill[run] == "resumable":  # resumed from its checkpoint, not trained again from scratch
            assert len(starts) == 2 and starts[0] == 0 and 0 < starts[1] <= epochs_at_kill[run], (run, starts)
        else:  # had not logged an epoch with a checkpoint: one fresh session
            assert starts == [0], (run, starts)
    sweep_dirs = sorted((results / ".sweeps").iterdir())
    launched = [json.loads(line)["run_dir"] for line in (sweep_dirs[-1] / "progress.jsonl").read_text().splitlines()]
    assert sorted(launched) == sorted(str(run) for run in runs if at_kill[run] != "complete")  # each once

    def new_jobs() -> dict[str, str]:
        return {job: state for job, state in accounted_jobs(slurm).items() if job not in jobs_before}

    # a job ends (and sacct says COMPLETED) a moment after the sweep has read its result
    wait_until(lambda: set(new_jobs().values()) == {"COMPLETED"}, 60, "the jobs to end")
    assert len(new_jobs()) == 4 - counts["complete"], new_jobs()

    # third time: everything is complete, nothing is submitted
    done = subprocess.run(["hersd-sweep", *args], env=slurm.env, capture_output=True, text=True,
                          timeout=COMMAND_TIMEOUT)
    assert done.returncode == 0 and "sweep: 4 runs: 4 complete (skipped)" in done.stdout
    assert not slurm.job_ids() and len(accounted_jobs(slurm)) == len(jobs_before) + 4 - counts["complete"]


def test_slurm_sweep_reports_a_failed_run(slurm: SlurmCluster, tmp_path: Path):
    results = tmp_path / "results"
    args = slurm_sweep_args(slurm, results, "schedule=constant", "epochs=2", ONE_THREAD)
    # seed 1's run directory is blocked by a file, so that run (only) fails in its SLURM job
    (blocked,) = [run for run in planned_runs(slurm, args) if run.name.startswith("seed1-")]
    blocked.parent.mkdir(parents=True)
    blocked.write_text("in the way")

    result = subprocess.run(["hersd-sweep", *args], env=slurm.env, capture_output=True, text=True,
                            timeout=COMMAND_TIMEOUT)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "1 done" in result.stdout and "1 failed" in result.stdout
    (failed,) = [line for line in result.stdout.splitlines() if line.startswith("  failed: ")]
    assert "seed=1" in failed and str(blocked) in failed  # the run's overrides and the cause
    assert "hersd-sweep: error: 1 run(s) failed" in result.stderr and "Traceback" not in result.stderr
    (log,) = results.rglob("run.mcap")
    assert read_run(log).complete and "/seed0-" in str(log)


def test_slurm_jobs_train_on_their_allocation(slurm: SlurmCluster, tmp_path: Path):
    args = slurm_sweep_args(slurm, tmp_path, "schedule=constant", "seeds=1", "epochs=1")
    result = subprocess.run(["hersd-sweep", *args], env=slurm.env, capture_output=True, text=True,
                            timeout=COMMAND_TIMEOUT)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    (log,) = tmp_path.rglob("run.mcap")
    assert read_run(log).meta["threads"] == 1  # the preset's cpus_per_task


# --------------------------------------------------------------------------- PostgreSQL
def test_search_on_postgresql_survives_a_killed_worker(tmp_path: Path):
    import optuna
    from optuna.storages import RDBStorage
    from optuna.trial import TrialState

    n_trials, epochs = 4, 4
    results = tmp_path / "results"
    with postgres_database() as url:
        args = ["search=ci", "task=reach", *TINY, f"epochs={epochs}", f"search.n_trials={n_trials}", "search.n_jobs=2",
                "search.pruner.kind=none", f"search.storage={url}", f"results_dir={results}"]
        first_log = tmp_path / "first.log"
        with open(first_log, "w") as output:
            first = subprocess.Popen(["hersd-search", *args], stdout=output, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        study: list[optuna.Study] = []

        def mid_trial() -> bool:
            """True once both workers have taken trials, one trial is complete and another is
            RUNNING with an epoch reported and at least 2 to go, so that the kill lands mid-trial
            (and every RUNNING trial names its worker: one killed before that stays RUNNING until
            search.stale_after_minutes, since nothing tells whose it was)."""
            if first.poll() is not None:
                raise AssertionError(f"the search ended before the kill:\n{first_log.read_text()[-3000:]}")
            if not study:
                started = [line.split()[1] for line in first_log.read_text().splitlines() if line.startswith("study ")]
                if not started:
                    return False  # the study's tables exist once this line is printed
                storage = RDBStorage(url, skip_table_creation=True)
                study.append(optuna.load_study(study_name=started[0], storage=storage))
            trials = study[0].get_trials(deepcopy=False)
            running = [t for t in trials if t.state == TrialState.RUNNING]
            workers = {t.user_attrs.get("worker") for t in trials} - {None}
            mid_way = [t for t in running if t.intermediate_values and max(t.intermediate_values) <= epochs - 2]
            return (any(t.state == TrialState.COMPLETE for t in trials) and bool(mid_way)
                    and all("worker" in t.user_attrs for t in running) and len(workers) == 2)

        tic = time.monotonic()
        try:
            wait_until(mid_trial, COMMAND_TIMEOUT, "a complete trial and a running one", (first_log,))
        finally:
            kill_group(first)  # the search and both of its worker processes
        before = {t.number: (t.value, t.params) for t in study[0].get_trials(states=(TrialState.COMPLETE,))}
        reported = {t.number: max(t.intermediate_values, default=0) for t in study[0].get_trials(
            states=(TrialState.RUNNING,)) if "worker" in t.user_attrs}  # a reported epoch has its checkpoint
        killed = sorted(reported)
        assert before and killed, first_log.read_text()[-2000:]

        print(f"search killed after {time.monotonic() - tic:.0f} s")
        tic = time.monotonic()
        again = subprocess.run(["hersd-search", *args], capture_output=True, text=True, timeout=COMMAND_TIMEOUT)
        print(f"search re-run: {time.monotonic() - tic:.0f} s")
        assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
        assert f"re-enqueued the parameters of lost trials {sorted(killed)}" in again.stdout

        trials = study[0].get_trials()
        complete = [t for t in trials if t.state == TrialState.COMPLETE]
        assert {t.number: (t.value, t.params) for t in complete if t.number in before} == before  # none lost
        assert len(complete) == n_trials
        params = [tuple(sorted(t.params.items())) for t in complete]
        assert len(set(params)) == n_trials  # none repeated
        assert sorted(t.number for t in trials if "lost" in t.user_attrs) == sorted(killed)
        retries = {t.user_attrs["retry_of"]: t for t in complete if "retry_of" in t.user_attrs}
        assert sorted(retries) == killed  # each lost trial re-run once
        assert any(reported.values())
        for number, epoch in reported.items():
            if epoch:  # it had finished an epoch: the retry resumed its run from the checkpoint
                (run,) = retries[number].user_attrs["run_dirs"]
                starts = [session["resumed_from_epoch"] for session in read_run(Path(run) / "run.mcap").sessions]
                # (epoch + 1: logged and checkpointed, not yet reported; [0]: it had just completed)
                assert starts in ([0, epoch], [0, epoch + 1]) or (starts == [0] and epoch >= epochs - 1), starts

        # the report draws the study from the database
        tic = time.monotonic()
        report = subprocess.run(["hersd-report", str(results), "--storage", url], capture_output=True, text=True,
                                timeout=COMMAND_TIMEOUT)
        assert report.returncode == 0, report.stdout[-2000:] + report.stderr[-2000:]
        print(f"report: {time.monotonic() - tic:.0f} s")
        figure = results / "report" / "search" / f"{study[0].study_name}_beta_plane.png"
        assert figure.is_file() and figure.stat().st_size > 0, report.stdout[-2000:]
        assert "Optuna searches" in (results / "report" / "index.html").read_text()
