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


# MuJoCo's muscle parameters (gainprm and biasprm hold the same nine): index of ``fpmax``, the
# passive force at ``lmax`` as a fraction of the peak isometric force.
FPMAX_INDEX = 7


def scale_passive_force(model: mujoco.MjModel, muscle_ids: np.ndarray, scale: float) -> None:
    """Multiply the passive force-length curve of ``muscle_ids`` by ``scale`` (their
    ``fpmax``): a contracture's stiffer muscles (``PatientCondition.stiffness_scale``)."""
    if not scale > 0.0:
        raise ValueError(f"scale={scale!r} must be > 0")
    model.actuator_gainprm[muscle_ids, FPMAX_INDEX] *= scale
    model.actuator_biasprm[muscle_ids, FPMAX_INDEX] *= scale


class MuscleMeter:
    """Counts the muscles' work and peak force after every physics step (:meth:`after_step`)
    and reports them with their state (:meth:`info`, the env's ``info`` entries
    :data:`INFO_KEYS`)."""

    def __init__(self, model: mujoco.MjModel, muscle_ids: np.ndarray) -> None:
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

    def reset(self, data: mujoco.MjData) -> None:
        """Start counting at the state in ``data`` (after ``mj_forward``)."""
        self.work_j = 0.0
        self.peak_force_n = float(np.max(-data.actuator_force[self.muscle_ids], initial=0.0))

    def after_step(self, data: mujoco.MjData) -> None:
        """Add one physics step: the power at the step's end times the timestep, and the
        largest pull."""
        force = np.take(data.actuator_force, self.muscle_ids, out=self._force)
        velocity = np.take(data.actuator_velocity, self.muscle_ids, out=self._velocity)
        self.work_j += float(force @ velocity) * self.timestep_s
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
