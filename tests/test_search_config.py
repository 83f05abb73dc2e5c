"""sweeps/search/config.py: the search configs, their checks and one-line errors."""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

import optuna
import pytest
from searches import fails_with, tiny_search

from hersd.contract.compose import group_options
from hersd.contract.schedules import Constant, Exponential, Linear
from hersd.contract.schedules.base import HER_RATE
from hersd.contract.study import PARAM_NAMES, REWARD_PARAM
from sweeps.search.config import compose_search
from sweeps.search.space import SpaceConfig
from sweeps.search.plan import make_plan
from sweeps.search.study import open_study


@pytest.mark.parametrize("name", group_options("search"))
def test_every_search_config_composes_and_plans(name: str, tmp_path: Path) -> None:
    config = compose_search(name, [])
    assert config.space.beta1.low <= config.space.beta1.high
    plan = make_plan(config, tiny_search(tmp_path), name)  # enqueued sets and range ends make valid runs
    assert plan.study_name.startswith(f"reach-her-{name}-") and plan.base.quiet


@pytest.mark.parametrize("override, message", [
    ("search.space.beta2.low=3", "search.space.beta2: low (3) must be <= high (2)"),
    ("search.space.beta1.high=1.5", "search.space.beta1.high=1.5: schedule.beta1 must be a number in [0, 1]"),
    ("search.space.beta1.low=-0.25", "search.space.beta1.low=-0.25: schedule.beta1 must be a number in [0, 1]"),
    ("search.space.beta2.high=100", "search.space.beta2.high=100: schedule.beta2 must be a number in [-50, 50]"),
    ("search.space.beta1.low=nan", "search.space.beta1: bounds must be finite numbers, got [nan, 1]"),
    ("search.space.lambda_h={low: 0, high: 1}", "search.space.lambda_h: low must be > 0, got 0\n"),  # as given, not 0.0
    ("search.space.kinds=[success]", "search.space.kinds: success cannot be searched"),
    ("search.space.kinds=[sawtooth]", "search.space.kinds: schedule.kind='sawtooth' is unknown"),
    ("search.space.kinds=[]", "search.space.kinds must be a non-empty list of distinct kinds"),
    ("search.space.kinds=[linear,linear]", "search.space.kinds must be a non-empty list of distinct kinds"),
    ("search.space.bogus=1", "search.space.bogus is not a search setting"),
    ("search.objective=best", "search.objective='best' is unknown"),
    ("search.n_trials=-1", "search.n_trials must be >= 1, got -1"),
    ("search.n_trials=1e20", "search.n_trials: Value '1e+20' of type 'float' could not be converted to Integer"),
    ("search.n_jobs=1000000", "search.n_jobs=1000000: local workers are processes of this machine"),
    ("search.seeds=0", "search.seeds must be >= 1, got 0"),
    ("search.first_seed=-1", "search.first_seed must be >= 0, got -1"),
    ("search.stale_after_minutes=0", "search.stale_after_minutes must be > 0"),
    ("search.stale_after_minutes=nan", "search.stale_after_minutes must be > 0"),
    ("search.sampler.seed=-1", "search.sampler.seed must be >= 0 and < 2**32 (4294967296), got -1"),
    ("search.sampler.seed=4294967296", "search.sampler.seed must be >= 0 and < 2**32 (4294967296), got 4294967296"),
    ("search.enqueue=[{beta1: abc}]", "search.enqueue[0].beta1 must be a finite number, got 'abc'"),
    ("search.enqueue=[{beta1: true}]", "search.enqueue[0].beta1 must be a finite number, got True"),
    ("search.enqueue=[{beta1: 2}]", "search.enqueue[0]: schedule.beta1 must be a number in [0, 1], got 2\n"),
    ("search.enqueue=[{eps: 0.5}]", "search.enqueue[0]: eps not searched for kind exponential"),
    ("search.enqueue=[1]", "search.enqueue must be a list of mappings"),
    ("search.study_name=../x", "search.study_name='../x': use 1-200 letters"),
    ("search.storage=foo://x", "search.storage=foo://x: unknown database scheme 'foo'"),
    ("search.storage=sqlite://", "search.storage: an in-memory SQLite database"),
    ("search.storage=", "search.storage is empty"),
    ("search.storage=journal:", "search.storage=journal:<path> needs a file path"),
    ("search.storage=sqlite:///x.db?mode=ro", "quote it: 'search.storage=\"sqlite:///x.db?mode=ro\"'"),
    ("search=nope", "search=nope is not a known search; choose one of: ci, default, wide"),
    ("results_dir=/proc/no-such-dir", "results_dir: cannot write to /proc/no-such-dir"),
    # training overrides Hydra refuses: one line, as hersd-train says them
    ("task=nope", "task=nope is not a known task; choose one of: custom, "),
    ("foo.bar=1", "foo is not a config field; see hersd-train --help"),
    ("epochs=abc", "epochs: Value 'abc' of type 'str' could not be converted to Integer"),
    ("--report", "--report was removed: hersd-search no longer draws figures; draw the study with hersd-report"),
])
def test_bad_search_settings_fail_at_start(override: str, message: str, tmp_path: Path, capsys) -> None:
    assert message in fails_with([*tiny_search(tmp_path), override], capsys)
    assert not (tmp_path / "search").exists()


def test_a_mapping_override_sets_a_null_range() -> None:
    space = compose_search("default", ["search.space.lambda_h={low: 0.25, high: 1.0}"]).space
    assert (space.lambda_h.low, space.lambda_h.high, space.lambda_h.log) == (0.25, 1.0, False)


def test_kinds_of_enqueued_sets_are_inferred_when_several_kinds_are_searched(tmp_path: Path) -> None:
    search = compose_search("default", ["search.space.kinds=[linear,exponential]",
                                        "search.enqueue=[{beta1: 0.25, beta2: 0.25}, {kind: linear, beta1: 0.5}]"])
    plan = make_plan(search, tiny_search(tmp_path))
    study = open_study(plan, optuna.storages.InMemoryStorage())
    assert [t.system_attrs["fixed_params"] for t in study.trials] == [
        {"kind": "exponential", "beta1": 0.25, "beta2": 0.25}, {"kind": "linear", "beta1": 0.5}]


def test_the_search_parameter_names_are_typed_once() -> None:
    from hersd.contract.study import PAPER_SETTINGS

    assert PARAM_NAMES == ("kind", *PAPER_SETTINGS, REWARD_PARAM)
    assert set(PAPER_SETTINGS) == {name for cls in (Constant, Linear, Exponential) for name in cls.searched}
    assert set(PAPER_SETTINGS) <= {item.name for item in fields(SpaceConfig)}
    root = Path(__file__).resolve().parents[1]
    for path in [*sorted((root / "sweeps" / "search").glob("*.py")), root / "analysis" / "search_figures.py"]:
        tree = ast.parse(path.read_text())
        texts = [node.value for node in ast.walk(tree) if isinstance(node, ast.Constant)
                 and isinstance(node.value, str) and "\n" not in node.value and " " not in node.value]
        assert not [text for text in texts if text.split(".")[-1] == REWARD_PARAM], path
        tuples = [{getattr(item, "value", None) for item in node.elts} for node in ast.walk(tree)
                  if isinstance(node, (ast.Tuple, ast.List))]
        assert not [names for names in tuples if set(PAPER_SETTINGS) <= names], path


def test_an_enqueued_set_leaving_a_setting_out_takes_it_as_schedule_kind_sets_it(tmp_path: Path) -> None:
    """Its preset's value (exponential's beta2 = 0.25: the class's 0.0 would be the linear schedule), else the
    class's default (HER's eps)."""
    def fixed(search: str, *overrides: str) -> list[dict]:
        plan = make_plan(compose_search(search, list(overrides)), tiny_search(tmp_path), search)
        return [trial.system_attrs["fixed_params"] for trial in open_study(plan, optuna.storages.InMemoryStorage()).trials]

    assert fixed("wide")[0] == {"kind": "constant", "eps": HER_RATE}  # conf/search/wide.yaml's HER point
    assert fixed("wide", "search.enqueue=[{kind: constant}, {kind: exponential, beta1: 0.25}]") == [
        {"kind": "constant", "eps": HER_RATE}, {"kind": "exponential", "beta1": 0.25, "beta2": 0.25}]
    assert fixed("wide", "search.enqueue=[{kind: linear}, {kind: exponential, beta2: 1.0}]") == [
        {"kind": "linear", "beta1": 0.25}, {"kind": "exponential", "beta1": 0.25, "beta2": 1.0}]


def test_the_default_files_paper_points_go_to_exponential_only(tmp_path: Path, monkeypatch) -> None:
    """default.yaml's two points name their kind: a search of a class of one's own whose settings are also called
    beta1 and beta2 (tests/user_schedules.py's Warp) does not take them, an exponential search does."""
    from user_schedules import MODULE, write_module

    monkeypatch.syspath_prepend(str(write_module(tmp_path)))
    assert compose_search("default", [f"search.space.kinds=[{MODULE}.Warp]"]).enqueue == []
    assert [dict(params) for params in compose_search("default", []).enqueue] == [
        {"kind": "exponential", "beta1": 0.25, "beta2": 0.25}, {"kind": "exponential", "beta1": 0.5, "beta2": 0.5}]
