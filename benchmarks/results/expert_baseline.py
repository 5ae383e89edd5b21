"""The scripted expert's baseline row: success, steps to finish, return and peak cuff force per
id and exercise, over every weight level.

    python benchmarks/expert_baseline.py [--seed 0] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys

import gymnasium as gym
import numpy as np

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.registration import ENV_SPECS
from rehabbot.rl.experts import ScriptedExpert


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
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="also write the rows to this file")
    args = parser.parse_args(argv)
    rows = []
    print(f"command: python benchmarks/expert_baseline.py --seed {args.seed}")
    print("| id | exercise | targets | success | steps to finish (L0..L4) | return (mean) "
          "| peak cuff force (L0..L4) | force limit |")
    print("|---|---|---|---|---|---|---|---|")
    for env_id in ENV_SPECS:
        env = gym.make(env_id)
        expert = ScriptedExpert(env)
        limit = env.unwrapped.safety.force_limit_n
        for exercise in (0, 1):
            runs = [run_episode(env, expert, exercise, level, args.seed) for level in range(5)]
            name = env.unwrapped.targets[exercise].exercise.name
            row = {"id": env_id, "exercise": exercise, "name": name, "seed": args.seed,
                   "runs": runs}
            rows.append(row)
            steps = [r["steps"] for r in runs]
            forces = [r["peak_force_n"] for r in runs]
            success = np.mean([r["success"] for r in runs])
            print(f"| {env_id.split('/')[1]} | {exercise} ({name}) | {runs[0]['targets']} "
                  f"| {success:.0%} | {min(steps)}–{max(steps)} "
                  f"| {np.mean([r['return'] for r in runs]):.1f} "
                  f"| {min(forces):.0f}–{max(forces):.0f} N | {limit:.0f} N |")
        env.close()
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
