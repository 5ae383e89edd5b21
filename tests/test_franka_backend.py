"""The Franka backend (rehabbot.deploy.franka) against franka-sim, a server of the libfranka
network protocol on MuJoCo (rehabbot/deploy/franka_sim_server.py; its own venv,
.venv-franka-sim, made by tools/franka-sim-venv.sh): a 10 s joint trajectory tracked at 1 kHz,
a stop that reaches the robot, the watchdog, a policy in shadow mode. Skipped, with the
reason, where the venv or pylibfranka is missing.
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from rehabbot.common.errors import UsageError
from rehabbot.deploy.franka_sim_server import NICENESS, SIM_PYTHON, franka_sim_server

TRACKING_TOLERANCE_RAD = 0.01
#: After stop() returns, the robot's joint speeds must fall below this within REST_WITHIN_S.
REST_SPEED_RAD_S = 0.01
REST_WITHIN_S = 0.5


def tracking_targets(q0: np.ndarray, steps: int, dt_s: float) -> np.ndarray:
    """Targets of a smooth 10 s test motion: ``q0 + a (1 - cos(2 pi f t))`` on every joint (a
    few tenths of a rad, 0.125-0.175 Hz), moving at its fastest when the motion ends."""
    amplitude = np.array([0.2, 0.15, 0.2, 0.2, 0.2, 0.2, 0.2])
    frequency = np.array([0.175, 0.125, 0.175, 0.125, 0.175, 0.125, 0.175])
    t = (np.arange(steps) + 1)[:, None] * dt_s
    return q0 + amplitude * (1.0 - np.cos(2.0 * np.pi * frequency * t))


def command_paced(backend, targets: np.ndarray) -> None:
    """Send one target per control period of the robot's clock (never catching up)."""
    sent_s = None
    for target in targets:
        if sent_s is not None:
            while backend.state().time_s < sent_s + backend.control_dt_s:
                time.sleep(0.0005)
        sent_s = backend.state().time_s
        backend.command(target)


@contextlib.contextmanager
def raised_priority() -> Iterator[None]:
    """A 1 kHz loop on a shared machine: raise this process's priority (the backend's loop
    process inherits it) where allowed, for the test's duration."""
    before = os.getpriority(os.PRIO_PROCESS, 0)
    with contextlib.suppress(PermissionError):
        os.setpriority(os.PRIO_PROCESS, 0, NICENESS)
    try:
        yield
    finally:
        with contextlib.suppress(PermissionError):
            os.setpriority(os.PRIO_PROCESS, 0, before)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    if not SIM_PYTHON.exists():
        pytest.skip(f"no franka-sim venv at {SIM_PYTHON.parent.parent} "
                    "(make it with tools/franka-sim-venv.sh)")
    pytest.importorskip("pylibfranka", reason="pylibfranka is not installed ([franka] extra)")
    with raised_priority(), franka_sim_server(tmp_path_factory.mktemp("franka") / "server.log"):
        yield


def test_bad_settings_are_refused_before_connecting() -> None:
    pytest.importorskip("pylibfranka", reason="pylibfranka is not installed ([franka] extra)")
    from rehabbot.deploy.franka import FrankaBackend

    with pytest.raises(UsageError, match="control_dt_s must be positive, got 0"):
        FrankaBackend("127.0.0.1", control_dt_s=0.0)
    with pytest.raises(UsageError, match=re.escape("watchdog_s=0.01")):
        FrankaBackend("127.0.0.1", watchdog_s=0.01)
    with pytest.raises(UsageError, match="7 positive speeds"):
        FrankaBackend("127.0.0.1", max_speed_rad_s=[1.0] * 6)


@pytest.mark.slow
@pytest.mark.realtime
def test_tracks_a_10_s_trajectory_and_stop_reaches_the_robot(server: None) -> None:
    from rehabbot.deploy.backend import RobotBackend
    from rehabbot.deploy.franka import FrankaBackend

    backend = FrankaBackend("127.0.0.1", record=True, watchdog_s=0.5)
    try:
        assert isinstance(backend, RobotBackend) and backend.healthy()
        q0 = backend.state().q_rad
        steps = round(10.0 / backend.control_dt_s)
        command_paced(backend, tracking_targets(q0, steps, backend.control_dt_s))
        assert backend.healthy(), backend.stop_reason
        moving_rad_s = np.abs(backend.state().dq_rad_s).max()
        started = time.monotonic()
        backend.stop()
        stop_s = time.monotonic() - started
        assert not backend.healthy() and backend.stop_reason == "stop()"
        rest_s = None
        while time.monotonic() - started < stop_s + REST_WITHIN_S:
            if np.abs(backend.state().dq_rad_s).max() < REST_SPEED_RAD_S:
                rest_s = time.monotonic() - started
                break
            time.sleep(0.005)
        with pytest.raises(UsageError, match=re.escape("stopped (stop())")):
            backend.command(q0)
        trace = backend.trace()
    finally:
        backend.close()
    # the robot measures at tick i what the setpoint of tick i - 1 made of it
    error = np.abs(trace["q_rad"][1:] - trace["setpoint_rad"][:-1]).max()
    assert error <= TRACKING_TOLERANCE_RAD
    assert np.ptp(trace["setpoint_rad"], axis=0).min() > 0.1  # every joint moved
    assert moving_rad_s > 0.1  # the stop came while the robot moved
    assert stop_s < 1.0 and rest_s is not None


@pytest.mark.slow
@pytest.mark.realtime
def test_watchdog_stops_the_robot_when_commands_stop(server: None) -> None:
    from rehabbot.deploy.franka import FrankaBackend

    backend = FrankaBackend("127.0.0.1")
    try:
        q0 = backend.state().q_rad
        with pytest.raises(UsageError, match="outside its range"):
            backend.command(q0 + np.array([0, 0, 0, 5.0, 0, 0, 0]))
        with pytest.raises(UsageError, match=re.escape("shape (6,)")):
            backend.command(q0[:6])
        command_paced(backend, tracking_targets(q0, 25, backend.control_dt_s))
        started = time.monotonic()
        while backend.healthy() and time.monotonic() - started < 2.0:
            time.sleep(0.005)
        assert not backend.healthy()
        assert backend.stop_reason.startswith("watchdog: no command for 0.1 s")
        with pytest.raises(UsageError, match="watchdog"):
            backend.command(q0)
        time.sleep(REST_WITHIN_S)
        assert np.abs(backend.state().dq_rad_s).max() < REST_SPEED_RAD_S
    finally:
        backend.close()


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.xfail(strict=False, reason=(
    "known intermittent fault: after the two other realtime tests, franka-sim aborts about half "
    "of these sessions with joint_motion_generator_acceleration_discontinuity late in the "
    "motion (last setpoint at rest in speed but accelerating at about 5 rad/s^2, the brake's "
    "deceleration); the cause in the supervisor's stop is not found yet"))
def test_a_policy_runs_in_shadow_mode_on_franka_sim(server: None, tmp_path: Path) -> None:
    """rehabbot deploy on franka-sim: the FR3 hip agent, its simulator twin computing the
    observation, every command through both filters to the robot, to the episode's end with no
    robot fault (acceleration cap, velocity discontinuity, watchdog). Whether the agent also
    finishes the exercise depends on how the robot's filter clipped the commands, which
    depends on the robot's timing: not asserted."""
    from rehabbot.deploy.launch import deploy
    from rehabbot.deploy.session_log import read_session

    result = deploy("zoo:rehab-hip-v2/ppo-fr3", tmp_path / "session", "franka",
                    robot_ip="127.0.0.1", robot_watchdog_s=0.5,
                    filter_settings={"hold_fraction": 0.8, "back_off_fraction": 0.9})
    assert result.status == "completed", result.reason
    session = read_session(tmp_path / "session")
    episode = session.episodes[0]
    assert episode.end in ("terminated", "truncated")
    assert np.all(episode["stepped"]) and episode.decisions > 100
    assert episode.shadow and np.all(np.isfinite(episode["robot_q_rad"]))
