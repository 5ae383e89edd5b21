"""Clinical conditions of the patient: spasticity, contracture, weakness, tremor, effort and
fatigue.

A :class:`PatientCondition` describes what is wrong with the exercised limb, in clinical or SI
units. The default is today's patient: healthy, relaxed, passive; an env built with it is
bit-identical to one built without it. :mod:`rehabbot.sim.patient_drive` turns a condition
into joint torques every physics step; ``docs/conditions.md`` has the models, their equations,
their calibration and their sources (its Sources section).

The numbers of this module are engineering estimates wherever the literature gives no table
(no numeric MAS-to-parameter mapping was found; ``docs/conditions.md`` says which).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from rehabbot.common.checks import as_dataclass, check_choice, check_number, is_real
from rehabbot.laws import patient as laws
from rehabbot.laws import scalar

# Modified Ashworth Scale grades (Bohannon & Smith 1987).
MAS_GRADES: tuple[str, ...] = ("0", "1", "1+", "2", "3", "4")
EFFORT_MODES: tuple[str, ...] = ("passive", "active_assisted", "resistive")
TREMOR_BAND_HZ = (2.0, 12.0)

# name -> (low, high): the numeric fields and their valid ranges.
CONDITION_RANGES: dict[str, tuple[float, float]] = {
    "stiffness_scale": (0.25, 20.0),
    "rom_scale": (0.2, 1.0),
    "strength_fraction": (0.0, 1.0),
    "tremor_hz": (0.0, TREMOR_BAND_HZ[1]),
    "tremor_amplitude_nm": (0.0, 10.0),
    "effort_fraction": (0.0, 1.0),
    "reaction_delay_s": (0.0, 0.5),
    "fatigue_scale": (0.0, 100.0),
}


@dataclass(frozen=True)
class SpasticReflex:
    """The stretch-reflex model of one MAS grade (``docs/conditions.md``, Spasticity).

    ``gain_scale`` multiplies each joint's reference reflex gain [N·m per rad/s above the
    threshold]; ``threshold_deg_s`` is the stretch velocity below which no reflex fires;
    ``catch_at_rest`` is the stretch position (fraction of the range, 0 at its start) where
    the reflex catches at zero speed, moving earlier by
    ``rehabbot.laws.patient.CATCH_SHIFT_PER_RAD_S`` per rad/s of stretch speed (the lambda
    model's lambda* = lambda - mu omega); ``release_to`` is the fraction of the reflex left
    after the catch releases (1: no release).
    """

    gain_scale: float
    threshold_deg_s: float
    catch_at_rest: float
    release_to: float


# Stretch-reflex latency: SpasticMyoElbow (Yu et al. 2024, arXiv:2412.04700).
REFLEX_LATENCY_S = 0.03

# Calibrated so that: no grade fires at 5 deg/s (every threshold is above it); at 100 deg/s
# (1.745 rad/s) the catch is at 90 % of the range for grade 1 (end of range), 60 % for 1+
# (less than half of the remaining range), 15 % for 2 and 5 % for 3 (most of the range) and at
# its start for 4; and the torque rises with the grade at every speed.
MAS_REFLEX: dict[str, SpasticReflex | None] = {
    "0": None,
    "1": SpasticReflex(0.5, 40.0, 1.25, 0.0),
    "1+": SpasticReflex(1.0, 30.0, 0.95, 0.25),
    "2": SpasticReflex(2.0, 20.0, 0.50, 1.0),
    "3": SpasticReflex(4.0, 15.0, 0.40, 1.0),
    "4": SpasticReflex(8.0, 10.0, 0.35, 1.0),
}

# Reference reflex gain per exercised joint [N·m s/rad] (scaled by the grade's gain_scale).
REFLEX_GAIN_NMS_PER_RAD: dict[str, float] = {
    "shoulder_flexion": 1.5, "shoulder_abduction": 1.5, "elbow_flexion": 1.0,
    "hip_flexion": 3.0, "hip_abduction": 3.0, "knee_flexion": 2.0,
}

# Healthy isometric strength per kg of body mass [N·m/kg], (positive direction, negative
# direction): flexion/extension, abduction/adduction. Rounded typical adult values (torque
# scales with body mass to the power 1, Jaric 2002); women x FEMALE_STRENGTH_FACTOR.
HEALTHY_STRENGTH_NM_PER_KG: dict[str, tuple[float, float]] = {
    "shoulder_flexion": (0.80, 0.95),
    "shoulder_abduction": (0.70, 1.00),
    "elbow_flexion": (0.90, 0.65),
    "hip_flexion": (1.70, 2.60),
    "hip_abduction": (1.40, 1.50),
    "knee_flexion": (1.30, 2.70),
}
FEMALE_STRENGTH_FACTOR = 0.65


def healthy_strength_nm(joint: str, mass_kg: float, sex: str) -> tuple[float, float]:
    """Healthy strength of ``joint`` (side-less name) for a patient of ``mass_kg`` and ``sex``:
    the largest voluntary torque [N·m] in its positive and negative directions."""
    per_kg = HEALTHY_STRENGTH_NM_PER_KG[joint]
    factor = mass_kg * (FEMALE_STRENGTH_FACTOR if sex == "female" else 1.0)
    return per_kg[0] * factor, per_kg[1] * factor


@dataclass(frozen=True)
class PatientCondition:
    """What is wrong with the exercised limb (defaults: a healthy, relaxed, passive limb).

    ======================= ======= ===========================================================
    field                   default meaning
    ======================= ======= ===========================================================
    ``spasticity_mas``      ``"0"`` Modified Ashworth grade ``"0"``, ``"1"``, ``"1+"``, ``"2"``,
                                    ``"3"``, ``"4"`` (ints 0-4 accepted): velocity-dependent
                                    stretch reflex with a catch on the exercised joints
    ``stiffness_scale``     1.0     passive stiffness and damping x this (contracture) [0.25, 20]
    ``rom_scale``           1.0     range of motion x this about the home posture [0.2, 1];
                                    targets and the range-of-motion rule follow
    ``strength_fraction``   1.0     voluntary strength, fraction of a healthy profile's [0, 1]
    ``tremor_hz``           0.0     tremor frequency [Hz]: 0 (none) or 2-12
    ``tremor_amplitude_nm`` 0.0     tremor torque amplitude on each exercised joint [N·m] [0, 10]
    ``effort``              passive ``"passive"``, ``"active_assisted"`` (the patient tries to
                                    follow the exercise) or ``"resistive"`` (the patient pushes
                                    against the motion)
    ``effort_fraction``     0.3     share of the remaining strength the patient uses when
                                    active or resistive [0, 1]
    ``reaction_delay_s``    0.15    the active patient's delay in noticing a new target [s]
                                    [0, 0.5]
    ``fatigue_scale``       0.0     muscle fatigue (3CC-r, :mod:`rehabbot.sim.fatigue`): its
                                    published fatigue and recovery rates x this; 0: none
                                    [0, 100]. Muscles only (``patient_model="myo"``)
    ======================= ======= ===========================================================
    """

    spasticity_mas: str = "0"
    stiffness_scale: float = 1.0
    rom_scale: float = 1.0
    strength_fraction: float = 1.0
    tremor_hz: float = 0.0
    tremor_amplitude_nm: float = 0.0
    effort: str = "passive"
    effort_fraction: float = 0.3
    reaction_delay_s: float = 0.15
    fatigue_scale: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        mas = self.spasticity_mas
        if is_real(mas) and float(mas) in (0, 1, 2, 3, 4) and float(mas).is_integer():
            mas = str(int(mas))
        if not isinstance(mas, str) or mas not in MAS_GRADES:
            raise ValueError(f"PatientCondition.spasticity_mas={self.spasticity_mas!r} is not a "
                             f"Modified Ashworth grade; valid: {list(MAS_GRADES)}")
        set_(self, "spasticity_mas", mas)
        for name, (low, high) in CONDITION_RANGES.items():
            set_(self, name, check_number(f"PatientCondition.{name}", getattr(self, name), low,
                                          high))
        if 0.0 < self.tremor_hz < TREMOR_BAND_HZ[0]:
            raise ValueError(f"PatientCondition.tremor_hz={self.tremor_hz!r} must be 0 (no "
                             f"tremor) or in [{TREMOR_BAND_HZ[0]}, {TREMOR_BAND_HZ[1]}] Hz")
        if self.tremor_amplitude_nm > 0.0 and self.tremor_hz == 0.0:
            raise ValueError(f"PatientCondition.tremor_amplitude_nm="
                             f"{self.tremor_amplitude_nm!r} needs a tremor_hz in "
                             f"[{TREMOR_BAND_HZ[0]}, {TREMOR_BAND_HZ[1]}] Hz")
        check_choice("PatientCondition.effort", self.effort, EFFORT_MODES)
        check_fields_act(self)

    # -- derived ---------------------------------------------------------------------------
    @property
    def is_healthy(self) -> bool:
        """Whether this is the default condition (a healthy, relaxed, passive limb)."""
        return self == PatientCondition()

    @property
    def has_tremor(self) -> bool:
        """Whether the limb trembles."""
        return self.tremor_hz > 0.0 and self.tremor_amplitude_nm > 0.0

    @property
    def reflex(self) -> SpasticReflex | None:
        """The stretch-reflex model of the MAS grade (None for grade 0)."""
        return MAS_REFLEX[self.spasticity_mas]

    @property
    def acts(self) -> bool:
        """Whether the condition applies joint torques (reflex, tremor or effort)."""
        return self.reflex is not None or self.has_tremor or (
            self.effort != "passive" and self.strength_fraction * self.effort_fraction > 0)

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain data (JSON-able)."""
        return dataclasses.asdict(self)

    def describe(self) -> str:
        """One line naming what differs from a healthy, passive limb."""
        default = PatientCondition()
        changed = [f"{f.name}={getattr(self, f.name)!r}" for f in dataclasses.fields(self)
                   if getattr(self, f.name) != getattr(default, f.name)]
        return ", ".join(changed) if changed else "healthy, passive"


def check_fields_act(condition: PatientCondition) -> None:
    """``ValueError`` for a field set away from its default that cannot act with the other
    fields (it would leave the patient bit-identical to one without it), naming the field,
    its value and what would make it act; as a tremor amplitude without a frequency is."""
    default = PatientCondition.__dataclass_fields__
    effort = condition.effort
    voluntary = ("strength_fraction", "effort_fraction")
    if effort == "passive":
        for name in (*voluntary, "reaction_delay_s"):
            value = getattr(condition, name)
            if value != default[name].default:
                raise ValueError(
                    f"PatientCondition.{name}={value!r} cannot act on a passive patient "
                    "(effort='passive' applies no voluntary torque); give effort="
                    "'active_assisted' or 'resistive' for it to act, or leave it out")
    else:
        for name in voluntary:
            value = getattr(condition, name)
            if value == 0.0:
                raise ValueError(
                    f"PatientCondition.{name}={value!r} leaves the {effort} patient no "
                    f"strength to use, so effort={effort!r} cannot act; give {name} > 0, or "
                    "effort='passive' for a patient who does not move the limb")
        if effort == "resistive" and condition.reaction_delay_s != \
                default["reaction_delay_s"].default:
            raise ValueError(
                f"PatientCondition.reaction_delay_s={condition.reaction_delay_s!r} cannot "
                "act on a resistive patient (only an active_assisted patient follows the "
                "targets); give effort='active_assisted' for it to act, or leave it out")
    if condition.fatigue_scale > 0.0 and condition.reflex is None and effort == "passive":
        raise ValueError(f"PatientCondition.fatigue_scale={condition.fatigue_scale!r} cannot "
                         "act on relaxed muscles (fatigue builds up in excited muscles only); "
                         "give effort='active_assisted' or 'resistive', or a spasticity_mas "
                         "above '0', for it to act, or leave it out")
    if condition.tremor_hz > 0.0 and condition.tremor_amplitude_nm == 0.0:
        raise ValueError(f"PatientCondition.tremor_hz={condition.tremor_hz!r} needs a "
                         "tremor_amplitude_nm > 0 (in (0, 10] N·m) to act; give one, or "
                         "leave tremor_hz out")


def as_condition(value: Any) -> PatientCondition:
    """A :class:`PatientCondition` from itself, a dict of its fields or None (the default)."""
    return as_dataclass(PatientCondition, value, "condition")


def reflex_torque_nm(reflex: SpasticReflex | None, gain_nms_per_rad: float,
                     velocity_rad_s: float, position_rad: float, low_rad: float,
                     high_rad: float) -> float:
    """The stretch-reflex torque [N·m] of one joint moving at ``velocity_rad_s`` (already
    delayed by the reflex latency) at ``position_rad`` in its range ``[low_rad, high_rad]``
    (:func:`rehabbot.laws.patient.reflex_torque_nm` with the grade's parameters; 0.0 without
    spasticity); it opposes the motion.
    """
    if reflex is None:
        return 0.0
    return laws.reflex_torque_nm(
        scalar, velocity_rad_s, position_rad, low_rad, high_rad,
        reflex.gain_scale * gain_nms_per_rad, math.radians(reflex.threshold_deg_s),
        reflex.catch_at_rest, reflex.release_to)
