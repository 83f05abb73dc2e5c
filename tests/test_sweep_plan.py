"""sweeps/plan.py: a grid's runs seed by seed, stages one after another, and the campaign grids."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from hersd.contract.compose import compose
from sweeps.plan import SweepError, grid_stages, register_schemas, seed_by_seed

SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]
RESULTS = Path(__file__).resolve().parent.parent / "results"


def listed(*args: str) -> list[tuple[str, str]]:
    """A dry run's runs, in launch order, as (state, directory)."""
    out = subprocess.run([*SWEEP, *args, "--dry-run"], capture_output=True, text=True, check=True, timeout=300).stdout
    return [(line.split()[0], line.split()[1]) for line in out.splitlines() if line.startswith("  ")]


def test_seed_by_seed_gives_every_grid_and_arm_its_nth_seed_before_any_n_plus_first():
    first = [["arm=a", "seed=0"], ["arm=a", "seed=1"], ["arm=b", "seed=0"], ["arm=b", "seed=1"]]  # arm-major
    second = [["arm=c", "seed=5"], ["arm=c", "seed=6"]]
    order = [" ".join(job) for job in seed_by_seed([first, second])]
    assert order == ["arm=a seed=0", "arm=b seed=0", "arm=c seed=5", "arm=a seed=1", "arm=b seed=1", "arm=c seed=6"]
    assert seed_by_seed([[["arm=b"], ["arm=a"]]]) == [["arm=b"], ["arm=a"]]  # no seed: the grid's order


def test_params_are_a_grid_or_stages_of_grids():
    assert grid_stages({"task": "push"}) == [[{"task": "push"}]]
    assert grid_stages([[{"task": "push"}, {"task": "reach"}], {"task": "slide"}]) == \
        [[{"task": "push"}, {"task": "reach"}], [{"task": "slide"}]]
    with pytest.raises(SweepError, match="a list of stages"):
        grid_stages([[], {"task": "push"}])


def test_a_grid_runs_seed_by_seed(tmp_path):
    runs = [Path(directory) for _, directory in listed("+grid=smoke", f"results_dir={tmp_path}")]
    assert [(run.parent.name, run.name.split("-")[0]) for run in runs] == \
        [("constant-0.8", "seed0"), ("linear-b1_0.25", "seed0"), ("constant-0.8", "seed1"), ("linear-b1_0.25", "seed1")]


def test_the_push_campaign_grid_plans_the_committed_runs_in_their_stages(tmp_path):
    runs = [Path(directory).relative_to(tmp_path) for _, directory in
            listed("+grid=push_paper_campaign", f"results_dir={tmp_path}")]
    assert len(runs) == len(set(runs)) == 20
    assert set(runs) <= {p.parent.relative_to(RESULTS) for p in RESULTS.glob("push/her/*/*/run.mcap")}  # committed
    arms = [(run.parent.name, int(run.name.split("-")[0].removeprefix("seed"))) for run in runs]
    main, control, success = ("constant-0.8", "linear-b1_0.25"), "constant-0.874375", "success-b1_0.25-w10"
    assert arms == [(arm, seed) for seed in range(3) for arm in main] + [(control, s) for s in range(3)] + \
        [(success, s) for s in range(3)] + [(arm, seed) for seed in (3, 4) for arm in main] + \
        [(control, s) for s in (3, 4)] + [(success, s) for s in (3, 4)]
    # the success-driven seeds 3-4 that the first campaign left training: the same folders
    assert {str(run) for run in runs[-2:]} == {"push/her/success-b1_0.25-w10/seed3-a35a453a",
                                               "push/her/success-b1_0.25-w10/seed4-13cbab58"}


def test_the_next_campaign_grid_takes_turns_then_adds_the_exponential_and_the_control(tmp_path):
    runs = [Path(directory).relative_to(tmp_path) for _, directory in
            listed("+grid=pnp_push_paper", f"results_dir={tmp_path}")]
    arms = [(run.parts[0], run.parts[2], int(run.name.split("-")[0].removeprefix("seed"))) for run in runs]
    main = ("constant-0.8", "linear-b1_0.25")
    assert arms == [(task, arm, seed + offset) for seed in range(5) for task, offset in
                    (("pick_and_place", 0), ("push", 5)) for arm in main] + \
        [("pick_and_place", "exponential-b1_0.25-b2_0.25", seed) for seed in range(5)] + \
        [("push", "constant-0.874375", seed) for seed in range(5, 10)]
    register_schemas()
    cfg = compose("sweep", ["+grid=pnp_push_paper"], job_name="test")
    assert (cfg.epochs, cfg.flush_denormal) == (200, True)


def test_the_decay_or_mean_campaign_finishes_the_exponential_then_takes_turns_with_the_control(tmp_path):
    runs = [Path(directory).relative_to(tmp_path) for _, directory in
            listed("+grid=decay_or_mean", f"results_dir={tmp_path}")]
    arms = [(run.parts[0], run.parts[2], int(run.name.split("-")[0].removeprefix("seed"))) for run in runs]
    exponential, control = "exponential-b1_0.25-b2_0.25", "constant-0.874375"
    assert arms == [("pick_and_place", exponential, 0), ("pick_and_place", exponential, 1)] + \
        [arm for seed in range(5) for arm in [("pick_and_place", control, seed)]
         + ([("pick_and_place", exponential, seed + 2)] if seed < 3 else [])] + \
        [("push", control, seed) for seed in range(5, 10)] + \
        [("slide", arm, seed) for seed in range(5) for arm in ("constant-0.8", "linear-b1_0.25")]
    # the runs it shares with the second campaign are the same folders
    shared = {Path(directory).relative_to(tmp_path) for _, directory in
              listed("+grid=pnp_push_paper", f"results_dir={tmp_path}")}
    assert sum(run in shared for run in runs) == 10


def test_the_bf16_campaign_trains_her_seeds_0_to_4_in_folders_apart_from_the_committed_fp32_ones(tmp_path):
    runs = [Path(directory).relative_to(tmp_path) for _, directory in  # runs on SLURM's nodes: any CPU may plan them
            listed("+grid=bf16_push", "hydra/launcher=slurm", f"results_dir={tmp_path}")]
    assert [(run.parent, run.name.split("-")[0]) for run in runs] == \
        [(Path("push/her/constant-0.8"), f"seed{seed}") for seed in range(5)]
    from hersd.contract.runlog import read_records

    fp32 = {path.parent.name for path in (RESULTS / "push/her/constant-0.8").glob("*/run.mcap")  # bf16 ones land here
            if read_records(path).meta["config"].get("precision", "fp32") == "fp32"}
    assert len(fp32) == 10 and not fp32 & {run.name for run in runs}


@pytest.mark.parametrize("args, seeds", [
    (["task=reach", "epochs=1", "seeds=3"], [0, 1, 2]),  # no grid: seeds=N is N runs
    (["task=reach", "seeds=3", "schedule=linear", "schedule.beta1=0.5,0.7"], [0, 0, 1, 1, 2, 2]),  # seed by seed
    (["task=reach", "seed=4"], [4]),  # the command's seed, not range(seeds); seeds= with seed= is refused
    (["+grid=smoke", "seed=1,2"], [1, 1, 2, 2]),
])
def test_seeds_sweeps_seed_unless_the_command_sets_it(tmp_path, args, seeds):
    runs = [Path(directory) for _, directory in listed(*args, f"results_dir={tmp_path}")]
    assert [int(run.name.split("-")[0].removeprefix("seed")) for run in runs] == seeds


def test_deleting_the_seed_is_one_line_saying_what_to_give():
    """``~seed`` was an IndexError traceback (exit 1)."""
    assert seed_by_seed([[["task=reach", "seed=1"]]]) == [["task=reach", "seed=1"]]
    with pytest.raises(SweepError, match=r"^~seed deletes the runs' seed: give seed=N") as caught:
        seed_by_seed([[["task=reach", "~seed"]]])
    assert caught.value.exit_code == 2


CHECKED_SWEEP = """
from hersd.contract.config import config_record
from sweeps import plan
from sweeps.launch import main

planned = plan.JobConfigs.config


def checked(self, job):
    cfg = planned(self, job)
    hydras = plan.job_train_config(self.loader.load_sweep_config(self.sweep_config, job))
    assert config_record(plan.job_train_config(cfg)) == config_record(hydras), job
    print("checked:", *job)
    return cfg


plan.JobConfigs.config = checked
main()
"""


@pytest.mark.parametrize("args", [
    ["+grid=beta", "task=slide", "seeds=1", "schedule.beta1=0.25,1.0"],
    ["+grid=paper", "task=push", "seeds=1", "schedule=constant,paper_linear_050,paper_exp_025"],
    ["+grid=iso_mu", "task=pick_and_place", "seeds=1", "schedule.mean_rate=0.85"],
    ["+grid=pnp_push_paper"],
    ["+grid=push_paper_campaign"],
    ["+grid=decay_shape", "hydra/launcher=slurm"],
    ["task=reach", "seeds=2", "learner=td3,sac", "ddpg.batch_size=64", "hydra/launcher=submitit_local"],
])
def test_each_planned_config_is_the_one_hydra_composes_for_the_job(tmp_path, args):
    """The planner composes once per set of group choices and applies each job's values to a copy
    (sweeps.plan.JobConfigs): every job's config equals Hydra's own composition of it."""
    done = subprocess.run([sys.executable, "-c", CHECKED_SWEEP, *args, f"results_dir={tmp_path}", "--dry-run"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    checked = [line for line in done.stdout.splitlines() if line.startswith("checked:")]
    listed_count = int(done.stdout.split("sweep: ", 1)[1].split(" runs", 1)[0])
    assert len(checked) >= listed_count >= 2


def test_the_decay_shape_campaign_starts_with_the_bf16_runs_then_takes_its_stages_in_order(tmp_path):
    """Stage 1 is conf/grid/bf16_push.yaml's runs (the same folders, training now); then the rising linear 0.25 and
    the constant 0.75 on FetchPickAndPlace seed by seed, the exponential 0.25 on FetchPush, ARCHER on
    FetchPickAndPlace (HER's rate and the linear decay)."""
    slurm = ("hydra/launcher=slurm", f"results_dir={tmp_path}")  # its nodes decide what they can train
    runs = [Path(directory).relative_to(tmp_path) for _, directory in listed("+grid=decay_shape", *slurm)]
    bf16 = [Path(directory).relative_to(tmp_path) for _, directory in listed("+grid=bf16_push", *slurm)]
    assert len(runs) == len(set(runs)) == 30 and runs[:5] == bf16
    arms = [(run.parts[0], run.parts[1], run.parts[2], int(run.name.split("-")[0].removeprefix("seed")))
            for run in runs[5:]]
    assert arms == [("pick_and_place", "her", arm, seed) for seed in range(5)
                    for arm in ("rising-b1_0.25", "constant-0.75")] + \
        [("push", "her", "exponential-b1_0.25-b2_0.25", seed) for seed in range(5)] + \
        [("pick_and_place", "archer", arm, seed) for seed in range(5) for arm in ("constant-0.8", "linear-b1_0.25")]


SWEEP_WITHOUT_BF16 = "from hersd.engine import resources; resources.cpu_has_bf16 = lambda: False\n" \
    "from sweeps.launch import main; main()"


def test_on_a_cpu_without_bf16_each_bf16_run_is_skipped_in_one_line_and_the_campaign_goes_on(tmp_path):
    """bf16_push alone is refused (exit 2, one line); decay_shape skips its five bf16 runs, one line each, and
    lists the other 25 to train."""
    def dry_run(grid: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", SWEEP_WITHOUT_BF16, f"+grid={grid}", f"results_dir={tmp_path}",
                               "--dry-run"], capture_output=True, text=True, timeout=300)

    refused = dry_run("bf16_push")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert "precision=bf16: this CPU has no bf16 instructions" in refused.stderr
    goes_on = dry_run("decay_shape")
    assert goes_on.returncode == 0, goes_on.stderr
    skipped = [line for line in goes_on.stdout.splitlines() if line.startswith("sweep: skipped ")]
    assert len(skipped) == 5 and all(line.endswith("precision=bf16: this CPU has no bf16 instructions "
                                                   "(avx512_bf16, amx_bf16); use precision=fp32") for line in skipped)
    assert [line.split()[2].removesuffix(":") for line in skipped] == \
        [str(tmp_path / "push/her/constant-0.8" / Path(d).name) for _, d in listed("+grid=bf16_push",
                                                                                   "hydra/launcher=slurm",
                                                                                   f"results_dir={tmp_path}")]
    planned = [line.split()[1] for line in goes_on.stdout.splitlines() if line.startswith("  ")]
    assert len(planned) == 25 and "rising-b1_0.25" in planned[0]
