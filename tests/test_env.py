"""The four paper environments: registry, spaces, targets, reward, info, reset draws, API."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot
from rehabbot.envs.registration import (
    BILATERAL_IDS,
    CONDITION_VARIANTS,
    ENV_SPECS,
    POPULATION_VARIANTS,
)
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.tasks import exercises as ex
from rehabbot.tasks import targets as tg
from rehabbot.tasks import workspace as ws
from rehabbot.tasks.observation import P_STAR, PHI, THETA, THETA_STAR, P

PAPER_IDS = tuple(i for i in ENV_SPECS if i.endswith("-v0"))
V1_IDS = tuple(i for i in ENV_SPECS if i.endswith("-v1") and i not in CONDITION_VARIANTS
               and i not in POPULATION_VARIANTS and i not in BILATERAL_IDS)
INFO_KEYS = {"is_success", "target_index", "safety_violation", "reward_distance",
             "reward_bonus", "reward_safety", "reward_smoothness", "reward_effort",
             "interaction_force_n", "robot_torque_nm", "patient_qpos", "exercise",
             "weight_level", "action_clipped", "num_targets", "patient_torque_nm",
             "patient_work_j", "robot_work_j", "assistance_ratio"}
REWARD_TERMS = ("reward_distance", "reward_bonus", "reward_safety", "reward_smoothness",
                "reward_effort")


@pytest.fixture(scope="module")
def envs():
    made = {env_id: gym.make(env_id) for env_id in PAPER_IDS}
    yield made
    for env in made.values():
        env.close()


def test_the_four_paper_ids_are_registered_as_kwargs_of_one_class():
    assert set(PAPER_IDS) == {"rehabbot/rehab-reach-v0", "rehabbot/rehab-reach-l-v0",
                              "rehabbot/rehab-hip-v0", "rehabbot/rehab-knee-v0"}
    for env_id in PAPER_IDS:
        spec = gym.spec(env_id)
        assert spec.entry_point == "rehabbot.envs.rehab_env:RehabEnv"
        assert spec.max_episode_steps == 1000
    expected = {
        "rehabbot/rehab-reach-v0": ("arm", "right", "reaching"),
        "rehabbot/rehab-reach-l-v0": ("arm", "left", "trajectory"),
        "rehabbot/rehab-hip-v0": ("hip", "right", "reaching"),
        "rehabbot/rehab-knee-v0": ("knee", "right", "trajectory"),
    }
    for env_id, (limb, side, task) in expected.items():
        kwargs = gym.spec(env_id).kwargs
        assert (kwargs["limb"], kwargs["side"], kwargs["task_type"]) == (limb, side, task)
        assert "reward" not in kwargs  # the paper's eq. (5)
        # Each -v1 id is the same task with the progress reward, and nothing else changed.
        v1 = gym.spec(env_id.replace("-v0", "-v1"))
        assert v1.kwargs == {**kwargs, "reward": "progress"}
        assert v1.entry_point == gym.spec(env_id).entry_point and v1.max_episode_steps == 1000
    assert set(V1_IDS) == {i.replace("-v0", "-v1") for i in PAPER_IDS}


@pytest.mark.slow
def test_every_registered_rehabbot_id_constructs_resets_and_steps():
    ids = [i for i in gym.registry if i.startswith("rehabbot/")]
    assert len(ids) >= 4
    for env_id in ids:
        env = gym.make(env_id)
        obs, _info = env.reset(seed=0)
        obs2, reward, _terminated, _truncated, _info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs) and env.observation_space.contains(obs2)
        assert math.isfinite(reward)
        env.close()


def test_registration_is_idempotent():
    before = len(gym.registry)
    rehabbot.register_envs()
    assert len(gym.registry) == before


def test_paper_spaces(envs):
    for env in envs.values():
        space = env.action_space
        assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
        assert space.shape == (6,)
        np.testing.assert_array_equal(space.low, np.float32(-math.pi / 400))
        np.testing.assert_array_equal(space.high, np.float32(math.pi / 400))
        obs_space = env.observation_space
        assert obs_space.shape == (23,) and obs_space.dtype == np.float32
        assert env.unwrapped.dt_s == pytest.approx(0.02)
        assert env.metadata["render_fps"] == 50


def test_model_and_data_are_exposed(envs):
    env = envs["rehabbot/rehab-reach-v0"].unwrapped
    assert isinstance(env.model, mujoco.MjModel) and isinstance(env.data, mujoco.MjData)


@pytest.mark.parametrize("mode", ["joint_position", "joint_velocity", "torque"])
def test_other_control_modes_have_honest_spaces(mode):
    env = gym.make("rehabbot/rehab-reach-v0", control_mode=mode)
    base = env.unwrapped
    space = env.action_space
    if mode == "joint_position":
        # The hardware ranges (+ 0.5 rad), the same for every patient; this patient's setpoint
        # bounds lie inside, and actions beyond them are clipped to them (and counted).
        np.testing.assert_allclose(space.high, base.robot.joint_high_rad() + 0.5, rtol=1e-6)
        np.testing.assert_allclose(space.low, base.robot.joint_low_rad() - 0.5, rtol=1e-6)
        assert np.all(space.low < base.setpoint_low_rad)
        assert np.all(space.high > base.setpoint_high_rad)
        env.reset(seed=3)
        _obs, _r, _t, _tr, info = env.step(space.high)
        np.testing.assert_allclose(base.controller.setpoint_rad, base.setpoint_high_rad,
                                   rtol=1e-6)
        assert info["action_clipped"] == 6
    elif mode == "joint_velocity":
        np.testing.assert_allclose(space.high, 0.5)
    else:
        np.testing.assert_array_equal(space.high, 1.0)
        # Servos are off: the action is the only robot torque besides gravity compensation.
        assert base.model.opt.disableactuator == 1 << 1
    obs, _ = env.reset(seed=3)
    for _ in range(20):
        obs, _reward, terminated, _, _info = env.step(space.sample())
        assert env.observation_space.contains(obs)
        if terminated:
            obs, _ = env.reset()


def test_joint_delta_moves_the_setpoint_by_the_action_and_keeps_it_in_bounds():
    env = gym.make("rehabbot/rehab-reach-v0", terminate_on_safety=False).unwrapped
    env.reset(seed=0)
    servo = env.handle.servo_ids
    before = env.data.ctrl[servo].copy()
    action = np.array([1, -1, 1, -1, 1, -1], np.float32) * np.float32(math.pi / 800)
    env.step(action)
    np.testing.assert_allclose(env.data.ctrl[servo] - before, action, atol=1e-7)
    for _ in range(400):  # push one joint against its bound
        env.step(np.array([math.pi / 400, 0, 0, 0, 0, 0], np.float32))
    assert env.data.ctrl[servo[0]] <= env.setpoint_high_rad[0] + 1e-12


def test_torque_mode_maps_action_to_the_joint_torque_limits():
    env = gym.make("rehabbot/rehab-reach-v0", control_mode="torque").unwrapped
    env.reset(seed=0)
    env.step(np.array([0.5, 0, 0, 0, 0, -1.0], np.float32))
    motors = env.data.ctrl[env.handle.motor_ids]
    np.testing.assert_allclose(motors, [75.0, 0, 0, 0, 0, -28.0])


# -- exercises and targets ------------------------------------------------------------------
def test_targets_are_feasible_distinct_and_inside_the_bounds(envs):
    for env_id, env in envs.items():
        base = env.unwrapped
        home = base.scene.home_qpos[base.handle.qpos_adr]
        jnt = [base.model.joint(n).id for n in base.scene.exercised_joints]
        rom = np.degrees(base.model.jnt_range[jnt])
        for seq in base.targets:
            assert seq.task_type == ENV_SPECS[env_id][0]["task_type"]
            robot = np.vstack([home, seq.robot_rad])
            steps = np.max(np.abs(np.diff(robot, axis=0)), axis=1)
            assert steps.min() >= 0.1 - 1e-9, "no duplicate consecutive targets, first != start"
            assert np.all(seq.robot_rad >= base.setpoint_low_rad)
            assert np.all(seq.robot_rad <= base.setpoint_high_rad)
            assert np.all(seq.ik_error_m < 1e-4), "every target is reachable with the cuff on"
            assert np.all(seq.patient_deg >= rom[:, 0]) and np.all(seq.patient_deg <= rom[:, 1])
            assert ws.within_table3(base.scene, base.config.scene.limb, seq.patient_deg)
            if seq.task_type == "reaching":
                assert len(seq) == 6
            else:
                assert len(seq) >= 15, "trajectory following uses dense waypoints"


def test_trajectory_waypoints_follow_a_minimum_jerk_profile():
    start = np.array([90.0, 4.0, 90.0])
    keys = np.array([[90.0, 4.0, 30.0]])
    points, is_key = tg.trajectory_samples(start, keys, segment_s=3.0, waypoint_dt_s=0.1)
    assert is_key[-1] and is_key.sum() == 1
    tau = np.arange(1, 31) / 30
    expected = 90.0 - 60.0 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    np.testing.assert_allclose(points[:, 2], expected)
    # Thinning keeps the key pose and spaces the rest.
    keep = tg.thin_waypoints(start, points, is_key, min_spacing=5.0)
    kept = points[keep]
    assert keep[-1] == len(points) - 1
    assert np.min(np.max(np.abs(np.diff(np.vstack([start, kept]), axis=0)), axis=1)) >= 5.0


def test_setpoint_bounds_cover_table3_workspace_and_stay_in_ur5e_ranges(envs):
    for env in envs.values():
        base = env.unwrapped
        grid = ws.workspace_grid_deg(base.scene, base.config.scene.limb)
        assert ws.within_table3(base.scene, base.config.scene.limb, grid)
        assert np.all(base.setpoint_low_rad > -2 * math.pi)
        assert np.all(base.setpoint_high_rad < 2 * math.pi)
        # The robot's joint limits were narrowed around the setpoint bounds.
        jnt = base.model.dof_jntid[base.handle.dof_adr]
        assert np.all(base.model.jnt_range[jnt, 0] < base.setpoint_low_rad)
        assert np.all(base.model.jnt_range[jnt, 1] > base.setpoint_high_rad)


def test_observation_layout_matches_the_state(envs):
    env = envs["rehabbot/rehab-reach-v0"]
    base = env.unwrapped
    obs, _info = env.reset(seed=0, options={"exercise": 1, "weight_level": 2})
    seq = base.target_sequence
    np.testing.assert_allclose(obs[THETA_STAR], seq.robot_rad[0], atol=1e-6)
    np.testing.assert_allclose(obs[P_STAR], seq.tool_pos_base_m[0], atol=1e-6)
    np.testing.assert_allclose(obs[THETA], base.data.qpos[base.handle.qpos_adr], atol=1e-6)
    np.testing.assert_allclose(obs[PHI], base.data.qpos[base.scene.exercised_qpos_adr],
                               atol=1e-6)
    assert obs[21] == 1 and obs[22] == 2
    # Tool position in the robot base frame: its distance from the base equals the world one.
    world = base.data.site_xpos[base.handle.tool_site_id] - \
        base.data.xpos[base.handle.base_body_id]
    assert np.linalg.norm(obs[P]) == pytest.approx(np.linalg.norm(world), abs=1e-6)
    # The target tool position is the flange at theta*.
    data = mujoco.MjData(base.model)
    data.qpos[:] = base.scene.home_qpos
    data.qpos[base.handle.qpos_adr] = seq.robot_rad[0]
    mujoco.mj_kinematics(base.model, data)
    rot = data.xmat[base.handle.base_body_id].reshape(3, 3)
    p_star = rot.T @ (data.site_xpos[base.handle.tool_site_id]
                      - data.xpos[base.handle.base_body_id])
    np.testing.assert_allclose(obs[P_STAR], p_star, atol=1e-6)


def _rollout(env, policy, steps, seed):
    obs, info = env.reset(seed=seed)
    records = [(obs, None, info)]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        records.append((obs, reward, info))
        if terminated or truncated:
            obs, info = env.reset()
            records.append((obs, None, info))
    return records


@pytest.mark.parametrize("mode", ["joint_delta", "torque"])
def test_observations_stay_in_bounds_and_reward_is_the_sum_of_its_terms(mode):
    for env_id in PAPER_IDS:
        env = gym.make(env_id, control_mode=mode, smoothness_weight=0.3, effort_weight=0.2)
        env.action_space.seed(1)
        records = _rollout(env, lambda _obs, env=env: env.action_space.sample(), 300, seed=1)
        if mode == "joint_delta":
            expert = ScriptedExpert(env)
            records += _rollout(env, lambda obs, expert=expert: expert(obs), 300, seed=2)
        for obs, reward, info in records:
            assert env.observation_space.contains(obs), (env_id, obs)
            assert set(info) >= INFO_KEYS
            assert info["robot_torque_nm"].shape == (6,)
            assert info["patient_qpos"].shape == (21,)
            if reward is not None:
                assert reward == pytest.approx(sum(info[k] for k in REWARD_TERMS), abs=1e-9)
                assert info["reward_smoothness"] <= 0 and info["reward_effort"] <= 0


def test_reward_is_equation_5():
    env = gym.make("rehabbot/rehab-reach-v0", exercise=0, weight_level=0).unwrapped
    obs, _ = env.reset(seed=0)
    expert = ScriptedExpert(env)
    bonuses = []
    while True:
        target = env.target_sequence.robot_rad[env.target_index].copy()
        last = env.target_index == len(env.target_sequence) - 1
        obs, _reward, terminated, truncated, info = env.step(expert(obs))
        theta = env.data.qpos[env.handle.qpos_adr]
        error = theta - target
        assert info["reward_distance"] == pytest.approx(-np.linalg.norm(error), abs=1e-12)
        reached = np.max(np.abs(error)) < 0.05
        assert info["reward_bonus"] == (100.0 if last else 10.0) * reached
        bonuses.append(info["reward_bonus"])
        if terminated or truncated:
            break
    assert info["is_success"] and terminated
    assert bonuses.count(10.0) == 5 and bonuses.count(100.0) == 1


def test_extra_reward_terms_are_zero_in_the_paper_ids(envs):
    for env in envs.values():
        env.reset(seed=0)
        for _ in range(5):
            _, _, _, _, info = env.step(env.action_space.sample())
            assert info["reward_smoothness"] == 0.0 and info["reward_effort"] == 0.0


# -- reset draws --------------------------------------------------------------------------------
def test_reset_draws_exercise_and_weight_level_from_the_seed(envs):
    env = envs["rehabbot/rehab-hip-v0"]
    draws = {}
    for seed in range(12):
        _, info = env.reset(seed=seed)
        draws[seed] = (info["exercise"], info["weight_level"])
        _, again = env.reset(seed=seed)
        assert (again["exercise"], again["weight_level"]) == draws[seed]
    assert len(set(draws.values())) > 3
    assert {e for e, _ in draws.values()} == {0, 1}


def test_reset_options_and_constructor_kwargs_fix_the_draws(envs):
    env = envs["rehabbot/rehab-reach-v0"]
    for seed in range(4):
        obs, info = env.reset(seed=seed, options={"exercise": 1, "weight_level": 4})
        assert (info["exercise"], info["weight_level"]) == (1, 4)
        assert obs[21] == 1 and obs[22] == 4
    fixed = gym.make("rehabbot/rehab-reach-v0", exercise=0, weight_level=3)
    for seed in range(4):
        _, info = fixed.reset(seed=seed)
        assert (info["exercise"], info["weight_level"]) == (0, 3)
    # The weight level changes the limb's mass.
    base = fixed.unwrapped
    mass3 = base.model.body_mass[base.scene.limb_body_ids].sum()
    fixed.reset(options={"weight_level": 0})
    mass0 = base.model.body_mass[base.scene.limb_body_ids].sum()
    assert mass3 / mass0 == pytest.approx(1.75)


@pytest.mark.slow
def test_every_variant_is_reachable_by_kwargs():
    for limb in ex.LIMBS:
        for side in ("right", "left"):
            for task in ex.TASK_TYPES:
                env = RehabEnv(limb=limb, side=side, task_type=task,
                               profile={"height_m": 1.6, "mass_kg": 60, "sex": "female"},
                               weight_level=1)
                obs, _info = env.reset(seed=0)
                assert env.observation_space.contains(obs)
                assert env.scene.profile.sex == "female"
                assert env.scene.exercised_joints[0].endswith("_r" if side == "right" else "_l")


@pytest.mark.parametrize("kwargs, word", [
    ({"limb": "neck"}, "limb"), ({"side": "middle"}, "side"), ({"task_type": "dance"}, "task"),
    ({"control_mode": "telepathy"}, "control_mode"), ({"weight_level": 7}, "weight_level"),
    ({"exercise": 2}, "exercise"), ({"profile": {"height_m": 3.0}}, "height"),
    ({"render_mode": "ascii"}, "render_mode"), ({"camera_name": "ceiling"}, "camera_name"),
    ({"frame_skip": 0}, "frame_skip"), ({"target_tolerance_rad": float("nan")}, "tolerance"),
    ({"cuff_force_limit_n": -1.0}, "cuff_force_limit_n"),
    ({"cuff": "velcro"}, "cuff"), ({"base_reorientation_deg": float("inf")}, "base_reorient"),
    ({"timestep_s": 0.05}, "timestep_s"), ({"segment_s": float("nan")}, "segment_s"),
    ({"waypoint_dt_s": 0.0}, "waypoint_dt_s"), ({"min_waypoint_spacing_rad": -0.1}, "spacing"),
    ({"max_speed_rad_s": 10.0}, "max_speed_rad_s"), ({"profile": {"heigth_m": 1.7}}, "heigth_m"),
    ({"profile": {"mass_kg": float("nan")}}, "mass_kg"), ({"profile": {"sex": "x"}}, "sex"),
    ({"profile": "tall"}, "profile"), ({"weight_level": True}, "weight_level"),
    ({"exercise": 1.5}, "exercise"), ({"terminate_on_safety": "yes"}, "terminate_on_safety"),
    ({"safety_penalty": "none"}, "safety_penalty"), ({"safety_penalty_steps": 0}, "steps"),
    ({"rom_tolerance_deg": -1.0}, "rom_tolerance_deg"), ({"width": 0}, "width"),
    ({"contact_tolerance_m": float("nan")}, "contact_tolerance_m"),
])
def test_bad_kwargs_raise_value_error_naming_the_value_before_building(kwargs, word,
                                                                       monkeypatch):
    def fail(*_args, **_kwargs):
        raise AssertionError("the scene was built before the kwargs were checked")

    monkeypatch.setattr("rehabbot.envs.build.build_scene", fail)
    with pytest.raises(ValueError, match=word) as err, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Gymnasium warns about an unknown render_mode
        gym.make("rehabbot/rehab-reach-v0", **kwargs)
    assert repr(next(iter(kwargs.values()))).strip("{}")[:8] in str(err.value) \
        or word in str(err.value)


def test_unknown_id_is_gymnasiums_error_naming_the_id():
    with pytest.raises(gym.error.Error, match="rehab-elbow"):
        gym.make("rehabbot/rehab-elbow-v0")


def test_bad_reset_options_raise(envs):
    env = envs["rehabbot/rehab-reach-v0"]
    with pytest.raises(ValueError, match="exercise"):
        env.reset(options={"exercise": 5})
    with pytest.raises(ValueError, match="weight_level"):
        env.reset(options={"weight_level": -1})
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"speed": 3})


def test_a_refused_first_reset_leaves_a_usable_env():
    """A first reset that raises leaves a usable env: the ids disable Gymnasium's passive
    checker (gym.make's default), under which the next step would raise a TypeError."""
    env = gym.make("rehabbot/rehab-reach-v0")
    with pytest.raises(ValueError, match="exercise=5"):
        env.reset(options={"exercise": 5})
    env.reset(seed=0)
    obs, *_ = env.step(np.zeros(6, np.float32))
    assert env.observation_space.contains(obs)


def test_bad_actions_raise_value_error_and_out_of_bound_actions_are_clipped_and_counted(envs):
    env = envs["rehabbot/rehab-reach-v0"]
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"indices \[1, 4\]"):
        env.step(np.array([0, np.nan, 0, 0, np.inf, 0], np.float32))
    with pytest.raises(ValueError, match=r"expected \(6,\)"):
        env.step(np.zeros(5, np.float32))
    _, _, _, _, info = env.step(np.array([1.0, 0, 0, 0, 0, -1.0]))  # float64, too large
    assert info["action_clipped"] == 2
    base = env.unwrapped
    setpoint = base.controller.setpoint_rad.copy()
    env.step([0.001, 0, 0, 0, 0, 0])  # a list within bounds is accepted
    assert base.controller.setpoint_rad[0] - setpoint[0] == pytest.approx(0.001)
    _, _, _, _, info = env.step(np.zeros(6, np.int64))  # integers are real numbers too
    assert info["action_clipped"] == 0
    for bad in (np.zeros(6, complex), np.zeros(6, bool), ["0.001"] * 6, [None] * 6,
                np.zeros(6, object), "abcdef"):
        with pytest.raises(ValueError, match=r"\(6,\)"):
            env.step(bad)
    with pytest.raises(ValueError, match=r"expected \(6,\)"):
        env.step(np.zeros((1, 6), np.float32))  # a batch of one is not an action
    with pytest.raises(ValueError, match=r"indices \[0\]"):
        env.step([-np.inf, 0, 0, 0, 0, 0])
    # After all the refused actions the env still steps normally.
    _, _, terminated, _, info = env.step(np.zeros(6, np.float32))
    assert not terminated and info["action_clipped"] == 0


def test_step_before_reset_after_termination_and_after_close_are_clear_errors():
    env = RehabEnv(limb="knee", control_mode="joint_position")  # unwrapped: no OrderEnforcing
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.step(np.zeros(6, np.float32))
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(env.action_space.high)  # a far setpoint at once
    assert terminated and info["safety_violation"] is not None
    with pytest.raises(gym.error.ResetNeeded, match="terminated"):
        env.step(np.zeros(6, np.float32))
    env.reset(seed=0)  # a reset makes it usable again
    env.close()
    env.close()  # a no-op
    with pytest.raises(RuntimeError, match="close"):
        env.step(np.zeros(6, np.float32))


# -- exercises of one's own -----------------------------------------------------------------
def test_an_exercise_of_ones_own_is_taught_without_editing_the_package():
    from rehabbot import Exercise
    from rehabbot.tasks.exercises import exercises_for

    raise_arm = Exercise("shoulder_raise", "shoulder flexion to 100 deg",
                         ({"shoulder_flexion": 55}, {"shoulder_flexion": 80},
                          {"shoulder_flexion": 100}))
    as_dict = {"name": "elbow_reach", "key_poses_deg": [{"elbow_flexion": 45},
                                                        {"elbow_flexion": 100}]}
    env = gym.make("rehabbot/rehab-reach-v0", exercises=(*exercises_for("arm"), raise_arm,
                                                         as_dict))
    base = env.unwrapped
    assert [e.name for e in base.exercises] == ["shoulder_flexion", "elbow_flexion",
                                                "shoulder_raise", "elbow_reach"]
    assert env.observation_space.high[21] == 3  # e ranges over the table
    expert = ScriptedExpert(env)
    for exercise, targets in ((2, 3), (3, 2)):
        obs, info = env.reset(seed=0, options={"exercise": exercise})
        assert info["num_targets"] == targets and obs[21] == exercise
        for _ in range(1000):
            obs, _r, terminated, truncated, info = env.step(expert(obs))
            if terminated or truncated:
                break
        assert info["is_success"] and info["safety_violation"] is None
        # The last target holds the patient near the last key pose (the robot is within
        # 0.05 rad of theta* on every joint; the strap and the limb's weight add a few degrees).
        last_pose = base.exercises[exercise].key_poses_deg[-1]
        joint = f"{next(iter(last_pose))}_r"
        assert math.degrees(base.data.qpos[base.model.joint(joint).qposadr[0]]) == \
            pytest.approx(next(iter(last_pose.values())), abs=6.0)


@pytest.mark.parametrize(("exercises", "message"), [
    ([{"name": "x", "key_poses_deg": [{"knee_flexion": 30}]}],
     r"moves \['knee_flexion'\], which are not joints of the 'arm' limb"),
    ([{"name": "x", "key_poses_deg": []}], "non-empty sequence"),
    ([{"name": "x", "key_poses_deg": [{"elbow_flexion": float("nan")}]}],
     "elbow_flexion=nan must be a finite angle"),
    ([{"name": "x", "key_poses_deg": [{"elbow_flexion": 40}]},
      {"name": "x", "key_poses_deg": [{"elbow_flexion": 50}]}], "names must be unique"),
    ([{"name": "x", "poses": []}], "needs the fields name, key_poses_deg"),
    ("shoulder", "non-empty sequence of Exercise objects"),
])
def test_bad_exercises_are_refused_naming_the_problem(exercises, message):
    with pytest.raises(ValueError, match=message):
        RehabEnv(exercises=exercises)


def test_an_exercise_index_beyond_the_table_is_refused():
    with pytest.raises(ValueError, match=r"exercise=2 is not one of \[0, 1\]"):
        RehabEnv(exercise=2)
    env = RehabEnv()
    with pytest.raises(ValueError, match=r"exercise=5 is not one of \[0, 1\]"):
        env.reset(options={"exercise": 5})
