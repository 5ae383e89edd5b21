"""SIGINT and SIGTERM handling for long jobs that must save their work before stopping.

A KeyboardInterrupt raised wherever a signal lands can be lost: measured with SBX training,
a Ctrl-C that arrived while JAX's native extension modules were being imported was swallowed
inside them (training went on to the end), or aborted the process (exit -6). Long jobs
therefore latch the first signal (:class:`SignalLatch`) and act on it at points of their own
choosing; a second signal still raises KeyboardInterrupt at once.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def handling_signals(handler: Callable[[int, Any], None]) -> Iterator[None]:
    """Install ``handler`` for SIGINT and SIGTERM (only in the main thread: elsewhere this is
    a no-op); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with keeping_signal_handlers():
        for signum in STOP_SIGNALS:
            signal.signal(signum, handler)
        yield


@contextlib.contextmanager
def keeping_signal_handlers() -> Iterator[None]:
    """Put back the SIGINT and SIGTERM handlers after the block, whatever a library installed in
    it (``ray.init`` leaves a SIGTERM handler and Ray Tune's ``Tuner.fit`` a SIGINT handler that
    only sets a flag of its own, so a later signal in the same process would be lost). Main
    thread only, as signal handlers are."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old if old is not None else signal.SIG_DFL)


class SignalLatch:
    """A SIGINT/SIGTERM handler that records the first signal (``signum``) and prints
    ``"received <NAME>: <doing>"`` on stderr, where ``doing`` says what happens next; a second
    signal raises KeyboardInterrupt at once."""

    def __init__(self, doing: str) -> None:
        self.signum: int | None = None
        self.doing = doing

    def __call__(self, signum: int, _frame: Any) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum
        print(f"\nreceived {signal.Signals(signum).name}: {self.doing} (send it again to stop "
              "at once)", file=sys.stderr, flush=True)

    def raise_if_received(self) -> None:
        """Raise KeyboardInterrupt if a signal was latched (a job's own point to stop at)."""
        if self.signum is not None:
            raise KeyboardInterrupt


@contextlib.contextmanager
def deferring_signals(doing: str = "stopping when this step is done") -> Iterator[SignalLatch]:
    """Latch SIGINT/SIGTERM through the block (for work that must not be cut anywhere, such as
    importing native libraries), then deliver the latched signal again to the handler that was
    there before (Python's default raises KeyboardInterrupt for SIGINT; SIGTERM's ends the
    process)."""
    latch = SignalLatch(doing)
    with handling_signals(latch):
        yield latch
    if latch.signum is not None:
        signal.raise_signal(latch.signum)
