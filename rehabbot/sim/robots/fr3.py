"""The Franka Research 3 (FR3), a 7-joint torque-controlled arm, built in code with
``mujoco.MjSpec``.

Kinematics follow Franka's published modified (Craig) Denavit–Hartenberg table [FR3-DH]; joint
ranges, speeds and torque limits are Franka's "Limits for Franka Research 3" [FR3-LIMITS];
link masses, centres of mass and inertia tensors are the values of Franka's
``franka_description`` package [FR3-INERTIALS]. ``docs/physics.md`` lists every number, its
source and what is estimated. Body ``link{i}`` carries Craig frame *i* (the joint *i* axis is
its z axis through its origin), so MuJoCo's joint angles are libfranka's ``q`` and the robot
base frame is Craig frame 0 (z up; at ``q = 0`` the elbow and wrist offsets point along +x).

Actuation per joint is that of every RehabBot robot (:mod:`rehabbot.sim.robots.parts`): an
impedance servo ``<j>_servo``, a feed-forward motor ``<j>_motor``, gravity compensation of the
links routed through the actuators, and the joint's total torque clamped at 87 N·m (joints 1-4)
or 12 N·m (joints 5-7).
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

JOINT_NAMES: tuple[str, ...] = tuple(f"fr3_joint{i}" for i in range(1, 8))

# Modified DH (Craig) [FR3-DH]: frame i in frame i-1 is Rx(alpha_i) Tx(a_i) Rz(q_i) Tz(d_i).
MDH_A_M = np.array([0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088])
MDH_D_M = np.array([0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0])
MDH_ALPHA_RAD = np.array([0.0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2,
                          np.pi / 2])
FLANGE_D_M = 0.107  # the flange frame: Tz(0.107) from frame 7

# Joint limits [FR3-LIMITS]: position [rad] (joints 4 and 6 are asymmetric), speed [rad/s],
# torque [N·m]. The position set is the narrower of the two that Franka has published (the
# other widens joints 1, 2, 4-7 by 0.03-0.16 rad), so every pose is inside both.
JOINT_LOW_RAD = np.array([-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159])
JOINT_HIGH_RAD = np.array([2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159])
MAX_JOINT_SPEED_RAD_S = np.array([2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26])
TORQUE_LIMIT_NM = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
# Position-based speed limits [FR3-LIMITS]: towards a position limit at distance d [rad] a
# joint may move at most sqrt(2 * deceleration * d) - offset [rad/s] (never above its rated
# speed), so that it can always stop before the limit; the robot aborts a motion past it.
SPEED_LIMIT_OFFSET_RAD_S = np.array([0.30, 0.20, 0.20, 0.30, 0.35, 0.35, 0.35])
SPEED_LIMIT_DECELERATION_RAD_S2 = np.array([6.0, 2.585, 3.5, 4.0, 17.0, 5.5, 17.0])


def speed_envelope_rad_s(q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and highest joint speeds [rad/s] the FR3 allows at ``q_rad`` (7 joints): its
    rated speeds, narrowed near a position limit to what stops in time (zero at the limit)."""
    up_rad = np.maximum(JOINT_HIGH_RAD - q_rad, 0.0)
    down_rad = np.maximum(q_rad - JOINT_LOW_RAD, 0.0)
    ramp = 2.0 * SPEED_LIMIT_DECELERATION_RAD_S2
    high = np.clip(np.sqrt(ramp * up_rad) - SPEED_LIMIT_OFFSET_RAD_S, 0.0, MAX_JOINT_SPEED_RAD_S)
    low = np.clip(np.sqrt(ramp * down_rad) - SPEED_LIMIT_OFFSET_RAD_S, 0.0, MAX_JOINT_SPEED_RAD_S)
    return -low, high

# Inertial parameters of links 1-7 in Craig frame i [FR3-INERTIALS]: mass [kg], centre of mass
# [m], inertia tensor about the centre of mass (ixx, iyy, izz, ixy, ixz, iyz) [kg m^2].
LINK_MASS_KG = np.array([2.9274653454, 2.9355370338, 2.2449013699, 2.6155955791,
                         2.3271207594, 1.8170376524, 0.6271432862])
LINK_COM_M = np.array([
    [0.0000004128, -0.0181251324, -0.0386035970],
    [0.0031828864, -0.0743221644, 0.0088146084],
    [0.0407015686, -0.0048200565, -0.0289730823],
    [-0.0459100965, 0.0630492960, -0.0085187868],
    [-0.0016039605, 0.0292536262, -0.0972965990],
    [0.0597131221, -0.0410294666, -0.0101692726],
    [0.0045225817, 0.0086261921, -0.0161633251],
])
LINK_INERTIA_KGM2 = np.array([
    [0.023927316, 0.022482161, 0.006350098, 0.000013318, -0.000114048, -0.001995032],
    [0.041938946, 0.025145149, 0.061702145, 0.000202573, 0.004077784, -0.004225216],
    [0.024101425, 0.019740533, 0.019044494, 0.002404695, -0.002856269, -0.002104213],
    [0.034529983, 0.028881622, 0.041254712, 0.013225523, 0.010151430, -0.000976283],
    [0.051610278, 0.047877297, 0.016423626, -0.005715173, -0.003567317, 0.010673985],
    [0.005412334, 0.014058330, 0.016080818, 0.006193456, 0.001421929, -0.001314075],
    [0.000210924, 0.000177186, 0.000059932, -0.000024333, 0.000045645, 0.000087441],
])
BASE_MASS_KG = 2.3966
BASE_COM_M = (-0.0172, 0.0004, 0.0745)
BASE_INERTIA_KGM2 = (0.0090, 0.0115, 0.0085, 0.0, 0.0020, 0.0)
# Reflected rotor inertia [kg m^2]: not published by Franka; an estimate of the same order as
# the UR5e's (large joints / wrist joints).
ARMATURE_KGM2 = np.array([0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05])
# The servo setpoints may lie this far beyond a joint's range (a load-carrying setpoint near the
# range's end); the env's joint_position space uses the same margin.
SETPOINT_MARGIN_RAD = 0.5
SERVO_ACTUATOR_GROUP = 1
MOTOR_ACTUATOR_GROUP = 2

# Joint impedance (docs/physics.md, "The FR3"): stiffness that keeps the tracking error of the
# heaviest limb load below about 0.05 rad within the 87 N·m limit, damping near critical for
# the effective inertia each joint sees with a limb strapped on.
DEFAULT_GAINS = ImpedanceGains(
    kp_nm_per_rad=(1200.0, 1200.0, 1000.0, 1000.0, 150.0, 150.0, 60.0),
    kv_nms_per_rad=(110.0, 110.0, 80.0, 80.0, 8.0, 8.0, 3.0))

_WHITE = (0.92, 0.92, 0.93, 1.0)
_GREY = (0.55, 0.57, 0.60, 1.0)
_DARK = (0.20, 0.22, 0.25, 1.0)


def _link_geometry(body: mujoco.MjsBody, i: int, prefix: str) -> None:
    """Collision capsules and joint housings of link ``i + 1`` in its Craig frame [m]."""
    tube, capsule = add_tube, add_capsule
    if i == 0:  # column from the base up to the joint-2 housing (about y1)
        capsule(body, "link1_column", (0, 0, -0.19), (0, 0, -0.06), 0.06, _WHITE, prefix)
        tube(body, "link1_housing", (0, -0.065, 0), (0, 0.065, 0), 0.06, _WHITE, prefix)
    elif i == 1:  # upper arm, lower half, along -y2
        capsule(body, "link2_tube", (0, -0.04, 0), (0, -0.2, 0), 0.06, _WHITE, prefix)
    elif i == 2:  # upper arm, upper half (along z3), and the elbow offset
        capsule(body, "link3_tube", (0, 0, -0.13), (0, 0, -0.02), 0.06, _WHITE, prefix)
        capsule(body, "link3_elbow", (0, 0, 0), (0.0825, 0, 0), 0.055, _WHITE, prefix)
    elif i == 3:  # joint-4 housing and the start of the forearm (along +y4, offset -x4)
        tube(body, "link4_housing", (0, 0, -0.055), (0, 0, 0.055), 0.055, _GREY, prefix)
        capsule(body, "link4_tube", (0, 0, 0), (-0.0825, 0.1, 0), 0.055, _WHITE, prefix)
    elif i == 4:  # forearm, along z5, ending at the wrist
        capsule(body, "link5_tube", (0, 0, -0.27), (0, 0, -0.05), 0.055, _WHITE, prefix)
    elif i == 5:  # wrist: joint-6 housing and the offset to joint 7
        tube(body, "link6_housing", (0, 0, -0.05), (0, 0, 0.05), 0.05, _GREY, prefix)
        capsule(body, "link6_offset", (0, 0, 0), (0.088, 0, 0), 0.045, _WHITE, prefix)
    else:  # joint-7 housing, flange, bracket and cuff
        tube(body, "link7_housing", (0, 0, -0.04), (0, 0, 0.09), 0.045, _GREY, prefix)
        tube(body, "flange", (0, 0, 0.09), (0, 0, FLANGE_D_M), 0.04, _DARK, prefix)


def add_fr3(parent: mujoco.MjsBody, spec: mujoco.MjSpec, opts: RobotBuildOptions | None = None,
            pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)) -> mujoco.MjsBody:
    """Add an FR3 under ``parent`` with its base frame at ``pos``/``quat``; return the base body.

    Adds bodies ``{prefix}base``, ``{prefix}link1`` … ``{prefix}link7``; joints
    ``{prefix}<JOINT_NAMES>``; sites ``{prefix}tool`` (flange centre, z out of the flange) and
    ``{prefix}cuff`` (cuff centre, same orientation); actuators ``{prefix}<joint>_servo`` and
    ``{prefix}<joint>_motor``.
    """
    opts = opts or RobotBuildOptions()
    gains = opts.gains if opts.gains is not None else DEFAULT_GAINS
    FR3.check_gains(gains)
    p = opts.prefix
    base = parent.add_body(name=f"{p}base", pos=list(pos), quat=list(quat))
    base.explicitinertial = True
    base.mass = BASE_MASS_KG
    base.ipos = list(BASE_COM_M)
    base.fullinertia = list(BASE_INERTIA_KGM2)
    add_tube(base, "base_column", (0, 0, 0.0), (0, 0, 0.14), 0.08, _WHITE, p)
    base.add_site(name=f"{p}base_frame", pos=[0, 0, 0], size=[0.01, 0, 0])

    body = base
    for i, joint_name in enumerate(JOINT_NAMES):
        alpha, a, d = MDH_ALPHA_RAD[i], MDH_A_M[i], MDH_D_M[i]
        # Rz(q) and Tz(d) commute: the body sits at Rx(alpha) Tx(a) Tz(d), the hinge is its z.
        body = body.add_body(name=f"{p}link{i + 1}",
                             pos=[a, -math.sin(alpha) * d, math.cos(alpha) * d],
                             quat=[math.cos(alpha / 2), math.sin(alpha / 2), 0.0, 0.0])
        body.explicitinertial = True
        body.mass = float(LINK_MASS_KG[i])
        body.ipos = list(LINK_COM_M[i])
        body.fullinertia = list(LINK_INERTIA_KGM2[i])
        body.gravcomp = 1.0
        joint = body.add_joint(name=f"{p}{joint_name}", type=mujoco.mjtJoint.mjJNT_HINGE,
                               axis=[0, 0, 1], pos=[0, 0, 0],
                               range=[JOINT_LOW_RAD[i], JOINT_HIGH_RAD[i]],
                               armature=float(ARMATURE_KGM2[i]))
        limit_joint_torque(joint, TORQUE_LIMIT_NM[i])
        _link_geometry(body, i, p)

    add_cuff(body, p, opts, flange_z_m=FLANGE_D_M)
    body.add_site(name=f"{p}tool", pos=[0, 0, FLANGE_D_M], size=[0.012, 0, 0],
                  rgba=(1, 0.5, 0, 1))
    body.add_site(name=f"{p}cuff", pos=[0, 0, FLANGE_D_M + opts.cuff_offset_m],
                  size=[0.012, 0, 0], rgba=(0.2, 0.8, 0.4, 1))
    setpoint_range = [(low - SETPOINT_MARGIN_RAD, high + SETPOINT_MARGIN_RAD)
                      for low, high in zip(JOINT_LOW_RAD, JOINT_HIGH_RAD, strict=True)]
    add_joint_actuators(spec, p, JOINT_NAMES, gains.kp_nm_per_rad, gains.kv_nms_per_rad,
                        setpoint_range, TORQUE_LIMIT_NM, SERVO_ACTUATOR_GROUP,
                        MOTOR_ACTUATOR_GROUP)
    return base


def build_fr3_spec(opts: RobotBuildOptions | None = None) -> mujoco.MjSpec:
    """A spec holding one FR3 on the world origin (for tests, benchmarks and inspection)."""
    return standalone_spec("fr3", add_fr3, opts)


def modified_dh_forward_kinematics(q_rad: np.ndarray) -> np.ndarray:
    """4x4 pose of the flange in the base frame, from the published modified DH table.

    Independent of MuJoCo: the tests compare it with the compiled model.
    """
    pose = np.eye(4)
    for i in range(7):
        ct, st = np.cos(q_rad[i]), np.sin(q_rad[i])
        ca, sa = np.cos(MDH_ALPHA_RAD[i]), np.sin(MDH_ALPHA_RAD[i])
        a, d = MDH_A_M[i], MDH_D_M[i]
        step = np.array([
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ])
        pose = pose @ step
    flange = np.eye(4)
    flange[2, 3] = FLANGE_D_M
    return pose @ flange


# IK seed postures (joints 2-7; joint 1 turns towards the cuff), tried in order: the elbow up
# and out, the forearm level, the wrist bent so that the flange meets the limb from the side
# (arm, seated knee) or from above (supine leg). The IK keeps its solution near the seed
# (rehabbot.sim.ik.RobotIK), so the first posture that reaches the cuff is the home branch.
SEED_POSTURES_RAD = np.array([
    [0.0, 0.0, -2.0, 0.0, 2.0, 0.8],
    [0.3, 0.0, -1.5, 0.0, 2.5, 0.8],
    [0.0, 0.0, -2.0, 0.0, 1.5, 0.8],
])

# Where the FR3's stand goes, from the scene's default (UR5e) placement, in the patient's
# mirror-symmetric frame (along x, outwards, up) [m] (docs/physics.md, "Placing the FR3"). The
# FR3's shoulder sits 0.333 m above its base and its wrist is offset from the flange, so its
# stand moves to where the limb's whole workspace box lies inside its reach on one IK branch,
# at least 0.1 rad inside every joint's range, for patients of 1.4-2.0 m
# (benchmarks/results/robot_placement.py measures it).
BASE_OFFSET_M = (
    ("arm", (-0.45, 0.0, -0.10)),  # beside the shoulder instead of in front of it
    ("leg_seated", (-0.25, 0.20, -0.20)),  # closer to the knee, lower, further out
    ("leg_supine", (0.0, -0.05, 0.05)),
)


def ik_seed(cuff_in_base_m: np.ndarray) -> np.ndarray:
    """IK seeds (one per row, tried in order) for a cuff position given in the base frame:
    :data:`SEED_POSTURES_RAD` with joint 1 turned towards the cuff."""
    pan = math.atan2(float(cuff_in_base_m[1]), float(cuff_in_base_m[0]))
    return np.column_stack([np.full(len(SEED_POSTURES_RAD), pan), SEED_POSTURES_RAD])


FR3 = RobotModel(
    name="fr3",
    joint_names=JOINT_NAMES,
    torque_limit_nm=tuple(float(t) for t in TORQUE_LIMIT_NM),
    joint_range_rad=tuple((float(low), float(high))
                          for low, high in zip(JOINT_LOW_RAD, JOINT_HIGH_RAD, strict=True)),
    max_joint_speed_rad_s=tuple(float(v) for v in MAX_JOINT_SPEED_RAD_S),
    default_gains=DEFAULT_GAINS,
    build=add_fr3,
    ik_seed=ik_seed,
    servo_group=SERVO_ACTUATOR_GROUP,
    motor_group=MOTOR_ACTUATOR_GROUP,
    base_offset_m=BASE_OFFSET_M,
)
