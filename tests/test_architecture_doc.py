"""docs/ARCHITECTURE.md's factual claims against the tree (tests/test_layers.py checks its layers and modules): the
learner table that spares the engine, the rates checked up front, the bias evaluation's cost in the committed runs,
what figures.py computes, how often a search seed reads its log, the render command apart from the loop, when the
old module paths go; and the docstring examples of the modules it describes."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

import hersd
from hersd.contract.config import FAST_UPDATE_LEARNERS, PACKAGE_LEARNERS
from hersd.contract.learners import package_cards
from hersd.contract.schedules import Schedule
from hersd.contract.schedules.base import CHECKED_UP_FRONT, ScheduleRateError, check_rates

ROOT = Path(__file__).resolve().parent.parent
DOC = " ".join((ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8").split())  # one space between words


def in_fresh_interpreter(code: str) -> str:
    """``code``'s standard output, run by a fresh interpreter (so what it imports is its own)."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip()


def test_a_learner_of_the_contracts_table_loads_no_engine_and_another_name_does():
    """PACKAGE_LEARNERS and FAST_UPDATE_LEARNERS are read from the learners' cards, as the doc says, and it lists
    their names; ``learner.name=td3`` is among them: no torch; a name outside the table and not registered loads
    the packages of hersd.learner_modules (the engine's learners, torch) before it is refused."""
    assert PACKAGE_LEARNERS == {name: card.settings for name, card in package_cards().items()}
    assert FAST_UPDATE_LEARNERS == tuple(name for name, card in package_cards().items() if card.fast_update)
    assert ("the contract's tables of them (`PACKAGE_LEARNERS`, `FAST_UPDATE_LEARNERS` in `hersd/contract/config.py`) "
            "are read from the cards") in DOC
    names = ", ".join(f"`{name}`" for name in PACKAGE_LEARNERS)
    assert f"(`PACKAGE_LEARNERS` in `config.py`: {names}, whose settings it knows without the engine" in DOC
    assert in_fresh_interpreter("""import sys
from hersd.contract.compose import compose_train
assert compose_train(["learner.name=td3"]).learner.name == "td3"
print("torch" in sys.modules, "hersd.engine.learners" in sys.modules)""") == "False False"
    assert in_fresh_interpreter("""import sys
from hersd.contract.config import learner_settings_class
from hersd.contract.errors import ConfigError
try:
    learner_settings_class("nosuchlearner")
except ConfigError:
    print("torch" in sys.modules, "hersd.engine.learners" in sys.modules)""") == "True True"


@dataclass
class LateBad(Schedule):
    """eps(k) = 0.5, then 2 after epoch ``bad_from`` - 1"""

    def rate(self, k, total_epochs, train_success=()):
        return 2.0 if k >= self.bad_from else 0.5


def test_a_fixed_schedules_first_checked_up_front_epochs_are_checked_when_its_run_is_resolved():
    assert f"for each of its first {CHECKED_UP_FRONT:,} epochs (`CHECKED_UP_FRONT` in `base.py`" in DOC
    LateBad.bad_from = CHECKED_UP_FRONT
    with pytest.raises(ScheduleRateError):
        check_rates(LateBad(), CHECKED_UP_FRONT + 1)
    LateBad.bad_from = CHECKED_UP_FRONT + 1
    rates = check_rates(LateBad(), CHECKED_UP_FRONT + 1)  # a later epoch's rate is checked when training reaches it
    assert len(rates) == CHECKED_UP_FRONT and set(rates) == {0.5}


def test_the_bias_evaluations_cost_is_the_committed_reports():
    """The median, least and most ``bias_percent`` of results/report/tables/runs_provenance.csv over the complete runs
    with evaluations (a run in progress has paid for its early evaluations only), and their count, as the doc quotes
    them."""
    table = pd.read_csv(ROOT / "results" / "report" / "tables" / "runs_provenance.csv")
    share = table.loc[table["complete"] & (table["bias_evaluations"] > 0), "bias_percent"]
    quoted = re.search(r"cost a median of ([\d.]+) % of a run \(([\d.]+) % to ([\d.]+) %, [^;]*; (\d+) runs\)", DOC)
    assert quoted, "the doc's sentence on the bias evaluation's cost changed: update this test"
    assert quoted.groups() == (f"{share.median():.2f}", f"{share.min():.2f}", f"{share.max():.2f}", str(len(share)))


def test_figures_py_computes_none_of_what_it_draws():
    """Fig. 1's rates, Fig. 12's outcomes and the critic's curves are computed where the doc says, not in
    analysis/figures.py, which only calls them."""
    import analysis.critic
    import analysis.metrics

    defined = {node.name for node in ast.walk(ast.parse((ROOT / "analysis" / "figures.py").read_text()))
               if isinstance(node, ast.FunctionDef)}
    for module, name in ((analysis.metrics, "schedule_curves"), (analysis.metrics, "mean_rate_outcomes"),
                         (analysis.critic, "critic_curves")):
        assert getattr(module, name).__module__ == module.__name__ and name not in defined
        assert f"`{module.__name__.split('.')[-1]}.py` (" in DOC and f"`{name}`" in DOC


@pytest.mark.parametrize("done_before", [0, 2, 4])
def test_a_search_seed_reads_no_log_new_resumed_or_complete(monkeypatch, tmp_path, done_before):
    """A new run, one resumed after 2 epochs, one found complete: the epochs the log holds reach the objective from
    training (``on_logged``), the others from the per-epoch callback; the objective reads no log."""
    import hersd.engine.train
    from hersd.contract import runlog
    from sweeps.search import objective

    records = [{"epoch": epoch, "test_success": epoch / 4} for epoch in (1, 2, 3, 4)]
    reads = []

    def train(spec, command, on_epoch, on_logged):
        on_logged(records[:done_before])
        for record in records[done_before:]:
            on_epoch(record)

    monkeypatch.setattr(runlog, "read_messages", lambda *args: reads.append(args))
    monkeypatch.setattr(hersd.engine.train, "train", train)
    trial = SimpleNamespace(number=0, set_user_attr=lambda *args: None, report=lambda *args: None,
                            should_prune=lambda: False)
    plan = SimpleNamespace(search=SimpleNamespace(metric="test_success", seeds=1), epochs=4, train_overrides=[],
                           study_name="study", base=SimpleNamespace(threads="1"))
    progress = objective.TrialProgress(trial, "final", 4)
    spec = SimpleNamespace(folder=tmp_path, config=SimpleNamespace(seed=0, threads=1))
    objective.train_seed(trial, plan, progress, {"kind": "linear", "beta1": 0.5}, spec, 0)
    assert reads == [] and progress.value() == 1.0
    assert ("the epochs a resumed or complete run's log already holds reach it from training (`on_logged`, the "
            "records training read), each new one from the per-epoch callback, so the objective reads no log") in DOC


def test_the_loop_imports_no_command():
    """hersd-render is render_cli.py, apart from the renderer train.py uses; pyproject's script names it."""
    assert in_fresh_interpreter("""import sys
import hersd.engine.train
print(sorted(name for name in sys.modules if name in ("hersd.engine.cli", "hersd.engine.render_cli")))""") == "[]"
    assert 'hersd-render = "hersd.engine.render_cli:main"' in (ROOT / "pyproject.toml").read_text()
    assert "`cli.py` is `hersd-train` and `render_cli.py` `hersd-render`: no module of the loop imports a command" \
        in DOC


def test_the_doc_says_when_the_old_module_paths_go():
    assert f"are removed in hersd {hersd.OLD_PATHS_REMOVED_IN} (`OLD_PATHS_REMOVED_IN`)" in DOC
    release = [tuple(int(part) for part in version.split(".")) for version in (hersd.__version__,
                                                                               hersd.OLD_PATHS_REMOVED_IN)]
    assert release[0] < release[1]  # still here in this release


def test_the_group_options_docstrings_example_is_the_task_groups_configs():
    from hersd.contract.compose import group_options

    example = re.search(r"``task`` -> ``\[([^\]]*)\]``", " ".join(group_options.__doc__.split())).group(1)
    assert example.split(", ") == group_options("task")
