"""The patient's joint torques: the stretch reflex of spasticity, voluntary effort, tremor and
the physiological bound of their sum (``docs/conditions.md`` has the models and their sources).

Every law here is elementwise over the compliant exercised joints: its arrays are one
world's ``(m,)``, many worlds' ``(worlds, m)``, or one joint's floats with
:mod:`rehabbot.laws.scalar` as ``xp`` (the CPU env's path). Parameters broadcast against the
state. A law's state (the reflex's delay line, the active patient's noticed goal, the
tremor's phases and random processes) is kept by the backend and passed in; the random
numbers of the tremor are drawn by the backend from its own stream and passed in as standard
normal draws.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

Array = Any  # a float, a NumPy array or a JAX array

# -- the stretch reflex ----------------------------------------------------------------------
CATCH_SHIFT_PER_RAD_S = 0.2  # mu: the catch moves this fraction of the range per rad/s
CATCH_RAMP = 0.03  # the catch builds up over this fraction of the range
RELEASE_WIDTH = 0.05  # the release decays over this fraction of the range
# -- voluntary effort ------------------------------------------------------------------------
RESIST_VELOCITY_RAD_S = 0.1  # the resistive patient reaches full push at this speed
ACTIVE_SATURATION_RAD = 0.35  # the active patient pulls with full strength beyond this error
ACTIVE_DAMPING_S = 0.3  # Kd = this x Kp
# -- tremor ----------------------------------------------------------------------------------
TREMOR_DRIFT_HZ = 0.2  # standard deviation of the tremor frequency's drift
TREMOR_MODULATION = 0.25  # amplitude modulation depth
TREMOR_CORRELATION_S = 2.0  # time constant of the drift and modulation
TWO_PI = 2.0 * math.pi


def reflex_torque_nm(xp: ModuleType, velocity_rad_s: Array, position_rad: Array,
                     low_rad: Array, high_rad: Array, gain_nms_per_rad: Array,
                     threshold_rad_s: Array, catch_at_rest: Array, release_to: Array) -> Array:
    """The stretch-reflex torque [N·m] of a joint moving at ``velocity_rad_s`` (already
    delayed by the reflex latency) at ``position_rad`` in its range ``[low_rad, high_rad]``.

    With the stretch ``s`` (the fraction of the range covered in the direction of motion),
    the speed's excess over the threshold ``e = |v| - threshold_rad_s`` and how far the
    stretch is past the catch, ``p = s - (catch_at_rest - CATCH_SHIFT_PER_RAD_S |v|)`` (the
    catch moves earlier with speed: the lambda model's lambda* = lambda - mu omega): zero
    while ``e <= 0`` or ``p <= 0``, else
    ``gain e min(p / CATCH_RAMP, 1) (r + (1 - r) exp(-max(p - CATCH_RAMP, 0) / RELEASE_WIDTH))``
    opposing the motion (``r = release_to``: the share left after the catch releases).
    ``gain_nms_per_rad`` is the joint's reference gain times the MAS grade's scale. On one
    joint's Python floats the law returns 0.0 as soon as a condition of zero holds; arrays
    take the ``where`` at its end.
    """
    speed = xp.abs(velocity_rad_s)
    excess = speed - threshold_rad_s
    if (excess <= 0.0) is True:  # one joint's float (the scalar namespace): known to be 0
        return 0.0
    lengthening = velocity_rad_s > 0
    stretch = xp.where(lengthening, position_rad - low_rad, high_rad - position_rad) \
        / (high_rad - low_rad)
    past = stretch - (catch_at_rest - CATCH_SHIFT_PER_RAD_S * speed)
    if (past <= 0.0) is True:
        return 0.0
    build_up = xp.minimum(past / CATCH_RAMP, 1.0)
    release = release_to + (1.0 - release_to) * xp.exp(
        -xp.maximum(past - CATCH_RAMP, 0.0) / RELEASE_WIDTH)
    magnitude = gain_nms_per_rad * excess * build_up * release
    return xp.where((excess <= 0.0) | (past <= 0.0), 0.0,
                    xp.where(lengthening, -magnitude, magnitude))


def active_gain_nm_per_rad(xp: ModuleType, available_pos_nm: Array,
                           available_neg_nm: Array) -> Array:
    """The active patient's PD gain Kp: full strength (the larger way) at an error of
    ``ACTIVE_SATURATION_RAD``."""
    return xp.maximum(available_pos_nm, available_neg_nm) / ACTIVE_SATURATION_RAD


def active_pull_nm(xp: ModuleType, position_rad: Array, velocity_rad_s: Array, goal_rad: Array,
                   bias_nm: Array, kp_nm_per_rad: Array, available_pos_nm: Array,
                   available_neg_nm: Array) -> Array:
    """The active-assisted patient's torque: it carries the limb's own weight (``bias_nm``,
    MuJoCo's ``qfrc_bias``) and pulls towards the goal it noticed,
    ``bias + Kp (goal - q) - ACTIVE_DAMPING_S Kp v``, bounded by the strength it uses each
    way, ``[-available_neg_nm, available_pos_nm]``."""
    kp = kp_nm_per_rad
    pull = bias_nm + kp * (goal_rad - position_rad) - ACTIVE_DAMPING_S * kp * velocity_rad_s
    return xp.minimum(xp.maximum(pull, -available_neg_nm), available_pos_nm)


def resistive_push_nm(xp: ModuleType, velocity_rad_s: Array, available_pos_nm: Array,
                      available_neg_nm: Array) -> Array:
    """The resistive patient's torque against the motion, ``-tanh(v / RESIST_VELOCITY_RAD_S)``
    times the strength it uses in the opposing way."""
    direction = xp.tanh(velocity_rad_s / RESIST_VELOCITY_RAD_S)
    return -direction * xp.where(direction > 0, available_neg_nm, available_pos_nm)


# -- tremor ----------------------------------------------------------------------------------
def tremor_start(xp: ModuleType, z_drift: Array, z_modulation: Array) -> tuple[Array, Array]:
    """The tremor's frequency drift [Hz] and amplitude modulation at the start of an episode
    from two standard normal draws: ``TREMOR_DRIFT_HZ z``, and ``z`` clipped to +-1."""
    return TREMOR_DRIFT_HZ * z_drift, xp.minimum(xp.maximum(z_modulation, -1.0), 1.0)


def tremor_decay(control_dt_s: float) -> tuple[float, float]:
    """The exact Ornstein-Uhlenbeck step over ``control_dt_s``: the decay ``exp(-dt / tau)``
    and the noise gain ``sqrt(1 - decay^2)`` (``tau = TREMOR_CORRELATION_S``)."""
    decay = math.exp(-control_dt_s / TREMOR_CORRELATION_S)
    return decay, math.sqrt(1.0 - decay * decay)


def tremor_processes(xp: ModuleType, drift_hz: Array, modulation: Array, z_drift: Array,
                     z_modulation: Array, decay: float, noise: float) -> tuple[Array, Array]:
    """One control step of the drift (standard deviation ``TREMOR_DRIFT_HZ``) and of the
    modulation (clipped to +-1), from two standard normal draws (:func:`tremor_decay` gives
    ``decay`` and ``noise``)."""
    drift = decay * drift_hz + noise * TREMOR_DRIFT_HZ * z_drift
    return drift, xp.minimum(xp.maximum(decay * modulation + noise * z_modulation, -1.0), 1.0)


def tremor_torque_nm(xp: ModuleType, amplitude_nm: Array, modulation: Array,
                     frequency_hz: Array, drift_hz: Array, phase_rad: Array, dt_s: float,
                     wrap: bool = False) -> tuple[Array, Array]:
    """A joint's tremor torque in a physics step of ``dt_s`` and its phase for the next step:
    ``A (1 + TREMOR_MODULATION m) sin(phase)``, the phase advancing by ``2 pi (f + df) dt``
    (``f = frequency_hz``, ``df = drift_hz``, ``m = modulation``); ``wrap``: the next phase
    brought back to ``[0, 2 pi)`` (the same sine, kept small for single precision)."""
    amplitude = amplitude_nm * (1.0 + TREMOR_MODULATION * modulation)
    phase = phase_rad + TWO_PI * (frequency_hz + drift_hz) * dt_s
    return amplitude * xp.sin(phase_rad), xp.mod(phase, TWO_PI) if wrap else phase


# -- their sum -------------------------------------------------------------------------------
def saturate_nm(xp: ModuleType, torque_nm: Array, peak_pos_nm: Array,
                peak_neg_nm: Array) -> Array:
    """The patient's torque on a joint: ``torque_nm``, the sum of the reflex, voluntary and
    tremor torques, bounded by the joint's healthy peak torque each way,
    ``[-peak_neg_nm, peak_pos_nm]`` (a reflex-driven muscle pulls no harder than a maximal
    voluntary contraction)."""
    return xp.minimum(xp.maximum(torque_nm, -peak_neg_nm), peak_pos_nm)
