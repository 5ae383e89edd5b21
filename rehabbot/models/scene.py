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

from rehabbot import statics
from rehabbot.kinematics import RobotIK, quat_from_mat
from rehabbot.models import patient as pt
from rehabbot.models import robot as ur

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

# Resting postures [deg] (joints not listed are 0).
_SEATED = {"hip_flexion_r": 90, "hip_flexion_l": 90, "knee_flexion_r": 90,
           "knee_flexion_l": 90, "hip_abduction_r": 4, "hip_abduction_l": 4}
_ARM_REST = {"shoulder_flexion": 15, "shoulder_abduction": 12, "elbow_flexion": 75}
_ARM_CUFFED = {"shoulder_flexion": 30, "shoulder_abduction": 12, "elbow_flexion": 70}
_SUPINE = {"knee_flexion_r": 10, "knee_flexion_l": 10, "hip_flexion_r": 5, "hip_flexion_l": 5,
           "hip_abduction_r": 5, "hip_abduction_l": 5, "ankle_dorsiflexion_r": -10,
           "ankle_dorsiflexion_l": -10, "elbow_flexion_r": 10, "elbow_flexion_l": 10,
           "shoulder_abduction_r": 10, "shoulder_abduction_l": 10}


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
    ``gains``                    robot joint impedance (:class:`robot.ImpedanceGains`)
    ``posture_hold_hz``          natural frequency of the posture-holding joint springs
    ``furniture_gap_m``          clearance between resting body and seat/bed at home
    ``initial_pose_deg``         overrides of the patient's home joint angles [deg]
    ``menagerie_dir``            optional local MuJoCo Menagerie checkout (``~`` expanded):
                                 draw the robots with its UR5e meshes (looks only;
                                 collisions stay on our capsules; nothing is downloaded)
    ============================ =========================================================
    """

    cuff: str = "connect"
    side: str | None = None
    posture: str | None = None
    base_reorientation_deg: float = 0.0
    timestep_s: float = 0.002
    gains: ur.ImpedanceGains = field(default_factory=ur.ImpedanceGains)
    posture_hold_hz: float = 6.0
    furniture_gap_m: float = 0.003
    initial_pose_deg: tuple[tuple[str, float], ...] = ()
    menagerie_dir: str | None = None

    def __post_init__(self) -> None:
        check_choice("cuff", self.cuff, CUFF_TYPES)
        if self.side is not None:
            check_choice("side", self.side, SIDES)
        if self.posture is not None:
            check_choice("posture", self.posture, POSTURES)
        _check_finite_range("base_reorientation_deg", self.base_reorientation_deg, -180.0, 180.0)
        _check_finite_range("timestep_s", self.timestep_s, 1e-4, 0.005)
        _check_finite_range("posture_hold_hz", self.posture_hold_hz, 0.5, 20.0)
        _check_finite_range("furniture_gap_m", self.furniture_gap_m, 0.0, 0.05)
        _check_pose(dict(self.initial_pose_deg), "initial_pose_deg")
        if self.menagerie_dir is not None:
            _check_menagerie_dir(self.menagerie_dir)


def _check_menagerie_dir(path) -> None:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"menagerie_dir={path!r} must be a path (str) or None")
    from rehabbot.models.menagerie import find_menagerie_ur5e  # optional, loaded on demand

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
        _check_finite_range(f"{what}[{name!r}]", value, low, high)


def check_choice(name: str, value, choices) -> None:
    """Raise ``ValueError`` naming ``value`` and the valid ``choices`` unless it is one."""
    if isinstance(value, bool) or value not in choices:
        raise ValueError(f"{name}={value!r} is not one of {list(choices)}")


def _check_finite_range(name: str, value, low: float, high: float) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value) \
            or not low <= value <= high:
        raise ValueError(f"{name}={value!r} must be a finite number in [{low}, {high}]")


def check_weight_level(level) -> int:
    """Return ``level`` as an int, or raise ``ValueError`` naming the valid levels."""
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) \
            or int(level) not in WEIGHT_LEVELS:
        raise ValueError(f"weight_level={level!r} is not one of {list(WEIGHT_LEVELS)}")
    return int(level)


@dataclass(frozen=True)
class RobotHandle:
    """Ids of one robot and its cuff (all resolved at build time)."""

    prefix: str
    limb: str
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    servo_ids: np.ndarray
    motor_ids: np.ndarray
    tool_site_id: int
    cuff_site_id: int
    patient_cuff_site_id: int
    base_body_id: int
    equality_id: int
    geom_ids: np.ndarray


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
    _scratch: mujoco.MjData | None = None

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
        _set_pose(self.model, home, pose_deg)
        error = _solve_robot_home(self.model, self._scratch_data(), self.robots, home,
                                  warm_start=True)
        if error > _IK_TOLERANCE_M:
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


# ----------------------------------------------------------------------------------------------
# Building
# ----------------------------------------------------------------------------------------------
def _limbs_for(preset: str, side: str | None) -> tuple[str, ...]:
    s = "l" if side == "left" else "r"
    return {
        "upper_right": ("arm_r",),
        "upper_left": ("arm_l",),
        "upper_bilateral": ("arm_r", "arm_l"),
        "hip": (f"leg_{s}",),
        "knee": (f"leg_{s}",),
    }[preset]


def _default_posture(preset: str) -> str:
    return "supine" if preset == "hip" else "seated"


def _home_pose_deg(posture: str, limbs: tuple[str, ...], options: SceneOptions) -> dict:
    pose = dict(_SEATED if posture == "seated" else _SUPINE)
    if posture == "seated":
        for s in ("r", "l"):
            arm = _ARM_CUFFED if f"arm_{s}" in limbs else _ARM_REST
            for joint, value in arm.items():
                pose[f"{joint}_{s}"] = value
    pose.update(dict(options.initial_pose_deg))
    return pose


def _yaw_quat(yaw_rad: float) -> np.ndarray:
    return np.array([math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


def _add_box(body, name, center, half, rgba) -> None:
    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=list(center),
                         size=list(half), rgba=rgba)
    geom.contype, geom.conaffinity = CONTYPE_FURNITURE, CONAFFINITY_FURNITURE


def _add_cylinder(body, name, p0, p1, radius, rgba) -> None:
    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CYLINDER, fromto=[*p0, *p1],
                         size=[radius, 0, 0], rgba=rgba)
    geom.contype, geom.conaffinity = CONTYPE_FURNITURE, CONAFFINITY_FURNITURE


# Exercised joints that the patient holds stiff (posture springs) in a preset: a straight-leg
# raise is done with the knee held extended; in seated knee exercises the thigh rests.
_HELD_BY_PATIENT: dict[tuple[str, str], tuple[str, ...]] = {
    ("hip", "supine"): ("knee_flexion",),
    ("hip", "seated"): ("knee_flexion",),
    ("knee", "seated"): ("hip_flexion", "hip_abduction"),
}
_WOOD = (0.55, 0.42, 0.30, 1.0)
_UPHOLSTERY = (0.30, 0.45, 0.50, 1.0)
_METAL = (0.45, 0.47, 0.50, 1.0)


def _add_room(spec: mujoco.MjSpec) -> None:
    spec.add_texture(name="floor_tex", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=256, height=256,
                     rgb1=[0.82, 0.80, 0.76], rgb2=[0.74, 0.72, 0.68])
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, width=256, height=256,
                     rgb1=[0.93, 0.95, 0.97], rgb2=[0.70, 0.76, 0.82])
    mat = spec.add_material(name="floor_mat", texrepeat=[8, 8], reflectance=0.05)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor_tex"
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=[4, 4, 0.05], material="floor_mat")
    floor.contype, floor.conaffinity = CONTYPE_FURNITURE, CONAFFINITY_FURNITURE
    spec.worldbody.add_light(name="key", pos=[1.5, -1.5, 3.0], dir=[-0.4, 0.4, -1.0],
                             diffuse=[0.7, 0.7, 0.7], castshadow=True)
    spec.worldbody.add_light(name="fill", pos=[-1.0, 1.5, 2.5], dir=[0.3, -0.5, -1.0],
                             diffuse=[0.35, 0.35, 0.35], castshadow=False)


def _lowest_z(model: mujoco.MjModel, data: mujoco.MjData, geom_id: int) -> float:
    """Lowest world z of a primitive geom at the current kinematics."""
    pos = data.geom_xpos[geom_id]
    mat = data.geom_xmat[geom_id].reshape(3, 3)
    size = model.geom_size[geom_id]
    gtype = model.geom_type[geom_id]
    if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
        return pos[2] - size[0]
    if gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return pos[2] - abs(mat[2, 2]) * size[1] - size[0]
    if gtype == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        return pos[2] - float(np.sqrt(np.sum((mat[2, :] * size) ** 2)))
    return pos[2] - float(np.sum(np.abs(mat[2, :]) * size[:3]))


def build_scene(preset: str, profile: pt.PatientProfile | None = None, weight_level: int = 0,
                **options) -> Scene:
    """Build a scene preset for ``profile`` at ``weight_level``; ``options`` are
    :class:`SceneOptions` fields. Raises ``ValueError`` naming any bad argument."""
    check_choice("preset", preset, tuple(PRESETS))
    profile = profile if profile is not None else pt.PatientProfile()
    if not isinstance(profile, pt.PatientProfile):
        raise ValueError(f"profile must be a PatientProfile, got {type(profile).__name__}")
    if "initial_pose_deg" in options and isinstance(options["initial_pose_deg"], dict):
        options["initial_pose_deg"] = tuple(sorted(options["initial_pose_deg"].items()))
    unknown = set(options) - set(SceneOptions.__dataclass_fields__)
    if unknown:
        raise ValueError(f"unknown scene option(s) {sorted(unknown)}; valid options: "
                         f"{sorted(SceneOptions.__dataclass_fields__)}")
    opts = SceneOptions(**options)
    level = check_weight_level(weight_level)
    posture = opts.posture or _default_posture(preset)
    if preset != "hip" and posture != _default_posture(preset):
        raise ValueError(f"posture={posture!r}: preset {preset!r} is "
                         f"{_default_posture(preset)} only; 'hip' offers {list(POSTURES)}")
    if preset.startswith("upper") and opts.side is not None:
        raise ValueError(f"side={opts.side!r} applies to 'hip' and 'knee' only; for the arms "
                         "choose the preset upper_right, upper_left or upper_bilateral")
    limbs = _limbs_for(preset, opts.side)
    pose_deg = _home_pose_deg(posture, limbs, opts)

    spec = mujoco.MjSpec()
    spec.modelname = f"rehabbot_{preset}"
    spec.compiler.degree = False
    spec.option.timestep = opts.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    _add_room(spec)

    # 1. Patient alone, to measure where the body rests.
    seg = pt.segment_table(profile)
    foot_clear = 0.06 * profile.height_m / 1.75 + opts.furniture_gap_m
    if posture == "seated":
        hip_z = foot_clear + seg["shank"].length_m + 0.05  # feet on a 5 cm leg rest
        torso_pos = np.array([0.0, 0.0, hip_z + seg["middle_trunk"].length_m
                              + seg["lower_trunk"].length_m])
        torso_quat = np.array([1.0, 0.0, 0.0, 0.0])
    else:
        bed_top = 0.62
        torso_pos = np.array([0.0, 0.0, bed_top + 0.2])  # refined below
        torso_quat = np.array([math.cos(-math.pi / 4), 0.0, math.sin(-math.pi / 4), 0.0])
    geometry = pt.add_patient(spec, spec.worldbody, profile, torso_pos, torso_quat, limbs)
    model0 = spec.compile()
    data0 = mujoco.MjData(model0)
    _set_pose(model0, data0.qpos, pose_deg)
    mujoco.mj_kinematics(model0, data0)

    patient_geoms = [g for g in range(model0.ngeom)
                     if model0.geom_contype[g] == pt.CONTYPE_PATIENT]

    def lowest(names: tuple[str, ...]) -> float:
        ids = [model0.geom(n).id for n in names]
        return min(_lowest_z(model0, data0, g) for g in ids)

    gap = opts.furniture_gap_m
    lift = np.zeros(3)
    if posture == "supine":
        # Lower the body so its lowest point rests `gap` above the bed top.
        low = min(_lowest_z(model0, data0, g) for g in patient_geoms)
        lift[2] = bed_top + gap - low
        torso_pos = torso_pos + lift
        spec.body("torso").pos = list(torso_pos)
    _add_furniture(spec, posture, profile, geometry, seg, torso_pos, lowest, gap,
                   bed_top=bed_top if posture == "supine" else None)

    # 2. Robots, placed from the patient's landmarks.
    for k, limb in enumerate(limbs):
        prefix = _robot_prefix(limbs, k)
        base_pos, base_yaw = _robot_base_pose(limb, posture, profile, seg, geometry, torso_pos,
                                              torso_quat)
        yaw = base_yaw + math.radians(opts.base_reorientation_deg)
        stand = spec.worldbody.add_body(name=f"{prefix}stand", pos=[base_pos[0], base_pos[1], 0])
        _add_cylinder(stand, f"{prefix}stand_column", (0, 0, 0.02), (0, 0, base_pos[2] - 0.01),
                      0.09, _METAL)
        _add_cylinder(stand, f"{prefix}stand_foot", (0, 0, 0.0), (0, 0, 0.03), 0.28, _METAL)
        _add_cylinder(stand, f"{prefix}stand_plate", (0, 0, base_pos[2] - 0.02),
                      (0, 0, base_pos[2]), 0.1, _METAL)
        robot_opts = ur.UR5eOptions(prefix=prefix, gains=opts.gains,
                                    menagerie_dir=opts.menagerie_dir)
        ur.add_ur5e(spec.worldbody, spec, robot_opts, pos=base_pos, quat=_yaw_quat(yaw))
        cuffed = pt.LIMB_BODIES[limb][1:]  # forearm+hand, or shank+foot
        for link in ("link4", "link5", "link6"):
            for body in cuffed:
                spec.add_exclude(bodyname1=f"{prefix}{link}", bodyname2=body)
        eq_type = mujoco.mjtEq.mjEQ_CONNECT if opts.cuff == "connect" else mujoco.mjtEq.mjEQ_WELD
        eq = spec.add_equality(name=f"{prefix}cuff", type=eq_type, objtype=mujoco.mjtObj.mjOBJ_SITE,
                               name1=f"{prefix}cuff", name2=f"cuff_{limb}")
        eq.solref = [0.01, 1.0]

    # 3. The patient's own effort on the exercised joints: weak, saturated at +-1 N·m.
    for limb in limbs:
        for name in pt.LIMB_EXERCISE_JOINTS[limb]:
            effort = spec.add_actuator(name=f"effort_{name}", target=name,
                                       trntype=mujoco.mjtTrn.mjTRN_JOINT)
            effort.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            effort.gainprm[0] = 1.0
            limit = pt.PATIENT_EFFORT_LIMIT_NM
            effort.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            effort.ctrlrange = [-limit, limit]
            effort.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            effort.forcerange = [-limit, limit]

    # Cameras look at the middle of the exercise: the shoulders, the hip or the knee; from the
    # exercised side (the right for the bilateral scene).
    side = 1.0 if len(limbs) == 1 and limbs[0].endswith("_l") else -1.0
    if preset.startswith("upper"):
        focus = torso_pos + np.array([0.25, 0.0, -0.2])
    elif posture == "supine":
        focus = data0.xpos[model0.body(f"thigh_{limbs[0][-1]}").id] + lift + [0.3, 0.0, 0.15]
    else:
        focus = data0.xpos[model0.body(f"shank_{limbs[0][-1]}").id] + lift + [0.1, 0.0, 0.1]
    _add_cameras(spec, focus, side)
    model = spec.compile()
    return _finish_scene(preset, profile, opts, posture, model, limbs, pose_deg, level)


def _robot_prefix(limbs: tuple[str, ...], k: int) -> str:
    return "" if len(limbs) == 1 else ("right_" if limbs[k].endswith("_r") else "left_")


def _set_pose(model: mujoco.MjModel, qpos: np.ndarray, pose_deg: dict) -> None:
    for name, value in pose_deg.items():
        qpos[model.joint(name).qposadr[0]] = math.radians(value)


def _add_furniture(spec, posture, profile, geometry, seg, torso_pos, lowest, gap, bed_top) -> None:
    """Chair (seat, backrest, legs) and leg rest under a seated body, or a bed under a supine
    one; resting surfaces sit ``gap`` below the body at home."""
    world = spec.worldbody
    if posture == "seated":
        rest_z = min(lowest(("thigh_r", "thigh_l")), lowest(("pelvis",)))
        seat_top = rest_z - gap
        hip_x = torso_pos[0]
        depth = 0.8 * seg["thigh"].length_m
        front = hip_x + depth - 0.12
        back = hip_x - geometry.torso_half_depth_m - 0.06
        half_w = 0.25
        _add_box(world, "chair_seat", ((front + back) / 2, 0, seat_top - 0.04),
                 ((front - back) / 2, half_w, 0.04), _UPHOLSTERY)
        back_x = torso_pos[0] - geometry.torso_half_depth_m - gap - 0.03
        _add_box(world, "chair_back", (back_x, 0, seat_top + 0.32), (0.03, half_w, 0.30),
                 _UPHOLSTERY)
        for i, (x, y) in enumerate(((front - 0.03, -0.22), (front - 0.03, 0.22),
                                    (back + 0.03, -0.22), (back + 0.03, 0.22))):
            _add_cylinder(world, f"chair_leg{i}", (x, y, 0), (x, y, seat_top - 0.08), 0.018,
                          _WOOD)
        knee_x = hip_x + seg["thigh"].length_m
        foot_len = seg["foot"].length_m
        rest_top = lowest(("foot_r", "foot_l")) - gap
        _add_box(world, "leg_rest", (knee_x + 0.35 * foot_len, 0, rest_top / 2),
                 (0.8 * foot_len, 0.3, rest_top / 2), _WOOD)
    else:
        length = profile.height_m + 0.25
        head_x = torso_pos[0] - 0.45 * profile.height_m
        center_x = head_x + length / 2 - 0.05
        _add_box(world, "bed", (center_x, 0, bed_top - 0.06), (length / 2, 0.38, 0.06),
                 _UPHOLSTERY)
        for i, (dx, y) in enumerate(((-1, -0.33), (-1, 0.33), (1, -0.33), (1, 0.33))):
            x = center_x + dx * (length / 2 - 0.06)
            _add_cylinder(world, f"bed_leg{i}", (x, y, 0), (x, y, bed_top - 0.12), 0.03, _METAL)


def _robot_base_pose(limb, posture, profile, seg, geometry, torso_pos, torso_quat):
    """Where the robot base stands (world) and its yaw: beside the limb, within easy reach."""
    side = -1.0 if limb.endswith("_r") else 1.0
    h_scale = profile.height_m / 1.75
    if limb.startswith("arm"):
        shoulder = torso_pos + (geometry.shoulder_r if side < 0 else geometry.shoulder_l)
        pos = shoulder + np.array([0.42, side * 0.52, -0.42]) * h_scale
        yaw = math.pi / 2 * (1 if side < 0 else -1)
        return pos, yaw
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, torso_quat)
    hip = torso_pos + rot.reshape(3, 3) @ (geometry.hip_r if side < 0 else geometry.hip_l)
    if posture == "seated":
        knee_x = hip[0] + seg["thigh"].length_m
        pos = np.array([knee_x + 0.55 * h_scale, hip[1] + side * 0.40 * h_scale,
                        hip[2] - 0.25 * h_scale])
        return pos, math.pi
    leg = seg["thigh"].length_m + seg["shank"].length_m
    pos = np.array([hip[0] + 0.45 * leg, hip[1] + side * 0.50 * h_scale, hip[2] + 0.15])
    return pos, math.pi / 2 * (1 if side < 0 else -1)


CAMERA_NAMES = ("overview", "front", "side")  # the fixed cameras of every scene


def _add_cameras(spec: mujoco.MjSpec, target: np.ndarray, side: float) -> None:
    """Three fixed cameras looking at ``target`` (world point): ``overview`` from the front on the
    exercised side and above, ``front``, and ``side`` (from the exercised side)."""
    views = dict(zip(CAMERA_NAMES, (np.array([1.5, 1.25 * side, 0.9]),
                                     np.array([2.0, 0.0, 0.35]),
                                     np.array([0.15, 2.0 * side, 0.3])), strict=True))
    up = np.array([0.0, 0.0, 1.0])
    for name, offset in views.items():
        forward = -offset / np.linalg.norm(offset)
        x_axis = np.cross(forward, up)
        x_axis /= np.linalg.norm(x_axis)
        y_axis = np.cross(x_axis, forward)
        spec.worldbody.add_camera(name=name, pos=list(target + offset),
                                  xyaxes=[*x_axis, *y_axis], fovy=50.0)


def _finish_scene(preset, profile, opts, posture, model, limbs, pose_deg, level) -> Scene:
    robots = []
    for k, limb in enumerate(limbs):
        p = _robot_prefix(limbs, k)
        joints = [model.joint(f"{p}{j}") for j in ur.JOINT_NAMES]
        base_id = model.body(f"{p}base").id
        robot_bodies = {base_id} | {model.body(f"{p}link{i}").id for i in range(1, 7)}
        robots.append(RobotHandle(
            prefix=p,
            limb=limb,
            qpos_adr=np.array([j.qposadr[0] for j in joints]),
            dof_adr=np.array([j.dofadr[0] for j in joints]),
            servo_ids=np.array([model.actuator(f"{p}{j}_servo").id for j in ur.JOINT_NAMES]),
            motor_ids=np.array([model.actuator(f"{p}{j}_motor").id for j in ur.JOINT_NAMES]),
            tool_site_id=model.site(f"{p}tool").id,
            cuff_site_id=model.site(f"{p}cuff").id,
            patient_cuff_site_id=model.site(f"cuff_{limb}").id,
            base_body_id=base_id,
            equality_id=model.equality(f"{p}cuff").id,
            geom_ids=np.array([g for g in range(model.ngeom)
                               if model.geom_bodyid[g] in robot_bodies]),
        ))
    exercised = tuple(j for limb in limbs for j in pt.LIMB_EXERCISE_JOINTS[limb])
    patient_joints = [model.joint(n) for n in pt.JOINT_NAMES]
    compliant = tuple(j for j in exercised if j.rsplit("_", 1)[0]
                      not in _HELD_BY_PATIENT.get((preset, posture), ()))
    posture_dofs = np.array([j.dofadr[0] for j in patient_joints if j.name not in compliant])
    limb_bodies = np.array([model.body(b).id for limb in limbs for b in pt.LIMB_BODIES[limb]])

    # Exercised joints: low-tone passive visco-elasticity about the home posture.
    for name in compliant:
        joint = model.joint(name)
        passive = pt.passive_for(name)
        model.jnt_stiffness[joint.id] = passive.stiffness_nm_per_rad
        model.dof_damping[joint.dofadr[0]] = passive.damping_nms_per_rad

    home = model.qpos0.copy()
    _set_pose(model, home, pose_deg)
    ik_data = mujoco.MjData(model)
    error = _solve_robot_home(model, ik_data, tuple(robots), home, warm_start=False)
    if error > _IK_TOLERANCE_M:
        raise ValueError(f"{preset}: the robot cannot reach the patient's cuff "
                         f"(IK error {error * 1000:.1f} mm); this scene does not support "
                         f"profile {profile} (README, Failure modes)")

    scene = Scene(
        preset=preset,
        profile=profile,
        options=opts,
        posture=posture,
        model=model,
        home_qpos=home,
        robots=tuple(robots),
        exercised_joints=exercised,
        exercised_qpos_adr=np.array([model.joint(n).qposadr[0] for n in exercised]),
        exercised_dof_adr=np.array([model.joint(n).dofadr[0] for n in exercised]),
        compliant_dof_adr=np.array([model.joint(n).dofadr[0] for n in compliant]),
        posture_dof_adr=posture_dofs,
        patient_qpos_adr=np.array([j.qposadr[0] for j in patient_joints]),
        patient_joint_names=pt.JOINT_NAMES,
        patient_actuator_ids=np.array([model.actuator(f"effort_{n}").id for n in exercised]),
        limb_body_ids=limb_bodies,
        nominal_body_mass=model.body_mass.copy(),
        nominal_body_inertia=model.body_inertia.copy(),
        camera_names=tuple(model.camera(i).name for i in range(model.ncam)),
        robot_geom_ids=np.concatenate([h.geom_ids for h in robots]),
        patient_geom_ids=np.array([g for g in range(model.ngeom)
                                   if model.geom_contype[g] == pt.CONTYPE_PATIENT]),
        furniture_geom_ids=np.array([g for g in range(model.ngeom)
                                     if model.geom_conaffinity[g] == CONAFFINITY_FURNITURE]),
    )
    _set_posture_springs(scene, ik_data)
    scene.set_weight_level(level)
    return scene


_IK_TOLERANCE_M = 1e-4


def _solve_robot_home(model: mujoco.MjModel, data: mujoco.MjData,
                      robots: tuple[RobotHandle, ...], qpos: np.ndarray,
                      warm_start: bool) -> float:
    """Write into ``qpos`` the robot angles that meet the patient's cuffs at the patient pose
    held in ``qpos``; return the worst IK pose error. Warm starts from the robot angles already
    in ``qpos`` and falls back to an elbow-up seed."""
    robot_ik = RobotIK(model)
    data.qpos[:] = qpos
    worst = 0.0
    for handle in robots:
        target_pos, target_quat = _cuff_target(model, data, handle)
        seeds = [qpos[handle.qpos_adr].copy()] if warm_start else []
        seeds.append(_ik_seed(model, data, handle))
        for seed in seeds:
            q, err = robot_ik.solve(data, handle, target_pos, target_quat, seed)
            if err <= _IK_TOLERANCE_M:
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
    """An elbow-up seed pointing the arm at the cuff (``data`` holds current kinematics of the
    base and the patient's cuff)."""
    base = data.xpos[handle.base_body_id]
    rot = data.xmat[handle.base_body_id].reshape(3, 3)
    rel = rot.T @ (data.site_xpos[handle.patient_cuff_site_id] - base)
    pan = math.atan2(rel[1], rel[0]) + math.pi  # at pan 0 the arm points along -x
    return np.array([pan, -1.9, 1.9, -1.6, -1.57, 0.0])


def _set_posture_springs(scene: Scene, data: mujoco.MjData) -> None:
    """Posture joints: critically damped springs at ``posture_hold_hz`` (gravity balanced
    later by :func:`balance_home`)."""
    model = scene.model
    data.qpos[:] = scene.home_qpos
    mujoco.mj_forward(model, data)
    mass_matrix = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass_matrix)
    omega = 2 * math.pi * scene.options.posture_hold_hz
    for dof in scene.posture_dof_adr:
        inertia = mass_matrix[dof, dof]
        joint_id = model.dof_jntid[dof]
        model.jnt_stiffness[joint_id] = inertia * omega**2
        model.dof_damping[dof] = 2.0 * inertia * omega


def balance_home(scene: Scene) -> np.ndarray:
    """Make the home state a static equilibrium; return the robots' servo setpoints (n, 6).

    Compliant joints rest at home (spring reference = home angle), so the cuffs carry the limb
    (:mod:`rehabbot.statics`); the robot setpoints are pre-loaded with that load and each
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
    model.qpos_spring[qadr] = scene.home_qpos[qadr] + (data.qfrc_bias[posture]
                                                       - load[posture]) / stiffness
    return statics.servo_setpoints(scene, data, load)
