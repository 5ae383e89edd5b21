"""The README's results table: every training run under the given folders, evaluated on the
same episode seeds, next to the scripted expert and random actions.

For each run folder (``.../<env>/<algo>/seed<k>/`` with a ``model.zip``) the final model is
evaluated with :func:`rehabbot.analysis.evaluation.evaluate` on ``--episodes`` episodes seeded
``--seed``, ``--seed`` + 1, ... (deterministic actions); runs of one algorithm and env are then
pooled (mean ± std over seeds of each seed's mean; success over all episodes). Wall-clock is
the training time from each run's manifest. Rows are printed as a Markdown table, and with
``--json`` written to a file.

Usage::

    python benchmarks/results_table.py runs/results [--episodes 20] [--seed 1000] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rehabbot.analysis.evaluation import evaluate
from rehabbot.envs.registration import env_short_name


def find_runs(roots: Sequence[Path]) -> list[Path]:
    """Run folders (a manifest and a final model) below ``roots``."""
    runs = []
    for root in roots:
        runs += [m.parent for m in sorted(root.rglob("manifest.json"))
                 if (m.parent / "model.zip").is_file()]
    return runs


def _fmt(values: list[float], digits: int = 0) -> str:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    if not finite:
        return "-"
    if len(finite) == 1:
        return f"{finite[0]:.{digits}f}"
    return f"{np.mean(finite):.{digits}f} ± {np.std(finite):.{digits}f}"


def table_rows(roots: Sequence[Path], episodes: int, seed: int) -> list[dict]:
    groups: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    env_ids = set()
    for run in find_runs(roots):
        manifest = json.loads((run / "manifest.json").read_text())
        report, _trace = evaluate(str(run / "model.zip"), None, episodes, seed)
        key = (manifest["env_id"], manifest["algo"], str(manifest["hyperparameters"]
                                                          .get("source", "sb3 defaults")))
        env_ids.add(manifest["env_id"])
        groups[key].append({"manifest": manifest, "report": report})
    rows = []
    for (env_id, algo, source), runs in sorted(groups.items()):
        rows.append(_row(env_id, algo.upper(), source, runs))
    for env_id in sorted(env_ids):
        for policy in ("expert", "random"):
            report, _trace = evaluate(policy, env_id, episodes, seed)
            rows.append(_row(env_id, policy, "-", [{"manifest": {}, "report": report}]))
    return rows


def _row(env_id: str, name: str, source: str, runs: list[dict]) -> dict:
    per_seed = [r["report"]["summary"] for r in runs]
    episodes = [e for r in runs for e in r["report"]["per_episode"]]
    seeds = [r["manifest"].get("seed") for r in runs]
    return {
        "env": env_short_name(env_id),
        "policy": name,
        "settings": source,
        "steps": sorted({r["manifest"].get("timesteps_done") for r in runs} - {None}),
        "seeds": [s for s in seeds if s is not None],
        "success_rate": float(np.mean([e["success"] for e in episodes])),
        "return": _fmt([s["return"]["mean"] for s in per_seed]) if len(runs) > 1 else
        _fmt([e["return"] for e in episodes]),
        "length": _fmt([e["length"] for e in episodes]),
        "steps_to_finish": _fmt([e["steps_to_finish"] for e in episodes
                                 if e["steps_to_finish"] is not None]),
        "sparc": _fmt([e["sparc"] for e in episodes], 2),
        "safety_stops": sum(e["safety_violation"] is not None for e in episodes),
        "episodes": len(episodes),
        "wall_clock_min": _fmt([r["manifest"]["wall_clock_s"] / 60 for r in runs
                                if "wall_clock_s" in r["manifest"]], 0),
    }


def format_rows(rows: list[dict]) -> str:
    header = ("| env | policy | settings | steps | seeds | success | return | length "
              "| steps to finish | SPARC | safety stops | wall-clock [min] |")
    lines = [header, "|" + "---|" * 12]
    for r in rows:
        steps = "/".join(f"{s // 1000}k" for s in r["steps"]) or "-"
        seeds = ",".join(str(s) for s in r["seeds"]) or "-"
        lines.append(f"| {r['env']} | {r['policy']} | {r['settings']} | {steps} | {seeds} | "
                     f"{100 * r['success_rate']:.0f} % ({r['episodes']} ep.) | {r['return']} | "
                     f"{r['length']} | {r['steps_to_finish']} | {r['sparc']} | "
                     f"{r['safety_stops']} | {r['wall_clock_min']} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+", type=Path, help="folders holding training runs")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per run (20)")
    parser.add_argument("--seed", type=int, default=1000, help="first episode seed (1000)")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = parser.parse_args(argv)
    missing = [str(r) for r in args.roots if not r.is_dir()]
    if missing:
        print(f"not a folder: {', '.join(missing)}", file=sys.stderr)
        return 2
    rows = table_rows(args.roots, args.episodes, args.seed)
    print(f"episodes {args.seed}..{args.seed + args.episodes - 1} per run, deterministic "
          "actions; return: mean ± std over seeds (one seed: over episodes)\n")
    print(format_rows(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
