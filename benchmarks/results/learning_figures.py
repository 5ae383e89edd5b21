"""The figures of a learning page (``benchmarks/results/stratified_results.py``): what each is
drawn from, and the drawing.

* **Success per cell**, one figure per env (and robot): a heat map per row of the summary
  table (an algorithm, its seeds pooled as in the per-cell tables) and one for the scripted
  expert on the same episodes; rows of the map are exercise x patient, columns weight levels;
  a cell's colour is the share of its episodes that finished, its text ``finished/episodes``,
  a red frame marks a cell where a safety rule stopped an episode, grey a cell the env refuses.
* **Learning curves**, one figure for the page, where its runs' data hold a curve
  (:mod:`benchmarks.results.training_curves`): success rate against env steps, a panel per
  env, each seed thin and the mean over seeds bold, per row.

:func:`cell_payloads` and :func:`curve_payload` compute what a figure shows from the page's
episodes (pure Python, no matplotlib): that data's digest is what the document and the PNG
record (:mod:`benchmarks.common.figures`). :data:`STYLE` is part of every payload: raise it
when a change to the drawing should redraw every published figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from rehabbot.envs.registration import env_short_name
from rehabbot.sim.scene import WEIGHT_LEVELS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

STYLE = 1
MAX_PANEL_COLUMNS = 4
MAX_CURVE_COLUMNS = 3
CELL_WIDTH_IN = 0.34
LINE_HEIGHT_IN = 0.24
STOP_COLOR = "#d62728"
REFUSED_COLOR = "0.85"
COLORMAP = "viridis"
CURVE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                "#bcbd22", "#17becf", "#d62728")
EXPERT = "expert"

Results = Mapping[tuple[str, str], Sequence[Mapping[str, Any]]]

__all__ = ["STYLE", "build_cells_figure", "build_curves_figure", "cell_payloads",
           "curve_payload"]


def _rows_by_env(results: Results) -> dict[str, list[str]]:
    """Each env label's rows in the summary table's order (sorted), the expert last."""
    rows: dict[str, list[str]] = {}
    for env, algo in sorted(results):
        if algo != EXPERT:
            rows.setdefault(env, []).append(algo)
    for env in rows:
        if (env, EXPERT) in results:
            rows[env].append(EXPERT)
    return rows


def cell_payloads(results: Results, patients: Sequence[str],
                  patient_column: str) -> list[dict[str, Any]]:
    """One payload per env label: for each row and the expert, the finished, played and
    stopped episodes of every (exercise, patient) x weight level, over all seeds."""
    payloads = []
    for env, algos in _rows_by_env(results).items():
        exercises = sorted({e["exercise"] for algo in algos for r in results[(env, algo)]
                            for e in r["episodes"]})
        lines = [[exercise, patient] for exercise in exercises for patient in patients]
        panels = []
        for algo in algos:
            count = {key: np.zeros((len(lines), len(WEIGHT_LEVELS)), dtype=int)
                     for key in ("finished", "episodes", "stopped")}
            index = {(exercise, patient): i for i, (exercise, patient) in enumerate(lines)}
            for run in results[(env, algo)]:
                for episode in run["episodes"]:
                    cell = (index[(episode["exercise"], episode["profile"])],
                            WEIGHT_LEVELS.index(episode["weight_level"]))
                    count["episodes"][cell] += 1
                    count["finished"][cell] += bool(episode["success"])
                    count["stopped"][cell] += bool(episode["safety_violation"])
            seeds = [r["train_seed"] for r in results[(env, algo)] if r.get("train_seed")
                     is not None]
            panels.append({"row": algo, "seeds": seeds,
                           **{key: value.tolist() for key, value in count.items()}})
        payloads.append({"kind": "success-per-cell", "style": STYLE,
                         "env": env_short_name(env), "patient_column": patient_column,
                         "levels": list(WEIGHT_LEVELS), "lines": lines, "panels": panels})
    return payloads


def curve_payload(results: Results) -> dict[str, Any] | None:
    """The learning curves of every run whose data hold one, per env label and row (None:
    no run has one)."""
    panels = []
    for env, algos in _rows_by_env(results).items():
        rows = []
        for algo in algos:
            curves = [{"seed": r.get("train_seed"), **r["curve"]}
                      for r in results[(env, algo)] if r.get("curve")]
            if curves:
                rows.append({"row": algo, "runs": curves})
        if rows:
            panels.append({"env": env_short_name(env), "rows": rows})
    if not panels:
        return None
    return {"kind": "training-curves", "style": STYLE, "panels": panels}


def _new_figure(size_in: tuple[float, float]) -> Figure:
    from rehabbot.analysis.figures import new_figure

    return new_figure(size_in)


def _panel_title(panel: Mapping[str, Any]) -> str:
    if panel["row"] == EXPERT:
        return "scripted expert"
    seeds = panel["seeds"]
    return f"{panel['row']}\n(seed{'s' if len(seeds) != 1 else ''} " \
           f"{', '.join(map(str, seeds))})"


def build_cells_figure(payload: Mapping[str, Any]) -> Figure:
    """The success-per-cell heat maps of one env (a payload of :func:`cell_payloads`)."""
    from matplotlib import colormaps
    from matplotlib.patches import Rectangle

    panels, lines, levels = payload["panels"], payload["lines"], payload["levels"]
    columns = min(MAX_PANEL_COLUMNS, len(panels))
    rows = math.ceil(len(panels) / columns)
    labels = [f"ex {exercise} · {patient}" for exercise, patient in lines]
    label_in = 0.3 + 0.055 * max(len(label) for label in labels)
    width = label_in + columns * (len(levels) * CELL_WIDTH_IN + 0.25) + 0.9
    height = 0.9 + rows * (len(lines) * LINE_HEIGHT_IN + 0.75)
    figure = _new_figure((width, height))
    axes = figure.subplots(rows, columns, squeeze=False, sharex=True, sharey=True)
    cmap = colormaps[COLORMAP].with_extremes(bad=REFUSED_COLOR)
    image = None
    font = 7 if len(lines) > 12 else 8
    for ax, panel in zip(axes.flat, panels, strict=False):
        finished = np.asarray(panel["finished"], dtype=float)
        played = np.asarray(panel["episodes"], dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = np.where(played > 0, finished / played, np.nan)
        image = ax.imshow(np.ma.masked_invalid(rate), cmap=cmap, vmin=0.0, vmax=1.0,
                          aspect="auto", interpolation="nearest")
        for (i, j), value in np.ndenumerate(rate):
            if played[i, j] == 0:
                ax.text(j, i, "n/a", ha="center", va="center", fontsize=font - 1, color="0.3")
                continue
            ax.text(j, i, f"{int(finished[i, j])}/{int(played[i, j])}", ha="center",
                    va="center", fontsize=font - 1,
                    color="black" if value >= 0.6 else "white")
            if panel["stopped"][i][j]:
                ax.add_patch(Rectangle((j - 0.46, i - 0.46), 0.92, 0.92, fill=False,
                                       edgecolor=STOP_COLOR, linewidth=1.6))
        for i in range(1, len(lines)):
            if lines[i][0] != lines[i - 1][0]:  # a new exercise
                ax.axhline(i - 0.5, color="white", linewidth=2.5)
        ax.set_title(_panel_title(panel), fontsize=8)
        ax.set_xticks(range(len(levels)), [f"l{level}" for level in levels], fontsize=font)
        ax.set_yticks(range(len(lines)), labels, fontsize=font)
        ax.tick_params(length=0)
    for ax in axes.flat[len(panels):]:
        ax.set_axis_off()
    if image is not None:
        bar = figure.colorbar(image, ax=axes, shrink=min(1.0, 3.0 / height + 0.3),
                              fraction=0.04, pad=0.02)
        bar.set_label("success rate", fontsize=8)
        bar.ax.tick_params(labelsize=7)
    figure.suptitle(f"{payload['env']}: success per exercise x {payload['patient_column']} x "
                    f"weight level, all seeds", fontsize=9)
    figure.supxlabel("weight level (red frame: a safety stop; grey: refused)", fontsize=8)
    return figure


def _mean_curve(runs: Sequence[Mapping[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """The mean over seeds on the union of their steps, each seed interpolated within its own
    range only."""
    grid = np.unique(np.concatenate([np.asarray(r["timesteps"], dtype=float) for r in runs]))
    values = np.full((len(runs), len(grid)), np.nan)
    for k, run in enumerate(runs):
        steps = np.asarray(run["timesteps"], dtype=float)
        inside = (grid >= steps[0]) & (grid <= steps[-1])
        values[k, inside] = np.interp(grid[inside], steps, run["success_rate"])
    return grid, np.nanmean(values, axis=0)


def build_curves_figure(payload: Mapping[str, Any]) -> Figure:
    """The learning curves of a page (a payload of :func:`curve_payload`)."""
    panels = payload["panels"]
    columns = min(MAX_CURVE_COLUMNS, len(panels))
    rows = math.ceil(len(panels) / columns)
    figure = _new_figure((3.0 * columns + 0.6, 3.3 * rows + 0.5))
    axes = figure.subplots(rows, columns, squeeze=False)
    for ax, panel in zip(axes.flat, panels, strict=False):
        for k, row in enumerate(panel["rows"]):
            color = CURVE_COLORS[k % len(CURVE_COLORS)]
            for run in row["runs"]:
                ax.plot(run["timesteps"], run["success_rate"], color=color, linewidth=0.7,
                        alpha=0.35)
            grid, mean = _mean_curve(row["runs"])
            sources = sorted({run["source"] for run in row["runs"]})
            ax.plot(grid, mean, color=color, linewidth=1.8,
                    label=f"{row['row']}, {len(row['runs'])} seed"
                          f"{'s' if len(row['runs']) != 1 else ''} ({', '.join(sources)})")
        ax.set_title(panel["env"], fontsize=9)
        ax.set_ylim(-0.03, 1.03)
        ax.set_xlabel("env steps", fontsize=8)
        ax.set_ylabel("success rate", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize=6.5, frameon=False)
    for ax in axes.flat[len(panels):]:
        ax.set_axis_off()
    figure.suptitle("Success rate during training (thin: each seed; bold: their mean)",
                    fontsize=9)
    return figure
