"""Success of trained runs on held-out episodes stratified over every exercise x weight level x
patient profile: the per-cell table and, per env and algorithm, the IQM over seeds with a 95 %
percentile-bootstrap interval (rliable's recommendation, :mod:`rehabbot.analysis.aggregate`).

Each run folder (``.../<env>/<algo>/seed<k>/`` with a ``model.zip``) is evaluated with
deterministic actions on ``--per-cell`` episodes of every cell: each exercise of the id, each
weight level 0..4 and each of three profiles (the 1.75 m, 75 kg man the runs trained on, and two
held out: a 1.60 m, 60 kg woman and a 1.85 m, 90 kg man). Episode seeds start at ``--seed``
(default 50 000, far from the training seeds, the expert demonstrations' 20 000 + i and the
evaluation callback's) and count up over the cells, the same for every run. The scripted
expert runs the same episodes as a reference. Every number in the output comes from these
episodes; ``--json`` keeps them all (with each episode's seed, cell, outcome and safety rule).

Usage::

    python benchmarks/stratified_results.py runs/v2 [--per-cell 2] [--seed 50000] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.analysis.aggregate import iqm_interval
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import runs
from rehabbot.rl.policies import load_policy
from rehabbot.sim.scene import WEIGHT_LEVELS

PROFILES = {
    "m175": None,  # 1.75 m, 75 kg, male: the profile training uses
    "f160": {"height_m": 1.60, "mass_kg": 60.0, "sex": "female"},
    "m185": {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"},
}
DEFAULT_SEED = 50_000


def find_runs(roots: Sequence[Path]) -> list[Path]:
    """Run folders (a manifest and a final model) below ``roots``."""
    found = []
    for root in roots:
        found += [m.parent for m in sorted(Path(root).rglob(runs.MANIFEST_NAME))
                  if (m.parent / runs.MODEL_NAME).is_file()]
    return found


def evaluate_cells(spec: str, env_id: str, env_kwargs: dict, per_cell: int,
                   seed: int) -> list[dict]:
    """Every episode of ``spec`` (a model path or ``expert``) over the cells of ``env_id``."""
    episodes = []
    next_seed = seed
    for profile_name, profile in PROFILES.items():
        kwargs = dict(env_kwargs)
        if profile is not None:
            kwargs["profile"] = profile
        env = gym.make(env_id, **kwargs)
        try:
            policy = load_policy(spec, env, seed=0)
            for exercise in range(len(env.unwrapped.targets)):
                for level in WEIGHT_LEVELS:
                    for _ in range(per_cell):
                        obs, info = env.reset(seed=next_seed, options={
                            "exercise": exercise, "weight_level": level})
                        done, steps = False, 0
                        while not done:
                            obs, _, terminated, truncated, info = env.step(policy.act(obs))
                            done, steps = terminated or truncated, steps + 1
                        episodes.append({
                            "seed": next_seed, "profile": profile_name, "exercise": exercise,
                            "weight_level": level, "success": bool(info["is_success"]),
                            "safety_violation": info["safety_violation"], "steps": steps})
                        next_seed += 1
        finally:
            env.close()
    return episodes


def training_text(manifest: dict) -> str:
    """How a run trained, from its manifest: library, policy, steps, demonstrations."""
    hp = manifest.get("hyperparameters") or {}
    demos = (manifest.get("demos") or {}).get("episodes", 0)
    kwargs = hp.get("kwargs") or {}
    returns = f"{kwargs.get('n_steps')}-step returns, " if kwargs.get("n_steps") else ""
    return (f"{manifest.get('backend')} {hp.get('policy')}, {returns}"
            f"{manifest.get('timesteps_done')} steps"
            + (f", {demos} expert episodes in the buffer" if demos else ""))


def skrl_run(data: dict, path: str) -> dict:
    """A run of ``examples/skrl_sac.py`` (its ``result.json``) in this script's format."""
    names = {json.dumps(v, sort_keys=True): k for k, v in PROFILES.items()}
    episodes = [{**e, "profile": names[json.dumps(e["profile"], sort_keys=True)]}
                for e in data["evaluation"]["episodes"]]
    return {"run_dir": path, "train_seed": data["seed"], "env_kwargs": data["env_kwargs"],
            "timesteps": data["timesteps"], "episodes": episodes,
            "training": f"skrl {data['skrl_version']} SAC, 256 x 256 MLPs, 1-step returns, "
                        f"{data['timesteps']} steps"}


def cell_key(episode: dict) -> tuple[int, int, str]:
    return episode["exercise"], episode["weight_level"], episode["profile"]


def summarize(results: dict[tuple[str, str], list[dict]]) -> str:
    """Markdown: one row per env and algorithm (IQM over seeds), then the per-cell tables."""
    lines = ["| env | algo | training (from the runs' manifests) | seeds | success per seed | "
             "success IQM [95 % CI] | expert |", "|---|---|---|---|---|---|---|"]
    cells_text = []
    for (env_id, algo), entries in sorted(results.items()):
        if algo == "expert":
            continue
        rates = [float(np.mean([e["success"] for e in r["episodes"]])) for r in entries]
        interval = iqm_interval(rates)
        expert = results.get((env_id, "expert"), [{}])[0].get("episodes", [])
        expert_rate = f"{100 * np.mean([e['success'] for e in expert]):.0f} %" if expert else "-"
        seeds = ", ".join(str(r["train_seed"]) for r in entries)
        per_seed = ", ".join(f"{100 * x:.0f}" for x in rates)
        training = "; ".join(sorted({r.get("training", "-") for r in entries}))
        lines.append(f"| {env_short_name(env_id)} | {algo} | {training} | {seeds} | "
                     f"{per_seed} % | {interval.format(0, 100)} % | {expert_rate} |")
        by_cell: dict[tuple, list[bool]] = defaultdict(list)
        stops: dict[tuple, list[str]] = defaultdict(list)
        for r in entries:
            for e in r["episodes"]:
                by_cell[cell_key(e)].append(e["success"])
                if e["safety_violation"]:
                    stops[cell_key(e)].append(e["safety_violation"])
        exercises = sorted({k[0] for k in by_cell})
        header = "| exercise | profile | " + " | ".join(f"l{lv}" for lv in WEIGHT_LEVELS) + " |"
        cells_text += [f"\n{env_short_name(env_id)} / {algo}: success per cell (all seeds; "
                       "stops in brackets)\n", header,
                       "|---|---|" + "---|" * len(WEIGHT_LEVELS)]
        for exercise in exercises:
            for profile in PROFILES:
                row = []
                for level in WEIGHT_LEVELS:
                    cell = by_cell[(exercise, level, profile)]
                    text = f"{sum(cell)}/{len(cell)}"
                    if stops[(exercise, level, profile)]:
                        kinds = sorted(set(stops[(exercise, level, profile)]))
                        text += f" ({len(stops[(exercise, level, profile)])} {'/'.join(kinds)})"
                    row.append(text)
                cells_text.append(f"| {exercise} | {profile} | " + " | ".join(row) + " |")
    return "\n".join(lines + cells_text)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="*", type=Path, help="folders holding run folders")
    parser.add_argument("--per-cell", type=int, default=2,
                        help="episodes per exercise x weight level x profile (default 2)")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED,
                        help=f"first episode seed (default {DEFAULT_SEED})")
    parser.add_argument("--json", type=Path, help="write every episode to this file")
    parser.add_argument("--skrl", type=Path, nargs="+", default=[], metavar="RESULT.json",
                        help="result.json files of examples/skrl_sac.py, shown as their own "
                             "rows (their episodes are that script's, seeds from 60000)")
    parser.add_argument("--from-json", type=Path, nargs="+", default=[], metavar="FILE",
                        help="render the tables from files written by --json (no evaluation; "
                             "the runs of every file are merged)")
    parser.add_argument("--markdown", type=Path,
                        help="also write the tables to this Markdown file (with the command)")
    args = parser.parse_args(argv)
    if args.per_cell < 1:
        parser.error(f"--per-cell {args.per_cell} must be at least 1")
    found = find_runs(args.roots)
    if not found and not args.skrl and not args.from_json:
        parser.error(f"no run folder with a {runs.MODEL_NAME} under {args.roots}")
    results: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for path in args.from_json:
        saved = json.loads(path.read_text())
        if (saved["per_cell"], saved["seed"]) != (args.per_cell, args.seed):
            parser.error(f"{path} holds --per-cell {saved['per_cell']} --seed {saved['seed']}, "
                         f"not {args.per_cell} and {args.seed}")
        for entry in saved["results"]:
            key = (entry["env_id"], entry["algo"])
            if entry["algo"] == "expert" and key in results:
                continue
            results[key] += entry["runs"]
    for run_dir in found:
        manifest = runs.read_manifest(run_dir) or {}
        env_id, algo = manifest["env_id"], manifest["algo"]
        env_kwargs = manifest.get("env_kwargs") or {}
        episodes = evaluate_cells(str(run_dir / runs.MODEL_NAME), env_id, env_kwargs,
                                  args.per_cell, args.seed)
        results[(env_id, algo)].append({"run_dir": str(run_dir), "train_seed":
                                        manifest.get("seed"), "env_kwargs": env_kwargs,
                                        "timesteps": manifest.get("timesteps_done"),
                                        "training": training_text(manifest),
                                        "episodes": episodes})
        rate = np.mean([e["success"] for e in episodes])
        print(f"{run_dir}: {100 * rate:.0f} % of {len(episodes)} episodes", file=sys.stderr,
              flush=True)
        if (env_id, "expert") not in results:
            results[(env_id, "expert")].append({
                "run_dir": None, "train_seed": None, "env_kwargs": env_kwargs,
                "episodes": evaluate_cells("expert", env_id, env_kwargs, args.per_cell,
                                           args.seed)})
    for path in args.skrl:
        data = json.loads(path.read_text())
        env_id = data["env"]
        results[(env_id, "sac (skrl)")].append(skrl_run(data, str(path)))
        if (env_id, "expert") not in results:
            results[(env_id, "expert")].append({
                "run_dir": None, "train_seed": None, "env_kwargs": {},
                "episodes": evaluate_cells("expert", env_id, {}, args.per_cell, args.seed)})
    command = " ".join(["python", "benchmarks/stratified_results.py",
                        *map(str, argv if argv is not None else sys.argv[1:])])
    text = (f"episodes from seed {args.seed} ({args.per_cell} per exercise x weight level x "
            "profile, deterministic actions), every run's final model\n\n"
            + summarize(results))
    print(text)
    if args.markdown:
        args.markdown.write_text(f"<!-- generated by: {command} -->\n\n{text}\n")
    if args.json:
        args.json.write_text(json.dumps({
            "command": command,
            "per_cell": args.per_cell, "seed": args.seed, "profiles": PROFILES,
            "results": [{"env_id": k[0], "algo": k[1], "runs": v} for k, v in results.items()],
        }, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
