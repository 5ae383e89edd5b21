"""Figures of one evaluated episode from the patient's side (``rehabbot plot`` draws them for
every ``trace.npz`` that holds the data):

===================================  ========================================================
file                                 content
===================================  ========================================================
``fig7_patient_joints_<label>``      each exercised joint's angle [deg] versus time, the
                                     prescribed path (the active target's angle, dashed), the
                                     joint's range-of-motion bounds (dotted, red, labelled
                                     with their values and source) and, in the panel's title,
                                     the excursion achieved against the one prescribed,
                                     flagged when it goes beyond (:mod:`.range_of_motion`)
``fig8_cuff_force_<label>``          the cuff force [N] versus time, its limit (dashed,
                                     labelled with its value and source: ISO/TS 15066's
                                     quasi-static limit of the body region under the cuff)
                                     and where the force first went above it
``fig9_work_<label>``                the robot's and the patient's cumulative work on the
                                     limb [J] since the reset, versus time; > 0: energy put
                                     into the limb, < 0: taken out of it
===================================  ========================================================

Every figure's title names the policy, the env and the patient; its legend sits outside the
axes; a safety stop is a dash-dotted line labelled with its rule
(:func:`~rehabbot.analysis.figures.mark_stop`). Every line carries a ``gid`` (``"measured"``,
``"prescribed"``, ``"rom-low"``, ``"rom-high"``, ``"cuff-force"``, ``"force-limit"``,
``"limit-crossing"``, ``"robot-work"``, ``"patient-work"``, ``"safety-stop"``) so that a reader
(or a test) can find it. A trace without the data a figure needs raises ``ValueError`` naming
the file and the missing keys (:func:`has_patient_data` tells beforehand).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.figures import (
    GIDS,
    LIMIT_COLOR,
    SOURCE_NOT_RECORDED,
    _as_trace,
    legend_outside,
    mark_stop,
    new_figure,
    trace_title,
)
from rehabbot.analysis.range_of_motion import (
    BEYOND_PRESCRIBED,
    PRESCRIBED_MIN_DEG,
    beyond_prescribed,
    range_of_motion_deg,
)
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


def joint_names(trace: Trace) -> list[str]:
    """The exercised joints' names (``joint j`` when the trace does not record them)."""
    n = np.asarray(trace.patient_qpos_rad).shape[1]
    return (list(trace.patient_joint_names) if trace.patient_joint_names is not None
            else [f"joint {j}" for j in range(n)])


def excursion_text(name: str, achieved_deg: float, prescribed_deg: float) -> tuple[str, bool]:
    """A joint panel's title, the excursion achieved against the one prescribed, and whether
    it is flagged (the limb went beyond the prescription)."""
    if prescribed_deg < PRESCRIBED_MIN_DEG:
        return f"{name}: not exercised (moved {achieved_deg:.0f}°)", False
    ratio = achieved_deg / prescribed_deg
    text = (f"{name}: achieved {achieved_deg:.0f}° of {prescribed_deg:.0f}° prescribed "
            f"({ratio:.2f})")
    flagged = beyond_prescribed(ratio)
    if flagged:
        text += f" ⚠ {BEYOND_PRESCRIBED}"
    return text, flagged


def build_patient_joints(trace: Trace | Path | str) -> Figure:
    """Each exercised joint: measured angle, prescribed path and range-of-motion bounds (with
    their values and source); each panel's title gives the excursion achieved against the one
    prescribed, flagged in red when it goes beyond (above 1)."""
    trace = _as_trace(trace)
    prescribed = prescribed_path_deg(trace)
    angles = np.degrees(np.asarray(trace.patient_qpos_rad, dtype=float))
    achieved_deg, prescribed_deg = range_of_motion_deg(trace.patient_qpos_rad,
                                                       trace.target_patient_deg)
    names = joint_names(trace)
    n = angles.shape[1]
    figure = new_figure((9.0, 2.6 * n + 0.6))
    axes = np.atleast_1d(figure.subplots(n, 1, sharex=True, squeeze=False)).ravel()
    source = trace.patient_range_source or SOURCE_NOT_RECORDED
    for j, ax in enumerate(axes):
        ax.plot(trace.time_s, angles[:, j], color=MEASURED_COLOR, linewidth=1.4,
                label="measured", gid=GIDS["measured"])
        ax.plot(trace.time_s, prescribed[:, j], color=PRESCRIBED_COLOR, linestyle="--",
                linewidth=1.2, drawstyle="steps-post", label="prescribed (active target)",
                gid=GIDS["prescribed"])
        if trace.patient_range_deg is not None:
            low, high = np.asarray(trace.patient_range_deg, dtype=float)[j]
            ax.axhline(low, color=LIMIT_COLOR, linestyle=":", linewidth=1.2,
                       label=f"range of motion {low:g}° to {high:g}°\n({source})",
                       gid=GIDS["rom-low"])
            ax.axhline(high, color=LIMIT_COLOR, linestyle=":", linewidth=1.2,
                       label="_nolegend_", gid=GIDS["rom-high"])
        mark_stop(ax, trace)
        title, flagged = excursion_text(names[j], float(achieved_deg[j]),
                                        float(prescribed_deg[j]))
        ax.set_title(title, fontsize="medium", color=LIMIT_COLOR if flagged else "black",
                     fontweight="bold" if flagged else "normal")
        ax.set_ylabel(f"{names[j]} [deg]")
        ax.grid(True, alpha=0.3)
        legend_outside(ax)
    axes[-1].set_xlabel("time [s]")
    figure.suptitle(trace_title("Patient joint angles", trace))
    return figure


def first_crossing(force_n: np.ndarray, limit_n: float) -> int | None:
    """The first row where the force is above the limit, None if it never is."""
    above = np.flatnonzero(np.asarray(force_n, dtype=float) > limit_n)
    return int(above[0]) if above.size else None


def build_cuff_force(trace: Trace | Path | str) -> Figure:
    """The cuff force versus time, its limit (value and source) and where the force first
    went above it."""
    trace = _as_trace(trace)
    _require(trace, FORCE_KEYS, "cuff force")
    force = np.asarray(trace.interaction_force_n, dtype=float)
    limit = float(trace.cuff_force_limit_n)
    source = trace.cuff_force_limit_source or SOURCE_NOT_RECORDED
    figure = new_figure((9.0, 3.6))
    ax = figure.subplots()
    ax.plot(trace.time_s, force, color=MEASURED_COLOR, linewidth=1.4, label="cuff force",
            gid=GIDS["cuff-force"])
    ax.axhline(limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.2,
               label=f"limit {limit:g} N\n({source})", gid=GIDS["force-limit"])
    crossing = first_crossing(force, limit)
    if crossing is not None:
        ax.plot([trace.time_s[crossing]], [force[crossing]], linestyle="none", marker="o",
                markersize=8, markerfacecolor="none", markeredgecolor=LIMIT_COLOR,
                markeredgewidth=2.0, gid=GIDS["crossing"],
                label=f"above the limit from {trace.time_s[crossing]:.2f} s (peak "
                      f"{np.nanmax(force):.0f} N)")
    mark_stop(ax, trace)
    ax.set_ylim(0.0, 1.1 * max(limit, float(np.nanmax(force, initial=0.0))))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cuff force [N]")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)
    figure.suptitle(trace_title("Cuff force", trace))
    return figure


WORK_SIGN_NOTE = ("work > 0: puts energy into the limb (drives its motion)\n"
                  "work < 0: takes energy out (brakes or resists its motion)")


def build_work(trace: Trace | Path | str) -> Figure:
    """The robot's and the patient's cumulative work on the limb since the reset, versus
    time, with what its sign means."""
    trace = _as_trace(trace)
    _require(trace, WORK_KEYS, "work")
    figure = new_figure((9.0, 3.6))
    ax = figure.subplots()
    robot = np.asarray(trace.robot_work_j, dtype=float)
    patient = np.asarray(trace.patient_work_j, dtype=float)
    ax.plot(trace.time_s, robot, color=ROBOT_COLOR, linewidth=1.4,
            label=f"robot, through the cuff (end: {robot[-1]:+.2f} J)", gid=GIDS["robot-work"])
    ax.plot(trace.time_s, patient, color=PATIENT_COLOR, linewidth=1.4,
            label=f"patient, by its muscles (end: {patient[-1]:+.2f} J)",
            gid=GIDS["patient-work"])
    ax.axhline(0.0, color="0.6", linewidth=0.8)
    mark_stop(ax, trace)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cumulative work\non the limb [J]")
    ax.grid(True, alpha=0.3)
    legend = legend_outside(ax, title=WORK_SIGN_NOTE, title_fontsize="small")
    legend.set_alignment("left")  # the sign note reads as a paragraph
    figure.suptitle(trace_title("Cumulative work on the limb since the start", trace))
    return figure


# (file prefix, builder): what plot_all writes for a trace with patient data
PATIENT_FIGURES = (("fig7_patient_joints", build_patient_joints),
                   ("fig8_cuff_force", build_cuff_force),
                   ("fig9_work", build_work))
