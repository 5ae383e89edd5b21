"""The MjModel MuJoCo Warp steps for a batched env: the CPU env's, changed only where MuJoCo
Warp would otherwise compute something else than MuJoCo (:func:`physics_model`)."""

from __future__ import annotations

import mujoco
import numpy as np

from rehabbot.batch.env_tables import EnvTables

# MuJoCo Warp's jacobian="auto" turns sparse above this many dofs (mujoco_warp io.is_sparse).
WARP_SPARSE_ABOVE_NV = 32


def physics_model(model: mujoco.MjModel, tables: EnvTables) -> mujoco.MjModel:
    """The model MuJoCo Warp steps: the CPU env's, with two changes where needed.

    * In ``torque`` mode the servos are switched off by zero gains (MuJoCo Warp ignores
      ``opt.disableactuator``, with which the CPU env switches them off). The robot's gravity
      compensation and torque clamp are joint properties (``actgravcomp``, ``actfrcrange``),
      so nothing else changes.
    * A model that MuJoCo Warp would give a sparse Jacobian (``jacobian="auto"`` and more
      than 32 dofs: the two-arm scene's 33) gets a dense one. MuJoCo Warp's sparse path
      regularises a site-to-site connect constraint (the cuffs) by the inverse weight of the
      sites' *welded ancestor* bodies, where MuJoCo (and its dense path) uses the sites' own
      bodies: the cuff forces at home came out 4 % higher (14.35 N against 13.85 N). The
      Jacobian's layout does not change MuJoCo's physics, so the dense one matches the CPU.
    """
    dense = model.opt.jacobian == mujoco.mjtJacobian.mjJAC_AUTO \
        and model.nv > WARP_SPARSE_ABOVE_NV
    torque = tables.control_mode == "torque"
    if not (torque or dense):
        return model
    copy = mujoco.MjModel.__copy__(model)
    if dense:
        copy.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    if torque:
        if not model.opt.disableactuator:
            raise AssertionError("the CPU env's torque mode no longer disables the servos")
        servo = tables.servo_ids
        if np.any(model.actuator_biasprm[servo, 0] != 0):
            raise AssertionError("a servo has a constant bias: zero gains would not switch it "
                                 "off")
        copy.actuator_gainprm[servo, 0] = 0.0
        copy.actuator_biasprm[servo, 1:3] = 0.0
        copy.opt.disableactuator = 0
    return copy
