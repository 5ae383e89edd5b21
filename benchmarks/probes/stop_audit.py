"""Does a safety stop ever pay? Every joint of every id, in every control mode, pushed in both
directions at the action bound until a safety rule stops the episode; its return from the
start, the middle and the step before the stop against holding still from there
(:func:`benchmarks.common.reward_audit.push_audit`), undiscounted and for gamma = 0.95, 0.99,
0.999. Prints the counts the issue-25 closing note quotes and writes every comparison as JSON.

A comparison is "asserted" by tests/test_stop_penalty.py when holding still avoids a stop and,
discounted, when the episode never out-earned the hold step for step before it stopped (no
"headway"); the others are counted apart.

    python benchmarks/probes/stop_audit.py --json results/stop_audit.json      # every id (~1 h)
    python benchmarks/probes/stop_audit.py --ids rehab-hip-v1 rehab-knee-v1 --modes joint_delta
    python benchmarks/probes/stop_audit.py --drift   # how far holding still lets the joints travel
                                              # in torque mode (control.TORQUE_HOLD_*)
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.reward_audit import AUDIT_GAMMAS, hold_action, push_action, push_audit
from rehabbot.common.files import atomic_write_json
from rehabbot.envs.registration import ENV_SPECS, resolve_env_id

MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")


def audit(ids: list[str], modes: list[str], seed: int) -> tuple[Counter, list[dict]]:
    counts: Counter = Counter()
    rows = []
    for env_id in ids:
        env = gym.make(env_id)
        n_joints = env.action_space.shape[0]
        env.close()
        for mode in modes:
            for joint in range(n_joints):
                for sign in (1, -1):
                    result = push_audit(env_id, mode, joint, sign, seed=seed)
                    counts["pushes"] += 1
                    counts["stops" if result.violation else "no stop"] += 1
                    for c in result.comparisons:
                        kind = ("hold stops too" if c.hold_stop else
                                "discounted, with headway" if c.gamma is not None and c.headway
                                else "asserted")
                        counts[kind] += 1
                        pays = result.stop_pays(c)
                        if pays:
                            counts[f"{kind}: stop pays"] += 1
                        rows.append({"env_id": env_id, "control_mode": mode, "joint": joint,
                                     "sign": sign, "violation": result.violation,
                                     "stop_step": result.stop_step, **dataclasses.asdict(c),
                                     "kind": kind, "stop_pays": pays})
            print(f"{env_id} done: {dict(counts)}", file=sys.stderr, flush=True)
    return counts, rows


def drift(ids: list[str], seed: int) -> None:
    """Torque mode: how far the joints travel when holding still after a push, against the
    joints' speed there (the sag and braking allowance of the safety penalty)."""
    rows = []
    for env_id in ids:
        env = gym.make(env_id, control_mode="torque")
        base = env.unwrapped
        handles = getattr(base, "handles", None) or (base.handle,)
        dof = np.concatenate([h.dof_adr for h in handles])
        for joint in range(env.action_space.shape[0]):
            for sign in (1, -1):
                for fraction in (1.0, 0.3):
                    for level in (0, 4):
                        options = {"exercise": 0, "weight_level": level}
                        env.reset(seed=seed, options=options)
                        actions = []
                        for _ in range(300):
                            actions.append(push_action(env, joint, sign, fraction))
                            *_, terminated, truncated, _info = env.step(actions[-1])
                            if terminated or truncated:
                                break
                        for state in sorted({0, len(actions) // 2, len(actions) - 1}):
                            env.reset(seed=seed, options=options)
                            for action in actions[:state]:
                                env.step(action)
                            held = base.data.qpos[base._qpos_adr].copy()
                            speed = float(np.linalg.norm(base.data.qvel[dof]))
                            travel = 0.0
                            for _ in range(300):
                                *_, terminated, truncated, _info = env.step(
                                    hold_action(env, held, servo=False))
                                travel = max(travel, float(np.linalg.norm(
                                    base.data.qpos[base._qpos_adr] - held)))
                                if terminated or truncated:
                                    break
                            rows.append((speed, travel))
        env.close()
    rows_array = np.array(rows)
    slow = rows_array[rows_array[:, 0] < 0.05]
    fast = rows_array[rows_array[:, 0] >= 0.05]
    print(f"{len(rows)} holds; at rest (speed < 0.05 rad/s): travel at most "
          f"{slow[:, 1].max() if len(slow) else 0:.3f} rad; moving: (travel - 0.1 rad) / speed "
          f"at most {((fast[:, 1] - 0.1) / fast[:, 0]).max() if len(fast) else 0:.3f} s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", default=list(ENV_SPECS))
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="write every comparison here")
    parser.add_argument("--drift", action="store_true",
                        help="measure the torque-mode hold travel instead (the -v0 ids)")
    args = parser.parse_args(argv)
    ids = [resolve_env_id(i) for i in args.ids]
    if args.drift:
        drift([i for i in ids if i.endswith("-v0")] or ids, args.seed)
        return 0
    counts, rows = audit(ids, args.modes, args.seed)
    print(f"gammas {AUDIT_GAMMAS} (None: undiscounted); margin 0.5 x STOP_MARGIN discounted")
    for key in sorted(counts):
        print(f"{key}: {counts[key]}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(args.json, {"seed": args.seed, "ids": ids, "modes": args.modes,
                                      "counts": dict(counts), "comparisons": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
