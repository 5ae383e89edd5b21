"""The UR5e collaborative robot, built in code with ``mujoco.MjSpec``.

Kinematics follow Universal Robots' published standard Denavit–Hartenberg parameters and link
masses / centres of mass for the UR5e (``docs/physics.md`` lists every number and its source).
Body ``link{i}`` carries DH frame *i*, so the MuJoCo joint angles equal the UR controller's joint
angles and the robot base frame is DH frame 0 (z up; at zero angles the arm stretches along -x).

Actuation per joint (all torques in N·m):

============== ======================================================================
``<j>_servo``   joint impedance: ``tau = kp (setpoint - q) - kv qdot``, ctrl = setpoint [rad]
``<j>_motor``   feed-forward joint torque, ctrl = torque [N·m]
gravity comp.   every link has ``gravcomp=1`` routed through the actuators (``actgravcomp``)
torque limit    the joint's total actuator torque (servo + motor + gravity compensation) is
                clamped to the UR5e limit: 150 N·m (pan, lift, elbow), 28 N·m (wrists)
============== ======================================================================

Control modes choose which of the two actuators carries the command; the clamp on the joint's
total makes the torque limit hold whatever the mode.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from rehabbot.sim.robots.base import ImpedanceGains, RobotBuildOptions, RobotModel
from rehabbot.sim.robots.parts import (
    add_capsule,
    add_cuff,
    add_joint_actuators,
    add_tube,
    limit_joint_torque,
    standalone_spec,
)

JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan",
    "shoulder_lift",
    "elbow",
    "wrist_1",
    "wrist_2",
    "wrist_3",
)

# Standard DH parameters of the UR5e [UR-DH]: a [m], d [m], alpha [rad].
DH_A_M = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
DH_D_M = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
DH_ALPHA_RAD = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])

# Link masses [kg] and centres of mass [m] in DH frame i [UR-DH].
LINK_MASS_KG = np.array([3.761, 8.058, 2.846, 1.37, 1.3, 0.365])
LINK_COM_M = np.array(
    [
        [0.0, -0.02561, 0.00193],
        [0.2125, 0.0, 0.11336],
        [0.15, 0.0, 0.0265],
        [0.0, -0.0018, 0.01634],
        [0.0, 0.0018, 0.01634],
        [0.0, 0.0, -0.001159],
    ]
)
# Principal moments [kg m^2] about the CoM. UR does not publish inertias for the UR5e; these are
# the magnitudes of the official ROS 2 description, with the smallest moment put on the long
# axis of the link (DH x for the upper arm and forearm).
LINK_INERTIA_KGM2 = np.array(
    [
        [0.00700, 0.00648, 0.00657],
        [0.01506, 0.33388, 0.33247],
        [0.00400, 0.07879, 0.07849],
        [0.00165, 0.00136, 0.00126],
        [0.00136, 0.00128, 0.00097],
        [0.000187, 0.000189, 0.000258],
    ]
)
BASE_MASS_KG = 4.0
TORQUE_LIMIT_NM = np.array([150.0, 150.0, 150.0, 28.0, 28.0, 28.0])
JOINT_RANGE_RAD = np.array([2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi])
# Actuator groups: MuJoCo can switch a whole group off (``model.opt.disableactuator``), which
# is how the torque control mode removes the impedance servos.
SERVO_ACTUATOR_GROUP = 1
MOTOR_ACTUATOR_GROUP = 2
MAX_JOINT_SPEED_RAD_S = np.pi  # 180 deg/s on all six joints
ARMATURE_KGM2 = np.array([0.1, 0.1, 0.1, 0.05, 0.05, 0.05])

_BLUE = (0.36, 0.58, 0.78, 1.0)
_GREY = (0.78, 0.80, 0.82, 1.0)
_DARK = (0.20, 0.22, 0.25, 1.0)


# Joint impedance of the servos (per joint): stiff enough to carry a patient's limb with a
# small tracking offset, damped near critically for the link inertias.
DEFAULT_GAINS = ImpedanceGains(kp_nm_per_rad=(1500.0, 1500.0, 1000.0, 200.0, 200.0, 100.0),
                               kv_nms_per_rad=(150.0, 150.0, 90.0, 12.0, 12.0, 6.0))


def _dh_child_frame(i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pose of body ``link{i+1}`` in its parent and the joint axis/anchor in the child frame.

    DH: ``T_i = Rz(theta) Tz(d) Tx(a) Rx(alpha)``. With the fixed part ``F = Tz(d) Tx(a) Rx(alpha)``
    we have ``Rz(theta) F = F (F^-1 Rz(theta) F)``: a hinge in the child frame about
    ``R^T z`` through ``-R^T t``.
    """
    a, d, alpha = DH_A_M[i], DH_D_M[i], DH_ALPHA_RAD[i]
    c, s = np.cos(alpha), np.sin(alpha)
    rot = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    trans = np.array([a, 0.0, d])
    quat = np.array([np.cos(alpha / 2), np.sin(alpha / 2), 0.0, 0.0])
    axis = rot.T @ np.array([0.0, 0.0, 1.0])
    anchor = -rot.T @ trans
    return trans, quat, axis, anchor


_cylinder = add_tube
_capsule = add_capsule


# Link shapes in each DH frame (points in metres). Tubes are grey, joint housings blue.
def _add_link_geometry(body: mujoco.MjsBody, i: int, prefix: str,
                       opts: RobotBuildOptions) -> None:
    if i == 0:  # shoulder: column up from the base, housing around the lift axis (z1)
        _cylinder(body, "shoulder_column", (0, -0.1225, 0), (0, -0.02, 0), 0.06, _BLUE, prefix)
        _cylinder(body, "shoulder_housing", (0, 0, -0.065), (0, 0, 0.075), 0.06, _BLUE, prefix)
    elif i == 1:  # upper arm: tube at the shoulder offset, housings at both ends
        _cylinder(body, "upper_arm_shoulder", (0.425, 0, 0.065), (0.425, 0, 0.19), 0.06, _BLUE,
                  prefix)
        _capsule(body, "upper_arm_tube", (0.37, 0, 0.138), (0.06, 0, 0.138), 0.045, _GREY, prefix)
        _cylinder(body, "upper_arm_elbow", (0, 0, 0.07), (0, 0, 0.19), 0.055, _BLUE, prefix)
    elif i == 2:  # forearm: tube at the elbow offset, ending at the wrist-1 housing
        _capsule(body, "forearm_tube", (0.35, 0, 0.03), (0.05, 0, 0.03), 0.035, _GREY, prefix)
        _cylinder(body, "forearm_wrist1", (0, 0, -0.01), (0, 0, 0.095), 0.045, _BLUE, prefix)
    elif i == 3:  # wrist 1 -> wrist 2 housing (along z4)
        _cylinder(body, "wrist1_housing", (0, 0, -0.035), (0, 0, 0.065), 0.045, _BLUE, prefix)
    elif i == 4:  # wrist 2 -> wrist 3 housing (along z5)
        _cylinder(body, "wrist2_housing", (0, 0, -0.04), (0, 0, 0.065), 0.045, _BLUE, prefix)
    elif i == 5:  # flange, bracket and cuff
        _cylinder(body, "flange", (0, 0, -0.045), (0, 0, 0.0), 0.045, _DARK, prefix)
        add_cuff(body, prefix, opts)


def add_ur5e(parent: mujoco.MjsBody, spec: mujoco.MjSpec, opts: RobotBuildOptions | None = None,
             pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)) -> mujoco.MjsBody:
    """Add a UR5e under ``parent`` with its base frame at ``pos``/``quat``; return the base body.

    Adds bodies ``{prefix}base``, ``{prefix}link1`` … ``{prefix}link6``; joints
    ``{prefix}<JOINT_NAMES>``; sites ``{prefix}tool`` (flange centre, z out of the flange) and
    ``{prefix}cuff`` (cuff centre, same orientation); actuators ``{prefix}<joint>_servo`` and
    ``{prefix}<joint>_motor``. :func:`rehabbot.sim.robots.menagerie.add_menagerie_visuals`
    can draw it with MuJoCo Menagerie's meshes afterwards.
    """
    opts = opts or RobotBuildOptions()
    gains = opts.gains if opts.gains is not None else DEFAULT_GAINS
    UR5E.check_gains(gains)
    p = opts.prefix
    base = parent.add_body(name=f"{p}base", pos=list(pos), quat=list(quat))
    base.explicitinertial = True
    base.mass = BASE_MASS_KG
    base.ipos = [0, 0, 0.03]
    base.inertia = [0.0044, 0.0044, 0.0072]
    _cylinder(base, "base_disc", (0, 0, 0.0), (0, 0, 0.09), 0.075, _BLUE, p)
    base.add_site(name=f"{p}base_frame", pos=[0, 0, 0], size=[0.01, 0, 0])

    body = base
    for i, joint_name in enumerate(JOINT_NAMES):
        trans, quat_i, axis, anchor = _dh_child_frame(i)
        body = body.add_body(name=f"{p}link{i + 1}", pos=list(trans), quat=list(quat_i))
        body.explicitinertial = True
        body.mass = float(LINK_MASS_KG[i])
        body.ipos = list(LINK_COM_M[i])
        body.inertia = list(LINK_INERTIA_KGM2[i])
        body.gravcomp = 1.0
        joint = body.add_joint(
            name=f"{p}{joint_name}",
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=list(axis),
            pos=list(anchor),
            range=[-JOINT_RANGE_RAD[i], JOINT_RANGE_RAD[i]],
            armature=float(ARMATURE_KGM2[i]),
        )
        limit_joint_torque(joint, TORQUE_LIMIT_NM[i])
        _add_link_geometry(body, i, p, opts)

    body.add_site(name=f"{p}tool", pos=[0, 0, 0], size=[0.012, 0, 0], rgba=(1, 0.5, 0, 1))
    body.add_site(name=f"{p}cuff", pos=[0, 0, opts.cuff_offset_m], size=[0.012, 0, 0],
                  rgba=(0.2, 0.8, 0.4, 1))

    add_joint_actuators(spec, p, JOINT_NAMES, gains.kp_nm_per_rad, gains.kv_nms_per_rad,
                        [(-r, r) for r in JOINT_RANGE_RAD], TORQUE_LIMIT_NM,
                        SERVO_ACTUATOR_GROUP, MOTOR_ACTUATOR_GROUP)
    return base


def build_ur5e_spec(opts: RobotBuildOptions | None = None) -> mujoco.MjSpec:
    """A spec holding one UR5e on the world origin (for tests, benchmarks and inspection)."""
    return standalone_spec("ur5e", add_ur5e, opts)


def dh_forward_kinematics(q_rad: np.ndarray) -> np.ndarray:
    """4x4 pose of DH frame 6 (the flange) in the base frame, from the published DH table.

    Independent of MuJoCo: the tests compare it with the compiled model.
    """
    pose = np.eye(4)
    for i in range(6):
        ct, st = np.cos(q_rad[i]), np.sin(q_rad[i])
        ca, sa = np.cos(DH_ALPHA_RAD[i]), np.sin(DH_ALPHA_RAD[i])
        step = np.array(
            [
                [ct, -st * ca, st * sa, DH_A_M[i] * ct],
                [st, ct * ca, -ct * sa, DH_A_M[i] * st],
                [0.0, sa, ca, DH_D_M[i]],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        pose = pose @ step
    return pose


def ik_seed(cuff_in_base_m: np.ndarray) -> np.ndarray:
    """An elbow-up seed that points the arm at a cuff position given in the base frame (at
    pan 0 the arm stretches along -x)."""
    pan = math.atan2(float(cuff_in_base_m[1]), float(cuff_in_base_m[0])) + math.pi
    return np.array([pan, -1.9, 1.9, -1.6, -1.57, 0.0])


UR5E = RobotModel(
    name="ur5e",
    joint_names=JOINT_NAMES,
    torque_limit_nm=tuple(float(t) for t in TORQUE_LIMIT_NM),
    joint_range_rad=tuple((-float(r), float(r)) for r in JOINT_RANGE_RAD),
    max_joint_speed_rad_s=(MAX_JOINT_SPEED_RAD_S,) * len(JOINT_NAMES),
    default_gains=DEFAULT_GAINS,
    build=add_ur5e,
    ik_seed=ik_seed,
    servo_group=SERVO_ACTUATOR_GROUP,
    motor_group=MOTOR_ACTUATOR_GROUP,
)
