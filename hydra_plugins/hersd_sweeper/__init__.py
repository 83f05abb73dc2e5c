"""Hydra plugin: the run-store-aware sweeper used by ``hersd-sweep`` (see sweeps/)."""
