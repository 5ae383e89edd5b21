"""Figures of one evaluated episode, as in the paper: Fig. 5 (joint velocity, acceleration
and jerk), Fig. 6 (actuator torques with their limits) and Fig. 3 (the tool's 3-D path over the
numbered targets); and the helpers every figure uses (a pyplot-free Agg figure, saving in
several formats).

``build_*`` return :class:`matplotlib.figure.Figure` objects (no pyplot, no global state);
``plot_*`` build, save and return the written paths. Importing this module does not import
matplotlib; a missing matplotlib raises an ``ImportError`` that says to
``pip install "rehabbot[plot]"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.traces import Trace, load_trace

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

DEFAULT_SMOOTH = 20
DEFAULT_FORMATS: tuple[str, ...] = ("png", "pdf")
SUPPORTED_FORMATS: tuple[str, ...] = ("png", "pdf", "svg")
SOURCES: tuple[str, ...] = ("train", "eval")
GRID_POINTS = 200
TOOL_PATH_COLOR = "#8000c0"
TARGET_PATH_COLOR = "0.5"
LIMIT_COLOR = "#d62728"
DPI = 150

ALGO_ORDER: tuple[str, ...] = ("ppo", "sac", "td3")
ALGO_COLORS: dict[str, str] = {"ppo": "#1f77b4", "sac": "#ff7f0e", "td3": "#2ca02c"}
EXTRA_COLORS: tuple[str, ...] = ("#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


def new_figure(figsize: tuple[float, float]) -> Figure:
    """A pyplot-free figure with an Agg canvas."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as err:
        raise ImportError(
            'plotting needs matplotlib: pip install "rehabbot[plot]"'
        ) from err
    figure = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def check_formats(formats: Sequence[str]) -> tuple[str, ...]:
    cleaned = tuple(fmt.lower().lstrip(".") for fmt in formats)
    if not cleaned:
        raise ValueError("no output format given")
    bad = [fmt for fmt in cleaned if fmt not in SUPPORTED_FORMATS]
    if bad:
        raise ValueError(
            f"unsupported format {bad[0]!r} (choose from {', '.join(SUPPORTED_FORMATS)})"
        )
    return tuple(dict.fromkeys(cleaned))


def save_figure(figure: Figure, out_dir: Path | str, stem: str,
                formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write ``<out_dir>/<stem>.<fmt>`` for each format; creates ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for fmt in check_formats(formats):
        target = out / f"{stem}.{fmt}"
        figure.savefig(target, format=fmt, dpi=DPI)
        written.append(target)
    return written


def _as_trace(trace: Trace | Path | str) -> Trace:
    return trace if isinstance(trace, Trace) else load_trace(trace)


def _finite_differences(trace: Trace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint velocity, acceleration and jerk (:func:`.metrics.finite_differences`)."""
    from rehabbot.analysis.metrics import finite_differences

    try:
        return finite_differences(trace.robot_qpos_rad, trace.dt_s)
    except ValueError as err:
        raise ValueError(f"{trace.path}: cannot differentiate the joint angles ({err})") from err


def build_kinematics(trace: Trace | Path | str) -> Figure:
    """Fig. 5: joint velocity, acceleration and jerk versus time, one line per joint."""
    trace = _as_trace(trace)
    velocity, acceleration, jerk = _finite_differences(trace)
    figure = new_figure((8.0, 8.0))
    axes: list[Axes] = list(figure.subplots(3, 1, sharex=True))
    panels = (
        (velocity, "velocity [rad/s]"),
        (acceleration, "acceleration [rad/s²]"),
        (jerk, "jerk [rad/s³]"),
    )
    for ax, (values, ylabel) in zip(axes, panels, strict=True):
        for j, name in enumerate(trace.joint_names):
            ax.plot(trace.time_s, values[:, j], linewidth=1.2, label=name)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[-1].set_xlabel("time [s]")
    figure.suptitle(f"Robot joint kinematics: {trace.policy} on {trace.env_id}")
    return figure


def plot_kinematics(trace_path: Trace | Path | str, out_dir: Path | str,
                    formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 5 ``fig5_kinematics_<label>.*`` for one trace."""
    return _plot_trace(build_kinematics, "fig5_kinematics", trace_path, out_dir, formats)


def _plot_trace(build, prefix: str, trace_path: Trace | Path | str, out_dir: Path | str,
                formats: Sequence[str]) -> list[Path]:
    """Build one per-trace figure and save it as ``<prefix>_<label>.*``."""
    check_formats(formats)
    trace = _as_trace(trace_path)
    return save_figure(build(trace), out_dir, f"{prefix}_{trace.label}", formats)


def build_torques(trace: Trace | Path | str) -> Figure:
    """Fig. 6: one panel per joint (2×3 grid): torque versus time, ± limit dashed."""
    trace = _as_trace(trace)
    n_joints = len(trace.joint_names)
    n_cols = min(3, n_joints)
    n_rows = math.ceil(n_joints / n_cols)
    figure = new_figure((4.0 * n_cols, 2.8 * n_rows))
    axes = np.atleast_1d(figure.subplots(n_rows, n_cols, sharex=True, squeeze=False)).ravel()
    for j, ax in enumerate(axes):
        if j >= n_joints:
            ax.set_visible(False)
            continue
        limit = float(trace.torque_limit_nm[j])
        ax.plot(trace.time_s, trace.robot_torque_nm[:, j], color="#1f77b4", linewidth=1.2,
                label="torque")
        ax.axhline(limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.0, label="limit")
        ax.axhline(-limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.0)
        ax.set_title(trace.joint_names[j], fontsize="medium")
        peak = float(np.nanmax(np.abs(trace.robot_torque_nm[:, j]), initial=0.0))
        span = max(1.15 * abs(limit), 1.05 * peak, 1e-3)
        ax.set_ylim(-span, span)
        ax.grid(True, alpha=0.3)
        if j % n_cols == 0:
            ax.set_ylabel("torque [N·m]")
        if j >= n_joints - n_cols:
            ax.set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize="small")
    figure.suptitle(f"Actuator torques: {trace.policy} on {trace.env_id}")
    return figure


def plot_torques(trace_path: Trace | Path | str, out_dir: Path | str,
                 formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 6 ``fig6_torques_<label>.*`` for one trace."""
    return _plot_trace(build_torques, "fig6_torques", trace_path, out_dir, formats)


def build_tool_path(trace: Trace | Path | str) -> Figure:
    """Fig. 3: 3-D tool path (purple) and numbered targets, equal axes, robot base frame."""
    trace = _as_trace(trace)
    figure = new_figure((7.0, 6.5))
    try:
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
    except ImportError as err:  # pragma: no cover - ships with matplotlib
        raise ImportError('plotting needs matplotlib: pip install "rehabbot[plot]"') from err
    ax = figure.add_subplot(projection="3d")
    path = trace.tool_pos_m
    targets = trace.target_tool_pos_m
    ax.plot(path[:, 0], path[:, 1], path[:, 2], color=TOOL_PATH_COLOR, linewidth=2.0,
            label="tool path")
    ax.scatter(*path[0], color=TOOL_PATH_COLOR, marker="o", s=30, label="start")
    if len(targets):
        ax.plot(targets[:, 0], targets[:, 1], targets[:, 2], color=TARGET_PATH_COLOR,
                linestyle="--", linewidth=1.0, label="target sequence")
        ax.scatter(targets[:, 0], targets[:, 1], targets[:, 2], color="black", marker="X",
                   s=50, depthshade=False, label="targets")
        for i, point in enumerate(targets, start=1):
            ax.text(point[0], point[1], point[2], f" {i}", color="black", fontsize=10,
                    fontweight="bold")
    points = np.vstack([path, targets]) if len(targets) else path
    low, high = points.min(axis=0), points.max(axis=0)
    center = (low + high) / 2
    half = max(float((high - low).max()) / 2 * 1.1, 0.01)
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title(f"Tool path (robot base frame): {trace.policy} on {trace.env_id}")
    return figure


def plot_tool_path(trace_path: Trace | Path | str, out_dir: Path | str,
                   formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 3 ``fig3_tool_path_<label>.*`` for one trace."""
    return _plot_trace(build_tool_path, "fig3_tool_path", trace_path, out_dir, formats)
