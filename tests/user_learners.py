"""A learner of a user's own, as a module's source, for the tests of outside learners (tests/test_user_learner.py,
tests/test_render.py)."""

# A user's module: TD3 whose actor waits ``actor_start`` updates, its settings TD3's and that one.
LATE = '''
from dataclasses import dataclass

from hersd.contract.learners.td3 import TD3Config
from hersd.contract.errors import ConfigError
from hersd.engine.learners.td3 import TD3


@dataclass
class LateSettings(TD3Config):
    actor_start: int = 4  # the actor steps only after this many updates

    def __post_init__(self):
        super().__post_init__()
        if self.actor_start < 0:
            raise ConfigError(f"learner.td3late.actor_start must be >= 0, got {self.actor_start}")


class TD3Late(TD3):
    SETTINGS = LateSettings

    def actor_step_due(self):
        return super().actor_step_due() and self.update_count > self.td3.actor_start


class RegisteredLate(TD3Late):
    NAME = "late"
'''
