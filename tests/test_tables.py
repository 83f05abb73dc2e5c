"""analysis/tables.py: the Markdown and HTML table renderer."""

from __future__ import annotations

import pandas as pd

from analysis.tables import html_table, markdown_table


def test_tables_leave_missing_values_empty():
    table = pd.DataFrame({"config": ["HER"], "epochs_to_0.9": pd.array([pd.NA], dtype="Int64"), "auc": [float("nan")],
                          "iqm": [0.12345]})
    assert markdown_table(table).splitlines()[2] == "| HER |  |  | 0.123 |"
    assert html_table(table).count("<td></td>") == 2 and "NA" not in html_table(table)
    assert "<td class=text>HER</td>" in html_table(table)
