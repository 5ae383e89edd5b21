"""Randomisation for transfer: agents trained with and without it, on held-out patients, with
and without the randomisation.

The house protocol of ``heldout_results.py`` (its functions, not a copy): every test body of
the adult envelope (healthy; :mod:`rehabbot.sim.envelope`, none of them trained on) x exercise
x weight level 0-4, deterministic actions, the scripted expert on the same episodes. Played
twice:

* **nominal**: the id's model as built, one episode per cell, seeds from ``--seed`` (60000, the
  held-out page's);
* **randomised**: the same cells with ``randomization=PRESET`` (``"transfer"``,
  :mod:`rehabbot.sim.randomization`), ``--draws`` episodes per cell (3) whose draws come from
  seeds counting up from ``--randomized-seed`` (70000), a stream of its own: a training run
  draws from its run seed's stream (and its expert demonstrations from seeds run seed + 20000
  + i), never these.

Every agent's figure is its success over all the episodes of a setting and the drop from
nominal to randomised in points; the floor: an agent trained with the randomisation drops by
at most ``FLOOR_POINTS`` (10) points, and an agent trained without it drops more. Each
randomised episode's action latency is recorded, for the breakdown by latency (the whole draw
follows from the episode's seed).

Usage::

    python benchmarks/results/transfer_results.py --agent without=zoo:rehab-knee-v2/sac \\
        --agent with=RUN_DIR_OR_MODEL [--env rehab-knee-v2] [--seed 60000] \\
        [--randomized-seed 70000] [--draws 3] [--workers N] [--max-bodies N] \\
        [--page docs/results/transfer]
    python benchmarks/results/transfer_results.py --from-json docs/results/transfer.json \\
        --page docs/results/transfer                            # render again, no episodes

An agent is ``with=SPEC`` or ``without=SPEC`` (whether it trained with the randomisation):
a zoo spec (``zoo:ENV/ALGO``), a run folder (its final model) or a model file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    repo_path,
    table_markdown,
    write_page,
)
from benchmarks.results import heldout_results as heldout
from benchmarks.results import stratified_results as stratified
from rehabbot.rl import runs
from rehabbot.sim.randomization import PRESETS

FLOOR_POINTS = 10.0
PART_TEXT = {"bodies": "the envelope's test bodies, healthy",
             "conditions": "the envelope's test-conditions bodies x held-out conditions"}
SETTINGS = ("nominal", "randomised")
KINDS = ("with", "without")
INTRO = """Agents trained with and without the randomisation for transfer
([the preset](../deployment/randomisation.md): segment masses, passive stiffness and damping,
cuff compliance, joint friction, encoder noise and 0-2 decisions of action latency, drawn every
episode), on {bodies} (held out: none trained on), every exercise x weight level 0-4,
played twice: **nominal** (the model as built, one episode per
cell, seeds from {seed}) and **randomised** ({draws} draws of the preset per cell, seeds from
{randomized_seed}, a stream no training run draws from). The scripted expert plays the same
episodes. The floor: an agent trained with the randomisation loses at most {floor:g} points of
success from nominal to randomised, and an agent trained without it loses more."""


def parse_agent(text: str) -> tuple[str, str]:
    """``with=SPEC`` or ``without=SPEC`` -> (kind, spec); ``ValueError`` naming a bad one."""
    kind, sep, spec = text.partition("=")
    if not sep or kind not in KINDS or not spec:
        raise ValueError(f"--agent {text!r} must be with=SPEC or without=SPEC")
    return kind, spec


def controller(kind: str, spec: str) -> dict[str, Any]:
    """The controller entry of an agent: a zoo agent's (``heldout.zoo_controller``) or a run
    folder's final model (a model file's run folder is its parent)."""
    if spec.startswith("zoo:"):
        _target, entry = heldout.zoo_controller(spec)
        return {**entry, "trained_with": kind}
    path = Path(spec)
    run_dir = path if path.is_dir() else path.parent
    manifest = runs.read_manifest(run_dir)
    if manifest is None:
        raise ValueError(f"{spec}: no run folder ({runs.MANIFEST_NAME}) holds this model")
    model = runs.final_model(run_dir) if path.is_dir() else path
    if model is None or not Path(model).is_file():
        raise ValueError(f"{spec}: the run folder has no final model (is it still training?)")
    kwargs = dict(manifest.get("env_kwargs") or {})
    entry = {"kind": "run", "spec": str(model), "run_dir": repo_path(run_dir),
             "algo": manifest["algo"], "trained_env_id": manifest["env_id"],
             "env_kwargs": kwargs, "train_seed": manifest.get("seed"),
             "timesteps": manifest.get("timesteps_done"),
             "trained_on": heldout.trained_text(manifest["env_id"], kwargs)}
    entry["row"] = stratified.row_label(manifest["algo"], entry)
    return {**entry, "trained_with": kind}


def targets_of(env_id: str, preset: str) -> dict[str, heldout.Target]:
    """The scene, nominal and with the preset."""
    nominal = heldout.make_target(env_id)
    randomised = dataclasses.replace(nominal, kwargs=tuple(sorted(
        {**nominal.env_kwargs, "randomization": preset}.items())))
    return {"nominal": nominal, "randomised": randomised}


def plans_of(target: heldout.Target, args: argparse.Namespace) -> dict[str, list]:
    """The episodes of each setting: the cells of the test split's ``part`` (``"bodies"``:
    the healthy test bodies; ``"conditions"``: test bodies x the held-out conditions, a
    tremor's cell once); randomised, ``draws`` per cell with seeds of their own."""
    patients = [p for p in heldout.cohort("test", target) if p.part == args.part]
    nominal = heldout.subset(heldout.plan_episodes(patients, heldout.exercise_count(target),
                                                   args.seed, 1), args.max_bodies)
    randomised = [dataclasses.replace(p, seed=args.randomized_seed + args.draws * i + k)
                  for i, p in enumerate(nominal) for k in range(args.draws)]
    return {"nominal": nominal, "randomised": randomised}


def draws_of(target: heldout.Target, plan: Sequence[heldout.Planned]) -> list[dict]:
    """Each randomised episode's action latency, read from a reset of its own patient's env
    with its seed and cell (the draw does not depend on the controller; the rest of it
    follows from the seed, ``info["randomization"]`` of that reset, and is not stored)."""
    draws = []
    for patient in dict.fromkeys(p.patient for p in plan):
        kwargs = {**target.env_kwargs, "profile": dataclasses.asdict(patient.body),
                  "condition": patient.condition.to_dict()}
        try:
            envs, _refused = stratified.cell_envs(target.env_id, kwargs)
        except ValueError:  # the scene takes this patient at no level: nothing was played
            continue
        try:
            for p in (p for p in plan if p.patient == patient and p.weight_level in envs):
                _obs, info = envs[p.weight_level].reset(seed=p.seed, options={
                    "exercise": p.exercise, "weight_level": p.weight_level})
                draws.append({"seed": p.seed,
                              "latency_steps": info["randomization"]["latency_steps"]})
        finally:
            for env in {id(e): e for e in envs.values()}.values():
                env.close()
    return draws


def evaluate(args: argparse.Namespace, agents: Sequence[dict]) -> dict[str, Any]:
    """Every controller (the expert first) in both settings; the page's data."""
    targets = targets_of(args.env, args.preset)
    plans = plans_of(targets["nominal"], args)
    controllers = [{"kind": "expert", "spec": "expert", "row": "expert", "trained_on": "-",
                    "train_seed": None, "trained_with": "-"}, *agents]
    jobs = [(c["spec"], targets[s], plans[s]) for s in SETTINGS for c in controllers]
    results = iter(heldout.run_jobs(jobs, args.workers))
    settings = {s: heldout.target_data(targets[s], plans[s],
                                       [next(results) for _ in controllers], controllers)
                for s in SETTINGS}
    draws = draws_of(targets["randomised"], plans["randomised"])
    return {"env_id": targets["nominal"].env_id, "preset": args.preset,
            "preset_ranges": PRESETS[args.preset].to_dict(), "seed": args.seed,
            "randomized_seed": args.randomized_seed, "draws_per_cell": args.draws,
            "max_bodies": args.max_bodies, "part": args.part, "settings": settings,
            "draws": draws}


# --------------------------------------------------------------------------- tables


def success(episodes: Sequence[dict]) -> float:
    """The share of ``episodes`` finished, in % (0 for none)."""
    return 100.0 * sum(bool(e["success"]) for e in episodes) / max(len(episodes), 1)


def figures(data: dict) -> list[dict[str, Any]]:
    """Per controller: its success nominal and randomised, the drop in points, and whether
    it is within the floor."""
    rows = []
    nominal, randomised = (data["settings"][s] for s in SETTINGS)
    for a, b in zip(nominal["controllers"], randomised["controllers"], strict=True):
        before = heldout.episodes_of(nominal, a)
        after = heldout.episodes_of(randomised, b)
        rows.append({"row": a["row"], "spec": a["spec"], "trained_on": a["trained_on"],
                     "trained_with": a.get("trained_with", "-"),
                     "nominal": [sum(e["success"] for e in before), len(before)],
                     "randomised": [sum(e["success"] for e in after), len(after)],
                     "drop_points": success(before) - success(after)})
    return rows


def floor_verdict(rows: Sequence[dict]) -> str:
    """Whether the floor holds: every agent trained with the randomisation drops at most
    :data:`FLOOR_POINTS`, and every agent trained without it drops more than each of them."""
    with_ = [r for r in rows if r["trained_with"] == "with"]
    without = [r for r in rows if r["trained_with"] == "without"]
    if not with_ or not without:
        return "not judged: the floor compares an agent trained with and one without"
    within = all(r["drop_points"] <= FLOOR_POINTS for r in with_)
    more = all(w["drop_points"] > r["drop_points"] for w in without for r in with_)
    verdict = "met" if within and more else "NOT met"
    worst_with = max(r["drop_points"] for r in with_)
    least_without = min(r["drop_points"] for r in without)
    return (f"{verdict}: trained with, a drop of at most {worst_with:.1f} points (floor "
            f"{FLOOR_POINTS:g}: {'within' if within else 'beyond'}); trained without, at least "
            f"{least_without:.1f} points ({'more' if more else 'not more'})")


def share(counts: Sequence[int]) -> str:
    done, of = counts
    return f"{done}/{of} ({100.0 * done / max(of, 1):.1f} %)"


def transfer_table(data: dict) -> dict[str, Any]:
    rows = figures(data)
    cells = [[r["row"], r["trained_with"], r["trained_on"], share(r["nominal"]),
              share(r["randomised"]), f"{r['drop_points']:+.1f}"] for r in rows]
    return make_table(
        "transfer", "Success on the held-out test bodies, nominal and randomised",
        ["controller", "trained with the randomisation", "trained on", "nominal",
         "randomised", "drop [points]"], cells, align=["left", "left", "left", "right",
                                                     "right", "right"],
        note=f"Floor ({FLOOR_POINTS:g} points): {floor_verdict(rows)}. Success counts every "
             "episode of the setting (finished / played); the drop is nominal minus "
             "randomised. The randomised episodes are different episodes (other seeds, "
             f"{data['draws_per_cell']} per cell), the expert plays exactly the agents' "
             "episodes.")


def latency_table(data: dict) -> dict[str, Any]:
    """Randomised success per drawn action latency (decisions)."""
    latency = {d["seed"]: d["latency_steps"] for d in data["draws"]}
    target = data["settings"]["randomised"]
    levels = sorted(set(latency.values()))
    cells = []
    for c in target["controllers"]:
        episodes = heldout.episodes_of(target, c)
        cells.append([c["row"], *(share([sum(e["success"] for e in episodes
                                               if latency[e["seed"]] == k),
                                           sum(1 for e in episodes if latency[e["seed"]] == k)])
                                     for k in levels)])
    return make_table("latency", "Randomised success by the episode's action latency",
                      ["controller", *(f"latency {k} ({20 * k} ms)" for k in levels)], cells,
                      align=["left", *["right"] * len(levels)],
                      note="The latency each randomised episode drew (a decision is 20 ms); "
                           "the other quantities are drawn in the same episodes.")


def stops_table(data: dict) -> dict[str, Any]:
    """How the unfinished episodes ended: each safety rule, or the time limit."""
    cells = []
    for setting in SETTINGS:
        target = data["settings"][setting]
        for c in target["controllers"]:
            ends = Counter(e["safety_violation"] or "time limit"
                           for e in heldout.episodes_of(target, c) if not e["success"])
            cells.append([setting, c["row"], ", ".join(f"{rule} {n}" for rule, n in
                                                       sorted(ends.items())) or "-"])
    return make_table("stops", "How the unfinished episodes ended", ["setting", "controller",
                                                                     "ends"], cells,
                      note="A safety rule's name where one stopped the episode, else the time "
                           "limit (1000 decisions).")


def transfer_document(data: dict, command: str, provenance: str | None = None
                      ) -> dict[str, Any]:
    stored = {**data, "settings": {s: heldout.pack({"targets": [t]})["targets"][0]
                                   for s, t in data["settings"].items()}}
    return make_document(
        title="Randomisation for transfer: held-out success, nominal and randomised",
        intro=INTRO.format(seed=data["seed"], draws=data["draws_per_cell"],
                           bodies=PART_TEXT[data.get("part", "bodies")],
                           randomized_seed=data["randomized_seed"], floor=FLOOR_POINTS),
        command=command, generated_by=__file__,
        tables=[transfer_table(data), latency_table(data), stops_table(data)],
        seeds={"nominal_first_seed": data["seed"],
               "randomised_first_seed": data["randomized_seed"],
               "training_seeds": "per controller (train_seed in the data)"},
        settings={"env_id": data["env_id"], "preset": data["preset"],
                  "draws_per_cell": data["draws_per_cell"], "actions": "deterministic",
                  "bodies": PART_TEXT[data.get("part", "bodies")],
                  **({"max_bodies": data["max_bodies"]} if data["max_bodies"] else {})},
        provenance=provenance, data=stored)


def unpacked(document: dict) -> dict[str, Any]:
    """A document's data with each setting's episodes as records again."""
    data = document["data"]
    return {**data, "settings": {s: heldout.unpack({"targets": [t]})["targets"][0]
                                 for s, t in data["settings"].items()}}


# --------------------------------------------------------------------------- CLI


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--agent", action="append", default=[], metavar="with|without=SPEC",
                        help="an agent and whether it trained with the randomisation")
    parser.add_argument("--env", default="rehabbot/rehab-knee-v2",
                        help="the one-patient id of the scene (rehabbot/rehab-knee-v2)")
    parser.add_argument("--preset", default="transfer", choices=sorted(PRESETS),
                        help="the randomisation preset (transfer)")
    add_seed_argument(parser, heldout.SEEDS["test"], help_text="first nominal episode seed (60000)")
    parser.add_argument("--randomized-seed", type=int, default=70_000,
                        help="first randomised episode seed (70000)")
    parser.add_argument("--draws", type=int, default=3, help="randomised episodes per cell (3)")
    parser.add_argument("--max-bodies", type=int, help="only the first N test bodies")
    parser.add_argument("--part", default="bodies", choices=list(heldout.PARTS["test"]),
                        help="the test split's part: healthy bodies, or bodies x conditions "
                             "(bodies)")
    parser.add_argument("--workers", type=int, default=1, help="processes that play (1)")
    parser.add_argument("--from-json", type=Path, metavar="F",
                        help="render a results document's JSON again, no episodes")
    add_page_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    command = script_command(__file__, argv)
    if args.from_json is not None:
        saved = json.loads(args.from_json.read_text(encoding="utf-8"))
        document = transfer_document(unpacked(saved), saved["command"], saved["provenance"])
    else:
        for name in ("draws", "workers"):
            if getattr(args, name) < 1:
                parser.error(f"--{name}={getattr(args, name)} must be >= 1")
        if args.max_bodies is not None and args.max_bodies < 1:
            parser.error(f"--max-bodies={args.max_bodies} must be >= 1")
        try:
            agents = [controller(*parse_agent(text)) for text in args.agent]
            heldout.make_target(args.env)
        except ValueError as err:
            parser.error(str(err))
        data = evaluate(args, agents)
        provenance = "; ".join(f"{a['row']}: {a['spec']}" for a in agents) or None
        document = transfer_document(data, command, provenance)
    print(table_markdown(document["tables"][0]))
    if args.page is not None:
        write_page(document, args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
