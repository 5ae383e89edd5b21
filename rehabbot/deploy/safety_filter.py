"""The deployment safety filter: every joint command passes through it on its way from a policy
to a robot, whatever the policy and whatever the robot.

:class:`SafetyFilter` works in the robot's joint space, on what a :class:`RobotState` reports
and the joint positions a policy asks for. Each call of :meth:`SafetyFilter.filter` returns a
:class:`FilterDecision`: the joint positions to command and one action, the first of these
rules that applies (``docs/deployment/safety-filter.md`` states what the rules guarantee and
what they do not):

=============  ================================================================================
action         when, and what is commanded
=============  ================================================================================
``stop``       a state or command that is non-finite, of the wrong shape, stale (older than
               ``max_state_age_s`` / ``max_command_age_s``), from the future, or a state older
               than the one before; a missing force estimate where the force rule is on; the
               watchdog (:meth:`SafetyFilter.watchdog`: no command for ``watchdog_timeout_s``).
               Latched: every later call answers ``stop`` until :meth:`SafetyFilter.reset`.
               The joint positions are the last ones commanded (the caller stops the robot).
``back_off``   the cuff force at or above ``back_off_fraction`` of its limit, a patient joint
               beyond its range, or within ``rom_margin_rad`` of a bound and moving toward it:
               retrace the robot's measured path back through the configurations last
               recorded as safe, at no more than the speed cap.
``hold``       the cuff force at or above ``hold_fraction`` of its limit, a patient joint
               that one decision at its present speed would take within ``rom_margin_rad`` of a
               bound, a measured robot joint speed above ``overspeed_factor`` times its cap, or
               a patient joint faster than ``max_patient_speed_rad_s``: keep the robot's
               measured position of the moment the hold began, moving the command there at no
               more than the speed cap.
``clip``       the command changed to respect the joint box, the speed cap and the acceleration
               cap (per decision of ``control_dt_s``: the step of the command at most
               ``max_speed_rad_s * dt``, the change of that step at most
               ``max_accel_rad_s2 * dt**2``).
``pass``       the command unchanged (the same array values, bit for bit).
=============  ================================================================================

Every command the filter returns moves each joint by at most ``max_speed_rad_s *
control_dt_s`` from the one before (``stop`` does not move it; ``hold`` and ``back_off`` with
``release_to_measured`` may first drop the command back onto the measured position, which asks
for no motion). ``pass`` and ``clip`` also keep the acceleration cap, except where the joint box
stops a command at its edge; ``hold`` and ``back_off`` brake or reverse as fast as the speed cap
allows. A configuration is recorded as safe (for ``back_off`` to retrace) at each decision where
no rule applied, once the robot has moved :data:`HISTORY_SPACING_RAD` from the last one
recorded.

The range-of-motion rules read the exercised patient joints from the state's
``patient_q_rad`` and ``patient_dq_rad_s`` (measured in the simulator; on a real robot an
estimate from the patient's twin): they are only as good as that estimate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rehabbot.common.checks import is_real
from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotState

ACTIONS: tuple[str, ...] = ("pass", "clip", "hold", "back_off", "stop")
# A configuration is recorded for back_off once the robot moved this far [rad] (the largest
# joint's change) from the last one recorded, so that a robot at rest fills no history.
HISTORY_SPACING_RAD = 0.002

_EMPTY: tuple[str, ...] = ()
_CLIP_REASONS = ("joint box", "speed cap", "acceleration cap")


def _finite(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
            open_low: bool = False) -> float:
    ok = is_real(value) and math.isfinite(float(value)) and (
        low < float(value) if open_low else low <= float(value)) and float(value) <= high
    if not ok:
        side = "(" if open_low else "["
        raise UsageError(f"safety filter: {name}={value!r} must be a finite number in "
                         f"{side}{low}, {high}]")
    return float(value)


def _vector(name: str, value: Any, positive: bool = False) -> tuple[float, ...]:
    """A scalar or a sequence of finite numbers (each > 0 with ``positive``) as a tuple."""
    items = [value] if is_real(value) else value
    try:
        items = list(items)
    except TypeError:
        raise UsageError(f"safety filter: {name}={value!r} must be a number or a sequence of "
                         "numbers") from None
    if not items:
        raise UsageError(f"safety filter: {name}={value!r} is empty")
    for k, item in enumerate(items):
        if not (is_real(item) and math.isfinite(float(item))) or (positive and item <= 0):
            what = "a finite number > 0" if positive else "a finite number"
            raise UsageError(f"safety filter: {name}[{k}]={item!r} must be {what} "
                             f"({name}={value!r})")
    return tuple(float(item) for item in items)


def _bounds(low_name: str, low: Any, high_name: str, high: Any) -> tuple[tuple[float, ...],
                                                                         tuple[float, ...]]:
    lo, hi = _vector(low_name, low), _vector(high_name, high)
    if len(lo) != len(hi):
        raise UsageError(f"safety filter: {low_name} has {len(lo)} entries and {high_name} "
                         f"{len(hi)}")
    for k, (a, b) in enumerate(zip(lo, hi, strict=True)):
        if not a < b:
            raise UsageError(f"safety filter: {low_name}[{k}]={a} must be below "
                             f"{high_name}[{k}]={b}")
    return lo, hi


@dataclass(frozen=True)
class FilterConfig:
    """What the filter enforces (module docstring; ``docs/deployment/safety-filter.md`` has
    the table of fields). SI units; per-joint values as one number or one per joint (robot
    joints in the state's ``q_rad`` order, patient joints in its ``patient_q_rad`` order). Every
    bad value raises a :class:`~rehabbot.common.errors.UsageError` naming it.

    The caps on the command (``max_speed_rad_s``, ``max_accel_rad_s2``) and its box
    (``joint_low_rad`` / ``joint_high_rad``); the patient's range (``rom_low_rad`` /
    ``rom_high_rad``, kept ``rom_margin_rad`` away from) and speed cap
    (``max_patient_speed_rad_s``); the cuff's limit (``cuff_force_limit_n``: hold from
    ``hold_fraction`` of it, back off from ``back_off_fraction``); the measured robot speed's
    hold (``overspeed_factor`` x the cap); the inputs' ages and the watchdog; how many safe
    configurations back off can retrace (``history_size``). ``None`` switches a rule off.
    """

    control_dt_s: float
    max_speed_rad_s: float | Sequence[float]
    max_accel_rad_s2: float | Sequence[float]
    joint_low_rad: Sequence[float] | None = None
    joint_high_rad: Sequence[float] | None = None
    rom_low_rad: Sequence[float] | None = None
    rom_high_rad: Sequence[float] | None = None
    rom_margin_rad: float = math.radians(5.0)
    cuff_force_limit_n: float | None = None
    hold_fraction: float = 0.6
    back_off_fraction: float = 0.8
    max_state_age_s: float = 0.05
    max_command_age_s: float = 0.05
    watchdog_timeout_s: float = 0.1
    overspeed_factor: float | None = 1.25
    max_patient_speed_rad_s: float | Sequence[float] | None = None
    release_to_measured: bool = True
    history_size: int = 500
    patient_joint_names: Sequence[str] | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "control_dt_s", _finite("control_dt_s", self.control_dt_s, 0.0, 10.0, True))
        set_(self, "max_speed_rad_s", _vector("max_speed_rad_s", self.max_speed_rad_s, True))
        set_(self, "max_accel_rad_s2", _vector("max_accel_rad_s2", self.max_accel_rad_s2, True))
        if (self.joint_low_rad is None) != (self.joint_high_rad is None):
            raise UsageError("safety filter: give joint_low_rad and joint_high_rad together "
                             f"(got {self.joint_low_rad!r} and {self.joint_high_rad!r})")
        if self.joint_low_rad is not None:
            lo, hi = _bounds("joint_low_rad", self.joint_low_rad,
                             "joint_high_rad", self.joint_high_rad)
            set_(self, "joint_low_rad", lo)
            set_(self, "joint_high_rad", hi)
        sizes = {name: len(getattr(self, name)) for name in ("max_speed_rad_s", "max_accel_rad_s2")
                 if len(getattr(self, name)) > 1}
        if self.joint_low_rad is not None:
            sizes["joint_low_rad"] = len(self.joint_low_rad)
        if len(set(sizes.values())) > 1:
            raise UsageError(f"safety filter: the per-joint settings disagree on the number of "
                             f"robot joints: {sizes}")
        set_(self, "rom_margin_rad", _finite("rom_margin_rad", self.rom_margin_rad, 0.0, 1.0))
        if (self.rom_low_rad is None) != (self.rom_high_rad is None):
            raise UsageError("safety filter: give rom_low_rad and rom_high_rad together "
                             f"(got {self.rom_low_rad!r} and {self.rom_high_rad!r})")
        if self.rom_low_rad is not None:
            lo, hi = _bounds("rom_low_rad", self.rom_low_rad, "rom_high_rad", self.rom_high_rad)
            for k, (a, b) in enumerate(zip(lo, hi, strict=True)):
                if not a + self.rom_margin_rad < b - self.rom_margin_rad:
                    raise UsageError(
                        f"safety filter: rom_margin_rad={self.rom_margin_rad} leaves nothing "
                        f"of patient joint {k}'s range [{a}, {b}]")
            set_(self, "rom_low_rad", lo)
            set_(self, "rom_high_rad", hi)
        if self.patient_joint_names is not None:
            names = tuple(self.patient_joint_names)
            if isinstance(self.patient_joint_names, str) or not all(
                    isinstance(n, str) for n in names):
                raise UsageError(f"safety filter: patient_joint_names="
                                 f"{self.patient_joint_names!r} must be a sequence of names")
            if self.rom_low_rad is None or len(names) != len(self.rom_low_rad):
                raise UsageError(f"safety filter: patient_joint_names={names!r} must name the "
                                 "joints of rom_low_rad / rom_high_rad, one each")
            set_(self, "patient_joint_names", names)
        if self.cuff_force_limit_n is not None:
            set_(self, "cuff_force_limit_n", _finite(
                "cuff_force_limit_n", self.cuff_force_limit_n, 0.0, 1e4, True))
        hold = _finite("hold_fraction", self.hold_fraction, 0.0, 1.0, True)
        back = _finite("back_off_fraction", self.back_off_fraction, 0.0, 1.0, True)
        if not hold < back:
            raise UsageError(f"safety filter: hold_fraction={hold} must be below "
                             f"back_off_fraction={back} (hold first, then back off)")
        set_(self, "hold_fraction", hold)
        set_(self, "back_off_fraction", back)
        for name in ("max_state_age_s", "max_command_age_s", "watchdog_timeout_s"):
            set_(self, name, _finite(name, getattr(self, name), 0.0, 3600.0, True))
        if self.overspeed_factor is not None:
            set_(self, "overspeed_factor", _finite("overspeed_factor", self.overspeed_factor,
                                                   1.0, 100.0))
        if self.max_patient_speed_rad_s is not None:
            speeds = _vector("max_patient_speed_rad_s", self.max_patient_speed_rad_s, True)
            if self.rom_low_rad is None or len(speeds) not in (1, len(self.rom_low_rad)):
                raise UsageError(f"safety filter: max_patient_speed_rad_s={speeds!r} needs the "
                                 "patient joints of rom_low_rad / rom_high_rad (one value or "
                                 "one per joint)")
            set_(self, "max_patient_speed_rad_s", speeds)
        if not isinstance(self.release_to_measured, bool):
            raise UsageError(f"safety filter: release_to_measured={self.release_to_measured!r} "
                             "must be a bool")
        size = self.history_size
        if not (is_real(size) and float(size).is_integer() and 1 <= size <= 100_000):
            raise UsageError(f"safety filter: history_size={size!r} must be an integer in "
                             "[1, 100000]")
        set_(self, "history_size", int(size))

    @property
    def n_joints(self) -> int | None:
        """The robot's joint count where a per-joint setting fixes it (else None: any)."""
        if self.joint_low_rad is not None:
            return len(self.joint_low_rad)
        for name in ("max_speed_rad_s", "max_accel_rad_s2"):
            if len(getattr(self, name)) > 1:
                return len(getattr(self, name))
        return None

    @classmethod
    def for_simulator(cls, backend: Any, **settings: Any) -> FilterConfig:
        """A config for a :class:`~rehabbot.deploy.simulator.SimulatorBackend`: its decision
        period, setpoint box, exercised joints' range of motion and cuff force limit, with
        ``settings`` (the caps at least) on top."""
        low, high = backend.setpoint_bounds_rad()
        rom_low, rom_high = backend.rom_bounds_rad()
        env = backend.env
        names = [env.model.joint(int(j)).name
                 for j in env.model.dof_jntid[np.asarray(env.scene.exercised_dof_adr)]]
        base: dict[str, Any] = {
            "control_dt_s": backend.control_dt_s, "joint_low_rad": low.tolist(),
            "joint_high_rad": high.tolist(), "rom_low_rad": rom_low.tolist(),
            "rom_high_rad": rom_high.tolist(), "patient_joint_names": names,
            "cuff_force_limit_n": backend.cuff_force_limit_n()}
        return cls(**{**base, **settings})


@dataclass(frozen=True)
class FilterDecision:
    """One decision of the filter: the joint positions to command [rad] (a new array), the
    action (one of :data:`ACTIONS`) and why (empty for ``pass``)."""

    q_rad: np.ndarray
    action: str
    reasons: tuple[str, ...] = ()


class SafetyFilter:
    """The filter (module docstring). Call :meth:`reset` with the robot's state before the
    first :meth:`filter`, and again after a stop."""

    def __init__(self, config: FilterConfig) -> None:
        if not isinstance(config, FilterConfig):
            raise UsageError(f"safety filter: config must be a FilterConfig, not {config!r}")
        self.config = config
        dt = config.control_dt_s
        self._dt = dt
        self._step_max = np.asarray(config.max_speed_rad_s) * dt
        self._change_max = np.asarray(config.max_accel_rad_s2) * dt * dt
        self._box = config.joint_low_rad is not None
        self._box_low = np.asarray(config.joint_low_rad if self._box else [-math.inf])
        self._box_high = np.asarray(config.joint_high_rad if self._box else [math.inf])
        self._rom = config.rom_low_rad is not None
        if self._rom:
            low, high = np.asarray(config.rom_low_rad), np.asarray(config.rom_high_rad)
            self._rom_low, self._rom_high = low, high
            self._safe_low = low + config.rom_margin_rad
            self._safe_high = high - config.rom_margin_rad
            self._patient_shape = (len(low),)
        self._overspeed = None if config.overspeed_factor is None else (
            np.asarray(config.max_speed_rad_s) * config.overspeed_factor)
        self._patient_speed = None if config.max_patient_speed_rad_s is None else (
            np.asarray(config.max_patient_speed_rad_s))
        self._force = config.cuff_force_limit_n is not None
        if self._force:
            limit = float(config.cuff_force_limit_n)  # type: ignore[arg-type]
            self._hold_n = config.hold_fraction * limit
            self._back_off_n = config.back_off_fraction * limit
        self._n: int | None = None
        self._shape: tuple[int, ...] = (0,)
        self._q_last = np.zeros(0)
        self._step_last = np.zeros(0)
        self._history = np.zeros((0, 0))
        self._count = 0
        self._hold_q: np.ndarray | None = None
        self._latched: str | None = None
        self._last_command_s = -math.inf
        self._last_state_s = -math.inf
        self.counts: dict[str, int] = dict.fromkeys(ACTIONS, 0)

    # -- state ---------------------------------------------------------------------------------
    @property
    def stopped(self) -> bool:
        """Whether the stop is latched (until :meth:`reset`)."""
        return self._latched is not None

    @property
    def stop_reason(self) -> str | None:
        """Why the filter stopped (None while it runs)."""
        return self._latched

    @property
    def last_command_rad(self) -> np.ndarray:
        """The last joint positions the filter returned (a copy)."""
        return self._q_last.copy()

    @property
    def safe_configurations(self) -> int:
        """How many safe configurations back off can retrace now."""
        return self._count

    def reset(self, state: RobotState, now_s: float | None = None) -> None:
        """Start (again) from ``state``: its measured joint positions become the last command,
        the motion is at rest, the stop latch and the history are cleared and the watchdog
        counts from ``now_s`` (default: the state's time). A state the filter could not use
        raises :class:`~rehabbot.common.errors.UsageError` naming the bad value."""
        if not isinstance(state, RobotState):
            raise UsageError(f"safety filter: reset with a {type(state).__name__}, not a "
                             "RobotState")
        q = np.array(state.q_rad, dtype=float)
        n = self.config.n_joints
        if q.ndim != 1 or q.size == 0 or (n is not None and q.size != n):
            raise UsageError(f"safety filter: reset with q_rad of shape {q.shape}; the config "
                             f"is for {n or 'any number of'} joints")
        time_s = _finite("state.time_s", state.time_s)
        start = time_s if now_s is None else _finite("now_s", now_s)
        self._shape = (q.size,)
        self._last_state_s = -math.inf
        problem, _ = self._check(state, np.zeros(q.size), start, None)
        if problem is not None:
            raise UsageError(f"safety filter: cannot reset: {problem}")
        self._n = q.size
        self._q_last = q
        self._step_last = np.zeros(q.size)
        self._history = np.zeros((self.config.history_size, q.size))
        self._count = 0
        self._hold_q = None
        self._latched = None
        self._last_command_s = start
        self._last_state_s = time_s
        if self._assess(state, []) == 0:
            self._record(q)

    # -- the rules -----------------------------------------------------------------------------
    def filter(self, state: RobotState, q_command_rad: Any, now_s: float,
               command_time_s: float | None = None) -> FilterDecision:
        """The decision for the command ``q_command_rad`` [rad], given the latest ``state``,
        at time ``now_s`` [s] (the clock of the states' ``time_s``). ``command_time_s``: when
        the policy computed the command (default: now)."""
        if self._n is None:
            raise UsageError("safety filter: call reset(state) before filter()")
        if self._latched is not None:
            return self._stopped()
        problem, command = self._check(state, q_command_rad, now_s, command_time_s)
        if problem is not None:
            return self._stop(problem)
        self._last_command_s = now_s
        self._last_state_s = state.time_s
        reasons: list[str] = []
        level = self._assess(state, reasons)
        if level == 2:
            self._hold_q = None
            return self._move(self._retrace_target(state, reasons), state.q_rad, "back_off",
                              reasons)
        if level == 1:
            if self._hold_q is None:
                self._hold_q = state.q_rad.copy()
            return self._move(self._hold_q, state.q_rad, "hold", reasons)
        self._hold_q = None
        self._record(state.q_rad)
        return self._follow(command)

    def watchdog(self, now_s: float) -> FilterDecision | None:
        """``stop`` (latched) when no command came for longer than ``watchdog_timeout_s``
        before ``now_s``, or when the filter is stopped already; else None."""
        if self._n is None:
            raise UsageError("safety filter: call reset(state) before watchdog()")
        if self._latched is not None:
            return self._stopped()
        if not (is_real(now_s) and math.isfinite(now_s)):
            return self._stop(f"watchdog: non-finite time now_s={now_s!r}")
        gap = now_s - self._last_command_s
        if gap > self.config.watchdog_timeout_s:
            return self._stop(f"watchdog: no command for {gap:.4g} s (> "
                              f"{self.config.watchdog_timeout_s:g} s)")
        return None

    def _check(self, state: Any, command: Any, now_s: Any,
               command_time_s: Any) -> tuple[str | None, np.ndarray]:
        """Why the inputs cannot be used (None: they can), and the command as floats."""
        cfg = self.config
        if not (is_real(now_s) and math.isfinite(now_s)):
            return f"non-finite time now_s={now_s!r}", command
        if not isinstance(state, RobotState):
            return f"state is a {type(state).__name__}, not a RobotState", command
        time_s = state.time_s
        if not (is_real(time_s) and math.isfinite(time_s)):
            return f"non-finite state time {time_s!r}", command
        age = now_s - time_s
        if age > cfg.max_state_age_s:
            return f"stale state: {age:.4g} s old (> {cfg.max_state_age_s:g} s)", command
        if age < 0.0:
            return f"state from the future: time_s={time_s!r} > now_s={now_s!r}", command
        if time_s < self._last_state_s:
            return f"state time went back: {time_s!r} < {self._last_state_s!r}", command
        if command_time_s is not None:
            if not (is_real(command_time_s) and math.isfinite(command_time_s)):
                return f"non-finite command time {command_time_s!r}", command
            age = now_s - command_time_s
            if age > cfg.max_command_age_s:
                return (f"stale command: {age:.4g} s old (> {cfg.max_command_age_s:g} s)",
                        command)
            if age < 0.0:
                return (f"command from the future: command_time_s={command_time_s!r} > "
                        f"now_s={now_s!r}", command)
        shape = self._shape
        if not (isinstance(command, np.ndarray) and command.dtype == np.float64):
            try:
                command = np.asarray(command, dtype=float)
            except (TypeError, ValueError):
                return f"command {command!r} is not an array of numbers", command
        if command.shape != shape:
            return f"command of shape {command.shape}, expected {shape}", command
        arrays = {"q_rad": state.q_rad, "dq_rad_s": state.dq_rad_s}
        if self._rom:
            arrays |= {"patient_q_rad": state.patient_q_rad,
                       "patient_dq_rad_s": state.patient_dq_rad_s}
        total = sum(command.tolist())  # NumPy's reductions cost more than a list's, at n ~ 7
        for name, array in arrays.items():
            want = self._patient_shape if name.startswith("patient") else shape
            if not (isinstance(array, np.ndarray) and array.dtype == np.float64
                    and array.shape == want):
                return (f"state {name} {array!r} is not a float64 array of shape {want}",
                        command)
            total += sum(array.tolist())
        if self._force:
            force = state.cuff_force_n
            if not (is_real(force) and math.isfinite(force) and force >= 0.0):
                return (f"cuff force {force!r}: the force rule needs a finite force "
                        "estimate >= 0", command)
        if not math.isfinite(total):  # a NaN or an inf somewhere (or an overflow: look)
            for name, array in {"command": command, **arrays}.items():
                if not np.isfinite(array).all():
                    return f"non-finite {name} {array.tolist()}", command
        return None, command

    def _assess(self, state: RobotState, reasons: list[str]) -> int:
        """0 (no rule applies), 1 (hold) or 2 (back off), with the reasons appended."""
        level = 0
        if self._force:
            force = state.cuff_force_n
            if force >= self._hold_n:
                back = force >= self._back_off_n
                level = 2 if back else 1
                fraction = self.config.back_off_fraction if back else self.config.hold_fraction
                reasons.append(f"cuff force {force:.1f} N >= {fraction:g} x the "
                               f"{self.config.cuff_force_limit_n:g} N limit")
        if self._overspeed is not None:
            over = (np.abs(state.dq_rad_s) > self._overspeed).tolist()
            if True in over:
                level = max(level, 1)
                k = over.index(True)
                reasons.append(f"robot joint {k} at {float(state.dq_rad_s[k]):.3f} rad/s, above "
                               f"{self.config.overspeed_factor:g} x its speed cap")
        if self._rom:
            p, dp = state.patient_q_rad, state.patient_dq_rad_s
            ahead = p + dp * self._dt
            near = ((np.minimum(p, ahead) < self._safe_low)
                    | (np.maximum(p, ahead) > self._safe_high)).tolist()
            if True in near:
                level = max(level, self._rom_level(p, dp, ahead, reasons))
            if self._patient_speed is not None:
                over = (np.abs(dp) > self._patient_speed).tolist()
                if True in over:
                    level = max(level, 1)
                    k = over.index(True)
                    names = self.config.patient_joint_names
                    name = names[k] if names is not None else f"patient joint {k}"
                    reasons.append(f"{name} at {float(dp[k]):.3f} rad/s, above its speed cap")
        return level

    def _rom_level(self, p: np.ndarray, dp: np.ndarray, ahead: np.ndarray,
                   reasons: list[str]) -> int:
        """The range rules, joint by joint (called only near a bound)."""
        names = self.config.patient_joint_names
        level = 0
        for k in range(p.size):
            name = names[k] if names is not None else f"patient joint {k}"
            lo, hi = float(self._rom_low[k]), float(self._rom_high[k])
            safe_lo, safe_hi = float(self._safe_low[k]), float(self._safe_high[k])
            q, v, nxt = float(p[k]), float(dp[k]), float(ahead[k])
            if q < lo or q > hi:
                level = 2
                reasons.append(f"{name} at {q:.4f} rad, beyond its range [{lo:.4f}, {hi:.4f}]")
            elif (q < safe_lo and v < 0.0) or (q > safe_hi and v > 0.0):
                level = 2
                reasons.append(f"{name} at {q:.4f} rad, within the margin of its range "
                               f"[{lo:.4f}, {hi:.4f}] and moving toward the bound")
            elif (nxt < safe_lo and v < 0.0) or (nxt > safe_hi and v > 0.0):
                level = max(level, 1)
                reasons.append(f"{name} heading for the margin of its range: {q:.4f} rad now, "
                               f"{nxt:.4f} rad one decision ahead")
        return level

    # -- what is commanded ---------------------------------------------------------------------
    def _follow(self, command: np.ndarray) -> FilterDecision:
        """``pass`` or ``clip``: the command in the box, within the speed and acceleration
        caps."""
        boxed = command
        if self._box:
            boxed = np.minimum(np.maximum(command, self._box_low), self._box_high)
        step = boxed - self._q_last
        low = np.maximum(self._step_last - self._change_max, -self._step_max)
        high = np.minimum(self._step_last + self._change_max, self._step_max)
        limited = np.minimum(np.maximum(step, low), high)
        in_box = boxed is command or False not in (boxed == command).tolist()
        if in_box and False not in (limited == step).tolist():
            q = command.copy()
            self._q_last = q
            self._step_last = step
            self.counts["pass"] += 1
            return FilterDecision(q.copy(), "pass", _EMPTY)
        last = self._q_last
        q = last + limited
        if self._box:  # an accelerating command braking toward the box's edge stops at it
            q = np.minimum(np.maximum(q, np.minimum(self._box_low, last)),
                           np.maximum(self._box_high, last))
            limited = q - last
        self._q_last = q
        reasons = self._clip_reasons(not in_box, step)
        self._step_last = limited
        self.counts["clip"] += 1
        return FilterDecision(q.copy(), "clip", reasons)

    def _clip_reasons(self, boxed: bool, step: np.ndarray) -> tuple[str, ...]:
        flags = (boxed, True in (np.abs(step) > self._step_max).tolist(),
                 True in (np.abs(step - self._step_last) > self._change_max).tolist())
        return tuple(r for r, f in zip(_CLIP_REASONS, flags, strict=True) if f)

    def _move(self, target: np.ndarray, measured: np.ndarray, action: str,
              reasons: list[str]) -> FilterDecision:
        """``hold`` or ``back_off``: toward ``target`` within the speed cap (no acceleration
        cap: braking comes first). With ``release_to_measured``, a joint whose measured position
        lies between the last command and the target moves from there: the command first
        drops back onto where the robot is (which asks for no motion: it ends the servo's push)."""
        last = self._q_last
        if self._box:  # the target is in the box; the robot may not be (after a reset)
            target = np.minimum(np.maximum(target, self._box_low), self._box_high)
        base = last
        if self.config.release_to_measured:
            base = np.where((measured - last) * (target - measured) >= 0.0, measured, last)
        step = np.minimum(np.maximum(target - base, -self._step_max), self._step_max)
        q = base + step
        if False not in (q == target).tolist():
            q = np.array(target, dtype=float)
        self._step_last = step
        self._q_last = q
        self.counts[action] += 1
        return FilterDecision(q.copy(), action, tuple(reasons))

    def _record(self, q: np.ndarray) -> None:
        """Remember the measured ``q`` as safe (once it moved from the last one recorded)."""
        history, count = self._history, self._count
        if count and max(np.abs(q - history[count - 1]).tolist()) < HISTORY_SPACING_RAD:
            return
        if count == len(history):  # full: forget the oldest
            history[:-1] = history[1:]
            count -= 1
        history[count] = q
        self._count = count + 1

    def _retrace_target(self, state: RobotState, reasons: list[str]) -> np.ndarray:
        """The safe configuration back off heads for: the latest recorded, the one before once
        the command has reached it (the first is kept: it is where the filter began)."""
        if self._count == 0:
            reasons.append("no safe configuration recorded: holding the measured position")
            return np.array(state.q_rad, dtype=float)
        target = self._history[self._count - 1]
        if self._count > 1 and False not in (self._q_last == target).tolist():
            self._count -= 1
            target = self._history[self._count - 1]
        return target

    def _stop(self, reason: str) -> FilterDecision:
        self._latched = reason
        self._step_last = np.zeros_like(self._q_last)
        return self._stopped()

    def _stopped(self) -> FilterDecision:
        self.counts["stop"] += 1
        return FilterDecision(self._q_last.copy(), "stop", (f"stopped: {self._latched}",))
