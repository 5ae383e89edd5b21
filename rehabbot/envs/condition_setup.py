"""Fitting a scene and its exercises to a patient's condition, once, when an env is built.

* **Contracture**: the compliant exercised joints' passive stiffness and damping are multiplied
  by ``stiffness_scale`` (on MyoSuite's legs: the exercised leg's muscles' passive
  force-length curve, and the joints' damping); their ranges shrink to ``rom_scale`` of their
  extent on either side of the home posture, and so do the exercises' key poses (so every
  target stays inside the patient's reduced range, and the range-of-motion rule checks the
  reduced range).
* **Weakness on muscles** (MyoSuite's legs): the exercised leg's muscles' peak active force is
  multiplied by ``strength_fraction`` (their passive curve keeps its scale). On the rigid
  patient, weakness scales the voluntary torque instead
  (:class:`~rehabbot.sim.patient_drive.PatientDrive`).
* **Feasibility** (:func:`check_condition_forces`): at every target of every exercise, the cuff
  force that holds the limb against gravity, the scaled passive springs, the tremor's peak and
  a resistive patient's full push must stay within the cuff's force limit; otherwise the env is
  refused with the reason. Spasticity is not in this check: its reflex needs speed, so moving
  slowly always avoids it, and a too-fast robot meets a ``"cuff_force"`` safety stop instead,
  which an agent can learn to avoid (``docs/conditions.md``, Feasibility).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from rehabbot.sim import statics
from rehabbot.sim.conditions import PatientCondition, healthy_strength_nm
from rehabbot.sim.muscles import limb_muscles, scale_active_force, scale_passive_force
from rehabbot.sim.scene import Scene
from rehabbot.sim.tremor import TREMOR_MODULATION
from rehabbot.tasks.exercises import Exercise
from rehabbot.tasks.targets import TargetSequence


def compliant_joint_names(scene: Scene) -> tuple[str, ...]:
    """The compliant exercised joints of ``scene`` (full names), in dof order."""
    model = scene.model
    return tuple(model.joint(int(model.dof_jntid[d])).name for d in scene.compliant_dof_adr)


def scale_passive(scene: Scene, condition: PatientCondition) -> None:
    """Multiply the compliant joints' stiffness and damping by ``stiffness_scale``; on
    MyoSuite's legs, the exercised leg's muscles' passive force-length curve (their
    ``fpmax``) and the compliant joints' damping."""
    if condition.stiffness_scale == 1.0:
        return
    model = scene.model
    if len(scene.muscle_actuator_ids):
        side = scene.exercised_joints[0].rsplit("_", 1)[1]
        scale_passive_force(model, limb_muscles(model, scene.muscle_actuator_ids, side),
                            condition.stiffness_scale)
        model.dof_damping[scene.compliant_dof_adr] *= condition.stiffness_scale
        return
    for dof in scene.compliant_dof_adr:
        model.jnt_stiffness[model.dof_jntid[dof]] *= condition.stiffness_scale
        model.dof_damping[dof] *= condition.stiffness_scale


def scale_strength(scene: Scene, condition: PatientCondition) -> None:
    """On MyoSuite's legs, multiply the exercised leg's muscles' peak active force by
    ``strength_fraction`` (weakness); nothing on the rigid patient, whose weakness scales its
    voluntary torque."""
    if condition.strength_fraction == 1.0 or not len(scene.muscle_actuator_ids):
        return
    side = scene.exercised_joints[0].rsplit("_", 1)[1]
    scale_active_force(scene.model, limb_muscles(scene.model, scene.muscle_actuator_ids, side),
                       condition.strength_fraction)


def reduced_ranges_rad(scene: Scene, condition: PatientCondition) -> np.ndarray:
    """(n_compliant, 2) ranges of the compliant joints, shrunk by ``rom_scale`` about home."""
    model = scene.model
    ranges = []
    for dof in scene.compliant_dof_adr:
        joint = int(model.dof_jntid[dof])
        home = scene.home_qpos[model.jnt_qposadr[joint]]
        low, high = model.jnt_range[joint]
        ranges.append((home + condition.rom_scale * (low - home),
                       home + condition.rom_scale * (high - home)))
    return np.array(ranges)


def apply_ranges(scene: Scene, ranges_rad: np.ndarray) -> None:
    """Set the compliant joints' ranges in the model (joint limits and the ROM rule)."""
    model = scene.model
    for dof, (low, high) in zip(scene.compliant_dof_adr, ranges_rad, strict=True):
        model.jnt_range[model.dof_jntid[dof]] = (low, high)


def scaled_exercises(scene: Scene, table: Sequence[Exercise],
                     condition: PatientCondition) -> tuple[Exercise, ...]:
    """The exercises with every compliant joint's key angle moved to ``rom_scale`` of its
    distance from home (the table itself when ``rom_scale`` is 1)."""
    if condition.rom_scale == 1.0:
        return tuple(table)
    model = scene.model
    home_deg = {name.rsplit("_", 1)[0]: math.degrees(scene.home_qpos[model.joint(name).qposadr[0]])
                for name in compliant_joint_names(scene)}
    scaled = []
    for exercise in table:
        poses = tuple({joint: (home_deg[joint] + condition.rom_scale * (angle - home_deg[joint])
                               if joint in home_deg else angle)
                       for joint, angle in pose.items()} for pose in exercise.key_poses_deg)
        description = f"{exercise.description} (range of motion x {condition.rom_scale:g})"
        scaled.append(Exercise(exercise.name, description, poses))
    return tuple(scaled)


def goals_rad(scene: Scene, targets: Sequence[TargetSequence]) -> tuple[list[list[float]], ...]:
    """Per exercise, per target: the compliant joints' angles [rad] (what an active patient
    aims for)."""
    compliant = compliant_joint_names(scene)
    index = [list(scene.exercised_joints).index(name) for name in compliant]
    return tuple([[math.radians(row[i]) for i in index] for row in sequence.patient_deg]
                 for sequence in targets)


def check_condition_forces(scene: Scene, targets: Sequence[TargetSequence],
                           condition: PatientCondition, force_limit_n: float,
                           levels: Sequence[int]) -> None:
    """``ValueError`` if holding the limb at a target, against the condition's steady torques,
    needs more cuff force than ``force_limit_n`` at a weight level of ``levels``."""
    model = scene.model
    profile = scene.profile
    dofs = scene.compliant_dof_adr
    names = compliant_joint_names(scene)
    push = np.zeros(len(dofs))
    if condition.effort == "resistive":
        share = condition.strength_fraction * condition.effort_fraction
        push += [share * max(healthy_strength_nm(n.rsplit("_", 1)[0], profile.mass_kg,
                                                 profile.sex)) for n in names]
    if condition.has_tremor:
        push += condition.tremor_amplitude_nm * (1.0 + TREMOR_MODULATION)
    data = mujoco.MjData(model)
    level0 = scene.weight_level
    try:
        for level in levels:
            scene.set_weight_level(level)
            for sequence in targets:
                for k in range(len(sequence)):
                    force = _holding_force_n(scene, data, sequence, k, push)
                    if force > force_limit_n:
                        raise ValueError(
                            f"condition ({condition.describe()}) makes exercise "
                            f"{sequence.exercise.name!r} infeasible for profile {profile} at "
                            f"weight_level {level}: holding target {k} "
                            f"({_pose_text(scene, sequence, k)}) needs {force:.0f} N at the "
                            f"cuff, above its {force_limit_n:.0f} N limit (docs/conditions.md, "
                            "Feasibility)")
    finally:
        scene.set_weight_level(level0)


def _holding_force_n(scene: Scene, data: mujoco.MjData, sequence: TargetSequence, k: int,
                     push_nm: np.ndarray) -> float:
    """Smallest cuff force holding the limb at target ``k`` against gravity, the passive
    springs and ``push_nm`` (in whichever direction adds to the load)."""
    model = scene.model
    data.qpos[:] = scene.home_qpos
    data.qpos[scene.exercised_qpos_adr] = np.radians(sequence.patient_deg[k])
    scene.follow_coupled_joints(data.qpos)
    data.qpos[scene.robots[0].qpos_adr] = sequence.robot_rad[k]
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    dofs = scene.compliant_dof_adr
    jac = statics.cuff_jacobian(scene, data)
    if len(scene.muscle_actuator_ids) or scene.coupled_joints:
        # Muscles' passive forces, and joints that follow another (MyoSuite's legs).
        generalised = data.qfrc_bias - data.qfrc_spring - data.qfrc_actuator
        coupling = statics.coupling_map(scene, data)
        if coupling is not None:
            jac, generalised = jac @ coupling, coupling.T @ generalised
        need = generalised[dofs]
    else:
        need = data.qfrc_bias[dofs] - data.qfrc_spring[dofs]
    jac = jac[:, dofs].T
    need = need + np.where(need >= 0.0, push_nm, -push_nm)
    force, *_ = np.linalg.lstsq(jac, need, rcond=None)
    return float(np.linalg.norm(force))


def _pose_text(scene: Scene, sequence: TargetSequence, k: int) -> str:
    return ", ".join(f"{name} {angle:.0f} deg" for name, angle in
                     zip(scene.exercised_joints, sequence.patient_deg[k], strict=True))
