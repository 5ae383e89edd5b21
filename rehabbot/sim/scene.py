"""Scenes: the room, the furniture, the patient and one or two UR5e robots strapped to a limb.

``build_scene(preset, profile, weight_level, **options)`` returns a :class:`Scene` that holds
the compiled ``MjModel``, the home state and every id the environments need (resolved once, here).

Physics choices (all documented in ``docs/physics.md``):

* Timestep 2 ms, ``implicitfast`` integrator (joint damping and the servo's velocity term are
  integrated implicitly), elliptic friction cones.
* The cuff is an equality constraint between the robot's ``cuff`` site and the patient's
  ``cuff_<limb>`` site. ``"connect"`` (default) pins the positions and leaves rotation free, as
  a padded strap does; it couples 3 + 3 = 6 degrees of freedom without over-constraining the
  limb's 3 exercised hinges. ``"weld"`` also locks orientation.
* At home every body is in static equilibrium: the robot's servo setpoints are pre-loaded with
  the cuff force that carries the limb, and the posture joints (all patient hinges that are not
  exercised) are critically damped springs whose references balance gravity.
* Collision classes: robot (contype 1, conaffinity 0), patient (2, 1) and furniture (0, 3):
  the robot touches patient and furniture, the patient touches robot and furniture, nothing
  touches itself. The robot's wrist links never collide with the strapped segment and its
  neighbour (they are meant to be in contact through the cuff).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import mujoco
import numpy as np

from rehabbot.common.checks import check_choice, check_number
from rehabbot.sim import patient as pt
from rehabbot.sim import statics
from rehabbot.sim.handles import RobotHandle
from rehabbot.sim.ik import RobotIK, quat_from_mat
from rehabbot.sim.myo_patient import PATIENT_MODELS
from rehabbot.sim.robots import ROBOT_NAMES, ImpedanceGains, get_robot

PRESETS: dict[str, str] = {
    "upper_right": "one UR5e on a stand, strapped to the seated patient's right hand",
    "upper_left": "one UR5e on a stand, strapped to the seated patient's left hand",
    "upper_bilateral": "two UR5e, one strapped to each hand of the seated patient",
    "hip": "one UR5e strapped above the ankle; supine straight-leg raise (or seated)",
    "knee": "one UR5e strapped above the ankle; seated knee flexion/extension",
}
POSTURES = ("seated", "supine")
CUFF_TYPES = ("connect", "weld")
SIDES = ("right", "left")
WEIGHT_LEVELS = (0, 1, 2, 3, 4)
# Weight level l multiplies the exercised limb's segment masses (and inertias) by a factor.
# Arms: up to x2 (the paper's "weight of the arm the robot has to lift"). Legs: up to x1.4; a
# leg is already ~16 % of body mass (a x2 leg of a 75 kg patient is 24 kg), and at x1.4 a
# supine straight-leg raise held above the ankle stays inside the ISO/TS 15066 lower-leg
# force limit (130 N) with room for tracking errors.
WEIGHT_FACTORS_BY_LIMB: dict[str, tuple[float, ...]] = {
    "arm": (1.0, 1.25, 1.5, 1.75, 2.0),
    "leg": (1.0, 1.1, 1.2, 1.3, 1.4),
}
WEIGHT_FACTORS: tuple[float, ...] = WEIGHT_FACTORS_BY_LIMB["arm"]


def weight_factors(preset: str) -> tuple[float, ...]:
    """The mass factors of weight levels 0..4 for ``preset``'s exercised limb."""
    return WEIGHT_FACTORS_BY_LIMB["arm" if preset.startswith("upper") else "leg"]

CONTYPE_FURNITURE, CONAFFINITY_FURNITURE = 0, 3

CAMERA_NAMES = ("overview", "front", "side")  # the fixed cameras of every scene


@dataclass(frozen=True)
class SceneOptions:
    """Build options shared by every preset (SI units).

    ============================ =========================================================
    ``cuff``                     ``"connect"`` (position only, default) or ``"weld"``
    ``side``                     ``"right"`` (default)/``"left"``: leg of ``hip``/``knee``
    ``posture``                  ``"seated"``/``"supine"`` (``hip`` only); ``None`` = default
    ``base_reorientation_deg``   rotation of the robot base about its vertical axis
                                 (paper §2.1: 90 puts the pan axis' zero across the limb)
    ``timestep_s``               physics step (default 0.002 s)
    ``robot``                    the robot model (:data:`rehabbot.sim.robots.ROBOT_NAMES`)
    ``gains``                    robot joint impedance (:class:`ImpedanceGains`); ``None``:
                                 the robot's own
    ``posture_hold_hz``          natural frequency of the posture-holding joint springs
    ``furniture_gap_m``          clearance between resting body and seat/bed at home
    ``initial_pose_deg``         overrides of the patient's home joint angles [deg]
    ``menagerie_dir``            optional local MuJoCo Menagerie checkout (``~`` expanded):
                                 draw the robots with its UR5e meshes (looks only;
                                 collisions stay on our capsules; nothing is downloaded)
    ``patient_model``            ``"rigid"`` (default: rigid links, joint-level
                                 conditions) or ``"myo"`` (MyoSuite's musculoskeletal
                                 legs, :mod:`rehabbot.sim.myo_patient`; ``hip`` and
                                 ``knee`` only, default profile only)
    ============================ =========================================================
    """

    cuff: str = "connect"
    side: str | None = None
    posture: str | None = None
    base_reorientation_deg: float = 0.0
    timestep_s: float = 0.002
    robot: str = "ur5e"
    gains: ImpedanceGains | None = None
    posture_hold_hz: float = 6.0
    furniture_gap_m: float = 0.003
    initial_pose_deg: tuple[tuple[str, float], ...] = ()
    menagerie_dir: str | None = None
    patient_model: str = "rigid"

    def __post_init__(self) -> None:
        check_choice("cuff", self.cuff, CUFF_TYPES)
        check_choice("patient_model", self.patient_model, PATIENT_MODELS)
        check_choice("robot", self.robot, ROBOT_NAMES)
        if self.gains is not None:
            if not isinstance(self.gains, ImpedanceGains):
                raise ValueError(f"gains={self.gains!r} must be an ImpedanceGains or None")
            get_robot(self.robot).check_gains(self.gains)
        if self.side is not None:
            check_choice("side", self.side, SIDES)
        if self.posture is not None:
            check_choice("posture", self.posture, POSTURES)
        check_number("base_reorientation_deg", self.base_reorientation_deg, -180.0, 180.0)
        check_number("timestep_s", self.timestep_s, 1e-4, 0.005)
        check_number("posture_hold_hz", self.posture_hold_hz, 0.5, 20.0)
        check_number("furniture_gap_m", self.furniture_gap_m, 0.0, 0.05)
        _check_pose(dict(self.initial_pose_deg), "initial_pose_deg")
        if self.menagerie_dir is not None:
            if self.robot != "ur5e":
                raise ValueError(f"menagerie_dir={self.menagerie_dir!r}: the Menagerie meshes "
                                 f"draw the UR5e only, not robot={self.robot!r}")
            _check_menagerie_dir(self.menagerie_dir)


def _check_menagerie_dir(path) -> None:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"menagerie_dir={path!r} must be a path (str) or None")
    from rehabbot.sim.robots.menagerie import find_menagerie_ur5e  # optional, loaded on demand

    try:
        find_menagerie_ur5e(path)
    except FileNotFoundError as err:
        raise ValueError(f"menagerie_dir={str(path)!r}: {err}") from err


def _check_pose(pose_deg: dict, what: str = "pose_deg") -> None:
    for name, value in pose_deg.items():
        if name not in pt.JOINT_BY_NAME:
            raise ValueError(f"{what}: unknown patient joint {name!r}; "
                             f"valid joints: {list(pt.JOINT_NAMES)}")
        low, high = pt.JOINT_BY_NAME[name].range_deg
        check_number(f"{what}[{name!r}]", value, low, high)


def check_weight_level(level) -> int:
    """Return ``level`` as an int, or raise ``ValueError`` naming the valid levels."""
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) \
            or int(level) not in WEIGHT_LEVELS:
        raise ValueError(f"weight_level={level!r} is not one of {list(WEIGHT_LEVELS)}")
    return int(level)



@dataclass
class Scene:
    """A compiled scene and everything needed to reset and drive it."""

    preset: str
    profile: pt.PatientProfile
    options: SceneOptions
    posture: str
    model: mujoco.MjModel
    home_qpos: np.ndarray
    robots: tuple[RobotHandle, ...]
    exercised_joints: tuple[str, ...]
    exercised_qpos_adr: np.ndarray
    exercised_dof_adr: np.ndarray
    compliant_dof_adr: np.ndarray
    posture_dof_adr: np.ndarray
    patient_qpos_adr: np.ndarray
    patient_joint_names: tuple[str, ...]
    patient_actuator_ids: np.ndarray
    limb_body_ids: np.ndarray
    nominal_body_mass: np.ndarray
    nominal_body_inertia: np.ndarray
    camera_names: tuple[str, ...]
    robot_geom_ids: np.ndarray
    patient_geom_ids: np.ndarray
    furniture_geom_ids: np.ndarray
    weight_level: int = 0
    home_setpoints: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # The patient's muscles (MyoSuite's, patient_model="myo"; none for the rigid patient).
    muscle_actuator_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    # Joints that follow another through a polynomial joint equality (MyoLeg's knee).
    coupled_joints: tuple[CoupledJoint, ...] = ()
    _scratch: mujoco.MjData | None = None

    @property
    def patient_model(self) -> str:
        """``"rigid"`` or ``"myo"`` (:data:`rehabbot.sim.myo_patient.PATIENT_MODELS`)."""
        return self.options.patient_model

    def follow_coupled_joints(self, qpos: np.ndarray) -> None:
        """Set, in ``qpos``, the joints that follow another (:attr:`coupled_joints`) from the
        joint they follow; nothing for the rigid patient."""
        for coupled in self.coupled_joints:
            coupled.follow(qpos)

    @property
    def n_robot_joints(self) -> int:
        """Number of joints of the scene's robot(s) (every robot of a scene has as many)."""
        return self.robots[0].n_joints

    # -- weight levels ---------------------------------------------------------------------
    def set_weight_level(self, level: int) -> None:
        """Scale the exercised limb(s) to ``level`` and re-balance the home state.

        Inertia is scaled with mass (constant inertia/mass ratio); no recompilation.
        """
        level = check_weight_level(level)
        factor = weight_factors(self.preset)[level]
        ids = self.limb_body_ids
        self.model.body_mass[ids] = self.nominal_body_mass[ids] * factor
        self.model.body_inertia[ids] = self.nominal_body_inertia[ids] * factor
        scratch = self._scratch_data()
        scratch.qpos[:] = self.model.qpos0
        mujoco.mj_setConst(self.model, scratch)
        self.weight_level = level
        self.home_setpoints = balance_home(self)

    def set_home_pose(self, pose_deg: dict[str, float]) -> None:
        """Move the home state to another patient pose (joint name -> angle [deg]; joints not
        named keep their current home angle), without recompiling.

        The robots' home angles are re-solved by IK so the cuffs stay satisfied, and the home
        state is re-balanced. Raises ``ValueError`` for unknown joints, angles outside the
        joint's range, or a pose the robot cannot reach.
        """
        _check_pose(pose_deg)
        home = self.home_qpos.copy()
        set_pose(self.model, home, pose_deg)
        error = solve_robot_home(self.model, self._scratch_data(), self.robots, home,
                                  warm_start=True)
        if error > IK_TOLERANCE_M:
            raise ValueError(f"pose {pose_deg} puts the cuff out of the robot's reach "
                             f"(IK error {error * 1000:.1f} mm)")
        self.home_qpos = home
        self.home_setpoints = balance_home(self)

    def _scratch_data(self) -> mujoco.MjData:
        if self._scratch is None:
            self._scratch = mujoco.MjData(self.model)
        return self._scratch

    # -- state -----------------------------------------------------------------------------
    def reset_data(self, data: mujoco.MjData) -> None:
        """Put ``data`` at the home state: posture, robot setpoints, zero velocity, forward."""
        mujoco.mj_resetData(self.model, data)
        data.qpos[:] = self.home_qpos
        for k, handle in enumerate(self.robots):
            data.ctrl[handle.servo_ids] = self.home_setpoints[k]
            data.ctrl[handle.motor_ids] = 0.0
        mujoco.mj_forward(self.model, data)

    def make_data(self) -> mujoco.MjData:
        """A new ``MjData`` at the home state."""
        data = mujoco.MjData(self.model)
        self.reset_data(data)
        return data

    def cuff_errors_m(self, data: mujoco.MjData) -> np.ndarray:
        """Distance between each robot's cuff site and the patient's cuff site [m]."""
        return np.array([
            np.linalg.norm(data.site_xpos[h.cuff_site_id] - data.site_xpos[h.patient_cuff_site_id])
            for h in self.robots
        ])


def set_pose(model: mujoco.MjModel, qpos: np.ndarray, pose_deg: dict) -> None:
    """Write the joint angles ``pose_deg`` (name -> deg) into ``qpos``; the joints coupled to
    them by joint equalities follow."""
    for name, value in pose_deg.items():
        qpos[model.joint(name).qposadr[0]] = math.radians(value)
    for coupled in coupled_joints(model):
        coupled.follow(qpos)


@dataclass(frozen=True)
class CoupledJoint:
    """A joint that follows another through a MuJoCo joint equality:
    ``q1 - q1_ref = c0 + c1 (q2 - q2_ref) + ... + c4 (q2 - q2_ref)^4`` (the refs: ``qpos0``)."""

    qpos_adr: int
    leader_qpos_adr: int
    dof_adr: int
    leader_dof_adr: int
    coefficients: tuple[float, ...]
    reference: float
    leader_reference: float

    def follow(self, qpos: np.ndarray) -> None:
        """Set this joint in ``qpos`` from its leader's value there."""
        x = float(qpos[self.leader_qpos_adr]) - self.leader_reference
        value = 0.0
        for c in reversed(self.coefficients):
            value = value * x + c
        qpos[self.qpos_adr] = self.reference + value

    def slope(self, qpos: np.ndarray) -> float:
        """d(this joint) / d(its leader) at ``qpos``."""
        x = float(qpos[self.leader_qpos_adr]) - self.leader_reference
        value = 0.0
        for power in range(len(self.coefficients) - 1, 0, -1):
            value = value * x + power * self.coefficients[power]
        return value


def coupled_joints(model: mujoco.MjModel) -> tuple[CoupledJoint, ...]:
    """The active joint equalities of ``model`` that make one joint follow another (a joint
    equality without a second joint holds its joint still and is left out)."""
    found = []
    for eq in range(model.neq):
        if model.eq_type[eq] != mujoco.mjtEq.mjEQ_JOINT or not model.eq_active0[eq] \
                or model.eq_obj2id[eq] < 0:
            continue
        joint, leader = int(model.eq_obj1id[eq]), int(model.eq_obj2id[eq])
        adr, leader_adr = int(model.jnt_qposadr[joint]), int(model.jnt_qposadr[leader])
        found.append(CoupledJoint(adr, leader_adr, int(model.jnt_dofadr[joint]),
                                  int(model.jnt_dofadr[leader]),
                                  tuple(float(c) for c in model.eq_data[eq, :5]),
                                  float(model.qpos0[adr]), float(model.qpos0[leader_adr])))
    return tuple(found)


IK_TOLERANCE_M = 1e-4


def solve_robot_home(model: mujoco.MjModel, data: mujoco.MjData,
                      robots: tuple[RobotHandle, ...], qpos: np.ndarray,
                      warm_start: bool) -> float:
    """Write into ``qpos`` the robot angles that meet the patient's cuffs at the patient pose
    held in ``qpos``; return the worst IK pose error. Warm starts from the robot angles already
    in ``qpos`` and falls back to the robot's own seed(s), tried in order."""
    robot_ik = RobotIK(model)
    data.qpos[:] = qpos
    worst = 0.0
    for handle in robots:
        target_pos, target_quat = _cuff_target(model, data, handle)
        seeds = [qpos[handle.qpos_adr].copy()] if warm_start else []
        seeds.extend(np.atleast_2d(_ik_seed(model, data, handle)))
        for seed in seeds:
            q, err = robot_ik.solve(data, handle, target_pos, target_quat, seed)
            if err <= IK_TOLERANCE_M:
                break
        worst = max(worst, err)
        qpos[handle.qpos_adr] = q
        data.qpos[handle.qpos_adr] = q
    return worst


def _cuff_target(model, data, handle) -> tuple[np.ndarray, np.ndarray]:
    """World pose the robot's cuff site must take for the patient pose held in ``data``."""
    mujoco.mj_kinematics(model, data)
    sid = handle.patient_cuff_site_id
    return data.site_xpos[sid].copy(), quat_from_mat(data.site_xmat[sid])


def _ik_seed(model, data, handle) -> np.ndarray:
    """The robot's own IK seed, or seeds (one per row), for the cuff's position in its base
    frame (``data`` holds the current kinematics of the base and the patient's cuff)."""
    base = data.xpos[handle.base_body_id]
    rot = data.xmat[handle.base_body_id].reshape(3, 3)
    return handle.robot.ik_seed(rot.T @ (data.site_xpos[handle.patient_cuff_site_id] - base))


def balance_home(scene: Scene) -> np.ndarray:
    """Make the home state a static equilibrium; return the robots' servo setpoints (n, 6).

    Compliant joints rest at home (spring reference = home angle), so the cuffs carry the limb
    (:mod:`rehabbot.sim.statics`); the robot setpoints are pre-loaded with that load and each
    posture spring's reference is shifted to cancel the gravity and cuff torque on its joint.
    """
    model = scene.model
    data = scene._scratch_data()
    mujoco.mj_resetData(model, data)
    data.qpos[:] = scene.home_qpos
    model.qpos_spring[scene.patient_qpos_adr] = scene.home_qpos[scene.patient_qpos_adr]
    mujoco.mj_forward(model, data)
    load = statics.cuff_load_torque(scene, data)
    posture = scene.posture_dof_adr
    stiffness = model.jnt_stiffness[model.dof_jntid[posture]]
    qadr = model.jnt_qposadr[model.dof_jntid[posture]]
    # Gravity, and the muscles' passive forces (none on the rigid patient), on each joint;
    # a joint led by another (MyoLeg's knee) passes its share on to its leader.
    held = statics.reduced(scene, data, data.qfrc_bias - data.qfrc_actuator)
    model.qpos_spring[qadr] = scene.home_qpos[qadr] + (held[posture] - load[posture]) / stiffness
    return statics.servo_setpoints(scene, data, load)
