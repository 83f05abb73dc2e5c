"""sweeps/search/cli.py: the hersd-search command, end to end."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

from helpers import run_command
from searches import FINISHED, fails_with, load, run_meta, tiny_search

from hersd.contract.cores import available_cores
from hersd.contract.runlog import read_run
from hersd.contract.study import default_storage
from sweeps.search import cli

CLI = "sweeps.search.cli:main"


def test_command_line_exit_code_is_2(tmp_path: Path) -> None:
    done = run_command(CLI, "search.space.beta2.low=1", "search.space.beta2.high=0", *tiny_search(tmp_path),
                       timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip() == "hersd-search: error: search.space.beta2: low (1) must be <= high (0)"


def test_help_also_through_the_packages_main(capsys) -> None:
    cli.main(["--help"])
    assert capsys.readouterr().out.startswith("usage: hersd-search")
    done = run_command("sweeps.search:main", "--help", timeout=120)  # the entry point scripts installed so far
    assert done.returncode == 0 and done.stdout.startswith("usage: hersd-search")


def test_the_command_loads_neither_torch_nor_the_analysis() -> None:
    code = ("import sys, sweeps.search.cli; "
            "print(sorted(m for m in ('torch', 'mujoco', 'analysis') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]"


def test_ci_search_on_two_workers_with_a_journal(tmp_path: Path, capsys) -> None:
    journal = tmp_path / "shared" / "study.log"
    cli.main(["search=ci", f"search.storage=journal:{journal}", *tiny_search(tmp_path)])
    study = load(f"journal:{journal}")
    assert len(study.get_trials(states=FINISHED)) == 6
    assert len({t.user_attrs["worker"] for t in study.trials}) == 2  # two processes shared the study
    for trial in study.get_trials(states=FINISHED):
        (run,) = trial.user_attrs["run_dirs"]
        assert Path(run).is_relative_to(tmp_path / "reach" / "her") and read_run(Path(run) / "run.mcap").epochs.size
        assert 1 <= run_meta(run)["threads"] <= max(1, available_cores() // 2)  # the cores shared by the two workers
    out = capsys.readouterr().out
    counts = [len(study.get_trials(states=(state,))) for state in FINISHED]
    assert f"trials: {counts[0]} complete, {counts[1]} pruned, 0 fail" in out
    assert not (tmp_path / "search").exists()  # the search draws nothing itself

    # the printed command draws the study (hersd-report reads the journal named by --storage)
    (command,) = [line.split(": ", 1)[1] for line in out.splitlines() if line.startswith("figures and tables: ")]
    assert command == shlex.join(["hersd-report", str(tmp_path), "--storage", f"journal:{journal}"])
    report = subprocess.run(shlex.split(command), capture_output=True, text=True, timeout=300)
    assert report.returncode == 0, report.stdout[-2000:] + report.stderr[-2000:]
    assert (tmp_path / "report" / "search" / f"{study.study_name}_beta_plane.png").stat().st_size > 0


def test_the_report_command_names_only_the_storages_the_report_would_not_find(tmp_path: Path) -> None:
    assert cli.report_command(tmp_path, default_storage(tmp_path, "s")) == shlex.join(["hersd-report", str(tmp_path)])
    assert cli.report_command(tmp_path, f"journal:{tmp_path}/search/s.log") == shlex.join(["hersd-report", str(tmp_path)])
    elsewhere = f"journal:{tmp_path}/shared/s.log"
    assert cli.report_command(tmp_path, elsewhere) == shlex.join(["hersd-report", str(tmp_path), "--storage", elsewhere])
    assert shlex.split(cli.report_command(tmp_path, "postgresql://u:secret@host/db"))[2:] == [
        "--storage", "postgresql://u:***@host/db"]


def test_a_search_training_here_refuses_bf16_on_a_cpu_without_it_before_any_trial(tmp_path: Path, capsys,
                                                                                   monkeypatch) -> None:
    from hersd.engine import resources

    monkeypatch.setattr(resources, "cpu_has_bf16", lambda: False)
    err = fails_with([*tiny_search(tmp_path), "precision=bf16"], capsys)
    assert err == ("hersd-search: error: precision=bf16: this CPU has no bf16 instructions (avx512_bf16, amx_bf16); "
                   "use precision=fp32\n")
    assert not (tmp_path / "search").exists()  # no study made, no trial failed
