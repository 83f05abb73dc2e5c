"""analysis/report.py: the hersd-report command, its errors, files and page, without torch, MuJoCo or the
sweeps layer; the composition table; the study storages it draws."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import metrics
from analysis.figures import composition_figures
from analysis.report import main as report_main, run_state_words
from analysis.synthetic import write_run

from analysis_logs import make_config, write_campaign_midway
from helpers import full_disk_writes
from analysis_logs import run_tables as _tables


def test_empty_folder_is_one_line_error_exit_2(tmp_path, capsys):
    assert exit_status([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no run.mcap files under" in err


def exit_status(arguments: list[str]) -> int:
    """hersd-report's exit status, whether main returns it or argparse exits with it."""
    try:
        return report_main(arguments)
    except SystemExit as exited:
        return exited.code


@pytest.mark.parametrize("arguments, message", [
    (["--smooth", "0"], "--smooth must be at least 1"),
    (["--task", "reach"], "no run matches the filters"),
    (["--format", "gif"], "invalid choice"),
])
def test_bad_options_are_one_line_errors(hand_sized, capsys, tmp_path, arguments, message):
    assert exit_status([str(hand_sized), "--out", str(tmp_path), *arguments]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


@pytest.mark.parametrize("out", ["a_file", "a_file/report"])
def test_an_out_that_is_or_passes_through_a_file_is_one_line_error_exit_2(hand_sized, capsys, tmp_path, out):
    (tmp_path / "a_file").write_text("mine")
    assert exit_status([str(hand_sized), "--out", str(tmp_path / out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a file, not a folder; give --out a folder" in err
    assert (tmp_path / "a_file").read_text() == "mine"


@pytest.mark.parametrize("given, what", [("a_file", "is a file, not a folder"), ("nothing", "does not exist")])
def test_a_folder_that_is_a_file_or_nothing_is_one_line_error_exit_2_before_the_out_check(capsys, tmp_path, given,
                                                                                           what):
    """``hersd-report afile`` said to give --out a folder (afile/report passing through a file): the input is
    the fault."""
    (tmp_path / "a_file").write_text("mine")
    assert exit_status([str(tmp_path / given)]) == 2
    err = capsys.readouterr().err
    assert err == (f"hersd-report: error: FOLDER {tmp_path / given} {what}; give a folder of run logs (run.mcap "
                   "files)\n")
    assert (tmp_path / "a_file").read_text() == "mine"


def test_report_writes_tables_figures_and_self_contained_html(sweep, tmp_path, capsys):
    out = tmp_path / "report"
    assert report_main([str(sweep), "--out", str(out), "--smooth", "3"]) == 0
    printed = capsys.readouterr().out
    assert "loaded 32 runs (0 incomplete, 0 skipped)" in printed and str(out / "index.html") in printed
    figures = sorted(path.stem for path in (out / "figures").glob("*.png"))
    assert figures == sorted(["schedules", "composition_push", "composition_slide", "curves_push_lr1_lh1",
                              "curves_push_lr1_lh0.5", "curves_slide_lr1_lh1", "curves_slide_lr1_lh0.5", "q_mean",
                              "mep", "mean_rate_push", "mean_rate_slide"])
    page = (out / "index.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == len(figures)
    assert "<img" in page and 'src="figures/' not in page
    summary = pd.read_csv(out / "tables" / "summary.csv")
    assert len(summary) == 2 * 8 and set(summary["seeds"]) == {2}
    assert (out / "tables" / "summary.md").read_text(encoding="utf-8").startswith("| task | config |")
    runs = pd.read_csv(out / "tables" / "runs.csv")
    assert len(runs) == 32 and page.count("run.mcap") >= 32
    tests = pd.read_csv(out / "tables" / "permutation_tests.csv")
    assert len(tests) == 2 * 8 * 7  # per task, every ordered pair of its 8 configurations
    assert "112 tests: too many for this page; they are in tables/permutation_tests.md" in page


def test_the_report_page_shows_a_short_list_of_permutation_tests(tmp_path):
    write_campaign_midway(tmp_path / "logs")
    assert report_main([str(tmp_path / "logs"), "--out", str(tmp_path / "report")]) == 0
    page = (tmp_path / "report" / "index.html").read_text(encoding="utf-8")
    assert "<h2>Permutation tests between configurations</h2>" in page and "<th>p: higher final success</th>" in page
    tests = (tmp_path / "report" / "tables" / "permutation_tests.md").read_text(encoding="utf-8")
    assert tests.splitlines()[2].startswith("| push | HER | linear b1=0.5 | 2 | 2 |")


def test_the_decay_against_the_constant_at_its_mean_rate_is_a_table_file_and_a_page_section(tmp_path):
    """linear b1=0.5 over K = 6 and the constant 17/24 (its mu_eps), two seeds each: equal_mu_tests.csv holds a row
    per outcome, summary.csv their mu_eps, the page the section; the Fig. 12 file keeps its name."""
    from hersd.contract.schedules import Constant, Linear

    for seed in (0, 1):
        write_run(tmp_path / "logs" / f"linear{seed}", make_config(schedule=Linear(beta1=0.5),
                                                                    seed=seed), np.full(6, 0.9))
        write_run(tmp_path / "logs" / f"control{seed}", make_config(schedule=Constant(eps=17 / 24), seed=seed),
                  np.full(6, 0.5))
    assert report_main([str(tmp_path / "logs"), "--out", str(tmp_path / "report")]) == 0
    tests = pd.read_csv(tmp_path / "report" / "tables" / "equal_mu_tests.csv")
    assert len(tests) == 6 and set(tests["config"]) == {"linear b1=0.5"} and set(tests["splits"]) == {6}
    summary = pd.read_csv(tmp_path / "report" / "tables" / "summary.csv")
    assert summary["mu_eps"].tolist() == pytest.approx([17 / 24] * 2)
    page = (tmp_path / "report" / "index.html").read_text(encoding="utf-8")
    assert "<h2>Decay or mean rate: each decay against the constant rate at its μ_ε</h2>" in page
    assert (tmp_path / "report" / "figures" / "mean_rate_push.png").exists()


def test_report_filters_and_svg(sweep, tmp_path):
    out = tmp_path / "svg"
    assert report_main([str(sweep), "--out", str(out), "--task", "slide", "--algo", "her", "--format", "svg"]) == 0
    assert {path.suffix for path in (out / "figures").iterdir()} == {".svg"}
    summary = pd.read_csv(out / "tables" / "summary.csv")
    assert set(summary["task"]) == {"slide"}
    assert not summary["config"].str.contains("λh").any() and "ARCHER" not in set(summary["config"])
    assert "data:image/svg+xml;base64," in (out / "index.html").read_text(encoding="utf-8")


def test_report_runs_without_torch_mujoco_or_the_sweeps_layer(sweep, tmp_path):
    # A finder that refuses these packages, in this process and in the report's forked workers:
    # importing one anywhere fails the report. (Setting sys.modules['torch'] = None would also
    # block the import, but scipy's array-API helpers then trip over the None entry.)
    script = (
        "import sys\n"
        "BLOCKED = ('torch', 'mujoco', 'gymnasium_robotics', 'gymnasium', 'sweeps')\n"
        "class Refuse:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in BLOCKED:\n"
        "            raise ImportError(f'{name} is blocked in this test')\n"
        "sys.meta_path.insert(0, Refuse())\n"
        "import analysis.report\n"
        f"sys.exit(analysis.report.main([{str(sweep)!r}, '--out', {str(tmp_path / 'out')!r}, '--task', 'push']))\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert len(list((tmp_path / "out" / "figures").glob("*.png"))) == 7  # drawn in forked workers too


def test_importing_the_report_loads_neither_the_sweeps_layer_nor_heavy_modules():
    code = ("import sys, analysis, analysis.report\n"
            "print(sorted(m for m in ('sweeps', 'torch', 'mujoco', 'optuna', 'matplotlib', 'scipy.stats') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"  # optuna, matplotlib and scipy.stats come only when drawing or computing


def test_composition_at_epoch_150_beside_the_papers(push_paper, tmp_path):
    out = tmp_path / "report"
    assert report_main([str(push_paper), "--out", str(out)]) == 0
    table = pd.read_csv(out / "tables" / "composition_150.csv")
    assert list(table.columns) == ["source", "config", "seeds", "epoch", "share_real_success", "share_hindsight",
                                   "share_real_failure"]
    paper, ours = table.to_dict("records")
    assert (paper["source"], paper["config"], paper["epoch"]) == ("paper (Fig. 2)", "HER", 150)
    assert [paper[c] for c in table.columns[4:]] == pytest.approx([0.053, 0.80, 0.147])
    assert (ours["source"], ours["config"], ours["seeds"], ours["epoch"]) == ("hersd", "HER", 3, 150)
    assert [ours[c] for c in table.columns[4:]] == pytest.approx([0.06, 0.80, 0.14])  # medians of HER_SHARES_150
    page = (out / "index.html").read_text(encoding="utf-8")
    figure_at, table_at = page.index('id="composition_push"'), page.index("epoch 150: hersd vs paper")
    assert figure_at < table_at < page.index("<figure", figure_at + 1)  # right after its figure
    (composition,) = composition_figures(metrics.analyse(*_tables(push_paper), window=50))
    her_panel = composition.draw().axes[0]
    assert her_panel.get_title() == "HER" and [150, 150] in [list(line.get_xdata()) for line in her_panel.get_lines()]


def test_no_composition_table_without_her_runs_that_reached_epoch_150(push_paper, sweep, tmp_path):
    assert report_main([str(sweep), "--out", str(tmp_path / "short"), "--task", "push"]) == 0  # 8 epochs
    assert not (tmp_path / "short" / "tables" / "composition_150.csv").exists()
    runs, epochs = _tables(push_paper)
    others = metrics.analyse(runs[runs["config"] != "HER"], epochs[epochs["config"] != "HER"], window=50)
    assert others.composition_vs_paper.empty  # the constant control (eps 0.874375) is not HER


def test_given_storages_are_drawn(hand_sized, storages, tmp_path, capsys):
    out = tmp_path / "out"
    assert report_main([str(hand_sized), "--out", str(out), "--storage", f"sqlite:///{storages / 'study.db'}",
                        "--storage", f"journal:{storages / 'study.log'}"]) == 0
    assert sorted(path.name for path in (out / "search").iterdir()) == sorted(
        f"{name}_{suffix}" for name in ("in_sqlite", "in_journal")
        for suffix in ("beta_plane.png", "best_trials.csv", "best_trials.md"))
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "Optuna searches" in page and "Best trials: in_journal" in page and "Best trials: in_sqlite" in page
    assert capsys.readouterr().err == ""


def test_storages_in_the_search_folder_are_found_and_a_bad_one_is_skipped(storages, tmp_path, capsys):
    write_run(tmp_path / "run", make_config(), np.linspace(0, 1, 6))
    (tmp_path / "search").mkdir()
    for name in ("study.db", "study.log", "plain.db"):
        (tmp_path / "search" / name).write_bytes((storages / name).read_bytes())
    assert report_main([str(tmp_path), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err.splitlines()
    plain = tmp_path / "search" / "plain.db"
    assert err == [f"warning: skipped study storage {plain}: no Optuna study in this storage"]
    assert {path.name for path in (tmp_path / "out" / "search").glob("*.png")} == {
        "in_sqlite_beta_plane.png", "in_journal_beta_plane.png"}
    assert "study storage" in (tmp_path / "out" / "index.html").read_text(encoding="utf-8")


def test_a_found_file_that_is_no_database_is_skipped_naming_it_first(tmp_path, capsys):
    # docs/ANALYSIS.md: "warning: skipped study storage <path>: <reason>", also for a file SQLite cannot open
    write_run(tmp_path / "run", make_config(), np.linspace(0, 1, 6))
    (tmp_path / "search").mkdir()
    junk = tmp_path / "search" / "junk.db"
    junk.write_text("not a database")
    assert report_main([str(tmp_path), "--out", str(tmp_path / "out")]) == 0
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"warning: skipped study storage {junk}: "), line


def test_the_run_list_says_each_state_in_words():
    assert run_state_words(complete=True, damaged=False, done=200, total=200) == "complete"
    assert run_state_words(complete=False, damaged=False, done=39, total=200) == "in progress (epoch 39 of 200)"
    assert run_state_words(complete=False, damaged=True, done=39, total=200) == (
        "in progress (epoch 39 of 200), log without a valid end")
    assert run_state_words(complete=True, damaged=True, done=200, total=200) == "complete, log without a valid end"


def test_the_readme_opens_with_the_committed_reports_fetchpush_curves_and_their_numbers():
    """README.md's first lines: an image of the committed report (results/report/) and the numbers of
    tables/summary.csv behind it, for HER, the control, the linear decay and the success-driven rate."""
    root = Path(__file__).resolve().parent.parent
    top = (root / "README.md").read_text(encoding="utf-8").split("\nHindsight experience replay")[0]
    (image,) = re.findall(r"\]\((results/report/figures/[^)]+\.png)\)", top)
    assert (root / image).is_file()
    summary = pd.read_csv(root / "results/report/tables/summary.csv").query("task == 'push'").set_index("config").loc[
        ["HER", "HER eps=0.874375", "linear b1=0.25", "success b1=0.25"]]
    text = " ".join(top.split())
    for config, row in summary.iterrows():
        assert f"{row['epochs_to_0.9']:.0f} with" in text, config
    assert "at epoch 200 " + ", ".join(f"{value:.3f}" for value in summary["final_median"][:3]) + " and " + (
        f"{summary['final_median'].iloc[3]:.3f}") in text
    seeds = summary["seeds"]  # complete seeds only: runs in progress stay out of every median
    if seeds.nunique() == 1:
        assert f"({seeds.iloc[0]} seeds each)" in text
    else:
        assert "(" + ", ".join(f"{n}" for n in seeds.iloc[:3]) + f" and {seeds.iloc[3]} complete seeds)" in text


def test_the_readme_opening_gives_fetchpickandplaces_numbers_as_the_committed_tables_say():
    """README.md's FetchPickAndPlace sentence: seeds, median success at epoch 200, the gain, its
    permutation p and the epoch of 0.5, from tables/summary.csv and tables/permutation_tests.csv."""
    root = Path(__file__).resolve().parent.parent
    text = " ".join((root / "README.md").read_text(encoding="utf-8").split("\nHindsight experience replay")[0].split())
    tables = root / "results/report/tables"
    summary = pd.read_csv(tables / "summary.csv").query("task == 'pick_and_place'").set_index("config")
    her, linear = summary.loc["HER"], summary.loc["linear b1=0.25"]
    test = pd.read_csv(tables / "permutation_tests.csv").query(
        "task == 'pick_and_place' and config == 'linear b1=0.25' and versus == 'HER'").iloc[0]
    gain = 100 * (linear["final_median"] / her["final_median"] - 1)
    assert f"{linear['seeds']} complete seeds each" in text and her["seeds"] == linear["seeds"]
    assert (f"at epoch 200 {linear['final_median']:.4g} with the linear decay against {her['final_median']:.4g} "
            f"with HER ({gain:+.1f} %; one-sided permutation p = {test['p_final']:.2g} for the decay") in text
    assert f"0.5 first reached at epoch {linear['epochs_to_0.5']:.0f} against {her['epochs_to_0.5']:.0f}" in text


def test_the_readme_opening_quotes_every_measured_row_of_the_committed_claims_table():
    """README.md's list of the paper's claims: each row of tables/claims.csv with a verdict, worded as the table
    words it (claim, figure, verdict, p as the claims markdown rounds it, seeds)."""
    root = Path(__file__).resolve().parent.parent
    text = " ".join((root / "README.md").read_text(encoding="utf-8").split("\nHindsight experience replay")[0].split())
    claims = pd.read_csv(root / "results/report/tables/claims.csv", dtype=str, keep_default_na=False)
    measured = claims[pd.to_numeric(claims["p"], errors="coerce").notna()]  # not measured, registered: no p
    assert len(measured) > 0
    tasks = {"push": "FetchPush", "pick_and_place": "FetchPickAndPlace", "slide": "FetchSlide"}
    for row in measured.itertuples():
        assert (f"- {tasks[row.task]}, {row.claim} ({row.paper}): {row.verdict} "
                f"(p = {float(row.p):.2g}, {row.seeds} seeds).") in text, row.claim

def test_the_summary_header_names_the_epoch_of_final_success_when_the_rows_share_it(tmp_path):
    for task, epochs in (("push", 6), ("reach", 4)):
        write_run(tmp_path / "logs" / task, make_config(task, epochs=epochs), np.linspace(0, 1, epochs))
    pages = {}
    for name, tasks in (("push", ["push"]), ("both", ["push", "reach"])):
        assert report_main([str(tmp_path / "logs"), "--out", str(tmp_path / name), "--task", *tasks]) == 0
        pages[name] = (tmp_path / name / "index.html").read_text(encoding="utf-8")
    assert "<th>test success at epoch 6, median over seeds</th>" in pages["push"]
    assert "<th>test success at epoch K, median over seeds</th>" in pages["both"]  # FetchReach ran 4 epochs
    assert "<td class=text>FetchPush</td>" in pages["both"] and "<td class=text>FetchReach</td>" in pages["both"]


def _paper_and_smoke(folder: Path, smoke: bool) -> None:
    """HER and linear b1=0.25 on FetchPush at the paper's K = 200 (2 seeds each), an exponential decay on
    FetchPickAndPlace whose two runs are both in progress (epoch 3 of 200), and with ``smoke`` the quick start's
    sweep: FetchReach HER and linear b1=0.25 at K = 4, 2 seeds each."""
    from analysis.load import PAPER_EPOCHS
    from hersd.contract.schedules import Exponential, Linear

    linear = Linear(beta1=0.25)
    for seed in (0, 1):
        for name, schedule in (("her", None), ("linear", linear)):
            write_run(folder / f"push/{name}{seed}", make_config(schedule=schedule, seed=seed, epochs=PAPER_EPOCHS),
                      np.linspace(0, 0.9 + 0.05 * seed, PAPER_EPOCHS))
            if smoke:
                write_run(folder / f"runs/reach/{name}{seed}",
                          make_config(task="reach", schedule=schedule, seed=seed, epochs=4), np.ones(4))
        write_run(folder / f"pick_and_place/exp{seed}",
                  make_config(task="pick_and_place", schedule=Exponential(beta1=0.25, beta2=0.25),
                              seed=seed, epochs=PAPER_EPOCHS), np.zeros(3), complete=False)


def test_a_smoke_sweep_stays_out_of_every_200_epoch_row_and_a_configuration_in_progress_is_listed(tmp_path):
    for name, smoke in (("paper", False), ("both", True)):
        _paper_and_smoke(tmp_path / name, smoke)
        assert report_main([str(tmp_path / name), "--out", str(tmp_path / f"{name}_report"), "--smooth", "5"]) == 0
    for table in ("summary", "aggregate", "permutation_tests"):
        paper, both = (pd.read_csv(tmp_path / f"{name}_report/tables/{table}.csv") for name in ("paper", "both"))
        if "total_epochs" in both:
            assert sorted(both.loc[both["total_epochs"] == 4, "config"]) == ["HER K=4", "linear b1=0.25 K=4"]
            both = both[both["total_epochs"] == 200]
        if "task" in both:
            both = both[both["task"] != "reach"]
        pd.testing.assert_frame_equal(both.reset_index(drop=True), paper)
    summary = pd.read_csv(tmp_path / "both_report/tables/summary.csv").set_index(["task", "config"])
    in_progress = summary.loc[("pick_and_place", "exp b1=0.25 b2=0.25")]
    assert (in_progress["total_epochs"], in_progress["seeds"], in_progress["in_progress"]) == (200, 0, 2)
    assert in_progress[["final_median", "auc", "iqm", "p_improve_HER"]].isna().all()
    page = (tmp_path / "both_report/index.html").read_text(encoding="utf-8")
    assert "FetchPickAndPlace · exp b1=0.25 b2=0.25: 2 runs, 0 complete, 2 in progress</summary>" in page


def test_a_second_report_into_the_same_folder_leaves_no_file_of_the_first(sweep, tmp_path):
    out = tmp_path / "report"
    assert report_main([str(sweep), "--out", str(out)]) == 0
    assert (out / "figures" / "curves_slide_lr1_lh1.png").exists()
    assert report_main([str(sweep), "--out", str(out), "--task", "push", "--algo", "her"]) == 0
    figures = {path.name for path in (out / "figures").glob("*.png")}
    assert figures and not any("slide" in name for name in figures)
    assert not any("lh0.5" in name for name in figures)  # ARCHER's panels went with --algo her
    summary = pd.read_csv(out / "tables" / "summary.csv")
    assert set(summary["task"]) == {"push"}
    page = (out / "index.html").read_text(encoding="utf-8")
    assert all(f'id="{Path(name).stem}"' in page for name in figures)  # every file left is on the page


def test_a_folder_of_ones_own_given_as_out_keeps_its_files(sweep, tmp_path):
    """--out at a folder that held no report (a paper's folder with figures/ and tables/ of its own): nothing of
    it is deleted."""
    out = tmp_path / "paper"
    (out / "figures").mkdir(parents=True)
    (out / "tables").mkdir()
    (out / "figures" / "fig1.pdf").write_bytes(b"%PDF")
    (out / "tables" / "notes.md").write_text("mine", encoding="utf-8")
    assert report_main([str(sweep), "--out", str(out), "--task", "push"]) == 0
    assert (out / "figures" / "fig1.pdf").exists() and (out / "tables" / "notes.md").exists()


@pytest.mark.parametrize("name", ["tables/summary.csv", "figures/schedules.png", "index.html",
                                  "figures"])
def test_a_full_disk_while_the_report_writes_is_one_line_naming_the_file_and_its_size_with_exit_2(
        hand_sized, tmp_path, capsys, monkeypatch, name):
    """The disk fills as the report writes a table, a figure (in a worker process), its page or a folder: one line
    naming that file and the bytes it needs (those the report writes once space is freed; a folder: one block), exit 2,
    no temporary file left; the same command then writes the report."""
    import errno
    import os

    from hersd.contract.errors import DiskFullError

    out = tmp_path / "report"
    if name == "figures":  # a folder it cannot make
        made = Path.mkdir

        def full_mkdir(path, *args, **kwargs):
            if path.name == name:
                raise OSError(errno.ENOSPC, "No space left on device", str(path))
            made(path, *args, **kwargs)

        monkeypatch.setattr(Path, "mkdir", full_mkdir)
    else:
        full_disk_writes(monkeypatch, f"{Path(name).name}*")  # the file or its temporary file
    assert exit_status([str(hand_sized), "--out", str(out)]) == 2
    monkeypatch.undo()  # space freed
    err = capsys.readouterr().err
    assert not list(tmp_path.rglob("*.tmp"))
    assert exit_status([str(hand_sized), "--out", str(out)]) == 0
    size = os.statvfs(out).f_bsize if name == "figures" else (out / name).stat().st_size  # a folder: one block
    needs = str(DiskFullError(out / name, size))
    assert err.count("\n") == 1 and err.startswith(f"hersd-report: error: {needs.rsplit(', ', 1)[0]}, "), err
    assert err.strip().endswith(" free; free some and run hersd-report again")


def test_an_error_while_a_worker_writes_a_figure_leaves_no_temporary_file(hand_sized, tmp_path, monkeypatch):
    """The workers write figures through temporary files; the parent's error (here its tables) stops them, one in the
    middle of its write (held there): its temporary file goes too."""
    import time

    import analysis.report as report
    from hersd.contract.runlog import replace_file, temporary_file

    def slow_write(path, data):  # a figure's write: its temporary file, then held there until it is stopped
        if path.suffix == ".png":
            temporary_file(path).write_bytes(b"half")
            time.sleep(60)
        replace_file(path, data.encode() if isinstance(data, str) else data, sync=False)
        return path

    def failing_tables(tables, folder):
        started = time.monotonic()
        while not list((tmp_path / "report" / "figures").glob("*.tmp")) and time.monotonic() - started < 30:
            time.sleep(0.05)
        raise RuntimeError("the tables failed")

    monkeypatch.setattr(report, "write_whole", slow_write)
    monkeypatch.setattr(report, "_write_tables", failing_tables)
    monkeypatch.setattr("analysis.workers.available_cores", lambda: 2)  # figures drawn in worker processes
    with pytest.raises(RuntimeError, match="the tables failed"):
        report.build_report(hand_sized, tmp_path / "report")
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_run_that_stopped_with_an_error_is_failed_in_the_tables_page_and_terminal(tmp_path, capsys):
    """A crashed run with an error.log beside its log was shown "in progress (epoch 1 of 2)"."""
    write_run(tmp_path / "done", make_config(epochs=2), np.ones(2))
    write_run(tmp_path / "running", make_config(epochs=2, seed=1), np.ones(1), complete=False)
    crashed = write_run(tmp_path / "crashed", make_config(epochs=2, seed=2), np.ones(1), complete=False)
    error = crashed.parent / "error.log"
    error.write_text('Traceback (most recent call last):\n  File "train.py", line 9, in train\n    save()\n'
                     "OSError: [Errno 28] No space left on device\n")
    stamp = crashed.stat().st_mtime + 1
    import os
    os.utime(error, (stamp, stamp))
    out = tmp_path / "report"
    assert report_main([str(tmp_path), "--out", str(out), "--smooth", "1"]) == 0
    printed = capsys.readouterr()
    assert "loaded 3 runs (2 incomplete, of which 1 failed, 0 skipped)" in printed.out
    assert "warning: failed run crashed/run.mcap: OSError: [Errno 28] No space left on device" in printed.err
    runs = pd.read_csv(out / "tables" / "runs.csv").set_index("path")
    assert runs.loc["crashed/run.mcap", "state"] == "failed (epoch 1 of 2): OSError: [Errno 28] No space left on device"
    assert runs.loc["running/run.mcap", "state"] == "in progress (epoch 1 of 2)"
    assert pd.read_csv(out / "tables" / "summary.csv")["in_progress"].tolist() == [1]  # the failed run is not
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "1 in progress, 1 failed" in page and "in progress (epoch 1 of 2)" in page
    assert "failed (epoch 1 of 2): OSError: [Errno 28] No space left on device" in page


def test_a_worker_killed_while_drawing_is_one_line_not_a_hang(hand_sized, tmp_path, monkeypatch, capsys):
    """A worker killed as it draws (the OOM killer, kill -9) lost its figure and the report waited for it forever;
    now it ends with one line, exit 1, and no temporary file."""
    import os

    import analysis.report as report

    def killed(job):
        report.temporary_file(job[1]).write_bytes(b"half")  # killed in the middle of its write
        os._exit(137)

    monkeypatch.setattr("analysis.workers.available_cores", lambda: 2)  # figures drawn in worker processes
    monkeypatch.setattr(report, "_render", killed)
    assert report_main([str(hand_sized), "--out", str(tmp_path / "report")]) == 1
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line == ("hersd-report: error: a worker process stopped before finishing its jobs (killed, or out of "
                    "memory?); run hersd-report again")
    assert not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"], ids=["ctrl_c", "kill"])
def test_ctrl_c_or_kill_of_the_report_is_one_line_with_exit_130(stop, hand_sized, tmp_path, monkeypatch, capsys):
    """Ctrl-C, or ``kill PID`` (SIGTERM), while the report draws: a traceback (or, for SIGTERM, a silent death
    that left its workers blocked forever); now one line, exit 130, no temporary file."""
    import os
    import signal

    import analysis.report as report

    def interrupted(job):
        report.temporary_file(job[1]).write_bytes(b"half")
        os.kill(os.getpid(), getattr(signal, stop))
        time.sleep(5)  # the handler raises here
        raise AssertionError(f"{stop} did not interrupt the report")

    def unhandled(signum, frame):  # without the command's handler (not pytest's death)
        raise AssertionError("hersd-report let SIGTERM through")

    monkeypatch.setattr("analysis.workers.available_cores", lambda: 1)  # figures drawn in this process
    monkeypatch.setattr(report, "_render", interrupted)
    previous = signal.signal(signal.SIGTERM, unhandled)
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (xdist ignores it)
    try:
        code = report_main([str(hand_sized), "--out", str(tmp_path / "report")])
    except KeyboardInterrupt:
        pytest.fail("a traceback: the interrupt left hersd-report")
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
    assert code == 130
    assert capsys.readouterr().err.strip().splitlines() == [
        "hersd-report: interrupted; run hersd-report again (the runs' logs are untouched)"]
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_report_folder_it_cannot_write_into_is_one_line_with_exit_2(hand_sized, tmp_path, monkeypatch, capsys):
    """An earlier report's tables/ (or figures/) read-only (another user's, a read-only mount) was a traceback."""
    import errno

    import analysis.report as report

    def refused(path, data, sync=True):
        raise OSError(errno.EROFS, "Read-only file system", str(report.temporary_file(path)))

    monkeypatch.setattr(report, "replace_file", refused)
    assert report_main([str(hand_sized), "--out", str(tmp_path / "report")]) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith(f"hersd-report: error: cannot write the report's file {tmp_path / 'report'}/")
    assert line.endswith(": Read-only file system; give --out a folder you can write to")


def test_a_run_file_it_cannot_read_is_one_line_with_exit_2_not_a_hint_about_out(hand_sized, tmp_path, monkeypatch,
                                                                                 capsys):
    """A file of a run the report copies (an animation) unreadable is not the report folder's fault."""
    import errno

    import analysis.report as report

    unreadable = hand_sized / "her0" / "policy" / "epoch_1.gif"

    def refused(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(unreadable))

    monkeypatch.setattr(report, "_copy_animations", refused)
    assert report_main([str(hand_sized), "--out", str(tmp_path / "report")]) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line == (f"hersd-report: error: cannot read {unreadable}: Permission denied; make it readable, or move it "
                    "out of the folder")
