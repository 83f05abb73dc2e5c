"""hersd's Hydra configs (YAML): shipped inside the package as ``hersd.conf``; see hersd/contract/compose.py."""
