"""Run logs -> tidy tables -> metrics -> figures -> an HTML report (``hersd-report``).

``load`` reads the MCAP logs, ``metrics`` computes (pure functions on DataFrames), ``figures``
draws, ``tables`` writes tables as Markdown and HTML, ``search_figures`` draws an Optuna
study (opened read-only by ``studies``), ``workers`` spreads reading and drawing over
the cores, ``report`` writes the files and holds the command line. Nothing here imports
torch, MuJoCo or the sweeps layer; ``import analysis.report`` imports neither scipy.stats,
matplotlib nor optuna (they come when computing, drawing or reading a study).
"""
