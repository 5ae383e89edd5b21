"""rehabbot.laws.control: each control mode's known answers, over NumPy and jax.numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rehabbot.laws import control

LOW = [-1.0, -0.5, 0.0]
HIGH = [1.0, 0.5, 2.0]


def _close(actual, expected) -> None:
    np.testing.assert_allclose(np.asarray(actual), np.asarray(expected), rtol=0, atol=1e-12)


def test_clip_to_box_clips_and_counts(xp) -> None:
    action = xp.asarray([2.0, -0.25, -3.0])
    clipped, count = control.clip_to_box(action, xp.asarray(LOW), xp.asarray(HIGH))
    _close(clipped, [1.0, -0.25, 0.0])
    assert int(count) == 2
    inside, none = control.clip_to_box(xp.asarray([0.5, 0.5, 0.5]), xp.asarray(LOW),
                                       xp.asarray(HIGH))
    _close(inside, [0.5, 0.5, 0.5])
    assert int(none) == 0


def test_clip_to_box_counts_a_nan(xp) -> None:
    clipped, count = control.clip_to_box(xp.asarray([math.nan, 0.0, 0.0]), xp.asarray(LOW),
                                         xp.asarray(HIGH))
    assert int(count) == 1 and math.isnan(float(clipped[0]))


def test_unit_map_ends_and_center(xp) -> None:
    low, high = xp.asarray(LOW), xp.asarray(HIGH)
    center, half = control.unit_box(low, high)
    _close(control.native_action(xp.asarray([-1.0, -1.0, -1.0]), center, half), LOW)
    _close(control.native_action(xp.asarray([1.0, 1.0, 1.0]), center, half), HIGH)
    _close(control.native_action(xp.zeros(3), center, half), [0.0, 0.0, 1.0])


def test_joint_delta_adds_and_clips_at_the_bound(xp) -> None:
    law = control.SETPOINT_LAWS["joint_delta"]
    setpoint = xp.asarray([0.99, 0.0, 1.0])
    moved = law(setpoint, xp.asarray([0.02, 0.01, -0.5]), xp.asarray(LOW), xp.asarray(HIGH),
                0.1)
    _close(moved, [1.0, 0.01, 0.5])


def test_joint_position_is_the_action_clipped(xp) -> None:
    law = control.SETPOINT_LAWS["joint_position"]
    moved = law(xp.zeros(3), xp.asarray([-2.0, 0.25, 2.5]), xp.asarray(LOW), xp.asarray(HIGH),
                0.1)
    _close(moved, [-1.0, 0.25, 2.0])


def test_joint_velocity_moves_by_speed_times_dt(xp) -> None:
    law = control.SETPOINT_LAWS["joint_velocity"]
    setpoint = xp.asarray([0.0, 0.45, 1.0])
    moved = law(setpoint, xp.asarray([0.5, 1.0, -0.5], dtype=xp.float32), xp.asarray(LOW),
                xp.asarray(HIGH), 0.2)
    # the float32 speeds in the setpoints' precision: 0.45 + 0.2 clips at 0.5
    _close(moved, [0.1, 0.5, 0.9])
    assert moved.dtype == setpoint.dtype


def test_torque_passes_through_and_clips(xp) -> None:
    limit = xp.asarray([150.0, 150.0, 28.0])
    _close(control.motor_torque_nm(xp.asarray([0.5, -1.0, 0.25]), limit), [75.0, -150.0, 7.0])
    _close(control.motor_torque_nm(xp.asarray([1.5, -2.0, 0.0]), limit), [150.0, -150.0, 0.0])
    setpoint = xp.asarray([0.1, 0.2, 0.3])
    held = control.SETPOINT_LAWS["torque"](setpoint, xp.ones(3), xp.asarray(LOW),
                                            xp.asarray(HIGH), 0.1)
    _close(held, [0.1, 0.2, 0.3])


def test_every_control_mode_has_a_law() -> None:
    from rehabbot.envs.config import CONTROL_MODES

    assert set(control.SETPOINT_LAWS) == set(CONTROL_MODES)


def test_laws_take_leading_batch_axes(xp) -> None:
    low = xp.asarray([LOW, LOW])
    high = xp.asarray([HIGH, HIGH])
    actions = xp.asarray([[2.0, 0.0, 0.5], [0.0, 0.0, 0.0]])
    clipped, count = control.clip_to_box(actions, low, high)
    assert clipped.shape == (2, 3)
    assert np.asarray(count).tolist() == [1, 0]
    setpoints = xp.asarray([[0.0, 0.0, 0.0], [0.9, 0.4, 1.9]])
    for mode, law in control.SETPOINT_LAWS.items():
        moved = law(setpoints, actions, low, high, 0.1)
        assert moved.shape == (2, 3), mode
        for world in range(2):  # one world at a time: the same floats
            alone = law(setpoints[world], actions[world], low[world], high[world], 0.1)
            np.testing.assert_array_equal(np.asarray(moved[world]), np.asarray(alone))


def test_a_changed_bound_fails_the_known_answer(xp) -> None:
    """A law whose clip used other bounds would fail the known answers above."""
    law = control.SETPOINT_LAWS["joint_delta"]
    moved = law(xp.asarray([0.99, 0.0, 1.0]), xp.asarray([0.02, 0.01, -0.5]),
                xp.asarray([-1.0, -0.5, 0.0]), xp.asarray([1.01, 0.5, 2.0]), 0.1)
    with pytest.raises(AssertionError):
        _close(moved, [1.0, 0.01, 0.5])
