"""Patient populations: the profiles and conditions an env draws a patient from each episode.

A :class:`PatientPopulation` is a cohort: every pair of one of its profiles and one of its
conditions is a patient, and each episode draws one uniformly (``rehabbot.envs.population``).
Two populations ship, with no profile and no condition in common, so that an agent trained on
one can be tested on patients it has never met (``docs/conditions.md``, Populations):

* ``"train"``: 3 profiles x 9 conditions (healthy, MAS 1, 1+ and 2, tremor at 4 and 8 Hz,
  active patients at 20 % and 50 % strength, a mild contracture);
* ``"test"``: 2 other profiles x 6 other conditions (MAS 3, a 6 Hz tremor twice as strong,
  an active patient at 35 % strength, a resistive patient, a stronger contracture, spasticity
  with contracture).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rehabbot.common.checks import as_dataclass
from rehabbot.sim.conditions import PatientCondition, as_condition
from rehabbot.sim.patient import PatientProfile


@dataclass(frozen=True)
class PatientPopulation:
    """A cohort of patients: every (profile, condition) pair, drawn uniformly per episode.

    ======================= ============================================================
    ``name``                a short identifier, reported with every result
    ``profiles``            :class:`PatientProfile` objects (or dicts of their fields)
    ``conditions``          :class:`PatientCondition` objects (or dicts of their fields)
    ======================= ============================================================
    """

    name: str
    profiles: tuple[PatientProfile, ...]
    conditions: tuple[PatientCondition, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"PatientPopulation.name={self.name!r} must be a non-empty string")
        for field, convert in (("profiles", _as_profile), ("conditions", as_condition)):
            values = getattr(self, field)
            if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, Sequence) \
                    or not values:
                raise ValueError(f"PatientPopulation.{field} must be a non-empty sequence, got "
                                 f"{values!r}")
            object.__setattr__(self, field, tuple(convert(v) for v in values))

    @property
    def patients(self) -> tuple[tuple[PatientProfile, PatientCondition], ...]:
        """Every patient of the cohort, profiles outermost."""
        return tuple((p, c) for p in self.profiles for c in self.conditions)

    def to_dict(self) -> dict[str, Any]:
        """The population as plain data (JSON-able)."""
        return {"name": self.name,
                "profiles": [{"height_m": p.height_m, "mass_kg": p.mass_kg, "sex": p.sex}
                             for p in self.profiles],
                "conditions": [c.to_dict() for c in self.conditions]}


def _as_profile(value: Any) -> PatientProfile:
    return as_dataclass(PatientProfile, value, "profile")


POPULATIONS: dict[str, PatientPopulation] = {
    "train": PatientPopulation(
        "train",
        profiles=(PatientProfile(1.60, 55.0, "female"), PatientProfile(1.75, 75.0, "male"),
                  PatientProfile(1.85, 90.0, "male")),
        conditions=(
            PatientCondition(),
            PatientCondition(spasticity_mas="1"),
            PatientCondition(spasticity_mas="1+"),
            PatientCondition(spasticity_mas="2"),
            PatientCondition(tremor_hz=4.0, tremor_amplitude_nm=0.5),
            PatientCondition(tremor_hz=8.0, tremor_amplitude_nm=0.5),
            PatientCondition(effort="active_assisted", strength_fraction=0.2),
            PatientCondition(effort="active_assisted", strength_fraction=0.5),
            PatientCondition(stiffness_scale=2.0, rom_scale=0.85),
        )),
    "test": PatientPopulation(
        "test",
        profiles=(PatientProfile(1.68, 62.0, "female"), PatientProfile(1.80, 85.0, "male")),
        conditions=(
            PatientCondition(spasticity_mas="3"),
            PatientCondition(tremor_hz=6.0, tremor_amplitude_nm=1.0),
            PatientCondition(effort="active_assisted", strength_fraction=0.35),
            PatientCondition(effort="resistive", effort_fraction=0.05),
            PatientCondition(stiffness_scale=3.0, rom_scale=0.7),
            PatientCondition(spasticity_mas="2", stiffness_scale=1.5, rom_scale=0.8),
        )),
}


def as_population(value: Any) -> PatientPopulation:
    """A population from itself, the name of a shipped one, or a dict of its fields."""
    if isinstance(value, PatientPopulation):
        return value
    if isinstance(value, str):
        if value not in POPULATIONS:
            raise ValueError(f"patients={value!r} is not a shipped population; valid: "
                             f"{list(POPULATIONS)} (or a PatientPopulation)")
        return POPULATIONS[value]
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {"name", "profiles", "conditions"})
        if unknown:
            raise ValueError(f"patients has unknown field(s) {unknown}; valid: name, profiles, "
                             "conditions")
        return PatientPopulation(name=value.get("name", "custom"),
                                 profiles=value.get("profiles", ()),
                                 conditions=value.get("conditions", ()))
    raise ValueError(f"patients={value!r} must be a PatientPopulation, a dict of its fields or "
                     f"the name of a shipped population {list(POPULATIONS)}")
