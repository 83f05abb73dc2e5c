"""The README's quick start leaves the checkout clean: the smoke sweep plans its runs under runs/, the README's
report command draws that folder, and git ignores the runs, the sweep's records and the report."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SWEEP = [sys.executable, "-c", "from sweeps.launch import main; main()"]


def quick_start() -> list[list[str]]:
    """The README's quick-start command line, as its steps' words."""
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("\n## Quick start\n")[1].split("\n## ")[0]
    line = next(line for line in section.splitlines() if "+grid=smoke" in line)
    return [step.split() for step in line.split("&&")]


def planned_runs(cwd: Path) -> list[str]:
    """The folders the smoke sweep's dry run plans, as it prints them (relative to ``cwd``)."""
    out = subprocess.run([*SWEEP, "+grid=smoke", "--dry-run"], capture_output=True, text=True, check=True,
                         timeout=300, cwd=cwd).stdout
    return [line.split()[1] for line in out.splitlines() if line.startswith("  ")]


def test_the_quick_start_reports_the_folder_its_sweep_writes(tmp_path):
    install, sweep, report = quick_start()
    assert install == ["pip", "install", "-e", "."] and sweep == ["hersd-sweep", "+grid=smoke"]
    runs = planned_runs(tmp_path)
    assert len(runs) == 4 and all(run.startswith("runs/") for run in runs), runs
    assert report == ["hersd-report", "runs/"]
    assert not (tmp_path / "runs").exists()  # a dry run writes nothing


def test_git_ignores_what_the_quick_start_writes():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    written = [f"{run}/run.mcap" for run in planned_runs(ROOT)]
    written += ["runs/.sweeps/20260101-000000/multirun.yaml", "runs/report/index.html",
                "runs/report/tables/runs_provenance.csv"]
    ignored = subprocess.run(["git", "check-ignore", "--no-index", *written], capture_output=True, text=True,
                             cwd=ROOT).stdout.split()
    assert ignored == written
    kept = subprocess.run(["git", "check-ignore", "--no-index", "results/report/index.html"], cwd=ROOT)
    assert kept.returncode == 1  # the committed report is tracked, not ignored
