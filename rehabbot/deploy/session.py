"""The deployment loop: a policy, the deployment safety filter and a robot, one decision per
control period, every decision logged (:mod:`rehabbot.deploy.session_log`).

Each decision: read the state; the policy acts on its observation; the action becomes joint
targets by the env's own law
(:meth:`~rehabbot.deploy.simulator.SimulatorBackend.policy_target`); the safety filter checks
them against the state and passes, clips, holds, backs off or stops; the filtered targets are
sent. On the simulator backend alone the observation is the simulator's, so a filter that
passes every decision reproduces ``env.step`` bit for bit (same observations, rewards, target
switches).

**Shadow mode** (a real robot, or a robot backend that stands in for one): a robot measures
its own joints but neither the patient's joints nor the targets the policy needs, so the
simulator runs beside it as its *twin*. The twin computes the observation and the policy's
targets as in simulation; the command goes through a filter on the twin's state and then
through a second filter on the robot's measured state (the more severe verdict wins), and the
result goes to both. The log keeps the robot's measured joints beside the twin's and their
difference (the tracking error). Before each episode the robot is moved to the twin's start
pose, a straight line at ``approach_speed_rad_s`` and ``approach_accel_rad_s2`` through the
robot's filter, within ``approach_timeout_s``, unless it is within ``start_tolerance_rad``.
The twin's patient is a model: without one fitted to the real patient (``rehabbot
calibrate``) and sensors for the patient's joints, the twin's patient joints and cuff force
are predictions, not measurements; only the robot filter's check of the measured joints (and
the robot's own force estimate, where it has one) is about the real patient.

The session ends when its episodes are done (``completed``), when a filter answers ``stop``
or the robot reports itself unhealthy (``stopped``: both backends are stopped at once), on
SIGINT/SIGTERM (``interrupted``: the signal is latched and acted on between two decisions,
:mod:`rehabbot.common.signals`; a second one stops at once) or on an error (``failed``). In
every case the robot is stopped and the log closed with the episode that was running.
"""

from __future__ import annotations

import contextlib
import dataclasses
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import RehabbotError, UsageError
from rehabbot.common.signals import SignalLatch, handling_signals
from rehabbot.deploy.backend import RobotBackend, RobotState
from rehabbot.deploy.safety_filter import FilterDecision, SafetyFilter
from rehabbot.deploy.session_log import (
    FILTER_ACTIONS,
    EpisodeRecorder,
    SessionLogWriter,
    episode_constants,
)
from rehabbot.deploy.simulator import SimulatorBackend
from rehabbot.rl.policies import LoadedPolicy

SEVERITY = {action: rank for rank, action in enumerate(FILTER_ACTIONS)}
TICK_SLACK_S = 1e-6  # a control period has come when this little of it is left


class DeploymentError(RehabbotError, RuntimeError):
    """The robot could not be brought to where a session needs it (exit 1 in the CLI)."""


class SessionInterrupted(Exception):  # noqa: N818  (not an error)
    """SIGINT or SIGTERM ended a session; the robot was stopped and the log closed."""

    def __init__(self, out_dir: Path | None, signum: int) -> None:
        known = {member.value: member.name for member in signal.Signals}
        name = known.get(signum, f"signal {signum}")
        where = f"; its log: {out_dir}" if out_dir is not None else ""
        super().__init__(f"deployment session interrupted by {name}: the robot was stopped"
                         f"{where}")
        self.out_dir = out_dir
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


@dataclass(frozen=True)
class SessionSettings:
    """How a session runs (the approach's settings: module docstring).
    ``pace``: wait for each control period of the robot (None: only in shadow mode; the
    simulator alone runs as fast as it can)."""

    deterministic: bool = True
    start_tolerance_rad: float = 0.02
    approach_speed_rad_s: float = 0.2
    approach_accel_rad_s2: float = 0.5
    approach_timeout_s: float = 60.0
    pace: bool | None = None

    def __post_init__(self) -> None:
        for name in ("start_tolerance_rad", "approach_speed_rad_s", "approach_accel_rad_s2",
                     "approach_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise UsageError(f"session setting {name}={value!r} must be a number > 0")


@dataclass
class SessionResult:
    """How a session ended (``status``, ``reason``) and its episodes' lines in ``session.json``."""

    status: str
    reason: str | None
    episodes: list[dict[str, Any]] = field(default_factory=list)
    out_dir: Path | None = None
    recorders: list[EpisodeRecorder] = field(default_factory=list)


@dataclass(frozen=True)
class Verdict(FilterDecision):
    """The decision sent: a filter's, or in shadow mode both filters' (:func:`combine`)."""

    twin_action: str | None = None
    robot_action: str | None = None


def checked_decision(decision: Any, who: str, n_joints: int) -> FilterDecision:
    """``decision`` once checked: a known action and ``n_joints`` finite joint targets.

    Raises:
        UsageError: naming the filter (``who``) and what it answered.
    """
    action = getattr(decision, "action", None)
    if action not in SEVERITY:
        raise UsageError(f"{who} filter answered action {action!r}; expected one of "
                         f"{list(FILTER_ACTIONS)}")
    q = np.asarray(getattr(decision, "q_rad", None), dtype=float)
    if q.shape != (n_joints,) or not np.all(np.isfinite(q)):
        raise UsageError(f"{who} filter answered joint targets {q.tolist()}; expected "
                         f"{n_joints} finite numbers")
    return decision


def combine(twin: FilterDecision, robot: FilterDecision | None) -> Verdict:
    """One verdict of the twin's filter and the robot's (shadow mode): the robot filter's
    targets (it filtered the twin filter's), the more severe action, both filters' reasons
    (prefixed ``twin:`` and ``robot:``)."""
    if robot is None:
        return Verdict(np.asarray(twin.q_rad, dtype=float), twin.action, tuple(twin.reasons))
    worst = max(twin.action, robot.action, key=SEVERITY.__getitem__)
    reasons = tuple(f"twin: {r}" for r in twin.reasons) + tuple(f"robot: {r}"
                                                                 for r in robot.reasons)
    return Verdict(np.asarray(robot.q_rad, dtype=float), worst, reasons, twin.action,
                    robot.action)


class DeploymentSession:
    """Runs a policy through the filter(s) on the twin and, in shadow mode, on a robot.

    ============================  =========================================================
    ``policy``                    a :class:`~rehabbot.rl.policies.LoadedPolicy` of the
                                  twin's env
    ``twin``                      the simulator backend (the observation's source,
                                  :class:`~rehabbot.deploy.simulator.SimulatorBackend`)
    ``twin_filter``               the filter that checks commands against the twin's state
                                  (a :class:`~rehabbot.deploy.safety_filter.SafetyFilter`,
                                  or anything with its ``reset`` and ``filter``)
    ``robot``, ``robot_filter``   shadow mode: the robot backend and its own filter (both or
                                  neither)
    ``log``                       where the session is written (None: kept in memory only,
                                  ``SessionResult.recorders``)
    ``clock``, ``sleep``          the time source used for pacing and ``wall_s``
    ============================  =========================================================
    """

    def __init__(self, policy: LoadedPolicy, twin: SimulatorBackend, twin_filter: SafetyFilter,
                 *, robot: RobotBackend | None = None, robot_filter: SafetyFilter | None = None,
                 log: SessionLogWriter | None = None,
                 settings: SessionSettings | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if (robot is None) != (robot_filter is None):
            raise UsageError("shadow mode needs both a robot backend and its filter")
        if robot is not None:
            if tuple(robot.joint_names) and len(robot.joint_names) != len(twin.joint_names):
                raise UsageError(f"the robot has {len(robot.joint_names)} joints "
                                 f"{list(robot.joint_names)}, the simulator's robot "
                                 f"{len(twin.joint_names)} {list(twin.joint_names)}: pass the "
                                 "env kwarg robot= that matches it")
            if not np.isclose(robot.control_dt_s, twin.control_dt_s, rtol=1e-9, atol=0.0):
                raise UsageError(f"the robot's control period {robot.control_dt_s!r} s is not "
                                 f"the env's decision period {twin.control_dt_s!r} s")
        self.policy = policy
        self.twin = twin
        self.twin_filter = twin_filter
        self.robot = robot
        self.robot_filter = robot_filter
        self.log = log
        self.settings = settings or SessionSettings()
        self.clock = clock
        self.sleep = sleep
        self.shadow = robot is not None
        self._pace = self.settings.pace if self.settings.pace is not None else self.shadow
        self._next_tick: float | None = None

    # ------------------------------------------------------------------------------------------
    def run(self, episodes: int, seed: int | None = 0) -> SessionResult:
        """Run ``episodes`` episodes (episode k reset with ``seed + k``; None: unseeded).

        Returns the session's result; the log (if any) is closed in every case.

        Raises:
            SessionInterrupted: SIGINT/SIGTERM (after the robot was stopped and the log
                closed).
            DeploymentError: the robot did not reach an episode's start pose in time.
            PolicyError, UsageError, ...: whatever failed (after the same).
        """
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
            raise UsageError(f"episodes={episodes!r} must be an integer >= 1")
        latch = SignalLatch("stopping the robot and closing the session log")
        result = SessionResult(status="running", reason=None,
                               out_dir=self.log.out_dir if self.log is not None else None)
        recorder: EpisodeRecorder | None = None
        try:
            with handling_signals(latch):
                for index in range(episodes):
                    if latch.signum is not None:  # between two episodes
                        result.status, result.reason = "interrupted", "a signal came"
                        break
                    episode_seed = None if seed is None else seed + index
                    recorder = EpisodeRecorder(index, episode_seed, {}, self.shadow)
                    self._run_episode(recorder, episode_seed, latch)
                    self._finish_episode(recorder, result)
                    recorder = None
                    if result.status != "running":
                        break
                else:
                    result.status = "completed"
                self._stop_all()
        except BaseException as err:
            self._fail(result, recorder, err)
            raise
        self._close(result)
        if result.status == "interrupted":
            raise SessionInterrupted(result.out_dir, latch.signum or signal.SIGINT)
        return result

    def _fail(self, result: SessionResult, recorder: EpisodeRecorder | None,
              err: BaseException) -> None:
        """After an error or a second signal: stop the robot, write the running episode and
        close the log, without hiding ``err`` (a failure of these is added to the reason)."""
        interrupted = isinstance(err, KeyboardInterrupt)
        result.status = "interrupted" if interrupted else "failed"
        result.reason = ("a second signal stopped the session at once" if interrupted
                         else f"{type(err).__name__}: {err}")
        try:
            self._stop_all()
        except Exception as stop_err:
            result.reason += f"; stopping the robot failed: {type(stop_err).__name__}: {stop_err}"
        if recorder is not None:
            recorder.end = "interrupted" if interrupted else "failed"
            try:
                self._finish_episode(recorder, result, keep_status=True)
            except Exception as log_err:
                result.reason += f"; writing the episode failed: {log_err}"
        with contextlib.suppress(Exception):
            self._close(result)

    # ------------------------------------------------------------------------------------------
    def _run_episode(self, rec: EpisodeRecorder, seed: int | None, latch: SignalLatch) -> None:
        twin, robot = self.twin, self.robot
        obs, info = twin.reset(seed=seed)
        rec.constants = episode_constants(twin)
        if robot is not None and not self._approach(rec, latch):
            rec.state(twin.state(), obs, int(info["target_index"]), robot.state())
            return
        # The robot's filter was reset by the approach and has followed its commands since:
        # the episode's first command continues from the approach's last one.
        self.twin_filter.reset(twin_reset_state(twin))
        target_index = int(info["target_index"])
        n_joints = len(twin.joint_names)
        space = twin.env.action_space
        self._next_tick = None
        while True:
            start = self.clock()
            twin_state = twin.state()
            robot_state = robot.state() if robot is not None else None
            rec.state(twin_state, obs, target_index, robot_state)
            if rec.end is not None:
                return
            if latch.signum is not None:
                rec.end = "interrupted"
                continue
            if robot is not None and not robot.healthy():
                rec.end = "robot_fault"
                self._stop_all()
                continue
            action = self.policy.act(obs, deterministic=self.settings.deterministic,
                                     action_space=space)
            q_policy = twin.policy_target(action)
            verdict = self._decide(twin_state, robot_state, q_policy, n_joints)
            if verdict.action == "stop":
                self._stop_all()
                rec.decision(action, q_policy, verdict.q_rad, verdict.action, verdict.reasons,
                             False, float("nan"), False, self.clock() - start, None,
                             verdict.twin_action, verdict.robot_action)
                rec.end = "filter_stop"
                continue
            if robot is not None:
                robot.command(verdict.q_rad)
            twin.command(verdict.q_rad)
            obs, reward, terminated, truncated, info = twin.last_step
            target_index = int(info["target_index"])
            rec.decision(action, q_policy, verdict.q_rad, verdict.action, verdict.reasons,
                         True, float(reward), bool(info.get("is_success", False)),
                         self.clock() - start, info.get("safety_violation"),
                         verdict.twin_action, verdict.robot_action)
            if terminated or truncated:
                rec.end = "terminated" if terminated else "truncated"
            else:
                self._wait_for_period()

    def _decide(self, twin_state: RobotState, robot_state: RobotState | None,
                q_policy: np.ndarray, n_joints: int) -> Verdict:
        first = checked_decision(self.twin_filter.filter(twin_state, q_policy,
                                                         twin_state.time_s), "twin", n_joints)
        second = None
        if robot_state is not None:
            second = checked_decision(
                self.robot_filter.filter(robot_state, np.asarray(first.q_rad, dtype=float),
                                         robot_state.time_s), "robot", n_joints)
        return combine(first, second)

    def _approach(self, rec: EpisodeRecorder, latch: SignalLatch) -> bool:
        """Move the robot to the twin's start pose (shadow mode: its servo setpoints, where
        the first command starts from) along a straight line in joint space, the largest
        joint at ``approach_speed_rad_s`` at most, speeding up and slowing down at
        ``approach_accel_rad_s2`` (at most twice that in the last period), each command through
        the robot's filter, until the line is done and every joint is within
        ``start_tolerance_rad``. False when the filter or a fault stopped it, or a
        signal came.

        Raises:
            DeploymentError: not there within ``approach_timeout_s`` (the robot is stopped).
        """
        robot, settings = self.robot, self.settings
        goal = twin_reset_state(self.twin).q_rad
        state = robot.state()
        rec.approach(None, state.q_rad)
        start = np.array(state.q_rad, dtype=float)
        distance = float(np.max(np.abs(goal - start)))
        self.robot_filter.reset(state)
        if distance <= settings.start_tolerance_rad:
            return True
        dt, accel = robot.control_dt_s, settings.approach_accel_rad_s2
        travelled, speed = 0.0, 0.0
        self._next_tick = None
        for _ in range(int(np.ceil(settings.approach_timeout_s / dt))):
            if latch.signum is not None or not robot.healthy():
                rec.end = "interrupted" if latch.signum is not None else "robot_fault"
                self._stop_all()
                return False
            speed = min(speed + accel * dt, settings.approach_speed_rad_s,
                        np.sqrt(2.0 * accel * max(distance - travelled, 0.0)))
            travelled = min(travelled + speed * dt, distance)
            command = start + (goal - start) * (travelled / distance)
            decision = checked_decision(self.robot_filter.filter(state, command, state.time_s),
                                        "robot", len(goal))
            if decision.action == "stop":
                rec.end = "filter_stop"
                self._stop_all()
                return False
            robot.command(np.asarray(decision.q_rad, dtype=float))
            self._wait_for_period()
            state = robot.state()
            rec.approach(decision.q_rad, state.q_rad, decision.action, decision.reasons)
            if travelled == distance and np.max(np.abs(state.q_rad - goal)) <= \
                    settings.start_tolerance_rad:  # at rest at the start pose
                return True
        self._stop_all()
        raise DeploymentError(
            f"the robot did not reach the episode's start pose within "
            f"{settings.approach_timeout_s:g} s (largest joint gap "
            f"{np.max(np.abs(state.q_rad - goal)):.4f} rad, tolerance "
            f"{settings.start_tolerance_rad:g} rad); it was stopped")

    def _wait_for_period(self) -> None:
        """Wait for the next control period (pacing only): by the robot's clock in shadow
        mode (a simulated robot's can run slower than the wall's), else by the wall's."""
        if not self._pace:
            return
        now_of = self.clock if self.robot is None else (lambda: self.robot.state().time_s)
        now, dt = now_of(), self.twin.control_dt_s
        self._next_tick = now + dt if self._next_tick is None else self._next_tick + dt
        if self._next_tick <= now:  # late: the next period starts now, not in the past
            self._next_tick = now
        give_up = self.clock() + 10 * dt  # a robot clock that stands still: go on
        while self._next_tick - now > TICK_SLACK_S and self.clock() < give_up:
            self.sleep(self._next_tick - now)
            now = now_of()

    def _stop_all(self) -> None:
        """Stop the robot first, then the twin; a failing stop does not keep the other from
        stopping (the robot's error is raised after the twin's stop)."""
        error: BaseException | None = None
        for backend in (self.robot, self.twin):
            try:
                if backend is not None:
                    backend.stop()
            except Exception as err:  # the other backend must still stop
                error = error or err
        if error is not None:
            raise error

    def _finish_episode(self, rec: EpisodeRecorder, result: SessionResult,
                        keep_status: bool = False) -> None:
        result.recorders.append(rec)
        result.episodes.append(rec.summary())
        if self.log is not None:
            self.log.write_episode(rec)
        if keep_status:
            return
        if rec.end == "filter_stop":
            reasons = rec.rows.get("filter_reasons", [""])[-1] if rec.decisions else ""
            result.status = "stopped"
            result.reason = (f"the safety filter stopped the robot in episode {rec.episode} "
                             f"at decision {max(rec.decisions - 1, 0)}"
                             + (f": {reasons}" if reasons else ""))
        elif rec.end == "robot_fault":
            why = getattr(self.robot, "stop_reason", None)
            result.status = "stopped"
            result.reason = (f"the robot reported a fault in episode {rec.episode}"
                             + (f": {why}" if why else ""))
        elif rec.end == "interrupted":
            result.status = "interrupted"
            result.reason = f"a signal ended episode {rec.episode}"

    def _close(self, result: SessionResult) -> None:  # the log, in every case
        if self.log is not None:
            self.log.close(result.status, result.reason)


def twin_reset_state(twin: SimulatorBackend) -> RobotState:
    """The twin's state as its filter starts from: the joints at the servo setpoints, the last
    command. (The simulated servo holds the limb against gravity a little away from its
    setpoints, so that the measured joints are not where the next command starts from; a
    filter started there would see the first command as a jump.)"""
    return dataclasses.replace(twin.state(), q_rad=np.array(twin.env.controller.setpoint_rad,
                                                            dtype=float))


# ----------------------------------------------------------------------------- `rehabbot deploy`
