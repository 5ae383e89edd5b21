"""The cuffs and the contact rule of the batched env, read from one world's MJX data: each
cuff's force (the safety rule's and the observation's), the work meters (the robots' work on
the limb through the cuffs, ``WorkMeter`` of :mod:`rehabbot.sim.physics`) and unintended
contact.

MuJoCo Warp keeps one contact array for all worlds. The contact rule therefore reads the
contacts through the world's own constraint rows (``efc_type`` a contact, ``efc_id`` the
contact), which belong to this world only, whatever ``vmap`` does.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jp
import mujoco
import numpy as np

from rehabbot.batch.env_tables import EnvTables
from rehabbot.laws.safety import force_magnitude_n, unintended_contact
from rehabbot.laws.work import accumulate_work, cuff_work_j

CONTACT_CONSTRAINTS = (int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS),
                       int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
                       int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC))
METER_KEYS = ("meter_pos", "meter_force", "meter_has_force", "robot_work_j",
              "robot_positive_work_j")


class CuffReadings:
    """What one world's data says about the cuffs and contacts (module docstring), from the
    env's tables (every arm's cuff, the geoms' owners)."""

    def __init__(self, tables: EnvTables) -> None:
        self._tables = tables
        self._cuff_sites = jp.asarray(np.asarray(tables.patient_cuff_sites, np.int32))
        self._is_robot = jp.asarray(tables.is_robot_geom)
        self._is_other = jp.asarray(tables.is_other_geom)
        self._robot_of = jp.asarray(np.asarray(tables.robot_of_geom, np.int32))
        self._contact_types = jp.asarray(np.asarray(CONTACT_CONSTRAINTS, np.int32))

    def rows_force(self, data: Any) -> tuple[jax.Array, jax.Array]:
        """Each cuff's constraint force (arms, 3) and whether its rows exist (the work
        meters')."""
        impl = data._impl
        rows = self._tables.cuff_rows.tolist()
        force = jp.stack([impl.efc__force[row:row + 3] for row in rows])
        return force, jp.reshape(impl.nefc, ()) >= jp.asarray(rows, jp.int32) + 3

    def meter_start(self, data: Any) -> dict[str, jax.Array]:
        """The work meters at the start of an episode (``WorkMeter.reset``, one per cuff)."""
        zero = jp.zeros((), jp.float32)
        arms = self._tables.arms
        return {"meter_pos": data.site_xpos[self._cuff_sites],
                "meter_force": jp.zeros((arms, 3), jp.float32),
                "meter_has_force": jp.zeros(arms, bool),
                "robot_work_j": zero, "robot_positive_work_j": zero}

    def meter_after_step(self, meter: dict, data: Any) -> dict[str, jax.Array]:
        """``WorkMeter.after_step`` of each cuff (:func:`rehabbot.laws.work.cuff_work_j`): the
        force of the physics step before times the cuff site's displacement since; the robots'
        work and positive work are the cuffs' sums."""
        pos = data.site_xpos[self._cuff_sites]
        works = jp.where(meter["meter_has_force"], cuff_work_j(
            jp.unstack(meter["meter_force"], axis=-1), jp.unstack(meter["meter_pos"], axis=-1),
            jp.unstack(pos, axis=-1)), 0.0)
        works, positive = accumulate_work(jp, 0.0, 0.0, works)  # each cuff's meter
        force, has_force = self.rows_force(data)
        return {"meter_pos": pos, "meter_force": force, "meter_has_force": has_force,
                "robot_work_j": meter["robot_work_j"] + jp.sum(works),
                "robot_positive_work_j": meter["robot_positive_work_j"] + jp.sum(positive)}

    def forces(self, data: Any) -> jax.Array:
        """Each cuff's force [N] (arms,): 0 while the cuffs' constraints are not active, as
        the CPU reads them."""
        impl = data._impl
        rows = self._tables.cuff_rows.tolist()
        xyz = jp.stack([impl.efc__force[row:row + 3] for row in rows])  # (cuffs, 3)
        forces = force_magnitude_n((xyz[:, 0], xyz[:, 1], xyz[:, 2]), jp)
        return jp.where(jp.reshape(impl.ne, ()) >= max(rows) + 3, forces, 0.0)

    def touch(self, data: Any) -> jax.Array:
        """Whether a robot geom touches the patient or the furniture deeper than the
        tolerance: the contacts of this world's contact constraint rows."""
        impl = data._impl
        rows = jp.arange(impl.efc__type.shape[-1]) < jp.reshape(impl.nefc, ())
        contact_row = rows & jp.isin(impl.efc__type, self._contact_types)
        cid = jp.clip(impl.efc__id, 0, impl.contact__geom.shape[0] - 1)
        geom = impl.contact__geom[cid]
        owner = self._robot_of[geom] if self._tables.robots_collide else None
        return unintended_contact(self._is_robot[geom], self._is_other[geom],
                                  impl.contact__dist[cid], self._tables.contact_tolerance_m,
                                  owner, counted=contact_row)
