"""Running a policy for one episode and keeping what happened, step by step
(:func:`run_episode`). The analysis layer turns an :class:`Episode` into clinical figures
(:mod:`rehabbot.analysis.evaluation`) and a trace file (:mod:`rehabbot.analysis.traces`)."""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from rehabbot.rl.policies import LoadedPolicy


@dataclass
class Episode:
    """One episode of a policy: its outcome and its time series (row 0: after ``reset``)."""

    env_id: str
    policy: str
    seed: int
    dt_s: float
    joint_names: tuple[str, ...]
    torque_limit_nm: np.ndarray  # (n_joints,)
    target_tool_pos_m: np.ndarray  # (N, 3) p* of every target, robot base frame
    target_robot_rad: np.ndarray  # (N, n_joints) theta* of every target
    target_patient_deg: np.ndarray  # (N, 3) the exercised joints at every target [deg]
    robot_qpos_rad: np.ndarray  # (T + 1, n_joints)
    tool_pos_m: np.ndarray  # (T + 1, 3) robot base frame
    patient_qpos_rad: np.ndarray  # (T + 1, 3) the exercised joints
    robot_torque_nm: np.ndarray  # (T + 1, n_joints)
    interaction_force_n: np.ndarray  # (T + 1,)
    patient_torque_nm: np.ndarray  # (T + 1, 3) the patient's muscle torques, exercised joints
    target_index: np.ndarray  # (T + 1,)
    total_return: float
    success: bool
    safety_violation: str | None
    truncated: bool
    exercise: int
    weight_level: int
    targets_reached: int
    num_targets: int
    robot_work_j: float = 0.0  # work on the limb over the episode: the robot's (cuff)
    patient_work_j: float = 0.0  # ... and the patient's (muscles)
    assistance_ratio: float = float("nan")  # robot's share of the positive work on the limb
    # MyoSuite's legs only (patient_model="myo"; None for the rigid patient): the exercised
    # leg's muscles over the episode (rehabbot.sim.muscles).
    muscle_work_j: float | None = None  # their forces' work on the limb
    peak_muscle_force_n: float | None = None  # the largest pull of one muscle
    mean_muscle_activation: float | None = None  # mean over steps and muscles
    mean_muscle_excitation: float | None = None

    @property
    def length(self) -> int:
        """Steps taken."""
        return len(self.robot_qpos_rad) - 1


def run_episode(env: gym.Env, policy: LoadedPolicy, seed: int,
                deterministic: bool = True) -> Episode:
    """Reset ``env`` with ``seed`` and run ``policy`` until the episode ends.

    Raises:
        PolicyError: the policy failed or returned something that is not a finite action of
            the env's action space (:meth:`~rehabbot.rl.policies.LoadedPolicy.act`), naming it.
    """
    base = env.unwrapped
    layout = base.layout
    theta, p, phi = layout.slice("theta"), layout.slice("p"), layout.slice("phi")
    obs, info = env.reset(seed=seed)
    sequence = base.target_sequence
    qpos, tool, patient, torque, force, index, muscle = [], [], [], [], [], [], []
    activation, excitation = [], []

    def record(observation: np.ndarray, step_info: dict) -> None:
        # The -v2 ids' agent observation holds errors, not angles: read the paper's fields.
        observation = step_info.get("paper_observation", observation)
        qpos.append(np.array(observation[theta], dtype=float))
        tool.append(np.array(observation[p], dtype=float))
        patient.append(np.array(observation[phi], dtype=float))
        torque.append(np.array(step_info["robot_torque_nm"], dtype=float))
        force.append(float(step_info["interaction_force_n"]))
        index.append(int(step_info["target_index"]))
        muscle.append(np.array(step_info["patient_torque_nm"], dtype=float))
        if "muscle_activation" in step_info:
            activation.append(float(step_info["muscle_activation"]))
            excitation.append(float(step_info["muscle_excitation"]))

    record(obs, info)
    total, truncated = 0.0, False
    while True:
        action = policy.act(obs, deterministic=deterministic, action_space=env.action_space)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        record(obs, info)
        if terminated or truncated:
            break
    success = bool(info["is_success"])
    return Episode(
        env_id=env.spec.id if env.spec else type(base).__name__,
        policy=policy.label, seed=seed, dt_s=float(base.dt),
        # A two-robot env names both robots' joints (prefixed) and their limits.
        joint_names=tuple(getattr(base, "joint_names", None) or base.robot.joint_names),
        torque_limit_nm=(base.torque_limits_nm if hasattr(base, "torque_limits_nm")
                         else base.robot.torque_limits()),
        target_tool_pos_m=np.array(sequence.tool_pos_base_m, dtype=float),
        target_robot_rad=np.array(sequence.robot_rad, dtype=float),
        target_patient_deg=np.array(sequence.patient_deg, dtype=float),
        robot_qpos_rad=np.array(qpos), tool_pos_m=np.array(tool),
        patient_qpos_rad=np.array(patient), robot_torque_nm=np.array(torque),
        interaction_force_n=np.array(force), target_index=np.array(index),
        patient_torque_nm=np.array(muscle),
        total_return=total, success=success, safety_violation=info["safety_violation"],
        truncated=bool(truncated), exercise=int(info["exercise"]),
        weight_level=int(info["weight_level"]),
        targets_reached=int(info["target_index"]) + int(success),
        num_targets=int(info["num_targets"]),
        robot_work_j=float(info["robot_work_j"]), patient_work_j=float(info["patient_work_j"]),
        assistance_ratio=float(info["assistance_ratio"]),
        **_muscle_figures(info, activation, excitation))


def _muscle_figures(info: dict, activation: list[float], excitation: list[float]) -> dict:
    """The Episode's muscle fields from the last ``info`` and the per-step means (none for
    the rigid patient)."""
    if "muscle_work_j" not in info:
        return {}
    return {"muscle_work_j": float(info["muscle_work_j"]),
            "peak_muscle_force_n": float(info["peak_muscle_force_n"]),
            "mean_muscle_activation": float(np.mean(activation)),
            "mean_muscle_excitation": float(np.mean(excitation))}
