"""The parametric patient: a profile (height, mass, sex) becomes a humanoid body.

Topology is the DeepMind humanoid's, with clean anatomical joint axes: abdomen 3 hinges, each leg
hip 3 + knee 1 + ankle 2, each arm shoulder 2 + elbow 1; hands and feet rigid. That makes 21
hinges. Segment masses, lengths, centres of mass and radii of gyration come from de Leva (1996),
Table 4, with lengths scaled by stature; capsule radii come from each segment's mass and length at
the density of soft tissue, so a heavier patient also looks heavier.

Frames: in the patient's reference (standing) pose the body frame has x forward (anterior),
y to the patient's left and z up. Every joint angle is 0 in that pose; positive angles are the
clinical directions named by the joint (flexion, abduction, internal rotation, dorsiflexion,
inversion). ``docs/physics.md`` tabulates the numbers and their sources.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

SEXES: tuple[str, ...] = ("male", "female")
HEIGHT_RANGE_M = (1.20, 2.20)
MASS_RANGE_KG = (30.0, 200.0)
TISSUE_DENSITY_KG_M3 = 1050.0

# Collision classes shared by every model in the scene (see ``scene.py``): the patient touches
# the robot and the furniture but not itself.
CONTYPE_PATIENT, CONAFFINITY_PATIENT = 2, 1


@dataclass(frozen=True)
class PatientProfile:
    """Who is in the chair. Defaults: a 50th-percentile adult man (1.75 m, 75 kg)."""

    height_m: float = 1.75
    mass_kg: float = 75.0
    sex: str = "male"

    def __post_init__(self) -> None:
        for name, (low, high) in (("height_m", HEIGHT_RANGE_M), ("mass_kg", MASS_RANGE_KG)):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise ValueError(f"PatientProfile.{name} must be a number in [{low}, {high}], "
                                 f"got {value!r}")
            if not math.isfinite(value) or not low <= value <= high:
                raise ValueError(
                    f"PatientProfile.{name}={value!r} is outside the allowed range [{low}, {high}]"
                )
        if self.sex not in SEXES:
            raise ValueError(f"PatientProfile.sex={self.sex!r} is not one of {list(SEXES)}")


@dataclass(frozen=True)
class SegmentData:
    """One row of de Leva's Table 4: mass fraction, reference length [m], CoM fraction from the
    proximal end, radii of gyration (sagittal, transverse, longitudinal) as fractions of length."""

    mass_fraction: float
    length_ref_m: float
    com_fraction: float
    gyration: tuple[float, float, float]


REFERENCE_STATURE_M = {"male": 1.741, "female": 1.735}

# de Leva (1996) Table 4. Head and trunk sub-segments (upper,
# middle, lower trunk) are from the same table; their lengths are the male reference lengths for
# both sexes (the trunk's geometry is not tested, its masses are).
DE_LEVA: dict[str, dict[str, SegmentData]] = {
    "male": {
        "head": SegmentData(0.0694, 0.2033, 0.5976, (0.362, 0.376, 0.312)),
        "upper_trunk": SegmentData(0.1596, 0.1707, 0.2999, (0.716, 0.454, 0.659)),
        "middle_trunk": SegmentData(0.1633, 0.2155, 0.4502, (0.482, 0.383, 0.468)),
        "lower_trunk": SegmentData(0.1117, 0.1457, 0.6115, (0.615, 0.551, 0.587)),
        "upper_arm": SegmentData(0.0271, 0.2817, 0.5772, (0.285, 0.269, 0.158)),
        "forearm": SegmentData(0.0162, 0.2689, 0.4574, (0.276, 0.265, 0.121)),
        "hand": SegmentData(0.0061, 0.0862, 0.7900, (0.628, 0.513, 0.401)),
        "thigh": SegmentData(0.1416, 0.4222, 0.4095, (0.329, 0.329, 0.149)),
        "shank": SegmentData(0.0433, 0.4340, 0.4459, (0.255, 0.249, 0.103)),
        "foot": SegmentData(0.0137, 0.2581, 0.4415, (0.257, 0.245, 0.124)),
    },
    "female": {
        "head": SegmentData(0.0668, 0.2033, 0.5894, (0.330, 0.359, 0.318)),
        "upper_trunk": SegmentData(0.1545, 0.1707, 0.2077, (0.746, 0.502, 0.718)),
        "middle_trunk": SegmentData(0.1465, 0.2155, 0.4512, (0.433, 0.354, 0.415)),
        "lower_trunk": SegmentData(0.1247, 0.1457, 0.4920, (0.433, 0.402, 0.444)),
        "upper_arm": SegmentData(0.0255, 0.2751, 0.5754, (0.278, 0.260, 0.148)),
        "forearm": SegmentData(0.0138, 0.2643, 0.4559, (0.261, 0.257, 0.094)),
        "hand": SegmentData(0.0056, 0.0780, 0.7474, (0.531, 0.454, 0.335)),
        "thigh": SegmentData(0.1478, 0.3685, 0.3612, (0.369, 0.364, 0.162)),
        "shank": SegmentData(0.0481, 0.4323, 0.4416, (0.271, 0.267, 0.093)),
        "foot": SegmentData(0.0129, 0.2283, 0.4014, (0.299, 0.279, 0.139)),
    },
}
LIMB_SEGMENTS = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")


@dataclass(frozen=True)
class Segment:
    """A segment sized for one profile (SI units)."""

    name: str
    mass_kg: float
    length_m: float
    com_from_proximal_m: float
    radius_of_gyration_m: tuple[float, float, float]  # sagittal, transverse, longitudinal

    @property
    def capsule_radius_m(self) -> float:
        """Radius of a cylinder of tissue with this segment's mass and length."""
        return math.sqrt(self.mass_kg / (TISSUE_DENSITY_KG_M3 * math.pi * self.length_m))


def segment_table(profile: PatientProfile) -> dict[str, Segment]:
    """Every de Leva segment for ``profile``; all masses sum to the profile mass."""
    rows = DE_LEVA[profile.sex]
    scale = profile.height_m / REFERENCE_STATURE_M[profile.sex]
    table = {}
    for name, row in rows.items():
        length = row.length_ref_m * scale
        table[name] = Segment(
            name=name,
            mass_kg=row.mass_fraction * profile.mass_kg,
            length_m=length,
            com_from_proximal_m=row.com_fraction * length,
            radius_of_gyration_m=tuple(g * length for g in row.gyration),
        )
    return table


def mass_fractions_total(sex: str) -> float:
    """Sum of de Leva's mass fractions over the whole body (both sides) for ``sex``."""
    rows = DE_LEVA[sex]
    bilateral = set(LIMB_SEGMENTS)
    return sum(r.mass_fraction * (2 if n in bilateral else 1) for n, r in rows.items())


@dataclass(frozen=True)
class PatientJoint:
    """A hinge of the patient: name, body, axis (body frame), anatomical range [deg]."""

    name: str
    body: str
    axis: tuple[float, float, float]
    range_deg: tuple[float, float]


def _side_sign(side: str) -> float:
    return -1.0 if side == "r" else 1.0


def joint_table() -> tuple[PatientJoint, ...]:
    """The 21 hinges with anatomical ranges (AAOS / Norkin & White).

    Axes are chosen so positive angles are flexion, abduction, internal rotation, dorsiflexion
    and inversion on both sides.
    """
    joints = [
        PatientJoint("abdomen_rotation", "lower_waist", (0, 0, 1), (-45, 45)),
        PatientJoint("abdomen_flexion", "lower_waist", (0, -1, 0), (-30, 80)),
        PatientJoint("abdomen_lateral", "pelvis", (1, 0, 0), (-35, 35)),
    ]
    for side in ("r", "l"):
        s = _side_sign(side)
        joints += [
            PatientJoint(f"hip_flexion_{side}", f"thigh_{side}", (0, -1, 0), (-30, 120)),
            PatientJoint(f"hip_abduction_{side}", f"thigh_{side}", (s, 0, 0), (-30, 45)),
            PatientJoint(f"hip_rotation_{side}", f"thigh_{side}", (0, 0, -s), (-45, 45)),
            PatientJoint(f"knee_flexion_{side}", f"shank_{side}", (0, 1, 0), (0, 135)),
            PatientJoint(f"ankle_dorsiflexion_{side}", f"foot_{side}", (0, -1, 0), (-50, 20)),
            PatientJoint(f"ankle_inversion_{side}", f"foot_{side}", (-s, 0, 0), (-20, 35)),
        ]
    for side in ("r", "l"):
        s = _side_sign(side)
        joints += [
            PatientJoint(f"shoulder_flexion_{side}", f"upper_arm_{side}", (0, -1, 0), (-60, 180)),
            PatientJoint(f"shoulder_abduction_{side}", f"upper_arm_{side}", (s, 0, 0), (-30, 180)),
            PatientJoint(f"elbow_flexion_{side}", f"forearm_{side}", (0, -1, 0), (0, 150)),
        ]
    return tuple(joints)


JOINTS: tuple[PatientJoint, ...] = joint_table()
JOINT_NAMES: tuple[str, ...] = tuple(j.name for j in JOINTS)
JOINT_BY_NAME: dict[str, PatientJoint] = {j.name: j for j in JOINTS}
# The hinges of the legs (hip, knee, ankle of both sides).
LEG_JOINT_NAMES: tuple[str, ...] = tuple(j.name for j in JOINTS
                                         if j.body.rsplit("_", 1)[0] in ("thigh", "shank", "foot"))
# The hinges of the arms (shoulder and elbow of both sides).
ARM_JOINT_NAMES: tuple[str, ...] = tuple(j.name for j in JOINTS
                                         if j.body.rsplit("_", 1)[0] in ("upper_arm", "forearm"))

# Segments of each limb, proximal to distal (weight levels scale these).
LIMB_BODIES: dict[str, tuple[str, ...]] = {
    "arm_r": ("upper_arm_r", "forearm_r", "hand_r"),
    "arm_l": ("upper_arm_l", "forearm_l", "hand_l"),
    "leg_r": ("thigh_r", "shank_r", "foot_r"),
    "leg_l": ("thigh_l", "shank_l", "foot_l"),
}
# The three exercised (compliant) joints of each limb, in observation order.
LIMB_EXERCISE_JOINTS: dict[str, tuple[str, ...]] = {
    "arm_r": ("shoulder_flexion_r", "shoulder_abduction_r", "elbow_flexion_r"),
    "arm_l": ("shoulder_flexion_l", "shoulder_abduction_l", "elbow_flexion_l"),
    "leg_r": ("hip_flexion_r", "hip_abduction_r", "knee_flexion_r"),
    "leg_l": ("hip_flexion_l", "hip_abduction_l", "knee_flexion_l"),
}


@dataclass(frozen=True)
class PassiveJoint:
    """Passive visco-elasticity of an exercised joint (about its resting posture)."""

    stiffness_nm_per_rad: float
    damping_nms_per_rad: float


# Relaxed, low-tone joints: the robot carries the limb. Elbow damping 0.5 N·m·s/rad as in
# MyoSuite's elbow; stiffness well under the <= 20 N·m/rad of an active elbow (Bennett et al. 1992).
EXERCISED_PASSIVE: dict[str, PassiveJoint] = {
    "shoulder_flexion": PassiveJoint(2.0, 0.8),
    "shoulder_abduction": PassiveJoint(2.0, 0.8),
    "elbow_flexion": PassiveJoint(1.0, 0.5),
    "hip_flexion": PassiveJoint(4.0, 2.0),
    "hip_abduction": PassiveJoint(4.0, 2.0),
    "knee_flexion": PassiveJoint(3.0, 1.0),
}
PATIENT_EFFORT_LIMIT_NM = 1.0
# The leg cuff sits on the distal shin, this fraction of the shank length below the knee.
LEG_CUFF_FRACTION = 0.75


def passive_for(joint_name: str) -> PassiveJoint:
    """Passive properties of an exercised joint, looked up by its side-less name."""
    return EXERCISED_PASSIVE[joint_name.rsplit("_", 1)[0]]


def _inertia_diag(seg: Segment, long_axis: int) -> np.ndarray:
    """Principal moments [kg m^2] with the longitudinal radius on ``long_axis`` (0=x, 2=z)."""
    sag, trans, lon = seg.radius_of_gyration_m
    m = seg.mass_kg
    if long_axis == 2:  # hangs along z: sagittal motion rotates about y, frontal about x
        return m * np.array([trans**2, sag**2, lon**2])
    return m * np.array([lon**2, sag**2, trans**2])  # foot: long axis x


def _combine(parts: list[tuple[float, np.ndarray, np.ndarray]]) -> tuple[float, np.ndarray,
                                                                         np.ndarray]:
    """Lump (mass, com, principal inertia) parts with aligned axes into one inertial."""
    mass = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / mass
    inertia = np.zeros(3)
    for m, c, inert in parts:
        r = c - com
        inertia += inert + m * np.array([r[1] ** 2 + r[2] ** 2, r[0] ** 2 + r[2] ** 2,
                                         r[0] ** 2 + r[1] ** 2])
    return mass, com, inertia


def _set_inertial(body: mujoco.MjsBody, mass: float, com, inertia) -> None:
    body.explicitinertial = True
    body.mass = float(mass)
    body.ipos = [float(c) for c in com]
    body.inertia = [float(i) for i in inertia]


_SKIN = (0.87, 0.72, 0.60, 1.0)
_CLOTH = (0.35, 0.42, 0.55, 1.0)


def _capsule(body, name, p0, p1, radius, rgba=_SKIN):
    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[*p0, *p1],
                         size=[radius, 0, 0], rgba=rgba)
    geom.contype, geom.conaffinity = CONTYPE_PATIENT, CONAFFINITY_PATIENT
    return geom


def _cuff_quat(side_sign: float, limb: str) -> np.ndarray:
    """Orientation of the cuff frame on a limb segment; its z axis is the robot's approach
    direction into the limb. Arms: from the lateral side, x distal along the forearm. Legs:
    from the front of the shin, x proximal along the shank."""
    if limb == "arm":
        x_axis, z_axis = np.array([0.0, 0.0, -1.0]), np.array([0.0, -side_sign, 0.0])
    else:
        x_axis, z_axis = np.array([0.0, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0])
    y_axis = np.cross(z_axis, x_axis)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).reshape(9))
    return quat


def _ellipsoid(body, name, pos, half_sizes, rgba=_CLOTH):
    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, pos=list(pos),
                         size=list(half_sizes), rgba=rgba)
    geom.contype, geom.conaffinity = CONTYPE_PATIENT, CONAFFINITY_PATIENT
    return geom


def _add_leg(pelvis: mujoco.MjsBody, side: str, seg: dict[str, Segment], pelvis_length_m: float,
             hip_y: float, height_m: float, cuff_limbs: tuple[str, ...]) -> None:
    """One leg, hanging along -z from its hip joint centre (thigh, shank, foot)."""
    s = _side_sign(side)
    h = height_m
    thigh_s, shank_s, foot_s = seg["thigh"], seg["shank"], seg["foot"]
    thigh = pelvis.add_body(name=f"thigh_{side}", pos=[0, s * hip_y, -pelvis_length_m])
    _set_inertial(thigh, thigh_s.mass_kg, [0, 0, -thigh_s.com_from_proximal_m],
                  _inertia_diag(thigh_s, 2))
    r = thigh_s.capsule_radius_m
    _capsule(thigh, f"thigh_{side}", (0, 0, -r * 0.6), (0, 0, -thigh_s.length_m + r * 0.3), r,
             _CLOTH)
    shank = thigh.add_body(name=f"shank_{side}", pos=[0, 0, -thigh_s.length_m])
    _set_inertial(shank, shank_s.mass_kg, [0, 0, -shank_s.com_from_proximal_m],
                  _inertia_diag(shank_s, 2))
    r = shank_s.capsule_radius_m
    _capsule(shank, f"shank_{side}", (0, 0, -r * 0.5), (0, 0, -shank_s.length_m + r * 0.5), r,
             _CLOTH)
    if f"leg_{side}" in cuff_limbs:
        cuff_z = -LEG_CUFF_FRACTION * shank_s.length_m
        shank.add_site(name=f"cuff_leg_{side}", pos=[0, 0, cuff_z],
                       quat=list(_cuff_quat(s, "leg")), size=[0.015, 0, 0],
                       rgba=(0.2, 0.8, 0.4, 1))
    # Foot: ankle joint centre at the end of the shank; the foot points forward (+x) with
    # its heel just behind the ankle.
    foot = shank.add_body(name=f"foot_{side}", pos=[0, 0, -shank_s.length_m])
    heel_x = -0.25 * foot_s.length_m
    foot_h = 0.045 * h / 1.75
    _set_inertial(foot, foot_s.mass_kg, [heel_x + foot_s.com_from_proximal_m, 0, -foot_h],
                  _inertia_diag(foot_s, 0))
    r = 0.35 * foot_h + 0.012
    _capsule(foot, f"foot_{side}", (heel_x + r, 0, -foot_h),
             (heel_x + foot_s.length_m - r, 0, -foot_h), r, (0.25, 0.25, 0.28, 1))


@dataclass(frozen=True)
class PatientGeometry:
    """Landmarks of the built body in the patient's root (torso) frame [m]."""

    shoulder_r: np.ndarray
    shoulder_l: np.ndarray
    hip_r: np.ndarray
    hip_l: np.ndarray
    torso_half_depth_m: float


def add_patient(spec: mujoco.MjSpec, parent: mujoco.MjsBody, profile: PatientProfile,
                pos, quat, cuff_limbs: tuple[str, ...], legs: bool = True,
                arms: tuple[str, ...] = ("r", "l")) -> PatientGeometry:
    """Add the patient under ``parent``; the torso is welded to it (no free joint).

    ``cuff_limbs`` (e.g. ``("arm_r",)``) get a ``cuff_<limb>`` site where the robot's cuff
    straps on: the hand's centre for an arm, just above the malleoli for a leg.
    ``legs=False`` builds no legs (the body ends at the pelvis, where another model's legs
    attach: :mod:`rehabbot.sim.myo_patient`); ``arms`` names the sides whose arms are built
    (another model's arm attaches at the other shoulder: :mod:`rehabbot.sim.myo_arm`).
    Joint stiffness, damping and spring references are set later by the scene, which knows the
    posture and which joints are exercised.
    """
    seg = segment_table(profile)
    h = profile.height_m
    head, upt, mpt, lpt = seg["head"], seg["upper_trunk"], seg["middle_trunk"], seg["lower_trunk"]

    # Landmarks along the trunk (z up from the hip joint centres' midpoint, MIDH).
    z_omph = lpt.length_m
    z_xyph = z_omph + mpt.length_m
    z_cerv = z_xyph + upt.length_m
    shoulder_y = 0.105 * h
    hip_y = 0.05 * h
    z_shoulder = z_cerv - 0.03 * h

    trunk_width = shoulder_y * 0.85
    torso_depth = math.sqrt(upt.mass_kg / (TISSUE_DENSITY_KG_M3 * math.pi * upt.length_m))

    # --- torso (upper trunk + head), welded to the chair or bed: frame at XYPH.
    torso = parent.add_body(name="torso", pos=list(pos), quat=list(quat))
    head_com = np.array([0.0, 0.0, z_cerv + head.length_m - head.com_from_proximal_m - z_xyph])
    upt_com = np.array([0.0, 0.0, z_cerv - upt.com_from_proximal_m - z_xyph])
    mass, com, inertia = _combine([
        (head.mass_kg, head_com, _inertia_diag(head, 2)),
        (upt.mass_kg, upt_com, _inertia_diag(upt, 2)),
    ])
    _set_inertial(torso, mass, com, inertia)
    top = z_cerv - z_xyph
    chest_depth = 0.8 * torso_depth
    _ellipsoid(torso, "torso_chest", (0, 0, top * 0.5), (chest_depth, trunk_width, top * 0.6))
    _capsule(torso, "torso_shoulders", (0, -(shoulder_y - 0.04), z_shoulder - z_xyph),
             (0, shoulder_y - 0.04, z_shoulder - z_xyph), 0.055, _CLOTH)
    _capsule(torso, "neck", (0, 0, top), (0, 0, top + 0.05), 0.05)
    head_r = 0.44 * head.length_m
    head_geom = torso.add_geom(name="head", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                               pos=[0.01, 0, top + head.length_m - head_r], size=[head_r, 0, 0],
                               rgba=_SKIN)
    head_geom.contype, head_geom.conaffinity = CONTYPE_PATIENT, CONAFFINITY_PATIENT

    # --- lower waist (middle trunk): abdomen rotation + flexion at XYPH.
    waist = torso.add_body(name="lower_waist", pos=[0, 0, 0])
    _set_inertial(waist, mpt.mass_kg, [0, 0, -mpt.com_from_proximal_m], _inertia_diag(mpt, 2))
    _ellipsoid(waist, "waist", (0, 0, -mpt.length_m * 0.5),
               (0.75 * torso_depth, 0.8 * trunk_width, 0.6 * mpt.length_m))

    # --- pelvis (lower trunk): abdomen lateral flexion at OMPH.
    pelvis = waist.add_body(name="pelvis", pos=[0, 0, -mpt.length_m])
    _set_inertial(pelvis, lpt.mass_kg, [0, 0, -lpt.com_from_proximal_m], _inertia_diag(lpt, 2))
    pelvis_r = math.sqrt(lpt.mass_kg / (TISSUE_DENSITY_KG_M3 * math.pi * 2 * hip_y)) * 0.8
    _capsule(pelvis, "pelvis", (0, -hip_y, -lpt.length_m), (0, hip_y, -lpt.length_m),
             pelvis_r, _CLOTH)

    for side in ("r", "l"):
        s = _side_sign(side)
        if legs:
            _add_leg(pelvis, side, seg, lpt.length_m, hip_y, h, cuff_limbs)

        if side not in arms:
            continue
        # --- arms, hanging along -z from the shoulder joint centre.
        ua_s, fa_s, hand_s = seg["upper_arm"], seg["forearm"], seg["hand"]
        upper = torso.add_body(name=f"upper_arm_{side}", pos=[0, s * shoulder_y,
                                                             z_shoulder - z_xyph])
        _set_inertial(upper, ua_s.mass_kg, [0, 0, -ua_s.com_from_proximal_m],
                      _inertia_diag(ua_s, 2))
        r = ua_s.capsule_radius_m
        _capsule(upper, f"upper_arm_{side}", (0, 0, -r * 0.3), (0, 0, -ua_s.length_m + r * 0.3), r)
        fore = upper.add_body(name=f"forearm_{side}", pos=[0, 0, -ua_s.length_m])
        _set_inertial(fore, fa_s.mass_kg, [0, 0, -fa_s.com_from_proximal_m],
                      _inertia_diag(fa_s, 2))
        r = fa_s.capsule_radius_m
        _capsule(fore, f"forearm_{side}", (0, 0, -r * 0.3), (0, 0, -fa_s.length_m + r * 0.5), r)
        hand = fore.add_body(name=f"hand_{side}", pos=[0, 0, -fa_s.length_m])
        _set_inertial(hand, hand_s.mass_kg, [0, 0, -hand_s.com_from_proximal_m],
                      _inertia_diag(hand_s, 2))
        hand_r = 0.32 * hand_s.length_m + 0.01
        hand_geom = hand.add_geom(name=f"hand_{side}", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
                                  pos=[0, 0, -0.6 * hand_s.length_m],
                                  size=[hand_r * 0.7, hand_r, 0.75 * hand_s.length_m], rgba=_SKIN)
        hand_geom.contype, hand_geom.conaffinity = CONTYPE_PATIENT, CONAFFINITY_PATIENT
        if f"arm_{side}" in cuff_limbs:
            hand.add_site(name=f"cuff_arm_{side}", pos=[0, 0, -0.5 * hand_s.length_m],
                          quat=list(_cuff_quat(s, "arm")), size=[0.015, 0, 0],
                          rgba=(0.2, 0.8, 0.4, 1))

    for joint in JOINTS:
        if not legs and joint.name in LEG_JOINT_NAMES:
            continue
        if joint.name in ARM_JOINT_NAMES and joint.name[-1] not in arms:
            continue
        body = spec.body(joint.body)
        added = body.add_joint(name=joint.name, type=mujoco.mjtJoint.mjJNT_HINGE,
                               axis=list(joint.axis), pos=[0, 0, 0],
                               range=[math.radians(joint.range_deg[0]),
                                      math.radians(joint.range_deg[1])],
                               armature=0.01)
        added.limited = mujoco.mjtLimited.mjLIMITED_TRUE

    return PatientGeometry(
        shoulder_r=np.array([0, -shoulder_y, z_shoulder - z_xyph]),
        shoulder_l=np.array([0, shoulder_y, z_shoulder - z_xyph]),
        hip_r=np.array([0, -hip_y, -mpt.length_m - lpt.length_m]),
        hip_l=np.array([0, hip_y, -mpt.length_m - lpt.length_m]),
        torso_half_depth_m=chest_depth,
    )
