"""Figures of one evaluated episode, as in the paper: Fig. 5 (joint velocity, acceleration
and jerk), Fig. 6 (actuator torques with their limits) and Fig. 3 (the tool's 3-D path over the
numbered targets); and the helpers every figure uses (a pyplot-free Agg figure, saving in
several formats).

``build_*`` return :class:`matplotlib.figure.Figure` objects (no pyplot, no global state);
``plot_*`` build, save and return the written paths. Importing this module does not import
matplotlib; a missing matplotlib raises an ``ImportError`` that says to
``pip install "rehabbot[plot]"``.

What every figure of an evaluated episode shows, so that it reads without its folder: its title
names the policy, the env and the patient (``patient: female, 1.6 m, 55 kg; MAS 3
spasticity``, :func:`trace_title`); every limit line is labelled with its value and source
(``limit ±150 N·m (UR5e rated joint torque, Universal Robots)``); legends sit outside the axes,
off the data (:func:`legend_outside`); and a safety stop is marked where it happened, with its
rule (:func:`mark_stop`). Lines carry a ``gid`` naming what they are (:data:`GIDS`), so that a
reader or a test finds them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.traces import Trace, load_trace
from rehabbot.common.extras import missing_module_message
from rehabbot.common.files import atomic_save_verified
from rehabbot.envs.registration import env_short_name

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
STOP_COLOR = "#ff7f0e"
DPI = 150
SOURCE_NOT_RECORDED = "source not recorded"
# gid of each kind of line, for readers and tests: ax.get_lines() with line.get_gid() == ...
GIDS = {"stop": "safety-stop", "torque-limit": "torque-limit", "force-limit": "force-limit",
        "crossing": "limit-crossing", "rom-low": "rom-low", "rom-high": "rom-high",
        "measured": "measured", "prescribed": "prescribed", "cuff-force": "cuff-force",
        "robot-work": "robot-work", "patient-work": "patient-work"}

# Fig. 3 target labels (see :func:`choose_target_labels`)
TARGET_MERGE_FRACTION = 0.02
LABEL_FONTSIZE_PT = 10.0
LABEL_CHAR_WIDTH_EM = 0.7
LABEL_HEIGHT_EM = 1.2
LABEL_DESCENT_EM = 0.3
LABEL_GAP_PT = 3.0
LABEL_OFFSET_PT = (4.0, 4.0)  # right of and above the target: its "X" (s=50 pt²) is 7 pt wide
LABEL_ZORDER = 10.0
# what the no-overlap rule guarantees between any two labels' anchors on the page
LABEL_MIN_SEPARATION_PT = (LABEL_FONTSIZE_PT * min(LABEL_HEIGHT_EM, LABEL_CHAR_WIDTH_EM)
                           + LABEL_GAP_PT)

ALGO_ORDER: tuple[str, ...] = ("ppo", "sac", "td3")
ALGO_COLORS: dict[str, str] = {"ppo": "#1f77b4", "sac": "#ff7f0e", "td3": "#2ca02c"}
EXTRA_COLORS: tuple[str, ...] = ("#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


def new_figure(figsize: tuple[float, float]) -> Figure:
    """A pyplot-free figure with an Agg canvas."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as err:
        raise ImportError(missing_module_message("plotting", "matplotlib")) from err
    figure = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def trace_title(what: str, trace: Trace) -> str:
    """A figure's title: what it shows, the policy and env, and on a second line the patient
    (profile and condition), so that a healthy and a MAS 3 run never look alike."""
    return (f"{what}: {trace.policy} on {env_short_name(trace.env_id)}\n"
            f"patient: {trace.patient_text}")


def legend_outside(ax: Axes, **kwargs) -> object:
    """``ax``'s legend to the right of the axes, off the data (the constrained layout makes
    room for it)."""
    options = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0,
               "fontsize": "small", **kwargs}
    return ax.legend(**options)


def stop_label(trace: Trace) -> str:
    """``"safety stop: cuff_force rule at 3.42 s"`` (the trace must have stopped)."""
    return f"safety stop: {trace.safety_violation} rule at {trace.stop_time_s:.2f} s"


def mark_stop(ax: Axes, trace: Trace, label: bool = True) -> object | None:
    """A vertical line at the time a safety rule stopped the episode, labelled with the rule;
    None (nothing drawn) when no rule stopped it."""
    if trace.stop_time_s is None:
        return None
    return ax.axvline(trace.stop_time_s, color=STOP_COLOR, linestyle="-.", linewidth=1.5,
                      label=stop_label(trace) if label else "_nolegend_", gid=GIDS["stop"],
                      zorder=3)


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
                formats: Sequence[str] = DEFAULT_FORMATS, dpi: int = DPI) -> list[Path]:
    """Write ``<out_dir>/<stem>.<fmt>`` for each format at ``dpi`` (PNG); creates ``out_dir``.

    Each file is written under a temporary name, read back (:func:`verify_figure`) and
    renamed: a full disk raises :class:`~rehabbot.common.errors.OutputError` and keeps an
    earlier file of the same name.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for fmt in check_formats(formats):
        target = out / f"{stem}.{fmt}"
        atomic_save_verified(target,
                             lambda name, fmt=fmt: figure.savefig(name, format=fmt, dpi=dpi),
                             lambda tmp, fmt=fmt: verify_figure(tmp, fmt))
        written.append(target)
    return written


def verify_figure(path: Path, fmt: str) -> None:
    """Read a written figure back: a PNG is decoded whole, a PDF must begin with ``%PDF``
    and end with ``%%EOF``, an SVG must parse as XML. Raises ValueError (or the reader's
    error) when the file is damaged."""
    path = Path(path)
    if fmt == "png":
        from PIL import Image  # matplotlib's own dependency

        with Image.open(path) as image:
            image.load()
    elif fmt == "pdf":
        data = path.read_bytes()
        if not data.startswith(b"%PDF") or b"%%EOF" not in data[-1024:]:
            raise ValueError("not a complete PDF")
    elif fmt == "svg":
        import xml.etree.ElementTree as ElementTree

        ElementTree.parse(path)  # our own file, just written


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
        mark_stop(ax, trace)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    legend_outside(axes[0])
    axes[-1].set_xlabel("time [s]")
    figure.suptitle(trace_title("Robot joint kinematics", trace))
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


def torque_limit_label(limit_nm: float, trace: Trace) -> str:
    """``"limit ±150 N·m (UR5e rated joint torque, Universal Robots)"``."""
    source = trace.torque_limit_source or SOURCE_NOT_RECORDED
    return f"limit ±{limit_nm:g} N·m\n({source})"


def build_torques(trace: Trace | Path | str) -> Figure:
    """Fig. 6: one panel per joint (2×3 grid): torque versus time, ± limit dashed and labelled
    with its value and source; one legend for all panels, below them."""
    trace = _as_trace(trace)
    n_joints = len(trace.joint_names)
    n_cols = min(3, n_joints)
    n_rows = math.ceil(n_joints / n_cols)
    figure = new_figure((4.0 * n_cols, 2.8 * n_rows + 0.8))
    axes = np.atleast_1d(figure.subplots(n_rows, n_cols, sharex=True, squeeze=False)).ravel()
    legend: dict[str, object] = {}
    for j, ax in enumerate(axes):
        if j >= n_joints:
            ax.set_visible(False)
            continue
        limit = float(trace.torque_limit_nm[j])
        line = ax.plot(trace.time_s, trace.robot_torque_nm[:, j], color="#1f77b4",
                       linewidth=1.2, label="torque")[0]
        legend.setdefault("torque", line)
        label = torque_limit_label(limit, trace)
        for sign in (1.0, -1.0):
            line = ax.axhline(sign * limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.0,
                              label=label if sign > 0 else "_nolegend_",
                              gid=GIDS["torque-limit"])
        legend.setdefault(label, line)
        stop = mark_stop(ax, trace)
        if stop is not None:
            legend.setdefault(stop.get_label(), stop)
        ax.set_title(f"{trace.joint_names[j]} (limit ±{limit:g} N·m)", fontsize="medium")
        peak = float(np.nanmax(np.abs(trace.robot_torque_nm[:, j]), initial=0.0))
        span = max(1.15 * abs(limit), 1.05 * peak, 1e-3)
        ax.set_ylim(-span, span)
        ax.grid(True, alpha=0.3)
        if j % n_cols == 0:
            ax.set_ylabel("torque [N·m]")
        if j >= n_joints - n_cols:
            ax.set_xlabel("time [s]")
    figure.legend(list(legend.values()), list(legend), loc="outside lower center",
                  ncols=min(3, len(legend)), fontsize="small")
    figure.suptitle(trace_title("Actuator torques", trace))
    return figure


def plot_torques(trace_path: Trace | Path | str, out_dir: Path | str,
                 formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 6 ``fig6_torques_<label>.*`` for one trace."""
    return _plot_trace(build_torques, "fig6_torques", trace_path, out_dir, formats)


@dataclass(frozen=True)
class TargetLabel:
    """One number label of Fig. 3: the 1-based numbers of the targets it names (ascending) and
    the tool position it is drawn at (that of its first target)."""

    numbers: tuple[int, ...]
    position_m: tuple[float, float, float]

    @property
    def text(self) -> str:
        return ", ".join(str(number) for number in self.numbers)


def group_coincident_targets(targets_m: np.ndarray, radius_m: float) -> list[tuple[int, ...]]:
    """0-based target indices grouped by place, in order of first visit: each target joins the
    first group whose first target lies within ``radius_m``, else starts a group (no chaining:
    a group never spans more than ``2 * radius_m``)."""
    targets_m = np.asarray(targets_m, dtype=float).reshape(-1, 3)
    groups: list[list[int]] = []
    for i, point in enumerate(targets_m):
        for group in groups:
            if np.linalg.norm(point - targets_m[group[0]]) <= radius_m:
                group.append(i)
                break
        else:
            groups.append([i])
    return [tuple(group) for group in groups]


def _label_box_pt(anchor_pt: np.ndarray, text: str,
                  fontsize_pt: float) -> tuple[float, float, float, float]:
    """Estimated extent (x0, y0, x1, y1) [pt] of left/baseline-aligned ``text`` at ``anchor_pt``:
    every character as wide as a bold digit or wider, the line's full height."""
    x0 = float(anchor_pt[0])
    y0 = float(anchor_pt[1]) - LABEL_DESCENT_EM * fontsize_pt
    return (x0, y0, x0 + LABEL_CHAR_WIDTH_EM * fontsize_pt * len(text),
            y0 + LABEL_HEIGHT_EM * fontsize_pt)


def _boxes_collide(a: tuple[float, float, float, float], b: tuple[float, float, float, float],
                   gap_pt: float) -> bool:
    """Whether two boxes (x0, y0, x1, y1) [pt] come closer than ``gap_pt``."""
    return (a[0] < b[2] + gap_pt and b[0] < a[2] + gap_pt
            and a[1] < b[3] + gap_pt and b[1] < a[3] + gap_pt)


def choose_target_labels(targets_m: np.ndarray, anchors_pt: np.ndarray, extent_m: float, *,
                         merge_fraction: float = TARGET_MERGE_FRACTION,
                         fontsize_pt: float = LABEL_FONTSIZE_PT,
                         gap_pt: float = LABEL_GAP_PT) -> list[TargetLabel]:
    """Which target number labels Fig. 3 draws, so that none overlap (pure; no rendering).

    ``targets_m`` (N, 3): the targets; ``anchors_pt`` (N, 2): where each projects on the page
    [pt]; ``extent_m``: the plot's axis span. Targets within ``merge_fraction × extent_m`` of a
    group's first target share one label ("2, 6"): Fig. 3 draws the span about 230-265 pt long,
    so 2 % of it is at most ~5 pt on the page in any view, less than the 7 pt "X" markers,
    which then overlap into one spot. Labels are then placed greedily: the first target's, the
    last target's (folded into the first label if the two would collide), then the others in
    order, each only if its estimated text box stays ``gap_pt`` clear of those already placed;
    any two placed labels' anchors are then :data:`LABEL_MIN_SEPARATION_PT` apart or more.
    Deterministic.
    """
    targets_m = np.asarray(targets_m, dtype=float).reshape(-1, 3)
    anchors_pt = np.asarray(anchors_pt, dtype=float).reshape(-1, 2)
    if len(anchors_pt) != len(targets_m):
        raise ValueError(f"{len(targets_m)} targets but {len(anchors_pt)} anchors")
    if not len(targets_m):
        return []
    groups = group_coincident_targets(targets_m, merge_fraction * extent_m)
    last = next(k for k, group in enumerate(groups) if len(targets_m) - 1 in group)
    order = list(dict.fromkeys([0, last, *range(len(groups))]))
    placed: list[tuple[tuple[int, ...], tuple[float, float, float, float]]] = []
    for k in order:
        box = _label_box_pt(anchors_pt[groups[k][0]], _numbers_text(groups[k]), fontsize_pt)
        if not any(_boxes_collide(box, other, gap_pt) for _, other in placed):
            placed.append((groups[k], box))
        elif k == last:  # only the first label is placed yet: name both there
            merged = tuple(sorted(placed[0][0] + groups[k]))
            placed[0] = (merged, _label_box_pt(anchors_pt[merged[0]],
                                               _numbers_text(merged), fontsize_pt))
    labels = []
    for group, _ in sorted(placed, key=lambda item: item[0]):
        x, y, z = (float(v) for v in targets_m[group[0]])
        labels.append(TargetLabel(tuple(i + 1 for i in group), (x, y, z)))
    return labels


def _numbers_text(indices: Sequence[int]) -> str:
    return ", ".join(str(i + 1) for i in indices)


def _page_points_pt(ax, points_m: np.ndarray) -> np.ndarray:
    """Where 3-D points land on the page [pt], with the axes' current view and layout."""
    from mpl_toolkits.mplot3d import proj3d

    xs, ys, _ = proj3d.proj_transform(points_m[:, 0], points_m[:, 1], points_m[:, 2],
                                      ax.get_proj())
    pixels = ax.transData.transform(np.column_stack([xs, ys]))
    return pixels * 72.0 / ax.figure.dpi


def build_tool_path(trace: Trace | Path | str) -> Figure:
    """Fig. 3: 3-D tool path (purple) and numbered targets, equal axes, robot base frame; one
    panel per robot (the bilateral env's two, each in its own base frame, right first)."""
    trace = _as_trace(trace)
    try:
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
    except ImportError as err:  # pragma: no cover - ships with matplotlib
        raise ImportError(missing_module_message("plotting", "matplotlib")) from err
    n_robots = trace.tool_pos_m.shape[1] // 3
    figure = new_figure((7.0 * n_robots, 7.5))
    names = ("right robot", "left robot") if n_robots == 2 else (None,) * n_robots
    for k, name in enumerate(names):
        ax = figure.add_subplot(1, n_robots, k + 1, projection="3d")
        columns = slice(3 * k, 3 * k + 3)
        _draw_tool_path(ax, trace.tool_pos_m[:, columns], trace.target_tool_pos_m[:, columns],
                        "robot base frame" if name is None else f"{name}, its base frame",
                        stop=stop_label(trace) if trace.stop_time_s is not None else None)
    figure.suptitle(trace_title("Tool path", trace))
    return figure


def _draw_tool_path(ax, path: np.ndarray, targets: np.ndarray, title: str,
                    stop: str | None = None) -> None:
    """One robot's tool path and numbered targets on the 3-D axes ``ax``; ``stop`` labels a
    marker where a safety rule stopped the episode (its last point)."""
    ax.plot(path[:, 0], path[:, 1], path[:, 2], color=TOOL_PATH_COLOR, linewidth=2.0,
            label="tool path")
    ax.scatter(*path[0], color=TOOL_PATH_COLOR, marker="o", s=30, label="start")
    if stop is not None:
        ax.scatter(*path[-1], facecolors="none", edgecolors=STOP_COLOR, marker="o", s=140,
                   linewidths=2.0, depthshade=False, label=stop, gid=GIDS["stop"],
                   zorder=LABEL_ZORDER)
    if len(targets):
        ax.plot(targets[:, 0], targets[:, 1], targets[:, 2], color=TARGET_PATH_COLOR,
                linestyle="--", linewidth=1.0, label="target sequence")
        markers = ax.scatter(targets[:, 0], targets[:, 1], targets[:, 2], color="black",
                             marker="X", s=50, depthshade=False, label="targets")
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
    ax.set_title(title, fontsize="medium")
    # The legend goes below the axes, off the data, before the layout is resolved for the
    # target labels: its height (one row per entry) is final now, and the targets' entry,
    # named once the labels are chosen, only changes its width, never the layout.
    provisional = "targets, labelled by number"
    if len(targets):
        markers.set_label(provisional)
    legend = ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.02), borderaxespad=0.0,
                       fontsize="small")
    if len(targets):
        text = _draw_target_labels(ax, targets, extent_m=2 * half)
        markers.set_label(text)
        for entry in legend.get_texts():
            if entry.get_text() == provisional:
                entry.set_text(text)


def _draw_target_labels(ax, targets_m: np.ndarray, extent_m: float) -> str:
    """Draw Fig. 3's target number labels (:func:`choose_target_labels`) once the view, limits
    and layout are final; returns the targets' legend entry."""
    from matplotlib.transforms import offset_copy

    ax.figure.draw_without_rendering()  # resolve the layout: where the axes sit on the page
    labels = choose_target_labels(targets_m, _page_points_pt(ax, targets_m), extent_m)
    dx_pt, dy_pt = LABEL_OFFSET_PT
    beside = offset_copy(ax.transData, fig=ax.figure, x=dx_pt, y=dy_pt, units="points")
    for label in labels:  # every label offset alike: their spacing is what was chosen
        ax.text(*label.position_m, label.text, color="black",
                fontsize=LABEL_FONTSIZE_PT, fontweight="bold", transform=beside,
                zorder=LABEL_ZORDER,  # over the markers, which mplot3d sorts by depth
                bbox={"boxstyle": "square,pad=0.05", "facecolor": "white", "edgecolor": "none",
                      "alpha": 0.7})
    if sum(len(label.numbers) for label in labels) < len(targets_m):
        return "targets, labelled by number (some omitted where crowded)"
    return "targets, labelled by number"


def plot_tool_path(trace_path: Trace | Path | str, out_dir: Path | str,
                   formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 3 ``fig3_tool_path_<label>.*`` for one trace."""
    return _plot_trace(build_tool_path, "fig3_tool_path", trace_path, out_dir, formats)
