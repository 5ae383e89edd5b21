"""The deployment safety filter (rehabbot/deploy/safety_filter.py): each rule fires when it
should and only then (synthetic states, no MuJoCo), the caps on every command, the latched stop
and the watchdog; then short fuzzes on the simulator (benchmarks/deploy/safety_fuzz.py) with
zero breaches, and with a rule removed, the breach it was there to prevent."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotState
from rehabbot.deploy.safety_filter import (
    ACTIONS,
    HISTORY_SPACING_RAD,
    FilterConfig,
    FilterDecision,
    SafetyFilter,
)

DT = 0.01
SPEED = 1.0  # rad/s: a step of at most 0.01 rad
ACCEL = 10.0  # rad/s^2: the step changes by at most 0.001 rad
STEP = SPEED * DT
CHANGE = ACCEL * DT * DT
LIMIT_N = 100.0
ROUND = 1e-12  # relative round-off allowed on a cap


def config(**changes: object) -> FilterConfig:
    base: dict[str, object] = {
        "control_dt_s": DT, "max_speed_rad_s": SPEED, "max_accel_rad_s2": ACCEL,
        "joint_low_rad": [-1.0, -1.0, -1.0], "joint_high_rad": [1.0, 1.0, 1.0],
        "rom_low_rad": [0.0, -1.0], "rom_high_rad": [1.0, 1.0], "rom_margin_rad": 0.1,
        "cuff_force_limit_n": LIMIT_N, "patient_joint_names": ["knee", "hip"]}
    return FilterConfig(**{**base, **changes})


def state(t: float = 0.0, q: object = (0.0, 0.0, 0.0), dq: object = (0.0, 0.0, 0.0),
          force: float = 10.0, p: object = (0.5, 0.0), dp: object = (0.0, 0.0)) -> RobotState:
    return RobotState(time_s=t, q_rad=np.array(q, dtype=float), dq_rad_s=np.array(dq, dtype=float),
                      cuff_force_n=force, patient_q_rad=np.array(p, dtype=float),
                      patient_dq_rad_s=np.array(dp, dtype=float))


def started(**changes: object) -> SafetyFilter:
    safety = SafetyFilter(config(**changes))
    safety.reset(state())
    return safety


# -- the config -------------------------------------------------------------------------------
@pytest.mark.parametrize(("changes", "named"), [
    ({"control_dt_s": 0.0}, "control_dt_s=0.0"),
    ({"max_speed_rad_s": -1.0}, "max_speed_rad_s[0]=-1.0"),
    ({"max_speed_rad_s": [1.0, math.nan, 1.0]}, "max_speed_rad_s[1]=nan"),
    ({"max_accel_rad_s2": 0.0}, "max_accel_rad_s2[0]=0.0"),
    ({"max_speed_rad_s": [1.0, 1.0]}, "disagree on the number of robot joints"),
    ({"joint_high_rad": None}, "joint_low_rad and joint_high_rad together"),
    ({"joint_low_rad": [-1.0, 2.0, -1.0]}, "joint_low_rad[1]=2.0"),
    ({"rom_high_rad": [1.0]}, "rom_low_rad has 2 entries"),
    ({"rom_margin_rad": 0.6}, "rom_margin_rad=0.6"),
    ({"rom_margin_rad": -0.1}, "rom_margin_rad=-0.1"),
    ({"cuff_force_limit_n": -5.0}, "cuff_force_limit_n=-5.0"),
    ({"hold_fraction": 0.9}, "hold_fraction=0.9"),
    ({"back_off_fraction": 1.5}, "back_off_fraction=1.5"),
    ({"max_state_age_s": 0.0}, "max_state_age_s=0.0"),
    ({"max_command_age_s": math.inf}, "max_command_age_s=inf"),
    ({"watchdog_timeout_s": math.nan}, "watchdog_timeout_s=nan"),
    ({"history_size": 0}, "history_size=0"),
    ({"overspeed_factor": 0.5}, "overspeed_factor=0.5"),
    ({"release_to_measured": "yes"}, "release_to_measured='yes'"),
    ({"patient_joint_names": ["knee"]}, "patient_joint_names=('knee',)"),
    ({"max_patient_speed_rad_s": 0.0}, "max_patient_speed_rad_s[0]=0.0"),
    ({"max_patient_speed_rad_s": [1.0, 1.0, 1.0]}, "needs the patient joints"),
])
def test_a_bad_setting_is_named(changes: dict, named: str) -> None:
    with pytest.raises(UsageError, match=named.replace("[", r"\[").replace("(", r"\(")
                       .replace(")", r"\)")):
        config(**changes)


def test_the_config_is_frozen_and_reads_back_as_tuples() -> None:
    cfg = config(max_speed_rad_s=[1.0, 2.0, 3.0])
    assert cfg.max_speed_rad_s == (1.0, 2.0, 3.0) and cfg.max_accel_rad_s2 == (ACCEL,)
    assert cfg.n_joints == 3 and config(joint_low_rad=None, joint_high_rad=None).n_joints is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.hold_fraction = 0.1  # type: ignore[misc]


def test_filter_before_reset_and_a_bad_reset_are_refused() -> None:
    safety = SafetyFilter(config())
    with pytest.raises(UsageError, match="reset"):
        safety.filter(state(), np.zeros(3), 0.0)
    with pytest.raises(UsageError, match="reset"):
        safety.watchdog(0.0)
    with pytest.raises(UsageError, match="shape"):
        safety.reset(state(q=(0.0, 0.0)))
    with pytest.raises(UsageError, match="non-finite q_rad"):
        safety.reset(state(q=(0.0, math.nan, 0.0)))
    with pytest.raises(UsageError, match="config must be a FilterConfig"):
        SafetyFilter({"control_dt_s": DT})  # type: ignore[arg-type]


# -- pass and clip ----------------------------------------------------------------------------
def test_a_command_within_the_caps_passes_unchanged() -> None:
    safety = started()
    command = np.array([0.0005, -0.0007, 0.0])
    decision = safety.filter(state(), command, 0.0)
    assert decision == FilterDecision(decision.q_rad, "pass", ())
    assert decision.q_rad.tolist() == command.tolist() and decision.q_rad is not command
    command[0] = 0.5  # the caller's array is not the filter's
    assert safety.last_command_rad.tolist() == [0.0005, -0.0007, 0.0]


def test_a_far_command_ramps_up_at_the_acceleration_cap_to_the_speed_cap() -> None:
    safety = started()
    previous, steps = np.zeros(3), []
    for k in range(20):
        decision = safety.filter(state(t=k * DT), np.full(3, 0.9), k * DT)
        assert decision.action == "clip"
        steps.append(float(decision.q_rad[0] - previous[0]))
        previous = decision.q_rad
    # 0.001, 0.002, ... (the acceleration cap), then 0.01 (the speed cap) for good.
    assert steps[0] == pytest.approx(CHANGE, rel=ROUND)
    assert steps[4] == pytest.approx(5 * CHANGE, rel=1e-9)
    assert steps[12:] == pytest.approx([STEP] * 8, rel=1e-9)
    assert all(s <= STEP * (1 + ROUND) for s in steps)
    assert "speed cap" in decision.reasons and "joint box" not in decision.reasons


def test_a_command_outside_the_joint_box_is_clipped_to_it() -> None:
    safety = started(joint_low_rad=[-1.0, -0.001, -1.0])
    decision = safety.filter(state(), np.array([0.0, -0.5, 0.0]), 0.0)
    assert decision.action == "clip" and decision.reasons == ("joint box",)
    assert decision.q_rad.tolist() == [0.0, -0.001, 0.0]


def test_a_command_braking_at_the_acceleration_cap_stops_at_the_box_edge() -> None:
    safety = started(joint_high_rad=[0.1, 1.0, 1.0])
    for k in range(40):  # full speed toward the edge: braking at 0.001 rad/step^2 overshoots
        decision = safety.filter(state(t=k * DT), np.array([0.1, 0.0, 0.0]), k * DT)
        assert decision.q_rad[0] <= 0.1
    assert decision.q_rad[0] == 0.1
    # Reset outside the box: the commands come back into it at the speed cap.
    outside = SafetyFilter(config())
    outside.reset(state(q=(1.5, 0.0, 0.0)))
    back = outside.filter(state(q=(1.5, 0.0, 0.0)), np.array([1.5, 0.0, 0.0]), 0.0)
    assert back.action == "clip" and back.reasons[0] == "joint box"
    assert 1.5 - STEP * (1 + ROUND) <= back.q_rad[0] < 1.5


def test_no_command_ever_steps_beyond_the_caps() -> None:
    """Random commands, far and near, with holds and back offs mixed in: every step within
    the speed cap (hold and back off start from the measured position where they drop back
    onto it), every pass / clip step within the acceleration cap of the one before."""
    rng = np.random.default_rng(7)
    safety = started(release_to_measured=False)
    previous, last_step = np.zeros(3), np.zeros(3)
    seen = set()
    for k in range(3000):
        force = float(rng.choice([10.0, 65.0, 85.0], p=[0.8, 0.1, 0.1]))
        scale = float(rng.choice([0.001, 0.02, 2.0]))
        q = previous + rng.normal(0.0, 0.002, 3)
        decision = safety.filter(state(t=k * DT, q=q, force=force),
                                 previous + rng.normal(0.0, scale, 3), k * DT)
        step = decision.q_rad - previous
        seen.add(decision.action)
        assert np.abs(step).max() <= STEP * (1 + ROUND)
        if decision.action in ("pass", "clip"):
            assert np.abs(step - last_step).max() <= CHANGE * (1 + ROUND) + 1e-15
        assert np.all(np.abs(decision.q_rad) <= 1.0)
        previous, last_step = decision.q_rad, step
    assert seen == {"pass", "clip", "hold", "back_off"}


# -- the force rules --------------------------------------------------------------------------
def test_force_holds_from_the_hold_fraction_and_backs_off_from_the_back_off_fraction() -> None:
    below = math.nextafter(0.6 * LIMIT_N, 0.0)
    assert started().filter(state(force=below), np.zeros(3), 0.0).action == "pass"
    hold = started().filter(state(force=0.6 * LIMIT_N), np.zeros(3), 0.0)
    assert hold.action == "hold" and "cuff force 60.0 N >= 0.6 x the 100 N limit" in hold.reasons
    back = started().filter(state(force=0.8 * LIMIT_N), np.zeros(3), 0.0)
    assert back.action == "back_off" and "0.8 x the 100 N limit" in back.reasons[0]
    no_rule = started(cuff_force_limit_n=None)
    assert no_rule.filter(state(force=1e4), np.zeros(3), 0.0).action == "pass"
    assert no_rule.filter(state(force=math.nan), np.zeros(3), 0.0).action == "pass"


def test_hold_keeps_the_measured_position_of_its_start() -> None:
    safety = started()
    for k in range(1, 6):  # the command leads the robot by 0.004 rad
        safety.filter(state(t=k * DT, q=np.full(3, 0.01 * k - 0.004)), np.full(3, 0.01 * k),
                      k * DT)
    measured = np.array([0.047, 0.046, 0.0465])
    first = safety.filter(state(t=0.06, q=measured, force=70.0), np.full(3, 0.06), 0.06)
    assert first.action == "hold" and first.q_rad.tolist() == measured.tolist()
    # The robot moves on (the patient pushes it): the hold stays where it began.
    second = safety.filter(state(t=0.07, q=measured + 0.003, force=70.0), np.full(3, 0.07), 0.07)
    assert second.action == "hold" and second.q_rad.tolist() == measured.tolist()
    # Without the release, the hold comes back from the command at the speed cap only.
    slow = started(release_to_measured=False)
    slow.filter(state(t=0.0), np.full(3, 0.001), 0.0)
    far = np.full(3, -0.5)
    decision = slow.filter(state(t=0.01, q=far, force=70.0), np.zeros(3), 0.01)
    assert decision.q_rad == pytest.approx(np.full(3, 0.001 - STEP), rel=1e-9)


def test_back_off_retraces_the_safe_configurations_in_reverse() -> None:
    safety = started(max_accel_rad_s2=1000.0)
    path = [np.full(3, 0.005 * k) for k in range(1, 8)]
    for k, q in enumerate(path, start=1):
        assert safety.filter(state(t=k * DT, q=q), q, k * DT).action == "pass"
    assert safety.safe_configurations == 1 + len(path)  # the start, then every 5 mrad
    pushed = np.full(3, 0.04)
    targets = []
    for k in range(8, 30):
        decision = safety.filter(state(t=k * DT, q=pushed, force=90.0), pushed, k * DT)
        assert decision.action == "back_off"
        targets.append(decision.q_rad[0])
        if decision.q_rad[0] == 0.0:
            break
    # The command stands on the latest safe configuration (0.035), so it goes back through
    # the ones before, 0.03, 0.025, ..., to the start.
    assert targets == [0.005 * k for k in range(6, -1, -1)]
    assert safety.safe_configurations == 1


def test_back_off_without_a_safe_configuration_holds_the_measured_position() -> None:
    safety = SafetyFilter(config())
    safety.reset(state(force=95.0))
    assert safety.safe_configurations == 0
    decision = safety.filter(state(q=(0.002, 0.0, 0.0), force=95.0), np.ones(3), 0.0)
    assert decision.action == "back_off" and decision.q_rad.tolist() == [0.002, 0.0, 0.0]
    assert "no safe configuration recorded" in decision.reasons[-1]


# -- the range-of-motion rules ----------------------------------------------------------------
@pytest.mark.parametrize(("p", "dp", "action", "words"), [
    ((0.5, 0.0), (0.0, 0.0), "pass", None),
    ((0.85, 0.0), (0.0, 0.0), "pass", None),               # at the margin's edge, at rest
    ((0.85, 0.0), (6.0, 0.0), "hold", "knee heading for the margin"),
    ((0.85, 0.0), (-6.0, 0.0), "pass", None),              # heading away from the bound
    ((0.95, 0.0), (0.1, 0.0), "back_off", "knee at 0.9500 rad, within the margin"),
    ((0.95, 0.0), (-0.1, 0.0), "pass", None),              # in the margin, coming back
    ((0.5, -0.95), (0.0, -0.1), "back_off", "hip at -0.9500 rad, within the margin"),
    ((1.01, 0.0), (-0.1, 0.0), "back_off", "knee at 1.0100 rad, beyond its range"),
])
def test_range_of_motion_rules(p: tuple, dp: tuple, action: str, words: str | None) -> None:
    decision = started().filter(state(p=p, dp=dp), np.zeros(3), 0.0)
    assert decision.action == action
    assert (words is None and decision.reasons == ()) or words in decision.reasons[0]


def test_without_range_bounds_the_patient_joints_are_not_needed() -> None:
    safety = SafetyFilter(config(rom_low_rad=None, rom_high_rad=None, patient_joint_names=None))
    safety.reset(state(p=(), dp=()))
    assert safety.filter(state(p=(), dp=()), np.zeros(3), 0.0).action == "pass"
    assert started().filter(state(p=(), dp=()), np.zeros(3), 0.0).action == "stop"


def test_a_robot_moving_faster_than_its_cap_is_held() -> None:
    fast = (0.0, 1.25 * SPEED * 1.001, 0.0)
    decision = started().filter(state(dq=fast), np.zeros(3), 0.0)
    assert decision.action == "hold" and "robot joint 1" in decision.reasons[0]
    assert started().filter(state(dq=(0.0, 1.25 * SPEED, 0.0)), np.zeros(3), 0.0).action == "pass"
    assert started(overspeed_factor=None).filter(state(dq=(0.0, 50.0, 0.0)), np.zeros(3),
                                                 0.0).action == "pass"


def test_a_patient_joint_moving_faster_than_its_cap_is_held() -> None:
    capped = started(max_patient_speed_rad_s=[0.5, 2.0])
    decision = capped.filter(state(dp=(-0.5001, 0.0)), np.zeros(3), 0.0)
    assert decision.action == "hold" and "knee at -0.500 rad/s" in decision.reasons[0]
    assert started(max_patient_speed_rad_s=[0.5, 2.0]).filter(
        state(dp=(0.5, 1.9)), np.zeros(3), 0.0).action == "pass"
    assert started().filter(state(dp=(0.6, 0.0)), np.zeros(3), 0.0).action == "pass"


# -- the stop ---------------------------------------------------------------------------------
NAN3 = np.array([0.0, math.nan, 0.0])


@pytest.mark.parametrize(("given", "command", "now", "command_time", "words"), [
    (state(), NAN3, 0.0, None, "non-finite command"),
    (state(), np.array([0.0, math.inf, 0.0]), 0.0, None, "non-finite command"),
    (state(), np.zeros(2), 0.0, None, "command of shape (2,)"),
    (state(), ["a", "b", "c"], 0.0, None, "not an array of numbers"),
    (state(q=(0.0, 0.0, math.nan)), np.zeros(3), 0.0, None, "non-finite q_rad"),
    (state(dq=(math.inf, 0.0, 0.0)), np.zeros(3), 0.0, None, "non-finite dq_rad_s"),
    (state(p=(math.nan, 0.0)), np.zeros(3), 0.0, None, "non-finite patient_q_rad"),
    (state(force=math.nan), np.zeros(3), 0.0, None, "needs a finite force estimate"),
    (state(force=-1.0), np.zeros(3), 0.0, None, "needs a finite force estimate"),
    (state(t=0.0), np.zeros(3), 0.0500001, None, "stale state"),
    (state(t=0.01), np.zeros(3), 0.0, None, "state from the future"),
    (state(t=0.06), np.zeros(3), 0.06, 0.0099, "stale command"),
    (state(), np.zeros(3), 0.0, 0.01, "command from the future"),
    (state(), np.zeros(3), math.nan, None, "non-finite time"),
    (state(), np.zeros(3), 0.0, math.inf, "non-finite command time"),
])
def test_bad_or_stale_input_stops(given: RobotState, command: object, now: float,
                                  command_time: float | None, words: str) -> None:
    decision = started().filter(given, command, now, command_time)
    assert decision.action == "stop" and words in decision.reasons[0]
    assert decision.q_rad.tolist() == [0.0, 0.0, 0.0]


def test_ages_at_the_limit_are_fresh() -> None:
    assert started().filter(state(t=0.0), np.zeros(3), 0.05).action == "pass"
    assert started().filter(state(t=0.0), np.zeros(3), 0.05, 0.0).action == "pass"


def test_a_state_older_than_the_last_one_stops() -> None:
    safety = started()
    assert safety.filter(state(t=0.02), np.zeros(3), 0.02).action == "pass"
    assert safety.filter(state(t=0.02), np.zeros(3), 0.03).action == "pass"  # not updated
    decision = safety.filter(state(t=0.01), np.zeros(3), 0.03)
    assert decision.action == "stop" and "state time went back" in decision.reasons[0]


def test_the_stop_is_latched_until_reset() -> None:
    safety = started()
    safety.filter(state(), np.array([0.001, 0.0, 0.0]), 0.0)
    assert safety.filter(state(t=0.01), NAN3, 0.01).action == "stop"
    assert safety.stopped and "non-finite command" in str(safety.stop_reason)
    for k in range(2, 5):
        later = safety.filter(state(t=k * DT), np.zeros(3), k * DT)
        assert later.action == "stop" and later.reasons[0].startswith("stopped: non-finite")
        assert later.q_rad.tolist() == [0.001, 0.0, 0.0]  # the last command, unchanged
    assert safety.watchdog(0.05) is not None
    safety.reset(state(t=0.05, q=(0.003, 0.0, 0.0)))
    assert not safety.stopped and safety.stop_reason is None
    assert safety.last_command_rad.tolist() == [0.003, 0.0, 0.0]
    assert safety.filter(state(t=0.05, q=(0.003, 0.0, 0.0)), np.array([0.003, 0.0, 0.0]),
                         0.05).action == "pass"
    assert safety.counts["stop"] == 5 and set(safety.counts) == set(ACTIONS)


def test_the_watchdog_stops_when_no_command_came_for_too_long() -> None:
    # Binary-exact times: a gap of exactly the timeout is still in time.
    safety = SafetyFilter(config(watchdog_timeout_s=0.125, max_state_age_s=0.25))
    safety.reset(state())
    safety.filter(state(t=0.25), np.zeros(3), 0.25)
    assert safety.watchdog(0.375) is None
    safety.filter(state(t=0.375), np.zeros(3), 0.375)
    assert safety.watchdog(0.5) is None
    decision = safety.watchdog(math.nextafter(0.5, 1.0))
    assert decision is not None and decision.action == "stop"
    assert "watchdog: no command for" in decision.reasons[0]
    assert safety.filter(state(t=0.5), np.zeros(3), 0.5).action == "stop"
    assert started().watchdog(math.nan).action == "stop"  # type: ignore[union-attr]


def test_reset_starts_the_watchdog_from_now() -> None:
    safety = SafetyFilter(config(watchdog_timeout_s=0.125))
    safety.reset(state(t=0.96875), now_s=1.0)
    assert safety.watchdog(1.125) is None and safety.watchdog(1.25) is not None
    with pytest.raises(UsageError, match="stale state"):
        safety.reset(state(t=0.0), now_s=1.0)


def test_the_history_keeps_configurations_apart() -> None:
    safety = started(history_size=3)
    for k in range(1, 10):
        q = np.full(3, HISTORY_SPACING_RAD * 0.6 * k)
        safety.filter(state(t=k * DT, q=q), q, k * DT)
    assert safety.safe_configurations == 3  # full: the oldest forgotten


def test_a_hold_from_outside_the_joint_box_moves_one_capped_step() -> None:
    """A robot reset outside the box (a home pose beyond the env's setpoint box) and then held
    is commanded from where it is, one capped step into the box, never onto the box's edge."""
    safety = SafetyFilter(config())
    outside = (1.5, 0.0, 0.0)
    safety.reset(state(q=outside))
    decision = safety.filter(state(t=DT, q=outside, force=70.0), np.array(outside), DT)
    assert decision.action == "hold"
    assert np.max(np.abs(decision.q_rad - np.array(outside))) <= STEP * (1 + ROUND)


# -- on the simulator -------------------------------------------------------------------------
def fuzz():  # imported here: it makes MuJoCo envs
    from benchmarks.deploy import safety_fuzz

    return safety_fuzz


NO_FORCE = {"cuff_force_limit_n": None}
NO_RANGE = {"rom_low_rad": None, "rom_high_rad": None, "patient_joint_names": None,
            "max_patient_speed_rad_s": None}


@pytest.mark.parametrize(("case", "condition"), [("knee", "healthy"), ("reach", "tremor")])
def test_a_short_fuzz_breaches_nothing(case: str, condition: str) -> None:
    result = fuzz().run_fuzz(case, condition, 400, seed=1)
    assert result.commands == 400 and result.decisions >= 400
    assert result.breaches == dict.fromkeys(fuzz().BREACHES, 0), result.first_breaches
    assert result.max_command_speed_ratio <= 1.0 + fuzz().COMMAND_ROUNDOFF
    assert sum(result.actions.values()) >= 400 and result.actions["clip"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("case", ["knee", "reach"])
def test_a_longer_fuzz_breaches_nothing_under_every_condition(case: str) -> None:
    for condition in fuzz().CONDITIONS:
        result = fuzz().run_fuzz(case, condition, 1500, seed=3)
        assert result.breaches == dict.fromkeys(fuzz().BREACHES, 0), (condition,
                                                                        result.first_breaches)
        assert result.actions["stop"] > 0 and result.actions["hold"] > 0


def test_without_the_force_rule_pushing_into_the_patient_breaches_the_limit() -> None:
    run = fuzz().run_fuzz
    safe = run("knee", "contracture", 300, 0, patterns=["force_push"])
    bare = run("knee", "contracture", 300, 0, config_overrides=NO_FORCE, patterns=["force_push"])
    assert safe.breaches["force"] == 0 and safe.max_force_ratio < 1.0
    assert bare.breaches["force"] > 0 and bare.max_force_ratio > 1.0


def test_without_the_range_rule_a_drive_past_the_range_reaches_the_bound() -> None:
    run = fuzz().run_fuzz
    safe = run("reach", "contracture", 300, 0, patterns=["rom_drive"])
    bare = run("reach", "contracture", 300, 0, config_overrides={**NO_FORCE, **NO_RANGE},
               patterns=["rom_drive"])
    assert safe.min_rom_clearance_deg > 0.0  # the filter kept every joint inside its range
    assert bare.min_rom_clearance_deg < 0.0  # the drive reached and passed a bound


def test_the_config_for_the_simulator_reads_its_bounds() -> None:
    from rehabbot.deploy.simulator import SimulatorBackend

    backend = SimulatorBackend("rehab-knee-v2")
    try:
        cfg = FilterConfig.for_simulator(backend, max_speed_rad_s=0.3, max_accel_rad_s2=3.0)
        low, high = backend.rom_bounds_rad()
        assert cfg.rom_low_rad == tuple(low.tolist()) and cfg.rom_high_rad == tuple(high.tolist())
        assert cfg.cuff_force_limit_n == backend.cuff_force_limit_n() == 130.0
        assert cfg.control_dt_s == backend.control_dt_s
        assert cfg.patient_joint_names == ("hip_flexion_r", "hip_abduction_r", "knee_flexion_r")
        assert cfg.n_joints == len(backend.joint_names)
    finally:
        backend.close()
