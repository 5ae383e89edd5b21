"""When the safety rules stop an episode: each rule's test on the step's readings, and the
decision between them, in :data:`RULES` order (the first rule that fires is the one
reported).

=========================  ====================================================================
rule (code)                fires when
=========================  ====================================================================
``"instability"`` (1)      the simulation diverged (:func:`blown_up`: a joint faster than
                           ``BLOWUP_SPEED_RAD_S`` or a cuff force beyond ``BLOWUP_FORCE_N``,
                           or either non-finite; the backend adds what it sees itself:
                           MuJoCo's warnings, a non-finite state, an observation outside its
                           box, :func:`outside_box`)
``"range_of_motion"`` (2)  a patient joint is beyond its range widened by the tolerance
                           (:func:`beyond_range`)
``"cuff_force"`` (3)       a cuff's force exceeds its limit (:func:`over_force_limit`)
``"unintended_contact"``   a robot geom touches the patient, the furniture or another robot
(4)                        deeper than the tolerance (:func:`unintended_contact`)
=========================  ====================================================================

:data:`NO_STOP` (0) is the code of a step no rule stops. Every test returns one flag per
world. A reading of a few entries (a force's components, the patient's joints, the cuffs) is
passed as the sequence of its entries, each a float (one world: the CPU env's Python floats,
at the cost of Python's own arithmetic) or an array of any batch shape (the batched env's
columns); a reading of many entries (joint speeds, contacts) as an array whose last axis
holds them.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType
from typing import Any

from rehabbot.laws.namespace import namespace_of

Array = Any

RULES = ("instability", "range_of_motion", "cuff_force", "unintended_contact")
NO_STOP = 0
# Each rule's code: 1 + its place in RULES (0: none fires).
RULE_CODES: dict[str, int] = {rule: k + 1 for k, rule in enumerate(RULES)}
# The rule of each code (None for NO_STOP).
RULE_NAMES: tuple[str | None, ...] = (None, *RULES)

# Speeds and forces no motion of these scenes reaches: random torques at the UR5e limits with
# the safety rules switched off peak at about 64 rad/s and 6.4 kN (benchmarks/performance/soak.py).
BLOWUP_SPEED_RAD_S = 1000.0
BLOWUP_FORCE_N = 1.0e5


def force_magnitude_n(force_xyz_n: Sequence[Array], xp: ModuleType) -> Array:
    """The magnitude [N] of a force given by its x, y, z components (each a float, or an
    array of any batch shape)."""
    fx, fy, fz = force_xyz_n
    return xp.sqrt(fx * fx + fy * fy + fz * fz)


def fastest_speed_rad_s(speeds_rad_s: Array) -> Array:
    """The largest joint speed magnitude over the last axis (NaN if any speed is NaN)."""
    xp = namespace_of(speeds_rad_s)
    return xp.maximum.reduce(xp.abs(speeds_rad_s), axis=-1)


def blown_up(fastest_rad_s: Array, force_n: Array, xp: ModuleType,
             speed_limit_rad_s: float = BLOWUP_SPEED_RAD_S,
             force_limit_n: float = BLOWUP_FORCE_N) -> Array:
    """Whether the fastest joint's speed (:func:`fastest_speed_rad_s`) or the largest cuff
    force ``force_n`` is non-finite or beyond its blow-up bound: a constraint or integration
    blow-up."""
    return xp.logical_not(xp.logical_and(fastest_rad_s <= speed_limit_rad_s,
                                         force_n <= force_limit_n))


def outside_box(values: Array, low: Array, high: Array) -> Array:
    """Whether a value (last axis) is outside ``[low, high]`` or NaN."""
    xp = namespace_of(values)
    return xp.logical_not(xp.logical_and.reduce((values >= low) & (values <= high), axis=-1))


def beyond_range(q_rad: Sequence[Array], low_rad: Sequence[Array],
                 high_rad: Sequence[Array]) -> Array:
    """Whether a joint angle is below ``low_rad`` or above ``high_rad`` (the joints' ranges
    widened by the tolerance); one entry per joint, each a float or an array of any batch
    shape (a NaN angle is not beyond)."""
    fired: Array = False
    for q, low, high in zip(q_rad, low_rad, high_rad, strict=True):
        fired = fired | (q < low) | (q > high)
    return fired


def over_force_limit(forces_n: Sequence[Array], limits_n: Sequence[Array]) -> Array:
    """Whether a cuff's force exceeds its limit; one entry per cuff, each a float or an
    array of any batch shape (a NaN force does not exceed it)."""
    fired: Array = False
    for force, limit in zip(forces_n, limits_n, strict=True):
        fired = fired | (force > limit)
    return fired


def unintended_contact(is_robot: Array, is_other: Array, dist_m: Array, tolerance_m: float,
                       owner: Array | None = None, counted: Array | None = None) -> Array:
    """Whether a contact (second-to-last axis of the geom pairs ``(..., contacts, 2)``, last
    of ``dist_m``) is deeper than ``tolerance_m`` (``dist_m < -tolerance_m``) between a robot
    geom (``is_robot``) and a patient's or furniture geom (``is_other``); with ``owner`` (the
    robot of each geom, -1 for none) also between two robots' geoms. ``counted`` marks the
    contacts that exist (all, when None)."""
    xp = namespace_of(dist_m)
    hit = (is_robot[..., 0] & is_other[..., 1]) | (is_robot[..., 1] & is_other[..., 0])
    if owner is not None:
        hit = hit | ((owner[..., 0] >= 0) & (owner[..., 1] >= 0)
                     & (owner[..., 0] != owner[..., 1]))
    hit = hit & (dist_m < -tolerance_m)
    if counted is not None:
        hit = hit & counted
    return xp.logical_or.reduce(hit, axis=-1)


def first_rule(instability: Array, range_of_motion: Array, cuff_force: Array,
               unintended_contact: Array) -> Array:
    """The code of the first rule that fires, in :data:`RULES` order, or :data:`NO_STOP`:
    one code per world of the flags (bools, or bool arrays of one shape)."""
    fired = (instability, range_of_motion, cuff_force, unintended_contact)
    code = NO_STOP
    for k in range(len(RULES) - 1, -1, -1):  # the last rule first: an earlier one overrides
        code = code + fired[k] * (k + 1 - code)
    return code


def rule_name(code: Array) -> str | None:
    """The rule of a code (None for :data:`NO_STOP`)."""
    return RULE_NAMES[int(code)]
