"""Building a scene: the room, the furniture, the patient sized from a profile, and one or
two robots placed from the patient's landmarks and strapped to a hand or shin.

:func:`build_scene` returns a :class:`rehabbot.sim.scene.Scene` at its home state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.common.checks import check_choice
from rehabbot.sim import myo_arm
from rehabbot.sim import myo_patient as myo
from rehabbot.sim import patient as pt
from rehabbot.sim.handles import RobotHandle
from rehabbot.sim.robots import RobotBuildOptions, get_robot
from rehabbot.sim.scene import (
    CAMERA_NAMES,
    CONAFFINITY_FURNITURE,
    CONTYPE_FURNITURE,
    IK_TOLERANCE_M,
    POSTURES,
    PRESETS,
    Scene,
    SceneOptions,
    check_weight_level,
    coupled_joints,
    set_pose,
    solve_robot_home,
)

# Resting postures [deg] (joints not listed are 0).
_SEATED = {"hip_flexion_r": 90, "hip_flexion_l": 90, "knee_flexion_r": 90,
           "knee_flexion_l": 90, "hip_abduction_r": 4, "hip_abduction_l": 4}
_ARM_REST = {"shoulder_flexion": 15, "shoulder_abduction": 12, "elbow_flexion": 75}
_ARM_CUFFED = {"shoulder_flexion": 30, "shoulder_abduction": 12, "elbow_flexion": 70}
_SUPINE = {"knee_flexion_r": 10, "knee_flexion_l": 10, "hip_flexion_r": 5, "hip_flexion_l": 5,
           "hip_abduction_r": 5, "hip_abduction_l": 5, "ankle_dorsiflexion_r": -10,
           "ankle_dorsiflexion_l": -10, "elbow_flexion_r": 10, "elbow_flexion_l": 10,
           "shoulder_abduction_r": 10, "shoulder_abduction_l": 10}


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


# MyoLeg's feet, seated: relaxed in 15 deg of plantarflexion. Its toes reach 7 cm further
# forward than the rigid foot's; at the rigid foot's neutral ankle they came within 4 mm of the
# robot's forearm at home and struck it as the knee extended.
_MYO_SEATED_FEET = {"ankle_dorsiflexion_r": -15, "ankle_dorsiflexion_l": -15}


def _home_pose_deg(posture: str, limbs: tuple[str, ...], options: SceneOptions) -> dict:
    pose = dict(_SEATED if posture == "seated" else _SUPINE)
    if posture == "seated":
        for s in ("r", "l"):
            arm = _ARM_CUFFED if f"arm_{s}" in limbs else _ARM_REST
            for joint, value in arm.items():
                pose[f"{joint}_{s}"] = value
        if options.patient_model == "myo" and _myo_limb(limbs) == "legs":
            pose.update(_MYO_SEATED_FEET)
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
    if opts.patient_model == "myo":
        _check_myo_scene(preset, profile)
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
    myo_part = _myo_limb(limbs) if opts.patient_model == "myo" else None
    geometry = pt.add_patient(spec, spec.worldbody, profile, torso_pos, torso_quat, limbs,
                              legs=myo_part != "legs",
                              arms=("l",) if myo_part == "arm_r" else ("r", "l"))
    myo_legs = myo_right_arm = None
    if myo_part == "legs":
        # The hips' midpoint in the pelvis frame (the pelvis hangs middle_trunk below XYPH).
        hips = (geometry.hip_r + geometry.hip_l) / 2 + [0.0, 0.0, seg["middle_trunk"].length_m]
        myo_legs = myo.add_myo_legs(spec, spec.body("pelvis"), hips, pt.CONTYPE_PATIENT,
                                    pt.CONAFFINITY_PATIENT, limbs)
    elif myo_part == "arm_r":
        myo_right_arm = myo_arm.add_myo_arm(spec, spec.body("torso"), geometry.shoulder_r,
                                            pt.CONTYPE_PATIENT, pt.CONAFFINITY_PATIENT)
    parts = (_myo_arm_parts(limbs, myo_right_arm) if myo_right_arm is not None
             else _patient_parts(limbs, myo_legs))
    model0 = spec.compile()
    data0 = mujoco.MjData(model0)
    set_pose(model0, data0.qpos, pose_deg)
    mujoco.mj_kinematics(model0, data0)

    patient_geoms = [g for g in range(model0.ngeom)
                     if model0.geom_contype[g] == pt.CONTYPE_PATIENT]

    def lowest(names: tuple[str, ...]) -> float:
        ids = [model0.geom(g).id for n in names for g in parts.segment_geoms.get(n, (n,))]
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
    robot = get_robot(opts.robot)
    for k, limb in enumerate(limbs):
        prefix = _robot_prefix(limbs, k)
        base_pos, base_yaw = _robot_base_pose(limb, posture, profile, seg, geometry, torso_pos,
                                              torso_quat)
        # The robot's own correction of the default placement (mirrored for the left side),
        # never closer to the floor than its stand's plate allows.
        base_pos = base_pos + _outward_to_world(limb, robot.base_offset(_placement(limb, posture)))
        base_pos[2] = max(base_pos[2], MIN_BASE_HEIGHT_M)
        yaw = base_yaw + math.radians(opts.base_reorientation_deg)
        stand = spec.worldbody.add_body(name=f"{prefix}stand", pos=[base_pos[0], base_pos[1], 0])
        _add_cylinder(stand, f"{prefix}stand_column", (0, 0, 0.02), (0, 0, base_pos[2] - 0.01),
                      0.09, _METAL)
        _add_cylinder(stand, f"{prefix}stand_foot", (0, 0, 0.0), (0, 0, 0.03), 0.28, _METAL)
        _add_cylinder(stand, f"{prefix}stand_plate", (0, 0, base_pos[2] - 0.02),
                      (0, 0, base_pos[2]), 0.1, _METAL)
        robot.build(spec.worldbody, spec, RobotBuildOptions(prefix=prefix, gains=opts.gains),
                    pos=base_pos, quat=_yaw_quat(yaw))
        if opts.menagerie_dir is not None:  # optional looks, loaded on demand
            from rehabbot.sim.robots.menagerie import add_menagerie_visuals

            add_menagerie_visuals(spec, prefix, opts.menagerie_dir)
        cuffed = parts.cuffed_bodies[limb]  # forearm+hand, or shank+foot
        for link in robot.link_names[-robot.cuffed_links:]:  # the wrist, around the cuff
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
        focus = data0.xpos[model0.body(parts.body(f"thigh_{limbs[0][-1]}")).id] + lift \
            + [0.3, 0.0, 0.15]
    else:
        focus = data0.xpos[model0.body(parts.body(f"shank_{limbs[0][-1]}")).id] + lift \
            + [0.1, 0.0, 0.1]
    _add_cameras(spec, focus, side)
    model = spec.compile()
    return _finish_scene(preset, profile, opts, posture, model, limbs, pose_deg, level, parts)


@dataclass(frozen=True)
class _PatientParts:
    """The names a scene needs of its patient's body: the rigid patient's tables, or those of
    the rigid upper body with MyoSuite's legs."""

    joint_names: tuple[str, ...]
    limb_bodies: dict[str, tuple[str, ...]]
    cuffed_bodies: dict[str, tuple[str, ...]]
    segment_geoms: dict[str, tuple[str, ...]]
    segment_body: dict[str, str]
    muscle_names: tuple[str, ...]

    def body(self, segment: str) -> str:
        """The body bearing the rigid patient's ``segment`` (``"shank_r"``)."""
        return self.segment_body.get(segment, segment)


def _patient_parts(limbs: tuple[str, ...], legs: myo.MyoLegs | None) -> _PatientParts:
    if legs is None:
        return _PatientParts(
            joint_names=pt.JOINT_NAMES,
            limb_bodies={limb: pt.LIMB_BODIES[limb] for limb in limbs},
            cuffed_bodies={limb: pt.LIMB_BODIES[limb][1:] for limb in limbs},
            segment_geoms={}, segment_body={}, muscle_names=())
    rigid = tuple(n for n in pt.JOINT_NAMES if n not in pt.LEG_JOINT_NAMES)
    return _PatientParts(
        joint_names=rigid + legs.joint_names,
        limb_bodies={limb: legs.limb_bodies[limb] for limb in limbs},
        # Below the knee: the patella, tibia, talus, calcaneus and toes.
        cuffed_bodies={limb: legs.limb_bodies[limb][1:] for limb in limbs},
        segment_geoms=legs.segment_geoms, segment_body=legs.segment_body,
        muscle_names=legs.muscle_names)


def _myo_arm_parts(limbs: tuple[str, ...], arm: myo_arm.MyoArm) -> _PatientParts:
    """The rigid patient without its right arm, and MyoSuite's right arm."""
    rigid = tuple(n for n in pt.JOINT_NAMES
                  if not (n in pt.ARM_JOINT_NAMES and n.endswith("_r")))
    return _PatientParts(
        joint_names=rigid + arm.joint_names,
        limb_bodies={limb: arm.limb_bodies for limb in limbs},
        cuffed_bodies={limb: arm.cuffed_bodies for limb in limbs},
        segment_geoms={}, segment_body=arm.segment_body, muscle_names=arm.muscle_names)


# The presets a musculoskeletal patient is built for, and which of MyoSuite's models it seats.
MYO_PRESETS: dict[str, str] = {"hip": "legs", "knee": "legs", "upper_right": "arm_r"}


def _myo_limb(limbs: tuple[str, ...]) -> str:
    """Which of MyoSuite's models seats ``limbs``: ``"legs"`` or ``"arm_r"``."""
    return "arm_r" if limbs == ("arm_r",) else "legs"


def _check_myo_scene(preset: str, profile: pt.PatientProfile) -> None:
    """MyoSuite's legs (the leg presets) and right arm (upper_right); the default profile
    only."""
    if preset not in MYO_PRESETS:
        raise ValueError(f"patient_model='myo' is built for the presets {list(MYO_PRESETS)} "
                         f"only, not {preset!r}: MyoSuite's arm model is a right arm "
                         f"(myoarm_r), so the left and bilateral arm scenes are rigid only")
    myo.check_myo_profile(profile)


# The lowest a robot's base may sit above the floor: the stand's foot and plate [m].
MIN_BASE_HEIGHT_M = 0.05


def _robot_prefix(limbs: tuple[str, ...], k: int) -> str:
    return "" if len(limbs) == 1 else ("right_" if limbs[k].endswith("_r") else "left_")


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
    """Where the robot base stands (world) and its yaw: beside the limb, within easy reach.

    An arm's robot stands at a fixed offset from the shoulder: the robot's links keep their
    size whatever the patient's, so an offset scaled with the patient's height folded the
    robot into its own stand for short patients (a 1.60 m patient's elbow extension put the
    forearm 18 mm into the column) and past its cuff-force limit on the left arm."""
    side = -1.0 if limb.endswith("_r") else 1.0
    h_scale = profile.height_m / 1.75
    if limb.startswith("arm"):
        shoulder = torso_pos + (geometry.shoulder_r if side < 0 else geometry.shoulder_l)
        pos = shoulder + np.array([0.42, side * 0.52, -0.42])
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


def _placement(limb: str, posture: str) -> str:
    """The placement a robot's ``base_offset_m`` is keyed by: arm, seated or supine leg."""
    return "arm" if limb.startswith("arm") else f"leg_{posture}"


def _outward_to_world(limb: str, offset_m: np.ndarray) -> np.ndarray:
    """An offset (along x, outwards from the midline, up) on ``limb``'s side, in world axes
    (the patient's right is world -y)."""
    side = -1.0 if limb.endswith("_r") else 1.0
    return np.array([offset_m[0], side * offset_m[1], offset_m[2]])


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


def _finish_scene(preset, profile, opts, posture, model, limbs, pose_deg, level,
                  parts: _PatientParts) -> Scene:
    robot = get_robot(opts.robot)
    robots = []
    for k, limb in enumerate(limbs):
        p = _robot_prefix(limbs, k)
        joints = [model.joint(f"{p}{j}") for j in robot.joint_names]
        base_id = model.body(f"{p}base").id
        robot_bodies = {model.body(f"{p}{name}").id for name in robot.link_names}
        robots.append(RobotHandle(
            robot=robot,
            prefix=p,
            limb=limb,
            qpos_adr=np.array([j.qposadr[0] for j in joints]),
            dof_adr=np.array([j.dofadr[0] for j in joints]),
            servo_ids=np.array([model.actuator(f"{p}{j}_servo").id for j in robot.joint_names]),
            motor_ids=np.array([model.actuator(f"{p}{j}_motor").id for j in robot.joint_names]),
            tool_site_id=model.site(f"{p}tool").id,
            cuff_site_id=model.site(f"{p}cuff").id,
            patient_cuff_site_id=model.site(f"cuff_{limb}").id,
            base_body_id=base_id,
            equality_id=model.equality(f"{p}cuff").id,
            geom_ids=np.array([g for g in range(model.ngeom)
                               if model.geom_bodyid[g] in robot_bodies]),
        ))
    exercised = tuple(j for limb in limbs for j in pt.LIMB_EXERCISE_JOINTS[limb])
    patient_joints = [model.joint(n) for n in parts.joint_names]
    compliant = tuple(j for j in exercised if j.rsplit("_", 1)[0]
                      not in _HELD_BY_PATIENT.get((preset, posture), ()))
    posture_dofs = np.array([j.dofadr[0] for j in patient_joints if j.name not in compliant])
    limb_bodies = np.array([model.body(b).id for limb in limbs for b in parts.limb_bodies[limb]])

    # Exercised joints: low-tone passive visco-elasticity about the home posture (MyoSuite's
    # legs: their muscles' passive forces and their own joint damping instead).
    for name in compliant if opts.patient_model == "rigid" else ():
        joint = model.joint(name)
        passive = pt.passive_for(name)
        model.jnt_stiffness[joint.id] = passive.stiffness_nm_per_rad
        model.dof_damping[joint.dofadr[0]] = passive.damping_nms_per_rad

    home = model.qpos0.copy()
    set_pose(model, home, pose_deg)
    ik_data = mujoco.MjData(model)
    error = solve_robot_home(model, ik_data, tuple(robots), home, warm_start=False)
    if error > IK_TOLERANCE_M:
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
        patient_joint_names=parts.joint_names,
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
        muscle_actuator_ids=np.array([model.actuator(n).id for n in parts.muscle_names],
                                     dtype=int),
        coupled_joints=coupled_joints(model),
    )
    _set_posture_springs(scene, ik_data)
    scene.set_weight_level(level)
    return scene


def _set_posture_springs(scene: Scene, data: mujoco.MjData) -> None:
    """Posture joints: critically damped springs at ``posture_hold_hz`` (gravity balanced
    later by :func:`rehabbot.sim.scene.balance_home`)."""
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


