"""hersd installs like any package: the wheel holds every config, and a non-editable install
runs the commands from any folder."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from helpers import TINY

from hersd.contract.runlog import read_run

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "-w", str(out), str(ROOT)],
                   check=True, capture_output=True, text=True, timeout=300)
    (path,) = out.glob("hersd-*.whl")
    return path


def test_the_wheel_holds_every_config_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    configs = {f"hersd/conf/{p.relative_to(ROOT / 'conf').as_posix()}" for p in (ROOT / "conf").rglob("*.yaml")}
    assert configs and configs <= names, sorted(configs - names)
    assert {"hersd/conf/train.yaml", "hersd/conf/sweep.yaml", "hersd/conf/hydra/launcher/slurm.yaml"} <= names
    assert "hydra_plugins/hersd_sweeper/runstore_sweeper.py" in names


@pytest.mark.slow
def test_a_non_editable_install_runs_the_smoke_sweep_from_an_empty_folder(wheel, tmp_path):
    venv = tmp_path / "venv"
    # The dependencies come from the site-packages folders of the interpreter running the tests (itself maybe
    # a virtualenv's, whose packages --system-site-packages would not see), listed in a .pth file as plain
    # paths: their own .pth files (an editable install of hersd among them) are not run. hersd itself comes
    # only from the wheel.
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    (site_packages,) = venv.glob("lib/python*/site-packages")
    (site_packages / "test_dependencies.pth").write_text(
        "".join(f"{path}\n" for path in sys.path if Path(path).name in ("site-packages", "dist-packages")))
    subprocess.run([venv / "bin" / "python", "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", str(wheel)],
                   check=True, capture_output=True, timeout=300)
    where = subprocess.run([venv / "bin" / "python", "-c", "import hersd.conf; print(hersd.conf.__file__)"],
                           capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    assert where.startswith(str(venv)), where
    empty = tmp_path / "empty"
    empty.mkdir()
    result = subprocess.run([venv / "bin" / "hersd-sweep", "+grid=smoke", "seeds=1", "epochs=1", *TINY,
                             "results_dir=results"], capture_output=True, text=True, cwd=empty, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    logs = list((empty / "results").rglob("run.mcap"))
    assert len(logs) == 2 and all(read_run(log).complete for log in logs)
    assert read_run(logs[0]).meta["git_commit"] is None  # not a checkout: no commit to claim
