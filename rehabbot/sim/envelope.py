"""Patients drawn across the adult envelope: disjoint training, validation and test cohorts.

An agent trained on one body serves that body; one trained across bodies and conditions serves
the patients between them. This module draws the cohorts that make both sides measurable, per
scene (limb and robot), from an :class:`Envelope` of heights, masses and body-mass indices that
the scene builds at every weight level:

* ``"envelope-train"``: the envelope's four corners (shortest and lightest, shortest and
  heaviest, tallest and lightest, tallest and heaviest) and six bodies drawn inside it, both
  sexes, x :data:`TRAIN_CONDITIONS` (healthy, spastic, tremor, active, weak, resistive,
  contracted);
* ``"envelope-validation"``: four other bodies x :data:`VALIDATION_CONDITIONS` (what agents are
  selected on);
* ``"envelope-test"``: eight other bodies, healthy (the bodies table of a held-out evaluation);
* ``"envelope-test-conditions"``: four of the test bodies x :data:`TEST_CONDITIONS` (effort,
  weakness, spasticity, contracture and tremor at values no other cohort uses).

Bodies are drawn by Latin-hypercube sampling over height and body-mass index (one stratum of
each per body, so a cohort spreads over the envelope), from a fixed seed per cohort, and
rounded (1 cm, 0.5 kg): the cohorts are the same on every machine. No test body equals a
training or validation body; :func:`nearest_training_body` says how far each lies from the
training bodies (``docs/conditions.md``, Held-out patients).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rehabbot.sim.conditions import PatientCondition
from rehabbot.sim.patient import PatientProfile

ENVELOPE_SPLITS: tuple[str, ...] = ("train", "validation", "test", "test-conditions")
POPULATION_PREFIX = "envelope-"


@dataclass(frozen=True)
class Envelope:
    """The bodies a scene takes at every weight level: height [m], mass [kg] and body-mass
    index [kg/m²] ranges (a body must satisfy all three)."""

    height_m: tuple[float, float]
    mass_kg: tuple[float, float]
    bmi_kg_m2: tuple[float, float] = (17.0, 38.0)

    def __post_init__(self) -> None:
        for name in ("height_m", "mass_kg", "bmi_kg_m2"):
            low, high = getattr(self, name)
            if not (math.isfinite(low) and math.isfinite(high) and 0 < low < high):
                raise ValueError(f"Envelope.{name}={getattr(self, name)!r} must be a range "
                                 "(low, high) with 0 < low < high")

    def mass_range_kg(self, height_m: float) -> tuple[float, float]:
        """The masses the envelope allows at ``height_m`` (its BMI range, within its mass
        range)."""
        low = max(self.mass_kg[0], self.bmi_kg_m2[0] * height_m ** 2)
        high = min(self.mass_kg[1], self.bmi_kg_m2[1] * height_m ** 2)
        if low > high:
            raise ValueError(f"the envelope {self} holds no body {height_m} m tall")
        return low, high

    def contains(self, profile: PatientProfile) -> bool:
        """Whether ``profile`` lies inside the envelope (rounding allowed)."""
        low, high = self.mass_range_kg(min(max(profile.height_m, self.height_m[0]),
                                           self.height_m[1]))
        return (self.height_m[0] - 1e-9 <= profile.height_m <= self.height_m[1] + 1e-9
                and low - 0.5 <= profile.mass_kg <= high + 0.5)


# The adult envelope: statures 1.50-2.00 m, 45-140 kg, BMI 17-38. Each scene's envelope is
# where it builds every weight level (benchmarks/results/profile_envelope.py,
# docs/research-notes/failure-modes.md): the UR5e's hip holds legs up to 100 kg; the FR3's
# supine hip saturates its shoulder joint with heavier or taller legs, so its envelope is
# smaller.
ADULT_ENVELOPE = Envelope(height_m=(1.50, 2.00), mass_kg=(45.0, 140.0))
ENVELOPES: dict[tuple[str, str], Envelope] = {
    ("arm", "ur5e"): ADULT_ENVELOPE,
    ("knee", "ur5e"): ADULT_ENVELOPE,
    ("hip", "ur5e"): Envelope(height_m=(1.50, 2.00), mass_kg=(45.0, 100.0)),
    ("arm", "fr3"): ADULT_ENVELOPE,
    ("knee", "fr3"): ADULT_ENVELOPE,
    ("hip", "fr3"): Envelope(height_m=(1.50, 1.85), mass_kg=(45.0, 60.0), bmi_kg_m2=(15.0, 38.0)),
}

# Conditions. Training spans each mode of the condition models; validation and test use
# values no other cohort uses (the test values include the hard cases: a patient
# resisting at 10 % of strength, a weak knee at 10 %).
TRAIN_CONDITIONS: tuple[PatientCondition, ...] = (
    PatientCondition(),
    PatientCondition(spasticity_mas="1"),
    PatientCondition(spasticity_mas="2"),
    PatientCondition(tremor_hz=4.0, tremor_amplitude_nm=0.5),
    PatientCondition(tremor_hz=8.0, tremor_amplitude_nm=1.0),
    PatientCondition(effort="active_assisted", strength_fraction=0.5),
    PatientCondition(effort="active_assisted", strength_fraction=0.05),
    PatientCondition(effort="resistive", effort_fraction=0.05),
    PatientCondition(effort="resistive", effort_fraction=0.15),
    PatientCondition(stiffness_scale=2.0, rom_scale=0.85),
)
VALIDATION_CONDITIONS: tuple[PatientCondition, ...] = (
    PatientCondition(),
    PatientCondition(spasticity_mas="1+"),
    PatientCondition(effort="active_assisted", strength_fraction=0.25),
    PatientCondition(effort="resistive", effort_fraction=0.08),
)
TEST_CONDITIONS: tuple[PatientCondition, ...] = (
    PatientCondition(effort="resistive", effort_fraction=0.1),
    PatientCondition(effort="active_assisted", strength_fraction=0.1),
    PatientCondition(effort="active_assisted", strength_fraction=0.35),
    PatientCondition(spasticity_mas="3"),
    PatientCondition(stiffness_scale=3.0, rom_scale=0.7),
    PatientCondition(tremor_hz=6.0, tremor_amplitude_nm=1.0),
)

# Seeds of the cohorts' draws (any fixed values: they make the cohorts the same everywhere).
_SEEDS = {"train": 431, "validation": 432, "test": 433}
_BODIES = {"train": 6, "validation": 4, "test": 8}  # drawn bodies (train adds the 4 corners)
_TEST_CONDITION_BODIES = 4  # test bodies (spread over the envelope) in the conditions table


def envelope_of(limb: str, robot: str = "ur5e") -> Envelope:
    """The envelope of a scene (``ValueError`` naming a limb or robot without one)."""
    try:
        return ENVELOPES[(limb, robot)]
    except KeyError:
        raise ValueError(f"no patient envelope for limb={limb!r}, robot={robot!r}; valid: "
                         f"{sorted(ENVELOPES)}") from None


def _round_profile(height_m: float, mass_kg: float, sex: str) -> PatientProfile:
    return PatientProfile(float(round(height_m, 2)), float(round(mass_kg * 2) / 2), sex)


def draw_bodies(envelope: Envelope, count: int, seed: int) -> tuple[PatientProfile, ...]:
    """``count`` bodies by Latin-hypercube sampling of height and of mass within the BMI range
    at that height (one stratum each per body), sexes alternating, from ``seed``."""
    if count < 1:
        raise ValueError(f"count={count!r} must be at least 1")
    rng = np.random.default_rng(seed)
    height_u = (rng.permutation(count) + rng.random(count)) / count
    mass_u = (rng.permutation(count) + rng.random(count)) / count
    bodies = []
    for k in range(count):
        height = envelope.height_m[0] + height_u[k] * (envelope.height_m[1] - envelope.height_m[0])
        low, high = envelope.mass_range_kg(height)
        bodies.append(_round_profile(height, low + mass_u[k] * (high - low),
                                     "female" if k % 2 else "male"))
    return tuple(bodies)


def corner_bodies(envelope: Envelope) -> tuple[PatientProfile, ...]:
    """The envelope's four corners: its shortest and tallest bodies at their lightest and
    heaviest masses (a woman at the short corners, a man at the tall ones)."""
    corners = []
    for height, sex in ((envelope.height_m[0], "female"), (envelope.height_m[1], "male")):
        for mass in envelope.mass_range_kg(height):
            corners.append(_round_profile(height, mass, sex))
    return tuple(corners)


def envelope_bodies(split: str, limb: str, robot: str = "ur5e") -> tuple[PatientProfile, ...]:
    """The bodies of cohort ``split`` (one of :data:`ENVELOPE_SPLITS`) for a scene; no body of
    one cohort is in another (``test-conditions`` takes test bodies)."""
    envelope = envelope_of(limb, robot)
    if split not in ENVELOPE_SPLITS:
        raise ValueError(f"split={split!r} is not one of {list(ENVELOPE_SPLITS)}")
    train = corner_bodies(envelope) + draw_bodies(envelope, _BODIES["train"], _SEEDS["train"])
    if split == "train":
        return train
    taken = set(train)
    if split == "validation":
        return _disjoint(envelope, "validation", taken)
    taken |= set(_disjoint(envelope, "validation", taken))
    test = _disjoint(envelope, "test", taken)
    if split == "test":
        return test
    by_height = sorted(test, key=lambda p: (p.height_m, p.mass_kg))
    picks = np.linspace(0, len(by_height) - 1, _TEST_CONDITION_BODIES).round().astype(int)
    return tuple(by_height[i] for i in picks)


def _disjoint(envelope: Envelope, split: str, taken: set[PatientProfile]
              ) -> tuple[PatientProfile, ...]:
    """Cohort ``split``'s drawn bodies with any body already ``taken`` drawn again (the next
    seed), so that no body is in two cohorts."""
    seed = _SEEDS[split]
    while True:
        bodies = draw_bodies(envelope, _BODIES[split], seed)
        if not taken.intersection(bodies):
            return bodies
        seed += 1000


def envelope_conditions(split: str) -> tuple[PatientCondition, ...]:
    """The conditions of cohort ``split``."""
    if split == "train":
        return TRAIN_CONDITIONS
    if split == "validation":
        return VALIDATION_CONDITIONS
    if split == "test":
        return (PatientCondition(),)
    if split == "test-conditions":
        return TEST_CONDITIONS
    raise ValueError(f"split={split!r} is not one of {list(ENVELOPE_SPLITS)}")


def body_distance(a: PatientProfile, b: PatientProfile, envelope: Envelope) -> float:
    """The distance between two bodies in units of the envelope's extent: the Euclidean norm of
    their height and mass differences, each divided by the envelope's height or mass span (sex
    is reported apart)."""
    dh = (a.height_m - b.height_m) / (envelope.height_m[1] - envelope.height_m[0])
    dm = (a.mass_kg - b.mass_kg) / (envelope.mass_kg[1] - envelope.mass_kg[0])
    return float(math.hypot(dh, dm))


@dataclass(frozen=True)
class Nearest:
    """How far a body lies from the nearest training body (:func:`body_distance`)."""

    body: PatientProfile
    nearest: PatientProfile
    distance: float
    height_diff_m: float
    mass_diff_kg: float
    same_sex: bool

    def to_dict(self) -> dict:
        return {"height_m": self.body.height_m, "mass_kg": self.body.mass_kg,
                "sex": self.body.sex,
                "nearest_training_body": {"height_m": self.nearest.height_m,
                                          "mass_kg": self.nearest.mass_kg,
                                          "sex": self.nearest.sex},
                "distance": round(self.distance, 4),
                "height_diff_m": round(self.height_diff_m, 3),
                "mass_diff_kg": round(self.mass_diff_kg, 2), "same_sex": self.same_sex}


def nearest_training_body(body: PatientProfile, training: Sequence[PatientProfile],
                          envelope: Envelope) -> Nearest:
    """The training body nearest to ``body`` and how far it is."""
    if not training:
        raise ValueError("training must hold at least one body")
    nearest = min(training, key=lambda t: body_distance(body, t, envelope))
    return Nearest(body, nearest, body_distance(body, nearest, envelope),
                   body.height_m - nearest.height_m, body.mass_kg - nearest.mass_kg,
                   body.sex == nearest.sex)
