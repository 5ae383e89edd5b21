"""What the patient's muscles do, every physics step: the torques of a
:class:`~rehabbot.sim.conditions.PatientCondition` and the work done on the limb.

:class:`PatientDrive` steps the physics one step at a time and, before each step, writes the
patient's torques on the compliant exercised joints into ``data.qfrc_applied``:

* the **stretch reflex** of spasticity (:func:`rehabbot.laws.patient.reflex_torque_nm`), fed
  by the joint velocity of ``REFLEX_LATENCY_S`` ago;
* **tremor** (:class:`rehabbot.sim.tremor.Tremor`): ``A (1 + 0.25 m(t)) sin(phase_j(t))``,
  its frequency and amplitude drifting, drawn from the env's ``np_random``;
* **voluntary effort**: ``"active_assisted"``: the patient carries the limb's own weight and
  pulls towards the target it noticed ``reaction_delay_s`` ago (a PD law), ``"resistive"``: it
  pushes against the motion, ``-S tanh(v / 0.1 rad/s)``; both saturated at the available
  strength ``S = effort_fraction x strength_fraction x`` the healthy strength of the profile.

Their sum on each joint is bounded by the patient's physiology: at most the healthy peak
isometric torque of that joint, in that direction, for the profile's mass and sex
(:func:`rehabbot.sim.conditions.healthy_strength_nm`; a reflex-driven muscle cannot pull
harder than a maximal voluntary contraction). Without the bound a grade-4 stretch reflex grew
with the stretch speed without limit (2,372 N·m with the safety stops off).

:meth:`PatientDrive.run` is the physics loop of a control step with these torques; the env
calls it through :class:`rehabbot.sim.physics.LimbPhysics`, which passes the
:class:`~rehabbot.sim.physics.WorkMeter` that counts the work.

The laws are those of :mod:`rehabbot.laws.patient`, evaluated joint by joint on floats (the
scalar namespace, :mod:`rehabbot.laws.scalar`); this class keeps their state (the delay
lines, the tremor) and their per-joint parameters.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from rehabbot.laws import patient as laws
from rehabbot.laws import scalar
from rehabbot.laws.patient import (  # noqa: F401  (re-exported)
    ACTIVE_DAMPING_S,
    ACTIVE_SATURATION_RAD,
    RESIST_VELOCITY_RAD_S,
)
from rehabbot.laws.work import joint_work_j
from rehabbot.sim.conditions import (
    REFLEX_GAIN_NMS_PER_RAD,
    REFLEX_LATENCY_S,
    PatientCondition,
    healthy_strength_nm,
)
from rehabbot.sim.scene import Scene
from rehabbot.sim.tremor import Tremor


class PatientDrive:
    """The condition's torques on the compliant exercised joints of ``scene`` (see the module
    docstring). ``ranges_rad`` are the (possibly reduced) ranges of those joints."""

    def __init__(self, scene: Scene, condition: PatientCondition, ranges_rad: np.ndarray,
                 frame_skip: int) -> None:
        model = scene.model
        self.condition = condition
        self.frame_skip = frame_skip
        self.dt_s = float(model.opt.timestep)
        dofs = [int(d) for d in scene.compliant_dof_adr]
        self._dofs = dofs
        self._qadr = [int(model.jnt_qposadr[model.dof_jntid[d]]) for d in dofs]
        names = [model.joint(int(model.dof_jntid[d])).name for d in dofs]
        bases = [n.rsplit("_", 1)[0] for n in names]
        exercised = list(scene.exercised_joints)
        self.exercised_index = [exercised.index(n) for n in names]
        self._low = [float(r[0]) for r in ranges_rad]
        self._high = [float(r[1]) for r in ranges_rad]
        profile = scene.profile
        self._reflex = condition.reflex
        self._gain = [REFLEX_GAIN_NMS_PER_RAD[b] for b in bases]
        # The reflex law's parameters: the grade's gain per joint, its threshold in rad/s.
        self._reflex_law = None if self._reflex is None else (
            [self._reflex.gain_scale * g for g in self._gain],
            math.radians(self._reflex.threshold_deg_s), self._reflex.catch_at_rest,
            self._reflex.release_to)
        share = condition.strength_fraction * condition.effort_fraction
        strength = [healthy_strength_nm(b, profile.mass_kg, profile.sex) for b in bases]
        self.available_nm = [(share * pos, share * neg) for pos, neg in strength]
        # The physiological bound of the summed torques: [-healthy negative, +healthy positive].
        self.peak_nm = [(pos, neg) for pos, neg in strength]
        self._mode = condition.effort if share > 0 else "passive"
        self._kp = [laws.active_gain_nm_per_rad(scalar, pos, neg)
                    for pos, neg in self.available_nm]
        self._lag = max(1, round(REFLEX_LATENCY_S / self.dt_s))
        self._velocity_history = [[0.0] * len(dofs) for _ in range(self._lag)]
        self._goal_lag = round(condition.reaction_delay_s / (frame_skip * self.dt_s))
        self._goals: list[list[float]] = []
        self._tremor = Tremor(condition.tremor_hz, condition.tremor_amplitude_nm, len(dofs),
                              self.dt_s) if condition.has_tremor else None
        self._step_index = 0
        self.torque_nm = np.zeros(len(exercised))  # the last physics step's, exercised joints

    # -- its parameters, read-only (the batched drive reads them: rehabbot.batch) ----------
    @property
    def dof_ids(self) -> tuple[int, ...]:
        """The compliant exercised joints' dofs (in qvel and qfrc_applied)."""
        return tuple(self._dofs)

    @property
    def qpos_ids(self) -> tuple[int, ...]:
        """... and their places in qpos."""
        return tuple(self._qadr)

    @property
    def stretch_ranges_rad(self) -> tuple[tuple[float, float], ...]:
        """Per joint, the (possibly reduced) range the reflex measures the stretch in."""
        return tuple(zip(self._low, self._high, strict=True))

    @property
    def reflex(self) -> Any:
        """The condition's stretch reflex (None: no spasticity)."""
        return self._reflex

    @property
    def reflex_gains_nms_per_rad(self) -> tuple[float, ...]:
        """Per joint, the reference reflex gain (times the grade's ``gain_scale``)."""
        return tuple(self._gain)

    @property
    def reflex_lag_steps(self) -> int:
        """The reflex latency in physics steps."""
        return self._lag

    @property
    def effort_mode(self) -> str:
        """``"passive"``, ``"active_assisted"`` or ``"resistive"``."""
        return self._mode

    @property
    def kp_nm_per_rad(self) -> tuple[float, ...]:
        """Per joint, the active patient's PD gain."""
        return tuple(self._kp)

    @property
    def goal_lag_steps(self) -> int:
        """The active patient's reaction delay in control steps."""
        return self._goal_lag

    @property
    def tremor(self) -> Tremor | None:
        """The condition's tremor (None: none)."""
        return self._tremor

    def reset(self, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Start an episode: clear the delays, draw the tremor's phases from ``rng``."""
        for row in self._velocity_history:
            row[:] = [0.0] * len(row)
        self._goals.clear()
        self._step_index = 0
        if self._tremor is not None:
            self._tremor.reset(rng)
        self.torque_nm[:] = 0.0
        data.qfrc_applied[self._dofs] = 0.0

    def run(self, model: mujoco.MjModel, data: mujoco.MjData, goal_rad: list[float],
            rng: np.random.Generator, meter: Any) -> None:
        """One control step: ``frame_skip`` physics steps with the patient's torques, the work
        counted by ``meter`` (a :class:`~rehabbot.sim.physics.WorkMeter`). ``goal_rad``: the
        compliant joints' angles at the active target."""
        self._goals.append(goal_rad)
        if len(self._goals) > self._goal_lag + 1:
            del self._goals[0]
        goal = self._goals[0]
        if self._tremor is not None:
            self._tremor.advance(rng, self.frame_skip * self.dt_s)
        qpos, qvel, applied, bias = data.qpos, data.qvel, data.qfrc_applied, data.qfrc_bias
        dofs, qadr = self._dofs, self._qadr
        # What the laws read: velocities for the reflex and the effort, the bias for the pull.
        moves = self._reflex_law is not None or self._mode != "passive"
        pulls = self._mode == "active_assisted"
        v = b = q = [qpos.item(a) for a in qadr]
        for _ in range(self.frame_skip):
            if moves:
                v = [qvel.item(d) for d in dofs]
            if pulls:
                b = [bias.item(d) for d in dofs]
            torque = self._torques(q, v, goal, b)
            for d, t in zip(dofs, torque, strict=True):
                applied[d] = t
            mujoco.mj_step(model, data)
            after = [qpos.item(a) for a in qadr]
            work = joint_work_j(torque, q, after)
            q = after
            meter.add_patient(work)
            meter.after_step(data)
        for i, t in zip(self.exercised_index, torque, strict=True):
            self.torque_nm[i] = t

    # -- the torque laws -------------------------------------------------------------------
    def _torques(self, q: list[float], v: list[float], goal: list[float],
                 bias: list[float]) -> list[float]:
        """This physics step's torques on the compliant joints (:mod:`rehabbot.laws.patient`):
        reflex + voluntary + tremor, saturated at the healthy peak."""
        history = self._velocity_history
        slot = self._step_index % self._lag
        delayed = history[slot]  # the velocity of `lag` physics steps ago
        history[slot] = v
        self._step_index += 1
        reflex_law, mode, tremor = self._reflex_law, self._mode, self._tremor
        tremor_nm = tremor.torques_nm() if tremor is not None else None
        low, high, kp, available, peak = self._low, self._high, self._kp, self.available_nm, \
            self.peak_nm
        if reflex_law is not None:
            gains, threshold, catch, release_to = reflex_law
        torque = []
        for j in range(len(q)):
            t = 0.0
            if reflex_law is not None:
                t = laws.reflex_torque_nm(scalar, delayed[j], q[j], low[j], high[j], gains[j],
                                          threshold, catch, release_to)
            if mode == "active_assisted":
                t += laws.active_pull_nm(scalar, q[j], v[j], goal[j], bias[j], kp[j],
                                         *available[j])
            elif mode == "resistive":
                t += laws.resistive_push_nm(scalar, v[j], *available[j])
            if tremor_nm is not None:
                t += tremor_nm[j]
            torque.append(laws.saturate_nm(scalar, t, *peak[j]))
        return torque
