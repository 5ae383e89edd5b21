"""What counting the work on the limb costs: an env step with the count against the same step
without it, in the same run.

Every env steps its physics one step at a time and counts the robot's (and the patient's)
work on the limb after each (:class:`rehabbot.sim.physics.WorkMeter`). The baseline here
is the same env with the count switched off (``WorkMeter.after_step`` replaced by a no-op);
rounds of ``--steps`` zero-action steps alternate between the two, and the figures are
medians over ``--rounds`` rounds, so a change of the machine's speed hits both alike.

Usage::

    python benchmarks/performance/work_meter_cost.py [--ids ID ...] [--steps 300] [--rounds 7]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import gymnasium as gym
import numpy as np

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.common.text_tables import markdown_table

DEFAULT_IDS = ("rehabbot/rehab-reach-v1", "rehabbot/rehab-knee-v1",
               "rehabbot/rehab-reach-spastic-v1")


def _round(env, steps: int) -> float:
    zero = np.zeros(env.action_space.shape, np.float32)
    env.reset(seed=0)
    started = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(zero)
        if terminated or truncated:
            env.reset()
    return (time.perf_counter() - started) / steps


def measure(env_id: str, steps: int, rounds: int) -> tuple[float, float]:
    """Median seconds per env step with and without the work count."""
    counted, uncounted = gym.make(env_id), gym.make(env_id)
    meter = uncounted.unwrapped._physics.meter
    meter.after_step = lambda data: None  # the count switched off
    with_count, without = [], []
    for k in range(rounds):
        pair = [(counted, with_count), (uncounted, without)]
        for env, out in (pair if k % 2 == 0 else pair[::-1]):
            out.append(_round(env, steps))
    counted.close()
    uncounted.close()
    return statistics.median(with_count), statistics.median(without)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", default=list(DEFAULT_IDS))
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    print(f"median of {args.rounds} interleaved rounds of {args.steps} zero-action steps\n")
    cells = []
    for env_id in args.ids:
        with_count, without = measure(env_id, args.steps, args.rounds)
        cells.append([env_id, f"{1e6 * with_count:.0f}", f"{1e6 * without:.0f}",
                      f"{1e6 * (with_count - without):.0f}",
                      f"{100 * (with_count / without - 1):.1f} %"])
    print(markdown_table(["id", "µs/step with the count", "without", "cost [µs/step]",
                          "cost [%]"], cells, align=["left", *["right"] * 4]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
