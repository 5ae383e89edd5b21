"""MyoSuite's musculoskeletal legs in the cuff (patient_model="myo", rehabbot/sim/myo_patient.py):
the scene in our joint names, still at home, the passive muscles' torque-angle curves, the
coupled knee, the muscles in ``info`` and in the evaluation, the expert on every exercise, and
what is refused, each with its reason."""

from __future__ import annotations

import builtins
import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim import build_scene, myo_arm, statics
from rehabbot.sim import myo_patient as mp
from rehabbot.sim.muscles import INFO_KEYS, muscle_torque_nm

pytest.importorskip("myo_sim", reason='patient_model="myo" needs pip install "rehabbot[myo]"')

MYO_IDS = ("rehabbot/rehab-knee-myo-v2", "rehabbot/rehab-hip-myo-v2")


@pytest.fixture(scope="module")
def knee_scene():
    return build_scene("knee", patient_model="myo")


def _passive_knee_torque_nm(scene, knee_deg: float, hip_deg: float) -> float:
    """The muscles' passive torque on the knee [N m] at a pose (zero excitation)."""
    return muscle_torque_nm(scene, "knee_flexion_r",
                            {"hip_flexion_r": hip_deg, "knee_flexion_r": knee_deg})


# --------------------------------------------------------------------------- the scene


@pytest.mark.parametrize("preset", ["knee", "hip"])
def test_the_legs_are_myosuites_in_our_joint_names_and_hold_still_at_home(preset):
    scene = build_scene(preset, patient_model="myo")
    model = scene.model
    assert scene.patient_model == "myo"
    assert scene.exercised_joints == ("hip_flexion_r", "hip_abduction_r", "knee_flexion_r")
    assert len(scene.muscle_actuator_ids) == 80
    assert all(model.actuator(int(i)).name.startswith(mp.MYO_PREFIX)
               for i in scene.muscle_actuator_ids)
    assert len(scene.coupled_joints) == 14  # MyoLeg's knee: 7 followers per leg
    # Abduction is adduction with the sign turned: MyoLeg's [-50, 30] deg of adduction.
    low, high = np.degrees(model.jnt_range[model.joint("hip_abduction_r").id])
    assert (round(low), round(high)) == (-30, 50)
    data = scene.make_data()
    assert scene.cuff_errors_m(data).max() < 1e-4
    start = data.qpos.copy()
    for _ in range(500):  # 1 s with the robot at its home setpoints
        mujoco.mj_step(model, data)
    drift_deg = np.degrees(np.abs(data.qpos - start))
    # Measured: 0.05 deg (knee), 0.03 deg (hip). Before the pelvis's contacts were left to
    # the rigid pelvis, the seated knee moved 5.7 deg.
    assert drift_deg[scene.patient_qpos_adr].max() < 0.5
    assert drift_deg[scene.robots[0].qpos_adr].max() < 0.1


def test_a_flexion_of_the_knee_moves_the_foot_back_and_its_followers_along(knee_scene):
    model = knee_scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = knee_scene.home_qpos
    mujoco.mj_kinematics(model, data)
    ankle = data.xpos[model.body("myo/talus_r").id].copy()
    follower = knee_scene.coupled_joints[0]
    before = data.qpos[follower.qpos_adr]
    data.qpos[model.joint("knee_flexion_r").qposadr[0]] += math.radians(20)
    knee_scene.follow_coupled_joints(data.qpos)
    mujoco.mj_kinematics(model, data)
    assert data.xpos[model.body("myo/talus_r").id][0] < ankle[0] - 0.05  # backwards
    assert data.qpos[follower.qpos_adr] != before
    # The follower sits where MuJoCo's joint equality wants it: zero residual.
    mujoco.mj_forward(model, data)
    assert np.abs(data.efc_pos[:len(knee_scene.coupled_joints)]).max() < 1e-9


def test_coupling_map_matches_finite_differences(knee_scene):
    model = knee_scene.model
    data = knee_scene.make_data()
    coupling = statics.coupling_map(knee_scene, data)
    site = model.site("cuff_leg_r").id
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, site)
    knee = model.joint("knee_flexion_r")
    moved = mujoco.MjData(model)
    moved.qpos[:] = data.qpos
    moved.qpos[knee.qposadr[0]] += 1e-6
    knee_scene.follow_coupled_joints(moved.qpos)
    mujoco.mj_kinematics(model, moved)
    velocity = (moved.site_xpos[site] - data.site_xpos[site]) / 1e-6
    np.testing.assert_allclose((jac @ coupling)[:, knee.dofadr[0]], velocity, atol=1e-5)
    # Without the followers the cuff's motion is off by millimetres per radian.
    assert np.abs(jac[:, knee.dofadr[0]] - velocity).max() > 1e-3
    assert statics.coupling_map(build_scene("knee"), data=None) is None


# --------------------------------------------------------------------------- passive muscles


def test_passive_knee_torque_rises_at_both_ends_and_with_the_hip_flexed(knee_scene):
    """Measured every 15 deg from 0 to 120 deg. Hip extended: 6.8, 2.9, 0.3, -0.0, -0.6, -1.4,
    -2.2, -4.0, -9.9 N m (flat in mid-range, steep at both ends: the passive force-length
    curve). Seated, hip at 90 deg: 39.7 ... 7.0 (60 deg) ... -9.7 N m: the biarticular
    hamstrings, stretched by the hip, resist extension six times as much."""
    angles = np.arange(0, 121, 15)
    lying = np.array([_passive_knee_torque_nm(knee_scene, a, 0) for a in angles])
    seated = np.array([_passive_knee_torque_nm(knee_scene, a, 90) for a in angles])
    for curve in (lying, seated):
        assert np.all(np.diff(curve) < 0), curve  # extending torque falls as the knee flexes
        assert curve[0] > 3.0 and curve[-1] < -5.0
    slope = -np.diff(lying)  # N m per 15 deg
    assert slope[0] > 4 * slope.min() and slope[-1] > 4 * slope.min(), slope
    assert slope.argmin() not in (0, len(slope) - 1)
    assert seated[0] > 3 * lying[0] and seated[0] > 25.0
    assert abs(seated[4]) < 10.0  # mid-range (60 deg): near neutral


# --------------------------------------------------------------------------- the env


@pytest.fixture(scope="module")
def knee_env():
    env = gym.make("rehabbot/rehab-knee-myo-v2")
    yield env
    env.close()


def test_info_reports_the_muscles_and_their_work_is_the_passive_torques_integral(knee_env):
    """Passive muscle forces depend on length only, so their work over an episode is the
    integral of their knee torque from the first knee angle to the last, whatever the path.
    Measured: -1.246 J counted, -1.186 J integrated (90 -> 58.7 deg)."""
    obs, info = knee_env.reset(seed=3, options={"exercise": 0, "weight_level": 0})
    assert set(INFO_KEYS) <= set(info)
    model, data = knee_env.unwrapped.scene.model, knee_env.unwrapped.data
    knee = model.joint("knee_flexion_r").qposadr[0]
    first = math.degrees(data.qpos[knee])
    expert = ScriptedExpert(knee_env)
    done = False
    while not done:
        obs, _reward, terminated, truncated, info = knee_env.step(expert(obs))
        done = terminated or truncated
    assert info["is_success"]
    assert info["muscle_excitation"] == 0.0 and info["muscle_activation"] == 0.0  # passive
    assert info["muscle_force_n"] > 50.0  # the stretched muscles pull
    assert info["peak_muscle_force_n"] > info["muscle_force_n"] / 40  # >= the mean pull
    grid = np.linspace(first, math.degrees(data.qpos[knee]), 200)
    torque = np.array([_passive_knee_torque_nm(knee_env.unwrapped.scene, a, 90) for a in grid])
    integral = float(np.sum((torque[1:] + torque[:-1]) / 2 * np.diff(np.radians(grid))))
    assert integral < -0.5
    assert abs(info["muscle_work_j"] - integral) < 0.15 * abs(integral)
    # The patient's voluntary work comes from its effort: none for this passive patient.
    assert info["patient_work_j"] == 0.0 and info["assistance_ratio"] == 1.0
    assert knee_env.observation_space.shape == gym.make("rehabbot/rehab-knee-v2") \
        .observation_space.shape


@pytest.mark.slow
@pytest.mark.parametrize("myo_id", MYO_IDS)
def test_a_myo_id_has_its_base_ids_spaces_at_every_weight_level_and_mode(myo_id):
    from rehabbot.envs.registration import MYO_VARIANTS

    def spaces(env_id, **kwargs):
        env = gym.make(env_id, **kwargs)
        obs, _info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        described = (repr(env.observation_space), repr(env.action_space),
                     env.observation_space.low.tobytes(), env.observation_space.high.tobytes(),
                     env.action_space.low.tobytes(), env.action_space.high.tobytes())
        env.close()
        return described

    for mode in ("joint_delta", "joint_position"):
        base = spaces(MYO_VARIANTS[myo_id], control_mode=mode)
        for level in (0, 4):
            assert spaces(myo_id, control_mode=mode, weight_level=level) == base, (mode, level)


def test_the_rigid_patient_reports_no_muscles():
    env = gym.make("rehabbot/rehab-knee-v2")
    _obs, info = env.reset(seed=0)
    assert not set(INFO_KEYS) & set(info)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", [*MYO_IDS, "rehabbot/rehab-reach-myo-v2"])
def test_the_expert_finishes_every_exercise_at_the_lightest_and_heaviest_level(env_id):
    env = gym.make(env_id)
    for exercise in range(len(env.unwrapped.config.exercise_table)):
        for level in (0, 4):
            obs, _info = env.reset(seed=10 * exercise + level,
                                   options={"exercise": exercise, "weight_level": level})
            expert = ScriptedExpert(env)
            done = False
            while not done:
                obs, _reward, terminated, truncated, info = env.step(expert(obs))
                done = terminated or truncated
            assert info["is_success"], (env_id, exercise, level, info["safety_violation"])
            assert info["peak_muscle_force_n"] > 0.0


def test_the_evaluation_tabulates_the_muscles():
    from rehabbot.analysis.evaluation import MUSCLE_METRICS, evaluate, format_table

    report, _trace = evaluate("expert", "rehabbot/rehab-knee-myo-v2", episodes=1, seed=7,
                              env_kwargs={"max_episode_steps": 80})
    assert report["per_episode"][0]["peak_muscle_force_n"] > 0.0
    for key, _label, _unit in MUSCLE_METRICS:
        assert report["summary"][key]["mean"] is not None, key
    table = format_table([report])
    assert "peak muscle force [N]" in table and "muscle work on the limb [J]" in table


# --------------------------------------------------------------------------- contracture


def test_a_contracture_scales_the_muscles_passive_force_and_narrows_the_range():
    healthy = gym.make("rehabbot/rehab-knee-myo-v2").unwrapped.scene
    contracted = gym.make("rehabbot/rehab-knee-myo-v2",
                          condition={"stiffness_scale": 1.3, "rom_scale": 0.8}).unwrapped.scene
    for angle in (20.0, 60.0, 110.0):
        ratio = (_passive_knee_torque_nm(contracted, angle, 90)
                 / _passive_knee_torque_nm(healthy, angle, 90))
        assert abs(ratio - 1.3) < 1e-9, (angle, ratio)  # only the right leg's muscles cross it
    knee = healthy.model.joint("knee_flexion_r").id
    low, high = contracted.model.jnt_range[knee]
    full_low, full_high = healthy.model.jnt_range[knee]
    home = healthy.home_qpos[healthy.model.joint("knee_flexion_r").qposadr[0]]
    assert math.isclose(low, home + 0.8 * (full_low - home))
    assert math.isclose(high, home + 0.8 * (full_high - home))
    # Three times the passive force: holding the knee extended needs more than the cuff's
    # limit, refused when the env is built, naming the target and the force.
    with pytest.raises(ValueError, match=r"infeasible.*knee_flexion_r \d+ deg.*needs \d+ N"):
        gym.make("rehabbot/rehab-knee-myo-v2", condition={"stiffness_scale": 3.0})


# --------------------------------------------------------------------------- refusals


def test_what_the_myo_patient_does_not_support_is_refused_naming_it():
    # MyoSuite's arm is a right arm (tests/test_myo_arm.py): the left arm is refused.
    with pytest.raises(ValueError, match=r"patient_model=.myo.*limb=.arm.*side=.right"):
        gym.make("rehabbot/rehab-reach-l-v2", patient_model="myo")
    with pytest.raises(ValueError, match=r"one adult size.*height_m=1.6"):
        gym.make("rehabbot/rehab-knee-myo-v2", profile={"height_m": 1.6})
    with pytest.raises(ValueError, match=r"patient_model.*.bones."):
        gym.make("rehabbot/rehab-knee-v2", patient_model="bones")
    with pytest.raises(ValueError, match=r"presets \['hip', 'knee', 'upper_right'\] only"):
        build_scene("upper_bilateral", patient_model="myo")


@pytest.mark.parametrize(("preset", "template"), [
    ("knee", mp._legs_template), ("upper_right", myo_arm._arm_template)])
def test_without_myo_sim_the_error_names_the_extra(monkeypatch, preset, template):
    real_import = builtins.__import__

    def no_myo_sim(name, *args, **kwargs):
        if name.startswith("myo_sim"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_myo_sim)
    template.cache_clear()
    try:
        with pytest.raises(mp.MyoModelMissingError,
                           match=r'myo-sim: pip install "rehabbot\[myo\]"'):
            build_scene(preset, patient_model="myo")
    finally:
        monkeypatch.undo()
        template.cache_clear()


# --------------------------------------------------------------------------- the command line


@pytest.mark.slow
def test_snapshot_draws_the_myo_legs_and_refuses_the_left_arm(tmp_path, capsys):
    imageio = pytest.importorskip("imageio.v2")
    from rehabbot.cli import main

    shots = {}
    for model in ("rigid", "myo"):
        out = tmp_path / f"{model}.png"
        assert main(["snapshot", "knee", "--patient-model", model, "--out", str(out),
                     "--width", "160", "--height", "120"]) == 0
        shots[model] = imageio.imread(out)
    assert np.any(shots["rigid"] != shots["myo"], axis=-1).mean() > 0.01
    capsys.readouterr()
    assert main(["snapshot", "upper_left", "--patient-model", "myo",
                 "--out", str(tmp_path / "arm.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not 'upper_left'" in err[0]
    assert not (tmp_path / "arm.png").exists()
