"""Tables as text: Markdown (the ``.md`` files) and HTML (the report page), one cell format for both."""

from __future__ import annotations

import html
import math

import pandas as pd

FLOAT_FORMAT = "{:.3f}"


def cell_text(value, float_format: str = FLOAT_FORMAT) -> str:
    """A table cell: floats through ``float_format``, missing values (None, NaN, pd.NA) empty."""
    if value is None or value is pd.NA:
        return ""
    if isinstance(value, float):  # numpy's float64 is a float
        return "" if math.isnan(value) else float_format.format(value)
    return str(value)


def markdown_table(table: pd.DataFrame, float_format: str = FLOAT_FORMAT) -> str:
    """A GitHub-flavoured Markdown table of ``table`` (header = its columns, one line per row)."""
    lines = ["| " + " | ".join(map(str, table.columns)) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell_text(value, float_format) for value in row) + " |"
              for row in table.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def html_table(table: pd.DataFrame, float_format: str = FLOAT_FORMAT) -> str:
    """An HTML ``<table class="data">`` of ``table``; text columns (e.g. config labels) left-aligned."""
    is_text = [not pd.api.types.is_numeric_dtype(table[name]) or pd.api.types.is_bool_dtype(table[name])
               for name in table.columns]
    head = "".join(f"<th>{html.escape(str(name))}</th>" for name in table.columns)
    attributes = [" class=text" if text else "" for text in is_text]
    rows = []
    for row in table.itertuples(index=False):
        cells = "".join(f"<td{attribute}>{html.escape(cell_text(value, float_format))}</td>"
                        for attribute, value in zip(attributes, row))
        rows.append(f"<tr>{cells}</tr>")
    return f'<table class="data"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
