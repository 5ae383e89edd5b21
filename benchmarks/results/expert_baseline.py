"""The scripted expert's baseline row: success, steps to finish, return and peak cuff force per
id and exercise, over every weight level.

    python benchmarks/results/expert_baseline.py [--seed 0] [--json FILE]
        [--page docs/results/expert-baseline]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from rehabbot.envs.registration import ENV_SPECS
from rehabbot.rl.experts import ScriptedExpert

INTRO = """The scripted expert (`rehabbot.rl.experts.ScriptedExpert`) on both exercises of every
registered id at every weight level, one seeded episode each: whether it finishes, the steps it
takes, its mean return, and its peak cuff force against the id's force limit. It is the
reference the learning tables' "expert" column comes from."""


def run_episode(env, expert, exercise: int, level: int, seed: int) -> dict:
    obs, info = env.reset(seed=seed, options={"exercise": exercise, "weight_level": level})
    steps, ret, peak = 0, 0.0, 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(expert.predict(obs)[0])
        steps += 1
        ret += reward
        peak = max(peak, info["interaction_force_n"])
        if terminated or truncated:
            return {"success": bool(info["is_success"]), "steps": steps, "return": ret,
                    "peak_force_n": peak, "safety_violation": info["safety_violation"],
                    "targets": info["num_targets"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_seed_argument(parser)
    parser.add_argument("--json", default=None, help="also write the rows to this file")
    add_page_argument(parser, "docs/results/expert-baseline")
    args = parser.parse_args(argv)
    command = script_command(__file__, argv)
    announce(command)
    rows, cells = [], []
    for env_id in ENV_SPECS:
        env = gym.make(env_id)
        expert = ScriptedExpert(env)
        limit = env.unwrapped.safety.force_limit_n
        for exercise in (0, 1):
            runs = [run_episode(env, expert, exercise, level, args.seed) for level in range(5)]
            name = env.unwrapped.targets[exercise].exercise.name
            rows.append({"id": env_id, "exercise": exercise, "name": name, "seed": args.seed,
                         "runs": runs})
            steps = [r["steps"] for r in runs]
            forces = [r["peak_force_n"] for r in runs]
            success = np.mean([r["success"] for r in runs])
            cells.append([env_id.split("/")[1], f"{exercise} ({name})", runs[0]["targets"],
                          f"{success:.0%}", f"{min(steps)}–{max(steps)}",
                          f"{np.mean([r['return'] for r in runs]):.1f}",
                          f"{min(forces):.0f}–{max(forces):.0f} N", f"{limit:.0f} N"])
        env.close()
    table = make_table(
        "expert", "The scripted expert on every id and exercise, weight levels 0-4",
        ["id", "exercise", "targets", "success", "steps to finish (L0..L4)", "return (mean)",
         "peak cuff force (L0..L4)", "force limit"], cells)
    print(table_markdown(table))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    if args.page is not None:
        write_page(make_document(
            title="The scripted expert's baseline", intro=INTRO, command=command,
            generated_by=__file__, tables=[table], seeds={"episodes": args.seed},
            settings={"weight_levels": [0, 1, 2, 3, 4], "exercises": [0, 1]},
            data={"rows": rows}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
