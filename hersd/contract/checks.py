"""The range checks every settings dataclass runs in its ``__post_init__`` (a :class:`ConfigError` whose message is
one line naming the field and the allowed values), the ranges the float32 arithmetic of an update needs, and the
key a learner's settings name in those messages (:func:`setting_name`)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Optional

from hersd.contract.errors import ConfigError

# Ranges the float32 arithmetic of an update needs (docs/ARCHITECTURE.md, "Ranges of the settings").
# The discount's horizon H = 1/(1-gamma) is at most HORIZON_LIMIT: a float32 Q near -lambda*H (24-bit
# significand, 1 part in 1.7e7) then still resolves one reward of lambda, and float32(gamma) < 1.
HORIZON_LIMIT = 1e6
# Weights and scales set by the user (lambda_r, lambda_h, action_l2, SAC's alpha, noise stds, input
# clips) are at most SCALE_LIMIT: Q targets then stay within q_min = -max(lambda) * H >= -1e12, so a
# squared TD error (<= 4e24), a batch's sum of them (batches < 1e9 transitions fit any memory) and
# Adam's squared gradients stay below float32's 3.4e38. Weights and the normaliser's std floor are at
# least 1/SCALE_LIMIT: far smaller, gradients sink below Adam's eps (1e-8) and learning stalls.
SCALE_LIMIT = 1e6
# Adam moves every weight by about lr per step; initial weights lie within +-1/sqrt(fan_in) <= 1, so a
# rate above 1 replaces the network at each update (and its float32 weights soon overflow).
LR_LIMIT = 1.0


def check(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def is_finite(value: float) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def shown_number(value: Any) -> str:
    """A given value for messages as its user wrote it: a whole float without its ".0" (2, not 2.0: typed
    configs hold 2 as 2.0), anything else as str."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e16:
        return str(int(value))
    return str(value)


def check_number(name: str, value: float, low: float, high: float, low_open: bool = False) -> None:
    """ConfigError (one line) unless ``value`` is a finite number in [low, high] ((low, high] if low_open)."""
    above_low = is_finite(value) and (value > low if low_open else value >= low)
    check(above_low and value <= high,
          f"{name} must be a number in {'(' if low_open else '['}{low:g}, {high:g}], got {shown_number(value)}")


# The key of the learner whose settings are being built: a subclass's settings are checked by its parent's
# __post_init__, whose messages then name the subclass's key (learner.td3late.*), not the parent's.
_SETTINGS_KEY: ContextVar[Optional[str]] = ContextVar("learner_settings_key", default=None)


def setting_name(key: str, name: str) -> str:
    """``learner.<key>.<name>``, under the key of the learner whose settings are being built, if any, else ``key``."""
    return f"learner.{_SETTINGS_KEY.get() or key}.{name}"


@contextmanager
def settings_of(key: str) -> Iterator[None]:
    """Within it, :func:`setting_name` names the settings of the learner whose key is ``key``."""
    token = _SETTINGS_KEY.set(key)
    try:
        yield
    finally:
        _SETTINGS_KEY.reset(token)
