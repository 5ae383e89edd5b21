"""MyoSuite's musculoskeletal legs as the patient's legs (``patient_model="myo"``).

The legs come from the installed ``myo-sim`` package (MyoSuite's model library, Apache-2.0:
``pip install "rehabbot[myo]"``); no model file is copied into RehabBot. Its ``myolegs``
model (both legs, 80 muscles: pelvis, femur, patella, tibia, talus, calcaneus and toes) is
loaded as an ``MjSpec``, stripped of its own torso scaffold, floor, light and cameras, and
attached under the rigid patient's pelvis, whose own legs are then not built:

* **Where:** the midpoint of MyoLeg's hip joint centres sits on the rigid patient's hip
  midpoint; MyoLeg faces the patient's front (its -y turned onto our +x).
* **Joints in our names and signs**, so the exercises, the range-of-motion rule, the poses
  and the feasibility checks address both patients alike: ``hip_flexion_<s>`` and
  ``hip_rotation_<s>`` keep their names, ``hip_adduction_<s>`` becomes ``hip_abduction_<s>``
  (axis and range negated: abduction positive), ``knee_angle_<s>`` becomes
  ``knee_flexion_<s>``, ``ankle_angle_<s>`` ``ankle_dorsiflexion_<s>`` and
  ``subtalar_angle_<s>`` ``ankle_inversion_<s>``. Every other MyoLeg name gets the prefix
  ``myo/`` (``myo/vasint_r``, the muscles; ``myo/mtp_angle_r``).
* **Coupled joints:** MyoLeg's knee translations, tibial rotations and the patella follow the
  knee angle through polynomial joint equalities; they are no patient joint of ours (not
  exercised, no posture spring, outside the range-of-motion rule) and
  :meth:`rehabbot.sim.scene.Scene.follow_coupled_joints` sets them wherever a pose is written.
* **Mass:** MyoLeg's pelvis is drawn but weighs nothing (the rigid pelvis carries the lower
  trunk's mass); its legs keep their own masses (13.4 kg each).
* **Contacts:** MyoLeg's own collision capsules and ellipsoids of the legs join the
  patient's collision class; its pelvis's do not (the rigid pelvis rests on the furniture);
  its bone meshes are drawn only.
* **Muscles:** passive (zero excitation) unless a condition drives them; MuJoCo's muscle
  model (activation dynamics, force-length-velocity and passive force-length curves) with
  MyoSuite's parameters.

MyoLeg is one adult size (OpenSim's gait model, about 1.8 m and 75 kg): a scene with it is
built for the default :class:`rehabbot.sim.patient.PatientProfile` only.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.common.extras import missing_module_message
from rehabbot.sim.mujoco_warnings import handling_mujoco_warnings
from rehabbot.sim.patient import PatientProfile

PATIENT_MODELS: tuple[str, ...] = ("rigid", "myo")
MYO_SIM_REQUIREMENT = "myo-sim==0.2.3"
MYO_PREFIX = "myo/"
SIDES = ("r", "l")
# MyoLeg joint (without side) -> (our name, sign): the independent hinges we address.
LEG_JOINTS: dict[str, tuple[str, float]] = {
    "hip_flexion": ("hip_flexion", 1.0),
    "hip_adduction": ("hip_abduction", -1.0),
    "hip_rotation": ("hip_rotation", 1.0),
    "knee_angle": ("knee_flexion", 1.0),
    "ankle_angle": ("ankle_dorsiflexion", 1.0),
    "subtalar_angle": ("ankle_inversion", 1.0),
}
# MyoLeg's bodies of one leg (without side), proximal to distal; weight levels scale these.
LEG_BODIES: tuple[str, ...] = ("femur", "patella", "tibia", "talus", "calcn", "toes")
# The rigid patient's segment -> MyoLeg's body bearing it (landmarks for furniture, cameras).
SEGMENT_BODY: dict[str, str] = {"thigh": "femur", "shank": "tibia", "foot": "calcn"}
# ... and the MyoLeg bodies whose collision geoms stand for that segment (the furniture rests
# under them).
SEGMENT_GEOM_BODIES: dict[str, tuple[str, ...]] = {
    "thigh": ("femur",), "shank": ("tibia",), "foot": ("calcn", "toes")}
# The leg cuff: this fraction of the knee-to-ankle distance below the knee (as the rigid
# patient's LEG_CUFF_FRACTION).
LEG_CUFF_FRACTION = 0.75
# MuJoCo warns each time myo-sim attaches one of its parts without a name prefix while it
# composes a model (harmless here: the composed spec is attached to ours with MYO_PREFIX, and
# never saved as XML). MuJoCo's default handler would print it and write MUJOCO_LOG.TXT.
EMPTY_PREFIX_WARNING = "Attaching a spec with an empty prefix"


def check_myo_profile(profile: PatientProfile) -> None:
    """``ValueError`` unless ``profile`` is the default :class:`PatientProfile` (MyoLeg and
    MyoArm are one adult size each)."""
    if profile != PatientProfile():
        raise ValueError(f"patient_model='myo': MyoSuite's legs and arm are one adult size, so the "
                         f"profile must be the default {PatientProfile()}, got {profile}")


class MyoModelMissingError(ImportError):
    """``myo-sim`` is not installed."""


def build_myo_spec(name: str) -> mujoco.MjSpec:
    """myo-sim's model ``name`` (a ``myo_sim.build.compose`` registry name: ``"myolegs"``,
    ``"myoarm_r"``, ...) as an ``MjSpec``. MuJoCo's empty-prefix warnings are dropped by our
    handler (:func:`rehabbot.sim.mujoco_warnings.handling_mujoco_warnings`), so nothing is
    printed and no ``MUJOCO_LOG.TXT`` is written. Raises :class:`MyoModelMissingError`
    without myo-sim."""
    try:
        from myo_sim.build.compose import build_spec
    except ImportError as err:
        raise MyoModelMissingError(missing_module_message(
            "patient_model='myo' (MyoSuite's models)", "myo_sim")) from err
    with handling_mujoco_warnings(EMPTY_PREFIX_WARNING):
        return build_spec(name)


@functools.lru_cache(maxsize=1)
def _legs_template() -> mujoco.MjSpec:
    """MyoLeg as myo-sim builds it (1.3 s; built once per process, copied for each scene)."""
    return build_myo_spec("myolegs")


def myo_available() -> bool:
    """Whether ``myo-sim`` can be imported."""
    try:
        import myo_sim.build.compose  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class MyoLegs:
    """What :func:`add_myo_legs` attached (names as they are in the scene's model)."""

    joint_names: tuple[str, ...]  # the independent hinges: both legs, then the toes
    limb_bodies: dict[str, tuple[str, ...]]  # "leg_r" -> MyoLeg's bodies of that leg
    segment_geoms: dict[str, tuple[str, ...]]  # "thigh_r" -> its collision geoms
    segment_body: dict[str, str]  # "thigh_r" -> the MyoLeg body bearing it
    muscle_names: tuple[str, ...]


def _rename_joint(spec: mujoco.MjSpec, old: str, new: str) -> None:
    """Rename a joint and the joint equalities that name it (MjSpec keeps references as
    names)."""
    spec.joint(old).name = new
    for equality in spec.equalities:
        if equality.name1 == old:
            equality.name1 = new
        if equality.name2 == old:
            equality.name2 = new


def _strip_scaffold(legs: mujoco.MjSpec) -> None:
    """Remove what is not a leg: the torso scaffold, the free joint, the floor and the other
    world geoms, the light, the cameras, and the materials and textures no geom uses; the
    legs' root is put at the world origin."""
    legs.delete(legs.body("sacrum"))
    legs.delete(legs.joint("root"))
    legs.body("Full Body").pos = [0.0, 0.0, 0.0]  # was its standing height; attached instead
    for item in [*legs.worldbody.geoms, *legs.worldbody.lights, *legs.worldbody.cameras]:
        legs.delete(item)
    delete_unused_assets(legs)


def delete_unused_assets(spec: mujoco.MjSpec) -> None:
    """Delete the materials no geom of ``spec`` uses, then the textures no material uses."""
    used = {geom.material for geom in spec.geoms if geom.material}
    for material in list(spec.materials):
        if material.name not in used:
            spec.delete(material)
    used_textures = {name for material in spec.materials for name in material.textures if name}
    for texture in list(spec.textures):
        if texture.name not in used_textures:
            spec.delete(texture)


def _cuff_frame(knee_to_ankle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The leg cuff's position and orientation in MyoLeg's tibia frame (OpenSim axes: x
    anterior, y superior, z to the right): on the knee-to-ankle line, x proximal along the
    shank, z into the shin from the front (the rigid patient's convention)."""
    x_axis = -knee_to_ankle / np.linalg.norm(knee_to_ankle)
    into = np.array([-1.0, 0.0, 0.0])
    z_axis = into - x_axis * float(into @ x_axis)
    z_axis /= np.linalg.norm(z_axis)
    y_axis = np.cross(z_axis, x_axis)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).reshape(9))
    return LEG_CUFF_FRACTION * knee_to_ankle, quat


@functools.lru_cache(maxsize=1)
def _leg_landmarks() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The hip joint centres' midpoint in MyoLeg's root frame (z up, facing -y) and each
    side's knee-to-ankle vector in its tibia frame, from the compiled template."""
    legs = _legs_template().copy()
    _strip_scaffold(legs)
    model = legs.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    root = data.xpos[model.body("myolegs_root").id]
    hips = [data.xpos[model.body(f"femur_{s}").id] - root for s in SIDES]
    shank = {s: model.body(f"talus_{s}").pos.copy() for s in SIDES}
    return (hips[0] + hips[1]) / 2, shank


# MyoLeg faces -y with its right side at -x; our patient faces +x with its right at -y.
_FACING_QUAT = np.array([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])


def _turned(vector: np.ndarray) -> np.ndarray:
    """A vector of MyoLeg's root frame in ours (the yaw of :data:`_FACING_QUAT`)."""
    return np.array([-vector[1], vector[0], vector[2]])


def add_myo_legs(spec: mujoco.MjSpec, pelvis: mujoco.MjsBody, hip_midpoint: np.ndarray,
                 patient_contype: int, patient_conaffinity: int,
                 cuff_limbs: tuple[str, ...]) -> MyoLegs:
    """Attach MyoLeg's two legs under ``pelvis`` (a body of ``spec``), their hip midpoint at
    ``hip_midpoint`` (in the pelvis frame); put a ``cuff_<limb>`` site on the shin of each leg
    of ``cuff_limbs`` (``"leg_r"``, ``"leg_l"``). Raises :class:`MyoModelMissingError` without
    myo-sim."""
    legs = _legs_template().copy()
    _strip_scaffold(legs)
    hips, shank = _leg_landmarks()
    for side in SIDES:
        for myo_name, (our_name, sign) in LEG_JOINTS.items():
            joint = legs.joint(f"{myo_name}_{side}")
            if sign < 0:
                joint.axis = [-a for a in joint.axis]
                low, high = joint.range
                joint.range = [-high, -low]
            _rename_joint(legs, f"{myo_name}_{side}", f"{our_name}_{side}")
    for geom in legs.geoms:
        if geom.contype or geom.conaffinity:
            geom.contype, geom.conaffinity = patient_contype, patient_conaffinity
    myo_pelvis = legs.body("pelvis")
    for geom in myo_pelvis.geoms:  # the rigid pelvis is the one that rests on the furniture
        geom.contype, geom.conaffinity = 0, 0
    myo_pelvis.explicitinertial = True
    myo_pelvis.mass = 0.0
    myo_pelvis.inertia = [0.0, 0.0, 0.0]
    for limb in cuff_limbs:
        side = limb[-1]
        pos, quat = _cuff_frame(shank[side])
        legs.body(f"tibia_{side}").add_site(name=f"cuff_{limb}", pos=list(pos), quat=list(quat),
                                            size=[0.015, 0, 0], rgba=[0.2, 0.8, 0.4, 1])
    frame = pelvis.add_frame(pos=list(np.asarray(hip_midpoint) - _turned(hips)),
                             quat=list(_FACING_QUAT))
    spec.attach(legs, prefix=MYO_PREFIX, frame=frame)
    joints = []
    for side in SIDES:
        for our_name, _sign in LEG_JOINTS.values():
            name = f"{our_name}_{side}"
            _rename_joint(spec, f"{MYO_PREFIX}{name}", name)
            joints.append(name)
    joints += [f"{MYO_PREFIX}mtp_angle_{side}" for side in SIDES]
    for limb in cuff_limbs:
        spec.site(f"{MYO_PREFIX}cuff_{limb}").name = f"cuff_{limb}"
    geoms: dict[str, tuple[str, ...]] = {}
    bodies: dict[str, str] = {}
    for side in SIDES:
        for segment, body_name in SEGMENT_BODY.items():
            bodies[f"{segment}_{side}"] = f"{MYO_PREFIX}{body_name}_{side}"
            geoms[f"{segment}_{side}"] = tuple(
                g.name for name in SEGMENT_GEOM_BODIES[segment]
                for g in spec.body(f"{MYO_PREFIX}{name}_{side}").geoms
                if g.contype == patient_contype)
    muscles = tuple(a.name for a in spec.actuators if a.name.startswith(MYO_PREFIX))
    return MyoLegs(
        joint_names=tuple(joints),
        limb_bodies={f"leg_{s}": tuple(f"{MYO_PREFIX}{b}_{s}" for b in LEG_BODIES)
                     for s in SIDES},
        segment_geoms=geoms,
        segment_body=bodies,
        muscle_names=muscles,
    )
