"""What the clinical evaluator keeps of an episode beyond :class:`~rehabbot.rl.rollout.Episode`:
the work on the limb step by step (:class:`WorkRecorder`, a Gymnasium wrapper that changes
nothing the policy sees) and the patient-side constants of the env (:func:`patient_limits`):
the exercised joints' names and ranges of motion, the cuff's force limit and the robot's torque
limits, each with its source (the figures label every limit line with its value and source)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

WORK_KEYS = ("robot_work_j", "patient_work_j")  # episode-so-far work on the limb, in info


class WorkRecorder(gym.Wrapper):
    """Records ``info["robot_work_j"]`` and ``info["patient_work_j"]`` after the reset and
    after every step (rows aligned with an :class:`~rehabbot.rl.rollout.Episode`'s)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.rows: dict[str, list[float]] = {key: [] for key in WORK_KEYS}

    def _record(self, info: dict) -> None:
        for key, rows in self.rows.items():
            rows.append(float(info.get(key, np.nan)))

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        for rows in self.rows.values():
            rows.clear()
        self._record(info)
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._record(info)
        return obs, reward, terminated, truncated, info

    def series(self) -> dict[str, np.ndarray]:
        """The recorded rows of the last episode, one array per key."""
        return {key: np.array(rows, dtype=float) for key, rows in self.rows.items()}


# Where each robot's torque limits come from (docs/physics.md, docs/robots.md).
TORQUE_LIMIT_SOURCES = {
    "ur5e": "UR5e rated joint torque, Universal Robots",
    "fr3": "Franka 'Limits for Franka Research 3'",
}


def torque_limit_source(robot_name: str) -> str:
    """Where the torque limits of the robot named ``robot_name`` come from."""
    return TORQUE_LIMIT_SOURCES.get(robot_name, f"robot {robot_name!r}: its torque_limit_nm")


def patient_limits(env: gym.Env) -> dict[str, np.ndarray]:
    """The episode's patient-side constants and where each limit comes from:

    ============================  ============================================================
    key                           value
    ============================  ============================================================
    ``patient_joint_names``       (3,) the exercised joints
    ``patient_range_deg``         (3, 2) their ranges of motion (after a condition's
                                  ``rom_scale``)
    ``patient_range_source``      the ranges' source: ``"AAOS normal range"`` (the rigid
                                  patient, docs/physics.md) or MyoSuite's model, the
                                  condition's ``rom_scale``, and how far beyond them the
                                  range-of-motion rule stops an episode
    ``cuff_force_limit_n``        the cuff's force limit (the lowest of the cuffs')
    ``cuff_force_limit_source``   ``"ISO/TS 15066 quasi-static, hands and fingers"`` (the body
                                  region under that cuff), or the env's ``cuff_force_limit_n``
    ``robot_name``                the robot (``"ur5e"``, ``"fr3"``)
    ``torque_limit_source``       where its torque limits come from
    ============================  ============================================================
    """
    from rehabbot.sim.physics import CUFF_BODY_REGION

    base = env.unwrapped
    patient_env = getattr(base, "current_env", base)
    scene = patient_env.scene
    model = scene.model
    names = [str(name) for name in scene.exercised_joints]
    ranges = np.degrees([model.jnt_range[model.joint(name).id] for name in names])
    limits = np.asarray(patient_env.safety.force_limits_n, dtype=float)
    thresholds = patient_env.safety.thresholds
    if thresholds.cuff_force_limit_n is not None:
        force_source = "the env's cuff_force_limit_n"
    else:
        limb = scene.robots[int(np.argmin(limits))].limb
        region = CUFF_BODY_REGION[limb.split("_")[0]].replace("_", " ")
        force_source = f"ISO/TS 15066 quasi-static, {region}"
    range_source = ("MyoSuite model's range" if scene.patient_model == "myo"
                    else "AAOS normal range")
    condition = getattr(getattr(getattr(patient_env, "config", None), "patient", None),
                        "condition", None)
    rom_scale = getattr(condition, "rom_scale", 1.0)
    if rom_scale != 1.0:
        range_source += f" x {rom_scale:g} (condition's rom_scale)"
    range_source += f"; stop {thresholds.rom_tolerance_deg:g}° beyond"
    robot = scene.robots[0].robot.name
    return {"patient_joint_names": np.array(names), "patient_range_deg": np.array(ranges),
            "patient_range_source": np.array(range_source),
            "cuff_force_limit_n": np.array(float(limits.min())),
            "cuff_force_limit_source": np.array(force_source),
            "robot_name": np.array(robot), "torque_limit_source": np.array(
                torque_limit_source(robot))}
