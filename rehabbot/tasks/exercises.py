"""Therapy exercises in clinical terms: key poses of the patient's exercised joints.

An :class:`Exercise` is a named list of key poses, each mapping joint names without their side
suffix (``"shoulder_flexion"``, ``"elbow_flexion"``, ``"hip_flexion"``, ``"knee_flexion"``,
...) to angles in degrees, positive in the clinical direction (flexion, abduction); joints a
pose does not name stay at the scene's home posture. :mod:`rehabbot.tasks.targets` turns an
exercise into robot targets through the coupled kinematics, so every target is reachable with
the cuff on.

Each limb has its own table (:data:`EXERCISES`); the exercise index ``e`` of the observation is
the position in the env's table. Add an exercise without editing the package by passing the
env a table of your own::

    from rehabbot.tasks.exercises import Exercise, exercises_for

    raise_arm = Exercise("shoulder_raise", "shoulder flexion 30 -> 100 deg",
                         ({"shoulder_flexion": 60}, {"shoulder_flexion": 100}))
    env = gym.make("rehabbot/rehab-reach-v0", exercises=(*exercises_for("arm"), raise_arm))

(``exercises`` also takes dicts with the fields of :class:`Exercise`, e.g. from JSON.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rehabbot.common.checks import check_choice, is_real

LIMBS = ("arm", "hip", "knee")
TASK_TYPES = ("reaching", "trajectory")
# The joints (side-less names) a limb's exercises may move, and their anatomical ranges are
# those of rehabbot.sim.patient; other joints of the patient stay at home.
LIMB_JOINTS: dict[str, tuple[str, ...]] = {
    "arm": ("shoulder_flexion", "shoulder_abduction", "elbow_flexion"),
    "hip": ("hip_flexion", "hip_abduction", "knee_flexion"),
    "knee": ("hip_flexion", "hip_abduction", "knee_flexion"),
}


@dataclass(frozen=True)
class Exercise:
    """One therapy exercise: key poses of the exercised joints, from the home posture.

    ============================ ==========================================================
    ``name``                     a short identifier, e.g. ``"shoulder_flexion"``
    ``description``              one line in clinical terms
    ``key_poses_deg``            the poses in order: joint name (no side suffix) -> angle
                                 [deg]; joints not named stay at home
    ============================ ==========================================================
    """

    name: str
    description: str
    key_poses_deg: tuple[Mapping[str, float], ...]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"Exercise.name={self.name!r} must be a non-empty string")
        if not isinstance(self.description, str):
            raise ValueError(f"Exercise {self.name!r}: description must be a string")
        poses = self.key_poses_deg
        if isinstance(poses, Mapping) or not isinstance(poses, Sequence) or not poses:
            raise ValueError(f"Exercise {self.name!r}: key_poses_deg must be a non-empty "
                             f"sequence of {{joint: angle_deg}} mappings, got {poses!r}")
        for k, pose in enumerate(poses):
            if not isinstance(pose, Mapping) or not pose:
                raise ValueError(f"Exercise {self.name!r}: key pose {k} must be a non-empty "
                                 f"{{joint: angle_deg}} mapping, got {pose!r}")
            for joint, angle in pose.items():
                if not (is_real(angle) and math.isfinite(float(angle))):
                    raise ValueError(f"Exercise {self.name!r}: key pose {k}: {joint}={angle!r} "
                                     "must be a finite angle in degrees")
        object.__setattr__(self, "key_poses_deg", tuple(dict(pose) for pose in poses))

    def joints(self) -> tuple[str, ...]:
        """The joints the key poses name, in order of first appearance."""
        return tuple(dict.fromkeys(j for pose in self.key_poses_deg for j in pose))

    def check_limb(self, limb: str) -> None:
        """``ValueError`` unless every joint the exercise moves belongs to ``limb``."""
        check_choice("limb", limb, LIMBS)
        unknown = [j for j in self.joints() if j not in LIMB_JOINTS[limb]]
        if unknown:
            raise ValueError(f"Exercise {self.name!r} moves {unknown}, which are not joints of "
                             f"the {limb!r} limb; valid: {list(LIMB_JOINTS[limb])}")

    @classmethod
    def from_value(cls, value: Any) -> Exercise:
        """An :class:`Exercise`, or one built from a dict of its fields."""
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            fields = {"name", "description", "key_poses_deg"}
            unknown = set(value) - fields
            if unknown or "name" not in value or "key_poses_deg" not in value:
                raise ValueError(f"an exercise needs the fields name, key_poses_deg (and "
                                 f"description); got {sorted(value)}")
            return cls(name=value["name"], description=value.get("description", ""),
                       key_poses_deg=tuple(value["key_poses_deg"]))
        raise ValueError(f"an exercise must be an Exercise or a dict of its fields, got "
                         f"{type(value).__name__}")

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain data (JSON-able)."""
        return {"name": self.name, "description": self.description,
                "key_poses_deg": [dict(pose) for pose in self.key_poses_deg]}


# Home postures (rehabbot.sim.scene_build): arm shoulder flexion 30, abduction 12, elbow 70;
# supine leg hip flexion 5, abduction 5, knee 10; seated leg hip flexion 90, knee 90.
EXERCISES: dict[str, tuple[Exercise, ...]] = {
    "arm": (
        Exercise("shoulder_flexion",
                 "shoulder flexion 30 -> 90 deg in 15 deg steps and back to 40 deg, "
                 "elbow held at 70 deg",
                 tuple({"shoulder_flexion": a} for a in (45, 60, 75, 90, 65, 40))),
        Exercise("elbow_flexion",
                 "elbow extension 70 -> 30 deg, then flexion to 120 deg and back to 90 deg, "
                 "shoulder held at 30 deg flexion",
                 tuple({"elbow_flexion": a} for a in (50, 30, 60, 90, 120, 90))),
    ),
    "hip": (
        Exercise("straight_leg_raise",
                 "supine straight-leg raise: hip flexion 5 -> 60 deg in 10-15 deg steps, "
                 "knee held near extension by the patient",
                 tuple({"hip_flexion": a} for a in (15, 25, 35, 45, 55, 60))),
        Exercise("hip_flexion_cycles",
                 "supine straight-leg hip flexion-extension cycles of growing amplitude "
                 "(15, 30, 20, 35, 25, 40 deg)",
                 tuple({"hip_flexion": a} for a in (15, 30, 20, 35, 25, 40))),
    ),
    "knee": (
        Exercise("knee_extension",
                 "seated knee extension 90 -> 20 deg and back to 50 deg, hip held at 90 deg",
                 tuple({"knee_flexion": a} for a in (75, 60, 45, 30, 20, 50))),
        Exercise("knee_flexion_cycles",
                 "seated knee flexion-extension cycles between 35 and 85 deg",
                 tuple({"knee_flexion": a} for a in (70, 50, 35, 60, 85, 60))),
    ),
}


# The built-in exercises of MyoSuite's legs (patient_model="myo") where they differ. Seated
# with the hip at 90 deg, MyoLeg's passive hamstrings resist knee extension with 22 N m at
# 30 deg and 40 N m at full extension; held at 20 deg, the cuff carries 143 N at weight level
# 4, beyond the lower leg's ISO/TS 15066 limit (130 N); at 35 deg, 108 N
# (docs/results/myo-patient.md, from benchmarks/results/myo_patient.py). Its knee extension
# ends at 35 deg.
MYO_EXERCISES: dict[str, tuple[Exercise, ...]] = {
    "knee": (
        Exercise("knee_extension",
                 "seated knee extension 90 -> 35 deg and back to 60 deg, hip held at 90 deg "
                 "(as far as the hamstrings of MyoSuite's leg allow within the cuff's limit)",
                 tuple({"knee_flexion": a} for a in (75, 65, 55, 45, 35, 60))),
        EXERCISES["knee"][1],
    ),
}


def exercises_for(limb: str, patient_model: str = "rigid") -> tuple[Exercise, ...]:
    """The built-in exercises of ``limb`` (``e = 0, 1, ...`` in this order) for the patient
    model (``"rigid"`` or ``"myo"``: :data:`MYO_EXERCISES` where they differ)."""
    check_choice("limb", limb, LIMBS)
    if patient_model == "myo" and limb in MYO_EXERCISES:
        return MYO_EXERCISES[limb]
    return EXERCISES[limb]


def exercise_table(limb: str, exercises: Sequence[Any] | None,
                   patient_model: str = "rigid") -> tuple[Exercise, ...]:
    """The exercises an env of ``limb`` uses: the built-in ones (of ``patient_model``), or
    ``exercises`` (Exercise objects or dicts), checked against the limb and for unique
    names."""
    if exercises is None:
        return exercises_for(limb, patient_model)
    if isinstance(exercises, (str, bytes, Mapping)) or not isinstance(exercises, Sequence) \
            or not exercises:
        raise ValueError(f"exercises must be a non-empty sequence of Exercise objects (or "
                         f"dicts), got {exercises!r}")
    table = tuple(Exercise.from_value(item) for item in exercises)
    for exercise in table:
        exercise.check_limb(limb)
    names = [exercise.name for exercise in table]
    if len(set(names)) != len(names):
        raise ValueError(f"exercise names must be unique, got {names}")
    return table
