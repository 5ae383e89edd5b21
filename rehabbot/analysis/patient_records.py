"""Who was in the chair in each evaluated episode, and the evaluation tabulated per patient.

:func:`patient_record` reads the episode's patient from the env that ran it (a
:class:`~rehabbot.envs.population.PopulationEnv` draws a new one every episode: its index in
the population, profile and condition; any other env: its one patient).
:func:`per_patient_summary` groups a report's episodes by patient (mean over each patient's
episodes) and :func:`format_patient_table` writes that as a Markdown table.
:func:`condition_text` words a condition as a therapist reads it (``"MAS 3 spasticity"``,
``"healthy, passive"``): every table and figure title names the patient with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.analysis.range_of_motion import BEYOND_PRESCRIBED, beyond_prescribed
from rehabbot.common.text_tables import markdown_table

# key in an episode's figures, column of the per-patient table, digits
PATIENT_METRICS: tuple[tuple[str, str, int], ...] = (
    ("success", "success rate [%]", 0),
    ("return", "return", 1),
    ("peak_cuff_force_n", "peak cuff force [N]", 1),
    ("robot_work_j", "robot work [J]", 2),
    ("patient_work_j", "patient work [J]", 2),
    ("assistance_ratio", "assistance ratio", 2),
    ("rom_achieved_fraction", "ROM achieved / prescribed", 2),
)


HEALTHY_TEXT = "healthy, passive"
EFFORT_WORDS = {"active_assisted": "active-assisted", "resistive": "resistive"}


def condition_text(condition: dict[str, Any] | None) -> str:
    """A condition (:meth:`~rehabbot.sim.conditions.PatientCondition.to_dict`'s fields, None
    for a healthy limb) as a therapist reads it: ``"MAS 3 spasticity"``,
    ``"MAS 2 spasticity, stiffness x1.5, ROM x0.8"``,
    ``"active-assisted (effort 30 %), strength 50 %"``, or ``"healthy, passive"``.
    Only the fields that differ from a healthy, passive limb are named; a field this function
    does not know is shown as ``name=value``, so nothing is left out."""
    if not condition:
        return HEALTHY_TEXT
    from rehabbot.sim.conditions import PatientCondition

    default = PatientCondition().to_dict()
    changed = {key: value for key, value in condition.items() if default.get(key) != value}
    if not changed:
        return HEALTHY_TEXT
    effort = condition.get("effort", default["effort"])
    words = []
    if "spasticity_mas" in changed:
        words.append(f"MAS {changed.pop('spasticity_mas')} spasticity")
    if "effort" in changed or "effort_fraction" in changed:
        changed.pop("effort", None)
        fraction = changed.pop("effort_fraction", default["effort_fraction"])
        if effort != "passive":
            words.append(f"{EFFORT_WORDS.get(effort, effort)} (effort "
                         f"{100 * float(fraction):.0f} %)")
    described = {
        "stiffness_scale": lambda v: f"stiffness x{v:g}",
        "rom_scale": lambda v: f"ROM x{v:g}",
        "strength_fraction": lambda v: f"strength {100 * v:.0f} %",
        "reaction_delay_s": lambda v: f"reaction delay {v:g} s",
        "fatigue_scale": lambda v: f"fatigue x{v:g}",
    }
    if "tremor_hz" in changed or "tremor_amplitude_nm" in changed:
        hz = float(changed.pop("tremor_hz", default["tremor_hz"]))
        amplitude = float(changed.pop("tremor_amplitude_nm", default["tremor_amplitude_nm"]))
        words.append(f"tremor {hz:g} Hz, {amplitude:g} N·m")
    for key, value in changed.items():
        words.append(described[key](float(value)) if key in described else f"{key}={value!r}")
    return ", ".join(words) if words else HEALTHY_TEXT


def profile_text(profile: dict[str, Any] | None) -> str:
    """``"male, 1.75 m, 75 kg"`` (empty for an env without a profile)."""
    if not profile:
        return ""
    return f"{profile['sex']}, {profile['height_m']:g} m, {profile['mass_kg']:g} kg"


def patient_record(env: gym.Env) -> dict[str, Any]:
    """The patient of ``env``'s current (or last) episode: ``index`` (in the population, else
    None), ``profile`` (height_m, mass_kg, sex), ``condition`` (its fields, None for a
    healthy, passive limb) and ``description``, one line: ``"#3: female, 1.6 m, 55 kg; MAS 2
    spasticity"`` (:func:`profile_text`, :func:`condition_text`)."""
    base = env.unwrapped
    index = getattr(base, "current_patient", None)
    patient_env = getattr(base, "current_env", base) if index is not None else base
    scene = getattr(patient_env, "scene", None)
    profile = getattr(scene, "profile", None)
    config = getattr(patient_env, "config", None)
    condition = getattr(getattr(config, "patient", None), "condition", None)
    profile_dict = None if profile is None else {
        "height_m": float(profile.height_m), "mass_kg": float(profile.mass_kg),
        "sex": str(profile.sex)}
    healthy = condition is None or condition.is_healthy
    condition_dict = None if healthy else condition.to_dict()
    text = "; ".join(part for part in (profile_text(profile_dict), condition_text(condition_dict))
                     if part)
    if index is not None:
        text = f"#{index}: {text}"
    return {"index": None if index is None else int(index), "profile": profile_dict,
            "condition": condition_dict, "description": text}


def _mean(values: Sequence[Any]) -> float | None:
    finite = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(finite)) if finite else None


def per_patient_summary(episodes: Sequence[dict]) -> list[dict[str, Any]]:
    """One entry per patient met in ``episodes`` (in order of first appearance): the patient,
    its episodes' seeds and the mean of each of :data:`PATIENT_METRICS`."""
    groups: dict[str, list[dict]] = {}
    for episode in episodes:
        patient = episode.get("patient") or {"description": "unknown"}
        groups.setdefault(patient["description"], []).append(episode)
    summary = []
    for group in groups.values():
        entry: dict[str, Any] = {"patient": group[0].get("patient"), "episodes": len(group),
                                 "seeds": [e["seed"] for e in group]}
        for key, _column, _digits in PATIENT_METRICS:
            entry[key] = _mean([e.get(key) for e in group])
        summary.append(entry)
    return summary


def format_patient_table(report: dict) -> str:
    """A Markdown table of ``report["per_patient"]``: one row per patient."""
    header = ["patient", "episodes", *(column for _key, column, _d in PATIENT_METRICS)]
    rows = []
    for entry in report["per_patient"]:
        patient = entry["patient"] or {}
        cells: list[Any] = [patient.get("description", "unknown"), entry["episodes"]]
        for key, _column, digits in PATIENT_METRICS:
            value = entry[key]
            if value is not None and key == "success":
                value = 100.0 * value
            cell = None if value is None else f"{value:.{digits}f}"
            if key == "rom_achieved_fraction" and beyond_prescribed(value):
                cell += f" ⚠ {BEYOND_PRESCRIBED}"
            cells.append(cell)
        rows.append(cells)
    return markdown_table(header, rows)
