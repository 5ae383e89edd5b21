"""Reward audit of the -v0 (eq. (5)) and -v1 (progress) ids, measured in the sim.

1. Stalling: for every target of a scripted-expert episode, the discounted value of going on
   from the last state short of the target versus holding still there, at gamma = 0.95, 0.99
   and 0.999. A design traps an agent where stalling is worth more.
2. Safety stops: driving one joint at the action bound until a safety rule ends the episode,
   versus holding still to the time limit and versus the expert (undiscounted returns, as
   ``evaluate_policy`` prints them).

    python benchmarks/probes/reward_trap.py            # every id (about 3 minutes on one core)
    python benchmarks/probes/reward_trap.py --ids rehab-reach-v0 rehab-reach-v1
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.reward_audit import stall_cases, stop_cases
from rehabbot.common.text_tables import markdown_table
from rehabbot.envs.registration import ENV_SPECS, resolve_env_id

GAMMAS = (0.95, 0.99, 0.999)


def stall_table(ids: list[str], seed: int) -> None:
    print("## Reaching versus stalling short of a target (expert episodes, weight level 2)\n")
    cells = []
    for env_id in ids:
        for exercise in (0, 1):
            cases = stall_cases(env_id, exercise, GAMMAS, seed=seed)
            for gamma in GAMMAS:
                mine = [c for c in cases if c.gamma == gamma]
                trapped = [c.target for c in mine if not c.reaching_pays]
                worst = min(c.reach_value - c.stall_value for c in mine)
                cells.append([env_id.split("/")[-1], exercise, gamma,
                              f"{len(trapped)}/{len(mine)} {trapped[:8]}", f"{worst:+.1f}"])
    print(markdown_table(["id", "exercise", "gamma", "targets where stalling pays",
                          "worst (reach - stall)"], cells) + "\n")


def stop_table(ids: list[str], seed: int) -> None:
    print("## Safety stops (undiscounted returns from the reset state, exercise 0, level 0)\n")
    cells = []
    for env_id in ids:
        for mode in ("joint_delta", "torque"):
            for c in stop_cases(env_id, mode, seed=seed):
                there = "-" if c.hold_from_there is None else f"{c.hold_from_there:.1f}"
                if c.hold_from_there_stop:
                    there += f" (stops: {c.hold_from_there_stop})"
                cells.append([env_id.split("/")[-1], mode, c.joint, c.violation, c.stop_step,
                              f"{c.stop_return:.1f}", f"{c.hold_return:.1f}",
                              f"{c.expert_return:.1f}", f"{c.last_step_reward:.1f}", there])
    print(markdown_table(["id", "mode", "joint pushed", "rule", "step", "stop return",
                          "hold return", "expert return", "last step", "hold from there"],
                         cells) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", default=list(ENV_SPECS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--skip", choices=("stall", "stop"))
    args = parser.parse_args(argv)
    ids = [resolve_env_id(i) for i in args.ids]
    print(f"seed {args.seed}\n")
    if args.skip != "stall":
        stall_table(ids, args.seed)
    if args.skip != "stop":
        stop_table(ids, args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
