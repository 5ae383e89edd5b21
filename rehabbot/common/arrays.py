"""Small array helpers for the per-step code."""

from __future__ import annotations

import numpy as np


def as_index(indices: np.ndarray) -> slice | np.ndarray:
    """A slice equal to ``indices`` when they form an increasing arithmetic progression (reads
    are views, writes are faster), else the indices themselves."""
    idx = np.asarray(indices, dtype=int)
    if len(idx) == 1:
        return slice(int(idx[0]), int(idx[0]) + 1)
    if len(idx) > 1 and idx[1] > idx[0] and np.all(np.diff(idx) == idx[1] - idx[0]):
        return slice(int(idx[0]), int(idx[-1]) + 1, int(idx[1] - idx[0]))
    return idx
