"""Controllers and agents on impaired patients: the README's "Patients with conditions" tables.

For every registered condition variant (``CONDITION_VARIANTS``) and for the held-out ``"test"``
population of each population id (``POPULATION_VARIANTS``), the same seeded episodes of:

* ``expert``: the scripted expert;
* ``aan``: the assist-as-needed controller (:mod:`rehabbot.rl.assist_as_needed`);
* ``sac-healthy``: SAC trained on a healthy patient: seed 0 of the base ``-v1`` id's run in
  ``--healthy-runs`` (e.g. ``runs/results-v1-sac``: the same settings, budget and seed as the
  runs on impaired patients), else the zoo's agent of the base id (the best of 3 seeds);
* ``sac-condition`` / ``sac-population``: SAC trained on that variant (from ``RUNS``, e.g.
  ``runs/results-conditions-sac``) or on the ``"train"`` population (``--population-runs``),
  when the run exists.

Per policy: success rate, mean return, peak cuff force, safety stops, the robot's work on the
limb and the assistance ratio (means over episodes).

Usage::

    python benchmarks/results/condition_results.py [RUNS] [--population-runs DIR]
        [--healthy-runs DIR] [--episodes 20] [--seed 1000] [--ids ID ...]
                                           [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from rehabbot.analysis.evaluation import evaluate_policies
from rehabbot.common.text_tables import markdown_table
from rehabbot.envs.registration import CONDITION_VARIANTS, POPULATION_VARIANTS, env_short_name


def _model(runs: Path | None, env_id: str) -> str | None:
    if runs is None:
        return None
    path = runs / env_short_name(env_id) / "sac" / "seed0" / "model.zip"
    return str(path) if path.exists() else None


def evaluate_case(env_id: str, env_kwargs: dict, base_id: str, trained: str | None,
                  trained_label: str, episodes: int, seed: int,
                  healthy: str | None = None) -> list[dict]:
    specs = ["expert", "aan", healthy or f"zoo:{env_short_name(base_id)}/sac"]
    labels = ["expert", "aan", "sac-healthy"]
    if trained is not None:
        specs.append(trained)
        labels.append(trained_label)
    rows = []
    for label, (report, _trace) in zip(labels, evaluate_policies(
            specs, env_id, episodes=episodes, seed=seed, env_kwargs=env_kwargs), strict=True):
        summary = report["summary"]
        stops = {rule: n for rule, n in summary["safety_terminations"].items() if n}
        rows.append({"env_id": env_id, "env_kwargs": env_kwargs, "policy": label,
                     "spec": report["policy"], "episodes": episodes,
                     "episode_seeds": report["episode_seeds"],
                     "success_rate": summary["success_rate"],
                     "return": summary["return"]["mean"],
                     "peak_cuff_force_n": summary["peak_cuff_force_n"]["mean"],
                     "stops": stops,
                     "robot_work_j": summary["robot_work_j"]["mean"],
                     "assistance_ratio": summary["assistance_ratio"]["mean"],
                     "rom_achieved_fraction": summary["rom_achieved_fraction"]["mean"]})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="?", type=Path, default=None,
                        help="folder of the SAC runs on the condition variants")
    parser.add_argument("--population-runs", type=Path, default=None,
                        help="folder of the SAC runs on the population ids")
    parser.add_argument("--healthy-runs", type=Path, default=None,
                        help="folder of the SAC runs on the healthy -v1 ids (default: the zoo)")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--ids", nargs="+", default=None, help="only these ids")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    started = time.perf_counter()
    cases = [(env_id, {}, base, _model(args.runs, env_id), "sac-condition")
             for env_id, (base, _condition, _text) in CONDITION_VARIANTS.items()]
    cases += [(env_id, {"patients": "test"}, base, _model(args.population_runs, env_id),
               "sac-population") for env_id, base in POPULATION_VARIANTS.items()]
    if args.ids:
        cases = [c for c in cases if env_short_name(c[0]) in args.ids or c[0] in args.ids]
    rows = []
    print(f"{args.episodes} episodes per policy, seeds {args.seed}..{args.seed + args.episodes - 1}"
          "\n")
    cells = []
    for env_id, kwargs, base, trained, label in cases:
        for row in evaluate_case(env_id, kwargs, base, trained, label, args.episodes, args.seed,
                                 _model(args.healthy_runs, base)):
            rows.append(row)
            name = env_short_name(env_id) + (" (test patients)" if kwargs else "")
            stops = ", ".join(f"{n} {rule}" for rule, n in row["stops"].items()) or "-"
            cells.append([name, row["policy"], f"{100 * row['success_rate']:.0f} %",
                          f"{row['return']:.0f}", f"{row['peak_cuff_force_n']:.0f}", stops,
                          f"{row['robot_work_j']:.2f}", f"{row['assistance_ratio']:.2f}",
                          f"{row['rom_achieved_fraction']:.2f}"])
            print(f"{name} / {row['policy']}: done", file=sys.stderr, flush=True)
    print(markdown_table(["env", "policy", "success", "return", "peak cuff force [N]", "stops",
                          "robot work [J]", "assistance ratio", "ROM achieved"], cells))
    print(f"\n({time.perf_counter() - started:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps({"command": "python " + " ".join(sys.argv),
                                               "rows": rows}, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
