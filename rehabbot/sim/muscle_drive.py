"""What a condition makes MyoSuite's muscles do, every physics step (``patient_model="myo"``):
the excitations of the exercised leg's muscles.

:class:`MuscleDrive` is the musculoskeletal counterpart of
:class:`rehabbot.sim.patient_drive.PatientDrive`: instead of joint torques it writes the
muscles' excitations (``data.ctrl``) before each physics step, and MuJoCo's muscle model
(activation dynamics, force-length-velocity) turns them into force:

* **Stretch reflex** (spasticity): each muscle that a compliant joint's range lengthens by
  ``REFLEX_MIN_EXCURSION_M`` or more fires on its own stretch, ``REFLEX_LATENCY_S`` late
  (SpasticMyoElbow's latency, Yu et al. 2024). The grade's
  :class:`~rehabbot.sim.conditions.SpasticReflex` is read in the muscle's terms: its stretch
  position is where its length lies along the range of the joint that stretches it most (a
  table of its length over that range, built once), its stretch speed that joint's speed
  towards lengthening it (not the tendon's own speed, which carries the jitter of MyoLeg's soft
  patella coupling). The threshold, the speed-dependent catch and the release are then the
  rigid patient's. The excitation is the share of the stretched muscles' strength that the
  rigid patient's reflex torque of that joint would take: ``REFLEX_FORCE_FACTOR x gain_scale x
  G_joint x`` (the speed above the threshold) ``/`` (the sum, over the reflex muscles that this
  motion of the joint stretches, of their healthy peak isometric force times their mean moment
  arm on it), at most 1, with ``G_joint`` the rigid patient's reference reflex gain
  (:data:`~rehabbot.sim.conditions.REFLEX_GAIN_NMS_PER_RAD`). So a slow stretch never fires,
  and the grades catch where the rigid patient's catch (``docs/musculoskeletal-patient.md``
  has the calibration; ``docs/results/myo-conditions.md`` the isokinetic table).
* **Voluntary effort**: the rigid patient's law gives the joint torque the patient wants (an
  ``"active_assisted"`` patient carries the limb and pulls towards the target it noticed
  ``reaction_delay_s`` ago; a ``"resistive"`` one pushes against the motion), saturated at the
  same available strength; it is shared out as one excitation over the muscles that pull the
  joint that way (their moment arms now), scaled by their peak isometric force.
* **Tremor** (:class:`~rehabbot.sim.tremor.Tremor`): the rigid patient's tremor torque on
  each compliant joint, drawn from the env's ``np_random`` in the same order, added to the
  patient's wish and shared out the same way, so the muscles that pull each way take turns.
* **Weakness** lowers the muscles' peak active force (``condition_setup``), so the same wish
  needs more excitation, and the reflex pulls less.
* **Fatigue** (``fatigue_scale > 0``): the excitations pass through the 3CC-r model
  (:mod:`rehabbot.sim.fatigue`), which gives each muscle its active fraction of motor units.

The patient's torque (``info["patient_torque_nm"]``) is the muscles' active force on the
exercised joints; the patient's work counts the work of the active forces
(:class:`~rehabbot.sim.muscles.MuscleMeter`).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from rehabbot.laws import patient as patient_laws
from rehabbot.laws import scalar
from rehabbot.laws.patient import CATCH_RAMP, CATCH_SHIFT_PER_RAD_S, RELEASE_WIDTH
from rehabbot.sim import statics
from rehabbot.sim.conditions import (
    REFLEX_GAIN_NMS_PER_RAD,
    REFLEX_LATENCY_S,
    PatientCondition,
    healthy_strength_nm,
)
from rehabbot.sim.fatigue import GENERAL_3CCR, KNEE_3CCR, ThreeCompartmentFatigue
from rehabbot.sim.muscles import FORCE_INDEX, PassiveForce, limb_muscles, moment_arms_m
from rehabbot.sim.scene import Scene
from rehabbot.sim.tremor import Tremor

# The reflex's excitation is this multiple of the share of the stretched muscles' isometric
# strength that the rigid patient's reflex torque would take: calibrated on the seated knee
# (its mean resistance at 100 deg/s matches the rigid knee's at grades 2 to 4) and checked on
# the elbow (docs/musculoskeletal-patient.md, Spasticity). Above 1 because the muscles do not
# all pull at their optimal length, and activation lags the excitation.
REFLEX_FORCE_FACTOR = 1.1
# A muscle joins the reflex when a compliant joint's range changes its length by this much.
REFLEX_MIN_EXCURSION_M = 0.02
REFLEX_TABLE_POINTS = 25  # the samples of a muscle's length along its joint's range


def _lengths_at(scene: Scene, data: mujoco.MjData, muscle_ids: np.ndarray,
                angles: dict[int, float]) -> np.ndarray:
    """The muscles' lengths at the home posture with the joints of ``angles`` (qpos address
    -> rad) moved (their followers too)."""
    data.qpos[:] = scene.home_qpos
    for adr, angle in angles.items():
        data.qpos[adr] = angle
    scene.follow_coupled_joints(data.qpos)
    mujoco.mj_kinematics(scene.model, data)
    mujoco.mj_comPos(scene.model, data)
    mujoco.mj_tendon(scene.model, data)
    mujoco.mj_transmission(scene.model, data)
    return data.actuator_length[muscle_ids].copy()


class MuscleDrive:
    """The condition's excitations of the exercised leg's muscles of ``scene`` (see the module
    docstring); ``ranges_rad`` are the (possibly reduced) ranges of the compliant joints."""

    def __init__(self, scene: Scene, condition: PatientCondition, ranges_rad: np.ndarray,
                 frame_skip: int) -> None:
        model = scene.model
        self.scene = scene
        self.condition = condition
        self.frame_skip = frame_skip
        self.dt_s = float(model.opt.timestep)
        side = scene.exercised_joints[0].rsplit("_", 1)[1]
        self.muscle_ids = limb_muscles(model, scene.muscle_actuator_ids, side)
        ids = self.muscle_ids
        dofs = [int(d) for d in scene.compliant_dof_adr]
        self._dofs = dofs
        self._qadr = [int(model.jnt_qposadr[model.dof_jntid[d]]) for d in dofs]
        names = [model.joint(int(model.dof_jntid[d])).name for d in dofs]
        self._joint_names = names
        exercised = list(scene.exercised_joints)
        self.exercised_index = [exercised.index(n) for n in names]
        self._exercised_dofs = [int(model.joint(n).dofadr[0]) for n in exercised]
        self._reflex = condition.reflex
        self._passive = PassiveForce(model, ids)
        self._peak_force = model.actuator_gainprm[ids, FORCE_INDEX].copy()
        self._geometry(scene, ids, np.asarray(ranges_rad, float))
        # Voluntary effort: the rigid patient's torque law and available strength.
        profile = scene.profile
        share = condition.strength_fraction * condition.effort_fraction
        bases = [n.rsplit("_", 1)[0] for n in names]
        strength = [healthy_strength_nm(b, profile.mass_kg, profile.sex) for b in bases]
        self.available_nm = [(share * pos, share * neg) for pos, neg in strength]
        self._mode = condition.effort if share > 0 else "passive"
        self._kp = [patient_laws.active_gain_nm_per_rad(scalar, pos, neg)
                    for pos, neg in self.available_nm]
        self._tremor = Tremor(condition.tremor_hz, condition.tremor_amplitude_nm, len(dofs),
                              self.dt_s) if condition.has_tremor else None
        # Whether the patient wishes joint torques (effort, tremor) that muscles must give.
        self._wishes = self._mode != "passive" or self._tremor is not None
        self._goal_lag = round(condition.reaction_delay_s / (frame_skip * self.dt_s))
        self._goals: list[list[float]] = []
        self._arms = np.zeros((len(ids), len(dofs)))  # effective moment arms [m], per step
        self._arms_current = False  # whether _arms are those of data's state
        self._lag = max(1, round(REFLEX_LATENCY_S / self.dt_s))
        self._speed_history = np.zeros((self._lag, len(self.reflex_rows)))
        self._step_index = 0
        self.fatigue = None
        if condition.fatigue_scale > 0.0:
            knee_only = all(b == "knee_flexion" for b in bases)
            rates = KNEE_3CCR if knee_only else GENERAL_3CCR
            scale = condition.fatigue_scale
            self.fatigue = ThreeCompartmentFatigue(len(ids), rates[0] * scale,
                                                   rates[1] * scale, rates[2], self.dt_s)
        self.excitation = np.zeros(len(ids))
        self.torque_nm = np.zeros(len(exercised))  # the last physics step's, exercised joints

    def _geometry(self, scene: Scene, ids: np.ndarray, ranges_rad: np.ndarray) -> None:
        """Each muscle's length along the compliant joint that stretches it most (the others
        at home), tabulated against the fraction of that joint's range in the direction that
        lengthens it (its stretch position); the muscles whose length that joint changes by
        at least ``REFLEX_MIN_EXCURSION_M`` take part in the reflex."""
        data = mujoco.MjData(scene.model)
        grid = np.linspace(0.0, 1.0, REFLEX_TABLE_POINTS)
        tables = [np.array([_lengths_at(scene, data, ids, {adr: low + f * (high - low)})
                            for f in grid]) for adr, (low, high) in
                  zip(self._qadr, ranges_rad, strict=True)]  # per joint: (points, muscles)
        excursion = np.array([t.max(axis=0) - t.min(axis=0) for t in tables])
        strongest = np.argmax(excursion, axis=0)
        reflex = np.flatnonzero(excursion.max(axis=0) >= REFLEX_MIN_EXCURSION_M)
        table = np.zeros((len(reflex), REFLEX_TABLE_POINTS))
        signs = []
        for row, i in enumerate(reflex):
            j = strongest[i]
            lengths = tables[j][:, i]
            signs.append(1.0 if lengths[-1] >= lengths[0] else -1.0)
            if signs[-1] < 0:  # the muscle lengthens as the joint's angle falls
                lengths = lengths[::-1]
            table[row] = np.maximum.accumulate(lengths)
        self.reflex_rows = reflex  # indices into muscle_ids
        self._reflex_ids = ids[reflex]
        self._table = table
        self._stretch_dof = np.array([self._dofs[strongest[i]] for i in reflex], dtype=int)
        self._stretch_sign = np.array(signs)
        # Each reflex muscle's excitation per rad/s above the threshold: the rigid reflex
        # torque's share of the healthy strength of the muscles that the same motion stretches.
        self._reflex_gain = np.zeros(len(reflex))
        condition = self.condition
        if condition.reflex is not None:
            healthy_force = self._peak_force[reflex] / condition.strength_fraction
            arm = (table[:, -1] - table[:, 0]) / np.array(
                [ranges_rad[strongest[i]][1] - ranges_rad[strongest[i]][0] for i in reflex])
            strength = healthy_force * arm
            for row, i in enumerate(reflex):
                joint = strongest[i]
                base = self._joint_names[joint].rsplit("_", 1)[0]
                same = (strongest[reflex] == joint) & (self._stretch_sign == signs[row])
                self._reflex_gain[row] = (REFLEX_FORCE_FACTOR * condition.reflex.gain_scale
                                          * REFLEX_GAIN_NMS_PER_RAD[base]
                                          / float(strength[same].sum()))

    def reset(self, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Start an episode: clear the delays and the excitations; fresh muscles; the tremor's
        phases drawn from ``rng``."""
        self._speed_history[:] = 0.0
        self._arms_current = False  # a new state
        self._goals.clear()
        self._step_index = 0
        self.excitation[:] = 0.0
        data.ctrl[self.muscle_ids] = 0.0
        if self.fatigue is not None:
            self.fatigue.reset()
        if self._tremor is not None:
            self._tremor.reset(rng)
        self.torque_nm[:] = 0.0

    def run(self, model: mujoco.MjModel, data: mujoco.MjData, goal_rad: list[float],
            rng: np.random.Generator, meter: Any, muscles: Any) -> None:
        """One control step: ``frame_skip`` physics steps with the muscles' excitations; the
        robot's work counted by ``meter`` (a :class:`~rehabbot.sim.physics.WorkMeter`), the
        muscles' by ``muscles`` (a :class:`~rehabbot.sim.muscles.MuscleMeter` counting their
        active work, which is the patient's). ``goal_rad``: the compliant joints' angles at the
        active target."""
        self._goals.append(goal_rad)
        if len(self._goals) > self._goal_lag + 1:
            del self._goals[0]
        goal = self._goals[0]
        if self._tremor is not None:
            self._tremor.advance(rng, self.frame_skip * self.dt_s)
        wishes = self._wishes
        if wishes and not self._arms_current:  # the last step's end left them current
            self._update_moment_arms(data, moment_arms_m(model, data, self.muscle_ids))
        ids = self.muscle_ids
        for _ in range(self.frame_skip):
            excitation = self._reflex_excitation(data)
            if wishes:
                excitation += self._wished_excitation(data, goal)
            np.clip(excitation, 0.0, 1.0, out=excitation)
            if self.fatigue is not None:
                excitation = self.fatigue.step(excitation)
            self.excitation[:] = excitation
            data.ctrl[ids] = excitation
            mujoco.mj_step(model, data)
            meter.after_step(data)
            muscles.after_step(data)
            meter.add_patient(muscles.last_active_work_j)
        self._update_torque(model, data)

    # -- the excitation laws ---------------------------------------------------------------
    def _reflex_excitation(self, data: mujoco.MjData) -> np.ndarray:
        """Each muscle's stretch-reflex excitation (0 for grade 0) at its stretch position (its
        length in its table), fed by its stretch speed of ``REFLEX_LATENCY_S`` ago: the speed
        of the joint that stretches it, towards lengthening it (the tendon's own speed also
        carries the jitter of MyoLeg's soft patella coupling, which a spindle does not feel)."""
        excitation = np.zeros(len(self.muscle_ids))
        reflex = self._reflex
        if reflex is None:
            return excitation
        ids, table = self._reflex_ids, self._table
        length = data.actuator_length[ids]
        after = np.clip((table < length[:, None]).sum(axis=1), 1, REFLEX_TABLE_POINTS - 1)
        rows = np.arange(len(ids))
        shorter, longer = table[rows, after - 1], table[rows, after]
        rise = longer - shorter
        within = np.clip((length - shorter) / np.maximum(rise, mujoco.mjMINVAL), 0.0, 1.0)
        stretch = (after - 1 + within) / (REFLEX_TABLE_POINTS - 1)
        slot = self._step_index % self._lag
        delayed = self._speed_history[slot].copy()  # joint speed that stretches it [rad/s]
        np.multiply(data.qvel[self._stretch_dof], self._stretch_sign,
                    out=self._speed_history[slot])
        self._step_index += 1
        excess = delayed - math.radians(reflex.threshold_deg_s)
        past = stretch - (reflex.catch_at_rest - CATCH_SHIFT_PER_RAD_S * delayed)
        build_up = np.clip(past / CATCH_RAMP, 0.0, 1.0)
        release = reflex.release_to + (1.0 - reflex.release_to) * np.exp(
            -np.maximum(past - CATCH_RAMP, 0.0) / RELEASE_WIDTH)
        fired = self._reflex_gain * np.maximum(excess, 0.0)
        excitation[self.reflex_rows] = fired * build_up * release
        return excitation

    def _update_moment_arms(self, data: mujoco.MjData, dense: np.ndarray) -> None:
        """The muscles' effective moment arms on the compliant joints now (the followers' share
        included), ``d length / d q``, from their moment arms ``dense`` at ``data``'s state."""
        coupling = statics.coupling_map(self.scene, data)
        if coupling is not None:
            dense = dense @ coupling
        self._arms[:] = dense[:, self._dofs]
        self._arms_current = True

    def _wished_torques_nm(self, data: mujoco.MjData, goal: list[float]) -> list[float]:
        """The torque the patient wishes on each compliant joint: the rigid patient's effort
        law (an active patient pulls towards ``goal``, a resistive one pushes against the
        motion, saturated at the available strength), plus the tremor's."""
        qpos, qvel, bias = data.qpos, data.qvel, data.qfrc_bias
        wishes = [0.0] * len(self._dofs)
        if self._mode != "passive":
            for j, (adr, dof) in enumerate(zip(self._qadr, self._dofs, strict=True)):
                q, v = qpos[adr], qvel[dof]
                if self._mode == "active_assisted":
                    wishes[j] = patient_laws.active_pull_nm(scalar, q, v, goal[j], bias[dof],
                                                            self._kp[j], *self.available_nm[j])
                else:
                    wishes[j] = patient_laws.resistive_push_nm(scalar, v, *self.available_nm[j])
        if self._tremor is not None:
            self._tremor.add_torques(wishes)
        return wishes

    def _wished_excitation(self, data: mujoco.MjData, goal: list[float]) -> np.ndarray:
        """The excitation that gives the wished torque on each compliant joint, shared over
        the muscles that pull that way (a muscle pulls a joint positive when it shortens as
        the joint's angle grows: its moment arm is negative)."""
        excitation = np.zeros(len(self.muscle_ids))
        for j, wish in enumerate(self._wished_torques_nm(data, goal)):
            if wish == 0.0:
                continue
            arms = self._arms[:, j]
            pulling = np.where(wish > 0.0, -arms, arms)  # > 0: the muscle pulls that way
            capacity = float(np.sum(np.maximum(pulling, 0.0) * self._peak_force))
            if capacity > 0.0:
                excitation += np.where(pulling > 0.0, abs(wish) / capacity, 0.0)
        return excitation

    def _update_torque(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """The muscles' active torques on the exercised joints now (``torque_nm``); for a
        patient who wishes torques, the moment arms the next control step starts from (the
        state does not change between two steps)."""
        dense = moment_arms_m(model, data, self.muscle_ids)
        active = self._passive.active_force_n(data)
        generalised = statics.reduced(self.scene, data, dense.T @ active)
        self.torque_nm[:] = generalised[self._exercised_dofs]
        if self._wishes:
            self._update_moment_arms(data, dense)
