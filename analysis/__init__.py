"""Run logs -> tidy tables -> metrics -> figures -> an HTML report (``hersd-report``).

``load`` reads the MCAP logs, ``metrics`` computes (pure functions on DataFrames),
``figures`` draws, ``report`` writes the files and holds the command line. Nothing here
imports torch or MuJoCo.
"""
