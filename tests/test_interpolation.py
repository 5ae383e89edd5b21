"""The policy-rate to servo-rate interpolation and the servo supervisor
(rehabbot.deploy.interpolation), on synthetic targets with known answers."""

from __future__ import annotations

import re

import numpy as np
import pytest

from rehabbot.common.errors import UsageError
from rehabbot.deploy.interpolation import (
    MAX_PENDING,
    QUINTIC_PEAK,
    ServoSupervisor,
    SetpointInterpolator,
    brake_duration_s,
    interpolate_targets,
    quintic_coefficients,
    quintic_eval,
)

T, DT, D = 0.02, 0.001, 0.01  # policy period, servo period, default delay (half a period)
M = round(T / DT)
EXACT = 1e-9  # far above rounding (1e-16), far below any real change (>= 1e-6 here)


def times(rows: int) -> np.ndarray:
    """Row i of interpolate_targets is (i + 1) servo periods after the first target."""
    return (np.arange(rows) + 1) * DT


def test_quintic_meets_both_ends() -> None:
    p0, v0, a0 = np.array([0.1, -2.0]), np.array([0.5, 0.0]), np.array([-3.0, 1.0])
    p1, v1, a1 = np.array([0.2, -1.5]), np.array([0.0, 2.0]), np.array([0.0, -4.0])
    c = quintic_coefficients(p0, v0, a0, p1, v1, a1, 0.04)
    for t, want in ((0.0, (p0, v0, a0)), (0.04, (p1, v1, a1))):
        for got, expected in zip(quintic_eval(c, t), want, strict=True):
            np.testing.assert_allclose(got, expected, rtol=0, atol=EXACT)
    with pytest.raises(UsageError, match=re.escape("-0.1")):
        quintic_coefficients(p0, v0, a0, p1, v1, a1, -0.1)


@pytest.mark.parametrize("shape", ["ramp", "parabola"])
def test_targets_on_a_parabola_are_followed_exactly_one_period_and_the_delay_late(
        shape: str) -> None:
    rate, accel = np.array([0.5, -0.25, 0.0]), np.array([2.0, -1.0, 0.5])

    def path(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t)[..., None]
        return rate * t + (accel * t**2 / 2.0 if shape == "parabola" else 0.0)

    targets = path((np.arange(20) + 1) * T)  # target k, given at k T, is the path at (k + 1) T
    setpoints = interpolate_targets(np.zeros(3), targets, T, DT)
    t = times(len(setpoints))
    steady = t >= 2 * T + D  # from the knot of the first three targets on one parabola
    np.testing.assert_allclose(setpoints[steady], path(t[steady] - D), rtol=0, atol=EXACT)
    # every target is reached exactly on its beat: (k + 1) T + D after the first target
    rows = (np.arange(len(targets)) + 1) * M + round(D / DT) - 1
    rows = rows[rows < len(setpoints)]
    np.testing.assert_allclose(setpoints[rows], targets[: len(rows)], rtol=0, atol=EXACT)


def test_constant_targets_hold_still() -> None:
    q0 = np.array([0.3, -1.2])
    setpoints = interpolate_targets(q0, np.tile(q0, (10, 1)), T, DT)
    assert np.array_equal(setpoints, np.tile(q0, (len(setpoints), 1)))


@pytest.mark.slow
def test_velocity_and_acceleration_are_continuous_across_every_knot() -> None:
    rng = np.random.default_rng(7)
    amplitude, frequency = rng.uniform(0.1, 0.4, 4), rng.uniform(0.2, 0.6, 4)
    fine = 1e-5  # servo period much shorter than a segment: jumps cannot hide
    interpolator = SetpointInterpolator(np.zeros(4), T)
    accelerations, velocities = [], []
    for k in range(40):
        interpolator.push(amplitude * (1 - np.cos(2 * np.pi * frequency * (k + 1) * T)))
        for _ in range(round(T / fine)):
            interpolator.step(fine)
            velocities.append(interpolator.v)
            accelerations.append(interpolator.a)
    dv = np.abs(np.diff(velocities, axis=0)).max()
    da = np.abs(np.diff(accelerations, axis=0)).max()
    # continuous: per 1e-5 s the velocity moves by < 1e-3 rad/s and the acceleration by
    # < 0.1 rad/s^2; a jump at a knot would be the size of the velocity (0.1-1 rad/s) or the
    # acceleration (~1 rad/s^2) themselves
    assert dv < 1e-3 and da < 0.1
    assert np.abs(velocities).max() > 0.2 and np.abs(accelerations).max() > 0.5


def test_a_late_target_on_a_ramp_costs_nothing() -> None:
    q0, rate = np.zeros(2), np.array([0.5, -0.25])
    targets = [rate * (k + 1) * T for k in range(12)]
    on_time = interpolate_targets(q0, np.array(targets), T, DT)
    interpolator, late = SetpointInterpolator(q0, T, rate_gain=0.0), []
    for k, target in enumerate(targets):
        if k != 6:
            interpolator.push(target)
        for i in range(M):
            if k == 6 and i == 15:  # 15 ms late: after the delay's 10 ms, inside the coast
                interpolator.push(target)
            late.append(interpolator.step(DT))
    np.testing.assert_allclose(np.array(late), on_time, rtol=0, atol=EXACT)


def test_the_beat_follows_a_slower_caller() -> None:
    """Targets of a ramp every 21 ms: the playback rate settles near 20/21 and the setpoint
    never brakes (its acceleration stays that of rate changes, far below a brake's)."""
    rate = np.array([0.3])
    interpolator = SetpointInterpolator(np.zeros(1), T)
    accelerations = []
    for k in range(150):
        interpolator.push(rate * (k + 1) * T)
        for _ in range(21):
            interpolator.step(DT)
            accelerations.append(interpolator.a[0])
            assert not interpolator.braking
    assert abs(interpolator.rate - 20 / 21) < 0.01
    assert np.abs(accelerations[200:]).max() < 0.5


def test_a_caller_running_ahead_drops_the_oldest_target_but_keeps_its_period() -> None:
    interpolator = SetpointInterpolator(np.zeros(1), T, rate_gain=0.0)
    rate = 0.2
    for k in range(MAX_PENDING + 3):  # all at once
        interpolator.push(np.array([rate * (k + 1) * T]))
    assert interpolator.dropped == 2
    positions = [interpolator.step(DT)[0] for _ in range(M * (MAX_PENDING + 3) + round(D / DT))]
    # the last target is still reached on its beat: the dropped periods were kept
    assert abs(positions[-1] - rate * (MAX_PENDING + 3) * T) < EXACT


def test_brake_stops_a_constant_velocity_halfway_and_within_the_deceleration() -> None:
    v = np.array([0.4, -0.2])
    duration = brake_duration_s(v, T, 5.0)
    assert duration >= QUINTIC_PEAK * 0.4 / 5.0
    assert brake_duration_s(np.zeros(2), T, 5.0) == T
    interpolator = SetpointInterpolator(np.zeros(2), T)
    interpolator.v = v.copy()  # a setpoint moving steadily
    interpolator.brake()
    accelerations = []
    for _ in range(round(duration / DT) + 5):
        interpolator.step(DT)
        accelerations.append(interpolator.a)
    np.testing.assert_allclose(interpolator.p, v * duration / 2, rtol=0, atol=EXACT)
    assert interpolator.at_rest
    assert np.abs(accelerations).max() <= 5.0


def test_supervisor_watchdog_brakes_and_finishes_then_refuses() -> None:
    supervisor = ServoSupervisor(np.zeros(2), T, 0.1, [2.0, 2.0], 9.0)
    for _ in range(200):  # before the first target the watchdog does not run
        supervisor.tick(DT)
    assert not supervisor.stopping
    supervisor.command(np.array([0.001, 0.0]))
    ticks = 0
    while not supervisor.stopping:
        supervisor.tick(DT)
        ticks += 1
    # 0.1 s after the target, give or take the rounding of the summed tick times
    assert ticks in (100, 101) and supervisor.stop_reason.startswith("watchdog")
    finished = False
    for _ in range(1000):
        _setpoint, finished = supervisor.tick(DT)
        if finished:
            break
    assert finished
    with pytest.raises(UsageError, match="watchdog"):
        supervisor.command(np.zeros(2))


def test_supervisor_speed_cap_refuses_a_jump_and_sends_nothing_beyond_it() -> None:
    speed_cap, accel_cap = 1.0, 9.0
    supervisor = ServoSupervisor(np.zeros(1), T, 0.1, [speed_cap], accel_cap)
    sent, finished, k = [np.zeros(1)], False, 0
    while not finished:
        if k < 10 and not supervisor.stopping:  # a slow ramp, then one target jumps ahead
            supervisor.command(np.array([0.02 * (k + 1) * T + (3.0 if k == 9 else 0.0)]))
        for _ in range(M):
            setpoint, finished = supervisor.tick(DT)
            sent.append(setpoint)
            if finished:
                break
        k += 1
    assert "speed cap" in supervisor.stop_reason and k > 10
    speeds = np.abs(np.diff(np.array(sent)[:, 0])) / DT
    assert speeds.max() <= speed_cap


def test_supervisor_rate_limits_targets_that_would_accelerate_beyond_the_cap() -> None:
    """Targets that jump back and forth each period (a policy's delta actions) ask the
    interpolation for far more than the cap: the setpoints sent stay within it, nothing stops,
    and once the targets are smooth again the setpoints follow the interpolation exactly."""
    accel_cap = 9.0
    supervisor = ServoSupervisor(np.zeros(1), T, 0.1, [2.0], accel_cap)
    free = SetpointInterpolator(np.zeros(1), T)
    sent, free_sent = [np.zeros(1)], [np.zeros(1)]
    for k in range(60):
        target = np.array([0.005 * (-1) ** k]) if k < 10 else np.array([0.0])
        supervisor.command(target)
        free.push(target)
        for _ in range(M):
            sent.append(supervisor.tick(DT)[0])
            free_sent.append(free.step(DT))
    assert not supervisor.stopping and supervisor.limited_ticks > 0
    free_accel = np.abs(np.diff(np.array(free_sent)[:, 0], 2)).max() / DT**2
    assert free_accel > 3 * accel_cap  # what the cap saves the robot from
    accelerations = np.abs(np.diff(np.array(sent)[:, 0], 2)) / DT**2
    assert accelerations.max() <= accel_cap * (1 + 1e-9)
    np.testing.assert_array_equal(sent[-M:], free_sent[-M:])  # in sync again, exactly


def test_fr3_speed_envelope_narrows_to_zero_at_a_position_limit() -> None:
    """Far from its limits a joint may use its rated speed both ways; towards a limit only
    sqrt(2 * deceleration * distance) - offset; at the limit nothing towards it."""
    from rehabbot.sim.robots import fr3

    middle = (fr3.JOINT_LOW_RAD + fr3.JOINT_HIGH_RAD) / 2
    low, high = fr3.speed_envelope_rad_s(middle)
    np.testing.assert_array_equal(high, fr3.MAX_JOINT_SPEED_RAD_S)
    np.testing.assert_array_equal(low, -fr3.MAX_JOINT_SPEED_RAD_S)
    near = fr3.JOINT_HIGH_RAD - 0.1
    low, high = fr3.speed_envelope_rad_s(near)
    expected = np.sqrt(2 * fr3.SPEED_LIMIT_DECELERATION_RAD_S2 * 0.1) - fr3.SPEED_LIMIT_OFFSET_RAD_S
    np.testing.assert_allclose(high, expected, rtol=1e-12)
    np.testing.assert_array_equal(low, -fr3.MAX_JOINT_SPEED_RAD_S)  # away from it: rated
    assert np.all(fr3.speed_envelope_rad_s(fr3.JOINT_HIGH_RAD)[1] == 0.0)
    assert np.all(fr3.speed_envelope_rad_s(fr3.JOINT_LOW_RAD - 0.01)[0] == 0.0)


def test_supervisor_rate_limits_to_a_position_based_speed_envelope() -> None:
    """A ramp at 1 rad/s towards a limit at 0.3 rad, on a robot that allows only
    sqrt(2 * 2 * distance) there: the setpoints slow down inside the envelope instead of
    running at the 2 rad/s cap into it, and nothing stops; without the envelope the same
    targets run at 1 rad/s up to the limit."""
    limit_rad, deceleration = 0.3, 2.0

    def envelope(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (np.full_like(q, -2.0),
                np.clip(np.sqrt(2 * deceleration * np.maximum(limit_rad - q, 0.0)), 0.0, 2.0))

    def run(speed_envelope) -> np.ndarray:
        supervisor = ServoSupervisor(np.zeros(1), T, 0.1, [2.0], 9.0,
                                     speed_envelope=speed_envelope)
        sent = [np.zeros(1)]
        for k in range(60):
            supervisor.command(np.array([min(1.0 * (k + 1) * T, 0.29)]))
            for _ in range(M):
                sent.append(supervisor.tick(DT)[0])
        assert not supervisor.stopping
        return np.array(sent)[:, 0]

    limited, free = run(envelope), run(None)
    speeds = np.diff(limited) / DT
    allowed = np.sqrt(2 * deceleration * np.maximum(limit_rad - limited[:-1], 0.0))
    assert np.all(speeds <= allowed - 0.05 + 1e-9)
    free_speeds = np.diff(free) / DT
    free_allowed = np.sqrt(2 * deceleration * np.maximum(limit_rad - free[:-1], 0.0))
    assert np.any(free_speeds > free_allowed)  # what the envelope saves the robot from
    assert abs(limited[-1] - 0.29) < 1e-3  # and it still arrives


def test_a_far_first_target_gets_a_longer_segment_within_the_cap() -> None:
    supervisor = ServoSupervisor(np.zeros(1), T, 1.0, [1.0], 9.0)
    supervisor.command(np.array([0.05]))  # 0.05 rad in 30 ms would need ~330 rad/s^2
    sent = [supervisor.tick(DT)[0] for _ in range(600)]
    assert not supervisor.stopping and supervisor.interpolator.at_rest
    # it passes the target (the velocity there is the targets' slope, slowed by the
    # lengthening) and brakes beyond it, never above the cap
    assert max(p[0] for p in sent) >= 0.05
    accelerations = np.diff(np.array(sent)[:, 0], 2) / DT**2
    assert np.abs(accelerations).max() <= 9.0


def test_stop_request_and_bad_input() -> None:
    supervisor = ServoSupervisor(np.zeros(2), T, 0.1, 2.0, 9.0)
    supervisor.request_stop("stop()")
    supervisor.request_stop("later")
    assert supervisor.stop_reason == "stop()"
    with pytest.raises(UsageError, match=re.escape("stop()")):
        supervisor.command(np.zeros(2))
    with pytest.raises(UsageError, match=re.escape("0.01")):
        ServoSupervisor(np.zeros(2), T, 0.01, 2.0, 9.0)
    with pytest.raises(UsageError, match=re.escape("-1.0")):
        ServoSupervisor(np.zeros(2), T, 0.1, [2.0, -1.0], 9.0)
    with pytest.raises(UsageError, match=re.escape("0.0015")):
        interpolate_targets(np.zeros(1), np.zeros((2, 1)), T, 0.0015)
    with pytest.raises(UsageError, match="nan"):
        SetpointInterpolator([0.0, float("nan")], T)
