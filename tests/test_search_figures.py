"""analysis/search_figures.py: the study figures command."""

from __future__ import annotations




def test_the_search_figures_command_reports_a_bad_storage_in_one_line(storages, tmp_path, capsys):
    from analysis.search_figures import main as search_figures_main

    assert search_figures_main([str(storages / "plain.db"), str(tmp_path)]) == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path), "--study", "other"]) == 2
    assert capsys.readouterr().err.count("\n") == 2
    assert search_figures_main([str(storages / "study.db"), str(tmp_path)]) == 0
