"""What an action does: the clip of an action to its box (and the count of clipped values),
the ``-v2`` unit map onto the controller's box, and each control mode's law from the
controller's action to the servo setpoints (or the motor torques).

==================  ==========================================================================
mode                law (one decision of ``dt_s``)
==================  ==========================================================================
``joint_delta``     setpoint <- clip(setpoint + action, low, high)
``joint_position``  setpoint <- clip(action, low, high)
``joint_velocity``  setpoint <- clip(setpoint + dt_s * action, low, high)
``torque``          motor torque [N·m] = torque limit * clip(action, -1, 1); setpoint unchanged
==================  ==========================================================================

``low`` and ``high`` are the setpoint bounds [rad] of the patient's workspace. Every function
takes arrays with any leading batch axes (the joints last) and returns new arrays; it runs
in the namespace of its first array (the action or the setpoints: one cheap look, as the
single CPU env calls these on every step).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rehabbot.laws.namespace import namespace_of

Array = Any
SetpointLaw = Callable[[Array, Array, Array, Array, float], Array]


def clip_to_box(action: Array, low: Array, high: Array) -> tuple[Array, Array]:
    """``(action clipped to [low, high], how many of its values the clip changed)``, counted
    over the last axis. A NaN stays NaN and counts as clipped (it is not inside the box)."""
    xp = namespace_of(action)
    clipped = xp.minimum(xp.maximum(action, low), high)
    return clipped, xp.add.reduce(clipped != action, axis=-1)


def unit_box(low: Array, high: Array) -> tuple[Array, Array]:
    """``(center, half range)`` of the unit map onto the box ``[low, high]``."""
    return (high + low) / 2, (high - low) / 2


def native_action(unit: Array, center: Array, half_range: Array) -> Array:
    """The controller's action of a unit action in ``[-1, 1]``: ``center + half_range *
    unit``, so -1 is the lower and +1 the upper bound of the controller's box."""
    return center + half_range * unit


def clip_setpoint(setpoint_rad: Array, low_rad: Array, high_rad: Array) -> Array:
    """``setpoint_rad`` kept inside the setpoint bounds ``[low_rad, high_rad]`` (a NaN stays
    NaN)."""
    xp = namespace_of(setpoint_rad)
    return xp.minimum(xp.maximum(setpoint_rad, low_rad), high_rad)


def delta_setpoint(setpoint_rad: Array, action_rad: Array, low_rad: Array, high_rad: Array,
                   dt_s: float = 0.0) -> Array:
    """``joint_delta``: the setpoints moved by ``action_rad``, clipped to the bounds."""
    del dt_s  # an increment per decision, whatever its length
    return clip_setpoint(setpoint_rad + action_rad, low_rad, high_rad)


def position_setpoint(setpoint_rad: Array, action_rad: Array, low_rad: Array,
                      high_rad: Array, dt_s: float = 0.0) -> Array:
    """``joint_position``: the action is the setpoint, clipped to the bounds."""
    del setpoint_rad, dt_s
    return clip_setpoint(action_rad, low_rad, high_rad)


def velocity_setpoint(setpoint_rad: Array, action_rad_s: Array, low_rad: Array,
                      high_rad: Array, dt_s: float = 0.0) -> Array:
    """``joint_velocity``: the setpoints moved by the speeds ``action_rad_s`` over one
    decision of ``dt_s`` (in the setpoints' precision), clipped to the bounds."""
    xp = namespace_of(setpoint_rad)
    speed = xp.astype(action_rad_s, setpoint_rad.dtype)
    return clip_setpoint(setpoint_rad + dt_s * speed, low_rad, high_rad)


def held_setpoint(setpoint_rad: Array, action: Array, low_rad: Array, high_rad: Array,
                  dt_s: float = 0.0) -> Array:
    """``torque``: the servos are off; their setpoints stay where they are."""
    del action, low_rad, high_rad, dt_s
    return setpoint_rad


def motor_torque_nm(action: Array, torque_limit_nm: Array) -> Array:
    """``torque``: the motors' torques [N·m] of a normalised action, clipped to ``[-1, 1]``
    (``torque_limit_nm`` at +1)."""
    xp = namespace_of(action)
    return torque_limit_nm * xp.minimum(xp.maximum(action, -1.0), 1.0)


# Each control mode's law from (setpoint, action, low, high, dt_s) to the next setpoint.
SETPOINT_LAWS: dict[str, SetpointLaw] = {
    "joint_delta": delta_setpoint,
    "joint_position": position_setpoint,
    "joint_velocity": velocity_setpoint,
    "torque": held_setpoint,
}
