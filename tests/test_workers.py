"""analysis/workers.py: jobs in forked worker processes."""

from __future__ import annotations

import gc
import multiprocessing
import subprocess
import sys
import time

import pytest

from analysis.workers import ForkedMap


def test_forked_jobs_give_the_results_in_order_and_raise_their_errors():
    items = list(range(12))
    assert ForkedMap(lambda x: x * x, items, workers=2).results() == [x * x for x in items]
    assert ForkedMap(lambda x: x + 1, items, workers=1).results() == [x + 1 for x in items]  # in this process
    with pytest.raises(ZeroDivisionError):
        ForkedMap(lambda x: 1 / (x - 3), items, workers=2).results()


def test_an_error_in_the_parent_while_the_workers_run_ends_them_and_unfreezes_the_objects():
    """The running jobs finish (a figure is seconds; the workers are never signalled), those not started are
    cancelled, and no worker is left."""
    with pytest.raises(RuntimeError, match="statistics failed"):
        with ForkedMap(lambda seconds: time.sleep(seconds), [1.0] * 8, workers=2):
            assert gc.get_freeze_count() > 0
            raise RuntimeError("statistics failed")  # as when the report's statistics raise while figures draw
    assert gc.get_freeze_count() == 0 and multiprocessing.active_children() == []


def test_workers_stopped_after_every_map_never_hang_the_parent():
    """The parent ends its workers after every map (``close``): many maps, in a fresh process, none waits."""
    program = ("from analysis.workers import ForkedMap\n"
               "for _ in range(60):\n"
               "    assert ForkedMap(abs, list(range(-3, 3)), workers=2).results() == [3, 2, 1, 0, 1, 2]\n")
    _fresh_python(program, timeout=120, hung="the parent hung ending its workers")


def test_a_worker_that_dies_is_an_error_not_a_hang():
    """A worker killed as it works (the OOM killer, ``kill -9``, a job's module calling sys.exit or os._exit) lost
    its job: the pool started another worker and waited for that job forever, the report hanging. Now ``results``
    raises WorkerLostError naming the worker's exit, and no worker is left."""
    program = ("import os, multiprocessing\n"
               "from analysis.workers import ForkedMap, WorkerLostError\n"
               "try:\n"
               "    ForkedMap(lambda x: os._exit(9) if x == 1 else x, [0, 1, 2, 3], workers=2).results()\n"
               "except WorkerLostError as err:\n"
               "    print(err)\n"
               "assert multiprocessing.active_children() == []\n")
    assert _fresh_python(program, timeout=60, hung="the parent hung waiting for the job of a worker that died") == "a worker process stopped before finishing its jobs (killed, or out of memory?)"


def test_an_idle_worker_killed_while_another_works_is_no_hang():
    """A ``multiprocessing.Pool`` whose idle worker (holding the task queue's lock as it waits) was killed hung in
    its own terminate(); the pool now breaks at once: the other job's result, or WorkerLostError, never a wait."""
    program = ("import os, signal, time, tempfile, multiprocessing\n"
               "from pathlib import Path\n"
               "from analysis.workers import ForkedMap, WorkerLostError\n"
               "mark = Path(tempfile.mkdtemp()) / 'idle'\n"
               "def job(x):\n"
               "    if x == 1:\n"
               "        mark.write_text(str(os.getpid()))\n"
               "        return x\n"
               "    while not mark.exists():\n"
               "        time.sleep(0.01)\n"
               "    time.sleep(0.5)\n"  # the other worker is idle now, waiting for a job
               "    os.kill(int(mark.read_text()), signal.SIGKILL)\n"
               "    time.sleep(1.0)\n"
               "    return x\n"
               "try:\n"
               "    print(ForkedMap(job, [0, 1], workers=2).results())\n"
               "except WorkerLostError as err:\n"
               "    print(err)\n"
               "assert multiprocessing.active_children() == []\n")
    assert _fresh_python(program, timeout=60, hung="the parent hung after an idle worker was killed") in ("[0, 1]", "a worker process stopped before finishing its jobs (killed, or out of "
                                              "memory?)")


def _fresh_python(program: str, timeout: float, hung: str) -> str:
    """``program`` run by a new interpreter -> its stdout, stripped; the test fails with ``hung`` past ``timeout``
    seconds, or with the program's stderr if it fails."""
    try:
        done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(hung)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


# Two jobs that each mark their start (a file named by the worker's pid in the folder given as argv[1]), the first
# then sleeping argv[2] seconds, the second none (its worker then idles); the parent prints "interrupted" on a Ctrl-C
# and exits 130.
SLEEPING_JOBS = """
import os, sys, time
from pathlib import Path
from analysis.workers import ForkedMap

def job(seconds):
    (Path(sys.argv[1]) / str(os.getpid())).touch()
    time.sleep(seconds)
    return seconds

try:
    ForkedMap(job, [float(sys.argv[2]), 0.0], workers=2).results()
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


def _started(folder, seconds: float) -> tuple[subprocess.Popen, list[int]]:
    """SLEEPING_JOBS started in a session of its own, its first job sleeping ``seconds`` -> (it, its workers' pids)
    once both jobs started and the second's worker idles."""
    import signal

    proc = subprocess.Popen([sys.executable, "-c", SLEEPING_JOBS, str(folder), str(seconds)], stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while len(list(folder.iterdir())) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    return proc, [int(path.name) for path in folder.iterdir()]


def test_the_workers_end_within_a_second_of_a_killed_parent(tmp_path):
    """``kill -9`` of the process that forked the workers (the report's): they were left forever, blocked on the
    pool's pipes; each now ends within a second or so."""
    import os
    import signal

    from helpers import group_alive

    proc, workers = _started(tmp_path, seconds=600)
    assert len(workers) == 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not group_alive(proc.pid, seconds=5), "the workers outlived their parent"


def test_a_ctrl_c_lets_the_running_jobs_finish_without_a_traceback(tmp_path):
    """A Ctrl-C (SIGINT to the terminal's process group) reaches the workers too: an idle one printed a
    KeyboardInterrupt traceback (and one stopped while sending its result back would leave the pool reading it
    forever); they now ignore it, the parent alone is interrupted, and it ends once the running job is done."""
    import os
    import signal

    proc, workers = _started(tmp_path, seconds=2)
    assert len(workers) == 2
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.strip() == "interrupted", err
