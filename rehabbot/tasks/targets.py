"""Target sequences: the robot joint angles theta* and tool positions p* that carry the limb
through an exercise, for a reaching or a trajectory-following task.

* **reaching**: the key poses themselves are the targets (``N`` = the number of key poses);
* **trajectory**: a minimum-jerk path (Flash & Hogan 1985) from the home posture through the
  key poses, sampled every ``waypoint_dt_s`` seconds of a ``segment_s``-long segment, with
  waypoints closer than ``min_spacing_rad`` to the previous one dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.common.checks import check_choice
from rehabbot.sim.paths import CoupledPath, coupled_path, minimum_jerk
from rehabbot.sim.scene import Scene
from rehabbot.tasks.exercises import TASK_TYPES, Exercise


@dataclass(frozen=True)
class TargetSequence:
    """Targets of one exercise, in patient and robot joint space."""

    exercise: Exercise
    task_type: str
    patient_deg: np.ndarray  # (N, 3) exercised joint angles [deg]
    robot_rad: np.ndarray  # (N, n_joints) theta*: robot joint angles [rad]
    tool_pos_base_m: np.ndarray  # (N, 3) p*: tool (flange) position in the robot base frame [m]
    servo_setpoint_rad: np.ndarray  # (N, n_joints) setpoints holding the limb at each target
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
