"""What the exercised limb's muscles do over an episode (MyoSuite's legs,
``patient_model="myo"``): their excitation, activation and force now, the largest force of any
one of them so far, and the work of their forces on the limb.

MuJoCo's muscle actuators pull (``actuator_force`` <= 0) along their tendon, whose lengthening
speed is ``actuator_velocity``; the power of a muscle on the limb is their product. A passive
muscle that the robot stretches absorbs work (negative); one that shortens while stretched
gives some back. The work counts passive and active force alike: it is not the patient's
voluntary work (``patient_work_j``), which comes from the patient's effort only.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rehabbot.sim import statics
from rehabbot.sim.scene import Scene, set_pose

INFO_KEYS: tuple[str, ...] = ("muscle_excitation", "muscle_activation", "muscle_force_n",
                              "peak_muscle_force_n", "muscle_work_j")
# MuJoCo's muscle parameters (gainprm and biasprm hold the same nine): the indices used here.
RANGE_INDEX = (0, 1)  # the operating range of normalised length
FORCE_INDEX = 2  # the peak isometric force [N] (its active part is gainprm's)
LMAX_INDEX = 5
FPMAX_INDEX = 7  # the passive force at lmax, a fraction of the peak isometric force


def limb_muscles(model: mujoco.MjModel, muscle_ids: np.ndarray, side: str) -> np.ndarray:
    """The ids among ``muscle_ids`` whose name ends with ``_<side>`` (``"r"`` or ``"l"``)."""
    return np.array([i for i in muscle_ids if model.actuator(int(i)).name.endswith(f"_{side}")],
                    dtype=int)


def muscle_torque_nm(scene: Scene, joint: str, pose_deg: dict[str, float]) -> float:
    """The muscles' generalised force [N m] on ``joint`` of ``scene`` at a pose: the scene's
    home state with the joints of ``pose_deg`` (name -> deg) moved there (the joints that
    follow them too) and every velocity zero. With zero excitation it is the passive torque;
    the share of the joints that follow ``joint`` (MyoLeg's knee) is included
    (:func:`rehabbot.sim.statics.reduced`). Positive: towards the joint's positive angle."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    set_pose(model, data.qpos, pose_deg)
    mujoco.mj_forward(model, data)
    torque = statics.reduced(scene, data, data.qfrc_actuator)
    return float(torque[model.joint(joint).dofadr[0]])


def scale_passive_force(model: mujoco.MjModel, muscle_ids: np.ndarray, scale: float) -> None:
    """Multiply the passive force-length curve of ``muscle_ids`` by ``scale`` (their
    ``fpmax``): a contracture's stiffer muscles (``PatientCondition.stiffness_scale``)."""
    if not scale > 0.0:
        raise ValueError(f"scale={scale!r} must be > 0")
    model.actuator_gainprm[muscle_ids, FPMAX_INDEX] *= scale
    model.actuator_biasprm[muscle_ids, FPMAX_INDEX] *= scale


def scale_active_force(model: mujoco.MjModel, muscle_ids: np.ndarray, fraction: float) -> None:
    """Multiply the peak active force of ``muscle_ids`` by ``fraction`` (their gain's
    ``force``; the passive force-length curve keeps its healthy scale): a weak patient's muscles
    (``PatientCondition.strength_fraction``). Every muscle must give its force explicitly."""
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction={fraction!r} must be in (0, 1]")
    if (model.actuator_gainprm[muscle_ids, FORCE_INDEX] <= 0.0).any():
        raise ValueError("every muscle must give its peak force (gainprm[2] > 0) to be scaled")
    model.actuator_gainprm[muscle_ids, FORCE_INDEX] *= fraction


def optimal_length_m(model: mujoco.MjModel, muscle_ids: np.ndarray) -> np.ndarray:
    """Each muscle's optimal length L0 [m] (MuJoCo's: its length range over its operating
    range of normalised length)."""
    prm = model.actuator_biasprm[muscle_ids]
    span = model.actuator_lengthrange[muscle_ids, 1] - model.actuator_lengthrange[muscle_ids, 0]
    return span / np.maximum(prm[:, RANGE_INDEX[1]] - prm[:, RANGE_INDEX[0]], mujoco.mjMINVAL)


class PassiveForce:
    """MuJoCo's passive force-length curve of some muscles (``mju_muscleBias``, vectorised):
    :meth:`force_n` at their lengths, <= 0 (a pull); a muscle's active force
    (:meth:`active_force_n`) is its ``actuator_force`` minus this."""

    def __init__(self, model: mujoco.MjModel, muscle_ids: np.ndarray) -> None:
        ids = np.asarray(muscle_ids, dtype=int)
        prm = model.actuator_biasprm[ids]
        if (prm[:, FORCE_INDEX] <= 0.0).any():
            raise ValueError("every muscle must give its peak force (biasprm[2] > 0)")
        self._l0 = optimal_length_m(model, ids)
        self._range0 = prm[:, RANGE_INDEX[0]].copy()
        self._length0 = model.actuator_lengthrange[ids, 0].copy()
        self._knee = 0.5 * (1.0 + prm[:, LMAX_INDEX])  # b: quadratic below, linear above
        self._width = np.maximum(self._knee - 1.0, mujoco.mjMINVAL)
        self._peak = prm[:, FORCE_INDEX] * prm[:, FPMAX_INDEX]
        self.muscle_ids = ids
        self._act_adr = model.actuator_actadr[ids].copy()

    def force_n(self, length_m: np.ndarray) -> np.ndarray:
        """The passive forces at ``length_m`` (one per muscle) [N], <= 0."""
        normalised = self._range0 + (length_m - self._length0) / self._l0
        x = (normalised - 1.0) / self._width
        quadratic = 0.5 * np.square(np.clip(x, 0.0, 1.0))
        linear = np.maximum(x - 1.0, 0.0)
        return -self._peak * (quadratic + linear)

    def active_force_n(self, data: mujoco.MjData) -> np.ndarray:
        """The muscles' active forces now [N], <= 0: ``actuator_force`` less the passive force,
        exactly 0 where a muscle's activation is 0."""
        ids = self.muscle_ids
        active = data.actuator_force[ids] - self.force_n(data.actuator_length[ids])
        active[data.act[self._act_adr] == 0.0] = 0.0
        return active


def moment_arms_m(model: mujoco.MjModel, data: mujoco.MjData,
                  muscle_ids: np.ndarray) -> np.ndarray:
    """(n_muscles, nv): each muscle's moment arms [m] at ``data``'s state, ``d length / d q``
    (MuJoCo's sparse ``actuator_moment``, after ``mj_forward`` or a step, made dense). A muscle
    pulls, so its force moves a joint towards where its arm is negative."""
    dense = np.zeros((len(muscle_ids), model.nv))
    moment, rowadr, rownnz, colind = (data.actuator_moment, data.moment_rowadr,
                                      data.moment_rownnz, data.moment_colind)
    for row, i in enumerate(muscle_ids):
        start = rowadr[i]
        end = start + rownnz[i]
        dense[row, colind[start:end]] = moment[start:end]
    return dense


class MuscleMeter:
    """Counts the muscles' work and peak force after every physics step (:meth:`after_step`)
    and reports them with their state (:meth:`info`, the env's ``info`` entries
    :data:`INFO_KEYS`). With ``count_active``, it also counts the work of their active forces
    alone (:attr:`active_work_j`, :attr:`last_active_work_j`: the patient's voluntary and reflex
    work when a condition excites them)."""

    def __init__(self, model: mujoco.MjModel, muscle_ids: np.ndarray,
                 count_active: bool = False) -> None:
        if len(muscle_ids) == 0:
            raise ValueError("a MuscleMeter needs at least one muscle actuator")
        self.muscle_ids = np.asarray(muscle_ids, dtype=int)
        self.act_adr = model.actuator_actadr[self.muscle_ids].copy()
        if (self.act_adr < 0).any():
            raise ValueError("every muscle actuator of a MuscleMeter must have an activation")
        self.timestep_s = float(model.opt.timestep)
        self.work_j = 0.0
        self.peak_force_n = 0.0
        self._force = np.zeros(len(self.muscle_ids))
        self._velocity = np.zeros(len(self.muscle_ids))
        self.passive = PassiveForce(model, self.muscle_ids) if count_active else None
        self.active_work_j = 0.0
        self.last_active_work_j = 0.0

    def reset(self, data: mujoco.MjData) -> None:
        """Start counting at the state in ``data`` (after ``mj_forward``)."""
        self.work_j = 0.0
        self.active_work_j = 0.0
        self.last_active_work_j = 0.0
        self.peak_force_n = float(np.max(-data.actuator_force[self.muscle_ids], initial=0.0))

    def after_step(self, data: mujoco.MjData) -> None:
        """Add one physics step: the power at the step's end times the timestep, and the
        largest pull."""
        force = np.take(data.actuator_force, self.muscle_ids, out=self._force)
        velocity = np.take(data.actuator_velocity, self.muscle_ids, out=self._velocity)
        self.work_j += float(force @ velocity) * self.timestep_s
        if self.passive is not None:
            active = self.passive.active_force_n(data)
            self.last_active_work_j = float(active @ velocity) * self.timestep_s
            self.active_work_j += self.last_active_work_j
        pull = -float(force.min())
        if pull > self.peak_force_n:
            self.peak_force_n = pull

    def info(self, data: mujoco.MjData) -> dict[str, float]:
        """Mean excitation (``ctrl``) and activation (``act``) of the limb's muscles, their
        total pull [N] now, the largest pull of one muscle since reset [N] and their work on
        the limb since reset [J]."""
        ids = self.muscle_ids
        return {
            "muscle_excitation": float(np.mean(data.ctrl[ids])),
            "muscle_activation": float(np.mean(data.act[self.act_adr])),
            "muscle_force_n": float(-np.sum(data.actuator_force[ids])),
            "peak_muscle_force_n": self.peak_force_n,
            "muscle_work_j": self.work_j,
        }
