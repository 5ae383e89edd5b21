"""The features of :class:`rehabbot.rl.features.TrackingErrorFeatures` in NumPy, without
PyTorch: what an exported agent (:mod:`rehabbot.rl.zoo`) computes before its first layer.

``tracking_error_features(obs, center, half_range, fine_scale_rad)`` is, for a batch of
observations of the RehabBot layout (23 values for the UR5e, 25 for the FR3, 44 for the
bilateral env: :func:`rehabbot.tasks.observation.layout_for_size`)::

    [(obs - center) / half_range,            23: the observation scaled to [-1, 1]
     (theta* - theta) / 0.5 rad,              6: joint tracking errors (every robot joint)
     (p* - p) / 0.1 m,                        3: tool tracking errors (3 per robot)
     tanh((theta* - theta) / fine_scale_rad)] 6: only when fine_scale_rad is given

in float32 and in the same order of operations as the PyTorch module, so both give the same
numbers (``tests/test_zoo.py`` compares them). The scales are defined here, once; the PyTorch
module imports them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rehabbot.tasks.observation import tracking_slices

JOINT_ERROR_SCALE_RAD = 0.5  # errors of a few key-pose spacings map to O(1) features
TOOL_ERROR_SCALE_M = 0.1

__all__ = ["JOINT_ERROR_SCALE_RAD", "TOOL_ERROR_SCALE_M", "action_bound_units", "bounds_scaling",
           "tracking_error_features"]


def bounds_scaling(low: np.ndarray, high: np.ndarray,
                   scale_to_bounds: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(center, half_range)`` that map ``[low, high]`` onto ``[-1, 1]`` (float32); with
    ``scale_to_bounds=False``, ``(0, 1)``: the observation is left as it is."""
    low = np.asarray(low, dtype=np.float32)
    high = np.asarray(high, dtype=np.float32)
    if not scale_to_bounds:
        low, high = -np.ones_like(low), np.ones_like(high)
    return (high + low) / np.float32(2), (high - low) / np.float32(2)


def tracking_error_features(obs: np.ndarray, center: np.ndarray, half_range: np.ndarray,
                            fine_scale_rad: float | None = None) -> np.ndarray:
    """The features of a batch ``obs`` of shape ``(n, 23)`` (float32, shape ``(n, 32)``, or
    ``(n, 38)`` with ``fine_scale_rad``); see the module docstring."""
    obs = np.asarray(obs, dtype=np.float32)
    if obs.ndim != 2:
        raise ValueError(f"tracking_error_features needs a batch of shape (n, size), got "
                         f"{obs.shape}")
    theta_star, p_star, theta, p = tracking_slices(obs.shape[1])
    joint_error = (obs[:, theta_star] - obs[:, theta]) / JOINT_ERROR_SCALE_RAD
    tool_error = (obs[:, p_star] - obs[:, p]) / TOOL_ERROR_SCALE_M
    scaled = (obs - center) / half_range
    parts = [scaled, joint_error, tool_error]
    if fine_scale_rad is not None:
        parts.append(np.tanh(joint_error * (JOINT_ERROR_SCALE_RAD / fine_scale_rad)))
    return np.concatenate(parts, axis=1).astype(np.float32, copy=False)


def action_bound_units(action_space: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(center, half)`` of a bounded Box action space (float32): the action is
    ``center + half * u`` for ``u`` in ``[-1, 1]``. A ValueError names any other space."""
    low, high = getattr(action_space, "low", None), getattr(action_space, "high", None)
    if not isinstance(low, np.ndarray) or not isinstance(high, np.ndarray) or \
            not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high > low)):
        raise ValueError(f"actions in units of the bound need a bounded Box action space, "
                         f"got {action_space}")
    low, high = low.astype(np.float64), high.astype(np.float64)
    return ((high + low) / 2).astype(np.float32), ((high - low) / 2).astype(np.float32)
