"""MyoSuite's musculoskeletal right arm in the cuff (patient_model="myo" on the right-arm reach
scene, rehabbot/sim/myo_arm.py): the scene in our joint names, still at home, flexion as
MyoArm's elevation in the sagittal plane, the passive elbow's torque-angle curve, the myo reach
id's spaces, the expert on every exercise, and what is refused."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.sim import build_scene
from rehabbot.sim import myo_patient as mp
from rehabbot.sim.muscles import INFO_KEYS, limb_muscles, muscle_torque_nm
from rehabbot.sim.scene import set_pose

pytest.importorskip("myo_sim", reason='patient_model="myo" needs pip install "rehabbot[myo]"')

MYO_REACH_ID = "rehabbot/rehab-reach-myo-v2"
EXERCISED = ("shoulder_flexion_r", "shoulder_abduction_r", "elbow_flexion_r")


@pytest.fixture(scope="module")
def arm_scene():
    return build_scene("upper_right", patient_model="myo")


# --------------------------------------------------------------------------- the scene


def test_the_right_arm_is_myosuites_in_our_joint_names(arm_scene):
    model = arm_scene.model
    assert arm_scene.exercised_joints == EXERCISED
    assert len(arm_scene.muscle_actuator_ids) == 63
    names = [model.actuator(int(i)).name for i in arm_scene.muscle_actuator_ids]
    assert all(n.startswith(mp.MYO_PREFIX) and n.endswith("_r") for n in names)
    # The exercised arm's muscles are found by their side, as the legs' are.
    assert len(limb_muscles(model, arm_scene.muscle_actuator_ids, "r")) == 63
    # The scapulohumeral rhythm: ten clavicle and scapula joints follow the flexion.
    flexion = model.joint("shoulder_flexion_r").qposadr[0]
    assert len(arm_scene.coupled_joints) == 10
    assert all(c.leader_qpos_adr == flexion for c in arm_scene.coupled_joints)
    # The rigid right arm is not built; the left one is.
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "upper_arm_r") == -1
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "upper_arm_l") >= 0
    # MyoArm's ranges: elevation 0-180 deg, elbow 0-130 deg.
    for joint, expected in (("shoulder_flexion_r", (0, 180)), ("elbow_flexion_r", (0, 130))):
        low, high = np.degrees(model.jnt_range[model.joint(joint).id])
        assert (round(low), round(high)) == expected, joint
    # The wrist and fingers are frozen: the arm's own hinges are the exercised ones, the
    # humerus's rotation and the forearm's pronation.
    assert arm_scene.patient_joint_names[-5:] == (*EXERCISED, "myo/shoulder_rot_r",
                                                 "myo/pro_sup_r")


@pytest.mark.parametrize("level", [0, 4])
def test_the_home_state_is_static(level):
    scene = build_scene("upper_right", patient_model="myo", weight_level=level)
    model = scene.model
    data = scene.make_data()
    assert scene.cuff_errors_m(data).max() < 1e-4
    start = data.qpos.copy()
    for _ in range(500):  # 1 s with the robot at its home setpoints
        mujoco.mj_step(model, data)
    drift_deg = np.degrees(np.abs(data.qpos - start)[scene.patient_qpos_adr])
    # Measured: 0.02 deg at level 0.
    assert drift_deg.max() < 0.5, dict(zip(scene.patient_joint_names, drift_deg, strict=True))
    assert data.ncon == 0  # the robot clears the patient and the chair at home


def _arm_direction(scene, pose_deg: dict[str, float]) -> np.ndarray:
    """The unit vector from the shoulder to the elbow (world: x forward, y left, z up)."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    set_pose(model, data.qpos, pose_deg)
    mujoco.mj_kinematics(model, data)
    shoulder = data.xpos[model.body(f"{mp.MYO_PREFIX}humerus_r").id]
    elbow = data.xpos[model.body(f"{mp.MYO_PREFIX}ulna_r").id]
    return (elbow - shoulder) / np.linalg.norm(elbow - shoulder)


def test_flexion_raises_the_arm_forwards_and_abduction_sideways(arm_scene):
    down = _arm_direction(arm_scene, {"shoulder_flexion_r": 0, "shoulder_abduction_r": 0})
    assert down[2] < -0.95
    forward = _arm_direction(arm_scene, {"shoulder_flexion_r": 90, "shoulder_abduction_r": 0})
    assert forward[0] > 0.95  # in the sagittal plane
    sideways = _arm_direction(arm_scene, {"shoulder_flexion_r": 0, "shoulder_abduction_r": 90})
    assert sideways[1] < -0.95  # the patient's right is world -y


def test_the_rhythm_follows_wherever_a_pose_is_written(arm_scene):
    model = arm_scene.model
    qpos = arm_scene.home_qpos.copy()
    set_pose(model, qpos, {"shoulder_flexion_r": 90})
    moved = qpos.copy()
    arm_scene.follow_coupled_joints(qpos)
    np.testing.assert_array_equal(qpos, moved)
    # MyoArm's linear rhythm: each follower moves by its coefficient times the elevation.
    for coupled in arm_scene.coupled_joints:
        expected = coupled.reference + coupled.coefficients[1] * np.radians(90)
        assert qpos[coupled.qpos_adr] == pytest.approx(expected, abs=1e-12)


# --------------------------------------------------------------------------- passive elbow


def test_the_passive_elbow_resists_at_both_ends_of_its_range(arm_scene):
    """Zero excitation, shoulder at home. Measured [N m] (positive: towards flexion): 0 deg
    0.48, 30 deg 3.28, 60 deg -0.31, 90 deg -2.05, 120 deg -3.55, 130 deg -3.33. The
    brachioradialis and brachialis pull towards flexion in extension, the triceps towards
    extension in flexion; near full extension the flexors' moment arms shrink, so the torque
    falls back to 0.5 N m at 0 deg (MyoArm's geometry)."""
    torque = {a: muscle_torque_nm(arm_scene, "elbow_flexion_r", {"elbow_flexion_r": a})
              for a in (0, 30, 60, 90, 120)}
    assert torque[30] > 0 and torque[0] > 0  # towards flexion in extension
    assert torque[90] < 0 and torque[120] < 0  # towards extension in flexion
    # Mid-range is near neutral: the ends resist several times harder.
    assert abs(torque[30]) > 3 * abs(torque[60])
    assert abs(torque[120]) > 3 * abs(torque[60])
    assert torque[120] < torque[90] < torque[60] < torque[30]


# --------------------------------------------------------------------------- the id


def test_the_myo_reach_id_has_the_base_ids_spaces_and_reports_the_muscles():
    env = gym.make(MYO_REACH_ID)
    base = gym.make("rehabbot/rehab-reach-v2")
    assert env.observation_space == base.observation_space
    assert env.action_space == base.action_space
    assert env.unwrapped.scene.patient_model == "myo"
    obs, info = env.reset(seed=0)
    assert obs.shape == base.observation_space.shape
    assert set(INFO_KEYS) <= set(info)
    obs, _reward, _terminated, _truncated, info = env.step(env.action_space.sample())
    assert info["muscle_force_n"] > 0.0


# --------------------------------------------------------------------------- refusals


def test_what_the_myo_arm_does_not_support_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"limb='arm'.*side='right' only.*'left'.*myoarm_r"):
        gym.make("rehabbot/rehab-reach-l-v2", patient_model="myo")
    with pytest.raises(ValueError, match=r"presets.*upper_right.*not 'upper_left'"):
        build_scene("upper_left", patient_model="myo")
    with pytest.raises(ValueError, match=r"not 'upper_bilateral'"):
        build_scene("upper_bilateral", patient_model="myo")
    with pytest.raises(ValueError, match=r"one adult size.*height_m=1.6"):
        gym.make(MYO_REACH_ID, profile={"height_m": 1.6})
