"""The README's ablation table, from the training logs alone (no extra simulation).

For every run folder below the given roots (finished or interrupted), it reads the training
monitor CSVs and the periodic evaluations and prints: the settings (hyperparameter file and
env kwargs from the manifest), the steps trained, and, over the training episodes that ended
in the last ``--window`` steps, the mean return per step (the mean tracking reward: about
minus the mean joint-space distance to the active target), the safety stops, the successes,
and the best periodic-evaluation success rate.

Usage::

    python benchmarks/results/ablation_table.py runs/ablation runs/results [--window 20000]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rehabbot.common.text_tables import markdown_table


def read_episodes(run: Path) -> list[tuple[int, float, int, bool, bool]]:
    """(cumulative steps, return, length, success, safety stop) per training episode."""
    rows = []
    for path in sorted((run / "monitor").glob("*.monitor.csv")):
        lines = path.read_text().splitlines()[1:]
        rows += [r for r in csv.DictReader(lines)]
    rows.sort(key=lambda r: float(r["t"]))
    episodes, steps = [], 0
    for r in rows:
        steps += int(r["l"])
        episodes.append((steps, float(r["r"]), int(r["l"]), r.get("is_success") == "True",
                         bool(r.get("safety_violation"))))
    return episodes


def summarize(run: Path, window: int) -> dict:
    manifest = json.loads((run / "manifest.json").read_text())
    episodes = read_episodes(run)
    done = episodes[-1][0] if episodes else 0
    recent = [e for e in episodes if e[0] > done - window]
    best_eval = None
    evaluations = run / "eval" / "evaluations.npz"
    if evaluations.is_file():
        with np.load(evaluations) as data:
            if "successes" in data.files and len(data["successes"]):
                best_eval = float(np.max(np.mean(data["successes"], axis=1)))
    hp = manifest.get("hyperparameters", {})
    return {
        "run": str(run),
        "algo": manifest["algo"].upper(),
        "settings": hp.get("source", "sb3 defaults"),
        "env_kwargs": manifest.get("env_kwargs") or {},
        "steps": manifest.get("timesteps_done", done),
        "status": manifest.get("status"),
        "window_episodes": len(recent),
        "return_per_step": (sum(e[1] for e in recent) / max(1, sum(e[2] for e in recent))
                            if recent else None),
        "safety_stops": sum(e[4] for e in recent),
        "successes": sum(e[3] for e in recent),
        "best_eval_success": best_eval,
        "wall_clock_s": manifest.get("wall_clock_s"),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+", type=Path)
    parser.add_argument("--window", type=int, default=20_000,
                        help="steps at the end of each run whose episodes are summarised")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    runs = sorted({m.parent for root in args.roots for m in root.rglob("manifest.json")})
    if not runs:
        print("no runs found", file=sys.stderr)
        return 2
    rows = [summarize(run, args.window) for run in runs]
    print(f"training episodes that ended in the last {args.window} steps of each run\n")
    cells = []
    for r in rows:
        per_step = "-" if r["return_per_step"] is None else f"{r['return_per_step']:.3f}"
        best = "-" if r["best_eval_success"] is None else f"{100 * r['best_eval_success']:.0f} %"
        kwargs = ", ".join(f"{k}={v}" for k, v in r["env_kwargs"].items()) or "-"
        cells.append([r["run"], r["algo"], r["settings"], kwargs, f"{r['steps'] // 1000}k",
                      per_step, r["safety_stops"], f"{r['successes']} / {r['window_episodes']}",
                      best])
    print(markdown_table(["run", "algo", "settings", "env kwargs", "steps", "return per step",
                          "safety stops", "successes / episodes", "best eval success"], cells))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
