"""The deployment loop (rehabbot.deploy.session), its log (rehabbot.deploy.session_log), its
figure (rehabbot.analysis.session_figures) and `rehabbot deploy`.

The key property: on the simulator backend, a filter that passes every decision leaves the
closed loop bit for bit the same as ``env.step`` (observations, rewards, target switches,
success), and a filter that intervenes changes it."""

from __future__ import annotations

import json
import signal
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

import rehabbot.envs  # noqa: F401  (registers the ids)
from rehabbot.common.errors import DataError, UsageError
from rehabbot.deploy.backend import RobotState
from rehabbot.deploy.launch import env_caps, filter_configs
from rehabbot.deploy.safety_filter import SafetyFilter
from rehabbot.deploy.session import (
    DeploymentError,
    DeploymentSession,
    SessionInterrupted,
    SessionSettings,
    combine,
    twin_reset_state,
)
from rehabbot.deploy.session_log import (
    SESSION_NAME,
    SessionLogWriter,
    episode_name,
    is_session,
    read_session,
)
from rehabbot.deploy.simulator import SimulatorBackend
from rehabbot.rl.policies import env_for, load_policy

KNEE = "zoo:rehab-knee-v2/ppo"
HIP_FR3 = "zoo:rehab-hip-v2/ppo-fr3"


# --------------------------------------------------------------------------- stand-ins
@dataclass(frozen=True)
class Decision:
    q_rad: np.ndarray
    action: str
    reasons: tuple[str, ...] = ()


class PassThrough:
    """A filter that passes every command (and counts its calls)."""

    def __init__(self) -> None:
        self.resets = 0
        self.calls = 0

    def reset(self, state: RobotState) -> None:
        self.resets += 1

    def filter(self, state: RobotState, q_command_rad: np.ndarray, now_s: float) -> Decision:
        self.calls += 1
        return Decision(np.asarray(q_command_rad, dtype=float), "pass")


class ClipBetween(PassThrough):
    """Halves the command's step from the measured joints on decisions [first, last)."""

    def __init__(self, first: int, last: int) -> None:
        super().__init__()
        self.first, self.last = first, last

    def filter(self, state, q_command_rad, now_s):
        k = self.calls
        decision = super().filter(state, q_command_rad, now_s)
        if self.first <= k < self.last:
            q = state.q_rad + 0.5 * (decision.q_rad - state.q_rad)
            return Decision(q, "clip", ("step limited",))
        return decision


class StopAt(PassThrough):
    def __init__(self, at: int) -> None:
        super().__init__()
        self.at = at

    def filter(self, state, q_command_rad, now_s):
        k = self.calls
        decision = super().filter(state, q_command_rad, now_s)
        if k == self.at:
            return Decision(np.asarray(state.q_rad), "stop", ("cuff force above its limit",))
        return decision


class SignalAt(PassThrough):
    """Sends SIGINT to this process on decision ``at`` (``times`` signals)."""

    def __init__(self, at: int, times: int = 1) -> None:
        super().__init__()
        self.at, self.times = at, times

    def filter(self, state, q_command_rad, now_s):
        if self.calls == self.at:
            for _ in range(self.times):
                signal.raise_signal(signal.SIGINT)
        return super().filter(state, q_command_rad, now_s)


class FakeRobot:
    """A kinematic robot: each command moves the joints ``gain`` of the way to the target in
    one period; it fails (``healthy() is False``) after ``fail_after`` commands."""

    def __init__(self, q0, dt_s, gain=1.0, fail_after=None, joint_names=None, clock=None):
        self.q = np.array(q0, dtype=float)
        self.clock = clock  # its time: the clock's since it was made, else dt per command
        self.start_s = clock() if clock is not None else 0.0
        self.control_dt_s = dt_s
        self.joint_names = tuple(joint_names or (f"j{k}" for k in range(len(self.q))))
        self.gain, self.fail_after = gain, fail_after
        self.time_s, self.commands, self.stopped = 0.0, [], False

    def state(self):
        time_s = self.clock() - self.start_s if self.clock is not None else self.time_s
        return RobotState(time_s, self.q.copy(), np.zeros_like(self.q))

    def command(self, q_target_rad):
        assert not self.stopped
        self.commands.append(np.array(q_target_rad, dtype=float))
        self.q = self.q + self.gain * (np.asarray(q_target_rad) - self.q)
        self.time_s += self.control_dt_s

    def stop(self):
        self.stopped = True

    def healthy(self):
        return not self.stopped and (self.fail_after is None
                                     or len(self.commands) < self.fail_after)


class FakeClock:
    def __init__(self):
        self.now, self.sleeps = 100.0, []

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.now += seconds


def _twin_and_policy(spec):
    env_id, kwargs = env_for([spec])
    twin = SimulatorBackend(env_id, **kwargs)
    return twin, load_policy(spec, twin.wrapped), env_id, kwargs


def _env_rollout(spec, seed):
    env_id, kwargs = env_for([spec])
    env = gym.make(env_id, **kwargs)
    policy = load_policy(spec, env)
    obs, info = env.reset(seed=seed)
    observations, rewards, index, success, violations = [obs], [], [info["target_index"]], [], []
    while True:
        obs, reward, terminated, truncated, info = env.step(
            policy.act(obs, action_space=env.action_space))
        observations.append(obs)
        rewards.append(reward)
        index.append(info["target_index"])
        success.append(info["is_success"])
        violations.append(info["safety_violation"] or "")
        if terminated or truncated:
            return {"observation": np.array(observations), "reward": np.array(rewards),
                    "target_index": np.array(index), "is_success": np.array(success),
                    "safety_violation": np.array(violations, dtype=str),
                    "end": "terminated" if terminated else "truncated"}


def _same_rollout(arrays, expected) -> bool:
    return all(np.array_equal(arrays[key], expected[key]) for key in
               ("observation", "reward", "target_index", "is_success", "safety_violation")) \
        and str(arrays["end"]) == expected["end"]


# --------------------------------------------------------------------------- the key property
def _loose(twin) -> dict:
    """Filter settings these agents never meet on seed 0: caps twice the env's (the fastest
    a policy of the env commands; the robot's measured speed goes beyond that, and the filter
    holds a robot faster than its cap), the force rule's thresholds above what they press."""
    speed, accel = env_caps(twin)
    return {"max_speed_rad_s": [2 * v for v in speed], "max_accel_rad_s2": [2 * a for a in accel],
            "hold_fraction": 0.9, "back_off_fraction": 0.95}


def _real_filter(twin):
    """The deployment filter with :func:`_loose` settings (its range rule as it comes)."""
    config, _ = filter_configs(twin, _loose(twin))
    return SafetyFilter(config)


@pytest.mark.parametrize("real_filter", [False, True], ids=["stand-in", "safety-filter"])
@pytest.mark.parametrize("spec", [KNEE, HIP_FR3])
def test_pass_through_session_is_env_step_bit_for_bit(spec, real_filter, tmp_path):
    expected = _env_rollout(spec, seed=0)
    twin, policy, env_id, _ = _twin_and_policy(spec)
    flt = _real_filter(twin) if real_filter else PassThrough()
    log = SessionLogWriter(tmp_path / "session", {"env_id": env_id})
    result = DeploymentSession(policy, twin, flt, log=log).run(1, seed=0)
    assert result.status == "completed"
    arrays = result.recorders[0].arrays()
    assert set(arrays["filter_action"]) == {"pass"}  # the filter never intervened
    assert len(arrays["reward"]) == len(expected["reward"]) > 100
    assert _same_rollout(arrays, expected)
    assert np.array_equal(arrays["q_command_rad"], arrays["q_policy_rad"])
    # ... and the file on disk holds the same arrays.
    on_disk = read_session(tmp_path / "session").episodes[0]
    assert _same_rollout(on_disk.arrays, expected)
    if not real_filter:
        assert flt.resets == 1 and flt.calls == len(expected["reward"])


def test_the_real_filter_clips_a_tighter_speed_cap():
    """The same loop with the filter's speed cap at half the env's: the decisions that ask for
    more are clipped to it, and the rollout is no longer env.step's."""
    expected = _env_rollout(KNEE, seed=0)
    twin, policy, _, _ = _twin_and_policy(KNEE)
    cap = 0.5 * env_caps(twin)[0][0]
    settings = {**_loose(twin), "max_speed_rad_s": cap}
    config, _ = filter_configs(twin, settings)
    result = DeploymentSession(policy, twin, SafetyFilter(config)).run(1, seed=0)
    arrays = result.recorders[0].arrays()
    actions = arrays["filter_action"]
    clipped = np.flatnonzero((actions[1:] == "clip") & np.isin(actions[:-1], ["pass", "clip"]))
    assert clipped.size > 10 and "speed cap" in arrays["filter_reasons"][clipped[0] + 1]
    steps = np.abs(np.diff(arrays["q_command_rad"], axis=0))[clipped]
    assert np.max(steps) <= cap * twin.control_dt_s * (1 + 1e-9)
    assert np.max(np.abs(np.diff(arrays["q_policy_rad"], axis=0))) > cap * twin.control_dt_s
    assert not _same_rollout(arrays, expected)


def test_an_intervention_changes_the_rollout():
    expected = _env_rollout(KNEE, seed=3)
    twin, policy, _, _ = _twin_and_policy(KNEE)
    result = DeploymentSession(policy, twin, ClipBetween(10, 20)).run(1, seed=3)
    arrays = result.recorders[0].arrays()
    actions = arrays["filter_action"]
    assert list(actions[10:20]) == ["clip"] * 10 and set(actions[:10]) == {"pass"}
    assert set(actions[20:]) == {"pass"}
    assert arrays["filter_reasons"][10] == "step limited" and arrays["filter_reasons"][9] == ""
    sent, asked = arrays["q_command_rad"], arrays["q_policy_rad"]
    assert np.array_equal(sent[:10], asked[:10]) and not np.array_equal(sent[10], asked[10])
    # The same until the first clipped decision, different from then on.
    assert np.array_equal(arrays["observation"][:11], expected["observation"][:11])
    assert not np.array_equal(arrays["observation"][11], expected["observation"][11])
    assert not _same_rollout(arrays, expected)


# --------------------------------------------------------------------------- how a session ends
def test_a_filter_stop_stops_the_robot_and_ends_the_session(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    log = SessionLogWriter(tmp_path / "s", {})
    result = DeploymentSession(policy, twin, StopAt(7), log=log).run(3, seed=0)
    assert result.status == "stopped" and "cuff force above its limit" in result.reason
    assert not twin.healthy()
    session = read_session(tmp_path / "s")
    assert session.header["status"] == "stopped" and len(session.episodes) == 1
    episode = session.episodes[0]
    assert episode.end == "filter_stop" and episode.decisions == 8
    assert list(episode["stepped"]) == [True] * 7 + [False]
    assert np.isnan(episode["reward"][-1]) and np.all(np.isfinite(episode["reward"][:-1]))
    assert episode["time_s"].shape == (9,) and episode["observation"].shape[0] == 9
    # nothing moved after the stop
    assert episode["time_s"][-1] == episode["time_s"][-2]


def test_sigint_stops_the_robot_and_keeps_the_log(tmp_path, python_sigint_handler):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    log = SessionLogWriter(tmp_path / "s", {})
    with pytest.raises(SessionInterrupted) as caught:
        DeploymentSession(policy, twin, SignalAt(12), log=log).run(2, seed=0)
    assert caught.value.exit_code == 130 and "SIGINT" in str(caught.value)
    assert not twin.healthy()
    session = read_session(tmp_path / "s")
    assert session.header["status"] == "interrupted"
    episode = session.episodes[0]
    # the signal came while decision 12 was filtered: that decision ran, none after it
    assert episode.end == "interrupted" and episode.decisions == 13
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_signal_stops_at_once_and_still_closes_the_log(tmp_path,
                                                                 python_sigint_handler):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    log = SessionLogWriter(tmp_path / "s", {})
    with pytest.raises(KeyboardInterrupt):
        DeploymentSession(policy, twin, SignalAt(5, times=2), log=log).run(1, seed=0)
    assert not twin.healthy()
    session = read_session(tmp_path / "s")
    assert session.header["status"] == "interrupted"
    assert session.episodes[0].end == "interrupted" and session.episodes[0].decisions == 5


def test_an_error_closes_the_log_as_failed(tmp_path):
    class Broken(PassThrough):
        def filter(self, state, q_command_rad, now_s):
            if self.calls == 4:
                return Decision(np.asarray(q_command_rad), "maybe")
            return super().filter(state, q_command_rad, now_s)

    twin, policy, _, _ = _twin_and_policy(KNEE)
    log = SessionLogWriter(tmp_path / "s", {})
    with pytest.raises(UsageError, match="'maybe'"):
        DeploymentSession(policy, twin, Broken(), log=log).run(1, seed=0)
    session = read_session(tmp_path / "s")
    assert session.header["status"] == "failed" and "'maybe'" in session.header["reason"]
    assert session.episodes[0].end == "failed" and not twin.healthy()


# --------------------------------------------------------------------------- shadow mode
def test_shadow_mode_approaches_the_start_pose_then_tracks(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    twin.reset(seed=1)
    start = twin_reset_state(twin).q_rad  # the servo setpoints: where the first command starts
    far = start + np.array([0.1, -0.05, 0.0, 0.02, 0.0, 0.0])
    clock = FakeClock()
    robot = FakeRobot(far, twin.control_dt_s, clock=clock)
    settings = SessionSettings(start_tolerance_rad=1e-3, approach_speed_rad_s=0.5)
    session = DeploymentSession(policy, twin, PassThrough(), robot=robot,
                                robot_filter=PassThrough(),
                                log=SessionLogWriter(tmp_path / "s", {}), settings=settings,
                                clock=clock, sleep=clock.sleep)
    result = session.run(1, seed=1)
    assert result.status == "completed" and robot.stopped
    episode = read_session(tmp_path / "s").episodes[0]
    approach = episode["approach_q_command_rad"]
    dt = twin.control_dt_s
    steps = np.diff(np.vstack([far, approach]), axis=0)
    # a straight line to the start pose: at most 0.5 rad/s (the largest joint), speeding up
    # and slowing down at about 0.5 rad/s^2 (the default), at rest at both ends
    assert len(approach) > 10 and np.allclose(approach[-1], start, rtol=0.0, atol=1e-12)
    assert np.max(np.abs(steps)) <= 0.5 * dt * (1 + 1e-9)
    changes = np.diff(np.vstack([np.zeros(6), steps, np.zeros(6)]), axis=0)
    assert np.max(np.abs(changes)) <= 2.5 * 0.5 * dt * dt
    direction = (start - far) / np.max(np.abs(start - far))
    assert np.allclose(steps / np.max(np.abs(steps), axis=1, keepdims=True), direction,
                       rtol=0.0, atol=1e-9)
    assert np.array_equal(episode["approach_robot_q_rad"][0], far)
    assert list(episode["approach_filter_action"]) == ["pass"] * len(approach)
    assert list(episode["approach_filter_reasons"]) == [""] * len(approach)
    # the robot followed every command exactly: the tracking error is robot - simulator
    assert np.array_equal(episode["tracking_error_rad"],
                          episode["robot_q_rad"] - episode["q_rad"])
    assert np.array_equal(episode["robot_q_rad"][1:], episode["q_command_rad"])
    # the twin ran as it runs alone: shadow mode does not change the simulation
    expected = _env_rollout(KNEE, seed=1)
    assert _same_rollout(episode.arrays, expected)
    # paced: one period of sleep per command (the last decision's excepted)
    assert len(clock.sleeps) == len(approach) + episode.decisions - 1
    assert np.allclose(clock.sleeps, twin.control_dt_s, rtol=1e-9, atol=0.0)


def test_shadow_mode_takes_the_more_severe_verdict():
    twin = Decision(np.zeros(2), "clip", ("speed",))
    robot = Decision(np.ones(2), "hold", ("force",))
    verdict = combine(twin, robot)
    assert verdict.action == "hold" and np.array_equal(verdict.q_rad, np.ones(2))
    assert verdict.reasons == ("twin: speed", "robot: force")
    assert combine(Decision(np.zeros(2), "stop"), robot).action == "stop"


def test_a_robot_fault_stops_both(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    twin.reset(seed=0)
    robot = FakeRobot(twin_reset_state(twin).q_rad, twin.control_dt_s, fail_after=6)
    clock = FakeClock()
    result = DeploymentSession(policy, twin, PassThrough(), robot=robot,
                               robot_filter=PassThrough(), clock=clock,
                               sleep=clock.sleep).run(2, seed=0)
    assert result.status == "stopped" and "fault" in result.reason
    assert result.episodes[0]["end"] == "robot_fault" and result.episodes[0]["decisions"] == 6
    assert robot.stopped and not twin.healthy() and len(result.episodes) == 1


def test_the_approach_gives_up_after_its_timeout(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    twin.reset(seed=0)
    robot = FakeRobot(twin_reset_state(twin).q_rad + 0.5, twin.control_dt_s, gain=0.0)
    clock = FakeClock()
    session = DeploymentSession(policy, twin, PassThrough(), robot=robot,
                                robot_filter=PassThrough(),
                                log=SessionLogWriter(tmp_path / "s", {}),
                                settings=SessionSettings(approach_timeout_s=0.2), clock=clock,
                                sleep=clock.sleep)
    with pytest.raises(DeploymentError, match="did not reach"):
        session.run(1, seed=0)
    assert robot.stopped and len(robot.commands) == 10
    episode = read_session(tmp_path / "s").episodes[0]  # readable, with what happened
    assert episode.end == "failed" and episode.decisions == 0
    assert episode["approach_q_command_rad"].shape == (10, 6)


def test_a_fault_during_the_approach_ends_the_session(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    twin.reset(seed=0)
    robot = FakeRobot(twin_reset_state(twin).q_rad + 0.3, twin.control_dt_s, fail_after=3)
    clock = FakeClock()
    result = DeploymentSession(policy, twin, PassThrough(), robot=robot,
                               robot_filter=PassThrough(),
                               log=SessionLogWriter(tmp_path / "s", {}), clock=clock,
                               sleep=clock.sleep).run(2, seed=0)
    assert result.status == "stopped" and robot.stopped and not twin.healthy()
    episode = read_session(tmp_path / "s").episodes[0]
    assert episode.end == "robot_fault" and episode.decisions == 0
    assert episode["robot_q_rad"].shape == (1, 6)
    assert np.array_equal(episode["robot_q_rad"][0], robot.q)


def test_shadow_mode_refuses_a_robot_that_does_not_fit():
    twin, policy, _, _ = _twin_and_policy(KNEE)
    with pytest.raises(UsageError, match="7 joints"):
        DeploymentSession(policy, twin, PassThrough(), robot=FakeRobot(np.zeros(7), 0.02),
                          robot_filter=PassThrough())
    with pytest.raises(UsageError, match=r"control period 0\.001"):
        DeploymentSession(policy, twin, PassThrough(), robot=FakeRobot(np.zeros(6), 0.001),
                          robot_filter=PassThrough())
    with pytest.raises(UsageError, match="both"):
        DeploymentSession(policy, twin, PassThrough(), robot=FakeRobot(np.zeros(6), 0.02))


# --------------------------------------------------------------------------- the log
def test_a_session_is_never_overwritten_and_damage_is_named(tmp_path):
    SessionLogWriter(tmp_path / "s", {}).close("completed")
    with pytest.raises(UsageError, match="already holds"):
        SessionLogWriter(tmp_path / "s", {})
    assert is_session(tmp_path / "s") and is_session(tmp_path / "s" / SESSION_NAME)
    assert not is_session(tmp_path)
    document = json.loads((tmp_path / "s" / SESSION_NAME).read_text())
    document["episodes"] = [{"file": episode_name(0)}]
    (tmp_path / "s" / SESSION_NAME).write_text(json.dumps(document))
    with pytest.raises(DataError, match=r"episode-0000\.npz"):
        read_session(tmp_path / "s")
    (tmp_path / "s" / episode_name(0)).write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(DataError, match="not a readable session episode"):
        read_session(tmp_path / "s")
    (tmp_path / "s" / SESSION_NAME).write_text('{"format": "something-else"}')
    with pytest.raises(DataError, match="something-else"):
        read_session(tmp_path / "s")


@pytest.mark.parametrize(("field", "value"), [("start_tolerance_rad", 0.0),
                                              ("approach_speed_rad_s", float("nan")),
                                              ("approach_timeout_s", -1.0)])
def test_bad_settings_are_named(field, value):
    with pytest.raises(UsageError, match=field):
        SessionSettings(**{field: value})


def test_episodes_must_be_positive():
    twin, policy, _, _ = _twin_and_policy(KNEE)
    with pytest.raises(UsageError, match="episodes=0"):
        DeploymentSession(policy, twin, PassThrough()).run(0)


# --------------------------------------------------------------------------- filter settings
def test_filter_configs_come_from_the_env_and_the_robot():
    twin, _, _, _ = _twin_and_policy(KNEE)
    config, robot_config = filter_configs(twin, {"hold_fraction": 0.7},
                                          RobotState(0.0, np.zeros(6), np.zeros(6)))
    low, _ = twin.setpoint_bounds_rad()
    assert config.joint_low_rad == tuple(low) and config.hold_fraction == 0.7
    assert config.cuff_force_limit_n == twin.cuff_force_limit_n()
    assert config.rom_low_rad == tuple(twin.rom_bounds_rad()[0])
    assert config.control_dt_s == twin.control_dt_s
    # the robot measures no patient joints and (here) no force: neither rule for it
    assert robot_config.rom_low_rad is None and robot_config.cuff_force_limit_n is None
    assert robot_config.max_speed_rad_s == config.max_speed_rad_s
    _, with_force = filter_configs(twin, None, RobotState(0.0, np.zeros(6), np.zeros(6), 3.0))
    assert with_force.cuff_force_limit_n == twin.cuff_force_limit_n()
    with pytest.raises(UsageError, match=r"'hold_fractoin'.*known: max_speed_rad_s"):
        filter_configs(twin, {"hold_fractoin": 0.7})
    with pytest.raises(UsageError, match="hold_fraction=2"):
        filter_configs(twin, {"hold_fraction": 2})


def test_shadow_mode_with_the_real_filters(tmp_path):
    twin, policy, _, _ = _twin_and_policy(KNEE)
    twin.reset(seed=2)
    robot = FakeRobot(twin_reset_state(twin).q_rad, twin.control_dt_s)
    config, robot_config = filter_configs(twin, _loose(twin), robot.state())
    clock = FakeClock()
    result = DeploymentSession(policy, twin, SafetyFilter(config), robot=robot,
                               robot_filter=SafetyFilter(robot_config),
                               log=SessionLogWriter(tmp_path / "s", {}, background=True),
                               clock=clock, sleep=clock.sleep).run(1, seed=2)
    assert result.status == "completed"
    episode = read_session(tmp_path / "s").episodes[0]
    assert set(episode["twin_filter_action"]) == set(episode["robot_filter_action"]) == {"pass"}
    assert len(episode["approach_q_command_rad"]) == 0  # it was at the start pose
    assert _same_rollout(episode.arrays, _env_rollout(KNEE, seed=2))


# --------------------------------------------------------------------------- the command
def _cli(argv):
    """``rehabbot ARGV`` as rehabbot.cli.main runs it (the parser built here, so that the test
    does not depend on the command's registration)."""
    import argparse

    from rehabbot.cli.deploy import add_deploy_parser
    from rehabbot.cli.errors import report
    from rehabbot.cli.plot import add_plot_parser

    parser = argparse.ArgumentParser(prog="rehabbot")
    commands = parser.add_subparsers(dest="command", required=True)
    add_deploy_parser(commands)
    add_plot_parser(commands)
    try:
        args = parser.parse_args(argv)
        return int(args.func(args))
    except SystemExit as err:
        return int(err.code)
    except (Exception, KeyboardInterrupt) as err:
        return report(err)


def _loose_json(spec) -> str:
    twin, _, _, _ = _twin_and_policy(spec)
    return json.dumps(_loose(twin))


@pytest.mark.slow
def test_deploy_then_plot(tmp_path, capsys):
    out = tmp_path / "knee"
    (tmp_path / "filter.json").write_text(_loose_json(KNEE))
    assert _cli(["deploy", KNEE, "--backend", "sim", "--episodes", "2", "--seed", "0",
                 "--filter-config", str(tmp_path / "filter.json"), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "episode 0 (seed 0)" in printed and f"rehabbot plot {out}" in printed
    session = read_session(out)
    assert session.header["status"] == "completed" and len(session.episodes) == 2
    assert session.header["backend"] == "sim" and session.header["filter"]["hold_fraction"] == 0.9
    assert session.header["policy"]["spec"] == KNEE
    assert _same_rollout(session.episodes[0].arrays, _env_rollout(KNEE, seed=0))
    # a session is never overwritten
    assert _cli(["deploy", KNEE, "--backend", "sim", "--out", str(out)]) == 2
    assert "already holds a deployment session" in capsys.readouterr().err
    assert _cli(["plot", str(out / "episode-0001.npz"), "--formats", "png", "--dpi", "50",
                 "--out", str(tmp_path / "figures")]) == 0
    assert (tmp_path / "figures" / "session_knee_ep0001.png").is_file()
    assert not (tmp_path / "figures" / "session_knee_ep0000.png").exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--filter-config", '{"max_speed": 1}'], "unknown setting(s) 'max_speed'"),
    (["--filter-config", "[1, 2]"], "must be a JSON object"),
    (["--filter-config", "missing.json"], "neither a JSON object nor a readable file"),
    (["--filter-config", '{"max_speed_rad_s": -1}'], "max_speed_rad_s[0]=-1"),
    (["--robot-ip", "10.0.0.2"], "--robot-ip is for --backend franka or ur"),
])
def test_deploy_refuses_bad_arguments_before_anything_runs(argv, message, tmp_path, capsys):
    out = tmp_path / "s"
    assert _cli(["deploy", KNEE, "--backend", "sim", "--out", str(out), *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_robot_backend_needs_its_robot_and_address(tmp_path, capsys):
    assert _cli(["deploy", KNEE, "--backend", "franka", "--out", str(tmp_path / "s")]) == 2
    assert "--robot-ip" in capsys.readouterr().err
    assert _cli(["deploy", KNEE, "--backend", "franka", "--robot-ip", "127.0.0.1",
                 "--out", str(tmp_path / "s")]) == 2
    assert 'drives the fr3, but the policy\'s env has the ur5e' in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_deploy_an_onnx_policy(tmp_path):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    from rehabbot.rl.onnx_export import export_onnx, load_onnx_policy

    path = tmp_path / "knee.onnx"
    export_onnx(KNEE, path)
    assert _cli(["deploy", str(path), "--backend", "sim", "--seed", "0", "--filter-config",
                 _loose_json(KNEE), "--out", str(tmp_path / "s")]) == 0
    session = read_session(tmp_path / "s")
    assert session.header["policy"]["kind"] == "onnx"
    assert session.header["env_id"] == "rehabbot/rehab-knee-v2"
    # the loop with the ONNX policy is env.step with the same policy
    onnx = load_onnx_policy(path)
    env = gym.make("rehabbot/rehab-knee-v2")
    obs, _ = env.reset(seed=0)
    observations = [obs]
    while True:
        obs, _r, terminated, truncated, _i = env.step(onnx.predict(obs)[0])
        observations.append(obs)
        if terminated or truncated:
            break
    assert np.array_equal(session.episodes[0]["observation"], np.array(observations))


# --------------------------------------------------------------------------- the figure
@pytest.mark.slow
def test_the_session_figure_marks_what_the_filter_did(tmp_path):
    pytest.importorskip("matplotlib")
    from rehabbot.analysis.session_figures import (
        build_session_episode,
        fraction_gid,
        intervention_gid,
    )

    twin, policy, _, _ = _twin_and_policy(KNEE)
    log = SessionLogWriter(tmp_path / "s", {"policy": {"spec": KNEE}, "backend": "sim",
                                            "env_id": "rehabbot/rehab-knee-v2"})
    DeploymentSession(policy, twin, ClipBetween(10, 20), log=log).run(1, seed=3)
    session = read_session(tmp_path / "s")
    episode = session.episodes[0]
    figure = build_session_episode(session, episode)
    lines = {}
    for ax in figure.axes:
        for line in ax.get_lines():
            lines.setdefault(line.get_gid(), []).append(line)
    # one marker per clipped decision, on every joint's panel and on the force panel
    clips = lines[intervention_gid("clip")]
    assert len(clips) == 6 + 1 and all(len(line.get_xdata()) == 10 for line in clips)
    assert np.array_equal(clips[0].get_xdata(), episode["time_s"][10:20])
    assert intervention_gid("hold") not in lines
    limit = lines["force-limit"][0]
    assert np.all(np.asarray(limit.get_ydata()) == twin.cuff_force_limit_n())
    share = lines[fraction_gid("clip")][0].get_ydata()
    assert share[-1] == 10 / episode.decisions and share[9] == 0.0
    assert "ended: terminated" in figure.texts[0].get_text() or \
        "ended: terminated" in figure._suptitle.get_text()
