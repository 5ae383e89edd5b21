"""Inverse kinematics of a robot's cuff site: damped least squares on MuJoCo's Jacobians."""

from __future__ import annotations

import mujoco
import numpy as np

from rehabbot.sim.handles import RobotHandle


def quat_from_mat(mat9: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a row-major 3x3 rotation."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat9, dtype=float).reshape(9))
    return quat


# The task of a cuff: 3 position and 3 orientation constraints.
TASK_DIMENSION = 6


class RobotIK:
    """Damped least-squares inverse kinematics of one robot's cuff site (position + orientation).

    Works on a kinematics-only ``MjData``; joint limits are respected by clipping each step.

    A robot with more joints than the cuff's six constraints (the FR3's seven) has a null space:
    a self-motion that leaves the cuff where it is. Left free, it drifts with each solve, so
    neighbouring patient poses get far-apart arm postures and the joints wander into their
    limits. For such a robot every step also moves, inside the null space, towards a rest
    posture (``posture_gain`` of the way per iteration): the solution is the pose nearest it.
    The rest posture is ``solve``'s ``posture``, else its seed. Sweeps of a workspace or a path
    pass the robot's home angles, so that a cuff pose gets the same arm posture whatever
    neighbour it was solved from (the targets of an exercise then lie inside the setpoint
    bounds swept from the workspace). A robot with six joints has no null space and takes the
    plain damped step.
    """

    def __init__(self, model: mujoco.MjModel, damping: float = 1e-3, max_iters: int = 300,
                 tol_m: float = 1e-7, posture_gain: float = 0.5) -> None:
        self.model = model
        self.posture_gain = posture_gain
        self.damping = damping
        self.max_iters = max_iters
        self.tol_m = tol_m
        self._jac_pos = np.zeros((3, model.nv))
        self._jac_rot = np.zeros((3, model.nv))
        self._quat = np.zeros(4)
        self._quat_err = np.zeros(4)
        self._rot_err = np.zeros(3)

    def solve(self, data: mujoco.MjData, handle: RobotHandle, target_pos: np.ndarray,
              target_quat: np.ndarray, seed: np.ndarray, orientation_weight_m: float = 0.1,
              posture: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """Joint angles putting ``handle``'s cuff site at the target; returns (q, pose error).

        The pose error is the position error [m] plus ``orientation_weight_m`` x the rotation
        error [rad]. ``posture`` is the rest posture of a redundant robot (default: ``seed``).
        ``data.qpos`` of the robot is left at the solution.
        """
        model = self.model
        qadr, dadr, site = handle.qpos_adr, handle.dof_adr, handle.cuff_site_id
        low = model.jnt_range[model.dof_jntid[dadr], 0]
        high = model.jnt_range[model.dof_jntid[dadr], 1]
        seed = np.array(seed, dtype=float)
        data.qpos[qadr] = seed
        redundant = len(dadr) > TASK_DIMENSION
        rest = seed if posture is None else np.asarray(posture, dtype=float)
        err = np.inf
        for _ in range(self.max_iters):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            pos_err = target_pos - data.site_xpos[site]
            mujoco.mju_mat2Quat(self._quat, data.site_xmat[site])
            mujoco.mju_subQuat(self._rot_err, target_quat, self._quat)  # in the site frame
            self._rot_err[:] = data.site_xmat[site].reshape(3, 3) @ self._rot_err
            err = float(np.linalg.norm(pos_err) + orientation_weight_m
                        * np.linalg.norm(self._rot_err))
            if err < self.tol_m:
                break
            mujoco.mj_jacSite(model, data, self._jac_pos, self._jac_rot, site)
            jac = np.vstack([self._jac_pos[:, dadr], orientation_weight_m * self._jac_rot[:, dadr]])
            e = np.concatenate([pos_err, orientation_weight_m * self._rot_err])
            # jac has 6 rows (3 position, 3 rotation) whatever the number of joints.
            step = jac.T @ np.linalg.solve(jac @ jac.T + self.damping**2 * np.eye(6), e)
            if redundant:
                # The exact projector onto the null space: a damped one would leak the posture
                # pull into the cuff's pose and stall the solve short of its tolerance.
                null = np.eye(len(dadr)) - np.linalg.pinv(jac) @ jac
                step += null @ (self.posture_gain * (rest - data.qpos[qadr]))
            scale = min(1.0, 0.3 / max(np.abs(step).max(), 1e-12))
            data.qpos[qadr] = np.clip(data.qpos[qadr] + scale * step, low, high)
        return data.qpos[qadr].copy(), err
