#!/usr/bin/env python
"""Rewrite every run log below a folder in the current format of hersd.contract.runlog: chunked, indexed,
with summary and footer, plain-typed schemas (a missing value is a missing key, not null).

    python scripts/convert_logs.py FOLDER [FOLDER ...]

Every readable message is kept in its order with its log time, publish time and sequence
number; only null-valued keys are dropped (the config is kept verbatim), which the reader
gives back as before. A log without a footer (a killed or running writer of the earlier
format) keeps every complete message. Each file is replaced through a temporary file and a
rename; a log already in the current format is left untouched, so running it again changes
nothing. One line per log: ``converted`` or ``unchanged``, with its epochs; an unreadable one
is named and the exit status is 1; a path that is no folder stops it before any
conversion (exit status 2). Do not convert the log of a run that is writing it: convert
after it stops (an older hersd would keep appending to the file it has open).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hersd.contract.runlog import LOG_NAME, RunLogError, read_records, replace_file, rewritten


def convert(path: Path) -> str:
    """Rewrite one log in the current format if it is not -> ``converted`` or ``unchanged``."""
    data = rewritten(path)
    if path.read_bytes() == data:
        return "unchanged"
    replace_file(path, data)
    return "converted"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/convert_logs.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="folders searched for run.mcap files")
    args = parser.parse_args(argv)
    for folder in args.folders:
        if not folder.is_dir():
            parser.exit(2, f"scripts/convert_logs.py: error: no folder {folder}\n")
    failed = 0
    for folder in args.folders:
        for path in sorted(folder.rglob(LOG_NAME)):
            try:
                verb = convert(path)
                records = read_records(path)
            except RunLogError as err:
                print(f"unreadable {err}", flush=True)
                failed += 1
                continue
            state = f"complete ({len(records.records)} epochs)" if records.complete else f"epoch {len(records.records)}"
            print(f"{verb:<10} {path}  {state}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
