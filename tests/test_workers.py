"""analysis/workers.py: jobs in forked worker processes."""

from __future__ import annotations

import pytest

from analysis.workers import ForkedMap


def test_forked_jobs_give_the_results_in_order_and_raise_their_errors():
    items = list(range(12))
    assert ForkedMap(lambda x: x * x, items, workers=2).results() == [x * x for x in items]
    assert ForkedMap(lambda x: x + 1, items, workers=1).results() == [x + 1 for x in items]  # in this process
    with pytest.raises(ZeroDivisionError):
        ForkedMap(lambda x: 1 / (x - 3), items, workers=2).results()
