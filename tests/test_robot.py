"""The UR5e model: published kinematics, masses, torque limits, gravity compensation."""

import mujoco
import numpy as np
import pytest

from rehabbot.sim import build_scene
from rehabbot.sim.robots import ImpedanceGains, RobotBuildOptions, get_robot
from rehabbot.sim.robots import ur5e as ur


@pytest.fixture(scope="module")
def ur5e():
    model = ur.build_ur5e_spec().compile()
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


def test_gravity_compensation_holds_the_arm_with_no_servo_error(ur5e):
    model, data = ur5e
    mujoco.mj_resetData(model, data)
    q0 = np.array([0.3, -1.2, 1.4, -1.7, -1.57, 0.2])
    data.qpos[:] = q0
    servo = [model.actuator(f"{j}_servo").id for j in ur.JOINT_NAMES]
    data.ctrl[servo] = q0
    mujoco.mj_step(model, data, nstep=1000)  # 2 s
    assert np.max(np.abs(data.qpos - q0)) < 1e-6
    # Gravity is balanced by the actuators, not by a servo error.
    assert np.max(np.abs(data.qfrc_actuator - data.qfrc_bias)) < 1e-3


def test_total_actuator_torque_is_clamped_to_the_limit(ur5e):
    model, data = ur5e
    mujoco.mj_resetData(model, data)
    data.qpos[:] = [0, -1.57, 1.57, -1.57, -1.57, 0]
    servo = [model.actuator(f"{j}_servo").id for j in ur.JOINT_NAMES]
    motor = [model.actuator(f"{j}_motor").id for j in ur.JOINT_NAMES]
    data.ctrl[servo] = data.qpos + 1.0  # far setpoints: the servo saturates
    data.ctrl[motor] = ur.TORQUE_LIMIT_NM  # and the motor adds its full torque on top
    mujoco.mj_forward(model, data)
    unclamped = data.actuator_force[servo] + data.actuator_force[motor]
    assert np.all(unclamped > ur.TORQUE_LIMIT_NM)  # what was asked for exceeds the limit ...
    np.testing.assert_allclose(data.qfrc_actuator, ur.TORQUE_LIMIT_NM)  # ... what acts does not
    for _ in range(50):
        mujoco.mj_step(model, data)
        assert np.all(np.abs(data.qfrc_actuator) <= ur.TORQUE_LIMIT_NM + 1e-9)


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
    with pytest.raises(ValueError, match=r"robot='kuka' is not one of \['ur5e'\]"):
        get_robot("kuka")
