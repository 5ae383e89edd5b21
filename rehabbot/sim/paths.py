"""Patient-space paths mapped to robot joint targets through the coupled kinematics."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.sim import statics
from rehabbot.sim.ik import RobotIK, quat_from_mat
from rehabbot.sim.scene import Scene


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Flash & Hogan's normalised minimum-jerk position profile s(tau), tau in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


@dataclass(frozen=True)
class CoupledPath:
    """A patient-space path and the robot setpoints that carry the limb along it."""

    dt_s: float
    patient_deg: np.ndarray  # (T, n_exercised) exercised joint angles [deg]
    robot_rad: np.ndarray  # (T, n_robots, n_joints) robot joint angles on the path [rad]
    servo_setpoint_rad: np.ndarray  # (T, n_robots, n_joints) setpoints holding the limb [rad]
    ik_error_m: np.ndarray  # (T,)


def coupled_path(scene: Scene, patient_deg: np.ndarray, dt_s: float) -> CoupledPath:
    """Robot joint targets for a sequence of exercised-joint angles (other joints at home).

    Each waypoint is solved by IK warm-started from the previous one, so the robot stays on
    one continuous branch; the servo setpoints add the static preload that carries the limb
    there (:mod:`rehabbot.sim.statics`). A redundant robot (more than six joints) takes, at each
    waypoint, the posture nearest its home angles, as the workspace sweep of the setpoint
    bounds does (:mod:`rehabbot.sim.ik`).
    """
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    ik = RobotIK(model)
    patient_deg = np.atleast_2d(np.asarray(patient_deg, dtype=float))
    robot = np.zeros((len(patient_deg), len(scene.robots), scene.n_robot_joints))
    setpoints = np.zeros_like(robot)
    errors = np.zeros(len(patient_deg))
    seeds = [scene.home_qpos[h.qpos_adr].copy() for h in scene.robots]
    rests = [seed.copy() for seed in seeds]
    for t, row in enumerate(patient_deg):
        data.qpos[scene.exercised_qpos_adr] = np.radians(row)
        scene.follow_coupled_joints(data.qpos)
        mujoco.mj_kinematics(model, data)
        for k, handle in enumerate(scene.robots):
            site = handle.patient_cuff_site_id
            q, err = ik.solve(data, handle, data.site_xpos[site].copy(),
                              quat_from_mat(data.site_xmat[site]), seeds[k],
                              posture=rests[k])
            robot[t, k] = q
            seeds[k] = q
            errors[t] = max(errors[t], err)
        mujoco.mj_forward(model, data)
        setpoints[t] = statics.servo_setpoints(scene, data, statics.cuff_load_torque(scene, data))
    return CoupledPath(dt_s=dt_s, patient_deg=patient_deg, robot_rad=robot,
                       servo_setpoint_rad=setpoints, ik_error_m=errors)
