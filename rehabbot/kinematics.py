"""Coupled kinematics of robot and patient: inverse kinematics to the cuff, patient-space
exercise paths mapped to robot joint setpoints, and the scripted sweep used by the demo and tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from rehabbot import statics

if TYPE_CHECKING:
    from rehabbot.models.scene import RobotHandle, Scene


def quat_from_mat(mat9: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a row-major 3x3 rotation."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat9, dtype=float).reshape(9))
    return quat


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Flash & Hogan's normalised minimum-jerk position profile s(tau), tau in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


class RobotIK:
    """Damped least-squares inverse kinematics of one robot's cuff site (position + orientation).

    Works on a kinematics-only ``MjData``; joint limits are respected by clipping each step.
    """

    def __init__(self, model: mujoco.MjModel, damping: float = 1e-3, max_iters: int = 300,
                 tol_m: float = 1e-7) -> None:
        self.model = model
        self.damping = damping
        self.max_iters = max_iters
        self.tol_m = tol_m
        self._jac_pos = np.zeros((3, model.nv))
        self._jac_rot = np.zeros((3, model.nv))
        self._quat = np.zeros(4)
        self._quat_err = np.zeros(4)
        self._rot_err = np.zeros(3)

    def solve(self, data: mujoco.MjData, handle: RobotHandle, target_pos: np.ndarray,
              target_quat: np.ndarray, seed: np.ndarray,
              orientation_weight_m: float = 0.1) -> tuple[np.ndarray, float]:
        """Joint angles putting ``handle``'s cuff site at the target; returns (q, pose error).

        The pose error is the position error [m] plus ``orientation_weight_m`` x the rotation
        error [rad]. ``data.qpos`` of the robot is left at the solution.
        """
        model = self.model
        qadr, dadr, site = handle.qpos_adr, handle.dof_adr, handle.cuff_site_id
        low = model.jnt_range[model.dof_jntid[dadr], 0]
        high = model.jnt_range[model.dof_jntid[dadr], 1]
        data.qpos[qadr] = seed
        err = np.inf
        for _ in range(self.max_iters):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            pos_err = target_pos - data.site_xpos[site]
            mujoco.mju_mat2Quat(self._quat, data.site_xmat[site])
            mujoco.mju_subQuat(self._rot_err, target_quat, self._quat)  # in the site frame
            self._rot_err[:] = data.site_xmat[site].reshape(3, 3) @ self._rot_err
            err = float(np.linalg.norm(pos_err) + orientation_weight_m
                        * np.linalg.norm(self._rot_err))
            if err < self.tol_m:
                break
            mujoco.mj_jacSite(model, data, self._jac_pos, self._jac_rot, site)
            jac = np.vstack([self._jac_pos[:, dadr], orientation_weight_m * self._jac_rot[:, dadr]])
            e = np.concatenate([pos_err, orientation_weight_m * self._rot_err])
            step = jac.T @ np.linalg.solve(jac @ jac.T + self.damping**2 * np.eye(6), e)
            scale = min(1.0, 0.3 / max(np.abs(step).max(), 1e-12))
            data.qpos[qadr] = np.clip(data.qpos[qadr] + scale * step, low, high)
        return data.qpos[qadr].copy(), err


@dataclass(frozen=True)
class CoupledPath:
    """A patient-space path and the robot setpoints that carry the limb along it."""

    dt_s: float
    patient_deg: np.ndarray  # (T, n_exercised) exercised joint angles [deg]
    robot_rad: np.ndarray  # (T, n_robots, 6) robot joint angles on the path [rad]
    servo_setpoint_rad: np.ndarray  # (T, n_robots, 6) setpoints that hold the limb there [rad]
    ik_error_m: np.ndarray  # (T,)


def coupled_path(scene: Scene, patient_deg: np.ndarray, dt_s: float) -> CoupledPath:
    """Robot joint targets for a sequence of exercised-joint angles (other joints at home).

    Each waypoint is solved by IK warm-started from the previous one, so the robot stays on
    one continuous branch; the servo setpoints add the static preload that carries the limb
    there (:mod:`rehabbot.statics`).
    """
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    ik = RobotIK(model)
    patient_deg = np.atleast_2d(np.asarray(patient_deg, dtype=float))
    robot = np.zeros((len(patient_deg), len(scene.robots), 6))
    setpoints = np.zeros_like(robot)
    errors = np.zeros(len(patient_deg))
    seeds = [scene.home_qpos[h.qpos_adr].copy() for h in scene.robots]
    for t, row in enumerate(patient_deg):
        data.qpos[scene.exercised_qpos_adr] = np.radians(row)
        mujoco.mj_kinematics(model, data)
        for k, handle in enumerate(scene.robots):
            site = handle.patient_cuff_site_id
            q, err = ik.solve(data, handle, data.site_xpos[site].copy(),
                              quat_from_mat(data.site_xmat[site]), seeds[k])
            robot[t, k] = q
            seeds[k] = q
            errors[t] = max(errors[t], err)
        mujoco.mj_forward(model, data)
        setpoints[t] = statics.servo_setpoints(scene, data, statics.cuff_load_torque(scene, data))
    return CoupledPath(dt_s=dt_s, patient_deg=patient_deg, robot_rad=robot,
                       servo_setpoint_rad=setpoints, ik_error_m=errors)


# Sweep end points [deg] per limb kind (preset, posture), for the exercised joints.
SWEEP_TARGETS_DEG: dict[tuple[str, str], dict[str, float]] = {
    ("arm", "seated"): {"shoulder_flexion": 85.0, "shoulder_abduction": 12.0,
                        "elbow_flexion": 140.0},
    ("hip", "supine"): {"hip_flexion": 60.0, "hip_abduction": 5.0, "knee_flexion": 10.0},
    ("hip", "seated"): {"hip_flexion": 118.0, "hip_abduction": 4.0, "knee_flexion": 90.0},
    ("knee", "seated"): {"hip_flexion": 90.0, "hip_abduction": 4.0, "knee_flexion": 15.0},
}


def sweep_path(scene: Scene, duration_s: float = 10.0, dt_s: float = 0.02) -> CoupledPath:
    """Home -> far end of the exercise -> home, minimum-jerk in the patient's joint space."""
    start = np.degrees(scene.home_qpos[scene.exercised_qpos_adr])
    kind = "arm" if scene.preset.startswith("upper") else scene.preset
    targets = SWEEP_TARGETS_DEG[(kind, scene.posture)]
    end = np.array([targets[name.rsplit("_", 1)[0]] for name in scene.exercised_joints])
    n = round(duration_s / dt_s)
    t = np.arange(n + 1) * dt_s
    half = duration_s / 2
    s = np.where(t <= half, minimum_jerk(t / half), minimum_jerk(2.0 - t / half))
    return coupled_path(scene, start + s[:, None] * (end - start), dt_s)


@dataclass(frozen=True)
class SweepResult:
    """What happened when the robot drove the limb through the sweep."""

    exercised_joint_range_deg: dict[str, float]
    max_cuff_error_m: float
    within_rom: bool
    max_rom_excess_deg: float
    finite: bool
    patient_deg: np.ndarray  # (T, n_exercised) measured
    max_robot_torque_nm: float


def run_sweep(scene: Scene, duration_s: float = 10.0, dt_s: float = 0.02,
              data: mujoco.MjData | None = None) -> SweepResult:
    """Drive the robot setpoints along :func:`sweep_path` and measure the patient's motion."""
    model = scene.model
    path = sweep_path(scene, duration_s, dt_s)
    data = data if data is not None else scene.make_data()
    scene.reset_data(data)
    substeps = max(1, round(dt_s / model.opt.timestep))
    jnt_ids = [model.joint(n).id for n in scene.patient_joint_names]
    low = model.jnt_range[jnt_ids, 0]
    high = model.jnt_range[jnt_ids, 1]
    measured = np.zeros((len(path.robot_rad), len(scene.exercised_joints)))
    max_err = 0.0
    rom_excess = 0.0
    torque = 0.0
    finite = True
    for t, setpoint in enumerate(path.servo_setpoint_rad):
        for k, handle in enumerate(scene.robots):
            data.ctrl[handle.servo_ids] = setpoint[k]
        mujoco.mj_step(model, data, nstep=substeps)
        if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
            finite = False
            break
        q = data.qpos[scene.patient_qpos_adr]
        rom_excess = max(rom_excess, float(np.max(np.maximum(low - q, q - high))))
        measured[t] = np.degrees(data.qpos[scene.exercised_qpos_adr])
        max_err = max(max_err, float(np.max(scene.cuff_errors_m(data))))
        for handle in scene.robots:
            torque = max(torque, float(np.max(np.abs(data.qfrc_actuator[handle.dof_adr]))))
    ranges = {name: float(np.ptp(measured[:, i])) for i, name in
              enumerate(scene.exercised_joints)}
    return SweepResult(
        exercised_joint_range_deg=ranges,
        max_cuff_error_m=max_err,
        within_rom=rom_excess <= math.radians(0.5),
        max_rom_excess_deg=math.degrees(max(rom_excess, 0.0)),
        finite=finite,
        patient_deg=measured,
        max_robot_torque_nm=torque,
    )
