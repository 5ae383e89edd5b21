"""SIGINT/SIGTERM latched by long jobs (rehabbot.common.signals): a signal is acted on at the
job's own points, never lost in whatever code it lands in, and a second one stops at once."""

from __future__ import annotations

import signal

import pytest
from swallowed_signals import swallowed_interrupt

from rehabbot.common.signals import SignalLatch, deferring_signals, handling_signals

pytestmark = pytest.mark.usefixtures("python_sigint_handler")


def test_the_default_handler_loses_the_signal_in_a_swallowing_library() -> None:
    swallowed_interrupt()  # the defect the latch guards against: nothing comes out


def test_a_deferred_signal_is_delivered_after_the_block() -> None:
    done = []
    with pytest.raises(KeyboardInterrupt), deferring_signals("test") as latch:
        swallowed_interrupt()
        assert latch.signum == signal.SIGINT
        done.append("the block ran to its end")
    assert done == ["the block ran to its end"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_deferred_sigterm_goes_to_the_handler_that_was_there() -> None:
    received: list[int] = []
    with handling_signals(lambda signum, _frame: received.append(signum)):
        with deferring_signals("test"):
            signal.raise_signal(signal.SIGTERM)
            sum(range(1000))
            assert received == []
        sum(range(1000))
        assert received == [signal.SIGTERM]


def test_a_second_signal_stops_at_once(capsys) -> None:
    latch = SignalLatch("doing the test")
    with handling_signals(latch):
        signal.raise_signal(signal.SIGINT)
        sum(range(1000))
        assert latch.signum == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
            sum(range(1000))
    err = capsys.readouterr().err
    assert "received SIGINT: doing the test (send it again to stop at once)" in err
    assert err.count("received") == 1


def test_no_signal_no_exception_and_the_handlers_come_back() -> None:
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with deferring_signals("test") as latch:
        assert signal.getsignal(signal.SIGINT) is latch
    assert latch.signum is None
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
