"""hersd/contract/study.py, the study's contract: storage specs and their names, the trial parameters'
encoding, the storages the report finds by itself. (Opening storages: tests/test_search_storage.py for writing,
tests/test_studies.py read-only.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from hersd.contract.study import (StudySettings, default_storage, found_by_report, storage_file, storage_location,
                                  storage_name, stored_params, trial_params)


def test_storage_specs_name_a_journal_a_sqlite_file_or_a_database(tmp_path: Path) -> None:
    assert storage_location(f"journal:{tmp_path}/a.txt") == ("journal", f"{tmp_path}/a.txt")
    assert storage_location(f"{tmp_path}/a.log") == ("journal", f"{tmp_path}/a.log")
    assert storage_location(f"{tmp_path}/a.db") == ("rdb", f"sqlite:///{tmp_path}/a.db")
    assert storage_file(f"sqlite:///{tmp_path}/a.db?timeout=5") == tmp_path / "a.db"
    assert storage_file("postgresql://u:secret@host/db") is None
    assert storage_name("postgresql://u:secret@host/db") == "postgresql://u:***@host/db"


def test_the_report_finds_by_itself_only_the_storages_in_its_folders_search_folder(tmp_path: Path) -> None:
    assert found_by_report(tmp_path, default_storage(tmp_path, "s"))
    assert found_by_report(tmp_path, f"journal:{tmp_path}/search/s.log")
    assert not found_by_report(tmp_path, f"journal:{tmp_path}/shared/s.log")
    assert not found_by_report(tmp_path, f"{tmp_path}/search/s.txt")
    assert not found_by_report(tmp_path, "postgresql://u:secret@host/db")


@pytest.mark.parametrize("params, kinds", [
    ({"kind": "exponential", "beta1": 0.5, "beta2": -1.0}, ["exponential"]),
    ({"kind": "linear", "beta1": 0.5, "lambda_h": 0.5}, ["linear"]),
    ({"kind": "constant", "eps": 0.9}, ["constant"]),
    ({"kind": "linear", "beta1": 0.5}, ["linear", "exponential"]),
])
def test_stored_parameters_give_back_the_trials(params: dict, kinds: list[str]) -> None:
    stored = stored_params(params, kinds)
    assert ("kind" in stored) == (len(kinds) > 1)  # Optuna draws the kind only when there is a choice
    assert trial_params(stored) == params


def test_settings_are_read_back_or_none() -> None:
    settings = StudySettings("auc", "test_success", 3, 0, 50, "push", "her", "0123abcd")
    assert StudySettings.of({"settings": vars(settings)}) == settings
    assert StudySettings.of({}) is None and StudySettings.of({"settings": {"objective": "auc"}}) is None
