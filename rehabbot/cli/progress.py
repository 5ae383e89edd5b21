"""A throttled progress line on stderr for slow commands (``rehabbot render``): frames done of
the total, elapsed time and the estimated time left, at most every
:data:`PROGRESS_INTERVAL_S` seconds, and always for the first and the last frame."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

PROGRESS_INTERVAL_S = 2.0


def clock_text(seconds: float) -> str:
    """``m:ss`` (``h:mm:ss`` from an hour on)."""
    seconds = max(0, round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class ProgressLine:
    """``progress(done, total)``: prints ``<prefix>: frame done/total (p %), m:ss elapsed,
    ~m:ss left`` to ``stream``, throttled."""

    def __init__(self, prefix: str, unit: str = "frame", stream: TextIO | None = None,
                 interval_s: float = PROGRESS_INTERVAL_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.prefix, self.unit, self.interval_s, self.clock = prefix, unit, interval_s, clock
        self.stream = stream
        self.started = clock()
        self.last_printed: float | None = None
        self.lines = 0

    def __call__(self, done: int, total: int) -> None:
        now = self.clock()
        final = done >= total
        if not final and self.last_printed is not None \
                and now - self.last_printed < self.interval_s:
            return
        elapsed = now - self.started
        left = elapsed / done * (total - done) if done else 0.0
        percent = 100.0 * done / total if total else 100.0
        tail = "done" if final else f"~{clock_text(left)} left"
        stream = self.stream if self.stream is not None else sys.stderr
        print(f"{self.prefix}: {self.unit} {done}/{total} ({percent:.0f} %), "
              f"{clock_text(elapsed)} elapsed, {tail}", file=stream, flush=True)
        self.last_printed = now
        self.lines += 1
