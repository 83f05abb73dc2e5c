"""Per-seed numbers (analysis/seeds.py) and the generated blocks of markdown files (analysis/doc_tables.py):
values read at their epochs from hand-made logs, the tables rendered from per_seed.csv, stale blocks found,
bad blocks one line and exit 2, and the committed docs fresh against the committed report."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.doc_tables import main as doc_tables
from analysis.load import load_runs
from analysis.metrics import analyse_curves
from analysis.seeds import seed_markdown, seed_values
from analysis.synthetic import write_run
from analysis_logs import make_config
from hersd.contract.schedules import Linear

ROOT = Path(__file__).resolve().parent.parent
K = 200
LINEAR = Linear(beta1=0.5)
EPOCH = np.arange(1, K + 1)
RISING = np.round(EPOCH / K, 1)  # a test success rising from 0 to 1 on the 0.1 grid


def first_epoch(level: float) -> int:
    return int(EPOCH[RISING >= level][0])


@pytest.fixture(scope="module")
def tables(tmp_path_factory) -> Path:
    """per_seed.csv of three 200-epoch runs: HER seeds 0 (RISING, Q = -k / 10, a bias of 100 / k evaluated at
    epochs 1, 10, 20, 50, 100 and 200) and 1 (never succeeds, stopped at epoch 120), linear 0.5 seed 0 (RISING)."""
    folder = tmp_path_factory.mktemp("seeds")
    bias = np.where(np.isin(EPOCH, [1, 10, 20, 50, 100, 200]), 100.0 / EPOCH, np.nan)
    write_run(folder / "her0", make_config(epochs=K, seed=0), RISING, q_mean=-EPOCH / 10.0, bias_real_mean=bias,
              bias_hindsight_mean=bias, bias_moved_mean=bias, bias_seconds=np.where(np.isnan(bias), np.nan, 5.0))
    write_run(folder / "her1", make_config(epochs=K, seed=1), np.zeros(120), complete=False)
    write_run(folder / "linear0", make_config(epochs=K, seed=0, schedule=LINEAR), RISING)
    table = load_runs(folder)
    analysis = analyse_curves(table.runs, table.epochs, window=50)
    out = tmp_path_factory.mktemp("tables")
    seed_values(table.runs, table.epochs, analysis.curves, analysis.outcomes).to_csv(out / "per_seed.csv", index=False)
    return out


def per_seed(tables: Path) -> pd.DataFrame:
    return pd.read_csv(tables / "per_seed.csv")


def test_each_runs_values_are_read_at_their_epochs(tables):
    her0 = per_seed(tables).query("config == 'HER' and seed == 0").iloc[0]
    assert her0["smoothed_at_50"] == pytest.approx(RISING[:50].mean())  # the trailing 50-epoch mean
    assert her0["smoothed_at_150"] == pytest.approx(RISING[100:150].mean())
    assert (her0["q_mean_at_10"], her0["q_mean_at_200"]) == (-1.0, -20.0)
    assert (her0["bias_real_mean_at_1"], her0["bias_real_mean_at_20"]) == (100.0, 5.0)
    assert her0["relabel_rate_at_1"] == 0.8 and her0["mu_eps"] == 0.8
    assert (her0["raw_epochs_to_0.5"], her0["raw_epochs_to_0.9"]) == (first_epoch(0.5), first_epoch(0.9))
    # trapezoids over epochs 1, 10, 20 and 50 (bias 100, 10, 5, 2), divided by 49
    assert her0["bias_real_1_50"] == pytest.approx((110 / 2 * 9 + 15 / 2 * 10 + 7 / 2 * 30) / 49)
    her1 = per_seed(tables).query("config == 'HER' and seed == 1").iloc[0]
    assert (her1["complete"], her1["epochs_done"]) == (False, 120) and np.isnan(her1["q_mean_at_200"])


def test_a_table_renders_a_column_per_seed_and_marks_what_a_run_lacks(tables):
    rows = ["smoothed", "smoothed_epochs", "q", "bias"]
    markdown = seed_markdown(per_seed(tables), "push", "HER", [0, 1], "HER", rows)
    lines = markdown.splitlines()
    assert lines[0] == "| | HER seed 0 | HER seed 1 |" and lines[1] == "| --- | --- | --- |"
    smoothed = lines[2].split(" | ")
    assert smoothed[2] == "0.000 / 0.000 / - / - |"  # seed 1 stopped at epoch 120: no value at 150 or 200
    assert lines[3].endswith("| never / never |")  # seed 1 never reaches either level
    assert lines[4].split(" | ")[1] == "-1.00 / -5.00 / -10.00 / -20.00"
    assert lines[5].split(" | ")[1] == "+100.0 / +10.0 / +5.0 / +2.0 / +1.0 / +0.5; +13.8"  # 675 / 49
    assert lines[5].endswith("| - / - / - / - / - / -; - |")  # seed 1 logged no bias
    moved, cost = seed_markdown(per_seed(tables), "push", "HER", [0, 1], "HER", ["moved", "cost"]).splitlines()[2:]
    assert moved.split(" | ")[1] == "- / +5.0 / - / +2.0 / - / +1.0 / - / +0.5"  # evaluated at 20, 50, 100, 200
    # 200 epochs of 45 s; six evaluations of 5 s: 30 s of 9000 s; seed 1: 120 epochs, none
    assert cost == ("| hours of epochs at the median pace / wall clock; the bias evaluations' share of the first "
                    "| 2.50 h / 2.50 h; 0.33 % | 1.50 h / 1.50 h; 0.00 % |")


def test_unknown_rows_duplicate_or_missing_seeds_are_errors_that_say_so(tables):
    table = per_seed(tables)
    with pytest.raises(ValueError, match="unknown per-seed rows \\['nope'\\]"):
        seed_markdown(table, "push", "HER", [0], "HER", ["nope"])
    with pytest.raises(ValueError, match="seed \\[3\\]"):
        seed_markdown(table, "push", "HER", [0, 3], "HER", ["smoothed"])
    with pytest.raises(ValueError, match="more than one run of a seed"):
        seed_markdown(pd.concat([table, table]), "push", "HER", [0], "HER", ["smoothed"])


def test_stale_blocks_are_rewritten_and_checked(tables, tmp_path, capsys):
    doc = tmp_path / "doc.md"
    block = '<!-- seeds task=push config="linear b1=0.5" seeds=0 name=linear rows=raw_epochs -->\n'
    doc.write_text(f"Before.\n{block}| stale |\n<!-- /seeds -->\nAfter.\n", encoding="utf-8")
    assert doc_tables(["--check", "--tables", str(tables), str(doc)]) == 1
    assert "stale" in capsys.readouterr().out and "| stale |" in doc.read_text()  # --check rewrites nothing
    assert doc_tables(["--tables", str(tables), str(doc)]) == 0
    assert doc.read_text() == (f"Before.\n{block}| | linear seed 0 |\n| --- | --- |\n"
                               "| first epoch the raw test success reaches 0.5 / 0.9 | "
                               f"{first_epoch(0.5)} / {first_epoch(0.9)} |\n<!-- /seeds -->\nAfter.\n")
    assert doc_tables(["--check", "--tables", str(tables), str(doc)]) == 0


def test_missing_tables_or_files_are_one_line_and_exit_2(tmp_path, capsys):
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- claims -->\n<!-- /claims -->\n", encoding="utf-8")
    assert doc_tables(["--tables", str(tmp_path / "nowhere"), str(doc)]) == 2
    assert "run `hersd-report` on the logs first" in capsys.readouterr().err
    assert doc_tables([str(tmp_path / "absent.md")]) == 2
    (tmp_path / "plain.md").write_text("no blocks\n", encoding="utf-8")
    assert doc_tables(["--tables", str(tmp_path), str(tmp_path / "plain.md")]) == 2
    assert "has no generated block" in capsys.readouterr().err


def test_the_committed_docs_blocks_are_what_the_committed_report_gives():
    """docs/RESULTS.md's claims and per-seed tables and README.md's claims list, against results/report/tables."""
    text = (ROOT / "docs/RESULTS.md").read_text(encoding="utf-8")
    assert text.count("<!-- seeds ") >= 4 and "<!-- claims-list" in (ROOT / "README.md").read_text(encoding="utf-8")
    assert doc_tables(["--check", "--tables", str(ROOT / "results/report/tables"), str(ROOT / "docs/RESULTS.md"),
                       str(ROOT / "README.md")]) == 0


def versus_tables(folder: Path) -> Path:
    """summary.csv and permutation_tests.csv of two arms on push, made by hand: linear 0.5 (3 seeds) and HER (2)."""
    pd.DataFrame({"task": ["push", "push"], "config": ["linear b1=0.5", "HER"], "final_median": [0.9125, 0.5],
                  "auc": [0.61, 0.4], "epochs_to_0.5": [80, 150], "epochs_to_0.9": [190, np.nan],
                  "raw_epochs_to_0.5": [40, 101], "raw_epochs_to_0.9": [np.nan, np.nan]}).to_csv(
        folder / "summary.csv", index=False)
    pd.DataFrame({"task": ["push", "push"], "config": ["linear b1=0.5", "HER"], "versus": ["HER", "linear b1=0.5"],
                  "seeds": [3, 2], "versus_seeds": [2, 3], "p_final": [0.1, 0.95], "p_epochs_to_0.5": [0.1, 1.0],
                  "p_epochs_to_0.9": [0.3, 0.8], "p_raw_epochs_to_0.5": [0.2, 0.9],
                  "p_raw_epochs_to_0.9": [1.0, 1.0]}).to_csv(folder / "permutation_tests.csv", index=False)
    return folder


def test_a_versus_block_shows_both_medians_both_one_sided_ps_and_the_power(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text('<!-- versus task=push config="linear b1=0.5" versus=HER name=linear versus_name=HER -->\n'
                   "<!-- /versus -->\n", encoding="utf-8")
    assert doc_tables(["--tables", str(versus_tables(tmp_path)), str(doc)]) == 0
    lines = doc.read_text().splitlines()
    assert lines[1] == ("| | linear, 3 seeds | HER, 2 seeds | one-sided p: linear does better | "
                        "one-sided p: HER does better |")
    assert lines[3] == "| median final smoothed test success | 0.912 | 0.500 | 0.1 | 0.95 |"
    assert lines[4] == "| epoch the median smoothed curve reaches 0.5 / 0.9 | 80 / 190 | 150 / never | 0.1 / 0.3 | 1 / 0.8 |"
    assert lines[5] == "| epoch the median raw curve reaches 0.5 / 0.9 | 40 / never | 101 / never | 0.2 / 1 | 0.9 / 1 |"
    assert lines[6] == "| area under the median smoothed curve (AUC) | 0.610 | 0.400 | - | - |"
    assert "exact (smallest p possible 0.1)" in lines[8]  # C(5, 2) = 10 splits


def test_a_rows_block_shows_the_matching_rows_under_the_pages_headers_and_formats(tmp_path):
    pd.DataFrame({"task": ["push", "push", "slide"], "outcome": ["final", "epochs_to_0.5", "final"],
                  "config_mean": [0.98291, 85.5, 0.1], "p_config_better": [0.0912421, 0.00033, 0.5]}).to_csv(
        tmp_path / "equal_mu_tests.csv", index=False)
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- rows name=equal_mu_tests task=push -->\n<!-- /rows -->\n"
                   "<!-- rows name=equal_mu_tests task=slide columns=p_config_better -->\n<!-- /rows -->\n",
                   encoding="utf-8")
    assert doc_tables(["--tables", str(tmp_path), str(doc)]) == 0
    assert doc.read_text().splitlines() == [
        "<!-- rows name=equal_mu_tests task=push -->",
        "| outcome (per seed) | mean over its seeds | p: it does better |", "| --- | --- | --- |",
        "| final | 0.9829 | 0.091 |", "| epochs_to_0.5 | 85.5 | 0.00033 |", "<!-- /rows -->",
        "<!-- rows name=equal_mu_tests task=slide columns=p_config_better -->",
        "| p: it does better |", "| --- |", "| 0.5 |", "<!-- /rows -->"]


@pytest.mark.parametrize("block, words", [
    ("<!-- seeds task=push config=HER seeds=0 name=HER rows=nope -->", "unknown per-seed rows"),
    ("<!-- seeds task=push config=HER seeds=zero name=HER rows=q -->", "give a range like 0-4"),
    ("<!-- seeds task=push config=HER seeds=0 rows=q -->", "lacks name"),
    ("<!-- seeds task=push config=ARCHER seeds=0 name=A rows=q -->", "no run of 'ARCHER'"),
    ('<!-- versus task=push config="linear b1=0.5" versus=ARCHER name=linear versus_name=ARCHER -->',
     "'linear b1=0.5' against 'ARCHER' on push"),
    ("<!-- versus task=push config=HER versus=HER name=HER -->", "lacks versus_name"),
    ("<!-- rows name=equal_mu_tests task=reach -->", "no row with task=reach"),
    ("<!-- rows name=equal_mu_tests task=push columns=nope -->", "no column nope"),
    ("<!-- rows name=absent task=push -->", "absent.csv does not exist"),
    ("<!-- rows task=push -->", "lacks name"),
])
def test_a_bad_block_is_one_line_and_exit_2_and_the_file_is_kept(tables, tmp_path, capsys, block, words):
    shutil.copy(tables / "per_seed.csv", versus_tables(tmp_path))
    pd.DataFrame({"task": ["push"], "outcome": ["final"]}).to_csv(tmp_path / "equal_mu_tests.csv", index=False)
    doc = tmp_path / "doc.md"
    text = f"{block}\nold\n<!-- /{block.split()[1]} -->\n"
    doc.write_text(text, encoding="utf-8")
    assert doc_tables(["--tables", str(tmp_path), str(doc)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and doc.read_text() == text
