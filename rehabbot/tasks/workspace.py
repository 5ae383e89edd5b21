"""Where the robot may go: the patient poses of a limb's workspace box (inside the paper's
Table 3 human ranges and the patient's range of motion) and the robot setpoint bounds that
hold the limb anywhere in it (:func:`setpoint_bounds`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import mujoco
import numpy as np

from rehabbot.common.checks import check_choice
from rehabbot.sim import statics
from rehabbot.sim.ik import RobotIK, quat_from_mat
from rehabbot.sim.scene import Scene
from rehabbot.tasks.exercises import LIMBS

# Patient poses the robot's setpoints may reach (a box inside Table 3 and the patient's ROM):
# joint base name -> (low, high) [deg]; the other exercised joints stay at home.
WORKSPACE_DEG: dict[str, dict[str, tuple[float, float]]] = {
    "arm": {"shoulder_flexion": (0.0, 120.0), "elbow_flexion": (10.0, 135.0)},
    "hip": {"hip_flexion": (0.0, 85.0)},
    "knee": {"knee_flexion": (5.0, 120.0)},
}

# The paper's Table 3, per limb: (human joint, mapped UR5e joint, low, high [rad], sign).
# Table 3 writes elbow and knee flexion as negative angles: ``sign`` turns our clinical angle
# (flexion positive) into Table 3's convention. Our patient has no shoulder internal rotation
# (two-hinge shoulder): that row is kept at 0.
TABLE3_RANGES_RAD: dict[str, tuple[tuple[str, str, float, float, float], ...]] = {
    "arm": (("shoulder_flexion", "shoulder_lift", -np.pi / 2, 3 * np.pi / 4, 1.0),
            ("shoulder_rotation", "shoulder_pan", -np.pi / 2, np.pi / 2, 1.0),
            ("elbow_flexion", "elbow", -3 * np.pi / 4, 0.0, -1.0)),
    "hip": (("hip_flexion", "shoulder_lift", -np.pi / 6, np.pi / 2, 1.0),
            ("hip_rotation", "shoulder_pan", -np.pi / 3, np.pi / 6, 1.0)),
    "knee": (("knee_flexion", "shoulder_lift", -3 * np.pi / 4, 0.0, -1.0),),
}
WORKSPACE_MARGIN_RAD = 0.1


def workspace_grid_deg(scene: Scene, limb: str, step_deg: float = 5.0) -> np.ndarray:
    """(M, 3) patient poses spanning the limb's workspace box, in a serpentine order so that
    consecutive poses are neighbours (the IK stays on one branch)."""
    home = np.degrees(scene.home_qpos[scene.exercised_qpos_adr])
    box = WORKSPACE_DEG[limb]
    axes = []
    for name, (low, high) in box.items():
        index = [j.rsplit("_", 1)[0] for j in scene.exercised_joints].index(name)
        axes.append((index, np.linspace(low, high, 1 + math.ceil((high - low) / step_deg))))
    rows = [home.copy()]
    if len(axes) == 1:
        (i, values), = axes
        for v in values:
            row = home.copy()
            row[i] = v
            rows.append(row)
    else:
        (i, outer), (j, inner) = axes
        for n, a in enumerate(outer):
            for b in (inner if n % 2 == 0 else inner[::-1]):
                row = home.copy()
                row[i], row[j] = a, b
                rows.append(row)
    return np.array(rows)


_BOUNDS_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_BOUNDS_CACHE_SIZE = 64


def setpoint_bounds(scene: Scene, limb: str) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds [rad] of the robot's joint setpoints for ``limb`` in ``scene``.

    The robot angles (and load-carrying setpoints) that hold the patient anywhere in the limb's
    workspace box (:data:`WORKSPACE_DEG`, inside Table 3's human ranges), widened by
    :data:`WORKSPACE_MARGIN_RAD`. For Table 3's mapped joints this is Table 3's range seen in
    robot joint space; for the other joints it acts as a safety-configured joint limit inside
    the UR5e's +-2 pi. Cached per scene geometry (preset, profile, posture, options).
    """
    check_choice("limb", limb, LIMBS)
    key = (scene.preset, scene.posture, scene.profile, limb, repr(scene.options),
           scene.weight_level)
    if key not in _BOUNDS_CACHE:
        robot = workspace_robot_angles(scene, workspace_grid_deg(scene, limb))
        low = robot.min(axis=0) - WORKSPACE_MARGIN_RAD
        high = robot.max(axis=0) + WORKSPACE_MARGIN_RAD
        low.setflags(write=False)
        high.setflags(write=False)
        if len(_BOUNDS_CACHE) >= _BOUNDS_CACHE_SIZE:
            _BOUNDS_CACHE.pop(next(iter(_BOUNDS_CACHE)))
        _BOUNDS_CACHE[key] = (low, high)
    return _BOUNDS_CACHE[key]


def solve_workspace(scene: Scene, grid_deg: np.ndarray, max_jump_rad: float = 0.6,
                    max_error_m: float = 1e-3) -> Iterator[tuple[np.ndarray, mujoco.MjData]]:
    """Solve the robot's IK for patient poses ``grid_deg`` on the home IK branch, yielding
    ``(q, data)`` per reachable pose: its robot angles, and ``data`` holding the pose (patient
    and robot angles set, kinematics only; valid until the next pose).

    Poses are solved outwards from home, each from the nearest pose solved so far; a pose the
    IK cannot reach (``max_error_m``) or reaches only by jumping to another branch (a joint
    moving more than ``max_jump_rad`` from its seed) is left out.
    """
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    handle = scene.robots[0]
    ik = RobotIK(model)
    solved_deg = [np.degrees(scene.home_qpos[scene.exercised_qpos_adr])]
    solved_q = [scene.home_qpos[handle.qpos_adr].copy()]
    rest = solved_q[0]  # a redundant robot's rest posture (rehabbot.sim.ik.RobotIK)
    site = handle.patient_cuff_site_id
    # Grow outwards from home, so each pose's nearest solved pose is a neighbour.
    order = np.argsort(np.max(np.abs(grid_deg - solved_deg[0]), axis=1), kind="stable")
    for row in grid_deg[order]:
        nearest = int(np.argmin(np.max(np.abs(np.array(solved_deg) - row), axis=1)))
        data.qpos[scene.exercised_qpos_adr] = np.radians(row)
        scene.follow_coupled_joints(data.qpos)
        mujoco.mj_kinematics(model, data)
        q, err = ik.solve(data, handle, data.site_xpos[site].copy(),
                          quat_from_mat(data.site_xmat[site]), solved_q[nearest], posture=rest)
        if err > max_error_m or np.max(np.abs(q - solved_q[nearest])) > max_jump_rad:
            continue
        solved_deg.append(row)
        solved_q.append(q)
        yield q, data


def workspace_robot_angles(scene: Scene, grid_deg: np.ndarray, max_jump_rad: float = 0.6,
                           max_error_m: float = 1e-3) -> np.ndarray:
    """Robot angles and load-carrying setpoints (2 per reachable pose, stacked) for patient
    poses ``grid_deg``, all on the home IK branch (:func:`solve_workspace`)."""
    out = []
    for q, data in solve_workspace(scene, grid_deg, max_jump_rad, max_error_m):
        mujoco.mj_forward(scene.model, data)
        setpoint = statics.servo_setpoints(scene, data, statics.cuff_load_torque(scene, data))
        out.extend([q, setpoint[0]])
    return np.array(out)


def table3_angles_rad(scene: Scene, limb: str, patient_deg: np.ndarray) -> np.ndarray:
    """(rows, len(Table 3 rows of ``limb``)) human joint angles in Table 3's convention [rad]
    for rows of exercised-joint angles; joints that are not exercised take their home angle."""
    patient_deg = np.atleast_2d(patient_deg)
    side = scene.exercised_joints[0].rsplit("_", 1)[1]
    names = [j.rsplit("_", 1)[0] for j in scene.exercised_joints]
    cols = []
    for human, _robot, _low, _high, sign in TABLE3_RANGES_RAD[limb]:
        if human in names:
            angle = np.radians(patient_deg[:, names.index(human)])
        elif f"{human}_{side}" in scene.patient_joint_names:
            adr = scene.model.joint(f"{human}_{side}").qposadr[0]
            angle = np.full(len(patient_deg), scene.home_qpos[adr])
        else:
            angle = np.zeros(len(patient_deg))
        cols.append(sign * angle)
    return np.stack(cols, axis=1)


def within_table3(scene: Scene, limb: str, patient_deg: np.ndarray) -> bool:
    """Whether every row of ``patient_deg`` is inside Table 3's human ranges for ``limb``."""
    angles = table3_angles_rad(scene, limb, patient_deg)
    lows = np.array([row[2] for row in TABLE3_RANGES_RAD[limb]])
    highs = np.array([row[3] for row in TABLE3_RANGES_RAD[limb]])
    return bool(np.all((angles >= lows - 1e-9) & (angles <= highs + 1e-9)))
