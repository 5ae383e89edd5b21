"""Fig. 4 of the paper for the user's own runs: episode return, length and success rate
versus environment steps, one line per algorithm (mean over seeds) with a ± std band, from
the training runs' monitor files or their periodic evaluations."""

from __future__ import annotations

import csv
import math
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rehabbot.analysis.figures import (
    ALGO_COLORS,
    ALGO_ORDER,
    DEFAULT_FORMATS,
    DEFAULT_SMOOTH,
    EXTRA_COLORS,
    GRID_POINTS,
    SOURCES,
    check_formats,
    new_figure,
    save_figure,
)
from rehabbot.analysis.traces import (
    TRACE_NAME,
    check_exists,
    find_files,
    find_traces,
    sanitize,
)
from rehabbot.common.errors import DataError
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import runs as run_files

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

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


def load_run(run_dir: Path) -> RunRecord:
    """One run directory (with ``manifest.json``) and its merged monitor episodes."""
    manifest = run_files.read_manifest(run_dir)
    if manifest is None:
        raise DataError(f"{run_dir / run_files.MANIFEST_NAME}: no such file")
    monitor_dir = run_dir / run_files.MONITOR_DIR
    files = sorted(monitor_dir.glob("*.monitor.csv")) if monitor_dir.is_dir() else []
    merged = merge_monitors([read_monitor_csv(file) for file in files])
    try:
        seed = int(manifest["seed"])
    except (TypeError, ValueError) as err:
        raise DataError(f"{run_dir / run_files.MANIFEST_NAME}: bad seed "
                        f"{manifest['seed']!r}") from err
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
    for path in check_exists(paths):
        manifests = find_files([path], run_files.MANIFEST_NAME)
        if not manifests and not find_traces([path]):
            raise ValueError(
                f"{path}: no training runs ({run_files.MANIFEST_NAME}) or evaluated episodes "
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
    path = run.path / run_files.EVALUATIONS_PATH
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
    return ALGO_COLORS.get(algo, EXTRA_COLORS[extra_index % len(EXTRA_COLORS)])


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
        figure = new_figure((13.0, 3.8))
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
    check_formats(formats)
    figures = build_learning_curves(runs, smooth=smooth, source=source)
    written: list[Path] = []
    for env_id, figure in figures.items():
        stem = "fig4_learning_curves"
        if len(figures) > 1:
            stem += f"_{sanitize(env_short_name(env_id))}"
        written += save_figure(figure, out_dir, stem, formats)
    return written
