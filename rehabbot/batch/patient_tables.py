"""What the batched patient drive reads from the CPU env: the rigid patient's
:class:`~rehabbot.sim.patient_drive.PatientDrive` (its condition, strengths, reduced ranges,
delays) and the active patient's goals, as NumPy arrays, so that the two cannot drift.

Contracture (``stiffness_scale``) and the reduced range of motion (``rom_scale``) need no table
here: the CPU env writes them into its model (joint stiffness, damping and ranges), its targets
and its range-of-motion rule, which the batched env reads already
(:mod:`rehabbot.batch.env_tables`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from rehabbot.batch.padding import stack_padded
from rehabbot.sim.patient_drive import PatientDrive


@dataclass(frozen=True)
class ReflexTable:
    """The stretch reflex of the condition's MAS grade
    (:class:`~rehabbot.sim.conditions.SpasticReflex`), its threshold in rad/s."""

    gain_scale: float
    threshold_rad_s: float
    catch_at_rest: float
    release_to: float


@dataclass(frozen=True)
class PatientTables:
    """The CPU drive's parameters, per compliant exercised joint (``m`` of them, dof order).

    Shapes: ``E`` exercises, ``T`` targets of the longest one (padded with its last goal).
    """

    dof_adr: np.ndarray  # (m,) the compliant joints in qvel / qfrc_applied
    qpos_adr: np.ndarray  # (m,) ... and in qpos
    exercised_index: np.ndarray  # (m,) their places among the exercised joints
    exercised_count: int
    low_rad: np.ndarray  # (m,) the reduced ranges the reflex measures the stretch in
    high_rad: np.ndarray
    reflex: ReflexTable | None  # None: no spasticity
    reflex_gain_nms_per_rad: np.ndarray  # (m,) reference gain (x the grade's gain_scale)
    reflex_lag: int  # the reflex latency in physics steps
    mode: str  # "passive", "active_assisted" or "resistive"
    available_pos_nm: np.ndarray  # (m,) the voluntary strength the patient uses, each way
    available_neg_nm: np.ndarray
    peak_pos_nm: np.ndarray  # (m,) the physiological bound of the summed torque, each way
    peak_neg_nm: np.ndarray
    kp_nm_per_rad: np.ndarray  # (m,) the active patient's PD gain
    goal_lag: int  # the active patient's reaction delay in control steps
    goals_rad: np.ndarray  # (E, T, m) the compliant joints' angles at each target
    tremor_hz: float  # 0: no tremor
    tremor_amplitude_nm: float
    dt_s: float  # one physics step
    frame_skip: int


def read_patient_tables(env: Any) -> PatientTables | None:
    """The patient drive's tables of the CPU env ``env`` (``gym.make(...).unwrapped``), or None
    when its condition applies no torque (a healthy, a contracted or a passive weak limb)."""
    drive = env.physics.drive
    if drive is None:
        return None
    if not isinstance(drive, PatientDrive):
        raise ValueError(f"{type(drive).__name__}: only the rigid patient's drive is batched")
    reflex = drive.reflex
    goals = env.goals_rad
    m = len(drive.dof_ids)
    padded = stack_padded(goals)
    tremor = drive.tremor
    ranges = np.asarray(drive.stretch_ranges_rad, dtype=float).reshape(m, 2)
    return PatientTables(
        dof_adr=np.asarray(drive.dof_ids, dtype=int),
        qpos_adr=np.asarray(drive.qpos_ids, dtype=int),
        exercised_index=np.asarray(drive.exercised_index, dtype=int),
        exercised_count=int(drive.torque_nm.shape[0]),
        low_rad=ranges[:, 0], high_rad=ranges[:, 1],
        reflex=None if reflex is None else ReflexTable(
            float(reflex.gain_scale), math.radians(reflex.threshold_deg_s),
            float(reflex.catch_at_rest), float(reflex.release_to)),
        reflex_gain_nms_per_rad=np.asarray(drive.reflex_gains_nms_per_rad, dtype=float),
        reflex_lag=int(drive.reflex_lag_steps), mode=str(drive.effort_mode),
        available_pos_nm=np.asarray([p for p, _ in drive.available_nm], dtype=float),
        available_neg_nm=np.asarray([n for _, n in drive.available_nm], dtype=float),
        peak_pos_nm=np.asarray([p for p, _ in drive.peak_nm], dtype=float),
        peak_neg_nm=np.asarray([n for _, n in drive.peak_nm], dtype=float),
        kp_nm_per_rad=np.asarray(drive.kp_nm_per_rad, dtype=float),
        goal_lag=int(drive.goal_lag_steps),
        goals_rad=padded,
        tremor_hz=float(tremor.frequency_hz) if tremor is not None else 0.0,
        tremor_amplitude_nm=float(tremor.amplitude_nm) if tremor is not None else 0.0,
        dt_s=float(drive.dt_s), frame_skip=int(drive.frame_skip),
    )
