"""Keeping a known message that a native library writes to the C stderr off the user's
terminal: :func:`dropping_stderr_lines` captures file descriptor 2 for a block and passes on
every line but the named ones (Python's ``warnings`` with the same text too), so nothing
else is lost."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator


@contextlib.contextmanager
def dropping_stderr_lines(*fragments: str) -> Iterator[None]:
    """Within the block, drop the stderr lines (C and Python) and the Python warnings that
    contain one of ``fragments``; write everything else to stderr after the block."""
    if not fragments or not all(fragments):
        raise ValueError(f"fragments={fragments!r}: give at least one non-empty text")
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as captured, warnings.catch_warnings():
        for fragment in fragments:
            warnings.filterwarnings("ignore", message=f".*{fragment}")
        os.dup2(captured.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            text = captured.read().decode(errors="replace")
    rest = [line for line in text.splitlines()
            if line.strip() and not any(fragment in line for fragment in fragments)]
    if rest:
        print("\n".join(rest), file=sys.stderr)
