"""The report's policy animations (analysis/animations.py): per task, each configuration's GIFs from the
complete seed nearest its median final success that has animations, one row per epoch every chosen
seed has (at most four, spread evenly), copied into the report and placed after the task's learning curves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.animations import choose_animations, place_after_curves, shown_epochs
from analysis.load import load_runs
from analysis.metrics import analyse
from analysis.report import build_report
from analysis.synthetic import write_animation, write_run
from hersd.contract.config import TaskConfig, TrainConfig
from hersd.contract.schedules import Constant, Linear

EPOCHS = 6
LINEAR = Linear(beta1=0.5)
# (task, schedule, seed, flat test success = its final smoothed success, epochs with an animation, complete)
RUNS = [
    ("push", Constant(), 0, 0.2, [3, 6], True),
    ("push", Constant(), 1, 0.5, [3, 6], True),  # HER's median: chosen
    ("push", Constant(), 2, 0.9, [3, 6], True),
    ("push", Constant(), 3, 0.85, [3], False),  # in progress: neither counted nor chosen
    ("push", Constant(), 4, 0.88, [3], False),
    ("push", LINEAR, 0, 0.3, [3, 6], True),
    ("push", LINEAR, 1, 0.6, [], True),  # the median, but without animations
    ("push", LINEAR, 2, 0.8, [3], True),  # nearest the median among those with one: only epoch 3
    ("reach", Constant(), 0, 0.7, [6], True),
    ("slide", Constant(), 0, 0.4, [2, 4, 6], True),  # two epochs in common with linear: two rows
    ("slide", LINEAR, 0, 0.6, [1, 4, 6], True),
]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("animated")
    for task, schedule, seed, success, epochs, complete in RUNS:
        run = root / task / schedule.kind / f"seed{seed}"
        config = TrainConfig(task=TaskConfig(name=task), schedule=schedule, seed=seed, epochs=EPOCHS)
        write_run(run, config, np.full(EPOCHS if complete else 4, success), complete=complete)
        for epoch in epochs:
            write_animation(run, epoch)
    return root


def test_each_configuration_shows_its_seed_nearest_the_median_at_matched_epochs(folder):
    table = load_runs(folder)
    chosen = choose_animations(analyse(table.runs, table.epochs, window=3), folder)
    shown = {task: [(item.config, item.seed, item.epoch) for item in items] for task, items in chosen.items()}
    assert shown == {"push": [("HER", 1, 3), ("linear b1=0.5", 2, 3)], "reach": [("HER", 0, 6)],
                     "slide": [("HER", 0, 4), ("linear b1=0.5", 0, 4), ("HER", 0, 6), ("linear b1=0.5", 0, 6)]}
    her = chosen["push"][0]
    assert (her.final, her.median) == pytest.approx((0.5, 0.5))
    assert her.source == folder / "push/constant/seed1/policy/epoch_3.gif"


def test_the_report_copies_them_and_shows_them_after_the_tasks_curves(folder, tmp_path):
    result = build_report(folder, tmp_path / "report", window=3, log=lambda line: None)
    page = result.index.read_text()
    copies = sorted((tmp_path / "report/figures/animations").iterdir())
    assert [copy.name for copy in copies] == ["push_0_HER_seed1_epoch3.gif", "push_1_linear_b1=0.5_seed2_epoch3.gif",
                                              "reach_0_HER_seed0_epoch6.gif", "slide_0_HER_seed0_epoch4.gif",
                                              "slide_1_linear_b1=0.5_seed0_epoch4.gif", "slide_2_HER_seed0_epoch6.gif",
                                              "slide_3_linear_b1=0.5_seed0_epoch6.gif"]
    assert copies[0].read_bytes() == (folder / "push/constant/seed1/policy/epoch_3.gif").read_bytes()
    for copy in copies:
        assert f'src="figures/animations/{copy.name}"' in page
    curves = page.index('<figure id="curves_push')
    assert page.index('<figure id="animations_push"') == page.index("</figure>", curves) + len("</figure>")
    assert "FetchPush: the policies, epoch 3" in page and "FetchReach: the policies, epoch 6" in page
    slide = page[page.index('<figure id="animations_slide"'):]
    slide = slide[:slide.index("<figcaption>Two")]
    assert "FetchSlide: the policies, epochs 4, 6" in slide and slide.count('<div style="display:flex') == 2
    assert slide.index("slide_1_linear") < slide.index("</div>") < slide.index("slide_2_HER")  # one row per epoch


@pytest.mark.parametrize("common, shown", [
    (set(), []), ({200}, [200]), ({50, 100, 150, 200}, [50, 100, 150, 200]),
    (set(range(10, 201, 10)), [10, 70, 140, 200]), ({1, 2, 3, 4, 5}, [1, 2, 4, 5]),
])
def test_at_most_four_epochs_are_shown_evenly_spread_from_first_to_last(common, shown):
    assert shown_epochs(common) == shown


def test_a_report_without_animations_has_no_animation_block(tmp_path):
    write_run(tmp_path / "logs/run", TrainConfig(task=TaskConfig(name="push"), epochs=EPOCHS), np.full(EPOCHS, 0.5))
    page = build_report(tmp_path / "logs", tmp_path / "report", window=3, log=lambda line: None).index.read_text()
    assert "animations_" not in page and not (tmp_path / "report/figures/animations").exists()


def test_blocks_go_after_the_last_curves_of_their_task_else_after_every_figure():
    names = ["schedules", "curves_push_lr1_lh1", "curves_push_lr1_lh0.5", "curves_hand_reach", "q_mean"]
    placed = place_after_curves(names, {"push": "P", "reach": "R", "hand_reach": "H"})
    assert placed == {"curves_push_lr1_lh0.5": ["P"], None: ["R"], "curves_hand_reach": ["H"]}
