"""A Universal Robots e-Series arm behind :class:`rehabbot.deploy.backend.RobotBackend`, on
``ur_rtde``.

``ur_rtde`` (SDU Robotics, the ``[ur]`` extra) talks RTDE to the controller: its
``RTDEControlInterface`` uploads a URScript that servos the joints to the positions it is sent
(``servoJ``), its ``RTDEReceiveInterface`` reads the robot's state. The backend:

* runs a servo loop at the controller's rate (``servo_dt_s`` = 0.002 s, 500 Hz on the e-Series)
  in a thread, paced by ``ur_rtde``'s ``initPeriod``/``waitPeriod``; every tick it sends
  ``servoJ(q, 0, 0, servo_dt_s, lookahead_time_s, gain)`` with the setpoint of
  :class:`rehabbot.deploy.interpolation.ServoSupervisor` (the policy's targets, one per
  ``control_dt_s``, joined by quintic segments with continuous velocity and acceleration) and
  kicks the controller-side watchdog. ``servoJ``'s speed and acceleration arguments are
  unused by ``ur_rtde``; its ``lookahead_time`` (0.03-0.2 s, 0.1 by default) smooths the
  setpoints further on the controller and ``gain`` (100-2000, 300 by default) is the
  proportional gain of the controller's tracking;
* **two watchdogs**: the supervisor's (no new target for ``watchdog_s``, 0.1 s, by the loop's
  clock: the setpoint brakes to rest and the robot stops), and the controller's own
  (``setWatchdog(1 / controller_watchdog_s)``): if the servo loop itself stops kicking it for
  ``controller_watchdog_s`` (0.1 s), the URScript stops the robot;
* **speed and acceleration caps**: a setpoint faster than a joint's cap (RehabBot's UR5e joint
  speeds, pi rad/s, by default) or accelerating more than 9 rad/s^2 is not sent; the setpoint
  brakes from the last one sent and the robot stops;
* a stop (:meth:`URBackend.stop`, the watchdog, a cap): the setpoint brakes to rest, then
  ``servoStop`` ends servo mode (the tool decelerating at 2 m/s^2) and ``stopJ`` brings every
  joint to a halt (at ``stop_deceleration_rad_s2``, 2 rad/s^2); if the loop does not end
  within the brake's time and a margin, ``stop()`` sends ``servoStop`` and ``stopJ`` itself.
  Every later ``command`` is refused (:class:`UsageError`);
* :meth:`URBackend.healthy` is False once stopped, after the loop ended, and when the receive
  interface is disconnected or reports a protective or emergency stop, or the control
  script no longer runs.

Joint order: the UR's base, shoulder, elbow, wrist 1-3, the order of RehabBot's UR5e
(``shoulder_pan`` ... ``wrist_3``), so targets pass unchanged; a target outside RehabBot's UR5e
joint ranges is refused. :attr:`RobotState.cuff_force_n` is the norm of the force part of the
controller's TCP force estimate (``getActualTCPForce``); the patient's joints are not measured
(empty arrays).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotState
from rehabbot.deploy.interpolation import (
    BRAKE_DECELERATION_RAD_S2,
    ServoSupervisor,
    brake_duration_s,
    checked_target,
)
from rehabbot.sim.robots import ROBOTS

UR5E = ROBOTS["ur5e"]
N_JOINTS = 6
#: The e-Series controller's servo period [s] (500 Hz).
SERVO_DT_S = 0.002
#: ``servoJ``'s look-ahead time [s] (ur_rtde's range: 0.03-0.2) and proportional gain
#: (100-2000).
LOOKAHEAD_TIME_S = 0.1
GAIN = 300.0
#: Seconds without a new target before the supervisor stops the robot (five policy periods).
WATCHDOG_S = 0.1
#: Seconds without a kick before the controller-side watchdog stops the robot.
CONTROLLER_WATCHDOG_S = 0.1
#: Acceleration cap of every joint [rad/s^2] (UR publishes no joint acceleration limit for
#: servoJ; the Franka backend's cap).
MAX_ACCELERATION_RAD_S2 = 9.0
#: Deceleration of ``stopJ`` [rad/s^2] (of its leading joint) and of ``servoStop`` [m/s^2] (of
#: the tool; ur_rtde's default is 10), sent once the setpoint is at rest.
STOP_DECELERATION_RAD_S2 = 2.0
SERVO_STOP_DECELERATION_M_S2 = 2.0
#: Extra seconds :meth:`URBackend.stop` waits for the loop beyond the brake's own time.
STOP_MARGIN_S = 1.0


def _connect(host: str, frequency_hz: float) -> tuple[Any, Any]:
    try:
        import rtde_control
        import rtde_receive
    except ImportError as err:
        raise UsageError("ur backend: ur_rtde is not installed (pip install 'rehabbot[ur]'): "
                         f"{err}") from None
    try:
        return (rtde_control.RTDEControlInterface(host, frequency_hz),
                rtde_receive.RTDEReceiveInterface(host, frequency_hz))
    except RuntimeError as err:
        raise ConnectionError(f"ur backend: cannot connect to {host!r}: {err}") from None


class URBackend:
    """One UR e-Series arm over RTDE (module docstring).

    ``connect(host, frequency_hz) -> (control, receive)`` makes the two ``ur_rtde``
    interfaces (by default ``RTDEControlInterface`` and ``RTDEReceiveInterface``; tests pass
    fakes). ``record``: keep every ``servoJ`` setpoint (:meth:`trace`).
    """

    joint_names: tuple[str, ...] = tuple(UR5E.joint_names)

    def __init__(self, host: str, *, control_dt_s: float = 0.02, servo_dt_s: float = SERVO_DT_S,
                 lookahead_time_s: float = LOOKAHEAD_TIME_S, gain: float = GAIN,
                 watchdog_s: float = WATCHDOG_S,
                 controller_watchdog_s: float = CONTROLLER_WATCHDOG_S,
                 max_speed_rad_s: Sequence[float] | None = None,
                 max_acceleration_rad_s2: float = MAX_ACCELERATION_RAD_S2,
                 deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2,
                 stop_deceleration_rad_s2: float = STOP_DECELERATION_RAD_S2,
                 record: bool = False,
                 connect: Callable[[str, float], tuple[Any, Any]] = _connect) -> None:
        checks = (("control_dt_s", control_dt_s, control_dt_s > 0.0),
                  ("servo_dt_s", servo_dt_s, 0.0 < servo_dt_s <= control_dt_s),
                  ("lookahead_time_s", lookahead_time_s, 0.03 <= lookahead_time_s <= 0.2),
                  ("gain", gain, 100.0 <= gain <= 2000.0),
                  ("controller_watchdog_s", controller_watchdog_s, controller_watchdog_s > 0.0),
                  ("max_acceleration_rad_s2", max_acceleration_rad_s2,
                   max_acceleration_rad_s2 > 0.0),
                  ("deceleration_rad_s2", deceleration_rad_s2, deceleration_rad_s2 > 0.0),
                  ("stop_deceleration_rad_s2", stop_deceleration_rad_s2,
                   stop_deceleration_rad_s2 > 0.0))
        for name, value, ok in checks:
            if not ok:
                raise UsageError(f"ur backend: {name}={value} is out of range (servo_dt_s in "
                                 "(0, control_dt_s], lookahead_time_s in [0.03, 0.2], gain in "
                                 "[100, 2000], the others positive)")
        speeds = UR5E.max_joint_speed_rad_s if max_speed_rad_s is None else max_speed_rad_s
        speed_cap = np.asarray(speeds, dtype=float)
        if speed_cap.shape != (N_JOINTS,) or not np.all(speed_cap > 0):
            raise UsageError(f"ur backend: max_speed_rad_s must be 6 positive speeds, got "
                             f"{list(speeds)}")
        self.control_dt_s = float(control_dt_s)
        self.servo_dt_s = float(servo_dt_s)
        self.lookahead_time_s = float(lookahead_time_s)
        self.gain = float(gain)
        self.stop_deceleration_rad_s2 = float(stop_deceleration_rad_s2)
        self.deceleration_rad_s2 = float(deceleration_rad_s2)
        self._low, self._high = np.array(UR5E.joint_range_rad, dtype=float).T
        self._control, self._receive = connect(host, 1.0 / self.servo_dt_s)
        self._control.setWatchdog(1.0 / controller_watchdog_s)
        self._lock = threading.Lock()
        self._state = self._read_state(0.0)
        self._supervisor = ServoSupervisor(self._state.q_rad, self.control_dt_s,
                                           float(watchdog_s), speed_cap,
                                           float(max_acceleration_rad_s2),
                                           self.deceleration_rad_s2)
        self._targets: list[np.ndarray] = []
        self._stopped = False
        self._reason: str | None = None
        self.record = record
        self._trace: list[tuple[float, np.ndarray]] = []
        self._thread = threading.Thread(target=self._loop, name="ur-servo", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------------------
    def state(self) -> RobotState:
        with self._lock:
            return self._state

    def command(self, q_target_rad: Any) -> None:
        target = checked_target("ur backend", q_target_rad, self.joint_names, self._low,
                                self._high)
        with self._lock:
            if self._stopped or self._supervisor.stopping or not self._thread.is_alive():
                raise UsageError(f"ur backend: stopped ({self.stop_reason}); commands are "
                                 "refused")
            self._targets.append(target.copy())

    def stop(self) -> None:
        with self._lock:
            self._stopped = True
            supervisor = self._supervisor
            supervisor.request_stop("stop()")
            interpolator = supervisor.interpolator
            wait_s = brake_duration_s(interpolator.v, self.control_dt_s,
                                      self.deceleration_rad_s2, interpolator.a)
        self._thread.join(wait_s + STOP_MARGIN_S)
        if self._thread.is_alive():
            with self._lock:
                self._reason = self._reason or "stop(): the servo loop did not answer"
            self._halt()

    def healthy(self) -> bool:
        with self._lock:
            if self._stopped or self._supervisor.stopping or self._reason is not None:
                return False
        if not self._thread.is_alive():
            return False
        receive, control = self._receive, self._control
        return bool(receive.isConnected() and control.isProgramRunning()
                    and not receive.isProtectiveStopped() and not receive.isEmergencyStopped())

    # ------------------------------------------------------------------------------------------
    @property
    def stop_reason(self) -> str | None:
        """Why the robot stopped (``stop()``, the watchdog, a cap, an error), or None."""
        if self._reason is not None:
            return self._reason
        if self._supervisor.stop_reason is not None:
            return self._supervisor.stop_reason
        return "stop()" if self._stopped else None

    def trace(self) -> dict[str, np.ndarray]:
        """With ``record=True``: every ``servoJ`` call's loop time ``time_s`` [s] and setpoint
        ``setpoint_rad``."""
        with self._lock:
            ticks = list(self._trace)
        return {"time_s": np.array([t[0] for t in ticks]),
                "setpoint_rad": np.array([t[1] for t in ticks]).reshape(-1, N_JOINTS)}

    def close(self) -> None:
        """Stop (if the loop runs) and disconnect both interfaces."""
        if self._thread.is_alive():
            self.stop()
        for interface in (self._control, self._receive):
            with contextlib.suppress(Exception):
                interface.disconnect()

    # ------------------------------------------------------------------------------------------
    def _read_state(self, time_s: float) -> RobotState:
        receive = self._receive
        force = np.asarray(receive.getActualTCPForce(), dtype=float)
        return RobotState(time_s=time_s, q_rad=np.array(receive.getActualQ(), dtype=float),
                          dq_rad_s=np.array(receive.getActualQd(), dtype=float),
                          cuff_force_n=float(np.linalg.norm(force[:3])))

    def _loop(self) -> None:
        control, supervisor = self._control, self._supervisor
        try:
            while True:
                start = control.initPeriod()
                with self._lock:
                    for target in self._targets:
                        if not supervisor.stopping:
                            supervisor.command(target)
                    self._targets.clear()
                    setpoint, finished = supervisor.tick(self.servo_dt_s)
                if finished:
                    self._halt()
                    return
                control.servoJ(setpoint.tolist(), 0.0, 0.0, self.servo_dt_s,
                               self.lookahead_time_s, self.gain)
                control.kickWatchdog()
                state = self._read_state(supervisor.time_s)
                with self._lock:
                    self._state = state
                    if self.record:
                        self._trace.append((supervisor.time_s, setpoint))
                control.waitPeriod(start)
        except Exception as err:
            with self._lock:
                self._reason = (self._reason
                                or f"ur backend: servo loop: {type(err).__name__}: {err}")
            self._halt()

    def _halt(self) -> None:
        """End servo mode and stop every joint (``servoStop``, then ``stopJ``)."""
        with contextlib.suppress(Exception):
            self._control.servoStop(SERVO_STOP_DECELERATION_M_S2)
        with contextlib.suppress(Exception):
            self._control.stopJ(self.stop_deceleration_rad_s2)
