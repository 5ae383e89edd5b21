"""Figures of one evaluated episode from the patient's side (``rehabbot plot`` draws them for
every ``trace.npz`` that holds the data):

===================================  ========================================================
file                                 content
===================================  ========================================================
``fig7_patient_joints_<label>``      each exercised joint's angle [deg] versus time, the
                                     prescribed path (the active target's angle, dashed) and
                                     the joint's range-of-motion bounds (dotted, red)
``fig8_cuff_force_<label>``          the cuff force [N] versus time and its limit (dashed)
``fig9_work_<label>``                the robot's and the patient's work on the limb [J] since
                                     the reset, versus time
===================================  ========================================================

Every line carries a label (``"measured"``, ``"prescribed"``, ``"range of motion"``,
``"cuff force"``, ``"limit"``, ``"robot"``, ``"patient"``) so that a reader (or a test) can
find it. A trace without the data a figure needs raises ``ValueError`` naming the file and the
missing keys (:func:`has_patient_data` tells beforehand).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.figures import LIMIT_COLOR, _as_trace, new_figure
from rehabbot.analysis.traces import Trace

if TYPE_CHECKING:
    from matplotlib.figure import Figure

JOINT_KEYS = ("patient_qpos_rad", "target_index", "target_patient_deg")
FORCE_KEYS = ("interaction_force_n", "cuff_force_limit_n")
WORK_KEYS = ("robot_work_j", "patient_work_j")
MEASURED_COLOR = "#1f77b4"
PRESCRIBED_COLOR = "0.35"
ROBOT_COLOR = "#8000c0"
PATIENT_COLOR = "#2ca02c"


def _missing(trace: Trace, keys: Sequence[str]) -> list[str]:
    return [key for key in keys if getattr(trace, key) is None]


def has_patient_data(trace: Trace) -> bool:
    """Whether ``trace`` holds what every patient-side figure needs."""
    return not _missing(trace, (*JOINT_KEYS, *FORCE_KEYS, *WORK_KEYS))


def _require(trace: Trace, keys: Sequence[str], what: str) -> None:
    missing = _missing(trace, keys)
    if missing:
        raise ValueError(f"{trace.path}: no {what} figure: the trace lacks {', '.join(missing)} "
                         "(evaluate the policy again with this version of rehabbot)")


def prescribed_path_deg(trace: Trace) -> np.ndarray:
    """(T + 1, 3) the exercised joints' prescribed angles: the active target's, each row."""
    _require(trace, JOINT_KEYS, "patient joint")
    index = np.clip(np.asarray(trace.target_index, dtype=int), 0,
                    len(trace.target_patient_deg) - 1)
    return np.asarray(trace.target_patient_deg, dtype=float)[index]


def build_patient_joints(trace: Trace | Path | str) -> Figure:
    """Each exercised joint: measured angle, prescribed path and range-of-motion bounds."""
    trace = _as_trace(trace)
    prescribed = prescribed_path_deg(trace)
    angles = np.degrees(np.asarray(trace.patient_qpos_rad, dtype=float))
    n = angles.shape[1]
    names = (list(trace.patient_joint_names) if trace.patient_joint_names is not None
             else [f"joint {j}" for j in range(n)])
    figure = new_figure((8.0, 2.6 * n))
    axes = np.atleast_1d(figure.subplots(n, 1, sharex=True, squeeze=False)).ravel()
    for j, ax in enumerate(axes):
        ax.plot(trace.time_s, angles[:, j], color=MEASURED_COLOR, linewidth=1.4,
                label="measured")
        ax.plot(trace.time_s, prescribed[:, j], color=PRESCRIBED_COLOR, linestyle="--",
                linewidth=1.2, drawstyle="steps-post", label="prescribed")
        if trace.patient_range_deg is not None:
            low, high = np.asarray(trace.patient_range_deg, dtype=float)[j]
            ax.axhline(low, color=LIMIT_COLOR, linestyle=":", linewidth=1.0,
                       label="range of motion")
            ax.axhline(high, color=LIMIT_COLOR, linestyle=":", linewidth=1.0)
        ax.set_ylabel(f"{names[j]} [deg]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    figure.suptitle(f"Patient joint angles: {trace.policy} on {trace.env_id}")
    return figure


def build_cuff_force(trace: Trace | Path | str) -> Figure:
    """The cuff force versus time, with the cuff's force limit."""
    trace = _as_trace(trace)
    _require(trace, FORCE_KEYS, "cuff force")
    force = np.asarray(trace.interaction_force_n, dtype=float)
    limit = float(trace.cuff_force_limit_n)
    figure = new_figure((8.0, 3.2))
    ax = figure.subplots()
    ax.plot(trace.time_s, force, color=MEASURED_COLOR, linewidth=1.4, label="cuff force")
    ax.axhline(limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.0, label="limit")
    ax.set_ylim(0.0, 1.1 * max(limit, float(np.nanmax(force, initial=0.0))))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cuff force [N]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize="small")
    figure.suptitle(f"Cuff force: {trace.policy} on {trace.env_id}")
    return figure


def build_work(trace: Trace | Path | str) -> Figure:
    """The robot's and the patient's work on the limb since the reset, versus time."""
    trace = _as_trace(trace)
    _require(trace, WORK_KEYS, "work")
    figure = new_figure((8.0, 3.2))
    ax = figure.subplots()
    ax.plot(trace.time_s, trace.robot_work_j, color=ROBOT_COLOR, linewidth=1.4, label="robot")
    ax.plot(trace.time_s, trace.patient_work_j, color=PATIENT_COLOR, linewidth=1.4,
            label="patient")
    ax.axhline(0.0, color="0.6", linewidth=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("work on the limb [J]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize="small")
    figure.suptitle(f"Work on the limb: {trace.policy} on {trace.env_id}")
    return figure


# (file prefix, builder): what plot_all writes for a trace with patient data
PATIENT_FIGURES = (("fig7_patient_joints", build_patient_joints),
                   ("fig8_cuff_force", build_cuff_force),
                   ("fig9_work", build_work))
