"""Tables as text: Markdown (the ``.md`` files) and HTML (the report page), one cell format for both.

The files keep the tables' column names (``final_median``, ``epochs_to_0.5``, ...: other code and the
docs cite them); the page shows each column under a human header with its unit (:data:`COLUMNS`) and
its numbers at that column's fixed decimals.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass
from typing import Iterable, Mapping

import pandas as pd

FLOAT_FORMAT = "{:.3f}"
EPOCHS, SHARE, PROBABILITY, BIAS = "{:.0f}", "{:.3f}", "{:.3f}", "{:.2f}"
MEAN_RATE, SMALL_P, MIXED = "{:.4f}", "{:.2g}", "{:.4g}"  # mu_eps; p-values down to 1/3003; epochs and success


@dataclass(frozen=True)
class Column:
    """How the page shows a table column: its header (``{K}`` stands for the table's number of epochs, see
    :func:`column_header`) and the format of its numbers (None: the table's ``float_format``)."""

    label: str
    number: str | None = None


def _reach(threshold: str, curve: str) -> Column:
    return Column(f"epochs to {threshold} success ({curve})", EPOCHS)


COLUMNS: dict[str, Column] = {
    "task": Column("task"),
    "config": Column("configuration"),
    "versus": Column("versus configuration"),
    "source": Column("source"),
    "tasks": Column("tasks"),
    "total_epochs": Column("K"),
    "seeds": Column("complete seeds"),
    "versus_seeds": Column("versus: complete seeds"),
    "in_progress": Column("runs in progress (left out)"),
    "mu_eps": Column("μ_ε over the epochs (eq. 10)", MEAN_RATE),
    "final_median": Column("test success at epoch {K}, median over seeds", SHARE),
    "auc": Column("area under the median curve (0 to 1)", SHARE),
    "epochs_to_0.5": _reach("0.5", "median, smoothed"),
    "epochs_to_0.9": _reach("0.9", "median, smoothed"),
    "raw_epochs_to_0.5": _reach("0.5", "median, raw"),
    "raw_epochs_to_0.9": _reach("0.9", "median, raw"),
    "iqm": Column("IQM of final success", SHARE),
    "iqm_low": Column("IQM 95\u00a0% interval: low", SHARE),
    "iqm_high": Column("IQM 95\u00a0% interval: high", SHARE),
    "iqm_interval": Column("IQM 95\u00a0% interval"),
    "p_improve_HER": Column("P(improvement over HER)", PROBABILITY),
    "p_final": Column("p: higher final success", PROBABILITY),
    "p_epochs_to_0.5": Column("p: fewer epochs to 0.5 (smoothed)", PROBABILITY),
    "p_epochs_to_0.9": Column("p: fewer epochs to 0.9 (smoothed)", PROBABILITY),
    "p_raw_epochs_to_0.5": Column("p: fewer epochs to 0.5 (raw)", PROBABILITY),
    "p_raw_epochs_to_0.9": Column("p: fewer epochs to 0.9 (raw)", PROBABILITY),
    # the decay against the constant rate at the same mu_eps, a variant against its defaults (analysis.metrics)
    "variant": Column("variant"),
    "outcome": Column("outcome (per seed)"),
    "config_mean": Column("mean over its seeds", MIXED),
    "versus_mean": Column("versus: mean over seeds", MIXED),
    "p_config_better": Column("p: it does better", SMALL_P),
    "p_versus_better": Column("p: versus does better", SMALL_P),
    "splits": Column("splits of the seeds"),
    "smallest_p": Column("smallest p the seeds allow", SMALL_P),
    "epoch": Column("epoch", EPOCHS),
    "share_real_success": Column("real successful (share of minibatch)", SHARE),
    "share_hindsight": Column("hindsight (share of minibatch)", SHARE),
    "share_real_failure": Column("real unsuccessful (share of minibatch)", SHARE),
    "goal_type": Column("goals"),
    "config_bias": Column("configuration's mean bias (Q minus return)", BIAS),
    "versus_bias": Column("versus' mean bias (Q minus return)", BIAS),
    "difference": Column("difference of the bias", BIAS),
    "p_two_sided": Column("p (two-sided)", PROBABILITY),
    "p": Column("p", SMALL_P),  # the claims table's test
    # the run list (analysis.report): one run's own numbers
    "run_folder": Column("run folder"),
    "seed": Column("seed"),
    "state": Column("state"),
    "final": Column("test success at its last epoch (smoothed)", SHARE),
    "raw_auc": Column("mean raw test success over its epochs", SHARE),
    "seconds_per_epoch": Column("seconds per epoch (median)", "{:.1f}"),
    "cpu": Column("CPU"),
    # a study's best trials (analysis.search_figures): numbers at the table's 4 significant digits
    "trial": Column("trial"),
    "value": Column("objective value"),
    "kind": Column("schedule"),
    "beta1": Column("β1"),
    "beta2": Column("β2"),
    "eps": Column("ε"),
    "lambda_h": Column("λh"),
    "mu_eps_approx": Column("μ_ε by eq. 11"),
    "in_band": Column("μ_ε in HER's best band"),
    "retry_of": Column("retry of trial"),
    "duration_s": Column("seconds"),
}
RUN_COLUMNS: dict[str, Column] = {  # the run list: a run's own curve, not a median
    **COLUMNS, **{f"{prefix}epochs_to_{threshold}": _reach(threshold, curve)
                  for prefix, curve in (("", "smoothed"), ("raw_", "raw")) for threshold in ("0.5", "0.9")}}


def column_header(name: str, epochs: int | None = None, columns: Mapping[str, Column] = COLUMNS) -> str:
    """The page's header of column ``name``: its label in ``columns``, ``{K}`` replaced by ``epochs`` (``K`` when
    None: the rows differ); a column not in ``columns`` by its name with spaces for underscores."""
    column = columns.get(name)
    if column is None:
        return str(name).replace("_", " ")
    return column.label.replace("{K}", "K" if epochs is None else str(epochs))


def cell_text(value, float_format: str = FLOAT_FORMAT) -> str:
    """A table cell: floats through ``float_format``, missing values (None, NaN, pd.NA) empty."""
    if value is None or value is pd.NA:
        return ""
    if isinstance(value, float):  # numpy's float64 is a float
        return "" if math.isnan(value) else float_format.format(value)
    return str(value)


def _unbroken(text: str) -> str:
    """``text`` as HTML whose words break only at spaces: a word holding a hyphen or a slash (where browsers may
    break a line) in a ``<span class=word>`` (the page's style: ``white-space: nowrap``)."""
    return " ".join(f"<span class=word>{html.escape(word)}</span>" if ("-" in word or "/" in word) and len(word) > 1
                    else html.escape(word) for word in text.split(" "))


def column_formats(names: Iterable[str], float_format: str = FLOAT_FORMAT,
                   columns: Mapping[str, Column] = COLUMNS) -> list[str]:
    """The number format of each column: its own in ``columns``, else ``float_format``."""
    return [(columns[name].number if name in columns else None) or float_format for name in names]


def markdown_table(table: pd.DataFrame, float_format: str = FLOAT_FORMAT) -> str:
    """A GitHub-flavoured Markdown table of ``table`` (header = its columns, one line per row), numbers at their
    column's decimals as on the page (:data:`COLUMNS`, else ``float_format``)."""
    lines = ["| " + " | ".join(map(str, table.columns)) + " |", "|" + "---|" * len(table.columns)]
    formats = column_formats(table.columns, float_format)
    lines += ["| " + " | ".join(cell_text(value, fmt) for fmt, value in zip(formats, row)) + " |"
              for row in table.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def html_table(table: pd.DataFrame, float_format: str = FLOAT_FORMAT, epochs: int | None = None,
               columns: Mapping[str, Column] = COLUMNS,
               titles: Mapping[str, pd.Series] | None = None) -> str:
    """An HTML ``<table class="data">`` of ``table``: headers by :func:`column_header`, numbers right-aligned
    at their column's decimals (:data:`COLUMNS`, else ``float_format``), text columns (e.g. config labels)
    left-aligned (``class=text``), hyphenated words of headers and text cells kept whole (``<span class=word>``), missing values
    empty. ``titles``: per column, a Series (aligned with the
    rows) of tooltips for its cells, e.g. a run's whole path."""
    is_text = [not pd.api.types.is_numeric_dtype(table[name]) or pd.api.types.is_bool_dtype(table[name])
               for name in table.columns]
    attributes = [" class=text" if text else "" for text in is_text]
    head = "".join(f"<th{attribute}>{_unbroken(column_header(name, epochs, columns))}</th>"
                   for name, attribute in zip(table.columns, attributes))
    formats = column_formats(table.columns, float_format, columns)
    tips = [None if titles is None or name not in titles else list(titles[name]) for name in table.columns]
    rows = []
    for index, row in enumerate(table.itertuples(index=False)):
        cells = "".join(
            f"<td{attribute}{'' if tip is None else ' title=' + html.escape(str(tip[index])).join(chr(34) * 2)}>"
            f"{_unbroken(cell_text(value, fmt)) if attribute else html.escape(cell_text(value, fmt))}</td>"
            for attribute, fmt, tip, value in zip(attributes, formats, tips, row))
        rows.append(f"<tr>{cells}</tr>")
    return f'<table class="data"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
