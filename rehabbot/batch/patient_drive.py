"""The rigid patient's joint torques in the batched env, every physics step: JAX's
:class:`rehabbot.sim.patient_drive.PatientDrive`, from the CPU drive's own tables
(:mod:`rehabbot.batch.patient_tables`) and with its laws (:mod:`rehabbot.laws.patient`, the
work: :mod:`rehabbot.laws.work`).

Per physics step, on the compliant exercised joints (written into ``qfrc_applied`` before the
step, as the CPU drive does):

* the **stretch reflex** of spasticity (:func:`rehabbot.laws.patient.reflex_torque_nm`), fed
  by the joint velocity of the reflex latency ago (a delay line of physics steps);
* **voluntary effort**: the active patient's PD pull towards the goal it noticed
  ``reaction_delay_s`` ago, with the limb's own weight carried (``qfrc_bias`` as MuJoCo left
  it), or the resistive patient's push against the motion; saturated at the available
  strength;
* **tremor** (:class:`rehabbot.sim.tremor.Tremor`): ``A (1 + 0.25 m) sin(phase)``, its drift
  and modulation advanced once per control step. Its random numbers come from the world's
  JAX key, not the CPU env's ``np_random``: the two envs tremble alike, not identically;
* their sum bounded by the healthy peak torque of each joint, each way.

The drive's state (the velocity delay line, the step counter, the goal delay line, the
tremor's phases, drift and modulation, the patient's work) is carried in ``State.info`` under
the keys of :meth:`BatchedPatientDrive.start`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jp
import numpy as np

from rehabbot.batch.padding import stack_padded
from rehabbot.batch.patient_tables import PatientTables
from rehabbot.laws import patient as laws
from rehabbot.laws.patient import TWO_PI
from rehabbot.laws.work import accumulate_work, joint_work_j


def _f32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.float32))


_MODES = ("passive", "active_assisted", "resistive")


def _neutral(template: PatientTables) -> PatientTables:
    """The tables of a patient without a drive, shaped as ``template``'s: no reflex, no
    effort, no tremor, and a zero torque bound, so every torque it applies is 0."""
    zeros = np.zeros_like(template.low_rad)
    return dataclasses.replace(
        template, reflex=None, reflex_gain_nms_per_rad=zeros, mode="passive",
        available_pos_nm=zeros, available_neg_nm=zeros, peak_pos_nm=zeros, peak_neg_nm=zeros,
        kp_nm_per_rad=zeros, goals_rad=np.zeros_like(template.goals_rad), tremor_hz=0.0,
        tremor_amplitude_nm=0.0)


class BatchedPatientDrive:
    """The conditions' torques (module docstring) for one world; ``jax.vmap`` batches it.

    ``tables`` holds one entry per patient of the env (one for a single-patient id, every
    patient of a population): a patient's :class:`PatientTables`, or None for a patient
    whose condition applies no torque. Every parameter is indexed by the world's patient;
    what sets the state's shapes (the compliant joints, the delay lines) is shared: the
    joints must be the same, the delay lines are as long as the longest patient's.
    """

    def __init__(self, tables: Sequence[PatientTables | None]) -> None:
        driven = [t for t in tables if t is not None]
        if not driven:
            raise ValueError("no patient applies torques: the env needs no drive")
        first = driven[0]
        for name in ("dof_adr", "qpos_adr", "exercised_index"):
            if any(not np.array_equal(getattr(t, name), getattr(first, name)) for t in driven):
                raise ValueError(f"the patients' drives act on different joints ({name})")
        for name in ("exercised_count", "dt_s", "frame_skip"):
            if len({getattr(t, name) for t in driven}) != 1:
                raise ValueError(f"the patients' drives differ in {name}")
        rows = [t if t is not None else _neutral(first) for t in tables]
        self.tables = first  # the shared fields (joints, step)
        self.patients = len(rows)
        self.reflex_lag = max(t.reflex_lag for t in rows)
        self.goal_lag = max(t.goal_lag for t in rows)
        self.has_reflex = any(t.reflex is not None for t in rows)
        self.modes = tuple(sorted({t.mode for t in rows}, key=_MODES.index))
        self.has_tremor = any(t.tremor_hz > 0.0 and t.tremor_amplitude_nm > 0.0 for t in rows)
        self._dof = jp.asarray(first.dof_adr, jp.int32)
        self._qpos = jp.asarray(first.qpos_adr, jp.int32)

        def stack(values: Sequence[Any]) -> jax.Array:
            return _f32(np.stack([np.asarray(v, dtype=float) for v in values]))

        self._low, self._high = stack([t.low_rad for t in rows]), stack([t.high_rad for t in rows])
        self._gain = stack([t.reflex_gain_nms_per_rad for t in rows])
        reflexes = [t.reflex for t in rows]
        # A patient without spasticity: gain 0 (its reflex torque is 0 wherever it fires).
        self._reflex_scale = stack([r.gain_scale if r else 0.0 for r in reflexes])
        self._threshold = stack([r.threshold_rad_s if r else 0.0 for r in reflexes])
        self._catch = stack([r.catch_at_rest if r else 1.0 for r in reflexes])
        self._release_to = stack([r.release_to if r else 1.0 for r in reflexes])
        self._reflex_lag = jp.asarray([t.reflex_lag for t in rows], jp.int32)
        self._goal_lag = jp.asarray([t.goal_lag for t in rows], jp.int32)
        self._mode = jp.asarray([_MODES.index(t.mode) for t in rows], jp.int32)
        self._available_pos = stack([t.available_pos_nm for t in rows])
        self._available_neg = stack([t.available_neg_nm for t in rows])
        self._peak_pos = stack([t.peak_pos_nm for t in rows])
        self._peak_neg = stack([t.peak_neg_nm for t in rows])
        self._kp = stack([t.kp_nm_per_rad for t in rows])
        count = max(t.goals_rad.shape[1] for t in rows)
        self._goals = stack([stack_padded(list(t.goals_rad), count) for t in rows])
        self._tremor_hz = stack([t.tremor_hz for t in rows])
        self._tremor_nm = stack([t.tremor_amplitude_nm for t in rows])
        self._decay, self._noise = laws.tremor_decay(first.frame_skip * first.dt_s)

    @property
    def joints(self) -> int:
        return int(self.tables.dof_adr.shape[0])

    def start(self, rng: jax.Array) -> dict[str, jax.Array]:
        """The drive's state at the start of an episode (``PatientDrive.reset``): empty delay
        lines, the tremor's phases and processes drawn from ``rng``."""
        m = self.joints
        zero = jp.zeros((), jp.float32)
        state = {"patient_velocities": jp.zeros((self.reflex_lag, m), jp.float32),
                 "patient_substep": jp.int32(0),
                 "patient_goal_index": jp.zeros(self.goal_lag + 1, jp.int32),
                 "patient_torque_nm": jp.zeros(m, jp.float32),
                 "patient_work_j": zero, "patient_positive_work_j": zero}
        if self.has_tremor:
            phase_key, drift_key, modulation_key = jax.random.split(rng, 3)
            state["tremor_phase"] = jax.random.uniform(phase_key, (m,), jp.float32, 0.0, TWO_PI)
            state["tremor_drift_hz"], state["tremor_modulation"] = laws.tremor_start(
                jp, jax.random.normal(drift_key, (), jp.float32),
                jax.random.normal(modulation_key, (), jp.float32))
        return state

    def begin_step(self, state: dict, patient: jax.Array, exercise: jax.Array,
                   index: jax.Array, rng: jax.Array) -> tuple[dict, jax.Array]:
        """A control step's start (``PatientDrive.run`` before its physics loop): the active
        target ``index`` enters the goal delay line; the goal (m,) is the entry of the
        patient's reaction delay ago. The tremor's drift and modulation take one
        Ornstein-Uhlenbeck step drawn from ``rng``."""
        line = jp.concatenate([state["patient_goal_index"][1:], index[None]])
        state = {**state, "patient_goal_index": line}
        if self.has_tremor:
            z_drift, z_modulation = jax.random.normal(rng, (2,), jp.float32)
            state["tremor_drift_hz"], state["tremor_modulation"] = laws.tremor_processes(
                jp, state["tremor_drift_hz"], state["tremor_modulation"], z_drift, z_modulation,
                self._decay, self._noise)
        noticed = line[self.goal_lag - self._goal_lag[patient]]
        return state, self._goals[patient, exercise, noticed]

    def apply(self, state: dict, data: Any, patient: jax.Array,
              goal: jax.Array) -> tuple[dict, Any, jax.Array]:
        """One physics step's torques written into ``data.qfrc_applied``; the new state, the
        data and the compliant joints' angles before the step (for :meth:`count_work`)."""
        q, v = data.qpos[self._qpos], data.qvel[self._dof]
        slot = state["patient_substep"] % self._reflex_lag[patient]
        delayed = state["patient_velocities"][slot]  # the velocity of the reflex lag ago
        state = {**state, "patient_velocities": state["patient_velocities"].at[slot].set(v),
                 "patient_substep": state["patient_substep"] + 1}
        torque = self._reflex(patient, delayed, q) + self._effort(
            patient, q, v, goal, data.qfrc_bias[self._dof])
        if self.has_tremor:
            tremor, state["tremor_phase"] = laws.tremor_torque_nm(
                jp, self._tremor_nm[patient], state["tremor_modulation"],
                self._tremor_hz[patient], state["tremor_drift_hz"], state["tremor_phase"],
                self.tables.dt_s, wrap=True)
            torque = torque + tremor
        torque = laws.saturate_nm(jp, torque, self._peak_pos[patient], self._peak_neg[patient])
        state["patient_torque_nm"] = torque
        data = data.replace(qfrc_applied=data.qfrc_applied.at[self._dof].set(torque))
        return state, data, q

    def exercised_torque(self, state: dict) -> jax.Array:
        """The last physics step's torques on the exercised joints (0 on those that are not
        compliant), as the CPU env's ``info["patient_torque_nm"]``."""
        t = self.tables
        out = jp.zeros(t.exercised_count, jp.float32)
        return out.at[jp.asarray(t.exercised_index, jp.int32)].set(state["patient_torque_nm"])

    def count_work(self, state: dict, data: Any, q_before: jax.Array) -> dict:
        """The patient's work in the physics step just taken (``WorkMeter.add_patient``)."""
        work = joint_work_j(state["patient_torque_nm"], q_before, data.qpos[self._qpos])
        total, positive = accumulate_work(jp, state["patient_work_j"],
                                          state["patient_positive_work_j"], work)
        return {**state, "patient_work_j": total, "patient_positive_work_j": positive}

    # -- the torque laws -------------------------------------------------------------------
    def _reflex(self, patient: jax.Array, velocity: jax.Array, q: jax.Array) -> jax.Array:
        """:func:`rehabbot.laws.patient.reflex_torque_nm` on every joint (``velocity``
        already delayed)."""
        if not self.has_reflex:
            return jp.zeros_like(q)
        return laws.reflex_torque_nm(
            jp, velocity, q, self._low[patient], self._high[patient],
            self._reflex_scale[patient] * self._gain[patient], self._threshold[patient],
            self._catch[patient], self._release_to[patient])

    def _effort(self, patient: jax.Array, q: jax.Array, v: jax.Array, goal: jax.Array,
                bias: jax.Array) -> jax.Array:
        """The voluntary torque of the patient's effort mode."""
        by_mode = {"passive": lambda: jp.zeros_like(q)}
        if "active_assisted" in self.modes:
            def pull() -> jax.Array:
                return laws.active_pull_nm(jp, q, v, goal, bias, self._kp[patient],
                                           self._available_pos[patient],
                                           self._available_neg[patient])
            by_mode["active_assisted"] = pull
        if "resistive" in self.modes:
            def push() -> jax.Array:
                return laws.resistive_push_nm(jp, v, self._available_pos[patient],
                                              self._available_neg[patient])
            by_mode["resistive"] = push
        if len(self.modes) == 1:
            return by_mode[self.modes[0]]()
        torques = [by_mode[mode]() for mode in self.modes]
        codes = [_MODES.index(mode) for mode in self.modes]
        return jp.select([self._mode[patient] == c for c in codes[:-1]], torques[:-1],
                         torques[-1])
