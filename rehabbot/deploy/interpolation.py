"""Joint targets at the policy's rate made into servo setpoints at the robot's rate.

A policy decides every ``policy_dt_s`` (0.02 s); a Franka's control loop wants a setpoint every
1 ms and a UR's ``servoJ`` every 2 ms, and both reject a setpoint stream whose velocity or
acceleration jumps. The rule, shared by every hardware backend:

* **One quintic segment per target, on a beat.** Each target ``q_k`` is a knot: the setpoint
  runs along a fifth-degree polynomial from the previous knot (its position, velocity and
  acceleration) to ``q_k`` in one policy period, and the next segment starts where that one
  ends, so position, velocity and acceleration are continuous. A target that arrives while a
  segment runs waits for it to end (at most ``MAX_PENDING`` wait; one more drops the oldest,
  whose period the next segment takes over: the caller ran ahead of the robot's clock). The
  first target after rest gets its segment lengthened by ``delay_s`` (half a period by
  default), so that later targets may come up to ``delay_s`` late without breaking the beat.
  Target ``k`` is therefore reached ``policy_dt_s + delay_s`` plus ``k`` periods after the
  first target came: the interpolation's lag.
* **The velocity and acceleration at a knot are those of the parabola through the last three
  targets**, at the newest: with the slopes ``s_k = (q_k - q_{k-1}) / policy_dt_s`` and
  ``s_{k-1}``, ``v_k = (3 s_k - s_{k-1}) / 2`` and ``a_k = (s_k - s_{k-1}) / policy_dt_s``
  (the first two targets count the start position twice before them). Targets on one
  parabola (a ramp, a constant acceleration) are therefore followed exactly once three of them
  lie on it, and smooth targets give setpoint accelerations close to the targets' own.
  Targets that jump are not smoothed away: a step overshoots, and the acceleration it demands
  is what the supervisor's cap refuses (below); the deployment safety filter upstream keeps
  the targets' changes small.
* **The beat follows the caller's clock.** The caller's period is never exactly the robot's:
  targets that keep coming late (or early) would exhaust the delay (or fill the queue). Each
  segment runs at a playback rate ``r`` (duration ``policy_dt_s / r``, the knot's velocity
  times ``r`` and acceleration times ``r^2``: the same path, in time scaled by ``1 / r``),
  nudged at each segment start toward keeping ``delay_s`` of slack (how long the target
  waited for its segment): ``r`` moves by at most ``RATE_STEP`` a segment and stays within
  ``1 +- RATE_RANGE``. Targets exactly one period apart keep ``r = 1``.
* **A late target: coast.** When a segment ends with a non-zero velocity or acceleration and
  no target waits, the setpoint coasts on along the parabola of its end state for one period.
  A target that comes meanwhile starts its segment from there, to end on the beat (in what is
  left of the period: the coast ran along the targets' path, so the target lies about where
  the coast will be then): a target late by less than half a period on a smooth stream costs
  nothing. Later than that, so short a segment would turn any small mismatch into large
  accelerations: the segment aims instead at the beat after, at the target's own parabola one
  period on, and counts as a coast again (the next target re-aims it).
* **No target: brake.** No target by the end of a coast: the setpoint brakes along a quintic
  from its state to rest in :func:`brake_duration_s` (at least one policy period, and long
  enough that no joint decelerates by more than ``deceleration_rad_s2``, 5 rad/s^2 by
  default); a constant velocity ``v`` stops ``v T / 2`` further on.
  :meth:`SetpointInterpolator.brake` starts the same brake at once (a stop). A target that
  comes during a brake (very late), and the first target after rest, start their segment at
  once in one period, lengthened up to eight times (the knot's velocity slowed as much) where
  it would otherwise accelerate beyond ``FIT_MARGIN`` of ``max_acceleration_rad_s2``; the beat
  starts again from that segment's end.

:class:`ServoSupervisor` adds what every backend's servo loop checks on each tick: a watchdog
(no new target for ``watchdog_s`` of the loop's own clock, counted from the first target:
brake to rest and finish), a speed cap (a setpoint whose velocity would exceed a joint's cap
is not sent: the setpoint brakes from the last one sent and the motion finishes), an
acceleration cap (where the interpolation would accelerate beyond it, as targets that change
direction within a period or come late ask, the setpoint sent chases the interpolation at the
cap instead, and follows it exactly again once it caught up: rate limiting, as libfranka's
``limitRate``), the robot's position-based speed envelope where it has one (near a position
limit the FR3 allows only the speed that stops in time: a faster setpoint is rate-limited the
same way, to the envelope) and the stop request; after a stop, the watchdog or the speed cap
it refuses every later target. It holds no thread and reads no clock: the backend calls
:meth:`ServoSupervisor.tick` with the time that passed, so the same code is tested on
synthetic inputs (:func:`interpolate_targets`) and drives the robots.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rehabbot.common.errors import UsageError

#: Default peak deceleration of a brake [rad/s^2]: half of the FCI's joint acceleration limit
#: (10 rad/s^2).
BRAKE_DECELERATION_RAD_S2 = 5.0

#: Where the interpolation would accelerate beyond the cap, the setpoint sent chases it at the
#: cap instead, closing the gap in this time; it is in sync again once the gap is below
#: SYNC_GAP_RAD (and the velocity's below SYNC_GAP_RAD / CHASE_TIME_S).
CHASE_TIME_S = 0.01
SYNC_GAP_RAD = 1e-6
#: The chase's jerk cap [rad/s^3]: half the FCI's joint jerk limit (5000 rad/s^3), which
#: libfranka reports as a velocity discontinuity.
MAX_JERK_RAD_S3 = 2500.0
#: How far inside a robot's position-based speed envelope the setpoints stay [rad/s].
ENVELOPE_MARGIN_RAD_S = 0.05

#: A robot's position-based speed envelope: the lowest and highest speed [rad/s] per joint
#: at a configuration [rad] (:func:`rehabbot.sim.robots.fr3.speed_envelope_rad_s`).
SpeedEnvelope = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

#: Targets that may wait for their segment; one more drops the oldest (the caller runs ahead),
#: whose period the next one's segment takes over (the path keeps its timing: no jump).
MAX_PENDING = 5

#: Playback rate control: the gain (rate change per period of slack error), the largest change
#: from one segment to the next, and the largest deviation from 1.
RATE_GAIN = 0.25
RATE_STEP = 0.01
RATE_RANGE = 0.1

#: Lengthenings of a segment tried after rest or a brake (:meth:`SetpointInterpolator._fitted`)
#: and the samples of its acceleration checked for each.
FIT_FACTORS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
FIT_SAMPLES = 21
#: The share of the acceleration cap a lengthened segment may use (its samples miss peaks).
FIT_MARGIN = 0.8

#: Peak over mean deceleration of a quintic stop from a constant velocity.
QUINTIC_PEAK = 15.0 / 8.0

#: A sample this close to a segment's end is its end (sums of servo periods round).
END_TOLERANCE_S = 1e-9


def quintic_coefficients(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, p1: np.ndarray,
                         v1: np.ndarray, a1: np.ndarray, duration_s: float) -> np.ndarray:
    """The coefficients ``c[0..5]`` (shape ``(6, n)``) of ``p(t) = sum c_i t^i`` that starts at
    ``(p0, v0, a0)`` and is at ``(p1, v1, a1)`` after ``duration_s`` seconds."""
    if not duration_s > 0.0:
        raise UsageError(f"a segment needs a positive duration, got {duration_s}")
    t = duration_s
    c0, c1, c2 = p0, v0, a0 / 2.0
    # the three end conditions, minus what the first three coefficients already give
    dp = p1 - (c0 + c1 * t + c2 * t**2)
    dv = v1 - (c1 + 2.0 * c2 * t)
    da = a1 - 2.0 * c2
    c3 = (10.0 * dp - 4.0 * dv * t + 0.5 * da * t**2) / t**3
    c4 = (-15.0 * dp + 7.0 * dv * t - da * t**2) / t**4
    c5 = (6.0 * dp - 3.0 * dv * t + 0.5 * da * t**2) / t**5
    return np.stack([np.asarray(c, dtype=float) * np.ones_like(p0, dtype=float)
                     for c in (c0, c1, c2, c3, c4, c5)])


def quintic_eval(coefficients: np.ndarray, t_s: float) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """Position, velocity and acceleration of a quintic (:func:`quintic_coefficients`) at
    ``t_s`` seconds from its start."""
    c0, c1, c2, c3, c4, c5 = coefficients
    t = t_s
    p = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
    v = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)))
    a = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5))
    return p, v, a


def brake_duration_s(v_rad_s: np.ndarray, policy_dt_s: float,
                     deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2,
                     a_rad_s2: np.ndarray | None = None) -> float:
    """How long a brake from the velocity ``v_rad_s`` (and acceleration ``a_rad_s2``, zero by
    default) to rest takes: the shortest of ``FIT_FACTORS`` times the longer of one policy
    period and ``15/8 max |v| / deceleration`` (a quintic stop from ``v`` with zero
    acceleration peaks at 15/8 of its mean deceleration) whose brake keeps every joint's
    acceleration within ``deceleration_rad_s2`` (sampled), else the longest."""
    v = np.atleast_1d(np.asarray(v_rad_s, dtype=float))
    a = np.zeros_like(v) if a_rad_s2 is None else np.atleast_1d(np.asarray(a_rad_s2, float))
    base = max(policy_dt_s, QUINTIC_PEAK * float(np.max(np.abs(v), initial=0.0))
               / deceleration_rad_s2)
    zero = np.zeros_like(v)
    for factor in FIT_FACTORS:
        duration = base * factor
        coefficients = quintic_coefficients(zero, v, a, v * duration / 2.0, zero, zero,
                                            duration)
        if all(np.all(np.abs(quintic_eval(coefficients, t)[2]) <= deceleration_rad_s2)
               for t in np.linspace(0.0, duration, FIT_SAMPLES)):
            return duration
    return duration


class SetpointInterpolator:
    """The setpoint stream of one robot (module docstring: the rule)."""

    def __init__(self, q0_rad: Sequence[float] | np.ndarray, policy_dt_s: float,
                 deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2,
                 delay_s: float | None = None,
                 max_acceleration_rad_s2: np.ndarray | float | None = None,
                 rate_gain: float = RATE_GAIN) -> None:
        q0 = np.array(q0_rad, dtype=float)
        if q0.ndim != 1 or q0.size == 0 or not np.all(np.isfinite(q0)):
            raise UsageError(f"the start position must be a finite vector, got {q0_rad!r}")
        if not policy_dt_s > 0.0:
            raise UsageError(f"policy_dt_s must be positive, got {policy_dt_s}")
        if not deceleration_rad_s2 > 0.0:
            raise UsageError(f"deceleration_rad_s2 must be positive, got {deceleration_rad_s2}")
        delay = policy_dt_s / 2.0 if delay_s is None else float(delay_s)
        if not 0.0 <= delay <= policy_dt_s:
            raise UsageError(f"delay_s={delay_s} must lie in [0, policy_dt_s={policy_dt_s}]")
        self.policy_dt_s = float(policy_dt_s)
        self.delay_s = delay
        self.max_acceleration_rad_s2 = max_acceleration_rad_s2
        if not rate_gain >= 0.0:
            raise UsageError(f"rate_gain must be >= 0, got {rate_gain}")
        self.rate_gain = float(rate_gain)
        self.rate = 1.0
        self.clock_s = 0.0
        self.deceleration_rad_s2 = float(deceleration_rad_s2)
        zero = np.zeros_like(q0)
        self.p, self.v, self.a = q0, zero.copy(), zero.copy()
        self._targets = [q0.copy(), q0.copy()]  # the last two targets (q_{k-2}, q_{k-1})
        # waiting knots: (p, v, a), arrival time, periods their segment lasts
        self._pending: list[tuple[tuple[np.ndarray, np.ndarray, np.ndarray], float, int]] = []
        self._coefficients: np.ndarray | None = None
        self._end = (q0.copy(), zero.copy(), zero.copy())
        self._elapsed_s = 0.0
        self._duration_s = 0.0
        self._braking = False
        self._coasting = False
        self.dropped = 0

    @property
    def at_rest(self) -> bool:
        """True when no segment runs, none waits and the setpoint holds still."""
        return (self._coefficients is None and not self._pending and not np.any(self.v)
                and not np.any(self.a))

    @property
    def braking(self) -> bool:
        """True while the setpoint brakes to rest."""
        return self._braking

    def push(self, q_target_rad: np.ndarray) -> None:
        """A new target (module docstring: when its segment starts)."""
        target = np.array(q_target_rad, dtype=float)
        before, last = self._targets
        dt = self.policy_dt_s
        slope, slope_before = (target - last) / dt, (last - before) / dt
        knot = (target, (3.0 * slope - slope_before) / 2.0, (slope - slope_before) / dt)
        self._targets = [last, target]
        if self._coefficients is None and not self._pending:  # from rest: the delay first
            self._start(*self._fitted(self._scaled(knot), dt / self.rate + self.delay_s))
        elif self._coasting:  # late: its segment ends on the beat
            late_s, left = self._elapsed_s, self._duration_s - self._elapsed_s
            p, v, a = self._scaled(knot)
            if left >= dt / (2.0 * self.rate):
                self._start(p, v, a, left)
            else:  # too little left: aim at the beat after, along the target's parabola
                tau = dt / self.rate
                self._start(p + v * tau + a * tau**2 / 2.0, v + a * tau, a, left + tau)
                self._coasting = True  # a prediction: the next target re-aims it
            self._adapt(-late_s)  # from the next segment on
        elif self._braking:  # very late: the brake gives way at once
            self._start(*self._fitted(self._scaled(knot), dt / self.rate))
        else:
            if len(self._pending) == MAX_PENDING:  # the oldest's period goes to the next
                _knot, _arrival, span = self._pending.pop(0)
                head_knot, head_arrival, head_span = self._pending[0]
                self._pending[0] = (head_knot, head_arrival, head_span + span)
                self.dropped += 1
            self._pending.append((knot, self.clock_s, 1))

    def brake(self) -> None:
        """Brake to rest from the present state now (a stop); waiting targets are dropped."""
        self.dropped += len(self._pending)
        self._pending.clear()
        duration = brake_duration_s(self.v, self.policy_dt_s, self.deceleration_rad_s2, self.a)
        self._start(self.p + self.v * duration / 2.0, np.zeros_like(self.p),
                    np.zeros_like(self.p), duration, braking=True)

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The present setpoint ``(p, v, a)`` (for :meth:`brake_from`)."""
        return self.p, self.v, self.a

    def brake_from(self, snapshot: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Go back to an earlier setpoint (:meth:`snapshot`) and brake from it."""
        self.p, self.v, self.a = snapshot
        self.brake()

    def step(self, elapsed_s: float) -> np.ndarray:
        """Move the setpoint on by ``elapsed_s`` and return its position (a new array)."""
        remaining, start_clock_s = elapsed_s, self.clock_s
        self.clock_s += elapsed_s
        while self._coefficients is not None:
            left = self._duration_s - self._elapsed_s
            if remaining < left - END_TOLERANCE_S:
                self._elapsed_s += remaining
                self.p, self.v, self.a = quintic_eval(self._coefficients, self._elapsed_s)
                break
            remaining -= max(left, 0.0)
            self.p, self.v, self.a = (x.copy() for x in self._end)
            was_braking, was_coasting = self._braking, self._coasting
            self._coefficients, self._braking, self._coasting = None, False, False
            if self._pending:
                knot, arrival_s, span = self._pending.pop(0)
                self._adapt(start_clock_s + elapsed_s - remaining - arrival_s)
                self._start(*self._scaled(knot), span * self.policy_dt_s / self.rate)
            elif was_braking or not (np.any(self.v) or np.any(self.a)):
                continue
            elif was_coasting:
                self.brake()
            else:  # coast on along the parabola for one period
                dt = self.policy_dt_s / self.rate
                self._start(self.p + self.v * dt + self.a * dt**2 / 2.0, self.v + self.a * dt,
                            self.a.copy(), dt)
                self._coasting = True
        if self._coefficients is None:
            self.v, self.a = np.zeros_like(self.p), np.zeros_like(self.p)
        return self.p.copy()

    def _scaled(self, knot: tuple[np.ndarray, np.ndarray, np.ndarray]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A knot's velocity and acceleration at the playback rate."""
        return knot[0], knot[1] * self.rate, knot[2] * self.rate**2

    def _adapt(self, slack_s: float) -> None:
        """Move the playback rate toward keeping ``delay_s`` of slack (how long a target
        waited for its segment; negative: it came late)."""
        want = 1.0 + self.rate_gain * (slack_s - self.delay_s) / self.policy_dt_s
        want = min(max(want, self.rate - RATE_STEP), self.rate + RATE_STEP)
        self.rate = min(max(want, 1.0 - RATE_RANGE), 1.0 + RATE_RANGE)

    def _fitted(self, knot: tuple[np.ndarray, np.ndarray, np.ndarray], duration_s: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The knot and duration of a segment after rest or a brake: the shortest of
        ``duration_s`` times ``FIT_FACTORS`` whose segment keeps within ``FIT_MARGIN`` of
        ``max_acceleration_rad_s2`` (sampled), else the longest; lengthened ``f`` times, the
        knot's velocity is divided by ``f`` and its acceleration by ``f^2`` (the targets' path,
        slowed down)."""
        cap = self.max_acceleration_rad_s2
        p, v, a = knot
        if cap is None:
            return p, v, a, duration_s
        for factor in FIT_FACTORS:
            duration = duration_s * factor
            v_end, a_end = v / factor, a / factor**2
            coefficients = quintic_coefficients(self.p, self.v, self.a, p, v_end, a_end,
                                                duration)
            if all(np.all(np.abs(quintic_eval(coefficients, t)[2]) <= FIT_MARGIN * cap)
                   for t in np.linspace(0.0, duration, FIT_SAMPLES)):
                break
        return p, v_end, a_end, duration

    def _start(self, p1: np.ndarray, v1: np.ndarray, a1: np.ndarray, duration_s: float,
               braking: bool = False) -> None:
        self._coefficients = quintic_coefficients(self.p, self.v, self.a, p1, v1, a1,
                                                  duration_s)
        self._end = (p1.copy(), v1.copy(), a1.copy())
        self._elapsed_s = 0.0
        self._duration_s = duration_s
        self._braking = braking
        self._coasting = False


def checked_target(who: str, q_target_rad: Any, joint_names: Sequence[str],
                   low_rad: np.ndarray, high_rad: np.ndarray) -> np.ndarray:
    """``q_target_rad`` as float64 joint positions, each finite and inside the joint's range;
    else a :class:`~rehabbot.common.errors.UsageError` naming the value, the joint and its
    range (``who``: the backend, in the message)."""
    target = np.asarray(q_target_rad, dtype=float)
    if target.shape != (len(joint_names),):
        raise UsageError(f"{who}: a command needs {len(joint_names)} joint positions, got "
                         f"shape {target.shape}")
    outside = ~np.isfinite(target) | (target < low_rad) | (target > high_rad)
    if np.any(outside):
        j = int(np.argmax(outside))
        raise UsageError(f"{who}: target {float(target[j])!r} rad of {joint_names[j]} is "
                         f"outside its range [{low_rad[j]}, {high_rad[j]}]")
    return target


class ServoSupervisor:
    """The per-tick logic of a backend's servo loop: interpolation, watchdog, speed cap and
    stop (module docstring). Call :meth:`command` from the policy's side and :meth:`tick` from
    the servo loop (the backend holds a lock around both)."""

    def __init__(self, q0_rad: Sequence[float] | np.ndarray, policy_dt_s: float,
                 watchdog_s: float, max_speed_rad_s: Sequence[float] | np.ndarray,
                 max_acceleration_rad_s2: Sequence[float] | np.ndarray | float,
                 deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2,
                 speed_envelope: SpeedEnvelope | None = None) -> None:
        self.interpolator = SetpointInterpolator(q0_rad, policy_dt_s, deceleration_rad_s2)
        self.speed_envelope = speed_envelope
        n = self.interpolator.p.size
        cap = np.broadcast_to(np.asarray(max_speed_rad_s, dtype=float), (n,)).copy()
        if not np.all(cap > 0.0):
            raise UsageError(f"max_speed_rad_s must be positive per joint, got {cap.tolist()}")
        accel = np.broadcast_to(np.asarray(max_acceleration_rad_s2, dtype=float), (n,)).copy()
        if not np.all(accel > 0.0):
            raise UsageError("max_acceleration_rad_s2 must be positive per joint, got "
                             f"{accel.tolist()}")
        self.max_acceleration_rad_s2 = accel
        self.interpolator.max_acceleration_rad_s2 = accel
        if not watchdog_s >= policy_dt_s:
            raise UsageError(f"watchdog_s={watchdog_s} must be at least one policy period "
                             f"({policy_dt_s} s)")
        self.max_speed_rad_s = cap
        # The setpoint last sent, its velocity and acceleration: the interpolator's own while
        # in sync with it, else the acceleration-limited chase of it.
        q0 = self.interpolator.p
        self._sent = (q0.copy(), np.zeros(n), np.zeros(n))
        self._synced = True
        self.limited_ticks = 0
        self.watchdog_s = float(watchdog_s)
        self.time_s = 0.0
        self.last_command_s: float | None = None  # the watchdog runs from the first target
        self.stop_reason: str | None = None
        self.finished = False

    @property
    def stopping(self) -> bool:
        """True once a stop, the watchdog or the speed cap ended the commanding."""
        return self.stop_reason is not None

    def command(self, q_target_rad: np.ndarray) -> None:
        """A new target from the policy; refused once stopping."""
        if self.stop_reason is not None:
            raise UsageError(f"the robot is stopped ({self.stop_reason}); commands are refused")
        self.interpolator.push(q_target_rad)
        self.last_command_s = self.time_s

    def request_stop(self, reason: str = "stop requested") -> None:
        """Brake to rest now and finish; the first reason given is kept."""
        if self.stop_reason is None:
            self.stop_reason = reason
            self.interpolator.brake_from(tuple(x.copy() for x in self._sent))

    def tick(self, elapsed_s: float) -> tuple[np.ndarray, bool]:
        """The next setpoint, ``elapsed_s`` after the last one, and whether it is the last
        (the motion is finished: at rest after a stop)."""
        self.time_s += elapsed_s
        last = self.last_command_s
        if self.stop_reason is None and last is not None and self.time_s - last > self.watchdog_s:
            self.request_stop(f"watchdog: no command for {self.watchdog_s} s")
        interpolator = self.interpolator
        setpoint = interpolator.step(elapsed_s)
        if not interpolator.braking:
            value, cap = interpolator.v, self.max_speed_rad_s
            if np.any(np.abs(value) > cap):
                j = int(np.argmax(np.abs(value) / cap))
                self.stop_reason = self.stop_reason or (
                    f"speed cap: joint {j} would reach {abs(value[j]):.3f} rad/s "
                    f"(cap {cap[j]} rad/s)")
                # not sent: brake from the last setpoint sent (the brake is not capped)
                interpolator.brake_from(tuple(x.copy() for x in self._sent))
                setpoint = interpolator.step(elapsed_s)
            elif (not self._synced
                  or self._outside_envelope(setpoint, interpolator.v)
                  or np.any(np.abs(interpolator.a) > self.max_acceleration_rad_s2)
                  or np.any(np.abs(interpolator.a - self._sent[2])
                            > MAX_JERK_RAD_S3 * elapsed_s)):
                setpoint = self._chase(setpoint, elapsed_s)
        if interpolator.braking or self._synced:
            self._sent = (setpoint.copy(), interpolator.v.copy(), interpolator.a.copy())
        self.finished = self.stop_reason is not None and interpolator.at_rest
        return setpoint, self.finished

    @property
    def sent(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The setpoint last sent, its velocity and its acceleration."""
        return self._sent

    def _speed_bounds(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The speeds a setpoint at ``q_rad`` may have: the caps, narrowed to the robot's
        position-based envelope (less :data:`ENVELOPE_MARGIN_RAD_S`) where it has one."""
        cap = self.max_speed_rad_s
        if self.speed_envelope is None:
            return -cap, cap
        low, high = self.speed_envelope(q_rad)
        return (np.clip(low + ENVELOPE_MARGIN_RAD_S, -cap, 0.0),
                np.clip(high - ENVELOPE_MARGIN_RAD_S, 0.0, cap))

    def _outside_envelope(self, q_rad: np.ndarray, v_rad_s: np.ndarray) -> bool:
        """Whether the speed ``v_rad_s`` at ``q_rad`` leaves the robot's envelope: the
        setpoint then follows the interpolation at the envelope (:meth:`_chase`)."""
        if self.speed_envelope is None:
            return False
        low, high = self._speed_bounds(q_rad)
        return bool(np.any(v_rad_s < low) or np.any(v_rad_s > high))

    def _chase(self, setpoint: np.ndarray, elapsed_s: float) -> np.ndarray:
        """The acceleration-limited chase of the interpolator's ``setpoint``: its velocity plus
        the gap closed in :data:`CHASE_TIME_S`, reached at no more than the acceleration cap
        and :data:`MAX_JERK_RAD_S3` (libfranka's rate limiting does the same); in sync again
        once the gap is closed."""
        p, v, a_sent = self._sent
        wanted = self.interpolator.v + (setpoint - p) / CHASE_TIME_S
        jerk = MAX_JERK_RAD_S3 * elapsed_s
        a = np.clip(np.clip((wanted - v) / elapsed_s, a_sent - jerk, a_sent + jerk),
                    -self.max_acceleration_rad_s2, self.max_acceleration_rad_s2)
        low, high = self._speed_bounds(p)
        v = np.clip(v + a * elapsed_s, low, high)
        p = p + v * elapsed_s
        self.limited_ticks += 1
        self._synced = bool(np.max(np.abs(p - setpoint)) < SYNC_GAP_RAD
                            and np.max(np.abs(v - self.interpolator.v)) < SYNC_GAP_RAD
                            / CHASE_TIME_S)
        if self._synced:
            return setpoint
        self._sent = (p, v, a)
        return p.copy()


def interpolate_targets(q0_rad: Sequence[float] | np.ndarray, targets_rad: np.ndarray,
                        policy_dt_s: float, servo_dt_s: float, delay_s: float | None = None,
                        deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2) -> np.ndarray:
    """The servo setpoints (shape ``(len(targets) * m, n)``, ``m = policy_dt_s / servo_dt_s``)
    of targets given one per policy period from ``q0_rad``, at rest: target ``k`` arrives just
    before servo tick ``k * m``; row ``i`` is the setpoint ``(i + 1) * servo_dt_s`` after the
    first target came."""
    ratio = policy_dt_s / servo_dt_s
    m = round(ratio)
    if m < 1 or abs(ratio - m) > 1e-9 * ratio:
        raise UsageError(f"policy_dt_s={policy_dt_s} must be a whole number of servo periods "
                         f"(servo_dt_s={servo_dt_s})")
    interpolator = SetpointInterpolator(q0_rad, policy_dt_s, deceleration_rad_s2, delay_s)
    targets = np.asarray(targets_rad, dtype=float)
    out = np.empty((targets.shape[0] * m, interpolator.p.size))
    for k, target in enumerate(targets):
        interpolator.push(target)
        for i in range(m):
            out[k * m + i] = interpolator.step(servo_dt_s)
    return out
