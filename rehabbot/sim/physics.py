"""One control step of the simulated scene and the rules it must keep: ``frame_skip`` MuJoCo
steps (with the patient's muscle torques when a condition applies them,
:mod:`rehabbot.sim.patient_drive`, or, on MyoSuite's legs, the muscles' excitations,
:mod:`rehabbot.sim.muscle_drive`), the mechanical work done on the limb, and the safety rules
checked on the new state (:class:`LimbPhysics`, the env's physics step).

:class:`WorkMeter` integrates the mechanical work on the limb: the patient's (torque x joint
displacement over each physics step) and the robot's (cuff force on the limb x displacement of
the patient's cuff site), each also as positive work only, and their ratio.

The safety rules (:class:`SafetyMonitor`) end an episode:

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
``"cuff_force"``           the force in a cuff exceeds the ISO/TS 15066 quasi-static limit of
                           the body region it holds (hand 140 N, lower leg 130 N), or
                           ``cuff_force_limit_n`` when given (every cuff is checked)
``"unintended_contact"``   a robot geom touches the patient's body or the furniture (or,
                           with ``robots_collide``, another robot), deeper than
                           ``contact_tolerance_m``
=========================  ====================================================================

Rules are checked in this order; the first that fires is reported. Each rule's test and the
order are the laws of :mod:`rehabbot.laws.safety` (the batched env's too); the monitor reads
their readings from MuJoCo's data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.common.arrays import as_index
from rehabbot.laws import scalar
from rehabbot.laws.safety import (  # noqa: F401 (the rules and bounds, re-exported)
    BLOWUP_FORCE_N,
    BLOWUP_SPEED_RAD_S,
    RULE_NAMES,
    RULES,
    beyond_range,
    blown_up,
    fastest_speed_rad_s,
    first_rule,
    force_magnitude_n,
    over_force_limit,
    unintended_contact,
)
from rehabbot.laws.work import accumulate_work, assistance_ratio, cuff_work_j
from rehabbot.sim.conditions import PatientCondition
from rehabbot.sim.muscle_drive import MuscleDrive
from rehabbot.sim.muscles import MuscleMeter, limb_muscles
from rehabbot.sim.patient_drive import PatientDrive
from rehabbot.sim.scene import Scene

# MuJoCo's warnings for a diverging simulation; on each it resets the state to the model's.
UNSTABLE_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                     mujoco.mjtWarning.mjWARN_BADQACC)

# ISO/TS 15066 Table A.2, quasi-static contact force limits [N].
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


def cuff_force_limits_n(scene: Scene, thresholds: SafetyThresholds) -> np.ndarray:
    """The force limit [N] of each cuff (one per robot): ``cuff_force_limit_n`` when given,
    else the ISO/TS 15066 quasi-static limit of the body region under that cuff."""
    if thresholds.cuff_force_limit_n is not None:
        return np.full(len(scene.robots), float(thresholds.cuff_force_limit_n))
    return np.array([ISO_TS_15066_QUASI_STATIC_N[CUFF_BODY_REGION[h.limb.split("_")[0]]]
                     for h in scene.robots])


def _equality_rows(model: mujoco.MjModel, eq_id: int) -> int:
    """Constraint rows of an equality: 3 for a connect, 6 for a weld (force first), ..."""
    kind = model.eq_type[eq_id]
    if kind == mujoco.mjtEq.mjEQ_CONNECT:
        return 3
    if kind == mujoco.mjtEq.mjEQ_WELD:
        return 6
    return 1


class SafetyMonitor:
    """Reads the safety rules' readings from a ``MjData`` after each control step and decides
    with the rules' laws (:mod:`rehabbot.laws.safety`); ids resolved once.

    Every cuff is checked against its own limit: the force of cuff ``k`` is the magnitude of
    the first three rows (the force) of its equality constraint, which MuJoCo puts first in
    the constraint arrays, in the order of the equalities.
    """

    def __init__(self, scene: Scene, thresholds: SafetyThresholds,
                 robots_collide: bool = False) -> None:
        model = scene.model
        self.scene = scene
        self.thresholds = thresholds
        self.force_limits_n = cuff_force_limits_n(scene, thresholds)
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
        # With robots_collide, a contact between geoms of two different robots counts too.
        self._robot_of = np.full(model.ngeom, -1)
        for k, handle in enumerate(scene.robots):
            self._robot_of[handle.geom_ids] = k
        self._robots_collide = bool(robots_collide) and len(scene.robots) > 1
        # Constraint row where each cuff's force starts (equalities come first, in id order).
        first_row = np.cumsum([0, *(_equality_rows(model, e) for e in range(model.neq))])
        self._cuff_rows = tuple(int(first_row[h.equality_id]) for h in scene.robots)
        self._cuff_rows_needed = max(self._cuff_rows) + 3
        self._force_slices = tuple(slice(row, row + 3) for row in self._cuff_rows)
        self._no_forces_n = np.zeros(len(self._cuff_rows))
        self.step_forces_n = self._no_forces_n.copy()  # each cuff's force at the last check
        # The laws' readings as Python floats: the ranges and the force limits.
        self._rom_low_list = self._rom_low.tolist()
        self._rom_high_list = self._rom_high.tolist()
        self._force_limits_list = self.force_limits_n.tolist()
        self._single_cuff = len(self._cuff_rows) == 1
        warnings = sorted(int(w) for w in UNSTABLE_WARNINGS)
        first, last = warnings[0], warnings[-1]
        if warnings != list(range(first, last + 1)):
            raise AssertionError("MuJoCo's instability warnings are no longer contiguous")
        self._warning_slice = slice(first, last + 1)
        self._warning_numbers = np.zeros(last - first + 1, dtype=int)
        self._warnings0 = 0
        self._qpos = np.zeros(model.nq)
        self._qvel = np.zeros(model.nv)

    @property
    def rom_bounds_rad(self) -> tuple[np.ndarray, np.ndarray]:
        """The range-of-motion rule's bounds on every patient joint (copies): the joints'
        ranges widened by the tolerance."""
        return self._rom_low.copy(), self._rom_high.copy()

    @property
    def robot_geom_mask(self) -> np.ndarray:
        """Per geom, whether it is a robot's (a copy)."""
        return self._is_robot.copy()

    @property
    def other_geom_mask(self) -> np.ndarray:
        """Per geom, whether it is the patient's or the furniture's (a copy): a robot geom
        touching one of these deeper than the tolerance is unintended contact."""
        return self._is_other.copy()

    @property
    def robot_of_geom(self) -> np.ndarray:
        """Per geom, the robot it belongs to (-1: none), a copy."""
        return self._robot_of.copy()

    @property
    def robots_collide(self) -> bool:
        """Whether a contact between two robots' geoms is unintended contact."""
        return self._robots_collide

    @property
    def cuff_rows(self) -> tuple[int, ...]:
        """The first constraint row of each cuff's force (``data.efc_force[row:row + 3]``)."""
        return self._cuff_rows

    @property
    def force_limit_n(self) -> float:
        """The lowest cuff force limit [N] (the only one, with one robot)."""
        return float(self.force_limits_n.min())

    def bind(self, data: mujoco.MjData) -> None:
        """Cache views of ``data``'s arrays (again after a pickle round trip)."""
        self._qpos = data.qpos
        self._qvel = data.qvel
        self._warning_numbers = data.warning.number[self._warning_slice]

    def reset(self, data: mujoco.MjData) -> None:
        """Start an episode on ``data`` (its views are cached and its warnings counted)."""
        self.bind(data)
        self._warnings0 = sum(self._warning_numbers.tolist())

    def cuff_forces_n(self, data: mujoco.MjData) -> np.ndarray:
        """Magnitude of each cuff's constraint force [N] (0 when the cuffs are not active;
        :func:`~rehabbot.laws.safety.force_magnitude_n`)."""
        if data.ne < self._cuff_rows_needed:
            return self._no_forces_n.copy()
        efc = data.efc_force
        return np.array([force_magnitude_n(efc[rows].tolist(), scalar)
                         for rows in self._force_slices])

    def cuff_force_n(self, data: mujoco.MjData) -> float:
        """The largest cuff force [N] (the cuff's force, with one robot)."""
        return self._largest_n(self.cuff_forces_n(data))

    def _largest_n(self, forces_n: np.ndarray) -> float:
        return forces_n.item() if self._single_cuff else float(forces_n.max())

    def unstable(self, data: mujoco.MjData, force_n: float) -> bool:
        """Whether the simulation diverged since :meth:`reset`: MuJoCo warned of a bad
        qpos/qvel/qacc (and reset the state), or a joint speed or the cuff force ``force_n``
        blew up (:func:`~rehabbot.laws.safety.blown_up`). Out-of-bounds observations are
        checked by the env."""
        return sum(self._warning_numbers.tolist()) != self._warnings0 \
            or bool(blown_up(float(fastest_speed_rad_s(self._qvel)), force_n, scalar))

    def check_step(self, data: mujoco.MjData) -> tuple[str | None, float]:
        """The first rule that fires after a step and the largest cuff force [N]: the same as
        :meth:`cuff_force_n` then :meth:`check`, in one call (the env's per-step path)."""
        forces_n = self.step_forces_n = self.cuff_forces_n(data)
        force_n = self._largest_n(forces_n)
        return self._decide(data, forces_n, force_n), force_n

    def check(self, data: mujoco.MjData, force_n: float) -> str | None:
        """The first rule that fires for ``data`` (its largest cuff force ``force_n``, from
        :meth:`cuff_force_n`, judged by the instability rule; the cuff rule reads each
        cuff's force), or None. ``data`` must hold the state after ``mj_step`` or
        ``mj_forward``."""
        return self._decide(data, self.cuff_forces_n(data), force_n)

    def _decide(self, data: mujoco.MjData, forces_n: np.ndarray, force_n: float) -> str | None:
        """The readings of ``data`` decided by :func:`~rehabbot.laws.safety.first_rule`."""
        code = first_rule(
            self.unstable(data, force_n),
            bool(beyond_range(self._qpos[self._patient_qpos_adr].tolist(), self._rom_low_list,
                              self._rom_high_list)),
            bool(over_force_limit(forces_n.tolist(), self._force_limits_list)),
            data.ncon > 0 and bool(self._contact(data)))
        return RULE_NAMES[code]

    def _contact(self, data: mujoco.MjData) -> np.bool_:
        """The unintended-contact rule on ``data``'s contacts."""
        contact = data.contact
        geom = contact.geom
        return unintended_contact(self._is_robot[geom], self._is_other[geom], contact.dist,
                                  self.thresholds.contact_tolerance_m,
                                  self._robot_of[geom] if self._robots_collide else None)

    def violated_rom_joints(self, data: mujoco.MjData) -> list[str]:
        """Names of the patient joints beyond range (for diagnostics)."""
        q = data.qpos[self._patient_qpos_adr]
        bad = (q < self._rom_low) | (q > self._rom_high)
        return [n for n, b in zip(self.scene.patient_joint_names, bad, strict=True) if b]


class WorkMeter:
    """Mechanical work on the limb since :meth:`reset`: the robot's through the cuff and the
    patient's through its muscles [J]; positive work counted separately for the ratio."""

    def __init__(self, cuff_site_id: int, cuff_row: int) -> None:
        self._site = cuff_site_id  # the patient's side of the cuff
        self._row = cuff_row
        self._site_pos = np.zeros(3)
        self.reset_counts()

    def reset_counts(self) -> None:
        self.robot_j = 0.0
        self.robot_positive_j = 0.0
        self.patient_j = 0.0
        self.patient_positive_j = 0.0
        self._force: list[float] | None = None
        self._pos: list[float] = [0.0, 0.0, 0.0]

    def bind(self, data: mujoco.MjData) -> None:
        """Cache a view of the patient's cuff site position (again after a pickle round trip)."""
        self._site_pos = data.site_xpos[self._site]

    def reset(self, data: mujoco.MjData) -> None:
        """Start counting from the state in ``data`` (after ``mj_forward``)."""
        self.reset_counts()
        self.bind(data)
        self._pos = self._site_pos.tolist()

    def after_step(self, data: mujoco.MjData) -> None:
        """Account for the robot's work up to the state ``data`` held at the start of the last
        physics step (``mj_step`` leaves its positions and constraint forces there): the force
        of the step before times the displacement since, as
        :func:`rehabbot.laws.work.cuff_work_j` counts it."""
        pos = self._site_pos.tolist()
        force = self._force
        if force is not None:
            work = cuff_work_j(force, self._pos, pos)
            self.robot_j, self.robot_positive_j = accumulate_work(
                scalar, self.robot_j, self.robot_positive_j, work)
        self._pos = pos
        row = self._row
        efc = data.efc_force
        self._force = efc[row:row + 3].tolist() if len(efc) >= row + 3 else None

    def add_patient(self, work_j: float) -> None:
        """Add the patient's work of one physics step."""
        self.patient_j, self.patient_positive_j = accumulate_work(
            scalar, self.patient_j, self.patient_positive_j, work_j)

    @property
    def assistance_ratio(self) -> float:
        """Robot's positive work / all positive work on the limb; 1.0 until the patient has
        done positive work (the robot carries the limb):
        :func:`rehabbot.laws.work.assistance_ratio`."""
        return assistance_ratio(scalar, self.robot_positive_j, self.patient_positive_j)


class LimbPhysics:
    """One control step of the physics (:meth:`advance`): ``frame_skip`` physics steps, the
    condition's torques when it applies any (:class:`~rehabbot.sim.patient_drive.PatientDrive`,
    one-arm scenes; on MyoSuite's legs the muscles' excitations,
    :class:`~rehabbot.sim.muscle_drive.MuscleDrive`), the work on the limb counted after every
    physics step (one :class:`WorkMeter` per cuff), then the safety rules on the new state."""

    def __init__(self, scene: Scene, condition: PatientCondition, safety: SafetyMonitor,
                 ranges_rad: np.ndarray | None, frame_skip: int) -> None:
        self.safety = safety
        self.meters = tuple(WorkMeter(handle.patient_cuff_site_id, row)
                            for handle, row in zip(scene.robots, safety.cuff_rows, strict=True))
        self.meter = self.meters[0]
        self.frame_skip = frame_skip
        self.drive: PatientDrive | MuscleDrive | None = None
        # MyoSuite's legs: the exercised leg's muscles (None for the rigid patient).
        self.muscles = None
        if condition.acts and len(self.meters) != 1:
            raise ValueError("a patient condition that applies torques needs a one-arm scene")
        if len(scene.muscle_actuator_ids):
            side = scene.exercised_joints[0].rsplit("_", 1)[1]
            self.muscles = MuscleMeter(scene.model, limb_muscles(
                scene.model, scene.muscle_actuator_ids, side), count_active=condition.acts)
            if condition.acts:
                self.drive = MuscleDrive(scene, condition, ranges_rad, frame_skip)
        elif condition.acts:
            self.drive = PatientDrive(scene, condition, ranges_rad, frame_skip)
        self.torque_nm = self.drive.torque_nm if self.drive is not None else \
            np.zeros(len(scene.exercised_joints))

    def bind(self, data: mujoco.MjData) -> None:
        """Cache views of ``data``'s arrays (again after a pickle round trip)."""
        for meter in self.meters:
            meter.bind(data)
        self.safety.bind(data)

    def reset(self, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Start an episode from the state in ``data`` (after ``mj_forward``)."""
        self.safety.reset(data)
        for meter in self.meters:
            meter.reset(data)
        if self.drive is not None:
            self.drive.reset(data, rng)
        if self.muscles is not None:
            self.muscles.reset(data)

    def advance(self, model: mujoco.MjModel, data: mujoco.MjData, goal_rad: list[float] | None,
                rng: np.random.Generator) -> None:
        """The ``frame_skip`` physics steps of one control step (``goal_rad``: what an active
        patient aims for), the patient's torques and the work meters; the env then judges the
        new state with ``safety.check_step``."""
        if isinstance(self.drive, MuscleDrive):
            self.drive.run(model, data, goal_rad, rng, self.meter, self.muscles)
        elif self.drive is not None:
            self.drive.run(model, data, goal_rad, rng, self.meter)
        elif self.muscles is not None:
            after_step, count_muscles = self.meter.after_step, self.muscles.after_step
            for _ in range(self.frame_skip):
                mujoco.mj_step(model, data)
                after_step(data)
                count_muscles(data)
        elif len(self.meters) == 1:
            after_step = self.meter.after_step
            for _ in range(self.frame_skip):
                mujoco.mj_step(model, data)
                after_step(data)
        else:
            meters = self.meters
            for _ in range(self.frame_skip):
                mujoco.mj_step(model, data)
                for meter in meters:
                    meter.after_step(data)

    def info(self, data: mujoco.MjData) -> dict:
        """The patient's entries of the env's ``info``: the patient's torques on the exercised
        joints, the work of the patient and of the robot(s) [J], and the assistance ratio (the
        robots' share of the positive work; 1.0 until the patient does positive work); with
        muscles, their entries too (:data:`rehabbot.sim.muscles.INFO_KEYS`)."""
        if len(self.meters) == 1:
            meter = self.meter
            info = {"patient_torque_nm": self.torque_nm.copy(), "patient_work_j": meter.patient_j,
                    "robot_work_j": meter.robot_j, "assistance_ratio": meter.assistance_ratio}
            if self.muscles is not None:
                info.update(self.muscles.info(data))
                fatigue = getattr(self.drive, "fatigue", None)
                if fatigue is not None:  # the most fatigued muscle's fatigued fraction (MF)
                    info["muscle_fatigue"] = float(np.max(fatigue.fatigued))
            return info
        meters = self.meters
        patient_positive = sum(m.patient_positive_j for m in meters)
        robot_positive = sum(m.robot_positive_j for m in meters)
        ratio = assistance_ratio(scalar, robot_positive, patient_positive)
        return {"patient_torque_nm": self.torque_nm.copy(),
                "patient_work_j": sum(m.patient_j for m in meters),
                "robot_work_j": sum(m.robot_j for m in meters), "assistance_ratio": ratio}
