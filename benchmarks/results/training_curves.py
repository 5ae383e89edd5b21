"""A training run's learning curve, read from its run folder, small enough to keep in a
results document's ``data``.

``benchmarks/results/stratified_results.py`` stores it with each run it evaluates (the run
folders themselves stay outside the repository), so that the page can draw learning curves
from its JSON alone. The curve is the success rate against environment steps, from the first
of these files the run has:

* ``training_log.csv`` (a batched run, ``--backend rsl_rl``): the success rate of the
  training episodes (stochastic actions) that ended in each PPO iteration;
* ``eval/evaluations.npz`` (a Stable-Baselines3/SBX run): SB3's ``EvalCallback``, the
  deterministic evaluation episodes on the training patient every ``eval_freq`` steps;
* ``monitor/*.monitor.csv``: the training episodes (stochastic actions), as the success rate
  over the last :data:`MONITOR_WINDOW` episodes.

A curve keeps at most :data:`MAX_POINTS` points (evenly spaced over its list, the last one
kept) with rates rounded to :data:`DECIMALS` decimals.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError
from rehabbot.rl.batch_training import LOG_NAME
from rehabbot.rl.runs import EVALUATIONS_PATH, MONITOR_DIR

MAX_POINTS = 100
DECIMALS = 4
MONITOR_WINDOW = 100
SOURCES = {
    LOG_NAME: "training episodes (stochastic actions) that ended in each PPO iteration",
    EVALUATIONS_PATH.as_posix(): "deterministic evaluation episodes during training "
                                 "(SB3's EvalCallback, the training patient)",
    f"{MONITOR_DIR}/*.monitor.csv": f"training episodes (stochastic actions), the success "
                                    f"rate over the last {MONITOR_WINDOW}",
}

__all__ = ["MAX_POINTS", "SOURCES", "run_curve", "thin"]


def thin(timesteps: np.ndarray, rates: np.ndarray,
         max_points: int = MAX_POINTS) -> dict[str, list]:
    """At most ``max_points`` of a curve, evenly spaced over its points, first and last kept;
    rates rounded to :data:`DECIMALS` decimals."""
    if len(timesteps) != len(rates):
        raise ValueError(f"{len(timesteps)} timesteps against {len(rates)} rates")
    keep = np.unique(np.linspace(0, len(timesteps) - 1, min(max_points, len(timesteps)))
                     .round().astype(int)) if len(timesteps) else np.zeros(0, dtype=int)
    return {"timesteps": [int(timesteps[i]) for i in keep],
            "success_rate": [round(float(rates[i]), DECIMALS) for i in keep]}


def _curve(source: str, timesteps: Any, rates: Any) -> dict[str, Any] | None:
    timesteps, rates = np.asarray(timesteps, dtype=float), np.asarray(rates, dtype=float)
    finite = np.isfinite(rates) & np.isfinite(timesteps)
    if not finite.any():
        return None
    return {"source": source, **thin(timesteps[finite], rates[finite])}


def _batched_log(path: Path) -> dict[str, Any] | None:
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
        points = [(float(row["timesteps"]), float(row["success_rate"]))
                  for row in rows if row.get("success_rate") not in (None, "")]
    except (OSError, UnicodeDecodeError, csv.Error, KeyError, ValueError) as err:
        raise DataError(f"{path}: not a readable training log ({err})") from err
    return _curve(LOG_NAME, [p[0] for p in points], [p[1] for p in points]) if points else None


def run_curve(run_dir: Path) -> dict[str, Any] | None:
    """The run's curve ``{"source", "timesteps", "success_rate"}`` (see the module's
    docstring), or None where its folder holds none of those files or none with a success
    rate. Raises :class:`~rehabbot.common.errors.DataError` naming an unreadable file."""
    from rehabbot.analysis.learning_curves import load_evaluations, load_run, rolling_mean

    run_dir = Path(run_dir)
    if (run_dir / LOG_NAME).is_file():
        return _batched_log(run_dir / LOG_NAME)
    try:
        record = load_run(run_dir)
        evaluations = load_evaluations(record)
    except ValueError as err:
        raise DataError(str(err)) from err
    if evaluations is not None:
        curve = _curve(EVALUATIONS_PATH.as_posix(), evaluations.steps, evaluations.successes)
        if curve is not None:
            return curve
    if record.n_episodes and not all(math.isnan(x) for x in record.successes):
        return _curve(f"{MONITOR_DIR}/*.monitor.csv", record.steps,
                      rolling_mean(record.successes, MONITOR_WINDOW))
    return None
