"""The UR backend (rehabbot.deploy.ur) against fakes of ur_rtde's two interfaces: no UR
protocol simulator runs here (URSim is a Docker image). The fakes record every call; the tests
check the servo rate and arguments, the setpoints' continuity and caps, the watchdogs and the
stop sequence."""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotBackend
from rehabbot.deploy.ur import URBackend

Q0 = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
SERVO_DT_S = 0.002


class FakeControl:
    """``RTDEControlInterface``: records calls; ``waitPeriod`` paces to the servo period."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple]] = []
        self.lock = threading.Lock()
        self.q = Q0.copy()
        self.running = True

    def _record(self, name: str, *args: object) -> None:
        with self.lock:
            self.calls.append((name, args))

    def setWatchdog(self, min_frequency: float) -> bool:
        self._record("setWatchdog", min_frequency)
        return True

    def kickWatchdog(self) -> bool:
        self._record("kickWatchdog")
        return True

    def initPeriod(self) -> float:
        return time.perf_counter()

    def waitPeriod(self, start: float) -> None:
        time.sleep(max(0.0, start + SERVO_DT_S - time.perf_counter()))

    def servoJ(self, q: list[float], speed: float, acceleration: float, time_s: float,
               lookahead_time: float, gain: float) -> bool:
        self._record("servoJ", list(q), speed, acceleration, time_s, lookahead_time, gain)
        self.q = np.array(q)
        return True

    def servoStop(self, a: float = 10.0) -> bool:
        self._record("servoStop", a)
        return True

    def stopJ(self, a: float = 2.0, asynchronous: bool = False) -> None:
        self._record("stopJ", a)
        self.running = False

    def isProgramRunning(self) -> bool:
        return self.running

    def disconnect(self) -> None:
        self._record("disconnect")

    def named(self, name: str) -> list[tuple]:
        with self.lock:
            return [args for n, args in self.calls if n == name]

    def names(self) -> list[str]:
        with self.lock:
            return [n for n, _args in self.calls]


class FakeReceive:
    """``RTDEReceiveInterface``: the robot is wherever the last ``servoJ`` sent it."""

    def __init__(self, control: FakeControl) -> None:
        self.control = control
        self.protective_stop = False

    def getActualQ(self) -> list[float]:
        return list(self.control.q)

    def getActualQd(self) -> list[float]:
        return [0.0] * 6

    def getActualTCPForce(self) -> list[float]:
        return [1.0, 2.0, 2.0, 0.5, 0.5, 0.5]

    def isConnected(self) -> bool:
        return True

    def isProtectiveStopped(self) -> bool:
        return self.protective_stop

    def isEmergencyStopped(self) -> bool:
        return False

    def disconnect(self) -> None:
        pass


@pytest.fixture
def robot() -> Iterator[tuple[URBackend, FakeControl, FakeReceive]]:
    control = FakeControl()
    receive = FakeReceive(control)
    frequencies: list[float] = []

    def connect(host: str, frequency_hz: float) -> tuple[FakeControl, FakeReceive]:
        assert host == "192.168.1.10"
        frequencies.append(frequency_hz)
        return control, receive

    backend = URBackend("192.168.1.10", record=True, connect=connect)
    assert frequencies == [pytest.approx(500.0)]
    yield backend, control, receive
    backend.close()


def move(backend: URBackend, amplitude_rad: np.ndarray, periods: int) -> None:
    """Targets ``Q0 + a (1 - cos(2 pi t))`` (a smooth start, 1 Hz), one per control period of
    the wall clock."""
    start = time.perf_counter()
    for k in range(periods):
        t = (k + 1) * backend.control_dt_s
        backend.command(Q0 + amplitude_rad * (1.0 - np.cos(2.0 * np.pi * t)))
        time.sleep(max(0.0, start + (k + 1) * backend.control_dt_s - time.perf_counter()))


def test_servo_rate_arguments_and_continuity(robot: tuple) -> None:
    backend, control, _receive = robot
    assert isinstance(backend, RobotBackend)
    assert backend.joint_names[0] == "shoulder_pan" and backend.control_dt_s == 0.02
    move(backend, np.array([0.05, -0.03, 0.03, 0.0, 0.05, -0.05]), 25)
    assert backend.healthy()
    state = backend.state()
    assert state.cuff_force_n == pytest.approx(3.0) and state.patient_q_rad.size == 0
    backend.stop()
    names = control.names()
    # the controller-side watchdog is armed first (10 Hz: 0.1 s) and kicked after every servoJ
    assert names[0] == "setWatchdog" and control.named("setWatchdog") == [(10.0,)]
    servo = control.named("servoJ")
    assert len(servo) > 200
    assert all(args[1:] == (0.0, 0.0, SERVO_DT_S, 0.1, 300.0) for args in servo)
    kicks = [i for i, n in enumerate(names) if n == "kickWatchdog"]
    assert len(kicks) == len(servo) and all(names[i - 1] == "servoJ" for i in kicks)
    # one servoJ per servo period of the loop's clock
    trace = backend.trace()
    np.testing.assert_allclose(np.diff(trace["time_s"]), SERVO_DT_S, rtol=0, atol=1e-12)
    q = np.array([args[0] for args in servo])
    velocity = np.diff(q, axis=0) / SERVO_DT_S
    acceleration = np.diff(velocity, axis=0) / SERVO_DT_S
    # the targets' top speed is 2 pi 0.05 = 0.31 rad/s, their acceleration 2.0 rad/s^2, the
    # stop's brake decelerates by at most 5 rad/s^2; a jump of the velocity would show as
    # ~0.3 / 0.002 = 150 rad/s^2
    assert np.abs(velocity).max() < 0.4
    assert np.abs(acceleration).max() <= 5.0
    assert np.abs(q - Q0).max() > 0.08  # it followed the targets (0.1 rad at t = 0.5 s)


def test_stop_ends_servo_mode_then_stops_the_joints_and_refuses_commands(robot: tuple) -> None:
    backend, control, _receive = robot
    move(backend, np.full(6, 0.02), 10)
    backend.stop()
    names = control.names()
    assert names[-2:] == ["servoStop", "stopJ"]
    assert "servoJ" not in names[names.index("servoStop"):]
    assert control.named("servoStop") == [(2.0,)] and control.named("stopJ") == [(2.0,)]
    # the setpoint braked to rest before servoStop: its last step is slower than 0.01 rad/s
    # (the targets moved at up to 0.06 rad/s when the stop came)
    servo = control.named("servoJ")
    last_speed = np.abs(np.subtract(servo[-1][0], servo[-2][0])).max() / SERVO_DT_S
    assert last_speed < 0.01
    assert not backend.healthy() and backend.stop_reason == "stop()"
    with pytest.raises(UsageError, match=re.escape("stopped (stop())")):
        backend.command(Q0)


def test_watchdog_stops_the_robot_when_commands_stop(robot: tuple) -> None:
    backend, control, _receive = robot
    move(backend, np.full(6, 0.02), 5)
    started = time.monotonic()
    while "stopJ" not in control.names() and time.monotonic() - started < 3.0:
        time.sleep(0.01)
    assert control.names()[-2:] == ["servoStop", "stopJ"]
    assert not backend.healthy()
    assert backend.stop_reason.startswith("watchdog: no command for 0.1 s")
    with pytest.raises(UsageError, match="watchdog"):
        backend.command(Q0)


def test_a_jump_hits_a_cap_and_nothing_beyond_it_is_sent(robot: tuple) -> None:
    backend, control, _receive = robot
    move(backend, np.full(6, 0.02), 5)
    backend.command(Q0 + 0.5)  # half a radian ahead in one period
    started = time.monotonic()
    while "stopJ" not in control.names() and time.monotonic() - started < 3.0:
        time.sleep(0.01)
    assert "cap" in backend.stop_reason
    q = np.array([args[0] for args in control.named("servoJ")])
    speeds = np.abs(np.diff(q, axis=0)) / SERVO_DT_S
    assert speeds.max() <= np.pi  # RehabBot's UR5e joint speed
    assert control.names()[-2:] == ["servoStop", "stopJ"]


def test_protective_stop_makes_it_unhealthy(robot: tuple) -> None:
    backend, _control, receive = robot
    assert backend.healthy()
    receive.protective_stop = True
    assert not backend.healthy()


def test_bad_input_is_refused_with_the_value(robot: tuple) -> None:
    backend, _control, _receive = robot
    with pytest.raises(UsageError, match=re.escape("shape (7,)")):
        backend.command(np.zeros(7))
    with pytest.raises(UsageError, match=re.escape("target 4.0 rad of elbow")):
        backend.command(np.array([0.0, 0.0, 4.0, 0.0, 0.0, 0.0]))
    with pytest.raises(UsageError, match=re.escape("lookahead_time_s=0.5")):
        URBackend("host", lookahead_time_s=0.5, connect=lambda *_: (None, None))
    with pytest.raises(UsageError, match=re.escape("gain=50")):
        URBackend("host", gain=50, connect=lambda *_: (None, None))
