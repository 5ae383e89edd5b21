"""How much in step a policy moves the two arms on the bilateral id: per symmetric episode
(both arms through the same key poses), the mean and the largest synchronisation gap
``max(|f_right - f_left| - sync_tolerance, 0)`` (``info["sync_gap"]``) and the sum of
``reward_sync``, next to the scripted expert.

Usage::

    python benchmarks/probes/bilateral_sync.py MODEL_OR_RUN_DIR ... [--episodes 10] [--seed 1000]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.common.text_tables import markdown_table
from rehabbot.rl.policies import env_for, load_policy

ENV_ID = "rehabbot/rehab-bilateral-v1"
SYMMETRIC = (0, 1)  # shoulder and elbow flexion, both arms together


def sync_of(spec: str, episodes: int, seed: int) -> dict:
    """Mean gap, largest gap, summed reward_sync and success over symmetric episodes."""
    env_id, kwargs = env_for([spec], ENV_ID if spec in ("expert", "random") else None)
    env = gym.make(env_id, **kwargs)
    policy = load_policy(spec, env)
    gaps, peaks, pays, wins = [], [], [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=seed + k, options={"exercise": SYMMETRIC[k % 2]})
        gap, pay, done = [], 0.0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy.act(obs))
            gap.append(info["sync_gap"])
            pay += info["reward_sync"]
            done = terminated or truncated
        gaps.append(np.mean(gap))
        peaks.append(np.max(gap))
        pays.append(pay)
        wins.append(info["is_success"])
    env.close()
    return {"policy": policy.label, "mean_gap": float(np.mean(gaps)),
            "peak_gap": float(np.max(peaks)), "reward_sync": float(np.mean(pays)),
            "success": float(np.mean(wins))}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="model.zip files (or 'expert')")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1000)
    args = parser.parse_args(argv)
    specs = [str(Path(p) / "model.zip") if Path(p).is_dir() else p for p in args.policies]
    print(f"{ENV_ID}, symmetric exercises, {args.episodes} episodes from seed {args.seed}\n")
    cells = []
    for spec in ["expert", *specs]:
        r = sync_of(spec, args.episodes, args.seed)
        cells.append([r["policy"], f"{100 * r['success']:.0f} %", f"{r['mean_gap']:.3f}",
                      f"{r['peak_gap']:.3f}", f"{r['reward_sync']:.2f}"])
    print(markdown_table(["policy", "success", "mean sync gap", "largest sync gap",
                          "reward_sync per episode"], cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
