"""Safety terminations: each rule provoked, its penalty, and the expert never triggering one."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from rehabbot.envs.config import CONTACT_TOLERANCE_MAX_M, CUFF_FORCE_LIMIT_MAX_N
from rehabbot.sim.physics import (
    BLOWUP_FORCE_N,
    BLOWUP_SPEED_RAD_S,
    ISO_TS_15066_QUASI_STATIC_N,
    RULES,
)
from rehabbot.sim.robots import ur5e as ur
from rehabbot.tasks.exercises import Exercise
from rehabbot.tasks.reward import STOP_MARGIN


def _run_until_terminated(env, policy, max_steps=300):
    hold_distance = env.unwrapped.reward_function.hold_distance_rad  # before the first step
    for _ in range(max_steps):
        _obs, reward, terminated, truncated, info = env.step(policy())
        info["test_hold_distance"] = hold_distance  # of the state before this step
        if terminated or truncated:
            return reward, info
        hold_distance = env.unwrapped.reward_function.hold_distance_rad
    raise AssertionError("the episode did not end")


def _assert_safety_penalty(env, reward, info):
    base = env.unwrapped
    steps_left = base.max_episode_steps - base._steps + 1
    if base.config.reward.safety_penalty_steps is not None:
        steps_left = min(steps_left, base.config.reward.safety_penalty_steps)
    assert not info["is_success"]
    if base.config.reward.safety_penalty == "worst_case":
        assert info["reward_safety"] == pytest.approx(steps_left * base.worst_step_reward)
        # Never better than continuing: at least the worst return of the remaining steps in
        # this patient's bounds.
        low, high = base.healthy_obs_low, base.healthy_obs_high
        worst_distance = np.linalg.norm(np.maximum(high[9:15] - low[0:6], high[0:6] - low[9:15]))
        assert info["reward_safety"] <= -worst_distance * (steps_left - 1) + 1e-6
    else:
        # "hold": at least what holding still from the state before the step would cost
        # until the time limit, at the larger of its distance and this step's.
        extras = base.config.reward.smoothness_weight + base.config.reward.effort_weight
        per_step = max(-info["reward_distance"], info["test_hold_distance"]) + extras
        if base.config.reward.safety_penalty_steps is None:
            # The gap G to the best hold of the episode, this step's other terms, one step,
            # the margin.
            rest = info["reward_distance"] + info["reward_smoothness"] + info["reward_effort"]
            expected = -(max(base.reward_function.hold_gap + rest, 0.0) + per_step + STOP_MARGIN)
            assert info["reward_safety"] == pytest.approx(expected)
            # Never better than holding still from the state before the step: that pays its
            # distance for every step left (steps_left counts this one and one more).
            assert reward < -(steps_left - 1) * info["test_hold_distance"]
        else:
            assert info["reward_safety"] == pytest.approx(-steps_left * per_step)
        assert info["reward_safety"] < 0
    assert reward == pytest.approx(info["reward_distance"] + info["reward_safety"])


def _pull_cuff_away_from_shoulder(base, scale):
    """Torque-mode policy: J^T F with F pulling the hand away from the shoulder (extends the
    elbow), normalised to the joint torque limits."""
    model, data = base.model, base.data
    jac = np.zeros((3, model.nv))
    shoulder = data.xpos[model.body("upper_arm_r").id]

    def policy():
        hand = data.site_xpos[base.handle.cuff_site_id]
        direction = (hand - shoulder) / np.linalg.norm(hand - shoulder)
        mujoco.mj_jacSite(model, data, jac, None, base.handle.cuff_site_id)
        torque = jac[:, base.handle.dof_adr].T @ (scale * direction)
        return np.clip(torque / ur.TORQUE_LIMIT_NM, -1, 1).astype(np.float32)

    return policy


def test_forcing_the_elbow_into_hyperextension_ends_with_range_of_motion():
    # The other two stops as loose as their physical bounds allow (rehabbot.envs.config).
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque",
                   cuff_force_limit_n=CUFF_FORCE_LIMIT_MAX_N,
                   contact_tolerance_m=CONTACT_TOLERANCE_MAX_M)
    base = env.unwrapped
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    reward, info = _run_until_terminated(env, _pull_cuff_away_from_shoulder(base, 400.0))
    assert info["safety_violation"] == "range_of_motion"
    elbow = base.data.qpos[base.model.joint("elbow_flexion_r").qposadr[0]]
    assert math.degrees(elbow) < -2.0, "the elbow is hyperextended past its 0 deg limit"
    _assert_safety_penalty(env, reward, info)


def test_cuff_force_beyond_the_iso_limit_ends_the_episode():
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque", safety_penalty="worst_case")
    base = env.unwrapped
    assert base.safety.force_limit_n == ISO_TS_15066_QUASI_STATIC_N["hands_and_fingers"] == 140
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    reward, info = _run_until_terminated(env, lambda: np.array([0, -0.5, 0, 0, 0, 0],
                                                               np.float32))
    assert info["safety_violation"] == "cuff_force"
    assert info["interaction_force_n"] > 140
    _assert_safety_penalty(env, reward, info)


def test_leg_cuff_uses_the_lower_leg_limit_and_the_threshold_is_a_kwarg():
    assert gym.make("rehabbot/rehab-knee-v0").unwrapped.safety.force_limit_n == 130
    env = gym.make("rehabbot/rehab-hip-v0", cuff_force_limit_n=20.0, terminate_on_safety=False)
    assert env.unwrapped.safety.force_limit_n == 20.0
    _obs, info = env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    assert info["interaction_force_n"] > 20.0  # the cuff carries the supine leg at rest
    _, _, terminated, _, info = env.step(np.zeros(6, np.float32))
    assert not terminated and info["safety_violation"] == "cuff_force"
    # A limit that the limb at rest already exceeds would end every episode at its first
    # step: with terminate_on_safety the env refuses it when it is built.
    with pytest.raises(ValueError, match=r"cuff_force_limit_n=20.0 N") as err:
        gym.make("rehabbot/rehab-hip-v0", cuff_force_limit_n=20.0)
    assert "at rest" in str(err.value)


@pytest.mark.slow
def test_profiles_that_cannot_do_the_exercise_are_refused_when_the_env_is_built():
    heavy = {"height_m": 1.75, "mass_kg": 130.0, "sex": "male"}
    with pytest.raises(ValueError, match=r"weight_level 2: the cuff carries 13\d N") as err:
        gym.make("rehabbot/rehab-hip-v0", profile=heavy)
    assert "weight levels [0, 1] are usable" in str(err.value)
    env = gym.make("rehabbot/rehab-hip-v0", profile=heavy, weight_level=1)
    _, info = env.reset(seed=0)
    with pytest.raises(ValueError, match="weight_level 3"):
        env.reset(seed=0, options={"weight_level": 3})
    # The usable level holds the leg below the limit for a whole second of holding still.
    for _ in range(50):
        _, _, terminated, _, info = env.step(np.zeros(6, np.float32))
        assert not terminated
    assert info["interaction_force_n"] < 130.0
    with pytest.raises(ValueError, match="foot_l touches forearm_wrist1"):
        gym.make("rehabbot/rehab-knee-v0", side="left",
                 profile={"height_m": 1.5, "mass_kg": 60.0, "sex": "male"})
    # An exercise beyond the paper's ranges: its target needs a robot angle outside the
    # setpoint bounds.
    beyond = Exercise("shoulder_flexion_150", "shoulder flexion to 150 deg",
                      ({"shoulder_flexion": 150.0},))
    with pytest.raises(ValueError, match=r"target 0 of exercise 'shoulder_flexion_150' needs "
                                         r"robot joint 2 at .* outside its setpoint bounds"):
        gym.make("rehabbot/rehab-reach-v0", exercises=(beyond,))
    # The robot's stand does not move with the patient's height, so short patients' arms
    # (1.20 m) build and reach their targets too.
    for env_id in ("rehabbot/rehab-reach-l-v0", "rehabbot/rehab-reach-v0"):
        env = gym.make(env_id, profile={"height_m": 1.2, "mass_kg": 30.0, "sex": "male"})
        _, info = env.reset(seed=0)
        assert info["interaction_force_n"] < env.unwrapped.safety.force_limit_n


def test_driving_the_robot_into_the_patient_or_furniture_is_unintended_contact():
    env = gym.make("rehabbot/rehab-knee-v0", control_mode="torque")
    base = env.unwrapped
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    reward, info = _run_until_terminated(env, lambda: np.array([0, 0.5, 0, 0, 0, 0],
                                                               np.float32))
    assert info["safety_violation"] == "unintended_contact"
    robot = set(base.scene.robot_geom_ids.tolist())
    others = set(base.scene.patient_geom_ids.tolist()) | set(
        base.scene.furniture_geom_ids.tolist())
    pairs = [tuple(c.geom) for c in base.data.contact[: base.data.ncon]]
    assert any((a in robot and b in others) or (b in robot and a in others) for a, b in pairs)
    _assert_safety_penalty(env, reward, info)


def test_unstable_physics_option_ends_with_instability_and_the_next_reset_is_healthy(
        tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the cwd
    # terminate_on_safety=False: the other rules only report; instability still ends.
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque", terminate_on_safety=False)
    base = env.unwrapped
    options = {"exercise": 0, "weight_level": 0}
    obs0, _ = env.reset(seed=0, options=options)
    for _ in range(3):
        healthy_obs, *_ = env.step(np.zeros(6, np.float32))
    # A deliberately unstable option: a 50 ms explicit-Euler step under bang-bang torques.
    base.model.opt.timestep = 0.05
    base.model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    for k in range(50):
        sign = 1.0 if k % 2 else -1.0
        hold_distance = base.reward_function.hold_distance_rad
        obs, reward, terminated, truncated, info = env.step(np.full(6, sign, np.float32))
        info["test_hold_distance"] = hold_distance
        if terminated:
            break
    assert terminated and not truncated and info["safety_violation"] == "instability"
    bad_qacc = base.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
    assert bad_qacc >= 1, "MuJoCo itself flagged the divergence"
    # The last healthy observation, finite and in its space; the penalty is charged.
    np.testing.assert_array_equal(obs, healthy_obs)
    assert env.observation_space.contains(obs) and math.isfinite(reward)
    _assert_safety_penalty(env, reward, info)
    assert all(np.all(np.isfinite(v)) for v in info.values() if isinstance(v, (float, np.ndarray)))
    with pytest.raises(gym.error.ResetNeeded, match="terminated"):
        env.step(np.zeros(6, np.float32))
    # reset() is healthy even with the bad option still set (it does not step the physics)...
    obs, _ = env.reset(seed=0, options=options)
    np.testing.assert_array_equal(obs, obs0)
    # ... and with the option restored the episode runs as before.
    base.model.opt.timestep = 0.002
    base.model.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    obs, _ = env.reset(seed=0, options=options)
    np.testing.assert_array_equal(obs, obs0)
    for _ in range(3):
        obs, reward, terminated, _, info = env.step(np.zeros(6, np.float32))
        assert info["safety_violation"] is None and not terminated
    np.testing.assert_array_equal(obs, healthy_obs)


def test_instability_detectors_catch_blow_ups_that_mujoco_does_not_reset():
    env = gym.make("rehabbot/rehab-knee-v0")
    base = env.unwrapped
    env.reset(seed=0)
    monitor, data = base.safety, base.data
    force = monitor.cuff_force_n(data)
    assert monitor.check(data, force) is None
    assert monitor.check(data, float("nan")) == "instability"
    assert monitor.check(data, 2.0 * BLOWUP_FORCE_N) == "instability"
    data.qvel[base.handle.dof_adr[0]] = 2.0 * BLOWUP_SPEED_RAD_S  # finite: MuJoCo keeps it
    assert monitor.check(data, force) == "instability"
    data.qvel[:] = 0.0
    assert monitor.check(data, force) is None
    # An observation outside its bounds is one too: shrink the checked bound of theta[0]
    # below the current angle; the env returns its last healthy observation.
    healthy_obs, *_ = env.step(np.zeros(6, np.float32))
    high = base.healthy_obs_high.copy()
    high[9] = healthy_obs[9] - 0.01
    base.set_healthy_box(base.healthy_obs_low, high)
    obs, reward, terminated, _, info = env.step(np.zeros(6, np.float32))
    assert terminated and info["safety_violation"] == "instability"
    np.testing.assert_array_equal(obs, healthy_obs)
    assert math.isfinite(reward) and info["reward_safety"] < 0


def test_terminate_on_safety_false_reports_without_ending():
    env = gym.make("rehabbot/rehab-hip-v0", cuff_force_limit_n=5.0, terminate_on_safety=False)
    env.reset(seed=0)
    _, _reward, terminated, _, info = env.step(np.zeros(6, np.float32))
    assert info["safety_violation"] == "cuff_force" and not terminated
    assert info["reward_safety"] == 0.0


def test_rules_are_documented():
    assert RULES == ("instability", "range_of_motion", "cuff_force", "unintended_contact")
    import rehabbot.sim.physics as safety

    for rule in RULES:
        assert f'"{rule}"' in safety.__doc__


def test_hold_penalty_never_pays_better_than_holding_still():
    """With the default penalty (every step left, uncapped), stopping costs at least what
    holding still from the state before the step would cost until the time limit; an unknown
    penalty name is refused."""
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque")
    base = env.unwrapped
    reward_config = base.config.reward
    assert reward_config.safety_penalty == "hold" and reward_config.safety_penalty_steps is None
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    reward, info = _run_until_terminated(env, _pull_cuff_away_from_shoulder(base, 400.0))
    steps_left = base.max_episode_steps - base._steps + 1
    assert info["safety_violation"] is not None
    _assert_safety_penalty(env, reward, info)
    # Holding still from the state before the step pays its distance for every step left.
    assert reward < -(steps_left - 1) * info["test_hold_distance"]
    with pytest.raises(ValueError, match=r"safety_penalty.*'hold'.*'worst_case'"):
        gym.make("rehabbot/rehab-reach-v0", safety_penalty="none")


def test_safety_penalty_steps_caps_the_steps_counted():
    assert gym.make("rehabbot/rehab-reach-v0").unwrapped.config.reward.safety_penalty_steps is None
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque", safety_penalty_steps=50)
    base = env.unwrapped
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    _reward, info = _run_until_terminated(env, _pull_cuff_away_from_shoulder(base, 400.0))
    assert base.max_episode_steps - base._steps + 1 > 50  # the cap is what binds
    per_step = max(-info["reward_distance"], info["test_hold_distance"])
    assert info["reward_safety"] == pytest.approx(-50 * per_step)
    with pytest.raises(ValueError, match="safety_penalty_steps"):
        gym.make("rehabbot/rehab-reach-v0", safety_penalty_steps=0)


def test_range_of_motion_reads_every_joint():
    """A joint beyond its range (after mj_forward) fires the rule; a fast joint inside its
    range does not."""
    env = gym.make("rehabbot/rehab-reach-v0")
    base = env.unwrapped
    env.reset(seed=0)
    monitor, model, data = base.safety, base.model, base.data
    elbow = model.joint("elbow_flexion_r")
    _low, high = model.jnt_range[elbow.id]
    force = monitor.cuff_force_n(data)
    assert monitor.check(data, force) is None
    data.qpos[elbow.qposadr[0]] = high + math.radians(2.5)  # beyond range + 2 deg tolerance
    mujoco.mj_forward(model, data)
    assert monitor.check(data, monitor.cuff_force_n(data)) == "range_of_motion"
    # Inside the range but moving fast: the joints are inside.
    base.scene.reset_data(data)
    monitor.reset(data)
    data.qvel[elbow.dofadr[0]] = 50.0
    assert monitor.check(data, monitor.cuff_force_n(data)) is None
