"""Safety rules that end an episode, and their thresholds.

=========================  ====================================================================
rule (``info`` name)       fires when
=========================  ====================================================================
``"instability"``          MuJoCo met a non-finite or huge state (its bad qpos/qvel/qacc
                           warnings: it then resets the state), a joint moved faster than
                           ``BLOWUP_SPEED_RAD_S``, the cuff force is non-finite or beyond
                           ``BLOWUP_FORCE_N`` (constraint blow-up), or an observation left
                           its bounds (checked by the env). Always ends the episode.
``"range_of_motion"``      a patient joint is more than ``rom_tolerance_deg`` beyond its
                           anatomical range (hyperextension)
``"cuff_force"``           the force in the cuff exceeds the ISO/TS 15066 quasi-static limit of
                           the strapped body region (hand 140 N, lower leg 130 N), or
                           ``cuff_force_limit_n`` when given
``"unintended_contact"``   a robot geom touches the patient's body or the furniture, deeper
                           than ``contact_tolerance_m``
=========================  ====================================================================

Rules are checked in this order; the first that fires is reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.control import as_index
from rehabbot.models.scene import Scene

RULES = ("instability", "range_of_motion", "cuff_force", "unintended_contact")

# MuJoCo's warnings for a diverging simulation; on each it resets the state to the model's.
UNSTABLE_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                     mujoco.mjtWarning.mjWARN_BADQACC)
# Speeds and forces no motion of these scenes reaches: random torques at the UR5e limits with
# the safety rules switched off peak at about 64 rad/s and 6.4 kN (benchmarks/soak.py).
BLOWUP_SPEED_RAD_S = 1000.0
BLOWUP_FORCE_N = 1.0e5

# ISO/TS 15066 Table A.2, quasi-static contact force limits [N] (domain-facts §4.1).
ISO_TS_15066_QUASI_STATIC_N: dict[str, float] = {
    "hands_and_fingers": 140.0,
    "lower_arms_and_wrists": 160.0,
    "upper_arms_and_elbows": 150.0,
    "thighs_and_knees": 220.0,
    "lower_legs": 130.0,
}
# Body region under the cuff: the hand for arm exercises, the shank (above the ankle) for legs.
CUFF_BODY_REGION: dict[str, str] = {"arm": "hands_and_fingers", "leg": "lower_legs"}


@dataclass(frozen=True)
class SafetyThresholds:
    """Thresholds of the safety rules (see the module docstring)."""

    rom_tolerance_deg: float = 2.0
    cuff_force_limit_n: float | None = None
    contact_tolerance_m: float = 0.002

    def __post_init__(self) -> None:
        for name in ("rom_tolerance_deg", "contact_tolerance_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}={value!r} must be a finite number >= 0")
        limit = self.cuff_force_limit_n
        if limit is not None and not (isinstance(limit, (int, float)) and math.isfinite(limit)
                                      and limit > 0):
            raise ValueError(f"cuff_force_limit_n={limit!r} must be a finite number > 0 or None")


def cuff_force_limit_n(scene: Scene, thresholds: SafetyThresholds) -> float:
    """The cuff force limit [N] for the scene's (first) cuffed limb."""
    if thresholds.cuff_force_limit_n is not None:
        return float(thresholds.cuff_force_limit_n)
    kind = scene.robots[0].limb.split("_")[0]
    return ISO_TS_15066_QUASI_STATIC_N[CUFF_BODY_REGION[kind]]


class SafetyMonitor:
    """Checks the rules on a ``MjData`` after each control step (ids resolved once)."""

    def __init__(self, scene: Scene, thresholds: SafetyThresholds) -> None:
        model = scene.model
        self.scene = scene
        self.thresholds = thresholds
        self.force_limit_n = cuff_force_limit_n(scene, thresholds)
        jnt = [model.joint(n).id for n in scene.patient_joint_names]
        tol = math.radians(thresholds.rom_tolerance_deg)
        self._patient_qpos_adr = as_index(scene.patient_qpos_adr)
        self._rom_low = model.jnt_range[jnt, 0] - tol
        self._rom_high = model.jnt_range[jnt, 1] + tol
        self._is_robot = np.zeros(model.ngeom, dtype=bool)
        self._is_robot[scene.robot_geom_ids] = True
        self._is_other = np.zeros(model.ngeom, dtype=bool)
        self._is_other[scene.patient_geom_ids] = True
        self._is_other[scene.furniture_geom_ids] = True
        self._eq_rows = 3  # a connect has 3 force rows; a weld's first 3 rows are its force
        self._warnings0 = 0
        self._qpos = np.zeros(model.nq)
        self._qvel = np.zeros(model.nv)
        self._speed = np.zeros(model.nv)

    def bind(self, data: mujoco.MjData) -> None:
        """Cache views of ``data``'s arrays (again after a pickle round trip)."""
        self._qpos = data.qpos
        self._qvel = data.qvel

    def reset(self, data: mujoco.MjData) -> None:
        """Start an episode on ``data`` (its views are cached and its warnings counted)."""
        self.bind(data)
        self._warnings0 = self._warning_count(data)

    @staticmethod
    def _warning_count(data: mujoco.MjData) -> int:
        warning = data.warning
        return sum(warning[w].number for w in UNSTABLE_WARNINGS)

    def cuff_force_n(self, data: mujoco.MjData) -> float:
        """Magnitude of the cuff's constraint force [N] (0 when the cuff is not active)."""
        if data.ne < self._eq_rows:
            return 0.0
        f = data.efc_force[:3]
        return math.sqrt(float(f @ f))

    def unstable(self, data: mujoco.MjData, force_n: float) -> bool:
        """Whether the simulation diverged since :meth:`reset`: MuJoCo warned of a bad
        qpos/qvel/qacc (and reset the state), a joint speed or the cuff force ``force_n`` is
        non-finite or beyond its blow-up bound. Out-of-bounds observations are checked by the
        env."""
        if self._warning_count(data) != self._warnings0:
            return True
        if not force_n <= BLOWUP_FORCE_N:  # also true for NaN
            return True
        speed = np.abs(self._qvel, out=self._speed)
        return not float(speed.max()) <= BLOWUP_SPEED_RAD_S

    def check(self, data: mujoco.MjData, force_n: float) -> str | None:
        """The first rule that fires for ``data`` (with its cuff force ``force_n``), or None."""
        if self.unstable(data, force_n):
            return "instability"
        q = self._qpos[self._patient_qpos_adr]
        if np.logical_or.reduce((q < self._rom_low) | (q > self._rom_high)):
            return "range_of_motion"
        if force_n > self.force_limit_n:
            return "cuff_force"
        if data.ncon:
            contact = data.contact
            geom = contact.geom
            robot = self._is_robot[geom]
            other = self._is_other[geom]
            hit = (robot[:, 0] & other[:, 1]) | (robot[:, 1] & other[:, 0])
            if hit.any() and (contact.dist[hit] < -self.thresholds.contact_tolerance_m).any():
                return "unintended_contact"
        return None

    def violated_rom_joints(self, data: mujoco.MjData) -> list[str]:
        """Names of the patient joints beyond range (for diagnostics)."""
        q = data.qpos[self._patient_qpos_adr]
        bad = (q < self._rom_low) | (q > self._rom_high)
        return [n for n, b in zip(self.scene.patient_joint_names, bad, strict=True) if b]
