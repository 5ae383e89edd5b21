"""A library that swallows KeyboardInterrupt, for the tests of latched signals
(``rehabbot.common.signals``; used by tests/test_signals.py and tests/test_training.py)."""

from __future__ import annotations

import signal


def swallowed_interrupt() -> None:
    """What a library that eats a KeyboardInterrupt raised inside it does (measured: JAX's
    extension modules while being imported): with Python's default handler this Ctrl-C is
    lost; a latching handler keeps it."""
    try:
        signal.raise_signal(signal.SIGINT)
        sum(range(1000))  # the handler runs at the next bytecode
    except KeyboardInterrupt:
        pass
