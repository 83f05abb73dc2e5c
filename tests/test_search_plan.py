"""sweeps/search/plan.py: the search plan and a trial's run configs."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import TINY
from searches import fails_with, tiny_search

from hersd.contract.compose import compose_train
from hersd.contract.cores import available_cores
from hersd.contract.runstore import config_hash, run_dir
from hersd.contract.study import param_overrides, trial_config
from sweeps.search import plan as search_plan
from sweeps.search.config import compose_search
from sweeps.search.plan import make_plan


@pytest.mark.parametrize("override", ["seed=3", "schedule=linear", "schedule.beta1=0.5", "schedule.mean_rate=0.8",
                                      "run_dir=/tmp/one-dir", "algo.lambda_h=0.5"])
def test_searched_training_keys_are_refused(override: str, tmp_path: Path, capsys) -> None:
    err = fails_with(["search=wide", override, *tiny_search(tmp_path)], capsys)
    assert f"{override.split('=')[0]} is set by the search for each run" in err


@pytest.mark.parametrize("params", [
    {"kind": "exponential", "beta1": 0.123456789012345, "beta2": -1.5},
    {"kind": "linear", "beta1": 0.25},
    {"kind": "constant", "eps": 0.8},
    {"kind": "exponential", "beta1": 0, "beta2": 1, "lambda_h": 0.5},  # ints, as an enqueued YAML set gives them
])
def test_a_trials_runs_are_those_of_hersd_train_with_the_equivalent_overrides(params: dict, tmp_path: Path) -> None:
    overrides = tiny_search(tmp_path / "results", "algo=archer")
    plan = make_plan(compose_search("wide", []), overrides, "wide")
    for seed in (0, 3):
        ours = trial_config(plan.base, params, seed, threads="1")
        theirs = compose_train([*overrides, *param_overrides(params), f"seed={seed}"])
        assert run_dir(ours) == run_dir(theirs) and config_hash(ours) == config_hash(theirs)
        assert ours.schedule == theirs.schedule and ours.algo == theirs.algo and ours.threads == "1"


def test_run_threads_share_the_cores_unless_given(idle_machine) -> None:
    base = compose_train(TINY)
    assert search_plan.run_threads(base, 2) == str(max(1, available_cores() // 2))  # 1 each on 2 cores
    assert search_plan.run_threads(base, 1) == str(available_cores())
    assert search_plan.run_threads(compose_train([*TINY, "threads=3"]), 2) == "3"
