"""DDPG's card (hersd/engine/learners/ddpg.py, the paper's learner): no settings of its own (it reads ``ddpg.*``,
which every learner shares), and a fast update."""

from __future__ import annotations

from hersd.contract.learners import LearnerCard

CARD = LearnerCard(name="ddpg", settings=None, fast_update=True)
