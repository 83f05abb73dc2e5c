"""Cost of the run log's crash-safe write per epoch, over a 200-epoch run.

After each epoch :class:`hersd.contract.runlog.RunLogWriter` rewrites the whole log (a complete, indexed
MCAP file) to a temporary file, fsyncs it and renames it over ``run.mcap``, so the file grows
and each write costs more than the last. This writes a real 200-epoch log's messages (a
committed FetchPush log's metadata and epochs, with bias-evaluation fields added at the default
bias epochs, as current runs log them) epoch by epoch into a temporary folder, timing each
``write_epoch``; and, for comparison, the earlier format's append-and-fsync of one message.

Printed: milliseconds per epoch at epochs 1, 50, 100, 150, 200, the mean and the total over the
run, the mean's share of a 30 s FetchPush epoch, and the final file size.

Usage: python benchmarks/bench_runlog.py [--log results/.../run.mcap] [--dir FOLDER] [--repeats 3]
(``--dir``: where to write, default the system's temporary folder; use the results folder's
file system to measure the disk the runs write to.)
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from hersd.contract.runlog import EPOCH_SCHEMA, RunLogWriter, read_records

REPOSITORY = Path(__file__).resolve().parent.parent
BIAS_EPOCHS = (1, 2, 5, 10, 20, 30, 50, 75, 100, 150, 200)  # hersd.contract.config's default bias.epochs
EPOCH_SECONDS = 30.0


def records_of(log: Path) -> tuple[dict, list[dict]]:
    """A log's first session and its epochs, with the bias fields a current run logs at BIAS_EPOCHS."""
    raw = read_records(log)
    records = []
    for record in raw.records:
        record = {k: v for k, v in record.items() if v is not None}
        if record["epoch"] in BIAS_EPOCHS:
            for goal in ("real", "hindsight"):
                record |= {f"bias_{goal}_mean": 1.234567, f"bias_{goal}_std": 2.345678,
                           f"bias_{goal}_count": 100, f"return_{goal}_mean": -12.345678}
            record["bias_seconds"] = 0.4
        records.append(record)
    return raw.meta, records


def time_current(meta: dict, records: list[dict], folder: Path) -> np.ndarray:
    """Seconds of each ``write_epoch`` of the current writer -> shape (epochs,)."""
    writer = RunLogWriter(folder / "run.mcap", meta)
    seconds = []
    for record in records:
        start = time.perf_counter()
        writer.write_epoch(record)
        seconds.append(time.perf_counter() - start)
    writer.finish(len(records))
    return np.array(seconds)


def time_earlier(meta: dict, records: list[dict], folder: Path) -> np.ndarray:
    """Seconds of each epoch's append + flush + fsync in the earlier, unchunked format -> shape (epochs,)."""
    with open(folder / "earlier.mcap", "wb") as stream:
        writer = Writer(stream, use_chunking=False)
        writer.start()
        schema = writer.register_schema(name="hersd.Epoch", encoding="jsonschema", data=EPOCH_SCHEMA)
        channel = writer.register_channel(topic="/epoch", message_encoding="json", schema_id=schema)
        writer.add_message(channel_id=channel, log_time=0, publish_time=0, data=json.dumps(meta).encode())
        seconds = []
        for record in records:
            start = time.perf_counter()
            now = time.time_ns()
            writer.add_message(channel_id=channel, log_time=now, publish_time=now, data=json.dumps(record).encode())
            stream.flush()
            os.fsync(stream.fileno())
            seconds.append(time.perf_counter() - start)
        writer.finish()
    return np.array(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    default_log = next(iter(sorted((REPOSITORY / "results").rglob("run.mcap"))), None)
    parser.add_argument("--log", type=Path, default=default_log, help="a 200-epoch run.mcap to replay")
    parser.add_argument("--dir", type=Path, default=None, help="folder to write in (default: a temporary one)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each writer; each epoch's time is the median over them")
    args = parser.parse_args()
    meta, records = records_of(args.log)
    folder = Path(tempfile.mkdtemp(prefix="bench_runlog-", dir=args.dir))
    try:
        current = np.median([time_current(meta, records, folder) for _ in range(args.repeats)], axis=0)
        earlier = np.median([time_earlier(meta, records, folder) for _ in range(args.repeats)], axis=0)
        size = (folder / "run.mcap").stat().st_size
    finally:
        shutil.rmtree(folder)
    shown = args.log.relative_to(REPOSITORY) if args.log.is_relative_to(REPOSITORY) else args.log
    print(f"{len(records)} epochs from {shown}, written in {folder.parent} (median of {args.repeats} runs)")
    print(f"{'epoch':>6} {'current ms':>11} {'earlier ms':>11}")
    for epoch in (1, 50, 100, 150, 200):
        if epoch <= len(records):
            print(f"{epoch:>6} {1e3 * current[epoch - 1]:>11.1f} {1e3 * earlier[epoch - 1]:>11.1f}")
    print(f"{'mean':>6} {1e3 * current.mean():>11.1f} {1e3 * earlier.mean():>11.1f}")
    print(f"{'total':>6} {current.sum():>10.2f}s {earlier.sum():>10.2f}s")
    print(f"current writer: {100 * current.mean() / EPOCH_SECONDS:.3f} % of a {EPOCH_SECONDS:.0f} s epoch on average, "
          f"{100 * current.max() / EPOCH_SECONDS:.3f} % at most; final log {size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
