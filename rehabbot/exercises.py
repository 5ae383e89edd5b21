"""Therapy exercises in clinical terms, and the robot targets that carry the limb through them.

An exercise is a list of key poses of the patient's exercised joints (degrees, positive in the
clinical direction: flexion, abduction), starting from the scene's home posture. The robot's
target joint angles theta* and tool positions p* are derived from the coupled kinematics
(:func:`rehabbot.kinematics.coupled_path`), so every target is reachable with the cuff on.

* **reaching**: the key poses themselves are the targets (``N = 6`` per exercise);
* **trajectory**: a minimum-jerk path (Flash & Hogan 1985) from the home posture through the
  key poses, sampled every ``waypoint_dt_s`` seconds of a ``segment_s``-long segment, with
  waypoints closer than ``min_waypoint_spacing_deg`` to the previous one dropped.

Each limb also has a *workspace*: the box of patient poses, inside the paper's Table 3 human
ranges and the patient's range of motion, that the robot's setpoints are limited to
(:func:`setpoint_bounds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot import statics
from rehabbot.kinematics import CoupledPath, RobotIK, coupled_path, minimum_jerk, quat_from_mat
from rehabbot.models.scene import Scene, check_choice

LIMBS = ("arm", "hip", "knee")
TASK_TYPES = ("reaching", "trajectory")
EXERCISE_IDS = (0, 1)


@dataclass(frozen=True)
class Exercise:
    """One therapy exercise: key poses of the exercised joints, from the home posture."""

    name: str
    description: str
    # Key poses: joint base name (no side suffix) -> angle [deg]; joints not named stay at home.
    key_poses_deg: tuple[dict[str, float], ...]


# Home postures (rehabbot.models.scene): arm shoulder flexion 30, abduction 12, elbow 70;
# supine leg hip flexion 5, abduction 5, knee 10; seated leg hip flexion 90, knee 90.
EXERCISES: dict[str, tuple[Exercise, Exercise]] = {
    "arm": (
        Exercise("shoulder_flexion",
                 "shoulder flexion 30 -> 90 deg in 15 deg steps and back to 40 deg, "
                 "elbow held at 70 deg",
                 tuple({"shoulder_flexion": a} for a in (45, 60, 75, 90, 65, 40))),
        Exercise("elbow_flexion",
                 "elbow extension 70 -> 30 deg, then flexion to 120 deg and back to 90 deg, "
                 "shoulder held at 30 deg flexion",
                 tuple({"elbow_flexion": a} for a in (50, 30, 60, 90, 120, 90))),
    ),
    "hip": (
        Exercise("straight_leg_raise",
                 "supine straight-leg raise: hip flexion 5 -> 60 deg in 10-15 deg steps, "
                 "knee held near extension by the patient",
                 tuple({"hip_flexion": a} for a in (15, 25, 35, 45, 55, 60))),
        Exercise("hip_flexion_cycles",
                 "supine straight-leg hip flexion-extension cycles of growing amplitude "
                 "(15, 30, 20, 35, 25, 40 deg)",
                 tuple({"hip_flexion": a} for a in (15, 30, 20, 35, 25, 40))),
    ),
    "knee": (
        Exercise("knee_extension",
                 "seated knee extension 90 -> 20 deg and back to 50 deg, hip held at 90 deg",
                 tuple({"knee_flexion": a} for a in (75, 60, 45, 30, 20, 50))),
        Exercise("knee_flexion_cycles",
                 "seated knee flexion-extension cycles between 35 and 85 deg",
                 tuple({"knee_flexion": a} for a in (70, 50, 35, 60, 85, 60))),
    ),
}

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


@dataclass(frozen=True)
class TargetSequence:
    """Targets of one exercise, in patient and robot joint space."""

    exercise: Exercise
    task_type: str
    patient_deg: np.ndarray  # (N, 3) exercised joint angles [deg]
    robot_rad: np.ndarray  # (N, 6) theta*: robot joint angles [rad]
    tool_pos_base_m: np.ndarray  # (N, 3) p*: tool (flange) position in the robot base frame [m]
    servo_setpoint_rad: np.ndarray  # (N, 6) setpoints that hold the limb at each target
    ik_error_m: np.ndarray  # (N,) pose error of the coupled kinematics at each target

    def __len__(self) -> int:
        return len(self.robot_rad)


def _pose_row(scene: Scene, home_deg: np.ndarray, pose: dict[str, float]) -> np.ndarray:
    row = home_deg.copy()
    for i, joint in enumerate(scene.exercised_joints):
        base = joint.rsplit("_", 1)[0]
        if base in pose:
            row[i] = pose[base]
    return row


def key_poses_deg(scene: Scene, exercise: Exercise) -> np.ndarray:
    """(K, 3) exercised-joint angles [deg] of the exercise's key poses in ``scene``."""
    home = np.degrees(scene.home_qpos[scene.exercised_qpos_adr])
    return np.array([_pose_row(scene, home, pose) for pose in exercise.key_poses_deg])


def trajectory_samples(start_deg: np.ndarray, keys_deg: np.ndarray, segment_s: float,
                       waypoint_dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-jerk path from ``start_deg`` through ``keys_deg`` sampled every
    ``waypoint_dt_s`` of each ``segment_s``-long segment; returns the samples (without the
    start) and a mask of which samples are key poses."""
    samples = max(1, round(segment_s / waypoint_dt_s))
    shape = minimum_jerk(np.arange(1, samples + 1) / samples)[:, None]
    points, is_key = [], []
    origin = np.asarray(start_deg, dtype=float)
    for key in np.asarray(keys_deg, dtype=float):
        points.extend(origin + shape * (key - origin))
        is_key.extend([False] * (samples - 1) + [True])
        origin = key
    return np.array(points), np.array(is_key)


def thin_waypoints(start: np.ndarray, points: np.ndarray, is_key: np.ndarray,
                   min_spacing: float) -> np.ndarray:
    """Indices of ``points`` to keep so that consecutive kept points (and the first and
    ``start``) are at least ``min_spacing`` apart in the infinity norm. Key points are always
    kept; a non-key point too close before a key point is replaced by it."""
    kept: list[int] = []
    last_is_key = True
    last = start
    for i, point in enumerate(points):
        far = np.max(np.abs(point - last)) >= min_spacing
        if is_key[i]:
            if not far and kept and not last_is_key:
                kept[-1] = i
            else:
                kept.append(i)
        elif far:
            kept.append(i)
        else:
            continue
        last, last_is_key = point, bool(is_key[i])
    return np.array(kept, dtype=int)


def build_targets(scene: Scene, exercise: Exercise, task_type: str, segment_s: float = 3.0,
                  waypoint_dt_s: float = 0.1, min_spacing_rad: float = 0.1) -> TargetSequence:
    """The target sequence of ``exercise`` in ``scene`` for a reaching or trajectory task.

    Trajectory waypoints are thinned so that consecutive robot targets differ by at least
    ``min_spacing_rad`` (infinity norm; 2 x the reach tolerance by default), so reaching one
    waypoint never reaches the next for free.
    """
    check_choice("task_type", task_type, TASK_TYPES)
    keys = key_poses_deg(scene, exercise)
    if task_type == "reaching":
        path = coupled_path(scene, keys, dt_s=waypoint_dt_s)
    else:
        start = np.degrees(scene.home_qpos[scene.exercised_qpos_adr])
        samples, is_key = trajectory_samples(start, keys, segment_s, waypoint_dt_s)
        dense = coupled_path(scene, samples, dt_s=waypoint_dt_s)
        keep = thin_waypoints(scene.home_qpos[scene.robots[0].qpos_adr], dense.robot_rad[:, 0],
                              is_key, min_spacing_rad)
        path = CoupledPath(dt_s=waypoint_dt_s, patient_deg=dense.patient_deg[keep],
                           robot_rad=dense.robot_rad[keep],
                           servo_setpoint_rad=dense.servo_setpoint_rad[keep],
                           ik_error_m=dense.ik_error_m[keep])
    robot = path.robot_rad[:, 0]
    return TargetSequence(
        exercise=exercise,
        task_type=task_type,
        patient_deg=path.patient_deg,
        robot_rad=robot,
        tool_pos_base_m=tool_positions_base(scene, robot),
        servo_setpoint_rad=path.servo_setpoint_rad[:, 0],
        ik_error_m=path.ik_error_m,
    )


def tool_positions_base(scene: Scene, robot_rad: np.ndarray) -> np.ndarray:
    """Tool (flange) positions [m] in the robot base frame for rows of robot joint angles."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    handle = scene.robots[0]
    out = np.zeros((len(robot_rad), 3))
    for i, q in enumerate(robot_rad):
        data.qpos[handle.qpos_adr] = q
        mujoco.mj_kinematics(model, data)
        rot = data.xmat[handle.base_body_id].reshape(3, 3)
        out[i] = rot.T @ (data.site_xpos[handle.tool_site_id] - data.xpos[handle.base_body_id])
    return out


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


def workspace_robot_angles(scene: Scene, grid_deg: np.ndarray, max_jump_rad: float = 0.6,
                           max_error_m: float = 1e-3) -> np.ndarray:
    """Robot angles and load-carrying setpoints (2 per reachable pose, stacked) for patient
    poses ``grid_deg``, all on the home IK branch.

    Each pose is solved from the nearest pose solved so far; a pose the IK cannot reach
    (``max_error_m``) or reaches only by jumping to another branch (a joint moving more than
    ``max_jump_rad`` from its seed) is left out.
    """
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    handle = scene.robots[0]
    ik = RobotIK(model)
    solved_deg = [np.degrees(scene.home_qpos[scene.exercised_qpos_adr])]
    solved_q = [scene.home_qpos[handle.qpos_adr].copy()]
    out = []
    # Grow outwards from home, so each pose's nearest solved pose is a neighbour.
    order = np.argsort(np.max(np.abs(grid_deg - solved_deg[0]), axis=1), kind="stable")
    for row in grid_deg[order]:
        nearest = int(np.argmin(np.max(np.abs(np.array(solved_deg) - row), axis=1)))
        data.qpos[scene.exercised_qpos_adr] = np.radians(row)
        mujoco.mj_kinematics(model, data)
        site = handle.patient_cuff_site_id
        q, err = ik.solve(data, handle, data.site_xpos[site].copy(),
                          quat_from_mat(data.site_xmat[site]), solved_q[nearest])
        if err > max_error_m or np.max(np.abs(q - solved_q[nearest])) > max_jump_rad:
            continue
        solved_deg.append(row)
        solved_q.append(q)
        mujoco.mj_forward(model, data)
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
