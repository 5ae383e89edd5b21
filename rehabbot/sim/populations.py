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

import numpy as np

from rehabbot.common.checks import as_dataclass
from rehabbot.sim.conditions import PatientCondition, as_condition
from rehabbot.sim.envelope import (
    ENVELOPE_SPLITS,
    POPULATION_PREFIX,
    envelope_bodies,
    envelope_conditions,
)
from rehabbot.sim.patient import PatientProfile


@dataclass(frozen=True)
class PatientPopulation:
    """A cohort of patients: every (profile, condition) pair, drawn uniformly per episode.

    ======================= ============================================================
    ``name``                a short identifier, reported with every result
    ``profiles``            :class:`PatientProfile` objects (or dicts of their fields)
    ``conditions``          :class:`PatientCondition` objects (or dicts of their fields)
    ``skip_infeasible``     default False: a patient the scene refuses (``ValueError``
                            when its env is built, e.g. a heavy patient resisting harder than
                            the cuff may hold) ends the episode's draw with that error; True:
                            it is left out of the cohort for that scene (the env lists it,
                            with the reason, in ``PopulationEnv.refused_patients``) and the
                            draw is made again
    ======================= ============================================================
    """

    name: str
    profiles: tuple[PatientProfile, ...]
    conditions: tuple[PatientCondition, ...]
    skip_infeasible: bool = False

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
        if not isinstance(self.skip_infeasible, bool):
            raise ValueError(f"PatientPopulation.skip_infeasible={self.skip_infeasible!r} must "
                             "be True or False")

    @property
    def patients(self) -> tuple[tuple[PatientProfile, PatientCondition], ...]:
        """Every patient of the cohort, profiles outermost."""
        return tuple((p, c) for p in self.profiles for c in self.conditions)

    def with_conditions(self, conditions: Any) -> PatientPopulation:
        """The cohort of this population's profiles with only ``conditions``: an index into
        :attr:`conditions`, one of its conditions (a :class:`PatientCondition` or a dict of its
        fields), or a non-empty sequence of them; kept in this population's order and named
        ``"<name>[conditions i, j]"``. ``ValueError`` naming a bad or repeated entry and
        listing the valid ones (a condition that is not this population's is refused: make a
        :class:`PatientPopulation` of it instead)."""
        entries = conditions if isinstance(conditions, Sequence) and not isinstance(
            conditions, (str, bytes)) else [conditions]
        if not entries:
            raise ValueError(f"conditions={conditions!r} must name at least one condition of "
                             f"population {self.name!r}; valid: {self._valid_conditions()}")
        chosen: list[int] = []
        for entry in entries:
            index = self._condition_index(entry)
            if index in chosen:
                raise ValueError(f"conditions={conditions!r} names condition {index} "
                                 f"({self.conditions[index].describe()}) twice")
            chosen.append(index)
        chosen.sort()
        return PatientPopulation(
            f"{self.name}[conditions {', '.join(map(str, chosen))}]", self.profiles,
            tuple(self.conditions[k] for k in chosen), self.skip_infeasible)

    def _condition_index(self, entry: Any) -> int:
        count = len(self.conditions)
        if isinstance(entry, (int, np.integer)) and not isinstance(entry, bool):
            if 0 <= int(entry) < count:
                return int(entry)
            raise ValueError(f"condition {entry!r} is not an index into the conditions of "
                             f"population {self.name!r}; valid: {self._valid_conditions()}")
        if isinstance(entry, (PatientCondition, Mapping)):
            try:
                condition = as_condition(entry)
            except (ValueError, TypeError) as err:
                raise ValueError(f"condition {entry!r}: {err}; valid: "
                                 f"{self._valid_conditions()}") from None
            if condition in self.conditions:
                return self.conditions.index(condition)
            raise ValueError(f"condition {condition.describe()!r} is not one of the conditions "
                             f"of population {self.name!r} (valid: "
                             f"{self._valid_conditions()}); for other conditions make a "
                             "PatientPopulation of them (patients=PatientPopulation(...))")
        raise ValueError(f"condition {entry!r} must be an index into the conditions of "
                         f"population {self.name!r}, or one of them (a PatientCondition or a "
                         f"dict of its fields); valid: {self._valid_conditions()}")

    def _valid_conditions(self) -> str:
        return "; ".join(f"{k} ({c.describe()})" for k, c in enumerate(self.conditions))

    def to_dict(self) -> dict[str, Any]:
        """The population as plain data (JSON-able)."""
        return {"name": self.name,
                "profiles": [{"height_m": p.height_m, "mass_kg": p.mass_kg, "sex": p.sex}
                             for p in self.profiles],
                "conditions": [c.to_dict() for c in self.conditions],
                "skip_infeasible": self.skip_infeasible}


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


ENVELOPE_POPULATIONS: tuple[str, ...] = tuple(f"{POPULATION_PREFIX}{split}"
                                              for split in ENVELOPE_SPLITS)


def envelope_population(name: str, limb: str, robot: str = "ur5e") -> PatientPopulation:
    """The envelope cohort ``name`` (one of :data:`ENVELOPE_POPULATIONS`) of a scene: its
    bodies x its conditions (:mod:`rehabbot.sim.envelope`), named ``"<name>:<limb>-<robot>"``."""
    if name not in ENVELOPE_POPULATIONS:
        raise ValueError(f"patients={name!r} is not an envelope cohort; valid: "
                         f"{list(ENVELOPE_POPULATIONS)}")
    split = name.removeprefix(POPULATION_PREFIX)
    return PatientPopulation(f"{name}:{limb}-{robot}", envelope_bodies(split, limb, robot),
                             envelope_conditions(split), skip_infeasible=True)


def population_names() -> list[str]:
    """Every population a name gives: the fixed ones and the envelope cohorts."""
    return [*POPULATIONS, *ENVELOPE_POPULATIONS]


def as_population(value: Any, limb: str | None = None, robot: str = "ur5e"
                  ) -> PatientPopulation:
    """A population from itself, the name of a shipped one, or a dict of its fields. An
    envelope cohort's name (``"envelope-train"``, ...) needs the scene: ``limb`` and
    ``robot``."""
    if isinstance(value, PatientPopulation):
        return value
    if isinstance(value, str):
        if value in ENVELOPE_POPULATIONS:
            if limb is None:
                raise ValueError(f"patients={value!r} is an envelope cohort, drawn per scene: "
                                 "give the limb (and robot) it is for")
            return envelope_population(value, limb, robot)
        if value not in POPULATIONS:
            raise ValueError(f"patients={value!r} is not a shipped population; valid: "
                             f"{population_names()} (or a PatientPopulation)")
        return POPULATIONS[value]
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {"name", "profiles", "conditions", "skip_infeasible"})
        if unknown:
            raise ValueError(f"patients has unknown field(s) {unknown}; valid: name, profiles, "
                             "conditions, skip_infeasible")
        return PatientPopulation(name=value.get("name", "custom"),
                                 profiles=value.get("profiles", ()),
                                 conditions=value.get("conditions", ()),
                                 skip_infeasible=value.get("skip_infeasible", False))
    raise ValueError(f"patients={value!r} must be a PatientPopulation, a dict of its fields or "
                     f"the name of a shipped population {population_names()}")
