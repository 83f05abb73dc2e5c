"""sweeps/search/space.py: what a search draws, the range each setting is drawn from, and their checks."""

from __future__ import annotations

import sys

import pytest
from searches import fails_with, tiny_search
from user_schedules import MODULE, SHARED_MODULE, write_module, write_shared_module

from sweeps.search.config import compose_search
from sweeps.search.space import space_bounds


@pytest.fixture
def newcomer_modules(tmp_path, monkeypatch):
    """tests/user_schedules.py's two modules importable in this process; forgotten afterwards."""
    write_shared_module(write_module(tmp_path))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    for module in (MODULE, SHARED_MODULE):
        sys.modules.pop(module, None)


def _range(kind: str, name: str, *overrides: str) -> tuple[float, float]:
    space = compose_search("default", [f"search.space.kinds=[{kind}]", *overrides]).space
    bounds = space_bounds(space, kind, name)
    return bounds.low, bounds.high


def test_a_class_declaring_beta1_or_eps_itself_is_searched_over_its_declared_range(newcomer_modules) -> None:
    assert _range(f"{SHARED_MODULE}.OwnEps", "eps") == (0.0, 1.0)  # not constant's search.space.eps
    assert _range(f"{SHARED_MODULE}.HalfDrop", "beta1") == (0.0, 0.5)  # not refused for search.space.beta1
    given = "search.space.ranges.beta1={low: 0.1, high: 0.2}"
    assert _range(f"{SHARED_MODULE}.HalfDrop", "beta1", given) == (0.1, 0.2)
    # the package's kinds, and a class inheriting their setting, keep search.space.<name>
    assert _range(f"{SHARED_MODULE}.HerLike", "eps") == _range("constant", "eps") == (0.5, 1.0)
    assert _range("exponential", "beta1", "search.space.beta1.high=0.5") == (0.0, 0.5)


@pytest.mark.parametrize("kinds, message", [
    (f"{MODULE}.KStep,{SHARED_MODULE}.ShortStep", f"search.space.kinds: {MODULE}.KStep and {SHARED_MODULE}.ShortStep "
     "both search k0, over [1, 10000] and [1, 50]; give it one range, search.space.ranges.k0={low: ..., high: ...}"),
    (f"exponential,{SHARED_MODULE}.HalfDrop", f"search.space.kinds: exponential and {SHARED_MODULE}.HalfDrop both "
     "search beta1, over [0, 1] and [0, 0.5]; give it one range, search.space.ranges.beta1="),
    (f"{MODULE}.KStep,{SHARED_MODULE}.WholeLow", f"search.space.kinds: {SHARED_MODULE}.WholeLow declares low a whole "
     f"number and {MODULE}.KStep does not; rename it in one of the classes"),
    (f"{SHARED_MODULE}.LambdaLow", f"search.space.kinds: {SHARED_MODULE}.LambdaLow searches a setting named lambda_h, "
     "the name a trial gives ARCHER's reward weight algo.lambda_h; rename the setting in the class"),
])
def test_two_kinds_drawing_one_setting_two_ways_are_refused_at_start(newcomer_modules, kinds, message, tmp_path,
                                                                     capsys) -> None:
    assert message in fails_with([*tiny_search(tmp_path), f"search.space.kinds=[{kinds}]", "search.n_trials=1"], capsys)


def test_two_kinds_given_one_range_of_a_setting_they_share_are_searched(newcomer_modules) -> None:
    kinds = f"search.space.kinds=[{MODULE}.KStep,{SHARED_MODULE}.ShortStep]"
    space = compose_search("default", [kinds, "search.space.ranges.k0={low: 1, high: 20}"]).space
    assert {space_bounds(space, kind, "k0").high for kind in space.kinds} == {20}
