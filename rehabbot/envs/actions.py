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


class UnitActions:
    """Actions in ``Box(-1, 1)`` (the ``-v2`` ids, ``action_scale="unit"``), mapped linearly
    onto the controller's box ``[clip_low, clip_high]``: -1 is the lower and +1 the upper
    bound of each joint's action (``-pi/400 .. pi/400`` rad in ``joint_delta`` mode; the
    patient's setpoint bounds in ``joint_position`` mode). The checks and the clipping count of
    :func:`checked_action` apply to the unit action."""

    def __init__(self, clip_low: np.ndarray, clip_high: np.ndarray) -> None:
        low = np.asarray(clip_low, dtype=np.float64)
        high = np.asarray(clip_high, dtype=np.float64)
        if low.shape != high.shape or not np.all(high > low):
            raise ValueError(f"a unit action needs a bounded box, got {low} .. {high}")
        self.space = spaces.Box(-1.0, 1.0, low.shape, np.float32)
        self._center, self._half = (high + low) / 2, (high - low) / 2
        self._ones = np.ones(low.shape)
        self._bounds = ((-1.0, 1.0),) * low.size

    def native(self, action) -> tuple[np.ndarray, int]:
        """``(the controller's action (float32, inside its box), how many values were
        clipped to [-1, 1])``; ``ValueError`` as :func:`checked_action`."""
        unit, clipped = checked_action(action, self.space, -self._ones, self._ones,
                                       self._bounds)
        # +-1 maps onto the bounds up to float64 rounding, far below float32's step: the cast
        # lands on the float32 bounds (the controller's check would clip and count anything
        # outside them).
        return (self._center + self._half * unit).astype(np.float32), clipped
