"""sweeps/plan.py: a grid's runs seed by seed, stages one after another, and the campaign grids."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from hersd.compose import compose
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
