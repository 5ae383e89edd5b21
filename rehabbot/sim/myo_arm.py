"""MyoSuite's musculoskeletal right arm as the patient's right arm (``patient_model="myo"`` on
the right-arm reach scene, preset ``upper_right``).

The arm comes from the installed ``myo-sim`` package (its ``myoarm_r`` model: clavicle,
scapula, humerus, ulna, radius and hand, 63 muscles); no model file is copied into RehabBot.
It is loaded as an ``MjSpec`` and attached to the rigid patient's torso at the right shoulder;
the rigid patient's own right arm is not built.

* **Where:** MyoArm's glenohumeral centre (its ``humphant_r`` body at the reference pose) sits
  on the rigid patient's right shoulder joint centre; MyoArm's OpenSim axes (x anterior, y up,
  z to the right) are turned onto ours (x anterior, y to the left, z up).
* **The shoulder in our joint names.** MyoArm's shoulder is elevation plane
  (``elv_angle``), elevation (``shoulder_elv``) and axial rotation, with a scapulohumeral
  rhythm: ten clavicle and scapula joints follow the elevation through linear joint
  equalities. Our exercises address flexion and abduction, so:

  - the elevation plane is fixed in the sagittal plane (``elv_angle`` = 90 deg, and its
    companion ``shoulder1_r2`` = -90 deg, baked into the bodies' frames), so that MyoArm's
    elevation *is* flexion: ``shoulder_elv_r`` becomes ``shoulder_flexion_r``, with its
    range (0-180 deg) and its rhythm unchanged;
  - ``shoulder_abduction_r`` is a hinge added after the flexion, about the anterior axis of
    the flexed frame (the rigid patient's convention: flexion, then abduction), with the rigid
    patient's range. The scapulohumeral rhythm follows the flexion only: an abduction moves
    the humerus, not the scapula (our exercises hold abduction at its home 12 deg);
  - ``shoulder_rot_r`` becomes ``myo/shoulder_rot_r``, a posture joint (held).
* **The elbow** keeps its name ``elbow_flexion_r`` and MyoArm's range (0-130 deg); forearm
  pronation-supination becomes ``myo/pro_sup_r``, a posture joint.
* **The wrist and fingers are frozen** at MyoArm's zero pose (their joints removed): the hand
  is rigid, as the rigid patient's; the robot's cuff straps onto it.
* **The torso scaffold** that carries the muscles' origins on the thorax (pectoralis,
  latissimus) is kept, welded to the rigid torso, weightless and without contacts or bone
  meshes; the rigid torso is the one drawn and touched.
* **Muscles** get the side suffix of our names (``myo/DELT1_r``), so the exercised arm's
  muscles are selected as the legs' are (:func:`rehabbot.sim.muscles.limb_muscles`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.sim import myo_patient as myo
from rehabbot.sim import patient as pt

SIDE = "r"
# MyoArm's elevation plane that makes its elevation a flexion (sagittal plane) [rad].
SAGITTAL_ELEVATION_PLANE_RAD = math.pi / 2
# MyoArm's joints that become exercised joints of ours (their names without the prefix).
ARM_JOINTS: dict[str, str] = {
    "shoulder_elv_r": "shoulder_flexion_r",
    "elbow_flexion_r": "elbow_flexion_r",
}
# MyoArm's joints kept as posture joints (held by the scene's posture springs), prefixed.
POSTURE_JOINTS: tuple[str, ...] = ("shoulder_rot_r", "pro_sup_r")
ABDUCTION_JOINT = "shoulder_abduction_r"
# The arm proper is the humerus and every body below it (weight levels scale these; the
# robot's wrist does not collide with those below the humerus, around the cuff).
UPPER_ARM_BODY = "humerus_r"
# The hand's root after its wrist is frozen; the cuff site sits on it.
HAND_ROOT = "lunate_r"
# The first body of the shoulder girdle: the scaffold is what is not below it.
GIRDLE_ROOT = "clavicle_r"
# Where the cuff sits on the hand: this fraction of the way from the wrist (lunate) to the
# heads of the metacarpals (the rigid hand's cuff: half the hand's length).
CUFF_FRACTION_OF_PALM = 0.5
# The rigid patient's segments -> MyoArm's bodies bearing them.
SEGMENT_BODY: dict[str, str] = {"upper_arm_r": "humerus_r", "forearm_r": "ulna_r",
                                "hand_r": HAND_ROOT}


@dataclass(frozen=True)
class MyoArm:
    """What :func:`add_myo_arm` attached (names as they are in the scene's model)."""

    joint_names: tuple[str, ...]  # the independent hinges: exercised, then posture
    limb_bodies: tuple[str, ...]  # humerus, forearm and hand bodies (weight levels scale)
    cuffed_bodies: tuple[str, ...]  # the forearm and hand bodies
    segment_body: dict[str, str]  # "hand_r" -> the MyoArm body bearing it
    muscle_names: tuple[str, ...]


@functools.lru_cache(maxsize=1)
def _arm_template() -> mujoco.MjSpec:
    """MyoArm as myo-sim builds it (built once per process, copied for each scene)."""
    return myo.build_myo_spec("myoarm_r")


def _below(body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
    """``body`` and every body below it."""
    found = [body]
    for child in body.bodies:
        found += _below(child)
    return found


def _axis_angle_quat(axis, angle_rad: float) -> np.ndarray:
    quat = np.zeros(4)
    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    mujoco.mju_axisAngle2Quat(quat, unit, angle_rad)
    return quat


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    return out


def _delete_joint(arm: mujoco.MjSpec, name: str) -> None:
    """Remove a joint and the joint equalities that name it."""
    for equality in list(arm.equalities):
        if name in (equality.name1, equality.name2):
            arm.delete(equality)
    arm.delete(arm.joint(name))


def _strip_scaffold(arm: mujoco.MjSpec) -> None:
    """World geoms, lights and cameras go; the torso scaffold above the shoulder girdle stays
    (muscle origins and wrapping surfaces) but weighs nothing and shows or touches nothing.
    MyoArm's explicit contact pairs (arm against thorax) go too: the scene's collision classes
    decide what the arm touches."""
    for item in [*arm.worldbody.geoms, *arm.worldbody.lights, *arm.worldbody.cameras,
                 *arm.pairs, *arm.excludes]:
        arm.delete(item)
    girdle = {b.name for b in _below(arm.body(GIRDLE_ROOT))}
    for body in _below(arm.body("Full Body")):
        if body.name in girdle:
            continue
        for geom in list(body.geoms):
            if geom.type == mujoco.mjtGeom.mjGEOM_MESH or geom.contype or geom.conaffinity:
                arm.delete(geom)
        body.explicitinertial = True
        body.mass = 0.0
        body.inertia = [0.0, 0.0, 0.0]
        body.ipos = [0.0, 0.0, 0.0]
    arm.body("Full Body").pos = [0.0, 0.0, 0.0]
    myo.delete_unused_assets(arm)


def _fix_elevation_plane(arm: mujoco.MjSpec) -> None:
    """Bake the sagittal elevation plane into the frames: ``elv_angle`` = +90 deg into the
    body that carries it, and ``shoulder1_r2`` (= -``elv_angle``, after the elevation) into
    the humerus; then add the abduction hinge after the elevation (flexion)."""
    plane = arm.joint("elv_angle_r")
    plane_body = arm.body("humphant_r")
    plane_quat = _axis_angle_quat(plane.axis, SAGITTAL_ELEVATION_PLANE_RAD)
    plane_body.quat = list(_quat_mul(np.asarray(plane_body.quat), plane_quat))
    undo = arm.joint("shoulder1_r2_r")
    humerus = arm.body(UPPER_ARM_BODY)
    undo_quat = _axis_angle_quat(undo.axis, -SAGITTAL_ELEVATION_PLANE_RAD)
    humerus.quat = list(_quat_mul(undo_quat, np.asarray(humerus.quat)))
    elevation = arm.joint("shoulder_elv_r")
    _delete_joint(arm, "shoulder1_r2_r")
    _delete_joint(arm, "elv_angle_r")
    # The anterior axis (OpenSim x) in the elevation body's frame, turned so that a positive
    # angle raises the right arm sideways (about -x).
    anterior = np.zeros(3)
    inverse = np.zeros(4)
    mujoco.mju_negQuat(inverse, plane_quat)
    mujoco.mju_rotVecQuat(anterior, np.array([-1.0, 0.0, 0.0]), inverse)
    low, high = pt.JOINT_BY_NAME[ABDUCTION_JOINT].range_deg
    abduction = arm.body("humphant1_r").add_joint(
        name=ABDUCTION_JOINT, type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(anterior),
        range=[math.radians(low), math.radians(high)], damping=elevation.damping,
        armature=elevation.armature)
    abduction.limited = mujoco.mjtLimited.mjLIMITED_TRUE


def _freeze_hand(arm: mujoco.MjSpec) -> None:
    """Remove the wrist's and fingers' joints: the hand is rigid at MyoArm's zero pose."""
    for body in _below(arm.body(HAND_ROOT)):
        for joint in list(body.joints):
            _delete_joint(arm, joint.name)


# Our axes (x anterior, y left, z up) of OpenSim's (x anterior, y up, z right): the columns
# are OpenSim's x, y and z in ours.
_OURS_OF_OPENSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class _Landmarks:
    """MyoArm at its reference pose: the glenohumeral centre in its root frame, the turn from
    its root frame to ours, and the cuff's pose in the hand's frame."""

    glenohumeral: np.ndarray
    ours_of_root: np.ndarray  # (3, 3)
    cuff_pos: np.ndarray
    cuff_quat: np.ndarray


@functools.lru_cache(maxsize=1)
def _arm_landmarks() -> _Landmarks:
    """From the compiled, frozen template at its reference pose."""
    arm = _arm_template().copy()
    _strip_scaffold(arm)
    _fix_elevation_plane(arm)
    _freeze_hand(arm)
    model = arm.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    root = data.xpos[model.body("Full Body").id]
    # The thorax's frame is OpenSim's (x anterior, y up, z right), in the root's axes.
    thorax = data.xmat[model.body("torso").id].reshape(3, 3)
    ours_of_root = _OURS_OF_OPENSIM @ thorax.T
    shoulder = data.xpos[model.body("humphant_r").id] - root
    hand = model.body(HAND_ROOT).id
    hand_pos, hand_rot = data.xpos[hand], data.xmat[hand].reshape(3, 3)
    thirdmc = model.body("thirdmc_r").id
    # The third metacarpal's head: its base plus the proximal phalanx's offset.
    head = data.xpos[thirdmc] + data.xmat[thirdmc].reshape(3, 3) @ model.body("3proxph_r").pos
    cuff_world = hand_pos + CUFF_FRACTION_OF_PALM * (head - hand_pos)
    elbow = data.xpos[model.body("ulna_r").id]
    # x distal along the forearm (elbow to cuff), z into the hand from the lateral side
    # (medially: OpenSim's -z), as the rigid arm's cuff.
    x_axis = cuff_world - elbow
    x_axis /= np.linalg.norm(x_axis)
    medial = -thorax[:, 2]
    z_axis = medial - x_axis * float(medial @ x_axis)
    z_axis /= np.linalg.norm(z_axis)
    y_axis = np.cross(z_axis, x_axis)
    frame_hand = hand_rot.T @ np.column_stack([x_axis, y_axis, z_axis])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, frame_hand.reshape(9))
    return _Landmarks(shoulder, ours_of_root, hand_rot.T @ (cuff_world - hand_pos), quat)


def add_myo_arm(spec: mujoco.MjSpec, torso: mujoco.MjsBody, shoulder: np.ndarray,
                patient_contype: int, patient_conaffinity: int) -> MyoArm:
    """Attach MyoArm's right arm to ``torso`` (a body of ``spec``), its glenohumeral centre at
    ``shoulder`` (in the torso frame), with a ``cuff_arm_r`` site on its hand. Raises
    :class:`rehabbot.sim.myo_patient.MyoModelMissingError` without myo-sim."""
    arm = _arm_template().copy()
    _strip_scaffold(arm)
    _fix_elevation_plane(arm)
    _freeze_hand(arm)
    marks = _arm_landmarks()
    for old, new in ARM_JOINTS.items():
        myo._rename_joint(arm, old, new)
    for actuator in arm.actuators:
        actuator.name = f"{actuator.name}_{SIDE}"
    girdle = {b.name for b in _below(arm.body(GIRDLE_ROOT))}
    for geom in arm.geoms:
        if geom.contype or geom.conaffinity:
            inside = geom.parent.name in girdle and geom.parent.name != GIRDLE_ROOT
            geom.contype, geom.conaffinity = ((patient_contype, patient_conaffinity) if inside
                                              else (0, 0))
    arm.body(HAND_ROOT).add_site(name=f"cuff_arm_{SIDE}", pos=list(marks.cuff_pos),
                                 quat=list(marks.cuff_quat), size=[0.015, 0, 0],
                                 rgba=[0.2, 0.8, 0.4, 1])
    turn = np.zeros(4)
    mujoco.mju_mat2Quat(turn, marks.ours_of_root.reshape(9))
    frame = torso.add_frame(pos=list(np.asarray(shoulder) - marks.ours_of_root
                                     @ marks.glenohumeral), quat=list(turn))
    spec.attach(arm, prefix=myo.MYO_PREFIX, frame=frame)
    for new in ARM_JOINTS.values():
        myo._rename_joint(spec, f"{myo.MYO_PREFIX}{new}", new)
    myo._rename_joint(spec, f"{myo.MYO_PREFIX}{ABDUCTION_JOINT}", ABDUCTION_JOINT)
    exercised = ["shoulder_flexion_r", ABDUCTION_JOINT, "elbow_flexion_r"]
    spec.site(f"{myo.MYO_PREFIX}cuff_arm_{SIDE}").name = f"cuff_arm_{SIDE}"
    posture = [f"{myo.MYO_PREFIX}{name}" for name in POSTURE_JOINTS]
    upper = spec.body(f"{myo.MYO_PREFIX}{UPPER_ARM_BODY}")
    below_humerus = [b.name for b in _below(upper)]
    cuffed = tuple(name for name in below_humerus if name != upper.name)
    muscles = tuple(a.name for a in spec.actuators if a.name.startswith(myo.MYO_PREFIX))
    return MyoArm(
        joint_names=(*exercised, *posture),
        limb_bodies=tuple(below_humerus),
        cuffed_bodies=cuffed,
        segment_body={seg: f"{myo.MYO_PREFIX}{body}" for seg, body in SEGMENT_BODY.items()},
        muscle_names=muscles,
    )
