"""How closely a trained policy's actions follow the scripted expert's, along the policy's own
episodes: a diagnosis of agents that fail (README, Results, "SAC on the -v1 reward").

    python benchmarks/probes/expert_agreement.py MODEL.zip [--episodes 4] [--seed 1000]
        [--steps 300]

For every step of each episode (deterministic actions, the env and its kwargs from the run's
manifest) it compares the policy's action ``a`` with the action ``e`` the scripted expert would
take in the same state: the cosine ``a·e / (|a| |e|)`` (1: same direction, -1: opposite) and
``|a| / |e|``. It prints, per episode, the exercise, the mean cosine, the share of steps with a
cosine below 0, the median size ratio, the targets reached, and how the episode ended. A policy that
pushes every episode the same way whatever the target shows mean cosines near 0 or below.
"""

from __future__ import annotations

import argparse
import sys

import gymnasium as gym
import numpy as np

from rehabbot.common.text_tables import markdown_table
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.rl.policies import env_for, load_policy

TINY = 1e-12


def agreement(model: str, episodes: int, seed: int, max_steps: int,
              env_id: str | None = None) -> list[dict]:
    """One row per episode: exercise, mean cosine, share of opposing steps, end state.
    ``model``: a model file of a run, ``zoo:ENV/ALGO`` or ``expert`` (then ``env_id``)."""
    env_id, env_kwargs = env_for([model], env_id)
    env = gym.make(env_id, **env_kwargs)
    policy = load_policy(model, env).policy
    expert = ScriptedExpert(env)
    rows = []
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        cosines, ratios = [], []
        for _ in range(max_steps):
            action, _ = policy.predict(obs, deterministic=True)
            target, _ = expert.predict(obs, deterministic=True)
            action = np.asarray(action, dtype=float)
            target = np.asarray(target, dtype=float)
            norm_a, norm_e = np.linalg.norm(action), np.linalg.norm(target)
            cosines.append(float(action @ target / (norm_a * norm_e + TINY)))
            ratios.append(float(norm_a / (norm_e + TINY)))
            obs, _reward, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        rows.append({"seed": seed + k, "exercise": info["exercise"],
                     "steps": len(cosines), "mean_cosine": float(np.mean(cosines)),
                     "opposing_share": float(np.mean(np.asarray(cosines) < 0.0)),
                     "median_norm_ratio": float(np.median(ratios)),
                     "targets_reached": int(info["target_index"]),
                     "num_targets": int(info["num_targets"]),
                     "ended": "success" if info["is_success"] else
                              (info["safety_violation"] or "running")})
    env.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model.zip (or checkpoint) of a run, or zoo:ENV/ALGO")
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1000, help="first episode seed (1000)")
    parser.add_argument("--steps", type=int, default=300, help="steps per episode at most")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.steps < 1:
        parser.error("--episodes and --steps must be >= 1")
    rows = agreement(args.model, args.episodes, args.seed, args.steps)
    print(markdown_table(
        ["seed", "exercise", "steps", "mean cosine to the expert", "steps opposing",
         "median |a|/|e|", "targets reached", "ended"],
        [[r["seed"], r["exercise"], r["steps"], f"{r['mean_cosine']:.2f}",
          f"{100 * r['opposing_share']:.0f} %", f"{r['median_norm_ratio']:.2f}",
          f"{r['targets_reached']}/{r['num_targets']}", r["ended"]] for r in rows]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
