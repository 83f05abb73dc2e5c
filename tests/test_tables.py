"""analysis/tables.py: the Markdown and HTML table renderer."""

from __future__ import annotations

import pandas as pd

from analysis.tables import COLUMNS, RUN_COLUMNS, column_header, html_table, markdown_table


def test_tables_leave_missing_values_empty():
    table = pd.DataFrame({"config": ["HER"], "epochs_to_0.9": pd.array([pd.NA], dtype="Int64"), "auc": [float("nan")],
                          "iqm": [0.12345]})
    assert markdown_table(table).splitlines()[2] == "| HER |  |  | 0.123 |"
    assert html_table(table).count("<td></td>") == 2 and "NA" not in html_table(table)
    assert "<td class=text>HER</td>" in html_table(table)


def test_page_headers_are_words_with_units_and_the_files_keep_the_column_names():
    assert column_header("final_median", epochs=200) == "test success at epoch 200, median over seeds"
    assert column_header("final_median") == "test success at epoch K, median over seeds"  # the rows' K differ
    assert column_header("epochs_to_0.5") == "epochs to 0.5 success (median, smoothed)"
    assert column_header("raw_epochs_to_0.9", columns=RUN_COLUMNS) == "epochs to 0.9 success (raw)"  # one run's own
    assert column_header("seconds_per_epoch") == "seconds per epoch (median)"
    assert column_header("mu_eps_approx") == "μ_ε by eq. 11"
    assert column_header("share_of_something") == "share of something"  # not in COLUMNS: its name, spaced
    assert all("_" not in column.label.replace("μ_ε", "") for column in COLUMNS.values())
    table = pd.DataFrame({"config": ["HER"], "final_median": [0.98]})
    assert markdown_table(table).startswith("| config | final_median |")  # the .md files: the names
    assert "<th class=text>configuration</th><th>test success at epoch 200, median over seeds</th>" in html_table(
        table, epochs=200)


def test_page_numbers_have_their_columns_decimals():
    table = pd.DataFrame({"epochs_to_0.5": [112.0, float("nan")], "final_median": [0.98, 1.0],
                          "p_final": [1 / 252, 0.5], "seconds_per_epoch": [30.24, 41.06], "other": [0.12345, 2.0],
                          "seeds": [5, 3]})
    cells = [row.split("</td><td>") for row in html_table(table).split("<tbody><tr><td>")[1]
             .removesuffix("</td></tr></tbody></table>").split("</td></tr><tr><td>")]
    assert cells == [["112", "0.980", "0.004", "30.2", "0.123", "5"], ["", "1.000", "0.500", "41.1", "2.000", "3"]]


def test_text_cells_break_only_at_spaces_and_carry_their_tooltips():
    table = pd.DataFrame({"run_folder": ["seed0-64e236fe"], "state": ["in progress (epoch 39 of 200)"],
                          "config": ["success b1=0.25 (task.env_id=Fetch-Push/v4)"]})
    page = html_table(table, titles={"run_folder": pd.Series(['push/her/a "b"/seed0-64e236fe/run.mcap'])})
    assert ('<td class=text title="push/her/a &quot;b&quot;/seed0-64e236fe/run.mcap">'
            "<span class=word>seed0-64e236fe</span></td>") in page
    assert "<td class=text>in progress (epoch 39 of 200)</td>" in page  # no hyphen, no slash: plain
    assert "<td class=text>success b1=0.25 <span class=word>(task.env_id=Fetch-Push/v4)</span></td>" in page


def test_the_md_files_and_the_page_give_a_column_the_same_digits():
    """A p of 1/10000 and the control's mu_eps 0.874375 are not rounded to 0.000 and 0.874 in the .md files."""
    table = pd.DataFrame({"config": ["linear"], "mu_eps": [0.874375], "smallest_p": [1e-4], "p": [0.0079365],
                          "auc": [0.71234]})
    assert markdown_table(table).splitlines()[2] == "| linear | 0.8744 | 0.0001 | 0.0079 | 0.712 |"
    page = html_table(table)
    assert all(f">{cell}</td>" in page for cell in ("0.8744", "0.0001", "0.0079", "0.712"))
