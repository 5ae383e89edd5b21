"""Scene presets: degrees of freedom, cuff, weight levels, statics, sweeps, contacts, options."""

import itertools
import math

import mujoco
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rehabbot.sim import PRESETS, PatientProfile, build_scene
from rehabbot.sim import patient as pt
from rehabbot.sim import scene as sc
from rehabbot.sim.scripted_sweep import run_sweep

ALL_PRESETS = tuple(PRESETS)
# Minimum range [deg] the sweep must move each preset's exercised joints through.
SWEEP_MINIMUM_DEG = {
    "upper_right": {"shoulder_flexion_r": 45, "elbow_flexion_r": 60},
    "upper_left": {"shoulder_flexion_l": 45, "elbow_flexion_l": 60},
    "upper_bilateral": {"shoulder_flexion_r": 45, "elbow_flexion_r": 60,
                        "shoulder_flexion_l": 45, "elbow_flexion_l": 60},
    "hip": {"hip_flexion_r": 45},
    "knee": {"knee_flexion_r": 60},
}


@pytest.fixture(scope="module")
def scenes():
    return {preset: build_scene(preset) for preset in ALL_PRESETS}


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_degrees_of_freedom(preset, scenes):
    model = scenes[preset].model
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    assert np.all(model.jnt_type == hinge)  # no free joint: the patient is seated or lying
    expected = 33 if preset == "upper_bilateral" else 27
    assert model.njnt == model.nq == model.nv == expected
    patient = [model.joint(n) for n in pt.JOINT_NAMES]
    assert len(patient) == 21


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_cuff_is_satisfied_at_reset(preset, scenes):
    scene = scenes[preset]
    data = scene.make_data()
    assert np.all(scene.cuff_errors_m(data) < 1e-3)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    preset=st.sampled_from(ALL_PRESETS),
    height_m=st.floats(1.45, 2.05),
    mass_kg=st.floats(40.0, 150.0),
    sex=st.sampled_from(pt.SEXES),
    level=st.sampled_from(sc.WEIGHT_LEVELS),
)
def test_cuff_is_satisfied_at_reset_for_any_profile(preset, height_m, mass_kg, sex, level):
    scene = build_scene(preset, PatientProfile(height_m, mass_kg, sex), weight_level=level)
    data = scene.make_data()
    assert np.all(scene.cuff_errors_m(data) < 1e-3)
    # ... and nothing interpenetrates at home.
    assert all(data.contact[i].dist > -1e-3 for i in range(data.ncon))


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_weight_levels_scale_exactly_the_exercised_limb(preset):
    scene = build_scene(preset)
    model = scene.model
    mass0 = model.body_mass.copy()
    inertia0 = model.body_inertia.copy()
    limb = set(scene.limb_body_ids.tolist())
    expected_limb_bodies = {model.body(b).id for limb_name in
                            {h.limb for h in scene.robots}
                            for b in pt.LIMB_BODIES[limb_name]}
    assert limb == expected_limb_bodies
    for level, factor in zip(sc.WEIGHT_LEVELS, sc.weight_factors(preset), strict=True):
        scene.set_weight_level(level)
        for body in range(model.nbody):
            if body in limb:
                assert model.body_mass[body] == pytest.approx(mass0[body] * factor)
                np.testing.assert_allclose(model.body_inertia[body] / model.body_mass[body],
                                           inertia0[body] / mass0[body])
            else:
                assert model.body_mass[body] == mass0[body]
    factors = sc.weight_factors(preset)
    assert factors[0] == 1.0 and sorted(factors) == list(factors) and len(set(factors)) == 5


def test_weight_level_at_reset_equals_weight_level_at_build():
    built = build_scene("upper_right", weight_level=3)
    switched = build_scene("upper_right", weight_level=0)
    switched.set_weight_level(3)
    np.testing.assert_array_equal(built.model.body_mass, switched.model.body_mass)
    np.testing.assert_allclose(built.home_setpoints, switched.home_setpoints, atol=1e-12)
    np.testing.assert_allclose(built.model.qpos_spring, switched.model.qpos_spring, atol=1e-12)


def test_heavier_limb_needs_more_robot_preload():
    scene = build_scene("upper_right")
    preload = []
    for level in sc.WEIGHT_LEVELS:
        scene.set_weight_level(level)
        home = scene.home_qpos[scene.robots[0].qpos_adr]
        preload.append(np.linalg.norm(scene.home_setpoints[0] - home))
    assert all(b > a for a, b in itertools.pairwise(preload))


@pytest.mark.parametrize("preset", ALL_PRESETS)
@pytest.mark.parametrize("level", [0, 4])
def test_holding_still_nothing_drifts(preset, level):
    scene = build_scene(preset, weight_level=level)
    data = scene.make_data()
    q0 = data.qpos.copy()
    mujoco.mj_step(scene.model, data, nstep=round(2.0 / scene.model.opt.timestep))
    assert np.max(np.abs(data.qpos - q0)) < math.radians(1.0)
    assert np.all(scene.cuff_errors_m(data) < 1e-3)


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_nothing_interpenetrates_at_rest(preset, scenes):
    scene = scenes[preset]
    data = scene.make_data()
    for when in ("home", "after 1 s"):
        for i in range(data.ncon):
            contact = data.contact[i]
            names = (scene.model.geom(contact.geom1).name, scene.model.geom(contact.geom2).name)
            assert contact.dist > -1e-3, f"{names} interpenetrate by {-contact.dist:.4f} m {when}"
        mujoco.mj_step(scene.model, data, nstep=500)


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_only_the_cuff_neighbourhood_is_excluded_from_collision(preset, scenes):
    model = scenes[preset].model
    pairs = set()
    for i in range(model.nexclude):
        a, b = model.exclude_signature[i] >> 16, model.exclude_signature[i] & 0xFFFF
        pairs.add(frozenset((model.body(a).name, model.body(b).name)))
    expected = set()
    for handle in scenes[preset].robots:
        for link in ("link4", "link5", "link6"):
            for body in pt.LIMB_BODIES[handle.limb][1:]:
                expected.add(frozenset((f"{handle.prefix}{link}", body)))
    assert pairs == expected


@pytest.mark.parametrize("preset", ALL_PRESETS)
@pytest.mark.parametrize("level", sc.WEIGHT_LEVELS)
def test_scripted_sweep_moves_the_limb_safely(preset, level):
    scene = build_scene(preset, weight_level=level)
    result = run_sweep(scene, duration_s=10.0)
    assert result.finite
    for joint, minimum in SWEEP_MINIMUM_DEG[preset].items():
        assert result.exercised_joint_range_deg[joint] >= minimum, (joint, result)
    assert result.max_cuff_error_m < 0.01
    assert result.within_rom, f"patient joint beyond range by {result.max_rom_excess_deg:.2f} deg"
    assert result.max_robot_torque_nm <= 150.0 + 1e-9


def test_weld_cuff_also_matches_orientation():
    scene = build_scene("upper_right", cuff="weld")
    data = scene.make_data()
    handle = scene.robots[0]
    assert scene.model.eq_type[handle.equality_id] == mujoco.mjtEq.mjEQ_WELD
    np.testing.assert_allclose(data.site_xmat[handle.cuff_site_id],
                               data.site_xmat[handle.patient_cuff_site_id], atol=1e-6)
    assert scene.cuff_errors_m(data)[0] < 1e-3


def test_connect_is_the_default_cuff(scenes):
    scene = scenes["upper_right"]
    assert scene.model.eq_type[scene.robots[0].equality_id] == mujoco.mjtEq.mjEQ_CONNECT


def test_base_reorientation_turns_the_robot_base_by_90_degrees():
    plain = build_scene("upper_right")
    turned = build_scene("upper_right", base_reorientation_deg=90.0)
    d0, d1 = plain.make_data(), turned.make_data()
    base = plain.robots[0].base_body_id
    x0 = d0.xmat[base].reshape(3, 3)[:, 0]
    x1 = d1.xmat[base].reshape(3, 3)[:, 0]
    assert math.degrees(math.acos(np.clip(x0 @ x1, -1, 1))) == pytest.approx(90.0, abs=1e-6)
    assert turned.cuff_errors_m(d1)[0] < 1e-3
    assert not np.allclose(plain.home_qpos[plain.robots[0].qpos_adr],
                           turned.home_qpos[turned.robots[0].qpos_adr])


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_patient_effort_actuators_saturate_at_one_newton_metre(preset, scenes):
    scene = scenes[preset]
    model = scene.model
    assert len(scene.patient_actuator_ids) == len(scene.exercised_joints)
    for act in scene.patient_actuator_ids:
        np.testing.assert_allclose(model.actuator_forcerange[act], [-1.0, 1.0])
        np.testing.assert_allclose(model.actuator_ctrlrange[act], [-1.0, 1.0])


def test_lower_limb_side_and_posture_options():
    left = build_scene("knee", side="left")
    assert left.exercised_joints == ("hip_flexion_l", "hip_abduction_l", "knee_flexion_l")
    seated_hip = build_scene("hip", posture="seated")
    data = seated_hip.make_data()
    assert seated_hip.cuff_errors_m(data)[0] < 1e-3
    assert data.qpos[seated_hip.model.joint("knee_flexion_r").qposadr[0]] == pytest.approx(
        math.radians(90))


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda: build_scene("shoulder"), "preset"),
        (lambda: build_scene("upper_right", weight_level=5), "weight_level"),
        (lambda: build_scene("upper_right", weight_level=1.5), "weight_level"),
        (lambda: build_scene("upper_right", cuff="glue"), "cuff"),
        (lambda: build_scene("knee", side="middle"), "side"),
        (lambda: build_scene("upper_right", side="left"), "side"),
        (lambda: build_scene("knee", posture="supine"), "posture"),
        (lambda: build_scene("upper_right", base_reorientation_deg=float("inf")),
         "base_reorientation_deg"),
        (lambda: build_scene("upper_right", timestep_s=0.5), "timestep_s"),
        (lambda: build_scene("upper_right", stiffness=3), "stiffness"),
        (lambda: build_scene("upper_right", initial_pose_deg={"elbow_flexion_r": 200}),
         "elbow_flexion_r"),
        (lambda: build_scene("upper_right", initial_pose_deg={"wrist_r": 10}), "wrist_r"),
        (lambda: build_scene("upper_right", profile={"height_m": 1.7}), "profile"),
    ],
)
def test_bad_options_raise_value_error_naming_the_value(call, needle):
    with pytest.raises(ValueError, match=needle):
        call()


def test_valid_choices_are_listed_in_errors():
    with pytest.raises(ValueError) as excinfo:
        build_scene("shoulder")
    for preset in ALL_PRESETS:
        assert preset in str(excinfo.value)


@pytest.mark.parametrize(("preset", "pose"), [
    ("upper_right", {"shoulder_flexion_r": 5.0, "elbow_flexion_r": 10.0}),
    ("upper_bilateral", {"shoulder_flexion_l": 60.0, "elbow_flexion_l": 100.0}),
    ("knee", {"knee_flexion_r": 40.0}),
    ("hip", {"hip_flexion_r": 30.0}),
])
def test_home_pose_can_move_without_recompiling(preset, pose):
    scene = build_scene(preset, weight_level=2)
    model_before = scene.model
    scene.set_home_pose(pose)
    assert scene.model is model_before
    data = scene.make_data()
    for name, value in pose.items():
        assert math.degrees(data.qpos[scene.model.joint(name).qposadr[0]]) == pytest.approx(value)
    assert np.all(scene.cuff_errors_m(data) < 1e-3)
    assert all(data.contact[i].dist > -1e-3 for i in range(data.ncon))
    q0 = data.qpos.copy()
    mujoco.mj_step(scene.model, data, nstep=1000)
    assert np.max(np.abs(data.qpos - q0)) < math.radians(1.0)
    # The same pose given at build time gives the same patient posture.
    built = build_scene(preset, weight_level=2, initial_pose_deg=pose)
    np.testing.assert_allclose(built.home_qpos[built.patient_qpos_adr],
                               scene.home_qpos[scene.patient_qpos_adr])


def test_home_pose_rejects_unknown_joints_and_out_of_range_angles(scenes):
    scene = build_scene("upper_right")
    with pytest.raises(ValueError, match="wrist_r"):
        scene.set_home_pose({"wrist_r": 3.0})
    with pytest.raises(ValueError, match="elbow_flexion_r"):
        scene.set_home_pose({"elbow_flexion_r": -20.0})


def test_builds_are_deterministic_and_pickle_round_trips():
    import pickle

    first = build_scene("knee", weight_level=1)
    second = pickle.loads(pickle.dumps(build_scene("knee", weight_level=1)))
    runs = []
    for scene in (first, second):
        data = scene.make_data()
        data.ctrl[scene.robots[0].motor_ids] = [5.0, -5.0, 3.0, 1.0, -1.0, 0.5]
        mujoco.mj_step(scene.model, data, nstep=500)
        runs.append(data.qpos.copy())
    np.testing.assert_array_equal(runs[0], runs[1])
    assert second.weight_level == 1
