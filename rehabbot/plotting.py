"""Figures of the RehabBot paper, drawn from the user's own training runs and evaluated episodes.

Figures (each written as PNG and PDF by default):

================================  ===========  ==============================================
file                              paper figure content
================================  ===========  ==============================================
``fig4_learning_curves``          Fig. 4       episode return, episode length and success rate
                                               versus environment steps: one line per
                                               algorithm (mean over seeds) with a ± std band
``fig5_kinematics_<label>``       Fig. 5       joint velocity, acceleration and jerk of the
                                               robot versus time in one evaluated episode
``fig6_torques_<label>``          Fig. 6       actuator torque of each robot joint versus time,
                                               with the torque limits as dashed lines
``fig3_tool_path_<label>``        Fig. 3       3-D tool path (purple) with the numbered targets
                                               in order, robot base frame, equal axes
================================  ===========  ==============================================

``<label>`` is the trace's policy and the short env name (``sac-seed0_rehab-reach-v0``),
sanitised for file names. When runs of several env ids are plotted together, Fig. 4 is one
figure per env id, ``fig4_learning_curves_<env-short>``; with a single env id the file is
``fig4_learning_curves``.

Inputs:

* training run directories written by ``rehabbot train`` (``<root>/<env>/<algo>/seed<k>/``
  with ``manifest.json``, ``monitor/*.monitor.csv`` and optionally ``eval/evaluations.npz``),
  discovered recursively by :func:`load_runs`;
* evaluated-episode traces ``trace.npz`` written by ``rehabbot evaluate``, discovered
  recursively by :func:`find_traces`. :func:`plot_all` asks
  :func:`rehabbot.evaluation.ensure_trace` for a trace of every run that has a final
  ``model.zip`` but no trace yet.

``build_*`` functions return :class:`matplotlib.figure.Figure` objects (no pyplot, no global
state, Agg canvas); ``plot_*`` functions build, save and return the written paths. Importing
this module does not import matplotlib; a missing matplotlib raises an :class:`ImportError`
that says to ``pip install "rehabbot[plot]"``.

Command line: ``rehabbot plot RUN_DIR...`` (see :func:`add_plot_parser`).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
import warnings
import zipfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

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
_EXTRA_COLORS: tuple[str, ...] = ("#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")

MANIFEST_NAME = "manifest.json"
TRACE_NAME = "trace.npz"
MODEL_NAME = "model.zip"
EVALUATIONS_PATH = Path("eval") / "evaluations.npz"

_TRACE_KEYS: tuple[str, ...] = (
    "env_id", "policy", "dt_s", "time_s", "robot_qpos_rad", "robot_torque_nm",
    "torque_limit_nm", "joint_names", "tool_pos_m", "target_tool_pos_m",
)


# --------------------------------------------------------------------------- data


@dataclass
class RunRecord:
    """One training run: its manifest and its finished training episodes in order.

    ``steps[i]`` is the cumulative number of environment steps (over all sub-envs) when
    episode ``i`` finished; ``successes`` is 1.0/0.0, NaN where the monitor did not log it.
    """

    path: Path
    env_id: str
    algo: str
    seed: int
    manifest: dict[str, Any]
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    returns: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    successes: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_episodes(self) -> int:
        return len(self.steps)


@dataclass
class EvalCurve:
    """Deterministic evaluations of one run (``eval/evaluations.npz``), averaged per point."""

    steps: np.ndarray
    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray


@dataclass
class Trace:
    """One evaluated episode (``trace.npz``)."""

    path: Path
    env_id: str
    policy: str
    dt_s: float
    time_s: np.ndarray
    robot_qpos_rad: np.ndarray
    robot_torque_nm: np.ndarray
    torque_limit_nm: np.ndarray
    joint_names: list[str]
    tool_pos_m: np.ndarray
    target_tool_pos_m: np.ndarray

    @property
    def label(self) -> str:
        """``<policy>_<env-short>``, safe as part of a file name."""
        return sanitize(f"{self.policy}_{env_short(self.env_id)}")


def env_short(env_id: str) -> str:
    """``"rehabbot/rehab-reach-v0"`` -> ``"rehab-reach-v0"``."""
    return env_id.rsplit("/", 1)[-1]


def sanitize(text: str) -> str:
    """Keep letters, digits, ``.``, ``_`` and ``-``; anything else becomes ``-``."""
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.")
    return cleaned or "unnamed"


def _check_exists(paths: Sequence[Path | str]) -> list[Path]:
    result = []
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise ValueError(f"{path}: no such file or directory")
        result.append(path)
    return result


def _find(paths: Sequence[Path | str], name: str) -> list[Path]:
    """Files called ``name`` at or below each path (a path may also be the file itself)."""
    found: dict[Path, None] = {}
    for path in _check_exists(paths):
        if path.is_file():
            candidates: Iterable[Path] = [path] if path.name == name else []
        else:
            candidates = sorted(path.rglob(name))
        for candidate in candidates:
            found.setdefault(candidate.resolve(), None)
    return list(found)


def find_traces(paths: Sequence[Path | str]) -> list[Path]:
    """All ``trace.npz`` files at or below ``paths`` (sorted per path, without duplicates).

    Raises:
        ValueError: a path does not exist.
    """
    return _find(paths, TRACE_NAME)


def _parse_bool(text: str) -> float:
    value = text.strip().lower()
    if value in ("true", "1", "1.0"):
        return 1.0
    if value in ("false", "0", "0.0"):
        return 0.0
    return math.nan


def read_monitor_csv(path: Path) -> dict[str, np.ndarray]:
    """Columns ``r``, ``l``, ``t``, ``is_success`` of one SB3 Monitor file as float arrays.

    Raises:
        ValueError: the file is not a readable Monitor CSV (names the file).
    """
    try:
        with path.open(newline="", encoding="utf-8") as stream:
            first = stream.readline()
            if not first.startswith("#"):
                raise ValueError("missing the '#{...}' header line")
            reader = csv.DictReader(stream)
            missing = {"r", "l", "t"} - set(reader.fieldnames or ())
            if missing:
                raise ValueError(f"missing column(s) {', '.join(sorted(missing))}")
            rows = list(reader)
        returns = np.array([float(row["r"]) for row in rows], dtype=float)
        lengths = np.array([float(row["l"]) for row in rows], dtype=float)
        times = np.array([float(row["t"]) for row in rows], dtype=float)
        successes = np.array(
            [_parse_bool(row.get("is_success") or "") for row in rows], dtype=float
        )
    except (OSError, UnicodeDecodeError, csv.Error, ValueError, TypeError) as err:
        raise ValueError(f"{path}: not a readable Monitor CSV file ({err})") from err
    if not (np.all(np.isfinite(lengths)) and np.all(lengths >= 0)):
        raise ValueError(f"{path}: not a readable Monitor CSV file (bad episode lengths)")
    return {"r": returns, "l": lengths, "t": times, "is_success": successes}


def merge_monitors(monitors: Sequence[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Merge sub-env monitor columns by wall time; adds ``steps`` = cumulative ``l``."""
    if not monitors:
        empty = np.zeros(0)
        return {"r": empty, "l": empty, "t": empty, "is_success": empty, "steps": empty}
    merged = {key: np.concatenate([m[key] for m in monitors]) for key in monitors[0]}
    order = np.argsort(merged["t"], kind="stable")
    merged = {key: value[order] for key, value in merged.items()}
    merged["steps"] = np.cumsum(merged["l"])
    return merged


def _read_manifest(path: Path) -> dict[str, Any]:
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not a readable JSON manifest ({err})") from err
    if not isinstance(manifest, dict):
        raise ValueError(f"{path}: the manifest is not a JSON object")
    missing = [key for key in ("env_id", "algo", "seed") if key not in manifest]
    if missing:
        raise ValueError(f"{path}: the manifest lacks {', '.join(missing)}")
    return manifest


def load_run(run_dir: Path) -> RunRecord:
    """One run directory (with ``manifest.json``) and its merged monitor episodes."""
    manifest = _read_manifest(run_dir / MANIFEST_NAME)
    monitor_dir = run_dir / "monitor"
    files = sorted(monitor_dir.glob("*.monitor.csv")) if monitor_dir.is_dir() else []
    merged = merge_monitors([read_monitor_csv(file) for file in files])
    try:
        seed = int(manifest["seed"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{run_dir / MANIFEST_NAME}: bad seed {manifest['seed']!r}") from err
    return RunRecord(
        path=run_dir,
        env_id=str(manifest["env_id"]),
        algo=str(manifest["algo"]).lower(),
        seed=seed,
        manifest=manifest,
        steps=merged["steps"],
        returns=merged["r"],
        lengths=merged["l"],
        successes=merged["is_success"],
    )


def load_runs(paths: Sequence[Path | str]) -> list[RunRecord]:
    """All training runs (directories holding ``manifest.json``) at or below ``paths``.

    Raises:
        ValueError: a path does not exist, holds neither runs nor traces, or holds a corrupt
            manifest or monitor file (the message names the path).
    """
    runs: list[RunRecord] = []
    seen: set[Path] = set()
    for path in _check_exists(paths):
        manifests = _find([path], MANIFEST_NAME)
        if not manifests and not find_traces([path]):
            raise ValueError(
                f"{path}: no training runs ({MANIFEST_NAME}) or evaluated episodes "
                f"({TRACE_NAME}) found there"
            )
        for manifest in manifests:
            if manifest.parent not in seen:
                seen.add(manifest.parent)
                runs.append(load_run(manifest.parent))
    return runs


def load_evaluations(run: RunRecord) -> EvalCurve | None:
    """The run's ``eval/evaluations.npz`` averaged over episodes, or None if there is none.

    Raises:
        ValueError: the file exists but is not a readable EvalCallback log.
    """
    path = run.path / EVALUATIONS_PATH
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            steps = np.asarray(data["timesteps"], dtype=float).reshape(-1)
            results = np.asarray(data["results"], dtype=float).reshape(len(steps), -1)
            lengths = np.asarray(data["ep_lengths"], dtype=float).reshape(len(steps), -1)
            if "successes" in data.files and np.size(data["successes"]) > 0:
                successes = np.asarray(data["successes"], dtype=float).reshape(len(steps), -1)
                success_rate = successes.mean(axis=1)
            else:
                success_rate = np.full(len(steps), math.nan)
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{path}: not a readable evaluations.npz ({err})") from err
    return EvalCurve(steps, results.mean(axis=1), lengths.mean(axis=1), success_rate)


def _str_item(value: np.ndarray) -> str:
    return str(np.asarray(value).reshape(-1)[0]) if np.size(value) else ""


def load_trace(path: Path | str) -> Trace:
    """Read a ``trace.npz`` written by ``rehabbot evaluate``.

    Raises:
        ValueError: the file is missing, corrupt or lacks a required key (names the file).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in _TRACE_KEYS if key not in data.files]
            if missing:
                raise ValueError(f"missing key(s) {', '.join(missing)}")
            trace = Trace(
                path=path,
                env_id=_str_item(data["env_id"]),
                policy=_str_item(data["policy"]),
                dt_s=float(data["dt_s"]),
                time_s=np.asarray(data["time_s"], dtype=float),
                robot_qpos_rad=np.asarray(data["robot_qpos_rad"], dtype=float),
                robot_torque_nm=np.asarray(data["robot_torque_nm"], dtype=float),
                torque_limit_nm=np.asarray(data["torque_limit_nm"], dtype=float).reshape(-1),
                joint_names=[str(name) for name in np.asarray(data["joint_names"]).reshape(-1)],
                tool_pos_m=np.asarray(data["tool_pos_m"], dtype=float).reshape(-1, 3),
                target_tool_pos_m=np.asarray(data["target_tool_pos_m"], dtype=float).reshape(
                    -1, 3
                ),
            )
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{path}: not a readable trace.npz ({err})") from err
    n_steps = len(trace.time_s)
    n_joints = trace.robot_qpos_rad.shape[-1] if trace.robot_qpos_rad.ndim == 2 else -1
    consistent = (
        n_steps >= 1
        and trace.robot_qpos_rad.shape == (n_steps, n_joints)
        and trace.robot_torque_nm.shape == (n_steps, n_joints)
        and len(trace.tool_pos_m) == n_steps
        and len(trace.joint_names) == n_joints
        and len(trace.torque_limit_nm) == n_joints
        and trace.dt_s > 0
    )
    if not consistent:
        raise ValueError(f"{path}: not a readable trace.npz (array shapes do not agree)")
    return trace


# --------------------------------------------------------------------------- matplotlib


def _new_figure(figsize: tuple[float, float]) -> Figure:
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


def _check_formats(formats: Sequence[str]) -> tuple[str, ...]:
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
    for fmt in _check_formats(formats):
        target = out / f"{stem}.{fmt}"
        figure.savefig(target, format=fmt, dpi=DPI)
        written.append(target)
    return written


# --------------------------------------------------------------------------- Fig. 4


def rolling_mean(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over the last ``window`` values (fewer at the start), ignoring NaN."""
    if window < 1:
        raise ValueError(f"smoothing window must be >= 1, got {window}")
    values = np.asarray(values, dtype=float)
    finite = np.isfinite(values)
    sums = np.concatenate([[0.0], np.cumsum(np.where(finite, values, 0.0))])
    counts = np.concatenate([[0], np.cumsum(finite)])
    stop = np.arange(1, len(values) + 1)
    start = np.maximum(stop - window, 0)
    total = sums[stop] - sums[start]
    count = counts[stop] - counts[start]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), math.nan)


def _algo_sort_key(algo: str) -> tuple[int, str]:
    return (ALGO_ORDER.index(algo) if algo in ALGO_ORDER else len(ALGO_ORDER), algo)


def _algo_color(algo: str, extra_index: int) -> str:
    return ALGO_COLORS.get(algo, _EXTRA_COLORS[extra_index % len(_EXTRA_COLORS)])


_CurveSet = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _run_curves(run: RunRecord, smooth: int, source: str) -> _CurveSet | None:
    """(steps, return, length, success) of one run, or None when it has no data."""
    if source == "eval":
        evaluations = load_evaluations(run)
        if evaluations is None or len(evaluations.steps) == 0:
            return None
        return (evaluations.steps, evaluations.returns, evaluations.lengths,
                evaluations.successes)
    if run.n_episodes == 0:
        return None
    return (run.steps, rolling_mean(run.returns, smooth), rolling_mean(run.lengths, smooth),
            rolling_mean(run.successes, smooth))


def _interp(grid: np.ndarray, steps: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation that leaves NaN where a run has no value nearby."""
    finite = np.isfinite(values)
    if not finite.any():
        return np.full(len(grid), math.nan)
    return np.interp(grid, steps[finite], values[finite])


def aggregate_seeds(curves: Sequence[_CurveSet], n_points: int = GRID_POINTS
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolate seed curves onto a common step grid and average them.

    The grid spans the steps that every seed covers (from the latest first point to the
    earliest last point). Returns ``grid`` (G,), ``mean`` (3, G) and ``std`` (3, G) for
    return, length and success (std over seeds, ``ddof=0``).
    """
    start = max(float(curve[0][0]) for curve in curves)
    stop = min(float(curve[0][-1]) for curve in curves)
    grid = np.linspace(start, stop, n_points) if stop > start else np.array([stop])
    stacked = np.array(
        [[_interp(grid, curve[0], curve[k]) for k in (1, 2, 3)] for curve in curves]
    )  # (seeds, 3, G)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN success columns
        mean = np.nanmean(stacked, axis=0)
        std = np.nanstd(stacked, axis=0)
    return grid, mean, std


_PANEL_LABELS: tuple[str, ...] = ("episode return", "episode length [steps]", "success rate")


def build_learning_curves(runs: Sequence[RunRecord], smooth: int = DEFAULT_SMOOTH,
                          source: str = "train") -> dict[str, Figure]:
    """Fig. 4 figures keyed by env id: three panels, one line (± std band) per algorithm.

    ``source="train"`` uses the training monitor episodes smoothed by a trailing mean over
    ``smooth`` episodes; ``source="eval"`` uses the deterministic evaluations of
    ``eval/evaluations.npz`` (already means over the evaluation episodes, not smoothed).
    Runs without data for the chosen source are skipped.

    Raises:
        ValueError: bad ``smooth``/``source``, or no run has any data.
    """
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r} (choose from {', '.join(SOURCES)})")
    if smooth < 1:
        raise ValueError(f"--smooth must be >= 1, got {smooth}")
    grouped: dict[str, dict[str, list[_CurveSet]]] = {}
    for run in runs:
        curves = _run_curves(run, smooth, source)
        if curves is not None:
            grouped.setdefault(run.env_id, {}).setdefault(run.algo, []).append(curves)
    if not grouped:
        what = ("finished training episodes (monitor/*.monitor.csv)" if source == "train"
                else "evaluations (eval/evaluations.npz)")
        where = ", ".join(sorted({str(run.path) for run in runs})) or "the given paths"
        raise ValueError(f"no run has {what}: {where}")

    figures: dict[str, Figure] = {}
    for env_id in sorted(grouped):
        figure = _new_figure((13.0, 3.8))
        axes: list[Axes] = list(figure.subplots(1, 3, sharex=True))
        extra = 0
        for algo in sorted(grouped[env_id], key=_algo_sort_key):
            curves = grouped[env_id][algo]
            grid, mean, std = aggregate_seeds(curves)
            color = _algo_color(algo, extra)
            extra += algo not in ALGO_COLORS
            n = len(curves)
            label = f"{algo.upper()} ({n} seed{'s' if n != 1 else ''})"
            for k, ax in enumerate(axes):
                ax.plot(grid, mean[k], color=color, linewidth=1.6, label=label)
                ax.fill_between(grid, mean[k] - std[k], mean[k] + std[k], color=color,
                                alpha=0.2, linewidth=0)
        for ax, ylabel in zip(axes, _PANEL_LABELS, strict=True):
            ax.set_xlabel("environment steps")
            ax.set_ylabel(ylabel)
            ax.grid(True, alpha=0.3)
            ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
        axes[2].set_ylim(-0.05, 1.05)
        axes[0].legend(loc="best", fontsize="small")
        kind = "training episodes" if source == "train" else "deterministic evaluations"
        figure.suptitle(f"Learning curves on {env_id} ({kind}; mean ± std over seeds)")
        figures[env_id] = figure
    return figures


def plot_learning_curves(runs: Sequence[RunRecord], out_dir: Path | str,
                         smooth: int = DEFAULT_SMOOTH, source: str = "train",
                         formats: Sequence[str] = DEFAULT_FORMATS) -> list[Path]:
    """Write Fig. 4: ``fig4_learning_curves.*`` (one env id) or
    ``fig4_learning_curves_<env-short>.*`` (one figure per env id)."""
    _check_formats(formats)
    figures = build_learning_curves(runs, smooth=smooth, source=source)
    written: list[Path] = []
    for env_id, figure in figures.items():
        stem = "fig4_learning_curves"
        if len(figures) > 1:
            stem += f"_{sanitize(env_short(env_id))}"
        written += save_figure(figure, out_dir, stem, formats)
    return written


# --------------------------------------------------------------------------- Figs. 5, 6, 3


def _as_trace(trace: Trace | Path | str) -> Trace:
    return trace if isinstance(trace, Trace) else load_trace(trace)


def _finite_differences(trace: Trace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint velocity, acceleration, jerk by :func:`rehabbot.metrics.finite_differences`."""
    from rehabbot.metrics import finite_differences

    try:
        return finite_differences(trace.robot_qpos_rad, trace.dt_s)
    except ValueError as err:
        raise ValueError(f"{trace.path}: cannot differentiate the joint angles ({err})") from err


def build_kinematics(trace: Trace | Path | str) -> Figure:
    """Fig. 5: joint velocity, acceleration and jerk versus time, one line per joint."""
    trace = _as_trace(trace)
    velocity, acceleration, jerk = _finite_differences(trace)
    figure = _new_figure((8.0, 8.0))
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
    _check_formats(formats)
    trace = _as_trace(trace_path)
    return save_figure(build(trace), out_dir, f"{prefix}_{trace.label}", formats)


def build_torques(trace: Trace | Path | str) -> Figure:
    """Fig. 6: one panel per joint (2×3 grid): torque versus time, ± limit dashed."""
    trace = _as_trace(trace)
    n_joints = len(trace.joint_names)
    n_cols = min(3, n_joints)
    n_rows = math.ceil(n_joints / n_cols)
    figure = _new_figure((4.0 * n_cols, 2.8 * n_rows))
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
    figure = _new_figure((7.0, 6.5))
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


# --------------------------------------------------------------------------- all figures


def _unique_label(label: str, used: set[str]) -> str:
    candidate, k = label, 2
    while candidate in used:
        candidate, k = f"{label}-{k}", k + 1
    used.add(candidate)
    return candidate


def _ensure_trace(run_dir: Path) -> Path:
    """Evaluate the run's final model once (``rehabbot.evaluation.ensure_trace``)."""
    try:
        from rehabbot.evaluation import ensure_trace
    except ImportError as err:
        raise ImportError(
            f"evaluating {run_dir} for Figs. 3, 5, 6 needs the training extras "
            f'(pip install "rehabbot[train]"): {err}; or pass --no-evaluate'
        ) from err
    return Path(ensure_trace(run_dir)).resolve()


def plot_all(paths: Sequence[Path | str], out_dir: Path | str, smooth: int = DEFAULT_SMOOTH,
             source: str = "train", formats: Sequence[str] = DEFAULT_FORMATS,
             evaluate: bool = True) -> list[Path]:
    """Every figure that the data under ``paths`` supports; returns the written files.

    Fig. 4 from all runs (skipped with a warning when no run has data yet); Figs. 5, 6 and 3
    for every ``trace.npz`` found. With ``evaluate`` (default), a run that has ``model.zip``
    but no trace first gets one from :func:`rehabbot.evaluation.ensure_trace`. Traces whose
    labels coincide get ``-2``, ``-3``, ... suffixes instead of overwriting each other.

    Raises:
        ValueError: a path is missing, holds no runs or traces, or holds a corrupt file.
        OSError: ``out_dir`` cannot be created or written.
    """
    formats = _check_formats(formats)
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r} (choose from {', '.join(SOURCES)})")
    if smooth < 1:
        raise ValueError(f"--smooth must be >= 1, got {smooth}")
    runs = load_runs(paths)
    trace_paths = find_traces(paths)
    if evaluate:
        for run in runs:
            if (run.path / MODEL_NAME).is_file() and not find_traces([run.path]):
                trace_paths.append(_ensure_trace(run.path))
    traces = [load_trace(path) for path in dict.fromkeys(trace_paths)]

    written: list[Path] = []
    if runs:
        try:
            figures = build_learning_curves(runs, smooth=smooth, source=source)
        except ValueError as err:
            warnings.warn(f"Fig. 4 skipped: {err}", stacklevel=2)
            figures = {}
        for env_id, figure in figures.items():
            stem = "fig4_learning_curves"
            if len(figures) > 1:
                stem += f"_{sanitize(env_short(env_id))}"
            written += save_figure(figure, out_dir, stem, formats)
    used: set[str] = set()
    for trace in traces:
        label = _unique_label(trace.label, used)
        written += save_figure(build_kinematics(trace), out_dir, f"fig5_kinematics_{label}",
                               formats)
        written += save_figure(build_torques(trace), out_dir, f"fig6_torques_{label}", formats)
        written += save_figure(build_tool_path(trace), out_dir, f"fig3_tool_path_{label}",
                               formats)
    return written


# --------------------------------------------------------------------------- CLI

PLOT_DESCRIPTION = """\
Draw the paper's figures for your own runs:
  Fig. 4  fig4_learning_curves.{png,pdf}    return / length / success vs. env steps,
                                            mean ± std over seeds, one line per algorithm
                                            (one file per env id, suffixed, for several)
  Fig. 5  fig5_kinematics_<label>.{png,pdf} joint velocity, acceleration, jerk vs. time
  Fig. 6  fig6_torques_<label>.{png,pdf}    joint torques with the torque limits
  Fig. 3  fig3_tool_path_<label>.{png,pdf}  3-D tool path with the numbered targets
<label> is <policy>_<env>. RUN_DIR may be a training run, any directory above runs
(all manifest.json below it are used) or a directory holding trace.npz files. A run with
model.zip but no evaluation/trace.npz is evaluated first (one deterministic episode)
unless --no-evaluate is given."""

PLOT_EPILOG = """\
examples:
  rehabbot plot runs/rehab-reach-v0                  # all algorithms and seeds below it
  rehabbot plot runs/rehab-reach-v0/sac/seed0 --out figures/
  rehabbot plot runs/a runs/b --smooth 50 --formats png
  rehabbot plot runs --source eval --no-evaluate     # Fig. 4 from eval/evaluations.npz

exit codes: 0 success, 1 unreadable input file, unwritable output or missing matplotlib,
2 bad usage (missing directory, nothing to plot, bad option value)"""


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def add_plot_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``plot`` subcommand to the ``rehabbot`` parser's subcommands."""
    parser = commands.add_parser(
        "plot",
        help="draw the paper's figures (learning curves, kinematics, torques, tool path)",
        description=PLOT_DESCRIPTION,
        epilog=PLOT_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", type=Path,
                        help="training run directories, their parents, or trace directories")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="output directory (default: <first RUN_DIR>/figures)")
    parser.add_argument("--smooth", type=_positive_int, default=DEFAULT_SMOOTH, metavar="N",
                        help="rolling-mean window of the training curves, in episodes "
                             f"(default: {DEFAULT_SMOOTH})")
    parser.add_argument("--source", choices=SOURCES, default="train",
                        help="Fig. 4 from the training episodes (monitor files, default) or "
                             "from the deterministic evaluations (eval/evaluations.npz)")
    parser.add_argument("--formats", nargs="+", choices=SUPPORTED_FORMATS,
                        default=list(DEFAULT_FORMATS), metavar="FMT",
                        help="file formats to write: png, pdf, svg (default: png pdf)")
    parser.add_argument("--no-evaluate", dest="evaluate", action="store_false",
                        help="do not evaluate runs that have model.zip but no trace.npz")
    parser.set_defaults(func=cmd_plot)


def cmd_plot(args: argparse.Namespace) -> int:
    """Run ``rehabbot plot``: write the figures, print each path, return 0."""
    from rehabbot.cli import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, CliError

    run_dirs = [Path(path) for path in args.run_dirs]
    for path in run_dirs:
        if not path.exists():
            raise CliError(f"{path}: no such file or directory", EXIT_USAGE)
    first = run_dirs[0] if run_dirs[0].is_dir() else run_dirs[0].parent
    out_dir = Path(args.out) if args.out is not None else first / "figures"
    if out_dir.exists() and not out_dir.is_dir():
        raise CliError(f"--out {out_dir}: exists and is not a directory", EXIT_USAGE)
    try:
        runs_or_traces = [path for path in run_dirs
                          if _find([path], MANIFEST_NAME) or find_traces([path])]
        if len(runs_or_traces) < len(run_dirs):
            bad = next(path for path in run_dirs if path not in runs_or_traces)
            raise CliError(
                f"{bad}: no training runs ({MANIFEST_NAME}) or evaluated episodes "
                f"({TRACE_NAME}) found there", EXIT_USAGE,
            )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            written = plot_all(run_dirs, out_dir, smooth=args.smooth, source=args.source,
                               formats=args.formats, evaluate=args.evaluate)
    except ImportError as err:
        raise CliError(str(err)) from err
    except ValueError as err:
        raise CliError(str(err), EXIT_FAILURE) from err
    except OSError as err:
        where = err.filename or out_dir
        raise CliError(f"cannot write {where}: {err.strerror or err}") from err
    for warning in caught:
        print(f"rehabbot plot: warning: {warning.message}", file=sys.stderr)
    if not written:
        raise CliError(f"nothing to plot under {', '.join(map(str, run_dirs))}", EXIT_USAGE)
    for path in written:
        print(path)
    return EXIT_OK
