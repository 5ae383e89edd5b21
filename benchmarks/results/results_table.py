"""The README's results table: every training run under the given folders, evaluated on the
same held-out episodes, next to the scripted expert and random actions.

For each run folder (``.../<env>/<algo>/seed<k>/`` with a ``model.zip``) the final model is
evaluated with :func:`rehabbot.analysis.evaluation.evaluate` on ``--episodes`` episodes seeded
``--seed``, ``--seed`` + 1, ... (deterministic actions), split evenly over the patient profiles
of ``--profiles``: the default profile the runs trained on and, unless ``--profiles default``,
two held-out ones (a 1.60 m, 60 kg woman and a 1.85 m, 90 kg man). Runs of one algorithm and env
are then aggregated across seeds as rliable recommends: the interquartile mean of each seed's
success rate and return, with a 95 % percentile-bootstrap interval
(:mod:`benchmarks.common.aggregate`). Wall-clock is the training time from each run's
manifest. Rows are printed as a Markdown table, and with ``--json`` written to a file.

Usage::

    python benchmarks/results/results_table.py runs/results [--episodes 50] [--seed 1000] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.aggregate import iqm_interval
from rehabbot.analysis.evaluation import evaluate
from rehabbot.common.text_tables import markdown_table
from rehabbot.envs.registration import env_short_name

HELD_OUT_PROFILES = {
    "default": None,  # 1.75 m, 75 kg, male: the profile training uses
    "f160": {"height_m": 1.60, "mass_kg": 60.0, "sex": "female"},
    "m185": {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"},
}


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


def _evaluate(spec: str, env_id: str | None, episodes: int, seed: int,
              profiles: Sequence[str], env_kwargs: dict | None = None) -> dict:
    """One policy on ``episodes`` episodes split over ``profiles``: a report whose
    ``per_episode`` list holds every episode (with its profile). ``env_kwargs`` (a run's,
    such as ``robot``) apply to every profile."""
    per_episode = []
    share = [episodes // len(profiles) + (k < episodes % len(profiles))
             for k in range(len(profiles))]
    first = seed
    for name, count in zip(profiles, share, strict=True):
        if count == 0:
            continue
        profile = HELD_OUT_PROFILES[name]
        kwargs = dict(env_kwargs or {})
        if profile is not None:
            kwargs["profile"] = profile
        report, _trace = evaluate(spec, env_id, count, first, env_kwargs=kwargs)
        per_episode += [{**e, "profile": name} for e in report["per_episode"]]
        first += count
    return {"per_episode": per_episode}


def table_rows(roots: Sequence[Path], episodes: int, seed: int,
               profiles: Sequence[str] = tuple(HELD_OUT_PROFILES)) -> list[dict]:
    """Rows of runs grouped by env (its id and the runs' env kwargs, such as
    ``robot="fr3"``), algorithm and settings, then the expert and random actions in each env."""
    groups: dict[tuple[str, str, str, str], list[dict]] = defaultdict(list)
    envs: dict[tuple[str, str], dict] = {}
    for run in find_runs(roots):
        manifest = json.loads((run / "manifest.json").read_text())
        report = _evaluate(str(run / "model.zip"), None, episodes, seed, profiles)
        env_kwargs = dict(manifest.get("env_kwargs") or {})
        env = (manifest["env_id"], json.dumps(env_kwargs, sort_keys=True))
        envs[env] = env_kwargs
        key = (*env, manifest["algo"], str(manifest["hyperparameters"]
                                           .get("source", "sb3 defaults")))
        groups[key].append({"manifest": manifest, "report": report})
    rows = []
    for (env_id, kwargs_key, algo, source), runs in sorted(groups.items()):
        backend = "/".join(sorted({r["manifest"].get("backend", "sb3") for r in runs}))
        rows.append(_row(env_id, f"{algo.upper()} ({backend})", source, runs,
                         envs[(env_id, kwargs_key)]))
    for (env_id, _), env_kwargs in sorted(envs.items()):
        for policy in ("expert", "random"):
            report = _evaluate(policy, env_id, episodes, seed, profiles, env_kwargs)
            rows.append(_row(env_id, policy, "-", [{"manifest": {}, "report": report}],
                             env_kwargs))
    return rows


def env_label(env_id: str, env_kwargs: dict | None) -> str:
    """The env column: the short id, and the env kwargs the runs were trained with."""
    extra = ", ".join(f"{k}={v!r}" if isinstance(v, str) else f"{k}={v}"
                      for k, v in sorted((env_kwargs or {}).items()))
    return f"{env_short_name(env_id)} ({extra})" if extra else env_short_name(env_id)


def _row(env_id: str, name: str, source: str, runs: list[dict],
         env_kwargs: dict | None = None) -> dict:
    episodes = [e for r in runs for e in r["report"]["per_episode"]]
    seeds = [r["manifest"].get("seed") for r in runs]
    success = iqm_interval([np.mean([e["success"] for e in r["report"]["per_episode"]])
                            for r in runs])
    returns = iqm_interval([np.mean([e["return"] for e in r["report"]["per_episode"]])
                            for r in runs])
    held_out = [e for e in episodes if e["profile"] != "default"]
    return {
        "env": env_label(env_id, env_kwargs),
        "policy": name,
        "settings": source,
        "steps": sorted({r["manifest"].get("timesteps_done") for r in runs} - {None}),
        "seeds": [s for s in seeds if s is not None],
        "success_rate": float(np.mean([e["success"] for e in episodes])),
        "success_iqm": success.format(0, 100),
        "held_out_success_rate": float(np.mean([e["success"] for e in held_out]))
        if held_out else None,
        "return_iqm": returns.format(0),
        "steps_to_finish": _fmt([e["steps_to_finish"] for e in episodes
                                 if e["steps_to_finish"] is not None]),
        "sparc": _fmt([e["sparc"] for e in episodes], 2),
        "peak_cuff_force_n": _fmt([e["peak_cuff_force_n"] for e in episodes]),
        "safety_stops": sum(e["safety_violation"] is not None for e in episodes),
        "episodes": len(episodes),
        "wall_clock_min": _fmt([r["manifest"]["wall_clock_s"] / 60 for r in runs
                                if "wall_clock_s" in r["manifest"]], 0),
    }


def format_rows(rows: list[dict]) -> str:
    header = ["env", "policy", "settings", "steps", "seeds", "success, IQM [95 % CI]",
              "success, all episodes (held-out profiles)", "return, IQM [95 % CI]",
              "steps to finish", "SPARC", "peak cuff force [N]", "safety stops",
              "wall-clock [min]"]
    lines = []
    for r in rows:
        steps = "/".join(f"{s // 1000}k" for s in r["steps"]) or "-"
        seeds = ",".join(str(s) for s in r["seeds"]) or "-"
        held = r["held_out_success_rate"]
        held = "" if held is None else f" ({100 * held:.0f} %)"
        lines.append([r["env"], r["policy"], r["settings"], steps, seeds, f"{r['success_iqm']} %",
                      f"{100 * r['success_rate']:.0f} %{held} of {r['episodes']}",
                      r["return_iqm"], r["steps_to_finish"], r["sparc"],
                      r["peak_cuff_force_n"], r["safety_stops"], r["wall_clock_min"]])
    return markdown_table(header, lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+", type=Path, help="folders holding training runs")
    parser.add_argument("--episodes", type=int, default=50, help="episodes per run (50)")
    parser.add_argument("--profiles", nargs="+", choices=tuple(HELD_OUT_PROFILES),
                        default=list(HELD_OUT_PROFILES),
                        help="patient profiles the episodes are split over (default: all)")
    parser.add_argument("--seed", type=int, default=1000, help="first episode seed (1000)")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = parser.parse_args(argv)
    missing = [str(r) for r in args.roots if not r.is_dir()]
    if missing:
        print(f"not a folder: {', '.join(missing)}", file=sys.stderr)
        return 2
    rows = table_rows(args.roots, args.episodes, args.seed, args.profiles)
    print(f"episodes {args.seed}..{args.seed + args.episodes - 1} per run over profiles "
          f"{', '.join(args.profiles)}, deterministic actions; IQM over seeds with a 95 % "
          "percentile-bootstrap interval (one seed: no interval)\n")
    print(format_rows(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
