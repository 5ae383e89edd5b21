"""The robot models: the UR5e's and the FR3's published kinematics, masses, joint and torque
limits, gravity compensation and the torque clamp."""

import math

import mujoco
import numpy as np
import pytest

from rehabbot.sim import build_scene
from rehabbot.sim.robots import ROBOT_NAMES, ImpedanceGains, RobotBuildOptions, fr3, get_robot
from rehabbot.sim.robots import ur5e as ur

# Each robot alone on the world origin, and a pose away from its joint limits and singularities.
ROBOT_SPECS = {"ur5e": ur.build_ur5e_spec, "fr3": fr3.build_fr3_spec}
TEST_POSE_RAD = {"ur5e": [0.3, -1.2, 1.4, -1.7, -1.57, 0.2],
                 "fr3": [0.3, -0.6, 0.2, -2.2, 0.3, 1.8, 0.5]}


@pytest.fixture(scope="module")
def ur5e():
    model = ur.build_ur5e_spec().compile()
    return model, mujoco.MjData(model)


@pytest.fixture(scope="module")
def fr3_model():
    model = fr3.build_fr3_spec().compile()
    return model, mujoco.MjData(model)


def test_forward_kinematics_matches_published_dh_table(ur5e):
    model, data = ur5e
    rng = np.random.default_rng(7)
    tool = model.site("tool").id
    for _ in range(25):
        q = rng.uniform(-np.pi, np.pi, 6)
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        expected = ur.dh_forward_kinematics(q)
        np.testing.assert_allclose(data.site_xpos[tool], expected[:3, 3], atol=1e-9)
        np.testing.assert_allclose(data.site_xmat[tool].reshape(3, 3), expected[:3, :3],
                                   atol=1e-9)


def test_zero_pose_reach_is_the_published_arm_length(ur5e):
    model, data = ur5e
    data.qpos[:] = 0
    mujoco.mj_kinematics(model, data)
    # At zero the arm stretches along -x: |a2| + |a3| = 0.8172 m from the pan axis.
    assert data.site_xpos[model.site("tool").id][0] == pytest.approx(-0.8172, abs=1e-9)


def test_link_masses_and_centres_of_mass_are_the_ur5e_values(ur5e):
    model, _ = ur5e
    for i in range(6):
        body = model.body(f"link{i + 1}")
        assert body.mass[0] == pytest.approx(ur.LINK_MASS_KG[i])
        np.testing.assert_allclose(body.ipos, ur.LINK_COM_M[i], atol=1e-12)
    # UR5e arm without base: 17.7 kg (not the legacy UR5 inertials, 17.0 kg).
    assert sum(model.body(f"link{i}").mass[0] for i in range(1, 7)) == pytest.approx(17.7,
                                                                                      abs=0.01)


def test_joint_torque_limits_are_ur5e_limits(ur5e):
    model, _ = ur5e
    for i, name in enumerate(ur.JOINT_NAMES):
        joint = model.joint(name)
        assert model.jnt_actfrclimited[joint.id]
        np.testing.assert_allclose(model.jnt_actfrcrange[joint.id],
                                   [-ur.TORQUE_LIMIT_NM[i], ur.TORQUE_LIMIT_NM[i]])
    assert list(ur.TORQUE_LIMIT_NM) == [150, 150, 150, 28, 28, 28]


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_gravity_compensation_holds_the_arm_with_no_servo_error(name):
    robot = get_robot(name)
    model = ROBOT_SPECS[name]().compile()
    data = mujoco.MjData(model)
    q0 = np.array(TEST_POSE_RAD[name])
    data.qpos[:] = q0
    servo = [model.actuator(f"{j}_servo").id for j in robot.joint_names]
    data.ctrl[servo] = q0
    mujoco.mj_step(model, data, nstep=1000)  # 2 s
    assert np.max(np.abs(data.qpos - q0)) < 1e-6
    # Gravity is balanced by the actuators, not by a servo error.
    assert np.max(np.abs(data.qfrc_actuator - data.qfrc_bias)) < 1e-3


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_total_actuator_torque_is_clamped_to_the_limit(name):
    robot = get_robot(name)
    limits = robot.torque_limits()
    model = ROBOT_SPECS[name]().compile()
    data = mujoco.MjData(model)
    data.qpos[:] = TEST_POSE_RAD[name]
    servo = [model.actuator(f"{j}_servo").id for j in robot.joint_names]
    motor = [model.actuator(f"{j}_motor").id for j in robot.joint_names]
    data.ctrl[servo] = data.qpos + 1.0  # far setpoints: the servo saturates
    data.ctrl[motor] = limits  # and the motor adds its full torque on top
    mujoco.mj_forward(model, data)
    unclamped = data.actuator_force[servo] + data.actuator_force[motor]
    assert np.all(unclamped > limits)  # what was asked for exceeds the limit ...
    np.testing.assert_allclose(data.qfrc_actuator, limits)  # ... what acts does not
    for _ in range(50):
        mujoco.mj_step(model, data)
        assert np.all(np.abs(data.qfrc_actuator) <= limits + 1e-9)


def test_impedance_gains_reject_bad_values():
    kp, kv = ur.DEFAULT_GAINS.kp_nm_per_rad, ur.DEFAULT_GAINS.kv_nms_per_rad
    with pytest.raises(ValueError, match="6 values per joint, got 2"):
        ur.add_ur5e(mujoco.MjSpec().worldbody, mujoco.MjSpec(), RobotBuildOptions(
            gains=ImpedanceGains(kp_nm_per_rad=(1.0, 2.0), kv_nms_per_rad=(1.0, 2.0))))
    with pytest.raises(ValueError, match="kv_nms_per_rad"):
        ImpedanceGains(kp_nm_per_rad=kp, kv_nms_per_rad=(1, 1, 1, 1, 1, float("nan")))
    with pytest.raises(ValueError, match="6 stiffnesses but 5 dampings"):
        ImpedanceGains(kp_nm_per_rad=kp, kv_nms_per_rad=kv[:5])
    with pytest.raises(ValueError, match="gains for ur5e need 6 values"):
        build_scene("upper_right", gains=ImpedanceGains((1.0,) * 7, (1.0,) * 7))


def test_the_robot_model_describes_the_ur5e():
    robot = get_robot("ur5e")
    assert robot is ur.UR5E and robot.n_joints == 6
    assert robot.joint_names == ur.JOINT_NAMES
    np.testing.assert_array_equal(robot.torque_limits(), ur.TORQUE_LIMIT_NM)
    model = ur.build_ur5e_spec().compile()
    assert model.nu == 2 * robot.n_joints and model.njnt == robot.n_joints
    assert [model.body(name).id for name in robot.link_names] == list(range(1, 8))
    with pytest.raises(ValueError, match=r"robot='kuka' is not one of \['ur5e', 'fr3'\]"):
        get_robot("kuka")


# Franka's published modified (Craig) DH table of the FR3, (a [m], d [m], alpha [rad]) per
# joint, and the flange's d: written out here, independently of rehabbot.sim.robots.fr3, so a
# wrong constant there fails.
FR3_PUBLISHED_MDH = ((0.0, 0.333, 0.0), (0.0, 0.0, -math.pi / 2), (0.0, 0.316, math.pi / 2),
                     (0.0825, 0.0, math.pi / 2), (-0.0825, 0.384, -math.pi / 2),
                     (0.0, 0.0, math.pi / 2), (0.088, 0.0, math.pi / 2))
FR3_FLANGE_D_M = 0.107


def craig_forward_kinematics(q_rad) -> np.ndarray:
    """Flange pose from the published table: per joint Rx(alpha) Tx(a) Rz(q) Tz(d)."""
    pose = np.eye(4)
    for (a, d, alpha), q in zip(FR3_PUBLISHED_MDH, q_rad, strict=True):
        rx, tx, rz, tz = np.eye(4), np.eye(4), np.eye(4), np.eye(4)
        rx[1:3, 1:3] = [[math.cos(alpha), -math.sin(alpha)], [math.sin(alpha), math.cos(alpha)]]
        tx[0, 3] = a
        rz[0:2, 0:2] = [[math.cos(q), -math.sin(q)], [math.sin(q), math.cos(q)]]
        tz[2, 3] = d
        pose = pose @ rx @ tx @ rz @ tz
    flange = np.eye(4)
    flange[2, 3] = FR3_FLANGE_D_M
    return pose @ flange


def test_fr3_forward_kinematics_matches_the_published_dh_table(fr3_model):
    model, data = fr3_model
    rng = np.random.default_rng(11)
    tool = model.site("tool").id
    low, high = fr3.FR3.joint_low_rad(), fr3.FR3.joint_high_rad()
    for _ in range(25):
        q = rng.uniform(low, high)
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        expected = craig_forward_kinematics(q)
        np.testing.assert_allclose(data.site_xpos[tool], expected[:3, 3], atol=1e-9)
        np.testing.assert_allclose(data.site_xmat[tool].reshape(3, 3), expected[:3, :3],
                                   atol=1e-9)
        np.testing.assert_allclose(fr3.modified_dh_forward_kinematics(q), expected, atol=1e-12)


@pytest.mark.parametrize(("q_rad", "flange_m"), [
    # q = 0: the arm stands straight up with the wrist offsets along +x, the flange points down.
    ((0, 0, 0, 0, 0, 0, 0), (0.088, 0.0, 0.926)),
    # Franka's "ready" pose (libfranka's examples): 0.3069 m ahead, 0.5903 m up.
    ((0, -math.pi / 4, 0, -3 * math.pi / 4, 0, math.pi / 2, math.pi / 4), (0.3069, 0.0, 0.5903)),
])
def test_fr3_reference_poses(fr3_model, q_rad, flange_m):
    model, data = fr3_model
    data.qpos[:] = q_rad
    mujoco.mj_kinematics(model, data)
    tool = model.site("tool").id
    np.testing.assert_allclose(data.site_xpos[tool], flange_m, atol=1e-4)
    np.testing.assert_allclose(data.site_xmat[tool].reshape(3, 3)[:, 2], (0, 0, -1), atol=1e-9)


def test_fr3_joint_ranges_speeds_and_torque_limits_are_frankas(fr3_model):
    model, _ = fr3_model
    # "Limits for Franka Research 3" (franka_description robots/fr3/joint_limits.yaml).
    low = [-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159]
    high = [2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159]
    torque = [87, 87, 87, 87, 12, 12, 12]
    speed = [2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26]
    robot = get_robot("fr3")
    assert robot.n_joints == 7 and robot.joint_names == fr3.JOINT_NAMES
    for i, name in enumerate(fr3.JOINT_NAMES):
        joint = model.joint(name)
        np.testing.assert_allclose(model.jnt_range[joint.id], [low[i], high[i]])
        assert model.jnt_actfrclimited[joint.id]
        np.testing.assert_allclose(model.jnt_actfrcrange[joint.id], [-torque[i], torque[i]])
    assert list(robot.torque_limits()) == torque
    assert list(robot.max_joint_speed_rad_s) == speed and robot.max_speed_rad_s == 2.62
    np.testing.assert_array_equal(robot.joint_low_rad(), low)
    np.testing.assert_array_equal(robot.joint_high_rad(), high)


def test_fr3_link_masses_are_the_franka_description_values(fr3_model):
    model, _ = fr3_model
    masses = [model.body(f"link{i}").mass[0] for i in range(1, 8)]
    np.testing.assert_allclose(masses, [2.9274653454, 2.9355370338, 2.2449013699, 2.6155955791,
                                        2.3271207594, 1.8170376524, 0.6271432862])
    assert model.body("base").mass[0] == pytest.approx(2.3966)
    # The seven links and the base of franka_description: 17.9 kg.
    assert sum(masses) + model.body("base").mass[0] == pytest.approx(17.89, abs=0.01)
    np.testing.assert_allclose(model.body("link4").ipos, [-0.0459100965, 0.0630492960,
                                                          -0.0085187868], atol=1e-12)


def test_the_robot_model_describes_the_fr3():
    robot = get_robot("fr3")
    assert robot is fr3.FR3
    model = fr3.build_fr3_spec().compile()
    assert model.nu == 2 * robot.n_joints == 14 and model.njnt == 7
    assert [model.body(name).id for name in robot.link_names] == list(range(1, 9))
    with pytest.raises(ValueError, match="gains for fr3 need 7 values per joint, got 6"):
        build_scene("upper_right", robot="fr3", gains=ur.DEFAULT_GAINS)
    # Each IK seed posture turns joint 1 towards the cuff and lies inside the joint ranges.
    seeds = robot.ik_seed(np.array([0.3, -0.3, 0.2]))
    assert seeds.shape == (3, 7)
    np.testing.assert_allclose(seeds[:, 0], -math.pi / 4)
    assert np.all(seeds[:, 1:] >= robot.joint_low_rad()[1:])
    assert np.all(seeds[:, 1:] <= robot.joint_high_rad()[1:])
