"""The package's learners as the contract knows them, without their engine classes (and so without torch): one
module per learner, named as its class's module in hersd/engine/learners/, holding its settings dataclass and its
``CARD``. The class binds to its card (``class TD3(DDPG, card=CARD)``) and takes its ``NAME`` and ``SETTINGS`` from
it; the config's tables of the package's learners are read from the cards (:func:`package_cards`). Adding a learner
to the package: its class's module and its card's, nothing else.
"""

from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass
from typing import Optional


@dataclass(frozen=True)
class LearnerCard:
    """What the config knows of a learner of the package before (and without) importing its class."""

    name: str  # learner=<name>: its class's NAME, the name its runs record
    settings: Optional[type]  # its settings dataclass (learner.<name>.*), its class's SETTINGS; None: it has none
    fast_update: bool = False  # update=fast has a hand-written update for it (FAST_CLASSES in engine/learners/fast.py)


def package_cards() -> dict[str, LearnerCard]:
    """Name -> card of every module of this package, in the order of the modules' names."""
    cards: dict[str, LearnerCard] = {}
    for module in pkgutil.iter_modules(__path__):
        card = importlib.import_module(f"{__name__}.{module.name}").CARD
        if card.name in cards:
            raise TypeError(f"two learner cards named {card.name!r}: in {module.name} and another module")
        cards[card.name] = card
    return cards
