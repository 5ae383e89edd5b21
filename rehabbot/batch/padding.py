"""Ragged per-exercise tables made rectangular for the batched env.

Exercises (and patients) have different numbers of targets; a world indexes its exercise's
row with its own target counter, so every row is padded to the longest: targets with their
last target (a world past its last target keeps aiming at it), the rests and segments after
them with zeros (nothing is left to travel).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

LAST = "last"


def pad_to(rows: np.ndarray, count: int, fill: str | float = LAST) -> np.ndarray:
    """``rows`` (``(k, ...)``, ``k <= count``) padded to ``count`` rows: repeating its last
    row (``fill="last"``) or with the constant ``fill``."""
    rows = np.asarray(rows, dtype=float)
    missing = count - rows.shape[0]
    if missing < 0:
        raise ValueError(f"{rows.shape[0]} rows do not fit in {count}")
    if missing == 0:
        return rows
    if fill == LAST:
        if rows.shape[0] == 0:
            raise ValueError("an empty table has no last row to pad with")
        pad = np.repeat(rows[-1:], missing, axis=0)
    else:
        pad = np.full((missing, *rows.shape[1:]), float(fill))
    return np.concatenate([rows, pad])


def stack_padded(tables: Sequence[np.ndarray], count: int | None = None,
                 fill: str | float = LAST) -> np.ndarray:
    """``(len(tables), count, ...)``: each table padded to ``count`` rows (default: the
    longest table's) by :func:`pad_to`."""
    if count is None:
        count = max(len(t) for t in tables)
    return np.stack([pad_to(t, count, fill) for t in tables])
