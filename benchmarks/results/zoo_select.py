"""Choose the zoo's agents on validation episodes, and export them.

    python benchmarks/results/stratified_results.py RUNS... --profiles validation --per-cell 1 \
        --seed 40000 --json val.json
    python benchmarks/results/zoo_select.py val.json [more.json ...] [--export] [--zoo DIR]
        [--min-success 0.5] [--skip ENV/AGENT ...]
    python benchmarks/results/heldout_results.py --runs RUNS --split validation --json val.json
    python benchmarks/results/zoo_select.py val.json --export --no-full   # envelope-trained

Runs trained on patients across the adult envelope are chosen on the envelope's validation
cohort (``heldout_results.py --split validation``: bodies and conditions of their own, seeds
from 40 000): the seed that finished the most of the validation episodes the scripted expert
finishes. Such an agent is filed under its base id (``rehab-knee-v2/sac``), with the
population it trained on in its metadata. ``--no-full`` exports the actor alone (no full
model: the package's git history does not hold one).

For every env x algorithm row of ``benchmarks/results/stratified_results.py`` (the runs of one id,
robot and algorithm), the run whose final model finished the most validation episodes is
chosen (ties: the lower training seed). The validation episodes are ``stratified_results``'
cells (every exercise x weight level x profile) with patients of their own (``--profiles
validation``) and seeds of their own (40 000 onwards), never the test patients and episodes
(50 000 onwards) that ``docs/results/learning-v2.md`` reports, so the published figures are not the
ones the choice was made on (a healthy id's episode depends on the patient, not the seed).
A row whose best seed finishes fewer than ``--min-success`` of its validation episodes
(default half) is not shipped: the table says so. ``--export`` writes each choice to
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

from rehabbot.common.text_tables import markdown_table
from rehabbot.envs.registration import POPULATION_VARIANTS, env_short_name
from rehabbot.rl import runs, zoo
from rehabbot.rl.zoo_export import export_policy

VALIDATION_SEED = 40_000
MIN_SUCCESS = 0.5


def choices(validation: dict[str, Any]) -> list[dict[str, Any]]:
    """One choice per row of a ``stratified_results --json`` file: the run with the most
    successful validation episodes (ties: the lower training seed)."""
    if validation["seed"] >= 50_000 or validation.get("profile_set") != "validation":
        raise ValueError(f"the file holds episodes from seed {validation['seed']} of the "
                         f"{validation.get('profile_set', 'test')} patients: choose on "
                         "validation episodes (--profiles validation --seed 40000)")
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


def heldout_choices(validation: dict[str, Any]) -> list[dict[str, Any]]:
    """One choice per row of a ``heldout_results.py --split validation --json`` file: the run
    that finished the most validation episodes the expert finishes (ties: the lower seed)."""
    if validation.get("split") != "validation":
        raise ValueError(f"the file holds the {validation.get('split')!r} split: choose on "
                         "validation episodes (heldout_results.py --split validation)")
    rows: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for entry in validation["per_controller"]:
        if entry["kind"] != "run":
            continue
        manifest = runs.read_manifest(Path(entry["run_dir"])) or {}
        env_id = POPULATION_VARIANTS.get(manifest["env_id"], manifest["env_id"])
        rows[(env_id, zoo.agent_name(manifest["algo"], manifest.get("env_kwargs")))].append(
            entry)
    picked = []
    for (env_id, name), row in sorted(rows.items()):
        rates = {int(e["train_seed"]): e["finished"] / max(e["of"], 1) for e in row}
        best = max(row, key=lambda e: (rates[int(e["train_seed"])], -int(e["train_seed"])))
        picked.append({"env_id": env_id, "agent": name, "run_dir": best["run_dir"],
                       "seed": int(best["train_seed"]), "success_by_seed": rates,
                       "episodes_per_run": best["of"]})
    return picked


def merge(files: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One validation record of several ``stratified_results --json`` files of the same
    episodes (first seed and episodes per cell); their commands are kept, joined by ``; ``."""
    if not files:
        raise ValueError("no validation file")
    first = files[0]
    for other in files[1:]:
        if ((other["seed"], other["per_cell"], other.get("profile_set"))
                != (first["seed"], first["per_cell"], first.get("profile_set"))):
            raise ValueError(f"validation files of different episodes: seed {other['seed']}, "
                             f"{other['per_cell']} per cell, {other.get('profile_set')} "
                             f"patients against seed {first['seed']}, {first['per_cell']} "
                             f"per cell, {first.get('profile_set')} patients")
    return {"seed": first["seed"], "per_cell": first["per_cell"],
            "profile_set": first.get("profile_set", "test"),
            "command": "; ".join(str(f.get("command")) for f in files),
            "results": [entry for f in files for entry in f["results"]]}


def selection_note(choice: dict[str, Any], validation: dict[str, Any]) -> dict[str, Any]:
    """The ``selection`` metadata of an exported agent."""
    if "per_controller" in validation:  # the envelope's validation cohort
        return {"selection": {
            "rule": "the final model of the training seed that finished the most of the "
                    "validation episodes the scripted expert finishes (ties: the lower seed)",
            "validation_command": validation.get("command"),
            "validation_episodes": {"first_seed": validation["seed"],
                                    "patients": "envelope-validation",
                                    "expert_finished_per_run": choice["episodes_per_run"]},
            "success_by_seed": {str(k): v
                                for k, v in sorted(choice["success_by_seed"].items())},
            "chosen_seed": choice["seed"],
            "test_results": "docs/results/heldout-envelope.md (held-out episodes from seed "
                            "60000)"}}
    return {"selection": {
        "rule": "the final model of the training seed that finished the most validation "
                "episodes (ties: the lower seed)",
        "validation_command": validation.get("command"),
        "validation_episodes": {"first_seed": validation["seed"],
                                "patients": validation.get("profile_set"),
                                "per_cell": validation["per_cell"],
                                "per_run": choice["episodes_per_run"]},
        "success_by_seed": {str(k): v for k, v in sorted(choice["success_by_seed"].items())},
        "chosen_seed": choice["seed"],
        "test_results": "docs/results/learning-v2.md (held-out episodes from seed 50000)"}}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("validation", type=Path, nargs="+",
                        help="stratified_results.py --json files of validation episodes "
                             "(their rows are merged)")
    parser.add_argument("--min-success", type=float, default=MIN_SUCCESS, metavar="F",
                        help="ship a row only if its best seed finishes at least this fraction "
                             f"of its validation episodes (default {MIN_SUCCESS})")
    parser.add_argument("--skip", nargs="+", default=[], metavar="ENV/AGENT",
                        help="rows to leave as they are in the zoo (e.g. rehab-hip-v2/sac)")
    parser.add_argument("--export", action="store_true",
                        help="export every choice to the zoo with its whole model")
    parser.add_argument("--zoo", type=Path, help="the zoo folder (default: the package's)")
    parser.add_argument("--no-full", action="store_true",
                        help="export the actors alone, without their full models")
    args = parser.parse_args(argv)
    if not 0.0 <= args.min_success <= 1.0:
        parser.error(f"--min-success {args.min_success} must be in [0, 1]")
    files = [json.loads(path.read_text()) for path in args.validation]
    if all("per_controller" in f for f in files) and len(files) == 1:
        validation, picked = files[0], heldout_choices(files[0])
    else:
        validation = merge(files)
        picked = choices(validation)
    shipped, cells = [], []
    for choice in picked:
        rates = ", ".join(f"{seed}: {100 * rate:.0f} %"
                          for seed, rate in sorted(choice["success_by_seed"].items()))
        name = f"{env_short_name(choice['env_id'])}/{choice['agent']}"
        best = choice["success_by_seed"][choice["seed"]]
        verdict = ("no (--skip)" if name in args.skip else
                   f"no (below {100 * args.min_success:.0f} %)" if best < args.min_success
                   else "yes")
        if verdict == "yes":
            shipped.append(choice)
        cells.append([name, choice["seed"], rates, choice["run_dir"], verdict])
    print(markdown_table(["agent", "chosen seed", "validation success by seed", "run",
                          "shipped"], cells), flush=True)
    if args.export:
        for choice in shipped:
            out = zoo.zoo_path(choice["env_id"], choice["agent"], args.zoo)
            meta = export_policy(choice["run_dir"], out_path=out, full=not args.no_full,
                                 metadata=selection_note(choice, validation))
            print(f"wrote {out}: success {meta.get('success_rate')} on "
                  f"{(meta.get('evaluation') or {}).get('episodes')} episodes", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
