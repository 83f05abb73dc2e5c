"""hersd/contract/errors.py: SIGTERM as a Ctrl-C."""

from __future__ import annotations

import os
import signal

import pytest

from hersd.contract.errors import sigterm_as_ctrl_c


def test_sigterm_is_a_ctrl_c_once_and_the_handler_before_it_comes_back() -> None:
    """The first SIGTERM raises KeyboardInterrupt; one that follows while the first is handled (its clean-up) is
    ignored; the handler from before the block is back after it."""
    seen: list[int] = []
    cleaned = False
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        with pytest.raises(KeyboardInterrupt), sigterm_as_ctrl_c():
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                raise AssertionError("SIGTERM did not interrupt")
            finally:
                os.kill(os.getpid(), signal.SIGTERM)  # a second one during the clean-up: no second interrupt
                cleaned = True
        assert cleaned and seen == []  # neither reached the handler from before
        os.kill(os.getpid(), signal.SIGTERM)
        assert seen == [signal.SIGTERM]  # and it is back
    finally:
        signal.signal(signal.SIGTERM, previous)
