"""What the run engine, the sweeps and the analysis share: a run's config schema and its composition, the errors,
the relabel-rate schedules, the tasks, the learner registry and cards, the resolved run (``RunSpec``), the run log, the
run's folder, the study's encoding and the threads=auto rule. Imports neither torch nor MuJoCo, nor any other layer (tests/test_layers.py)."""
