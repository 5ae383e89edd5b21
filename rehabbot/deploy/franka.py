"""A Franka FR3 behind :class:`rehabbot.deploy.backend.RobotBackend`, on ``pylibfranka``.

``pylibfranka`` is Franka's own Python binding of libfranka (the ``[franka]`` extra). The robot
runs a 1 kHz loop: every millisecond it sends its state and expects a joint-position setpoint
back, and it aborts the motion (a reflex) when the setpoints' velocity, acceleration or jerk
jump or exceed the joint limits. The backend therefore:

* **runs the 1 kHz loop in its own process** (started with the backend; it owns the
  connection): Python threads share one interpreter lock, and a policy's inference, a log
  write or a garbage collection in the caller's process would stall a loop thread for
  milliseconds. The caller's :meth:`FrankaBackend.command` sends the target through a pipe;
  the state comes back through shared memory;
* starts a joint-position motion (the robot's joint impedance controller) at the first
  command and answers every state of the loop with a setpoint of
  :class:`rehabbot.deploy.interpolation.ServoSupervisor`: the policy's targets (one per
  ``control_dt_s``) joined by quintic segments with continuous velocity and acceleration,
  advanced by the time the robot says has passed (a lost cycle counts);
* **watchdog**: no new target for ``watchdog_s`` (0.1 s, five policy periods, by the robot's
  clock): the setpoint brakes to rest and the motion finishes; the backend is then stopped;
* **speed and acceleration caps**: a setpoint faster than a joint's cap (the FR3's rated joint
  speeds by default) or accelerating more than 9 rad/s^2 (the FCI aborts at 10) is not sent;
  the setpoint brakes from the last one sent and the motion finishes. Near a position limit,
  where the robot allows only the speed that stops in time
  (:func:`rehabbot.sim.robots.fr3.speed_envelope_rad_s`), setpoints are rate-limited to it;
* :meth:`FrankaBackend.stop`: the same brake, then the motion finishes (``motion_finished``
  on the last setpoint, so the robot holds still under its controller) and the loop calls
  libfranka's ``Robot.stop()``; ``stop()`` waits for that. If the loop does not answer within
  the brake's time and a margin, its process is ended, which drops the connection (the robot
  then stops on its own communication check). Every later ``command`` is refused
  (:class:`UsageError`);
* :meth:`FrankaBackend.healthy` is False once stopped, after the loop ended for any reason (a
  reflex, a lost connection: the message is in :attr:`FrankaBackend.stop_reason`) and while
  the robot reports a mode other than idle or moving (a reflex, the user stop).

Joint order: the FR3's ``joint1..joint7``, the same joints and order as RehabBot's FR3
(``fr3_joint1..7``, :data:`rehabbot.sim.robots.ROBOTS`), so targets pass unchanged; a target
outside RehabBot's FR3 joint ranges is refused. :attr:`RobotState.cuff_force_n` is the norm of
the force of libfranka's estimated external wrench at the end effector (``O_F_ext_hat_K``),
the cuff's force where the cuff is the end effector; the patient's joints are not measured
(empty arrays).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import time
from collections.abc import Sequence
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
from rehabbot.sim.robots.fr3 import speed_envelope_rad_s

FR3 = ROBOTS["fr3"]
N_JOINTS = 7
#: Seconds without a new target before the watchdog stops the robot (five policy periods).
WATCHDOG_S = 0.1
#: Acceleration cap of every joint [rad/s^2], below the FCI's joint-position limit of 10.
MAX_ACCELERATION_RAD_S2 = 9.0
#: Extra seconds :meth:`FrankaBackend.stop` waits for the loop beyond the brake's own time.
STOP_MARGIN_S = 1.0
#: Seconds the backend waits for its loop process to connect.
CONNECT_TIMEOUT_S = 30.0
#: Seconds :meth:`FrankaBackend.trace` waits for the loop process's answer.
TRACE_TIMEOUT_S = 10.0
#: Seconds between two state reads while no motion runs.
IDLE_READ_S = 0.01
#: Robot modes (``pylibfranka.RobotMode`` names) in which the robot can move on command.
HEALTHY_MODES = ("Idle", "Move")

# The shared state: time, q, dq, cuff force, then flags (see _Shared).
_TIME, _Q, _DQ = 0, slice(1, 8), slice(8, 15)
_FORCE, _MOVING, _STOPPING, _FINISHED, _MODE_OK, _SIZE = 15, 16, 17, 18, 19, 20


class FrankaBackend:
    """One Franka robot over the FCI (module docstring).

    ``host``: the robot's (or a protocol simulator's) address. ``realtime``: ask libfranka to
    enforce a real-time kernel (``RealtimeConfig.kEnforce``; False: ``kIgnore``).
    ``record``: keep every servo tick and command (:meth:`trace`).
    """

    joint_names: tuple[str, ...] = tuple(FR3.joint_names)

    def __init__(self, host: str, *, control_dt_s: float = 0.02, watchdog_s: float = WATCHDOG_S,
                 max_speed_rad_s: Sequence[float] | None = None,
                 max_acceleration_rad_s2: float = MAX_ACCELERATION_RAD_S2,
                 deceleration_rad_s2: float = BRAKE_DECELERATION_RAD_S2,
                 realtime: bool = False, record: bool = False) -> None:
        if not control_dt_s > 0.0:
            raise UsageError(f"franka backend: control_dt_s must be positive, got {control_dt_s}")
        if not watchdog_s >= control_dt_s:
            raise UsageError(f"franka backend: watchdog_s={watchdog_s} must be at least one "
                             f"control period ({control_dt_s} s)")
        speeds = FR3.max_joint_speed_rad_s if max_speed_rad_s is None else max_speed_rad_s
        speed_cap = np.asarray(speeds, dtype=float)
        if speed_cap.shape != (N_JOINTS,) or not np.all(speed_cap > 0):
            raise UsageError(f"franka backend: max_speed_rad_s must be 7 positive speeds, got "
                             f"{list(speeds)}")
        for name, value in (("max_acceleration_rad_s2", max_acceleration_rad_s2),
                            ("deceleration_rad_s2", deceleration_rad_s2)):
            if not value > 0.0:
                raise UsageError(f"franka backend: {name} must be positive, got {value}")
        _import_pylibfranka()
        self.control_dt_s = float(control_dt_s)
        self.deceleration_rad_s2 = float(deceleration_rad_s2)
        self._low, self._high = np.array(FR3.joint_range_rad, dtype=float).T
        self._stopped = False
        self._reason: str | None = None
        self._trace: dict[str, np.ndarray] | None = None
        context = multiprocessing.get_context("spawn")
        self._shared = context.Array("d", _SIZE)
        self._conn, child = context.Pipe()
        settings = {"host": host, "realtime": realtime, "record": record,
                    "control_dt_s": self.control_dt_s, "watchdog_s": float(watchdog_s),
                    "max_speed_rad_s": speed_cap.tolist(),
                    "max_acceleration_rad_s2": float(max_acceleration_rad_s2),
                    "deceleration_rad_s2": self.deceleration_rad_s2}
        self._process = context.Process(target=_serve, args=(settings, child, self._shared),
                                        name="franka-1kHz", daemon=True)
        self._process.start()
        child.close()
        if not self._conn.poll(CONNECT_TIMEOUT_S):
            self._end_process()
            raise ConnectionError(f"franka backend: no answer from {host!r} within "
                                  f"{CONNECT_TIMEOUT_S} s")
        try:
            kind, message = self._conn.recv()
        except EOFError:
            kind, message = "error", f"the loop process ended (exit {self._process.exitcode})"
        if kind != "ready":
            self._end_process()
            raise ConnectionError(f"franka backend: cannot connect to {host!r}: {message}")

    # ------------------------------------------------------------------------------------------
    def state(self) -> RobotState:
        with self._shared.get_lock():
            values = np.array(self._shared[:])
        return RobotState(time_s=float(values[_TIME]), q_rad=values[_Q].copy(),
                          dq_rad_s=values[_DQ].copy(), cuff_force_n=float(values[_FORCE]))

    def command(self, q_target_rad: Any) -> None:
        target = checked_target("franka backend", q_target_rad, self.joint_names, self._low,
                                self._high)
        self._collect()
        if self._stopped or self._shared[_STOPPING] or not self._process.is_alive():
            if self._reason is None and self._conn.poll(STOP_MARGIN_S):
                self._collect()  # the loop's message on why follows its flag
            raise UsageError(f"franka backend: stopped ({self.stop_reason}); commands are "
                             "refused")
        self._conn.send(("target", target))

    def stop(self) -> None:
        self._stopped = True
        if not self._process.is_alive():
            return
        speed = np.array(self._shared[_DQ])
        wait_s = brake_duration_s(speed, self.control_dt_s, self.deceleration_rad_s2)
        with contextlib.suppress(OSError):
            self._conn.send(("stop", None))
        deadline = time.monotonic() + wait_s + STOP_MARGIN_S
        while time.monotonic() < deadline and self._process.is_alive():
            if self._shared[_FINISHED]:
                break
            time.sleep(0.002)
        self._collect()
        if not self._shared[_FINISHED] and self._shared[_MOVING]:
            self._reason = self._reason or "stop(): the loop did not answer; its process ended"
            self._end_process()

    def healthy(self) -> bool:
        self._collect()
        shared = self._shared
        return bool(not self._stopped and self._process.is_alive() and not shared[_STOPPING]
                    and shared[_MODE_OK])

    # ------------------------------------------------------------------------------------------
    @property
    def stop_reason(self) -> str | None:
        """Why the robot stopped (``stop()``, the watchdog, a cap, an error), or None."""
        self._collect()
        if self._reason is not None:
            return self._reason
        if not self._process.is_alive():
            return "the loop process ended"
        return "stop()" if self._stopped else None

    def trace(self) -> dict[str, np.ndarray]:
        """With ``record=True``, once the motion finished: every servo tick's loop time
        ``time_s`` [s], the setpoint ``setpoint_rad`` sent on it and the ``q_rad`` and
        ``dq_rad_s`` measured before it; every command's loop time ``command_time_s`` and
        target ``command_rad``."""
        self._collect()
        if self._trace is None and not self._shared[_MOVING] and self._process.is_alive():
            with contextlib.suppress(OSError):
                self._conn.send(("trace", None))
                if self._conn.poll(TRACE_TIMEOUT_S):
                    self._collect()
        if self._trace is None:
            raise UsageError("franka backend: no trace (record=False, or the motion has not "
                             "finished: stop() first)")
        return self._trace

    def close(self) -> None:
        """Stop (if moving) and end the loop process (it lets go of the connection)."""
        if self._process.is_alive():
            if self._shared[_MOVING]:
                self.stop()
            with contextlib.suppress(OSError):
                self._conn.send(("close", None))
            self._process.join(STOP_MARGIN_S)
        self._end_process()
        self._collect()

    # ------------------------------------------------------------------------------------------
    def _collect(self) -> None:
        """Read what the loop process reported (stop reasons, the trace)."""
        try:
            while self._conn.poll():
                kind, message = self._conn.recv()
                if kind in ("stopping", "stopped", "error") and self._reason is None:
                    self._reason = message
                elif kind == "trace" and message is not None:
                    self._trace = {k: np.asarray(v) for k, v in message.items()}
        except (EOFError, OSError):
            pass

    def _end_process(self) -> None:
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(STOP_MARGIN_S)
            if self._process.is_alive():
                self._process.kill()
                self._process.join()


def _import_pylibfranka() -> Any:
    try:
        import pylibfranka
    except ImportError as err:
        raise UsageError("franka backend: pylibfranka is not installed (pip install "
                         f"'rehabbot[franka]'): {err}") from None
    return pylibfranka


# ----------------------------------------------------------------------------------------------
# The loop process.

def _publish(shared: Any, state: Any, time_s: float) -> None:
    wrench = state.O_F_ext_hat_K
    mode = getattr(state.robot_mode, "name", str(state.robot_mode))
    with shared.get_lock():
        shared[_TIME] = time_s
        shared[_Q] = list(state.q)
        shared[_DQ] = list(state.dq)
        shared[_FORCE] = float(np.linalg.norm(np.asarray(wrench, dtype=float)[:3]))
        shared[_MODE_OK] = 1.0 if mode in HEALTHY_MODES else 0.0


def _serve(settings: dict[str, Any], conn: Any, shared: Any) -> None:
    """The loop process: connect, start the motion (holding still until the first target), run
    it until it finishes, then publish the state until the backend closes."""
    import pylibfranka

    config = (pylibfranka.RealtimeConfig.kEnforce if settings["realtime"]
              else pylibfranka.RealtimeConfig.kIgnore)
    try:
        robot = pylibfranka.Robot(settings["host"], config)
        state = robot.read_once()
        _publish(shared, state, 0.0)
        control = robot.start_joint_position_control(pylibfranka.ControllerMode.JointImpedance)
    except Exception as err:
        conn.send(("error", f"{type(err).__name__}: {err}"))
        return
    shared[_MOVING] = 1.0
    conn.send(("ready", None))
    trace = _move(robot, control, settings, conn, shared, np.array(state.q, dtype=float))
    while True:  # after the motion: publish the state, answer for the trace, until closed
        if conn.poll(IDLE_READ_S):
            kind, _payload = conn.recv()
            if kind == "close":
                return
            if kind == "trace":
                conn.send(("trace", trace))
        try:
            _publish(shared, robot.read_once(), shared[_TIME])
        except Exception as err:
            conn.send(("error", f"read_once: {type(err).__name__}: {err}"))
            shared[_MODE_OK] = 0.0
            return


def _move(robot: Any, control: Any, settings: dict[str, Any], conn: Any, shared: Any,
          q0: np.ndarray) -> dict[str, np.ndarray] | None:
    """The motion: hold ``q0``, follow the targets, until it finishes (or fails); its trace
    (with ``record``)."""
    import pylibfranka

    record = settings["record"]
    ticks: list[tuple[float, list[float], list[float], list[float]]] = []
    commands: list[tuple[float, np.ndarray]] = []
    supervisor = ServoSupervisor(q0, settings["control_dt_s"], settings["watchdog_s"],
                                 settings["max_speed_rad_s"], settings["max_acceleration_rad_s2"],
                                 settings["deceleration_rad_s2"], speed_envelope_rad_s)
    try:
        first = True
        while True:
            state, period = control.readOnce()
            # the first period counts from the last read before the motion: not a tick
            elapsed_s = 0.0 if first else period.to_sec()
            first = False
            while conn.poll():
                kind, payload = conn.recv()
                if kind == "target" and not supervisor.stopping:
                    supervisor.command(payload)
                    if record:
                        commands.append((supervisor.time_s, payload))
                elif kind in ("stop", "close"):
                    supervisor.request_stop("stop()")
            setpoint, finished = supervisor.tick(elapsed_s)
            if supervisor.stopping and not shared[_STOPPING]:
                conn.send(("stopping", supervisor.stop_reason))  # before the flag: no race
                shared[_STOPPING] = 1.0
            _publish(shared, state, supervisor.time_s)
            if record:
                ticks.append((supervisor.time_s, setpoint.tolist(), list(state.q),
                              list(state.dq)))
            command = pylibfranka.JointPositions(setpoint.tolist())
            command.motion_finished = finished
            control.writeOnce(command)
            if finished:
                break
        del control
        robot.stop()
        conn.send(("stopped", supervisor.stop_reason))
    except Exception as err:
        p, v, a = supervisor.sent
        conn.send(("error", f"control loop: {type(err).__name__}: {err} (at "
                            f"{supervisor.time_s:.3f} s of the motion; last setpoint "
                            f"{np.round(p, 4).tolist()} rad, {np.round(v, 3).tolist()} rad/s, "
                            f"{np.round(a, 2).tolist()} rad/s^2)"))
        shared[_STOPPING] = 1.0
    finally:
        shared[_MOVING] = 0.0
        shared[_FINISHED] = 1.0
    if not record:
        return None
    return {"time_s": np.array([t[0] for t in ticks]),
            "setpoint_rad": np.array([t[1] for t in ticks]).reshape(-1, N_JOINTS),
            "q_rad": np.array([t[2] for t in ticks]).reshape(-1, N_JOINTS),
            "dq_rad_s": np.array([t[3] for t in ticks]).reshape(-1, N_JOINTS),
            "command_time_s": np.array([c[0] for c in commands]),
            "command_rad": np.array([c[1] for c in commands]).reshape(-1, N_JOINTS)}
