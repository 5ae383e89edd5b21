"""Checking an action before it reaches the controller: the env's slow path, for actions that
are not float32 arrays of the right shape inside the box (those take the controller's fast
path, :meth:`rehabbot.envs.control.Controller.apply_fast`)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

FLOAT32 = np.dtype(np.float32)


def checked_action(action, space: spaces.Box, clip_low: np.ndarray, clip_high: np.ndarray,
                   clip_bounds: tuple[tuple[float, float], ...]) -> tuple[np.ndarray, int]:
    """``action`` as an array inside ``[clip_low, clip_high]`` and how many values were
    clipped. ``ValueError`` names the problem for anything that cannot be an action:
    NaN/inf (with their indices), a wrong shape, a dtype that is not a real number (bool,
    complex, str, object)."""
    if type(action) is np.ndarray and action.dtype is FLOAT32 and action.shape == space.shape:
        for value, (low, high) in zip(action.tolist(), clip_bounds, strict=True):
            if not low <= value <= high:  # also for NaN
                break
        else:
            return action, 0  # the common case: float32, inside the box
    try:
        a = np.asarray(action)
    except (TypeError, ValueError) as err:
        raise ValueError(f"action {action!r} cannot be read as {space.shape} floats: "
                         f"{err}") from None
    if a.dtype.kind not in "iuf":  # no silent casts of bool, complex, str or objects
        raise ValueError(f"action {action!r} has dtype {a.dtype}; expected {space.shape} real "
                         "numbers (float32 preferred)")
    a = a.astype(float)
    if a.shape != space.shape:
        raise ValueError(f"action has shape {a.shape}; expected {space.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"action has non-finite values at indices "
                         f"{np.flatnonzero(bad).tolist()}: {a.tolist()}")
    clipped = int(np.count_nonzero((a < clip_low) | (a > clip_high)))
    if clipped:
        a = np.clip(a, clip_low, clip_high)
    return a, clipped
