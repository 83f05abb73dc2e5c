#!/usr/bin/env python
"""Land a campaign's logs in the repository: copy each run's ``run.mcap`` (complete or in
progress, never a checkpoint) and its ``policy/epoch_<k>.gif`` from the campaign folder to the
same paths below ``results/``; with ``--commit``, commit each complete run's files with git. A log is
landed in the current format of hersd.contract.runlog (a campaign run by an older hersd writes the earlier
one): every readable message, identical in content (``scripts/convert_logs.py``).

    python scripts/land.py [CAMPAIGN_DIR] [--into RESULTS] [--commit]

CAMPAIGN_DIR defaults to ~/hersd-campaign (a sweep's ``results_dir``), RESULTS to this
repository's ``results/``. Every file is written through a temporary file and a rename, so no
copy is ever half written; a complete log there is never replaced by an unfinished one (``kept``);
animations there that the run no longer has (an earlier attempt's, when it restarted) are
removed when its log is landed anew. An unfinished log there with more epochs than the campaign's (the
run restarted without a checkpoint and has not caught up) is kept too, until the new attempt passes
it. A campaign log that is not a readable run log (no run metadata) is not landed (``skipped``); a
chunk whose checksum fails ends what is read of a log, like a cut (hersd.contract.runlog). One line
per run: ``landed``, ``unchanged``, ``kept``, ``skipped`` or ``refused``, with its state. A log with a
session whose ``git_commit`` ends in ``-dirty`` (trained uncommitted code, which exists nowhere) that the log
below RESULTS does not hold yet (a new log, or a landed one resumed by uncommitted code) is ``refused``, in one
line, and the exit status is 1; the landed log stays as it is, and so do the sessions landed before.

``--commit``: each complete run whose files differ from git's is committed alone, those files
only (whatever else is staged stays staged): ``results: <run> complete (K epochs)``. A git
command that fails (another holds the index lock) is retried; if it still fails the line says so
and the exit status is 1. Safe to run at any time and again: after each run, or in a loop
(results/README.md). An operator's chore, not package code: the package never commits.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from hersd.contract.runlog import LOG_NAME, RunLogError, read_records, rewritten
from hersd.contract.runstore import POLICY_DIR, RunFolder

REPOSITORY = Path(__file__).resolve().parent.parent
GIT_TRIES, GIT_WAIT = 10, 3.0  # tries of a git command that fails, seconds between them
DIRTY = "-dirty"  # a session's git_commit ending so trained uncommitted code (hersd.contract.runlog)


def log_state(path: Path) -> tuple[bool, int, str]:
    """(complete, epochs, ``complete (K epochs)`` / ``epoch N`` / ``unreadable``) of a log file."""
    try:
        records = read_records(path)
    except RunLogError:
        return False, -1, "unreadable"
    epochs = len(records.records)
    return records.complete, epochs, (f"complete ({epochs} epochs)" if records.complete else f"epoch {epochs}")


def sessions_of(path: Path) -> list[dict]:
    """A log's training sessions (``/run/meta``), oldest first; none when there is no log or it is unreadable."""
    try:
        return read_records(path).sessions if path.exists() else []
    except RunLogError:
        return []


def dirty_session(path: Path, landed: Path) -> str | None:
    """Why a log's code exists nowhere: ``session N trained at <commit>-dirty``, for its first session whose
    ``git_commit`` marks uncommitted changes and that the log landed before (``landed``) does not hold already
    (the same start time and commit); None when every new session trained committed code."""
    held = {(session.get("start_time"), session.get("git_commit")) for session in sessions_of(landed)}
    dirty = [(number, session["git_commit"]) for number, session in enumerate(sessions_of(path), start=1)
             if str(session.get("git_commit") or "").endswith(DIRTY)
             and (session.get("start_time"), session.get("git_commit")) not in held]
    return f"session {dirty[0][0]} trained at {dirty[0][1]}" if dirty else None


def write_atomically(data: bytes, target: Path) -> bool:
    """``data`` into ``target`` through a temporary file and a rename; False if it holds them already."""
    if target.exists() and target.read_bytes() == data:
        return False
    target.parent.mkdir(parents=True, exist_ok=True)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    temporary.write_bytes(data)
    os.replace(temporary, target)
    return True


def land_run(source: Path, target: Path) -> tuple[str, bool, str]:
    """Copy one run directory's log and animations -> (verb, complete, state of the log landed or kept)."""
    snapshot = target.with_name(f".{target.name}.{os.getpid()}.snapshot.tmp")  # the bytes copied, judged
    snapshot.parent.mkdir(parents=True, exist_ok=True)
    snapshot.write_bytes((source / LOG_NAME).read_bytes())  # one snapshot of a log that may be growing
    try:
        complete, epochs, state = log_state(snapshot)
        if epochs < 0:
            return "skipped", False, f"{state}: not landed"
        if dirty := dirty_session(snapshot, target / LOG_NAME):  # the sessions landed before stay as they are
            return "refused", False, (f"{state}: {dirty}, code that exists nowhere: not landed; train from a "
                                      "committed tree (results/README.md)")
        if not complete and (target / LOG_NAME).exists():
            landed_complete, landed_epochs, landed_state = log_state(target / LOG_NAME)
            if landed_complete or landed_epochs > epochs:  # a run that restarted has not caught up yet
                return "kept", landed_complete, f"{landed_state} (the campaign's copy: {state})"
        # in the current format, whatever hersd wrote it
        log_changed = write_atomically(rewritten(snapshot), target / LOG_NAME)
    finally:
        snapshot.unlink(missing_ok=True)
    animations = RunFolder(source).animations()
    changed = log_changed
    for path in animations.values():
        changed |= write_atomically(path.read_bytes(), target / POLICY_DIR / path.name)
    for epoch, path in RunFolder(target).animations().items():
        if log_changed and epoch not in animations:  # an earlier attempt's, not a source's lost file
            path.unlink()
            changed = True
    return ("landed" if changed else "unchanged"), complete, state


def git(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """A git command, retried while it fails (e.g. another git command holds the index lock)."""
    for attempt in range(GIT_TRIES):
        done = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
        if done.returncode == 0 or "index.lock" not in done.stderr or attempt == GIT_TRIES - 1:
            return done
        time.sleep(GIT_WAIT)
    raise AssertionError("unreachable")


def commit_run(run_dir: Path, relative: Path, state: str) -> str:
    """Commit a complete run's landed files, alone -> what happened, for its line."""
    status = git("status", "--porcelain", "--", str(run_dir), cwd=run_dir)
    if status.returncode:
        raise RuntimeError(f"not committed (git status: {status.stderr.strip().splitlines()[-1]})")
    if not status.stdout.strip():
        return "committed before"
    message = f"results: {relative.as_posix()} {state}"
    for step in (("add", "-A", "--", str(run_dir)), ("commit", "--quiet", "-m", message, "--", str(run_dir))):
        done = git(*step, cwd=run_dir)
        if done.returncode:
            cause = (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
            raise RuntimeError(f"not committed (git {step[0]}: {cause})")
    return f"committed: {message}"


def say(line: str) -> None:
    """One line on stdout; a reader that went away (``| head``) ends the lines, not the landing."""
    try:
        print(line, flush=True)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/land.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("campaign", nargs="?", type=Path, default=Path.home() / "hersd-campaign",
                        help="the sweep's results_dir (default ~/hersd-campaign)")
    parser.add_argument("--into", type=Path, default=REPOSITORY / "results",
                        help="the folder mirroring it (default: this repository's results/)")
    parser.add_argument("--commit", action="store_true", help="commit each complete run's files with git")
    args = parser.parse_args(argv)
    campaign = args.campaign.expanduser()
    if not campaign.is_dir():
        parser.exit(2, f"scripts/land.py: error: no folder {campaign}; pass the sweep's results_dir\n")
    try:
        args.into.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        parser.exit(2, f"scripts/land.py: error: --into {args.into}: not a folder it can write ({err.strerror})\n")
    failed = 0
    logs = sorted(log for log in campaign.rglob(LOG_NAME)
                  if not any(part.startswith(".") for part in log.relative_to(campaign).parts))
    for log in logs:
        relative = log.parent.relative_to(campaign)
        target = args.into / relative
        verb, complete, state = land_run(log.parent, target)
        note = ""
        failed += verb == "refused"
        if args.commit and complete:
            try:
                note = "; " + commit_run(target, relative, state)
            except RuntimeError as err:
                note, failed = f"; {err}", failed + 1
        say(f"{verb:<9} {target / LOG_NAME}  {state}{note}")
    say(f"{len(logs)} run(s) in {campaign} landed in {args.into}" + (f"; {failed} not landed or not committed"
                                                                     if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
