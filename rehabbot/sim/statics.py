"""Statics of the coupled robot–patient system: who carries the limb's weight.

At a pose held in ``data`` (``mj_forward`` done, zero velocity), the limb is in equilibrium when
the cuff force ``f`` satisfies, on the patient's compliant joints,
``J_c^T f = g - tau_spring - tau_muscle`` (gravity minus the passive joint springs and, for
MyoSuite's legs, the muscles' passive forces); the robot's servos must
then supply ``g_robot - tau_gravcomp - J_c^T f`` on its own joints. With fewer compliant joints
than cuff constraints, the minimum-norm force is taken.

The functions take any object with the scene's ``model``, ``robots`` (their handles) and
``compliant_dof_adr``: a :class:`rehabbot.sim.scene.Scene`, typically.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import mujoco
import numpy as np

from rehabbot.sim.handles import RobotHandle


class CoupledSystem(Protocol):
    """What the statics needs of a scene."""

    model: mujoco.MjModel
    robots: Sequence[RobotHandle]
    compliant_dof_adr: np.ndarray


def cuff_jacobian(system: CoupledSystem, data: mujoco.MjData) -> np.ndarray:
    """Stacked (3 per cuff, nv) Jacobian of robot-cuff minus patient-cuff site positions."""
    model = system.model
    rows = []
    jac_robot = np.zeros((3, model.nv))
    jac_patient = np.zeros((3, model.nv))
    for handle in system.robots:
        mujoco.mj_jacSite(model, data, jac_robot, None, handle.cuff_site_id)
        mujoco.mj_jacSite(model, data, jac_patient, None, handle.patient_cuff_site_id)
        rows.append(jac_robot - jac_patient)
    return np.vstack(rows)


def coupling_map(system: CoupledSystem, data: mujoco.MjData) -> np.ndarray | None:
    """``T`` (nv, nv): the velocity of every DoF for unit velocities of the independent ones
    (identity, plus ``d q_follower / d q_leader`` for each joint that follows another through a
    joint equality: MyoLeg's knee), at ``data.qpos``; None when no joint follows another."""
    coupled = getattr(system, "coupled_joints", ())
    if not coupled:
        return None
    coupling = np.eye(system.model.nv)
    for joint in coupled:
        coupling[joint.dof_adr, joint.leader_dof_adr] = joint.slope(data.qpos)
    return coupling


def reduced(system: CoupledSystem, data: mujoco.MjData, force: np.ndarray) -> np.ndarray:
    """A generalised force (nv,) on the independent DoFs: each follower's share is added to
    its leader's (``T^T force``); ``force`` itself when no joint follows another."""
    coupling = coupling_map(system, data)
    return force if coupling is None else coupling.T @ force


def cuff_load_torque(system: CoupledSystem, data: mujoco.MjData) -> np.ndarray:
    """Generalised torque (nv,) that the cuff(s) apply when they carry the limb statically."""
    jac, force = _cuff_load(system, data)
    return jac.T @ force


def cuff_load_force(system: CoupledSystem, data: mujoco.MjData) -> np.ndarray:
    """The force (3 per cuff) [N] the cuff(s) carry when they hold the limb statically."""
    return _cuff_load(system, data)[1]


def _cuff_load(system: CoupledSystem, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    jac = cuff_jacobian(system, data)
    ex = system.compliant_dof_adr
    coupling = coupling_map(system, data)
    if coupling is None:
        need = data.qfrc_bias[ex] - data.qfrc_spring[ex] - data.qfrc_actuator[ex]
    else:
        jac = jac @ coupling
        need = (coupling.T @ (data.qfrc_bias - data.qfrc_spring - data.qfrc_actuator))[ex]
    force, *_ = np.linalg.lstsq(jac[:, ex].T, need, rcond=None)
    return jac, force


def servo_setpoints(system: CoupledSystem, data: mujoco.MjData, load: np.ndarray) -> np.ndarray:
    """Servo setpoints (n_robots, n_joints) that hold the robots at ``data.qpos`` under
    ``load``."""
    model = system.model
    setpoints = np.zeros((len(system.robots), system.robots[0].n_joints))
    for k, handle in enumerate(system.robots):
        dofs = handle.dof_adr
        torque = data.qfrc_bias[dofs] - data.qfrc_gravcomp[dofs] - load[dofs]
        kp = model.actuator_gainprm[handle.servo_ids, 0]
        setpoints[k] = data.qpos[handle.qpos_adr] + torque / kp
    return setpoints
