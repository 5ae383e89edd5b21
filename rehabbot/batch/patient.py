"""The rigid patient's joint torques in the batched env, every physics step: JAX's
:class:`rehabbot.sim.patient_drive.PatientDrive`, from the CPU drive's own tables
(:mod:`rehabbot.batch.patient_tables`).

Per physics step, on the compliant exercised joints (written into ``qfrc_applied`` before the
step, as the CPU drive does):

* the **stretch reflex** of spasticity (:func:`rehabbot.sim.conditions.reflex_torque_nm`), fed
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

import math
from typing import Any

import jax
import jax.numpy as jp
import numpy as np

from rehabbot.batch.patient_tables import PatientTables
from rehabbot.sim.conditions import CATCH_RAMP, CATCH_SHIFT_PER_RAD_S, RELEASE_WIDTH
from rehabbot.sim.patient_drive import ACTIVE_DAMPING_S, RESIST_VELOCITY_RAD_S
from rehabbot.sim.tremor import TREMOR_CORRELATION_S, TREMOR_DRIFT_HZ, TREMOR_MODULATION

TWO_PI = 2.0 * math.pi


def _f32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.float32))


class BatchedPatientDrive:
    """The condition's torques (module docstring) for one world; ``jax.vmap`` batches it."""

    def __init__(self, tables: PatientTables) -> None:
        t = self.tables = tables
        self.has_tremor = t.tremor_hz > 0.0 and t.tremor_amplitude_nm > 0.0
        self._dof = jp.asarray(t.dof_adr, jp.int32)
        self._qpos = jp.asarray(t.qpos_adr, jp.int32)
        self._low, self._high = _f32(t.low_rad), _f32(t.high_rad)
        self._span = _f32(t.high_rad - t.low_rad)
        self._gain = _f32(t.reflex_gain_nms_per_rad)
        self._available_pos, self._available_neg = _f32(t.available_pos_nm), \
            _f32(t.available_neg_nm)
        self._peak_pos, self._peak_neg = _f32(t.peak_pos_nm), _f32(t.peak_neg_nm)
        self._kp = _f32(t.kp_nm_per_rad)
        self._goals = _f32(t.goals_rad)
        control_dt_s = t.frame_skip * t.dt_s
        self._decay = math.exp(-control_dt_s / TREMOR_CORRELATION_S)
        self._noise = math.sqrt(1.0 - self._decay * self._decay)

    @property
    def joints(self) -> int:
        return int(self.tables.dof_adr.shape[0])

    def start(self, rng: jax.Array) -> dict[str, jax.Array]:
        """The drive's state at the start of an episode (``PatientDrive.reset``): empty delay
        lines, the tremor's phases and processes drawn from ``rng``."""
        t, m = self.tables, self.joints
        zero = jp.zeros((), jp.float32)
        state = {"patient_velocities": jp.zeros((t.reflex_lag, m), jp.float32),
                 "patient_substep": jp.int32(0),
                 "patient_goal_index": jp.zeros(t.goal_lag + 1, jp.int32),
                 "patient_torque_nm": jp.zeros(m, jp.float32),
                 "patient_work_j": zero, "patient_positive_work_j": zero}
        if self.has_tremor:
            phase_key, drift_key, modulation_key = jax.random.split(rng, 3)
            state["tremor_phase"] = jax.random.uniform(phase_key, (m,), jp.float32, 0.0, TWO_PI)
            state["tremor_drift_hz"] = TREMOR_DRIFT_HZ * jax.random.normal(drift_key, (),
                                                                           jp.float32)
            state["tremor_modulation"] = jp.clip(
                jax.random.normal(modulation_key, (), jp.float32), -1.0, 1.0)
        return state

    def begin_step(self, state: dict, exercise: jax.Array, index: jax.Array,
                   rng: jax.Array) -> tuple[dict, jax.Array]:
        """A control step's start (``PatientDrive.run`` before its physics loop): the active
        target ``index`` enters the goal delay line, whose oldest entry is the goal (m,); the
        tremor's drift and modulation take one Ornstein-Uhlenbeck step drawn from ``rng``."""
        line = jp.concatenate([state["patient_goal_index"][1:], index[None]])
        state = {**state, "patient_goal_index": line}
        if self.has_tremor:
            z_drift, z_modulation = jax.random.normal(rng, (2,), jp.float32)
            state["tremor_drift_hz"] = self._decay * state["tremor_drift_hz"] \
                + self._noise * TREMOR_DRIFT_HZ * z_drift
            state["tremor_modulation"] = jp.clip(
                self._decay * state["tremor_modulation"] + self._noise * z_modulation, -1.0, 1.0)
        return state, self._goals[exercise, line[0]]

    def apply(self, state: dict, data: Any, goal: jax.Array) -> tuple[dict, Any, jax.Array]:
        """One physics step's torques written into ``data.qfrc_applied``; the new state, the
        data and the compliant joints' angles before the step (for :meth:`count_work`)."""
        q, v = data.qpos[self._qpos], data.qvel[self._dof]
        lag = self.tables.reflex_lag
        slot = state["patient_substep"] % lag
        delayed = state["patient_velocities"][slot]  # the velocity of `lag` steps ago
        state = {**state, "patient_velocities": state["patient_velocities"].at[slot].set(v),
                 "patient_substep": state["patient_substep"] + 1}
        torque = self._reflex(delayed, q) + self._effort(q, v, goal, data.qfrc_bias[self._dof])
        if self.has_tremor:
            amplitude = self.tables.tremor_amplitude_nm * (
                1.0 + TREMOR_MODULATION * state["tremor_modulation"])
            phase = state["tremor_phase"]
            torque = torque + amplitude * jp.sin(phase)
            step = TWO_PI * (self.tables.tremor_hz + state["tremor_drift_hz"]) * self.tables.dt_s
            state["tremor_phase"] = jp.mod(phase + step, TWO_PI)
        torque = jp.clip(torque, -self._peak_neg, self._peak_pos)
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
        work = jp.dot(state["patient_torque_nm"], data.qpos[self._qpos] - q_before)
        return {**state, "patient_work_j": state["patient_work_j"] + work,
                "patient_positive_work_j": state["patient_positive_work_j"]
                + jp.maximum(work, 0.0)}

    # -- the torque laws -------------------------------------------------------------------
    def _reflex(self, velocity: jax.Array, q: jax.Array) -> jax.Array:
        """:func:`rehabbot.sim.conditions.reflex_torque_nm` on every joint (``velocity``
        already delayed)."""
        reflex = self.tables.reflex
        if reflex is None:
            return jp.zeros_like(q)
        speed = jp.abs(velocity)
        excess = speed - reflex.threshold_rad_s
        lengthening = velocity > 0
        stretch = jp.where(lengthening, q - self._low, self._high - q) / self._span
        past = stretch - (reflex.catch_at_rest - CATCH_SHIFT_PER_RAD_S * speed)
        build_up = jp.minimum(past / CATCH_RAMP, 1.0)
        release = reflex.release_to + (1.0 - reflex.release_to) * jp.exp(
            -jp.maximum(past - CATCH_RAMP, 0.0) / RELEASE_WIDTH)
        magnitude = reflex.gain_scale * self._gain * excess * build_up * release
        fires = (excess > 0.0) & (past > 0.0)
        return jp.where(fires, jp.where(lengthening, -magnitude, magnitude), 0.0)

    def _effort(self, q: jax.Array, v: jax.Array, goal: jax.Array,
                bias: jax.Array) -> jax.Array:
        """The voluntary torque of the effort mode."""
        mode = self.tables.mode
        if mode == "active_assisted":
            kp = self._kp
            pull = bias + kp * (goal - q) - ACTIVE_DAMPING_S * kp * v
            return jp.clip(pull, -self._available_neg, self._available_pos)
        if mode == "resistive":
            push = jp.tanh(v / RESIST_VELOCITY_RAD_S)
            return -push * jp.where(push > 0, self._available_neg, self._available_pos)
        return jp.zeros_like(q)
