"""scripts/land.py: a campaign folder's logs and animations landed in a git repository's results/,
atomically, never a complete log replaced by an unfinished one, each complete run committed alone."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from analysis.synthetic import write_animation, write_run
from hersd.contract.config import TrainConfig
from hersd.contract.runlog import read_records

LAND = [sys.executable, str(Path(__file__).resolve().parent.parent / "scripts" / "land.py")]
DONE, RUNNING = Path("push/her/constant-0.8/seed5-aaaa0000"), Path("push/her/linear-b1_0.25/seed5-bbbb1111")


def write_log(directory: Path, epochs_done: int, complete: bool = False) -> Path:
    with mock.patch("os.fsync"):
        return write_run(directory, TrainConfig(epochs=200), np.linspace(0, 1, epochs_done), complete=complete)


def git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True, check=True).stdout


@pytest.fixture
def repo(tmp_path) -> Path:
    """A git repository with one commit and a file staged by someone else."""
    repo = tmp_path / "repo"
    repo.mkdir()
    git(repo, "init", "--quiet")
    git(repo, "config", "user.email", "test@example.com")
    git(repo, "config", "user.name", "test")
    (repo / "README").write_text("x")
    git(repo, "add", "README")
    git(repo, "commit", "--quiet", "-m", "start")
    (repo / "other.txt").write_text("someone else's")
    git(repo, "add", "other.txt")
    return repo


def land(campaign: Path, repo: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*LAND, str(campaign), "--into", str(repo / "results"), *args], capture_output=True,
                          text=True, timeout=120)


def test_land_copies_logs_and_animations_and_commits_each_complete_run_alone(tmp_path, repo):
    campaign = tmp_path / "campaign"
    write_log(campaign / DONE, 200, complete=True)
    write_animation(campaign / DONE, 200)
    write_log(campaign / RUNNING, 30)
    (campaign / RUNNING / "checkpoint.pt").write_bytes(b"never landed")
    write_log(campaign / ".sweeps" / "x", 3)  # not a run of the folder
    landed = land(campaign, repo, "--commit")
    assert landed.returncode == 0, landed.stderr
    results = repo / "results"
    files = sorted(p.relative_to(results) for p in results.rglob("*") if p.is_file())
    assert files == [DONE / "policy" / "epoch_200.gif", DONE / "run.mcap", RUNNING / "run.mcap"]
    assert (results / DONE / "run.mcap").read_bytes() == (campaign / DONE / "run.mcap").read_bytes()
    message = f"results: {DONE.as_posix()} complete (200 epochs)"
    assert git(repo, "log", "--format=%s") == f"{message}\nstart\n"
    assert git(repo, "show", "--name-only", "--format=", "HEAD").split() == \
        [f"results/{DONE}/policy/epoch_200.gif", f"results/{DONE}/run.mcap"]
    assert "A  other.txt" in git(repo, "status", "--porcelain")  # someone else's staged file: still staged
    assert f"landed    {results / RUNNING / 'run.mcap'}  epoch 30" in landed.stdout

    again = land(campaign, repo, "--commit")  # nothing new: nothing written, no commit
    assert "unchanged" in again.stdout and "committed before" in again.stdout
    assert len(git(repo, "log", "--format=%s").splitlines()) == 2


def test_a_complete_log_is_never_replaced_by_an_unfinished_one_and_stale_animations_go(tmp_path, repo):
    campaign, results = tmp_path / "campaign", repo / "results"
    write_log(results / DONE, 200, complete=True)  # landed complete before (e.g. made on another machine)
    write_log(campaign / DONE, 40)  # this folder's copy of the run, still training
    write_log(results / RUNNING, 10)
    write_animation(results / RUNNING, 50)  # an earlier attempt's, which restarted from scratch
    write_log(campaign / RUNNING, 20)
    write_animation(campaign / RUNNING, 10)
    out = land(campaign, repo).stdout
    assert f"kept      {results / DONE / 'run.mcap'}  complete (200 epochs) (the campaign's copy: epoch 40)" in out
    assert read_records(results / DONE / "run.mcap").complete
    assert len(read_records(results / RUNNING / "run.mcap").records) == 20
    assert sorted(p.name for p in (results / RUNNING / "policy").iterdir()) == ["epoch_10.gif"]
    assert not list(results.rglob(".*tmp")) and not list(results.rglob("*.snapshot*"))
    assert git(repo, "log", "--format=%s") == "start\n"  # no --commit: nothing committed


def test_an_unfinished_log_with_more_epochs_is_kept_until_a_restarted_run_passes_it(tmp_path, repo):
    campaign, results = tmp_path / "campaign", repo / "results"
    write_log(results / RUNNING, 39)  # landed at a stop; the run then restarted without a checkpoint
    write_log(campaign / RUNNING, 2)
    out = land(campaign, repo).stdout
    assert f"kept      {results / RUNNING / 'run.mcap'}  epoch 39 (the campaign's copy: epoch 2)" in out
    assert len(read_records(results / RUNNING / "run.mcap").records) == 39
    write_log(campaign / RUNNING, 40)
    assert f"landed    {results / RUNNING / 'run.mcap'}  epoch 40" in land(campaign, repo).stdout
    assert len(read_records(results / RUNNING / "run.mcap").records) == 40


def corrupt_one_digit(log: Path, epoch: int) -> None:
    """Change one digit of an epoch's test success inside its chunk: still valid JSON, a failing checksum."""
    data = bytearray(log.read_bytes())
    at = [match.end() for match in re.finditer(rb'"test_success": 0\.', data)][epoch - 1]
    data[at] = ord("9") if data[at] != ord("9") else ord("1")
    log.write_bytes(bytes(data))


def test_a_complete_log_whose_checksum_fails_replaces_no_good_log(tmp_path, repo):
    """A damaged chunk ends what is read of the campaign's copy: it is no complete log, the landed one stays."""
    campaign, results = tmp_path / "campaign", repo / "results"
    write_log(results / DONE, 200, complete=True)
    write_log(campaign / DONE, 200, complete=True)
    good = (results / DONE / "run.mcap").read_bytes()
    corrupt_one_digit(campaign / DONE / "run.mcap", 150)
    records = read_records(campaign / DONE / "run.mcap")
    assert records.damaged and not records.complete and len(records.records) < 150
    out = land(campaign, repo, "--commit").stdout
    assert f"kept      {results / DONE / 'run.mcap'}  complete (200 epochs)" in out
    assert (results / DONE / "run.mcap").read_bytes() == good


def test_a_log_that_is_no_run_log_is_skipped_and_nothing_of_its_run_lands(tmp_path, repo):
    campaign, results = tmp_path / "campaign", repo / "results"
    write_log(campaign / RUNNING, 5)
    write_animation(campaign / RUNNING, 5)
    log = campaign / RUNNING / "run.mcap"
    log.write_bytes(log.read_bytes()[:100])  # cut before its metadata
    out = land(campaign, repo).stdout
    assert f"skipped   {results / RUNNING / 'run.mcap'}  unreadable: not landed" in out
    assert not (results / RUNNING).exists() and not list(results.rglob("*.snapshot*"))


def test_animations_stay_when_the_log_is_the_same_attempt(tmp_path, repo):
    """Only a log landed anew (an attempt that restarted) takes the animations it lacks away."""
    campaign, results = tmp_path / "campaign", repo / "results"
    write_log(campaign / DONE, 200, complete=True)
    write_animation(campaign / DONE, 50)
    land(campaign, repo, "--commit")
    (campaign / DONE / "policy" / "epoch_50.gif").unlink()
    assert "unchanged" in land(campaign, repo, "--commit").stdout.splitlines()[0]
    assert (results / DONE / "policy" / "epoch_50.gif").is_file()


def test_the_snapshot_of_a_log_being_judged_is_a_file_git_ignores(tmp_path):
    """A landing killed mid-way leaves at most a ``*.tmp`` file, which .gitignore keeps out of results/."""
    spec = importlib.util.spec_from_file_location("land", LAND[1])
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    judged = []
    write_log(tmp_path / "campaign" / RUNNING, 3)
    with mock.patch.object(module, "log_state", side_effect=lambda path: judged.append(path) or (False, -1, "x")):
        module.land_run(tmp_path / "campaign" / RUNNING, tmp_path / "results" / RUNNING)
    assert judged and judged[0].name.endswith(".tmp") and judged[0].parent == (tmp_path / "results" / RUNNING).parent
    assert "results/**/*.tmp" in (Path(LAND[1]).parent.parent / ".gitignore").read_text().splitlines()


def test_logs_of_the_earlier_format_land_in_the_current_one_with_every_message_identical(tmp_path, repo):
    """A campaign run by an older hersd: its logs (complete, and running: no footer) land chunked and indexed."""
    from mcap.reader import make_reader
    from runlogs import write_old_format

    campaign, results = tmp_path / "campaign", repo / "results"
    for run, complete in ((DONE, True), (RUNNING, False)):
        (campaign / run).mkdir(parents=True)
        write_old_format(campaign / run / "run.mcap", 7, complete=complete)
    out = land(campaign, repo).stdout
    assert f"landed    {results / RUNNING / 'run.mcap'}  epoch 7" in out
    for run in (DONE, RUNNING):
        old, new = read_records(campaign / run / "run.mcap"), read_records(results / run / "run.mcap")
        assert new.messages == old.messages and new.records == old.records and not new.damaged
        with open(results / run / "run.mcap", "rb") as stream:
            assert make_reader(stream).get_summary().statistics.channel_message_counts[2] == 7  # /epoch
    assert "unchanged" in land(campaign, repo).stdout.splitlines()[0]


def test_a_missing_campaign_folder_is_one_line_and_exit_2(tmp_path, repo):
    result = land(tmp_path / "nowhere", repo)
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0 and "no folder" in result.stderr


@pytest.mark.parametrize("into", ["file", "file/results"])
def test_an_into_that_cannot_be_a_folder_is_one_line_and_exit_2(tmp_path, into):
    write_log(tmp_path / "campaign" / RUNNING, 3)
    (tmp_path / "file").write_text("")
    result = subprocess.run([*LAND, str(tmp_path / "campaign"), "--into", str(tmp_path / into)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and "not a folder it can write" in result.stderr


def test_a_reader_that_went_away_ends_the_lines_not_the_landing(tmp_path, repo):
    campaign = tmp_path / "campaign"
    for run in (DONE, RUNNING):
        write_log(campaign / run, 3)
    read, write = os.pipe()
    os.close(read)  # as `| head` does once it has its lines
    landed = subprocess.run([*LAND, str(campaign), "--into", str(repo / "results")], stdout=write,
                            stderr=subprocess.PIPE, text=True, timeout=120)
    os.close(write)
    assert landed.returncode == 0 and not landed.stderr
    assert all((repo / "results" / run / "run.mcap").is_file() for run in (DONE, RUNNING))


def test_a_new_log_with_a_dirty_session_is_refused_in_one_line_and_landed_ones_stay(tmp_path, repo):
    """A session trained at ``<commit>-dirty`` ran code that exists nowhere: such a new log is not landed (one
    line, exit 1); a clean one beside it lands; a log already below results/ stays as it was landed."""
    campaign, results = tmp_path / "campaign", repo / "results"
    with mock.patch("os.fsync"):
        write_run(campaign / RUNNING, TrainConfig(epochs=200), np.linspace(0, 1, 3), complete=False,
                  meta={"git_commit": "1a2b3c4-dirty"})
        write_run(campaign / DONE, TrainConfig(epochs=200), np.linspace(0, 1, 3), complete=False,
                  meta={"git_commit": "1a2b3c4"})
    done = land(campaign, repo)
    refused = [line for line in done.stdout.splitlines() if line.startswith("refused")]
    assert done.returncode == 1 and refused == [
        f"refused   {results / RUNNING / 'run.mcap'}  epoch 3: session 1 trained at 1a2b3c4-dirty, code that "
        "exists nowhere: not landed; train from a committed tree (results/README.md)"]
    assert not (results / RUNNING).exists() and (results / DONE / "run.mcap").is_file()
    (results / RUNNING).mkdir(parents=True)  # landed before this rule, dirty session and all: it follows its copy
    (results / RUNNING / "run.mcap").write_bytes((campaign / RUNNING / "run.mcap").read_bytes())
    with mock.patch("os.fsync"):
        resume_at(campaign / RUNNING, "1a2b3c4")
    assert f"landed    {results / RUNNING / 'run.mcap'}  epoch 4" in land(campaign, repo).stdout


def resume_at(folder: Path, commit: str) -> None:
    """A fourth epoch in ``folder``'s log by a new session trained at ``commit`` (as a resume writes it)."""
    from hersd.contract.runlog import RunLogWriter, read_run

    previous = read_run(folder / "run.mcap")
    writer = RunLogWriter(folder / "run.mcap", {**previous.sessions[-1], "git_commit": commit,
                                                "start_time": "2025-01-02T00:00:00+0000"}, previous)
    writer.write_epoch({**previous.epochs.iloc[-1].to_dict(), "epoch": len(previous.epochs) + 1})
    writer.close()


def test_a_landed_log_resumed_by_uncommitted_code_is_refused_and_stays_as_landed(tmp_path, repo):
    """A run landed clean and then resumed at ``<commit>-dirty`` gained epochs from code that exists nowhere: its
    new log is refused in one line (exit 1) and the landed one stays byte for byte."""
    campaign, results = tmp_path / "campaign", repo / "results"
    with mock.patch("os.fsync"):
        write_run(campaign / RUNNING, TrainConfig(epochs=200), np.linspace(0, 1, 3), complete=False,
                  meta={"git_commit": "1a2b3c4"})
    assert land(campaign, repo).returncode == 0
    landed = (results / RUNNING / "run.mcap").read_bytes()
    with mock.patch("os.fsync"):
        resume_at(campaign / RUNNING, "5d6e7f8-dirty")
    done = land(campaign, repo)
    assert done.returncode == 1 and done.stdout.splitlines()[0] == (
        f"refused   {results / RUNNING / 'run.mcap'}  epoch 4: session 2 trained at 5d6e7f8-dirty, code that "
        "exists nowhere: not landed; train from a committed tree (results/README.md)")
    assert (results / RUNNING / "run.mcap").read_bytes() == landed
