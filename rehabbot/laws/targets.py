"""When a target counts as reached, when the next one becomes active, and the path left
through a target sequence.

An exercise is a sequence of ``N`` targets ``theta*_0 .. theta*_(N-1)`` in robot joint space,
one active at a time. A step reaches the active target when every robot joint (of every arm)
is within the target tolerance of it, ``||theta - theta*_i||_inf < epsilon``, and no safety
rule stopped the episode in that step. Reaching a target before the last makes the next one
active for the following steps; reaching the last ends the episode as a success. The
functions run in the namespace ``xp`` of their inputs (or the one passed), with any leading
batch axes.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any, NamedTuple

from rehabbot.laws.namespace import namespace_of

Array = Any  # an array of the namespace, or a Python number

TARGET_TOLERANCE_RAD = 0.05  # epsilon: the largest joint error at a reached target


class TargetSwitch(NamedTuple):
    """What a step did to the target sequence."""

    reached: Array  # the active target was reached (and the step did not stop)
    last: Array  # the active target is the sequence's last
    index: Array  # the target active after the step
    success: Array  # the last target was reached: the episode ends as a success


def largest_error_rad(theta_rad: Array, target_rad: Array, *,
                      xp: ModuleType | None = None) -> Array:
    """``||theta - theta*||_inf``: the largest joint error, over the last axis."""
    xp = namespace_of(theta_rad, target_rad) if xp is None else xp
    return xp.max(xp.abs(theta_rad - target_rad), axis=-1)


def switch_target(largest_error: Array, index: Array, count: Array, stop: Array,
                  tolerance_rad: float = TARGET_TOLERANCE_RAD, *,
                  xp: ModuleType | None = None) -> TargetSwitch:
    """The target switch of a step (module docstring): ``largest_error`` is the step's
    ``||theta - theta*_index||_inf`` [rad], ``count`` the sequence's length and ``stop``
    whether a safety rule stopped the episode in the step."""
    xp = namespace_of(largest_error, index) if xp is None else xp
    last = index == count - 1
    reached = (largest_error < tolerance_rad) & xp.logical_not(stop)
    return TargetSwitch(reached, last, xp.where(reached & (index != count - 1), index + 1,
                                                index), reached & last)


def remaining_path_rad(targets_rad: Array, *, xp: ModuleType | None = None) -> Array:
    """``rest[i]``: the joint-space length from target ``i`` through every later target
    (``rest[-1] = 0``); ``targets_rad`` is ``(..., N, n_joints)``."""
    xp = namespace_of(targets_rad) if xp is None else xp
    steps = xp.linalg.norm(xp.diff(targets_rad, axis=-2), axis=-1)
    after = xp.flip(xp.cumsum(xp.flip(steps, axis=-1), axis=-1), axis=-1)
    return xp.concatenate([after, xp.zeros((*after.shape[:-1], 1), after.dtype)], axis=-1)


def joint_distance_rad(theta_rad: Array, target_rad: Array, *,
                       xp: ModuleType | None = None) -> Array:
    """``||theta - theta*||_2``: the joint-space distance, over the last axis."""
    xp = namespace_of(theta_rad, target_rad) if xp is None else xp
    error = theta_rad - target_rad
    return xp.sqrt(xp.sum(error * error, axis=-1))
