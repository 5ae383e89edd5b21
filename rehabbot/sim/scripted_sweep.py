"""The scripted sweep: the robot carries the limb home -> far end -> home, and what the
patient's joints, the cuff and the robot's torques did on the way (demo, tests, benchmarks)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.sim.paths import CoupledPath, coupled_path, minimum_jerk
from rehabbot.sim.scene import Scene

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
