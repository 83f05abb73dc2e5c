"""``python -m analysis.doc_tables FILE...``: rewrite the generated blocks of markdown files from a report's tables.

A block is the text between an opening comment and its closing one; everything outside blocks is left
as it is. Kinds (the opening comment's first word):

- ``<!-- claims ... -->`` ... ``<!-- /claims -->``: the claims tables (:func:`analysis.claims.claims_markdown`
  of ``claims.csv``);
- ``<!-- claims-list ... -->`` ... ``<!-- /claims-list -->``: one line per measured claim: task, claim,
  figure, verdict, p and seeds (README.md's opening);
- ``<!-- seeds task=T config="C" seeds=0-4 name=N rows=smoothed,raw_epochs -->`` ... ``<!-- /seeds -->``:
  a per-seed table of ``per_seed.csv`` (:func:`analysis.seeds.seed_markdown`; ``seeds`` a range ``a-b`` or a
  list ``0,2,3``; ``rows`` keys of :data:`analysis.seeds.SEED_ROWS`);
- ``<!-- versus task=T config="C" versus="V" name=N versus_name=M -->`` ... ``<!-- /versus -->``: two
  configurations side by side, their medians (``summary.csv``) and both one-sided permutation tests of the
  seeds' means (``permutation_tests.csv``), with the test's power (:func:`versus_markdown`);
- ``<!-- rows name=equal_mu_tests task=T columns=outcome,p_config_better -->`` ... ``<!-- /rows -->``: the
  rows of a report table (``tables/<name>.csv``) whose columns equal the block's other settings (here
  ``task``), its ``columns`` (default: all but those matched) under the report page's headers and number
  formats (:func:`report_table_markdown`).

``--check`` rewrites nothing and exits 1 naming each file whose blocks differ from what the tables give
(the tests run it on docs/RESULTS.md and README.md against the committed report). Bad input (a missing
file or table, an unknown block, a configuration without such seeds) is one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from analysis.claims import claims_markdown, permutation_words
from analysis.seeds import seed_markdown
from analysis.tables import cell_text, column_formats, column_header
from hersd.contract.tasks import task_title

DEFAULT_TABLES = Path("results/report/tables")


class DocTablesError(ValueError):
    """A block or a table that cannot be rendered: the message says which and what to do."""


def read_table(tables: Path, name: str, **options) -> pd.DataFrame:
    path = tables / f"{name}.csv"
    if not path.is_file():
        raise DocTablesError(f"{path} does not exist: run `hersd-report` on the logs first")
    return pd.read_csv(path, **options)


def _claims(tables: Path) -> pd.DataFrame:
    table = read_table(tables, "claims", dtype=str, keep_default_na=False)
    return table.assign(p=pd.to_numeric(table["p"], errors="coerce"))


def claims_list(table: pd.DataFrame) -> str:
    """One markdown bullet per measured claim (``table``: claims.csv as :func:`_claims` reads it)."""
    lines = [f"- {task_title(row.task)}, {row.claim} ({row.paper}): {row.verdict} (p = {row.p:.2g}, "
             f"{row.seeds} seeds)." for row in table.itertuples() if np.isfinite(row.p)]
    return "\n".join(lines) + "\n"


def _seeds(words: str) -> list[int]:
    if re.fullmatch(r"\d+-\d+", words):
        first, last = (int(part) for part in words.split("-"))
        return list(range(first, last + 1))
    if re.fullmatch(r"\d+(,\d+)*", words):
        return [int(part) for part in words.split(",")]
    raise DocTablesError(f"seeds={words!r}: give a range like 0-4 or a list like 0,2,3")


def _settings(kind: str, options: str, needed: Sequence[str]) -> dict[str, str]:
    """A block's ``key=value`` options, each of ``needed`` present."""
    try:
        settings = dict(part.split("=", 1) for part in shlex.split(options))
    except ValueError:
        raise DocTablesError(f"{kind} block {options.strip()!r}: write key=value pairs (quote a value with spaces)")
    if missing := [key for key in needed if key not in settings]:
        raise DocTablesError(f"{kind} block {options.strip()!r} lacks {', '.join(missing)}")
    return settings


def _seed_block(options: str, tables: Path) -> str:
    settings = _settings("seeds", options, ("task", "config", "seeds", "name", "rows"))
    try:
        return seed_markdown(read_table(tables, "per_seed"), settings["task"], settings["config"],
                             _seeds(settings["seeds"]), settings["name"], settings["rows"].split(","))
    except ValueError as error:
        raise DocTablesError(f"seeds block {options.strip()!r}: {error}") from None


def _matching(table: pd.DataFrame, match: dict[str, str]) -> pd.DataFrame:
    """The rows of ``table`` whose columns named in ``match`` hold its values, compared as text (all without)."""
    return table[np.logical_and.reduce([table[key].astype(str) == value for key, value in match.items()])
                 if match else np.ones(len(table), bool)]


# summary.csv column(s) -> the row's words and the permutation test's outcome(s); epochs ``never`` where missing
VERSUS_ROWS = (
    ("median final smoothed test success", ("final_median",), ("final",)),
    ("epoch the median smoothed curve reaches 0.5 / 0.9", ("epochs_to_0.5", "epochs_to_0.9"),
     ("epochs_to_0.5", "epochs_to_0.9")),
    ("epoch the median raw curve reaches 0.5 / 0.9", ("raw_epochs_to_0.5", "raw_epochs_to_0.9"),
     ("raw_epochs_to_0.5", "raw_epochs_to_0.9")),
    ("area under the median smoothed curve (AUC)", ("auc",), ()),
)


def versus_markdown(summary: pd.DataFrame, tests: pd.DataFrame, task: str, config: str, versus: str, name: str,
                    versus_name: str) -> str:
    """``config`` (shown as ``name``) beside ``versus`` on ``task``: a row per VERSUS_ROWS entry with each side's
    median (``summary``: summary.csv) and the one-sided p of each doing better (``tests``: permutation_tests.csv,
    the seeds' means; ``-`` for a row without a test), then a line with the test's kind and power. Raises
    ValueError when either configuration lacks complete seeds to test."""
    def row_of(table: pd.DataFrame, **match: str) -> pd.Series:
        chosen = _matching(table, match)
        if len(chosen) != 1:
            raise ValueError(f"{config!r} against {versus!r} on {task}: not in the report's tables (each needs "
                             "two complete seeds)")
        return chosen.iloc[0]

    sides = [row_of(summary, task=task, config=side) for side in (config, versus)]
    p_better = [row_of(tests, task=task, config=one, versus=other) for one, other in ((config, versus), (versus, config))]
    seeds, versus_seeds = int(p_better[0]["seeds"]), int(p_better[0]["versus_seeds"])

    def shown(values: pd.Series, columns: Sequence[str]) -> str:
        return " / ".join(("never" if pd.isna(values[column]) else f"{int(values[column])}") if "epochs" in column
                          else f"{values[column]:.3f}" for column in columns)

    lines = [f"| | {name}, {seeds} seeds | {versus_name}, {versus_seeds} seeds | one-sided p: {name} does better | "
             f"one-sided p: {versus_name} does better |", "| --- " * 5 + "|"]
    for words, columns, outcomes in VERSUS_ROWS:
        p_cells = [" / ".join(f"{side[f'p_{outcome}']:.2g}" for outcome in outcomes) or "-" for side in p_better]
        lines.append(f"| {words} | {shown(sides[0], columns)} | {shown(sides[1], columns)} | {' | '.join(p_cells)} |")
    return "\n".join(lines) + (f"\n\np-values: {permutation_words(seeds, versus_seeds, two_sided=False)}, on the "
                               f"difference of the seeds' means (an epoch never reached counts as K + 1).\n")


def _versus_block(options: str, tables: Path) -> str:
    settings = _settings("versus", options, ("task", "config", "versus", "name", "versus_name"))
    try:
        return versus_markdown(read_table(tables, "summary"), read_table(tables, "permutation_tests"),
                               settings["task"], settings["config"], settings["versus"], settings["name"],
                               settings["versus_name"])
    except ValueError as error:
        raise DocTablesError(f"versus block {options.strip()!r}: {error}") from None


def report_table_markdown(table: pd.DataFrame, match: dict[str, str], columns: Sequence[str] | None = None) -> str:
    """The rows of ``table`` whose columns named in ``match`` hold its values (compared as text), as markdown:
    ``columns`` (default: every column not in ``match``) under :func:`analysis.tables.column_header`, numbers at
    their column's format. Raises ValueError for an unknown column or when no row matches."""
    unknown = [name for name in (*match, *(columns or ())) if name not in table.columns]
    if unknown:
        raise ValueError(f"no column {', '.join(unknown)}; the table has {', '.join(table.columns)}")
    chosen = _matching(table, match)
    if chosen.empty:
        raise ValueError(f"no row with {', '.join(f'{key}={value}' for key, value in match.items())}")
    shown = list(columns) if columns else [name for name in table.columns if name not in match]
    formats = column_formats(shown)
    lines = ["| " + " | ".join(column_header(name) for name in shown) + " |", "| --- " * len(shown) + "|"]
    lines += ["| " + " | ".join(cell_text(value, form) for value, form in zip(row, formats)) + " |"
              for row in chosen[shown].itertuples(index=False)]
    return "\n".join(lines) + "\n"


def _rows_block(options: str, tables: Path) -> str:
    settings = _settings("rows", options, ("name",))
    name, columns = settings.pop("name"), settings.pop("columns", None)
    try:
        return report_table_markdown(read_table(tables, name), settings, columns.split(",") if columns else None)
    except ValueError as error:
        raise DocTablesError(f"rows block {options.strip()!r}: {error}") from None


# a block's kind -> its body from (the opening comment's options, the tables' folder)
RENDERERS = {
    "claims": lambda options, tables: claims_markdown(_claims(tables)),
    "claims-list": lambda options, tables: claims_list(_claims(tables)),
    "seeds": _seed_block,
    "versus": _versus_block,
    "rows": _rows_block,
}
KINDS = "|".join(sorted(RENDERERS, key=len, reverse=True))  # claims-list before claims
BLOCK = re.compile(rf"(<!-- ({KINDS})\b(.*?)-->\n)(.*?)(<!-- /\2 -->)", re.DOTALL)


def render(text: str, tables: Path) -> str:
    """``text`` with every block rewritten from the tables in ``tables``."""
    def block(match: re.Match) -> str:
        opening, kind, options, _, closing = match.groups()
        return opening + RENDERERS[kind](options, tables) + closing

    return BLOCK.sub(block, text)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m analysis.doc_tables", description=__doc__.split("\n")[0])
    parser.add_argument("files", nargs="+", type=Path, help="markdown files with generated blocks")
    parser.add_argument("--tables", type=Path, default=DEFAULT_TABLES,
                        help=f"the report's tables (default {DEFAULT_TABLES})")
    parser.add_argument("--check", action="store_true", help="rewrite nothing; exit 1 if a block is stale")
    args = parser.parse_args(argv)
    stale = []
    try:
        for path in args.files:
            if not path.is_file():
                raise DocTablesError(f"{path} does not exist")
            text = path.read_text(encoding="utf-8")
            if not BLOCK.search(text):
                raise DocTablesError(f"{path} has no generated block (<!-- claims -->, <!-- seeds ... -->)")
            rendered = render(text, args.tables)
            if rendered != text:
                stale.append(path)
                if not args.check:
                    path.write_text(rendered, encoding="utf-8")
    except DocTablesError as error:
        print(f"doc_tables: {error}", file=sys.stderr)
        return 2
    for path in stale:
        print(f"{path}: {'stale: run python -m analysis.doc_tables ' + str(path) if args.check else 'rewritten'}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
