"""Fig. 10: the controllers evaluated together, on one figure (``fig10_overlay_<env>``).

``rehabbot evaluate`` runs every policy on the same episodes (the same reset seeds, so the same
patient and targets); :func:`build_overlay` draws their first episodes over each other: one
panel per joint the exercise moves (its angle, with the targets' angles dotted), the cuff force
with its limit, and the robot's cumulative work on the limb. One colour per controller, the
same in every panel; a controller stopped by a safety rule ends in a cross labelled with the
rule. :func:`overlay_groups` finds the traces evaluated together (the label folders of one
evaluation folder).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.figures import (
    ALGO_COLORS,
    EXTRA_COLORS,
    LIMIT_COLOR,
    SOURCE_NOT_RECORDED,
    _as_trace,
    new_figure,
)
from rehabbot.analysis.patient_figures import FORCE_KEYS, JOINT_KEYS, WORK_KEYS, joint_names
from rehabbot.analysis.range_of_motion import PRESCRIBED_MIN_DEG, range_of_motion_deg
from rehabbot.analysis.traces import Trace
from rehabbot.envs.registration import env_short_name

if TYPE_CHECKING:
    from matplotlib.figure import Figure

OVERLAY_PREFIX = "fig10_overlay"
POLICY_GID = "policy:"  # gid of a controller's line: "policy:<label>"
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf",
          "#bcbd22", *EXTRA_COLORS, *ALGO_COLORS.values())


def _key(trace: Trace) -> tuple:
    return (trace.env_id, trace.seed, trace.patient)


def check_same_episode(traces: Sequence[Trace]) -> None:
    """``ValueError`` unless ``traces`` are two or more first episodes of one evaluation: the
    same env, reset seed and patient, each with the patient-side data, distinct policies."""
    if len(traces) < 2:
        raise ValueError(f"an overlay needs two traces or more, got {len(traces)}")
    first = traces[0]
    for trace in traces:
        missing = [key for key in (*JOINT_KEYS, *FORCE_KEYS, *WORK_KEYS)
                   if getattr(trace, key) is None]
        if missing:
            raise ValueError(f"{trace.path}: no overlay: the trace lacks {', '.join(missing)}")
        if _key(trace) != _key(first):
            raise ValueError(
                f"{trace.path} and {first.path} are not the same episode (env, seed, patient: "
                f"{_key(trace)} and {_key(first)}); an overlay draws controllers evaluated "
                "together")
    policies = [trace.policy for trace in traces]
    if len(set(policies)) < len(policies):
        raise ValueError(f"two traces of one policy in an overlay: {policies}")


def overlay_groups(traces: Sequence[Trace]) -> list[list[Trace]]:
    """The traces evaluated together, two or more per group: those in the label folders of one
    evaluation folder (``OUT/<label>/trace.npz``) with the same env, seed and patient, in the
    order found."""
    groups: dict[tuple, list[Trace]] = {}
    for trace in traces:
        if trace.patient_qpos_rad is None or trace.robot_work_j is None:
            continue
        folder = Path(trace.path).resolve().parent.parent
        groups.setdefault((folder, *_key(trace)), []).append(trace)
    return [group for group in groups.values()
            if len(group) > 1 and len({t.policy for t in group}) == len(group)]


def exercised_joints(trace: Trace) -> list[int]:
    """The joints the exercise moves (prescribed excursion >= ``PRESCRIBED_MIN_DEG``); all of
    them when it moves none."""
    _achieved, prescribed = range_of_motion_deg(trace.patient_qpos_rad, trace.target_patient_deg)
    moved = [j for j, value in enumerate(prescribed) if value >= PRESCRIBED_MIN_DEG]
    return moved or list(range(len(prescribed)))


def build_overlay(traces: Sequence[Trace | Path | str]) -> Figure:
    """The controllers of one evaluation over each other (see the module docstring)."""
    loaded = [_as_trace(trace) for trace in traces]
    check_same_episode(loaded)
    first = loaded[0]
    joints = exercised_joints(first)
    names = joint_names(first)
    n_panels = len(joints) + 2
    figure = new_figure((10.0, 2.3 * n_panels + 0.6))
    axes = list(np.atleast_1d(figure.subplots(n_panels, 1, sharex=True, squeeze=False)).ravel())
    handles: dict[str, object] = {}
    targets_deg = np.asarray(first.target_patient_deg, dtype=float)
    for ax, j in zip(axes, joints, strict=False):
        for level in np.unique(np.round(targets_deg[:, j], 6)):
            line = ax.axhline(level, color="0.6", linestyle=":", linewidth=1.0,
                              label="target angles", gid="targets")
            handles.setdefault("target angles", line)
        ax.set_ylabel(f"{names[j]} [deg]")
    force_ax, work_ax = axes[-2], axes[-1]
    limit = float(first.cuff_force_limit_n)
    source = first.cuff_force_limit_source or SOURCE_NOT_RECORDED
    label = f"cuff force limit {limit:g} N\n({source})"
    handles[label] = force_ax.axhline(limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.2,
                                      label=label, gid="force-limit")
    force_ax.set_ylabel("cuff force [N]")
    work_ax.set_ylabel("robot's cumulative\nwork on the limb [J]\n(> 0: into the limb)")
    work_ax.axhline(0.0, color="0.6", linewidth=0.8)
    peak_force = limit
    for k, trace in enumerate(loaded):
        color = COLORS[k % len(COLORS)]
        angles = np.degrees(np.asarray(trace.patient_qpos_rad, dtype=float))
        force = np.asarray(trace.interaction_force_n, dtype=float)
        series = [angles[:, j] for j in joints] + [force,
                                                   np.asarray(trace.robot_work_j, dtype=float)]
        peak_force = max(peak_force, float(np.nanmax(force, initial=0.0)))
        for ax, values in zip(axes, series, strict=True):
            line = ax.plot(trace.time_s, values, color=color, linewidth=1.5,
                           label=trace.policy, gid=f"{POLICY_GID}{trace.policy}")[0]
            handles.setdefault(trace.policy, line)
            if trace.stop_time_s is not None:
                stop = f"{trace.policy}: safety stop, {trace.safety_violation} rule"
                marker = ax.plot([trace.time_s[-1]], [values[-1]], linestyle="none",
                                 marker="X", markersize=10, color=color,
                                 markeredgecolor="black", label=stop, gid="safety-stop")[0]
                handles.setdefault(stop, marker)
    force_ax.set_ylim(0.0, 1.1 * peak_force)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    figure.legend(list(handles.values()), list(handles), loc="outside right upper",
                  fontsize="small")
    seed = "" if first.seed is None else f", seed {first.seed}"
    figure.suptitle(f"Controllers on the same episode: {env_short_name(first.env_id)}{seed}\n"
                    f"patient: {first.patient_text}")
    return figure
