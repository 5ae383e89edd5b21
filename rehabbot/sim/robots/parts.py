"""Building blocks every robot module shares: collision classes, link tubes, the rehab cuff,
the per-joint servo + motor pair and the joint's torque clamp (see :mod:`rehabbot.sim.robots`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from rehabbot.sim.robots.base import RobotBuildOptions

# Collision classes shared by every model in the scene (see ``scene.py``): the robot touches
# the patient and the furniture, never itself.
CONTYPE_ROBOT, CONAFFINITY_ROBOT = 1, 0
CUFF_RGBA = (0.15, 0.45, 0.30, 0.6)
BRACKET_RGBA = (0.20, 0.22, 0.25, 1.0)


def add_tube(body: mujoco.MjsBody, name: str, p0, p1, radius: float, rgba, prefix: str,
             kind: mujoco.mjtGeom = mujoco.mjtGeom.mjGEOM_CYLINDER) -> mujoco.MjsGeom:
    """A cylinder (joint housing) or capsule (link tube) from ``p0`` to ``p1`` in the body
    frame, in the robot's collision class."""
    geom = body.add_geom(name=f"{prefix}{name}", type=kind, fromto=[*p0, *p1],
                         size=[radius, 0.0, 0.0], rgba=rgba)
    geom.contype, geom.conaffinity = CONTYPE_ROBOT, CONAFFINITY_ROBOT
    return geom


def add_capsule(body: mujoco.MjsBody, name: str, p0, p1, radius: float, rgba,
                prefix: str) -> mujoco.MjsGeom:
    """A capsule from ``p0`` to ``p1`` (see :func:`add_tube`)."""
    return add_tube(body, name, p0, p1, radius, rgba, prefix, mujoco.mjtGeom.mjGEOM_CAPSULE)


def add_cuff(body: mujoco.MjsBody, prefix: str, opts: RobotBuildOptions,
             flange_z_m: float = 0.0) -> None:
    """The bracket from the flange (at ``flange_z_m`` on the body's z axis) to the cuff, and
    the cuff: a padded strap around the limb, drawn but never collided."""
    off = flange_z_m + opts.cuff_offset_m
    add_capsule(body, "cuff_bracket", (0, 0, flange_z_m), (0, 0, off - opts.cuff_radius_m), 0.02,
                BRACKET_RGBA, prefix)
    cuff = body.add_geom(
        name=f"{prefix}cuff",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        pos=[0, 0, off],
        quat=[np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0],
        size=[opts.cuff_radius_m, 0.03, 0.0],
        rgba=CUFF_RGBA,
    )
    cuff.contype, cuff.conaffinity = 0, 0


def limit_joint_torque(joint: mujoco.MjsJoint, torque_limit_nm: float) -> None:
    """Route gravity compensation through the joint's actuators and clamp their total torque
    (servo + motor + gravity compensation) at ``torque_limit_nm``."""
    joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    joint.actgravcomp = True
    joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
    joint.actfrcrange = [-torque_limit_nm, torque_limit_nm]


def add_joint_actuators(spec: mujoco.MjSpec, prefix: str, joint_names: Sequence[str],
                        kp: Sequence[float], kv: Sequence[float],
                        setpoint_range_rad: Sequence[tuple[float, float]],
                        torque_limit_nm: Sequence[float], servo_group: int,
                        motor_group: int) -> None:
    """Per joint an impedance servo ``<joint>_servo`` (``tau = kp (ctrl - q) - kv qdot``,
    ctrl = setpoint [rad] in ``setpoint_range_rad``) and a feed-forward motor
    ``<joint>_motor`` (ctrl = torque [N·m]), each saturated at the joint's torque limit."""
    for i, joint_name in enumerate(joint_names):
        kp_i, kv_i = float(kp[i]), float(kv[i])
        limit = torque_limit_nm[i]
        servo = spec.add_actuator(name=f"{prefix}{joint_name}_servo",
                                  target=f"{prefix}{joint_name}",
                                  trntype=mujoco.mjtTrn.mjTRN_JOINT)
        servo.group = servo_group
        servo.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        servo.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        servo.gainprm[0] = kp_i
        servo.biasprm[0:3] = [0.0, -kp_i, -kv_i]
        servo.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        servo.ctrlrange = list(setpoint_range_rad[i])
        servo.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        servo.forcerange = [-limit, limit]
        motor = spec.add_actuator(name=f"{prefix}{joint_name}_motor",
                                  target=f"{prefix}{joint_name}",
                                  trntype=mujoco.mjtTrn.mjTRN_JOINT)
        motor.group = motor_group
        motor.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        motor.gainprm[0] = 1.0
        motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        motor.ctrlrange = [-limit, limit]


def standalone_spec(name: str, add_robot: Callable[..., mujoco.MjsBody],
                    opts: RobotBuildOptions | None = None) -> mujoco.MjSpec:
    """A spec holding one robot on the world origin, with the scene's timestep and integrator
    (for tests, benchmarks and inspection); ``add_robot(worldbody, spec, opts)`` builds it."""
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.modelname = name
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    add_robot(spec.worldbody, spec, opts)
    return spec
