"""hersd: DDPG + hindsight experience replay with a decaying relabel rate.

Importing the package is cheap (no torch, no MuJoCo): ``hersd.runlog`` is used by the
analysis package on machines without either.
"""

__version__ = "0.1.0"
