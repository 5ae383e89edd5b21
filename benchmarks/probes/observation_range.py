"""Which entries of the ``-v2`` agent observation pass 1 (docs/envs.md, "Which observation
values pass 1").

For every ``-v2`` id (the ``-myo-`` ids when ``myo-sim`` is installed) four episodes of at most
``--steps`` steps: seeded uniform random actions, all actions +1, all -1, and the scripted
expert (seeds 0 to 3). For each field of the observation, the largest ``|value|`` seen,
including the last observation of an episode that a safety rule ended. Prints one line per id
with the fields past 1; ``--json FILE`` writes every field's peak.

Usage::

    python benchmarks/probes/observation_range.py [--steps 1000] [--ids reach knee] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.myo_patient import myo_available

POLICIES = ("random", "push+", "push-", "expert")


def field_peaks(env_id: str, steps: int) -> dict[str, float]:
    """The largest |value| of each observation field over the four episodes of ``env_id``."""
    env = gym.make(env_id)
    layout = env.unwrapped.agent_layout
    peak = np.zeros(env.observation_space.shape)
    shape = env.action_space.shape
    for seed, policy in enumerate(POLICIES):
        obs, _ = env.reset(seed=seed)
        expert = ScriptedExpert(env) if policy == "expert" else None
        rng = np.random.default_rng(seed)
        for _ in range(steps):
            peak = np.maximum(peak, np.abs(obs))
            if policy == "random":
                action = rng.uniform(-1.0, 1.0, shape).astype(np.float32)
            elif policy == "expert":
                action = expert.predict(obs)[0]
            else:
                action = np.full(shape, 1.0 if policy == "push+" else -1.0, np.float32)
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        peak = np.maximum(peak, np.abs(obs))
    env.close()
    return {name: float(peak[layout.slice(name)].max()) for name in layout.names}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=1000, help="steps per episode at most")
    parser.add_argument("--ids", nargs="*", default=[],
                        help="only the ids containing one of these texts")
    parser.add_argument("--json", type=Path, help="write every field's peak here")
    args = parser.parse_args(argv)
    ids = sorted(i for i in gym.registry if i.startswith("rehabbot/") and i.endswith("-v2")
                 and ("-myo-" not in i or myo_available())
                 and (not args.ids or any(text in i for text in args.ids)))
    results = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for env_id in ids:
            peaks = results[env_id] = field_peaks(env_id, args.steps)
            past = {name: round(value, 3) for name, value in peaks.items() if value > 1.0}
            print(f"{env_id}: max |obs| {max(peaks.values()):.3f}; fields past 1: {past}",
                  flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
