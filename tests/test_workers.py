"""analysis/workers.py: jobs in forked worker processes."""

from __future__ import annotations

import gc
import multiprocessing
import time

import pytest

from analysis.workers import ForkedMap


def test_forked_jobs_give_the_results_in_order_and_raise_their_errors():
    items = list(range(12))
    assert ForkedMap(lambda x: x * x, items, workers=2).results() == [x * x for x in items]
    assert ForkedMap(lambda x: x + 1, items, workers=1).results() == [x + 1 for x in items]  # in this process
    with pytest.raises(ZeroDivisionError):
        ForkedMap(lambda x: 1 / (x - 3), items, workers=2).results()


def test_an_error_in_the_parent_while_the_workers_run_stops_them_and_unfreezes_the_objects():
    with pytest.raises(RuntimeError, match="statistics failed"):
        with ForkedMap(lambda seconds: time.sleep(seconds), [30.0, 30.0], workers=2):
            assert gc.get_freeze_count() > 0
            raise RuntimeError("statistics failed")  # as when the report's statistics raise while figures draw
    assert gc.get_freeze_count() == 0 and multiprocessing.active_children() == []


def test_a_worker_stopped_while_it_writes_a_file_leaves_no_temporary_file(tmp_path):
    """The parent's error stops the workers (SIGTERM): one writing a report file through its temporary file removes
    it on the way out, as a failed write does (hersd.contract.runlog.replace_file)."""
    from hersd.contract.runlog import replace_file

    def write(path):
        import builtins
        real_open = builtins.open

        def slow_open(*args, **kwargs):
            stream = real_open(*args, **kwargs)
            stream.write(b"half")
            stream.flush()
            time.sleep(30)
            return stream
        builtins.open = slow_open
        replace_file(path, b"whole", sync=False)

    started = time.monotonic()
    with pytest.raises(RuntimeError, match="tables failed"):
        with ForkedMap(write, [tmp_path / "a.png", tmp_path / "b.png"], workers=2):
            while len(list(tmp_path.glob("*.tmp"))) < 2 and time.monotonic() - started < 20:
                time.sleep(0.05)
            raise RuntimeError("tables failed")
    assert list(tmp_path.iterdir()) == [] and multiprocessing.active_children() == []
