"""Who was in the chair in each evaluated episode, and the evaluation tabulated per patient.

:func:`patient_record` reads the episode's patient from the env that ran it (a
:class:`~rehabbot.envs.population.PopulationEnv` draws a new one every episode: its index in
the population, profile and condition; any other env: its one patient).
:func:`per_patient_summary` groups a report's episodes by patient (mean over each patient's
episodes) and :func:`format_patient_table` writes that as a Markdown table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.tables import markdown_table

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


def patient_record(env: gym.Env) -> dict[str, Any]:
    """The patient of ``env``'s current (or last) episode: ``index`` (in the population, else
    None), ``profile`` (height_m, mass_kg, sex), ``condition`` (its fields, None for a
    healthy, passive limb) and ``description`` (one line)."""
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
    text = "" if profile is None else \
        f"{profile.sex} {profile.height_m:g} m {profile.mass_kg:g} kg"
    text += ", " + ("healthy, passive" if healthy else condition.describe())
    if index is not None:
        text = f"#{index}: {text}"
    return {"index": None if index is None else int(index), "profile": profile_dict,
            "condition": None if healthy else condition.to_dict(), "description": text}


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
            cells.append(None if value is None else f"{value:.{digits}f}")
        rows.append(cells)
    return markdown_table(header, rows)
