import math
import re
from dataclasses import dataclass

import numpy as np
import pytest

from hersd.contract.schedules import Constant, Cosine, Exponential, Linear, Success, mean_rate_approx, mean_rate_exact


def test_constant_rate_is_eps_every_epoch():
    schedule = Constant(eps=0.8)
    assert [schedule.rate(k, 200) for k in (1, 100, 200)] == [0.8, 0.8, 0.8]


def test_linear_rate_by_hand():
    schedule = Linear(beta1=0.5)
    # eps(k) = 1 - 0.5 * k / 4
    assert [schedule.rate(k, 4) for k in range(1, 5)] == pytest.approx([0.875, 0.75, 0.625, 0.5])


def test_exponential_rate_by_hand():
    # exp(ln 2) = 2: eps(k) = 1 - 0.5 * (k / 4)^2
    schedule = Exponential(beta1=0.5, beta2=math.log(2))
    assert [schedule.rate(k, 4) for k in range(1, 5)] == pytest.approx(
        [1 - 0.5 / 16, 1 - 0.5 / 4, 1 - 0.5 * 9 / 16, 0.5])
    # beta2 < 0 is convex: exp(-ln 2) = 1/2, eps(1) = 1 - 0.5 * (1/4)^0.5 = 0.75
    convex = Exponential(beta1=0.5, beta2=-math.log(2))
    assert convex.rate(1, 4) == pytest.approx(0.75)


def test_final_rate_is_one_minus_beta1():
    for beta2 in (-1.0, 0.0, 0.75):
        assert Exponential(beta1=0.3, beta2=beta2).rate(50, 50) == pytest.approx(0.7)


def test_mean_rate_exact_eq10_by_hand():
    assert mean_rate_exact(0.5, 0.0, 4) == pytest.approx((0.875 + 0.75 + 0.625 + 0.5) / 4)
    assert mean_rate_exact(0.5, math.log(2), 2) == pytest.approx((0.875 + 0.5) / 2)


def test_mean_rate_approx_eq11_by_hand_and_as_limit():
    assert mean_rate_approx(0.5, 0.0) == pytest.approx(0.75)
    assert mean_rate_approx(0.5, math.log(2)) == pytest.approx(1 - 0.5 / 3)
    # paper, Fig. 12: beta1 = beta2 = 0.5 lies in the optimal band [0.8, 0.889], 0.25 just above it
    assert mean_rate_approx(0.5, 0.5) == pytest.approx(1 - 0.5 / (1 + np.exp(0.5)))
    assert 0.8 <= mean_rate_approx(0.5, 0.5) <= 0.889 < mean_rate_approx(0.25, 0.25) < 0.891
    assert mean_rate_exact(0.75, 0.5, 100_000) == pytest.approx(mean_rate_approx(0.75, 0.5), abs=1e-4)


def test_each_kind_gives_its_exact_mean_rate():
    assert Constant(eps=0.8).exact_mean_rate(200) == 0.8
    assert Linear(beta1=0.5).exact_mean_rate(4) == pytest.approx(0.6875)


def test_success_schedule_by_hand():
    schedule = Success(beta1=0.5, window=2, eps_min=0.7)
    assert schedule.rate(1, 10, []) == 1.0  # nothing learnt yet: relabel everything
    assert schedule.rate(2, 10, [0.2]) == pytest.approx(1 - 0.5 * 0.2)
    assert schedule.rate(4, 10, [0.0, 0.2, 0.4]) == pytest.approx(1 - 0.5 * 0.3)  # last 2 epochs
    assert schedule.rate(5, 10, [1.0, 1.0, 1.0, 1.0]) == 0.7  # clipped at eps_min
    assert schedule.exact_mean_rate(10) is None  # known only from the run's log


def test_success_schedule_follows_its_formula_on_logged_success_and_resumes_exactly(tmp_path):
    from helpers import TINY, metrics

    from hersd.contract.compose import compose_train
    from hersd.contract.runlog import read_run
    from hersd.engine.train import train

    # A 0.15 m success radius: FetchReach's goals lie within 0.15 m of the gripper's start, so
    # even the barely trained policy succeeds in some train episodes and the rate moves.
    beta1, window, eps_min, epochs = 0.9, 2, 0.5, 5
    args = [*TINY, "quiet=true", "threads=1", f"epochs={epochs}", "task.distance_threshold=0.15", "schedule=success",
            f"schedule.beta1={beta1}", f"schedule.window={window}", f"schedule.eps_min={eps_min}"]
    reference = read_run(train(compose_train([*args, f"results_dir={tmp_path / 'ref'}"]))).epochs
    success = reference["train_success"].tolist()
    assert any(s > 0 for s in success[:-1]), success  # the rate has something to follow
    expected = [1.0]  # eps(k) = clip(1 - beta1 * mean of the last `window` successes before k, eps_min, 1)
    for k in range(2, epochs + 1):
        recent = success[max(0, k - 1 - window):k - 1]
        expected.append(min(1.0, max(eps_min, 1.0 - beta1 * sum(recent) / len(recent))))
    assert min(expected) < 1.0, success
    assert reference["relabel_rate"].tolist() == pytest.approx(expected, abs=1e-12), success

    class Stop(Exception):
        pass

    def stop_after_2(record):
        if record["epoch"] == 2:
            raise Stop

    cut = compose_train([*args, f"results_dir={tmp_path / 'cut'}"])
    with pytest.raises(Stop):
        train(cut, on_epoch=stop_after_2)
    resumed = train(cut)
    assert metrics(resumed).equals(reference.drop(columns=[c for c in reference if c.endswith("_seconds")]))


def test_train_help_states_every_schedules_formula_and_settings(capsys):
    from hersd.engine.cli import main

    main(["--help"])
    out = capsys.readouterr().out
    formulas = out[out.index("schedules (eps(k)"):]
    assert "success: eps(k) = clip(1 - beta1 * s(k), eps_min, 1)" in formulas
    assert "exponential: eps(k) = 1 - beta1 * (k / K) ** exp(beta2)" in formulas
    assert "cosine: eps(k) = end + (start - end) * (1 + cos(pi * k / K)) / 2" in formulas
    assert "schedule.window=10" in formulas and "schedule.from_run=null" in formulas


def test_train_help_lists_a_preset_of_ones_own_and_its_class_settings(tmp_path, monkeypatch, capsys):
    """``schedule=step hydra.searchpath=[file://<folder>]``, the route docs/ARCHITECTURE.md gives for one's own
    kind beside the paper's in a sweep: --help listed neither the preset nor its class's settings."""
    from hersd.engine.cli import main

    (tmp_path / "conf" / "schedule").mkdir(parents=True)
    (tmp_path / "conf" / "schedule" / "mystep.yaml").write_text("_target_: help_steps.HelpStep\nhigh: 0.9\n")
    (tmp_path / "help_steps.py").write_text(
        "from dataclasses import dataclass\nfrom hersd.contract.schedules import Schedule, param\n\n\n@dataclass\n"
        "class HelpStep(Schedule):\n    high: float = param(0.9, 0.0, 1.0, 'the rate before epoch 3')\n\n"
        "    def rate(self, k, total_epochs, train_success=()):\n        return self.high if k < 3 else 0.5\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    main(["schedule=mystep", f"hydra.searchpath=[file://{tmp_path / 'conf'}]", "--help"])
    out = capsys.readouterr().out
    assert "|mystep|" in next(line for line in out.splitlines() if line.startswith("  schedule="))
    assert "help_steps.HelpStep:" in out and "schedule.high=0.9" in out and "the rate before epoch 3" in out


def test_cosine_runs_from_start_to_end_and_its_exact_mean_rate_is_its_formulas():
    schedule = Cosine(start=0.9, end=0.3)
    for total in (1, 2, 7, 200):
        rates = schedule.epoch_rates(total)
        assert rates[-1] == pytest.approx(0.3) and np.all(np.diff(rates) <= 1e-12)
        assert schedule.exact_mean_rate(total) == pytest.approx(float(np.mean(rates)), abs=1e-12)
    assert schedule.limit_mean_rate() == pytest.approx(0.6)


def test_table_rates_inline_from_a_file_and_from_a_runs_log(tmp_path):
    from analysis.synthetic import write_run
    from hersd.contract.config import TrainConfig
    from hersd.contract.errors import ConfigError

    inline = TrainConfig(schedule={"kind": "table", "rates": [0.9, 0.8, 0.7]}, epochs=3).schedule
    assert list(inline.epoch_rates(3)) == [0.9, 0.8, 0.7] and inline.exact_mean_rate(3) == pytest.approx(0.8)
    (tmp_path / "rates.txt").write_text("0.9, 0.8\n0.7\n")
    from_file = TrainConfig(schedule={"kind": "table", "file": str(tmp_path / "rates.txt")}, epochs=3).schedule
    assert from_file.record() == inline.record() and from_file.tag() == inline.tag()  # the rates, not the path
    # a success-driven run's realised rates replayed as a function of the epoch
    success = TrainConfig(schedule={"kind": "success", "beta1": 0.5, "window": 1}, epochs=4)
    write_run(tmp_path / "run", success, np.array([0.0, 0.5, 1.0, 1.0]))
    replay = TrainConfig(schedule={"kind": "table", "from_run": str(tmp_path / "run")}, epochs=4).schedule
    assert list(replay.epoch_rates(4)) == pytest.approx([1.0, 1 - 0.5 * 0.9 * 0.0, 1 - 0.5 * 0.9 * 0.5, 1 - 0.5 * 0.9])
    assert replay.record()["from_run"] is None and replay.tag().startswith("table-")
    kept = tmp_path / "run.mcap.orig"  # a log itself, under any name, as every reader of a run takes it
    kept.write_bytes((tmp_path / "run" / "run.mcap").read_bytes())
    assert TrainConfig(schedule={"kind": "table", "from_run": str(kept)}, epochs=4).schedule.record() == replay.record()
    with pytest.raises(ConfigError, match="^schedule.rates holds 3 rates but epochs=5"):
        TrainConfig(schedule={"kind": "table", "rates": [0.9, 0.8, 0.7]}, epochs=5)
    with pytest.raises(ConfigError, match="^schedule.from_run="):
        TrainConfig(schedule={"kind": "table", "from_run": str(tmp_path / "nowhere")}, epochs=4)


def kind_literals(source: str, kinds) -> list[tuple[int, str]]:
    """(line, name) where ``source`` writes a name of ``kinds`` as a schedule's kind: compared (==, !=, in) with an
    expression that reads a kind (``x.kind``, ``x["kind"]``, a name holding "kind"), assigned to one, as a ``"kind"``
    value or a ``kind=`` argument, as a key of a dict literal (a table by kind) or an index of ``SCHEDULES``. Other
    strings that happen to equal a kind's name (Adam's state key 'step', an env's info key 'success') are not kinds."""
    import ast

    def reads_kind(node) -> bool:
        return any(isinstance(part, ast.Attribute) and "kind" in part.attr or isinstance(part, ast.Name) and
                   "kind" in part.id or isinstance(part, ast.Constant) and part.value == "kind"
                   for part in ast.walk(node))

    def literals(node) -> list:  # the kind names a node is, or holds as a tuple, list or set
        elements = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else [node]
        return [element for element in elements if isinstance(element, ast.Constant) and element.value in kinds]

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(reads_kind(side) for side in (node.left, *node.comparators)):
            found += [literal for side in (node.left, *node.comparators) for literal in literals(side)]
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None and any(
                reads_kind(target) for target in getattr(node, "targets", [getattr(node, "target", None)])):
            found += literals(node.value)
        elif isinstance(node, ast.Dict):
            found += [literal for key in node.keys if key is not None for literal in literals(key)]
            found += [literal for key, value in zip(node.keys, node.values)
                      if isinstance(key, ast.Constant) and key.value == "kind" for literal in literals(value)]
        elif isinstance(node, ast.keyword) and node.arg and "kind" in node.arg:
            found += literals(node.value)
        elif isinstance(node, ast.Subscript) and "SCHEDULES" in ast.unparse(node.value):
            found += literals(node.slice)
    return sorted({(literal.lineno, literal.value) for literal in found})


def kind_literals_outside_their_files(kinds) -> list[str]:
    """Every place of the tree's layers that writes a kind of ``kinds`` as a kind, outside that kind's own file."""
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    found = []
    for package in ("hersd", "sweeps", "analysis", "scripts"):
        for path in sorted((root / package).rglob("*.py")):
            name = path.relative_to(root).as_posix()
            found += [f"{name}:{line} {kind!r}" for line, kind in kind_literals(path.read_text(encoding="utf-8"), kinds)
                      if name != f"hersd/contract/schedules/{kind}.py"]
    return found


def test_kind_names_are_literals_only_in_their_own_schedule_file():
    """Every other layer asks the schedule (its class, its record) instead of matching on its kind."""
    from hersd.contract.schedules import SCHEDULES

    assert not kind_literals_outside_their_files(SCHEDULES)


def test_a_schedule_named_step_would_pass_the_kind_name_check():
    """docs/ARCHITECTURE.md's example kind, ``step``: the tree's other 'step' (Adam's state key in
    hersd/engine/learners/fast.py) is no kind; every way of matching on a kind is found."""
    from hersd.contract.schedules import SCHEDULES

    assert not kind_literals_outside_their_files({*SCHEDULES, "step"})
    source = """if cfg.schedule.kind == "linear": pass
titles = {"cosine": "Cosine"}
record = {"kind": "step", "beta1": 0.5}
built = make(kind="constant")
cls = SCHEDULES["success"]
if record["kind"] in ("table", "exponential"): pass
kind = "step"
adam = state["step"]; reached = info["success"]; renamed = {"test_success": "success"}"""
    assert kind_literals(source, {*SCHEDULES, "step"}) == [
        (1, "linear"), (2, "cosine"), (3, "step"), (4, "constant"), (5, "success"), (6, "exponential"), (6, "table"),
        (7, "step")]


def test_a_table_replaying_a_success_runs_log_computes_that_run_again(tmp_path):
    """The one-line control: the rates a success-driven run realised, replayed as a function of the epoch,
    give the same run (same seed) epoch for epoch, in a folder of its own."""
    from helpers import TINY, metrics

    from hersd.contract.compose import compose_train
    from hersd.engine.train import train

    args = [*TINY, "quiet=true", "threads=1", "epochs=3", "task.distance_threshold=0.15", f"results_dir={tmp_path}"]
    adaptive = train(compose_train([*args, "schedule=success", "schedule.beta1=0.9", "schedule.window=1"]))
    replay = train(compose_train([*args, "schedule=table", f"schedule.from_run={adaptive.parent}"]))
    assert replay.parent.parent.name.startswith("table-") and replay.parent != adaptive.parent
    assert metrics(adaptive)["relabel_rate"].min() < 1.0  # the rate moved, so a table ignoring the log would differ
    assert metrics(replay).equals(metrics(adaptive))


def test_an_exponential_schedule_with_beta2_0_is_the_linear_one_and_finds_its_committed_runs():
    """+grid=beta's beta2 = 0 column: its runs are linear 0.25's, committed under linear-b1_0.25."""
    from pathlib import Path

    from hersd.contract.compose import compose_train
    from hersd.contract.runstore import run_dir

    made = [compose_train(["task=push", "seed=0", *schedule]) for schedule in (
        ["schedule.kind=exponential", "schedule.beta1=0.25", "schedule.beta2=0.0"], ["schedule=linear"])]
    assert all(isinstance(cfg.schedule, Linear) for cfg in made)
    assert run_dir(made[0]) == run_dir(made[1]) and run_dir(made[0]).parent.name == "linear-b1_0.25"
    assert (Path(__file__).resolve().parents[1] / run_dir(made[0]) / "run.mcap").is_file()  # a committed run


@pytest.mark.parametrize("settings, rate", [
    (["schedule.kind=linear", "schedule.beta1=0"], 1.0),
    (["schedule.kind=exponential", "schedule.beta1=0", "schedule.beta2=0.5"], 1.0),
    (["schedule.kind=exponential", "schedule.beta1=0.0", "schedule.beta2=0"], 1.0),
    (["schedule.kind=cosine", "schedule.start=0.7", "schedule.end=0.7"], 0.7),
])
def test_settings_that_make_a_constant_rate_file_their_runs_as_that_constant(settings, rate):
    """linear beta1 = 0, exponential beta1 = 0 and cosine start = end were three folders of one constant rate."""
    from hersd.contract.compose import compose_train
    from hersd.contract.runstore import run_dir

    made, constant = (compose_train(["task=push", "epochs=20", *schedule]) for schedule in (
        settings, ["schedule=constant", f"schedule.eps={rate}"]))
    assert type(made.schedule) is Constant and run_dir(made) == run_dir(constant)
    given = {"linear": Linear(), "exponential": Exponential(beta2=0.5), "cosine": Cosine(start=0.7, end=0.7)}
    kind = settings[0].removeprefix("schedule.kind=")
    as_given = given[kind] if kind == "cosine" else type(given[kind])(**{**vars(given[kind]), "beta1": 0.0})
    assert list(as_given.epoch_rates(20)) == list(made.schedule.epoch_rates(20)) == [rate] * 20  # bit for bit
    assert Linear(mean_rate=1.0).equivalent() == Linear(mean_rate=1.0)  # beta1 not yet solved: itself


def test_a_subclass_of_the_exponential_kind_at_beta2_0_stays_itself():
    """Only the package's exponential at beta2 = 0 is the linear kind: a subclass's rate may be its own."""

    @dataclass
    class Steeper(Exponential):
        def rate(self, k, total_epochs, train_success=()):
            return 1.0 - self.beta1 * (k / total_epochs) ** 2

    steeper = Steeper(beta1=0.5)
    assert steeper.equivalent() is steeper
    assert type(Exponential(beta1=0.5).equivalent()).__name__ == "Linear"


@pytest.mark.parametrize("typed", [["schedule=linear", "schedule.beta1=1"], ["schedule=constant", "schedule.eps=1"],
                                   ["schedule=exponential", "schedule.beta2=1"]])
def test_a_setting_typed_as_a_whole_number_is_the_same_run_as_its_float(typed):
    """schedule.beta1=1 and schedule.beta1=1.0 are one setting, one run folder (a float setting takes 1 as 1.0)."""
    from hersd.contract.compose import compose_train
    from hersd.contract.runstore import run_dir

    as_float = [*typed[:1], f"{typed[1]}.0"]
    assert run_dir(compose_train(typed)) == run_dir(compose_train(as_float))


@pytest.mark.parametrize("declared, says", [("step", "nothing registers"), ("cosine", "is another class")])
def test_a_class_chosen_by_its_path_declaring_a_kind_no_one_registers_for_it_is_refused(monkeypatch, declared, says):
    """Its logs would record that kind: read back, "step" finds nothing (the report skipped every such run) and
    "cosine" finds the package's cosine (the report pooled the two)."""
    from hersd.contract.errors import ConfigError
    from hersd.contract.schedules import Schedule, registry

    @dataclass
    class Step(Schedule):
        kind = declared

        def rate(self, k, total_epochs, train_success=()):
            return 0.9

    monkeypatch.setattr(registry, "class_at", lambda path, what: Step)
    with pytest.raises(ConfigError, match=rf"^schedule my_pkg\.Step declares kind='{declared}', which {says}"):
        registry.schedule_class("my_pkg.Step")

    @dataclass
    class Unnamed(Step):  # no kind of its own: recorded by its path
        kind = ""

    monkeypatch.setattr(registry, "class_at", lambda path, what: Unnamed)
    assert registry.schedule_class("my_pkg.Unnamed") is Unnamed


def test_a_schedule_class_without_dataclass_is_told_to_add_it(monkeypatch):
    """Without @dataclass its param() settings stay Field objects: its rate was "Field(...), not in [0, 1]"."""
    from hersd.contract.errors import ConfigError
    from hersd.contract.schedules import Schedule, param, registry

    class Step(Schedule):
        high: float = param(0.9, 0.0, 1.0, "the rate")

        def rate(self, k, total_epochs, train_success=()):
            return self.high

    monkeypatch.setattr(registry, "class_at", lambda path, what: Step)
    with pytest.raises(ConfigError, match=r"^schedule my_pkg\.Step: put @dataclass above its class"):
        registry.schedule_class("my_pkg.Step")


def test_a_subclass_of_a_package_kind_names_its_own_folder_and_label():
    """FloorLinear(Linear) with a setting of its own is not linear: its folder and label were linear's
    (linear-b1_0.5, "linear b1=0.5"), its setting in neither."""
    from hersd.contract.schedules import param

    @dataclass
    class FloorLinear(Linear):
        floor: float = param(0.1, 0.0, 1.0, "the lowest rate")

    floor = FloorLinear(beta1=0.5)
    assert floor.tag() == "floorlinear-beta1_0.5-mean_rate_null-floor_0.1"
    assert floor.label() == "floorlinear beta1=0.5 mean_rate=null floor=0.1"
    assert (Linear(beta1=0.5).tag(), Linear(beta1=0.5).label()) == ("linear-b1_0.5", "linear b1=0.5")


@pytest.mark.parametrize("rate, taken", [(np.where(True, 0.9, 0.5), 0.9), (np.int64(1), 1.0), (np.float32(0.5), 0.5),
                                         (np.array([0.25]), 0.25)])
def test_a_rate_given_as_a_numpy_scalar_or_one_element_array_is_taken(rate, taken):
    """np.where(k <= k0, 0.9, 0.5) is a 0-d array: it was refused as "is 0.9, not in [0, 1]"."""
    from hersd.contract.schedules import Schedule

    @dataclass
    class Numpy(Schedule):
        def rate(self, k, total_epochs, train_success=()):
            return rate

    assert Numpy().checked_rate(1, 10) == taken and type(Numpy().checked_rate(1, 10)) is float


@pytest.mark.parametrize("rate, shown", [("0.9", "'0.9', a str"), (True, "True, a bool"), (1.5, "1.5"),
                                         (math.nan, "nan")])
def test_a_rate_that_is_no_number_in_0_1_says_what_it_is(rate, shown):
    from hersd.contract.schedules import Schedule
    from hersd.contract.schedules.base import ScheduleRateError

    @dataclass
    class Odd(Schedule):
        def rate(self, k, total_epochs, train_success=()):
            return rate

    with pytest.raises(ScheduleRateError, match=rf"its rate at epoch 1 of 10 is {re.escape(shown)}, not in \[0, 1\]"):
        Odd().checked_rate(1, 10)


@pytest.mark.parametrize("low, high", [(None, None), (1.0, 0.0), ("0", 1.0), (False, 1.0)])
def test_a_param_range_that_is_not_two_ordered_numbers_is_one_line(low, high):
    """param(0.5, None, None, ...) passed, then a search or check failed on "'<=' not supported"."""
    from hersd.contract.errors import ConfigError
    from hersd.contract.schedules import param

    with pytest.raises(ConfigError, match=r"^param\(0\.5, .*\): its range must be two numbers, low <= high"):
        param(0.5, low, high, "the rate")
    assert param(3, 1, float("inf"), "epochs", integer=True).metadata["high"] == float("inf")


@pytest.mark.parametrize("beta2, tag, label", [(0.0, "rising-b1_0.25", "rising b1=0.25"),
                                               (0.25, "rising-b1_0.25-b2_0.25", "rising b1=0.25 b2=0.25")])
def test_the_rising_schedule_is_the_decays_rates_in_reverse_order_with_its_mean_rate(beta2, tag, label):
    """eps_rev(k) = eps(K + 1 - k) of the linear (beta2 = 0) and exponential decay: the same multiset of K rates,
    the same mean rate (eq. 10), a folder and a label of its own."""
    from hersd.contract.schedules import Rising, settle

    total = 200
    rising = settle(Rising(beta1=0.25, beta2=beta2), total)
    decay = Exponential(beta1=0.25, beta2=beta2).equivalent()
    assert np.array_equal(rising.epoch_rates(total), decay.epoch_rates(total)[::-1])
    assert sorted(rising.epoch_rates(total)) == sorted(decay.epoch_rates(total))
    assert (rising.rate(1, total), rising.rate(total, total)) == pytest.approx((0.75, 1 - 0.25 * (1 / total) ** math.exp(beta2)))
    assert abs(rising.exact_mean_rate(total) - decay.exact_mean_rate(total)) < 1e-12
    assert abs(np.mean(rising.epoch_rates(total)) - decay.exact_mean_rate(total)) < 1e-12
    assert (rising.tag(), rising.label()) == (tag, label) and tag not in (decay.tag(), "linear-b1_0.25")


def test_the_rising_preset_is_linear_025_reversed_and_the_late_rate_preset_is_constant_075():
    from hersd.contract.compose import compose_train

    rising = compose_train(["schedule=rising_linear_025"]).schedule
    decay = compose_train(["schedule=paper_linear_025"]).schedule
    assert rising.tag() == "rising-b1_0.25" and rising.exact_mean_rate(200) == pytest.approx(0.874375, abs=1e-12)
    assert np.array_equal(rising.epoch_rates(200), decay.epoch_rates(200)[::-1])
    late = compose_train(["schedule=constant_075"]).schedule
    assert (late.tag(), late.exact_mean_rate(200)) == ("constant-0.75", 0.75) == (late.tag(), decay.rate(200, 200))


@pytest.mark.parametrize("read", [len, list, bool, lambda history: history[-1], lambda history: np.asarray(history).size,
                                  lambda history: history.index(1.0)])
def test_a_fixed_schedule_whose_rate_reads_train_success_is_refused_in_one_line(read):
    """Its fixed rates were computed once, with train_success=(): ``0.3 if len(train_success) else 0.9`` without
    ``adaptive = True`` trained at 0.9 in every epoch."""
    from hersd.contract.errors import ConfigError
    from hersd.contract.schedules import Schedule
    from hersd.contract.schedules.base import check_rates

    @dataclass
    class ReadsSuccess(Schedule):
        def rate(self, k, total_epochs, train_success=()):
            return 0.3 if read(train_success) else 0.9

    with pytest.raises(ConfigError) as error:
        check_rates(ReadsSuccess(), 4)
    assert str(error.value) == (f"{__name__}.{ReadsSuccess.__qualname__}.rate reads train_success: declare adaptive "
                                "= True in the class (docs/ARCHITECTURE.md, \"Add a schedule\")")
    ReadsSuccess.adaptive = True
    assert check_rates(ReadsSuccess(), 4) is None


def test_hersd_train_stops_a_fixed_schedule_reading_train_success_before_any_work(tmp_path, monkeypatch, capsys):
    from helpers import TINY

    from hersd.engine.cli import main

    (tmp_path / "reads_success.py").write_text(
        "from dataclasses import dataclass\nfrom hersd.contract.schedules import Schedule\n\n\n@dataclass\n"
        "class ReadsSuccess(Schedule):\n    def rate(self, k, total_epochs, train_success=()):\n"
        "        return 0.3 if len(train_success) else 0.9\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, "schedule._target_=reads_success.ReadsSuccess", "epochs=3", f"results_dir={tmp_path / 'runs'}"])
    assert exit_info.value.code == 2 and not (tmp_path / "runs").exists()
    assert capsys.readouterr().err == ("hersd-train: error: reads_success.ReadsSuccess.rate reads train_success: declare "
                                       "adaptive = True in the class (docs/ARCHITECTURE.md, \"Add a schedule\")\n")
