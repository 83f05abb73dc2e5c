"""hersd-sweep end to end: grids, dry runs, the smoke sweep, kill and re-run, bad input."""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import group_alive, killed_while_training

from hersd.contract.cores import available_cores
from hersd.contract.runlog import read_run
from hersd.contract.runstore import RunFolder

SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]
TINY = ["task.cycles_per_epoch=2", "ddpg.batches_per_cycle=5", "ddpg.test_rollouts=1", "ddpg.batch_size=64",
        "render_every=0", "bias.epochs=[]"]


def sweep(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run([*SWEEP, *args], capture_output=True, text=True, check=check, timeout=600)


def listed_runs(output: str) -> list[str]:
    return [line.split()[1] for line in output.splitlines() if line.startswith("  new ")]


def test_beta_grid_lists_300_runs_without_running_them(tmp_path):
    result = sweep("+grid=beta", "--dry-run", f"results_dir={tmp_path}")
    runs = listed_runs(result.stdout)
    assert len(runs) == len(set(runs)) == 300  # 20 beta points x 3 tasks x 5 seeds
    assert {Path(r).parts[len(tmp_path.parts)] for r in runs} == {"push", "pick_and_place", "slide"}
    assert not any(tmp_path.iterdir())


def test_overrides_compose_with_a_grid(tmp_path):
    runs = listed_runs(sweep("+grid=beta", "--dry-run", "seeds=2", "task=push", f"results_dir={tmp_path}").stdout)
    assert len(runs) == 20 * 2 and all("/push/" in r for r in runs)


def test_paper_grid_lists_the_papers_runs(tmp_path):
    runs = listed_runs(sweep("+grid=paper", "--dry-run", f"results_dir={tmp_path}").stdout)
    # (HER + 4 linear + 4 exponential) x (lambda_h 1, 0.5) x 3 tasks x 5 seeds
    assert len(runs) == len(set(runs)) == 9 * 2 * 3 * 5
    assert sum("/archer/constant-0.8/" in r for r in runs) == 15
    assert sum("/her/exponential-b1_0.5-b2_0.5/" in r for r in runs) == 15


def test_iso_mu_grid_lies_in_the_optimal_band(tmp_path):
    from hersd.contract.schedules import mean_rate_exact

    result = sweep("+grid=iso_mu", "--dry-run", "seeds=1", "task=push", f"results_dir={tmp_path}")
    runs = listed_runs(result.stdout)
    assert len(runs) >= 6
    for run in runs:
        tag = Path(run).parent.name  # exponential-b1_<beta1>-b2_<beta2>, or linear-b1_<beta1> where beta2 = 0
        beta1, beta2 = re.fullmatch(r"(?:exponential|linear)-b1_([\d.]+)(?:-b2_(-?[\d.]+))?", tag).groups()
        assert 0.8 <= mean_rate_exact(float(beta1), float(beta2 or 0), 200) <= 0.889


@pytest.mark.parametrize("args, expected", [
    (["+grid=nope"], "+grid=nope is not a known grid; choose one of: beta, bf16_push, "),
    (["task=cartpole"], "task=cartpole is not a known task; choose one of: custom, hand_block, "),
    (["hydra/launcher=nope"], "hydra/launcher=nope is not a known hydra/launcher; choose one of: "),
    (["task=push,pushh"], "run [seed=0 task=pushh RESULTS]: task=pushh is not a known task; choose one of: "),
    (["task=null"], "task=null is not a known task; choose one of: custom, hand_block, "),
    (["+grid=null"], "+grid=null is not a known grid; choose one of: beta, "),
    (["+grid=beta,smoke"], "+grid=beta,smoke: a sweep runs one grid; run hersd-sweep once per grid"),
    (["+grid=smoke", "run_dir=one_run"], "would put the sweep's 4 runs in one folder; leave it out"),
    (["task=push,null"], "run [seed=0 task=null RESULTS]: task=null is not a known task; choose one of: "),
    (["+grid=beta", "schedule.beta1=2"], "schedule.beta1 must be a number in [0, 1]"),
    (["+grid=smoke", "schedule.beta1=0.5"], "schedule.beta1 is not a setting of schedule constant; its settings: eps"),
    (["+grid=smoke", "no_such_key=1"], "no_such_key is not a sweep setting; see hersd-sweep --help"),
    (["+grid=smoke", "seed=a"], "seed: Value 'a' of type 'str' could not be converted to Integer"),
    (["+grid=smoke", "seeds=0"], "seeds must be >= 1, got 0"),
    (["task=reach", "seeds=2", "seed=3"], "seeds=2 with seed=3: give seed=N (or seed=a,b) for those seeds, or "
                                          "seeds=N for seeds 0..N-1, not both"),
    (["schedule=linear,exponential", "schedule.beta1=3"],
     "run [seed=0 schedule=linear schedule.beta1=3 RESULTS]: schedule.beta1 must be a number in [0, 1], got 3"),
])
def test_bad_input_is_one_line_naming_the_choices_and_exit_2(tmp_path, args, expected):
    result = sweep(*args, "--dry-run", f"results_dir={tmp_path}", check=False)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("hersd-sweep: error: ")
    assert expected.replace("RESULTS", f"results_dir={tmp_path}") in result.stderr
    assert not any(tmp_path.iterdir())


def test_a_setting_fixed_for_every_swept_schedule_is_checked_on_each_not_on_the_default(tmp_path):
    """The grid's base (HER's constant schedule) has no beta1; the runs, linear and exponential, have."""
    result = sweep("schedule=linear,exponential", "schedule.beta1=0.3", "seeds=1", "--dry-run", f"results_dir={tmp_path}")
    assert [Path(run).parent.name for run in listed_runs(result.stdout)] == ["linear-b1_0.3",
                                                                              "exponential-b1_0.3-b2_0.25"]


@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]])  # the dry run listed the runs as new, exit 0
def test_an_unwritable_results_dir_is_one_line_and_exit_2_before_any_run(tmp_path, dry_run):
    (tmp_path / "a_file").write_text("not a folder")
    result = sweep("+grid=smoke", f"results_dir={tmp_path / 'a_file' / 'runs'}", *dry_run, check=False)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"hersd-sweep: error: results_dir: cannot write to {tmp_path / 'a_file' / 'runs'}")
    assert result.stderr.rstrip().endswith("pass results_dir=<a writable folder>")
    assert result.stdout == ""  # the error's line alone: the plan line came first ("sweep: 4 runs: ...")
    assert [path.name for path in tmp_path.iterdir()] == ["a_file"]


@pytest.mark.parametrize("args", [["task=reach", "--bogus"], ["--dry-run", "--bogus", "results_dir=RESULTS"]])
def test_an_unknown_option_is_one_line_naming_only_what_was_typed_with_exit_2(tmp_path, args):
    """It printed argparse's usage (8 lines), or with --dry-run named its rewrite, hydra.sweeper.dry_run=true."""
    result = sweep(*[arg.replace("RESULTS", str(tmp_path)) for arg in args], check=False)
    assert result.returncode == 2
    assert result.stderr == ("hersd-sweep: error: unknown option --bogus; hersd-sweep takes -h, --help, --dry-run and "
                             "KEY=VALUE overrides (hersd-sweep --help lists them)\n")
    assert not any(tmp_path.iterdir())


def test_hydra_full_error_still_gives_the_traceback(tmp_path):
    result = subprocess.run([*SWEEP, "+grid=nope", f"results_dir={tmp_path}"], capture_output=True, text=True,
                            timeout=600, env={**os.environ, "HYDRA_FULL_ERROR": "1"})
    assert result.returncode != 0 and "Traceback" in result.stderr and "grid/nope" in result.stderr


@pytest.mark.parametrize("n_jobs", ["0", "-1"])
def test_no_runs_at_once_is_one_line_saying_what_to_do_and_exit_2(tmp_path, n_jobs):
    result = sweep("+grid=smoke", f"hydra.launcher.n_jobs={n_jobs}", f"results_dir={tmp_path}", check=False)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == (f"hersd-sweep: error: hydra.launcher.n_jobs={n_jobs}: give the number of runs "
                                     f"to train at once, 1 or more, or ${{hersd_cores:}} for one per core "
                                     f"({available_cores()} here, the default of hydra/launcher=local)")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("sinfo, override, message", [
    ("printf 'debug*\\ncpu\\n'", "hydra.launcher.partition=nope",
     "hydra.launcher.partition=nope: no partition nope here; choose among: debug, cpu"),
    ("echo 'sinfo: fatal: no controller' >&2; exit 1", "hydra.launcher.partition=debug",
     "hydra/launcher=slurm: SLURM does not answer here (sinfo: fatal: no controller)"),
    ("printf 'debug*\\n'", "hydra.launcher.mem_gb=-1", "hydra.launcher.mem_gb=-1: give the GB of memory of each job"),
    ("printf 'debug*\\n'", "hydra.launcher.timeout_min=0", "hydra.launcher.timeout_min=0: give the minutes of each job"),
    ("printf 'debug*\\n'", "hydra.launcher.cpus_per_task=0", "hydra.launcher.cpus_per_task=0: give the CPUs of each job"),
])
def test_slurm_problems_stop_the_sweep_at_start_as_they_stop_a_search(tmp_path, monkeypatch, sinfo, override, message):
    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "sinfo").write_text(f"#!/bin/sh\n{sinfo}\n")
    (tmp_path / "bin" / "sinfo").chmod(0o755)
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}:{os.environ['PATH']}")
    results = tmp_path / "results"
    result = sweep("+grid=smoke", "hydra/launcher=slurm", override, f"results_dir={results}", check=False)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"hersd-sweep: error: {message}") and not results.exists()


def test_a_run_this_machine_cannot_train_is_refused_before_any_run_unless_the_runs_train_elsewhere(tmp_path):
    """A sweep training here checks what its runs ask of the machine first (one line, exit 2, dry run too);
    one whose jobs run on a cluster's nodes lists them: the nodes decide."""
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA device")
    for dry_run in (["--dry-run"], []):
        result = sweep("+grid=smoke", "device=cuda", f"results_dir={tmp_path}", *dry_run, check=False)
        assert result.returncode == 2 and result.stderr == ("hersd-sweep: error: device=cuda: torch sees no CUDA "
                                                            "device here; use device=cpu or device=auto\n")
        assert result.stdout == "" and not any(tmp_path.iterdir())  # no plan line before the error
    listed = sweep("+grid=smoke", "device=cuda", "hydra/launcher=slurm", f"results_dir={tmp_path}", "--dry-run")
    assert len(listed_runs(listed.stdout)) == 4


def test_bf16_is_refused_on_a_cpu_without_its_instructions_before_any_run(monkeypatch):
    from hersd.engine import resources
    from sweeps.plan import refused_here

    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: False)
    assert refused_here({("cpu", "fp32")}) == {}
    refused = refused_here({("cpu", "fp32"), ("cpu", "bf16")})
    assert list(refused) == [("cpu", "bf16")]
    assert refused["cpu", "bf16"].startswith("precision=bf16: this CPU has no bf16 instructions")
    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: True)
    assert refused_here({("cpu", "fp32"), ("cpu", "bf16")}) == {}


def test_checking_runs_that_need_nothing_of_the_machine_loads_no_torch():
    """fp32 on the CPU (or ``auto``, which falls back to it) cannot be refused: the dry run stays light."""
    code = ("import sys; from sweeps.plan import refused_here; "
            "print(refused_here({('auto', 'fp32'), ('cpu', 'fp32')}), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "{} False"


def test_the_commands_module_loads_no_library_so_ctrl_c_is_caught_from_its_start():
    """The modules a sweep needs load inside main's Ctrl-C handling: a Ctrl-C while they load is one line."""
    code = ("import sys, sweeps.launch; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'numpy', 'pandas', 'omegaconf', 'hydra', 'torch', 'mcap'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]"


def test_a_joblib_launcher_of_ones_own_without_n_jobs_is_told_what_to_set():
    """The joblib plugin's default n_jobs, -1, is refused with the setting that gives one run per core."""
    from hydra_plugins.hydra_joblib_launcher.config import JobLibLauncherConf
    from omegaconf import OmegaConf

    from sweeps.launchers import check_launcher
    from sweeps.plan import SweepError

    with pytest.raises(SweepError) as refused:
        check_launcher(OmegaConf.structured(JobLibLauncherConf))
    assert refused.value.exit_code == 2 and "n_jobs=-1" in str(refused.value)
    assert "${hersd_cores:} for one per core" in str(refused.value)
    check_launcher(OmegaConf.structured(JobLibLauncherConf(n_jobs=2)))


def test_help_names_the_command_and_only_the_groups_a_sweep_takes():
    text = sweep("--help").stdout
    assert text.startswith("usage: hersd-sweep ") and "Hydra" not in text
    groups = [line.split("=")[0].strip() for line in text.split("config groups:\n")[1].split("\n\n")[0].splitlines()]
    assert groups == ["+grid", "task", "algo", "schedule", "learner", "hydra/launcher"]
    assert "\ncampaign" not in text and "search=" not in text  # conf/search is hersd-search's, not a sweep's


def test_the_local_launcher_runs_one_per_core_in_the_listed_order(tmp_path):
    from hersd.contract.compose import compose
    from sweeps.plan import register_schemas

    register_schemas()
    launcher = compose("sweep", ["+grid=smoke"], job_name="test", with_hydra=True).hydra.launcher
    assert (launcher.n_jobs, int(launcher.batch_size)) == (available_cores(), 1)  # a free worker takes the next
    args = ["+grid=smoke", "epochs=1", *TINY, "hydra.launcher.n_jobs=1", f"results_dir={tmp_path}"]
    order = listed_runs(sweep(*args, "--dry-run").stdout)
    sweep(*args)
    finished = [json.loads(line)["run_dir"] for p in tmp_path.glob(".sweeps/*/progress.jsonl")
                for line in p.read_text().splitlines()]
    assert finished == order  # seed by seed: (HER, linear) seed 0, then seed 1


def test_smoke_grid_makes_one_complete_log_per_run_then_skips_them(tmp_path):
    result = sweep("+grid=smoke", f"results_dir={tmp_path}")
    logs = sorted(tmp_path.rglob("run.mcap"))
    assert len(logs) == 4, result.stdout
    for log_path in logs:
        log = read_run(log_path)
        assert log.complete and list(log.epochs["epoch"]) == [1, 2, 3, 4]
        assert log.meta["command"].startswith("hersd-sweep ")
        assert 1 <= log.meta["threads"] <= max(1, available_cores() // min(available_cores(), 4))  # cores shared out
    assert "4 done" in result.stdout and "0 failed" in result.stdout
    stamps = [p.stat().st_mtime_ns for p in logs]
    again = sweep("+grid=smoke", f"results_dir={tmp_path}")
    assert "4 complete (skipped)" in again.stdout
    assert [p.stat().st_mtime_ns for p in logs] == stamps


def test_a_sweeps_jobs_train_the_runs_its_planner_resolved(tmp_path, monkeypatch):
    """Each run is resolved once, in the sweeping process (folder, identity, rates): the jobs take their spec from
    the sweep's specs.pkl by their overrides (threads added), and a job finding its spec there resolves nothing."""
    import pickle

    from sweeps import plan

    sweep("task=reach", "seeds=2", "epochs=1", *TINY, f"results_dir={tmp_path}")
    (specs_file,) = tmp_path.glob(f".sweeps/*/{plan.SPECS_NAME}")
    specs = pickle.loads(specs_file.read_bytes())
    assert len(specs) == 2
    for job, spec in specs.items():
        meta = read_run(spec.folder / "run.mcap").meta
        assert meta["run_id"] == spec.run_id and meta["config"]["threads"] == spec.config.threads
        assert f"threads={spec.config.threads}" in job and meta["command"] == f"hersd-sweep {' '.join(job)}"
    monkeypatch.setattr(plan, "job_train_config", lambda cfg: pytest.fail("the job resolved its run again"))
    job, spec = next(iter(specs.items()))
    assert plan.job_spec(None, specs_file.parent, list(job)).run_id == spec.run_id


def test_a_failed_run_does_not_stop_the_sweep(tmp_path):
    # seed 1's run directory is blocked by a file, so that run (only) fails
    ok = sweep("+grid=smoke", "schedule=constant", *TINY, "--dry-run", f"results_dir={tmp_path}")
    blocked = Path([r for r in listed_runs(ok.stdout) if "/seed1-" in r][0])
    blocked.parent.mkdir(parents=True)
    blocked.write_text("in the way")
    result = sweep("+grid=smoke", "schedule=constant", *TINY, f"results_dir={tmp_path}", check=False)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "1 done" in result.stdout and "1 failed" in result.stdout
    assert len(list(tmp_path.rglob("run.mcap"))) == 1


# hersd-sweep whose disk fills at its run's epoch 2 (the run trains in the sweep's own process: hydra/launcher=basic):
# from then on every file written fails as on a full disk: the run's log, then its error.log, then the sweep's
# progress file.
FULL_DISK_SWEEP = """
import sys
import pytest
import hersd.engine.train as train_module
from helpers import full_disk_writes
from sweeps.launch import main

run_epoch = train_module.run_epoch

def filling(state, epoch, *args, **kwargs):
    if epoch == 2:
        full_disk_writes(pytest.MonkeyPatch(), "*")
    return run_epoch(state, epoch, *args, **kwargs)

train_module.run_epoch = filling
sys.argv[0] = "hersd-sweep"
main()
"""


def test_a_full_disk_that_leaves_no_room_for_a_failed_runs_error_log_is_one_line_with_exit_2(tmp_path):
    """The run stops on a full disk (its log at epoch 2) and its error.log cannot be written either: one line
    naming error.log, the bytes it needs and the run's error, exit 2, no error.log or temporary file; once space
    is freed the same command resumes the run from its epoch 1."""
    args = ["+grid=smoke", "schedule=constant", "seeds=1", "epochs=3", *TINY, "hydra/launcher=basic",
            f"results_dir={tmp_path}"]
    full = subprocess.run([sys.executable, "-c", FULL_DISK_SWEEP, *args], capture_output=True, text=True, timeout=600,
                          cwd=Path(__file__).parent)
    (run,) = [log.parent for log in tmp_path.rglob("run.mcap")]
    err = full.stderr.strip()
    assert full.returncode == 2 and len(err.splitlines()) == 1, full.stdout[-2000:] + full.stderr[-3000:]
    assert err.startswith(f"hersd-sweep: error: no space left on the device of {run / 'error.log'}: writing it needs ")
    assert f" free; the run stopped with DiskFullError: no space left on the device of " \
           f"{run / 'run.mcap'}: writing it needs " in err
    assert err.endswith("; free some and run the same command again (finished runs are kept and skipped, the others "
                        "resume)")
    assert sorted(path.name for path in run.iterdir()) == ["checkpoint.pt", "run.lock", "run.mcap"]  # no .tmp
    assert list(read_run(run / "run.mcap").epochs["epoch"]) == [1]
    assert "1 failed" in full.stdout and not list(tmp_path.rglob("*.tmp"))

    result = sweep(*args)  # space freed
    assert "1 resumed" in result.stdout and "0 failed" in result.stdout
    log = read_run(run / "run.mcap")
    assert log.complete and list(log.epochs["epoch"]) == [1, 2, 3] and log.sessions[1]["resumed_from_epoch"] == 1


def test_killed_sweep_finishes_on_rerun_without_loss_or_duplicates(tmp_path):
    args = ["+grid=smoke", "epochs=5", *TINY, "hydra.launcher.n_jobs=1", f"results_dir={tmp_path}"]
    proc = subprocess.Popen([*SWEEP, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    for line in proc.stdout:
        if line.startswith("[sweep 1/"):
            os.killpg(proc.pid, signal.SIGKILL)
            break
    proc.wait()
    finished = {p: p.read_bytes() for p in tmp_path.rglob("run.mcap") if read_run(p).complete}
    assert 1 <= len(finished) < 4

    result = sweep(*args)
    assert f"{len(finished)} complete (skipped)" in result.stdout and "0 failed" in result.stdout
    logs = list(tmp_path.rglob("run.mcap"))
    assert len(logs) == 4
    for log_path in logs:
        log = read_run(log_path)
        assert log.complete and list(log.epochs["epoch"]) == [1, 2, 3, 4, 5]  # none lost, none twice
        assert 1 <= log.meta["threads"] <= available_cores()  # one run at a time: the cores it found idle, 1 or more
    assert all(path.read_bytes() == data for path, data in finished.items())  # finished runs not re-run
    progress = [json.loads(line)["run_dir"] for p in tmp_path.glob(".sweeps/*/progress.jsonl")
                for line in p.read_text().splitlines()]
    for path in finished:
        assert progress.count(str(path.parent)) == 1


def test_the_workers_end_within_seconds_of_a_killed_sweep_and_the_same_command_finishes_their_runs(tmp_path):
    """kill -9 of the sweep's main process alone (no signal reaches its workers): its two workers, training,
    and the resource trackers they share end within seconds; the same command then resumes both runs."""
    args = ["+grid=smoke", "schedule=constant", "seeds=2", "epochs=10", *TINY, "hydra.launcher.n_jobs=2",
            f"results_dir={tmp_path}"]
    killed_while_training([*SWEEP, *args], tmp_path)
    result = sweep(*args)
    assert "2 resumed, 0 running elsewhere, 0 failed" in result.stdout, result.stdout
    for log_path in tmp_path.rglob("run.mcap"):
        log = read_run(log_path)
        assert log.complete and list(log.epochs["epoch"]) == list(range(1, 11))
        assert len(log.sessions) == 2 and log.sessions[1]["resumed_from_epoch"] >= 1


def test_the_sweep_names_its_main_process_to_its_jobs_for_the_launch_only(monkeypatch):
    """watched_by_jobs sets HERSD_SWEEP_PROCESS for the processes the launch starts and restores it after (a sweep
    run inside another process, a test's, leaves nothing behind); jobs that train elsewhere are not named it."""
    from types import SimpleNamespace

    from sweeps.launchers import SWEEP_ENV, main_process, watched_by_jobs

    monkeypatch.delenv(SWEEP_ENV, raising=False)
    launcher = SimpleNamespace(joblib={"n_jobs": 4})
    with watched_by_jobs(launcher, 2):
        assert os.environ[SWEEP_ENV] == main_process() and launcher.joblib["n_jobs"] == 2
    assert SWEEP_ENV not in os.environ
    monkeypatch.setenv(SWEEP_ENV, "1:2")
    with watched_by_jobs(launcher, 1, here=False):
        assert os.environ[SWEEP_ENV] == "1:2" and launcher.joblib["n_jobs"] == 2
    with watched_by_jobs(launcher, 1):
        assert os.environ[SWEEP_ENV] == main_process()
    assert os.environ[SWEEP_ENV] == "1:2"


def test_ctrl_c_ends_a_sweep_with_one_line_and_exit_130_and_keeps_its_work(tmp_path):
    """Ctrl-C (SIGINT to the terminal's process group) during the second run: one line, exit 130,
    no process left behind, the first run complete; the same command finishes the rest."""
    args = ["+grid=smoke", "epochs=3", *TINY, "hydra.launcher.n_jobs=1", f"results_dir={tmp_path}"]
    proc = subprocess.Popen([*SWEEP, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    for line in proc.stdout:
        if line.startswith("[sweep 1/"):
            os.killpg(proc.pid, signal.SIGINT)
            break
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130
    assert err.strip().splitlines()[-1] == ("hersd-sweep: interrupted; finished runs and epochs are kept: re-run "
                                            "the same command to resume") and "Traceback" not in err
    assert not group_alive(proc.pid)  # the sweep's workers ended with it
    assert sum(read_run(p).complete for p in tmp_path.rglob("run.mcap")) >= 1
    result = sweep(*args)
    assert all(read_run(p).complete for p in tmp_path.rglob("run.mcap")) and "0 failed" in result.stdout


def test_submitit_local_launcher_runs_the_same_sweep(tmp_path):
    result = sweep("+grid=smoke", "schedule=constant", "seeds=1", "epochs=1", *TINY,
                   "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10", f"results_dir={tmp_path}")
    logs = list(tmp_path.rglob("run.mcap"))
    assert len(logs) == 1 and read_run(logs[0]).complete, result.stdout + result.stderr


def test_a_run_held_by_another_process_is_reported_busy_not_run(tmp_path):
    args = ["+grid=smoke", "schedule=constant", "seeds=2", "epochs=1", *TINY, f"results_dir={tmp_path}"]
    held = Path([r for r in listed_runs(sweep(*args, "--dry-run").stdout) if "/seed0-" in r][0])
    held.mkdir(parents=True)
    with RunFolder(held).lock():
        result = sweep(*args, "threads=1")
    assert "1 done" in result.stdout and "1 running elsewhere" in result.stdout and "0 failed" in result.stdout
    assert not (held / "run.mcap").exists()
    assert read_run(next(tmp_path.rglob("seed1-*/run.mcap"))).meta["threads"] == 1  # an explicit count wins


def launcher_config(*overrides: str):
    """The composed ``hydra.launcher`` node of a sweep with these overrides."""
    from hersd.contract.compose import compose
    from sweeps.plan import register_schemas

    register_schemas()
    return compose("sweep", ["+grid=smoke", *overrides], job_name="test", with_hydra=True).hydra.launcher


def test_runs_at_once_come_from_each_launchers_own_settings(idle_machine):
    """joblib: its n_jobs; submitit's local executor: every run; Hydra's basic launcher: one after
    another; SLURM: each job on its own allocation, resolving threads=auto there (None)."""
    from sweeps.launch import auto_threads, concurrent_runs

    assert concurrent_runs(launcher_config("hydra.launcher.n_jobs=1"), n_runs=10) == 1
    assert concurrent_runs(launcher_config(), n_runs=10) == available_cores()
    assert concurrent_runs(launcher_config("hydra/launcher=submitit_local"), n_runs=10) == 10
    assert concurrent_runs(launcher_config("hydra/launcher=basic"), n_runs=10) == 1
    assert concurrent_runs(launcher_config("hydra/launcher=slurm"), n_runs=10) is None
    assert auto_threads(launcher_config("hydra/launcher=slurm"), n_runs=10) is None
    assert auto_threads(launcher_config("hydra.launcher.n_jobs=1"), n_runs=10) == available_cores()


USER_LAUNCHER = """# @package hydra.launcher
# A user's launcher: submitit's local executor, its jobs cut after 10 minutes.
defaults:
  - submitit_local
timeout_min: 10
"""


def test_a_launcher_yaml_alone_runs_the_smoke_grid(tmp_path):
    """A launcher added as one YAML in a config dir of the user's (hydra.searchpath), no Python edit."""
    conf = tmp_path / "conf"
    (conf / "hydra" / "launcher").mkdir(parents=True)
    (conf / "hydra" / "launcher" / "mine.yaml").write_text(USER_LAUNCHER)
    args = ["+grid=smoke", "schedule=constant", "seeds=1", "epochs=1", *TINY, f"hydra.searchpath=[file://{conf}]",
            "hydra/launcher=mine", f"results_dir={tmp_path / 'results'}"]
    assert len(listed_runs(sweep(*args, "--dry-run").stdout)) == 1
    result = sweep(*args)
    logs = list((tmp_path / "results").rglob("run.mcap"))
    assert "1 done" in result.stdout and len(logs) == 1 and read_run(logs[0]).complete, result.stdout + result.stderr
    assert (tmp_path / "results" / ".sweeps").exists() and list(tmp_path.rglob(".submitit"))  # submitit ran it


def test_a_main_process_killed_but_not_yet_reaped_is_gone_to_its_workers():
    """A sweep's main process killed (SIGTERM, SIGKILL) stays a zombie until its own parent reaps it, e.g. a
    script reading the sweep's output until the pipes close, which its workers hold open: the workers must see it
    gone then, not train on and idle for minutes holding those pipes (sweeps.launchers.alive)."""
    from sweeps.launchers import alive, process_start

    child = subprocess.Popen(["sleep", "60"])
    start = process_start(child.pid)
    try:
        assert alive(child.pid, start)
        child.kill()
        os.waitid(os.P_PID, child.pid, os.WEXITED | os.WNOWAIT)  # dead, not reaped: a zombie
        assert not alive(child.pid, start)
    finally:
        child.kill()
        child.wait()


def test_a_worker_killed_outside_hersd_ends_the_sweep_with_one_line_not_a_traceback():
    """SIGKILL (or the OOM killer) of one joblib worker: loky raises TerminatedWorkerError in the sweep; it is one
    line saying what happened and that the same command resumes (exit 1), like a submitit job that died."""
    from types import SimpleNamespace

    from joblib.externals.loky.process_executor import TerminatedWorkerError

    from sweeps.launch import launch_jobs
    from sweeps.plan import SweepError

    def launch(jobs, initial_job_idx):
        raise TerminatedWorkerError("A worker process managed by the executor was unexpectedly terminated. This "
                                    "could be caused by a segmentation fault.\n\nThe exit codes of the workers are "
                                    "{SIGKILL(-9)}")

    with pytest.raises(SweepError) as raised:
        launch_jobs(SimpleNamespace(launcher=SimpleNamespace(launch=launch)), [["seed=0"]])
    message = str(raised.value)
    assert raised.value.exit_code == 1 and len(message.splitlines()) == 1
    assert "worker" in message and "run the same command again" in message


FULL_DISK_AT_START = """
import sys
import pytest
from helpers import full_disk_writes
from sweeps.launch import main

full_disk_writes(pytest.MonkeyPatch(), "specs.pkl*")
sys.argv = ["hersd-sweep", *sys.argv[1:]]
main()
"""


def test_a_full_disk_before_the_first_run_is_one_line_with_exit_2_and_leaves_no_file(tmp_path):
    """The disk fills as the sweep writes its plan (specs.pkl, before any run): one line naming the file and the
    bytes it needs, exit 2, and no half-written or temporary file left, nor the sweep's folder."""
    args = ["+grid=smoke", "schedule=constant", "seeds=1", "epochs=1", *TINY, "hydra/launcher=basic",
            f"results_dir={tmp_path}"]
    full = subprocess.run([sys.executable, "-c", FULL_DISK_AT_START, *args], capture_output=True, text=True,
                          timeout=600, cwd=Path(__file__).parent)
    err = full.stderr.strip()
    assert full.returncode == 2 and len(err.splitlines()) == 1, full.stdout[-2000:] + full.stderr[-3000:]
    assert err.startswith("hersd-sweep: error: no space left on the device of ") and "specs.pkl" in err
    assert not [path for path in tmp_path.rglob("*") if path.is_file()]  # no specs.pkl, no .tmp
    assert not list((tmp_path / ".sweeps").iterdir())  # nor the sweep's empty folder


def test_sigterm_to_the_sweep_ends_it_as_ctrl_c_does_with_one_line_and_no_temporary_file(tmp_path):
    """``kill PID`` (SIGTERM) of a sweep training in its own process (one run at a time): one line, exit 130, no
    ``.tmp`` file of a write it cut short, as a Ctrl-C; the same command then finishes the runs."""
    args = ["+grid=smoke", "schedule=constant", "seeds=1", "epochs=6", *TINY, "hydra.launcher.n_jobs=1", "quiet=false",
            f"results_dir={tmp_path}"]
    proc = subprocess.Popen([*SWEEP, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    for line in proc.stdout:
        if line.startswith("epoch    2/"):
            os.kill(proc.pid, signal.SIGTERM)
            break
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["hersd-sweep: interrupted; finished runs and epochs are kept: re-run the "
                                        "same command to resume"]
    assert not group_alive(proc.pid) and not list(tmp_path.rglob("*.tmp"))
    result = sweep(*args)
    assert "1 resumed" in result.stdout and all(read_run(p).complete for p in tmp_path.rglob("run.mcap"))
