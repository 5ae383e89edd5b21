"""What the clinical evaluator keeps of an episode beyond :class:`~rehabbot.rl.rollout.Episode`:
the work on the limb step by step (:class:`WorkRecorder`, a Gymnasium wrapper that changes
nothing the policy sees) and the patient-side constants of the env (:func:`patient_limits`):
the exercised joints' names and ranges of motion and the cuff's force limit."""

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


def patient_limits(env: gym.Env) -> dict[str, np.ndarray]:
    """The episode's patient-side constants: ``patient_joint_names`` (3,), their ranges of
    motion ``patient_range_deg`` (3, 2) (after a condition's ``rom_scale``) and the cuff's
    force limit ``cuff_force_limit_n`` (the lowest of the cuffs')."""
    base = env.unwrapped
    patient_env = getattr(base, "current_env", base)
    scene = patient_env.scene
    model = scene.model
    names = [str(name) for name in scene.exercised_joints]
    ranges = np.degrees([model.jnt_range[model.joint(name).id] for name in names])
    limit = float(np.min(patient_env.safety.force_limits_n))
    return {"patient_joint_names": np.array(names), "patient_range_deg": np.array(ranges),
            "cuff_force_limit_n": np.array(limit)}
