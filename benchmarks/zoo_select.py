"""Choose the zoo's agents on validation episodes, and export them.

    python benchmarks/stratified_results.py RUNS... --per-cell 1 --seed 40000 --json val.json
    python benchmarks/zoo_select.py val.json [--export] [--zoo DIR]

For every env x algorithm row of ``benchmarks/stratified_results.py`` (the runs of one id,
robot and algorithm), the run whose final model finished the most validation episodes is
chosen (ties: the lower training seed). The validation episodes are ``stratified_results``'
cells (every exercise x weight level x profile) on seeds of their own (40 000 onwards), never
the held-out test episodes (50 000 onwards) that ``docs/results-v2.md`` reports, so the
published figures are not the ones the choice was made on. ``--export`` writes each choice to
the zoo with its whole model (``rehabbot zoo export RUN --full``), recording the choice in the
agent's metadata (``selection``: the validation file's command, every seed's success and the
chosen seed). Without ``--export`` it only prints the table.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.envs.registration import env_short_name
from rehabbot.rl import runs, zoo
from rehabbot.rl.zoo_export import export_policy

VALIDATION_SEED = 40_000


def choices(validation: dict[str, Any]) -> list[dict[str, Any]]:
    """One choice per row of a ``stratified_results --json`` file: the run with the most
    successful validation episodes (ties: the lower training seed)."""
    if validation["seed"] >= 50_000:
        raise ValueError(f"the file holds episodes from seed {validation['seed']}: the test "
                         "episodes; choose on validation episodes (--seed 40000)")
    rows: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for entry in validation["results"]:
        if entry["algo"] == "expert":
            continue
        for run in entry["runs"]:
            if run.get("run_dir") and Path(run["run_dir"], runs.MANIFEST_NAME).is_file():
                manifest = runs.read_manifest(Path(run["run_dir"])) or {}
                name = zoo.agent_name(manifest["algo"], manifest.get("env_kwargs"))
                rows[(manifest["env_id"], name)].append(run)
    picked = []
    for (env_id, name), row in sorted(rows.items()):
        rates = {int(run["train_seed"]): float(np.mean([e["success"] for e in run["episodes"]]))
                 for run in row}
        best = max(row, key=lambda run: (rates[int(run["train_seed"])], -int(run["train_seed"])))
        picked.append({"env_id": env_id, "agent": name, "run_dir": best["run_dir"],
                       "seed": int(best["train_seed"]), "success_by_seed": rates,
                       "episodes_per_run": len(best["episodes"])})
    return picked


def selection_note(choice: dict[str, Any], validation: dict[str, Any]) -> dict[str, Any]:
    """The ``selection`` metadata of an exported agent."""
    return {"selection": {
        "rule": "the final model of the training seed that finished the most validation "
                "episodes (ties: the lower seed)",
        "validation_command": validation.get("command"),
        "validation_episodes": {"first_seed": validation["seed"],
                                "per_cell": validation["per_cell"],
                                "per_run": choice["episodes_per_run"]},
        "success_by_seed": {str(k): v for k, v in sorted(choice["success_by_seed"].items())},
        "chosen_seed": choice["seed"],
        "test_results": "docs/results-v2.md (held-out episodes from seed 50000)"}}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("validation", type=Path,
                        help="a stratified_results.py --json file of validation episodes")
    parser.add_argument("--export", action="store_true",
                        help="export every choice to the zoo with its whole model")
    parser.add_argument("--zoo", type=Path, help="the zoo folder (default: the package's)")
    args = parser.parse_args(argv)
    validation = json.loads(args.validation.read_text())
    picked = choices(validation)
    print("| agent | chosen seed | validation success by seed | run |")
    print("|---|---|---|---|")
    for choice in picked:
        rates = ", ".join(f"{seed}: {100 * rate:.0f} %"
                          for seed, rate in sorted(choice["success_by_seed"].items()))
        print(f"| {env_short_name(choice['env_id'])}/{choice['agent']} | {choice['seed']} | "
              f"{rates} | {choice['run_dir']} |", flush=True)
    if args.export:
        for choice in picked:
            out = zoo.zoo_path(choice["env_id"], choice["agent"], args.zoo)
            meta = export_policy(choice["run_dir"], out_path=out, full=True,
                                 metadata=selection_note(choice, validation))
            print(f"wrote {out}: success {meta.get('success_rate')} on "
                  f"{(meta.get('evaluation') or {}).get('episodes')} episodes", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
