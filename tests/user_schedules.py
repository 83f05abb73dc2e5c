"""A newcomer's schedules, in a module outside hersd that the tests write into a temporary folder
(``write_module``) and put on the path of a fresh interpreter (``command``): tests/test_user_schedule.py and
tests/test_search_schedules.py import this."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

MODULE = "newcomer_steps"

# KStep declares no tag, label or kind: the defaults name its folders; Warp's settings share eq. 9's names. Over's rate leaves [0, 1] from the
# start, LateOver's (adaptive) at epoch 2, LateRaise's (adaptive) raises there. A fixed schedule's rates are all computed
# when its run is resolved, before any work: what fails once a run is under way is CRASH's learner (below).
SOURCE = '''
from dataclasses import dataclass

from hersd.contract.schedules import Schedule, param


@dataclass
class KStep(Schedule):
    formula = "eps(k) = high for k <= k0, low after"
    searched = ("low", "k0")

    high: float = param(0.9, 0.0, 1.0, "the rate until epoch k0")
    low: float = param(0.5, 0.0, 1.0, "the rate after epoch k0")
    k0: int = param(1, 1, 10_000, "the last epoch at the high rate", integer=True)

    def rate(self, k, total_epochs, train_success=()):
        return self.high if k <= self.k0 else self.low


@dataclass
class Warp(Schedule):
    searched = ("beta1", "beta2")

    beta1: float = param(0.4, 0.3, 0.6, "the drop by epoch K")
    beta2: float = param(0.5, 0.0, 1.0, "the bend: eps(k) = 1 - beta1 (k / K) ** (1 + beta2)")

    def rate(self, k, total_epochs, train_success=()):
        return 1.0 - self.beta1 * (k / total_epochs) ** (1.0 + self.beta2)


@dataclass
class Over(KStep):
    high: float = param(1.4, 0.0, 2.0, "a rate no schedule may give")


@dataclass
class LateOver(Schedule):
    adaptive = True

    def rate(self, k, total_epochs, train_success=()):
        return 0.9 if k == 1 else 1.4


@dataclass
class LateRaise(Schedule):
    adaptive = True

    def rate(self, k, total_epochs, train_success=()):
        return 0.9 / (2 - k)
'''

CRASH_MODULE = "newcomer_crash"
# A learner whose update raises once a run is under way (its epoch 2 at 2 cycles x 5 updates, searches.TINY's),
# after every check: learner._target_=newcomer_crash.Crash; CrashThird: only in the third run of its process.
CRASH = '''
from hersd.engine.learners.ddpg import DDPG


class Crash(DDPG):
    def update(self, batch):
        self.calls = getattr(self, "calls", 0) + 1
        if self.calls > 10:
            raise RuntimeError("boom at epoch 2")
        return super().update(batch)


RUNS = [0]


class CrashThird(Crash):  # only the third run made in this process crashes
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        RUNS[0] += 1
        self.calls = 0 if RUNS[0] == 3 else float("-inf")
'''


def write_module(folder: Path) -> Path:
    """The modules ``newcomer_steps`` and ``newcomer_crash`` written into ``folder`` -> ``folder``."""
    (folder / f"{MODULE}.py").write_text(SOURCE)
    (folder / f"{CRASH_MODULE}.py").write_text(CRASH)
    return folder


def command(module_main: str, args: list[str], module_dir: Path, code: int | None = 0,
            cwd: Path | None = None) -> subprocess.CompletedProcess:
    """A command's entry point in a fresh interpreter with ``module_dir`` on PYTHONPATH, asserting its exit code
    (None: any); started with ``background=True`` semantics by :func:`start`."""
    result = subprocess.run(argv(module_main, args), capture_output=True, text=True, timeout=600,
                            env=environment(module_dir), cwd=cwd)
    assert code is None or result.returncode == code, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def start(module_main: str, args: list[str], module_dir: Path) -> subprocess.Popen:
    """The command of :func:`command` started, not awaited."""
    return subprocess.Popen(argv(module_main, args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(module_dir))


def argv(module_main: str, args: list[str]) -> list[str]:
    module, function = module_main.split(":")
    return [sys.executable, "-c", f"import sys; from {module} import {function}; sys.exit({function}())", *args]


def environment(module_dir: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(module_dir), os.environ.get("PYTHONPATH", "")])}


# A second module of a newcomer's classes, for the search's ranges (tests/test_search_config.py): OwnEps and HalfDrop
# declare settings the package's kinds declare too (eps, beta1), over their own ranges; HerLike inherits constant's
# eps; ShortStep declares KStep's k0 over another range, WholeLow KStep's low as a whole number; LambdaLow a
# setting named as a search's trial names ARCHER's weight.
SHARED_MODULE = "newcomer_shared"
SHARED_SOURCE = '''
from dataclasses import dataclass

from hersd.contract.schedules import Constant, Schedule, param


@dataclass
class OwnEps(Schedule):
    searched = ("eps",)

    eps: float = param(0.8, 0.0, 1.0, "the fixed rate")

    def rate(self, k, total_epochs, train_success=()):
        return self.eps


@dataclass
class HalfDrop(Schedule):
    searched = ("beta1",)

    beta1: float = param(0.25, 0.0, 0.5, "the drop over the run, at most half")

    def rate(self, k, total_epochs, train_success=()):
        return 1.0 - self.beta1 * k / total_epochs


@dataclass
class HerLike(Constant):
    pass


@dataclass
class ShortStep(Schedule):
    searched = ("k0",)

    k0: int = param(5, 1, 50, "the last epoch at rate 0.9", integer=True)

    def rate(self, k, total_epochs, train_success=()):
        return 0.9 if k <= self.k0 else 0.5


@dataclass
class LambdaLow(Schedule):
    searched = ("lambda_h",)

    lambda_h: float = param(0.5, 0.0, 1.0, "the rate (a name a search's trial gives ARCHER's weight)")

    def rate(self, k, total_epochs, train_success=()):
        return self.lambda_h


@dataclass
class WholeLow(Schedule):
    searched = ("low",)

    low: int = param(1, 0, 1, "the rate, 0 or 1", integer=True)

    def rate(self, k, total_epochs, train_success=()):
        return float(self.low)
'''


def write_shared_module(folder: Path) -> Path:
    """The module ``newcomer_shared`` written into ``folder`` -> ``folder``."""
    (folder / f"{SHARED_MODULE}.py").write_text(SHARED_SOURCE)
    return folder
