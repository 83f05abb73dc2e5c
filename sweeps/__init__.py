"""Sweeps and searches over training runs: grids through Hydra launchers, Optuna studies."""
