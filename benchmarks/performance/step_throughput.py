"""How much of an env step is physics: every registered id, made the way users make it.

For each ``rehabbot/`` id the env comes from ``gym.make(id)`` (with the wrappers the
registration adds) and takes zero actions. The baseline is the raw physics of the same step:
``mujoco.mj_step(model, data, nstep=frame_skip)`` on a *copy* of the env's model, in an
``MjData`` holding a copy of the env's state after ``reset``. A round is ``--steps`` env steps
and as many physics calls, timed back to back; rounds alternate which of the two goes first,
so that a change of the machine's speed (other processes) hits both alike. The figures are
medians over ``--rounds`` rounds:

* ``physics share``: physics time / env time per step (the part of an env step spent in
  ``mj_step``); the goal is at least 90 %;
* ``overhead``: env time - physics time per step (Python, NumPy, wrappers, resets);
* ``env steps/s`` and ``x realtime`` (env steps/s x ``dt``).

The absolute rates depend on the machine; the share is a ratio measured in the same run.

Usage::

    python benchmarks/performance/step_throughput.py [--steps 300] [--rounds 7]
        [--warmup 100] [--ids ID ...] [--robot NAME] [--json FILE] [--page docs/results/NAME]

``--robot fr3`` makes every id with that robot (``gym.make(id, robot=...)``).
"""

from __future__ import annotations

import argparse
import copy
import json
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine

PHYSICS_SHARE_GOAL = 0.90
INTRO = """Every registered id made the way users make it (`gym.make(id)`, with the wrappers the
registration adds), stepped with zero actions, against the raw physics of the same step
(`mujoco.mj_step(model, data, nstep=frame_skip)` on a copy of the env's model and state after
`reset`). Rounds of env steps and of physics calls alternate which goes first, so a change of
the machine's speed hits both alike; the figures are medians over the rounds."""


@dataclass
class Row:
    """One line of the table."""

    env_id: str
    wrappers: str
    frame_skip: int
    dt_s: float
    env_steps_per_s: float
    physics_steps_per_s: float
    physics_share: float
    overhead_us: float
    realtime_factor: float
    shares: list[float]


def _wrappers(env: gym.Env) -> str:
    names = []
    while isinstance(env, gym.Wrapper):
        names.append(type(env).__name__)
        env = env.env
    return " > ".join(names) or "-"


def _physics_copy(env: gym.Env) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A copy of the env's model and an ``MjData`` holding the env's current state."""
    base = env.unwrapped
    model = copy.deepcopy(base.model)
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(base.model, spec))
    mujoco.mj_getState(base.model, base.data, state, spec)
    mujoco.mj_setState(model, data, state, spec)
    mujoco.mj_forward(model, data)
    return model, data


def time_env(env: gym.Env, action: np.ndarray, steps: int) -> float:
    """Seconds for ``steps`` env steps with ``action`` (episodes that end are reset)."""
    step, reset, clock = env.step, env.reset, time.perf_counter
    start = clock()
    for _ in range(steps):
        _obs, _reward, terminated, truncated, _info = step(action)
        if terminated or truncated:
            reset()
    return clock() - start


def time_physics(model: mujoco.MjModel, data: mujoco.MjData, frame_skip: int,
                 steps: int) -> float:
    """Seconds for ``steps`` calls of ``mj_step(model, data, nstep=frame_skip)``."""
    mj_step, clock = mujoco.mj_step, time.perf_counter
    start = clock()
    for _ in range(steps):
        mj_step(model, data, nstep=frame_skip)
    return clock() - start


def measure(env_id: str, steps: int, rounds: int, warmup: int, seed: int,
            robot: str | None = None) -> Row:
    env = gym.make(env_id) if robot is None else gym.make(env_id, robot=robot)
    try:
        env.reset(seed=seed)
        base = env.unwrapped
        frame_skip, dt_s = int(base.frame_skip), float(base.dt)
        model, data = _physics_copy(env)
        action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        time_env(env, action, warmup)
        time_physics(model, data, frame_skip, warmup)
        env_s, physics_s = [], []
        for k in range(rounds):
            if k % 2:
                physics_s.append(time_physics(model, data, frame_skip, steps))
                env_s.append(time_env(env, action, steps))
            else:
                env_s.append(time_env(env, action, steps))
                physics_s.append(time_physics(model, data, frame_skip, steps))
        wrappers = _wrappers(env)
    finally:
        env.close()
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise RuntimeError(f"{env_id}: the physics copy diverged")
    shares = [p / e for e, p in zip(env_s, physics_s, strict=True)]
    env_rate = steps / statistics.median(env_s)
    label = env_id if robot is None else f"{env_id} (robot={robot})"
    return Row(env_id=label, wrappers=wrappers, frame_skip=frame_skip, dt_s=dt_s,
               env_steps_per_s=env_rate, physics_steps_per_s=steps / statistics.median(physics_s),
               physics_share=statistics.median(shares),
               overhead_us=statistics.median((e - p) / steps * 1e6
                                             for e, p in zip(env_s, physics_s, strict=True)),
               realtime_factor=env_rate * dt_s, shares=shares)


def results_table(rows: Sequence[Row]) -> dict[str, Any]:
    """The rows as a results-document table (``physics share`` is the ratio measured in the
    same run; ``(< goal)`` marks a share under :data:`PHYSICS_SHARE_GOAL`)."""
    cells = []
    for row in rows:
        flag = "" if row.physics_share >= PHYSICS_SHARE_GOAL else " (< goal)"
        cells.append([row.env_id, f"{row.env_steps_per_s:.0f}", f"{row.physics_steps_per_s:.0f}",
                      f"{row.physics_share:.1%}{flag}", f"{row.overhead_us:.1f}",
                      f"{row.realtime_factor:.0f}"])
    return make_table(
        "step", "Env steps against the same step's physics",
        ["id", "env steps/s", "physics steps/s", "physics share", "overhead [µs/step]",
         "x realtime"], cells, align=["left", *["right"] * 5],
        note=f"The physics share is physics time / env time per step, medians over interleaved "
             f"rounds of the same run (the goal: at least {PHYSICS_SHARE_GOAL:.0%}); it is the "
             "figure to compare across machines, the absolute rates depend on the machine.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="env steps per round (300)")
    parser.add_argument("--rounds", type=int, default=7, help="rounds; medians are kept (7)")
    parser.add_argument("--warmup", type=int, default=100, help="untimed steps first (100)")
    add_seed_argument(parser, help_text="reset seed (0)")
    parser.add_argument("--ids", nargs="+", metavar="ID", help="default: every rehabbot/ id")
    parser.add_argument("--robot", metavar="NAME", help="make every id with this robot")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the rows as JSON")
    add_page_argument(parser, "docs/results/step-throughput")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.steps < 1 or args.rounds < 1 or args.warmup < 0:
        print("--steps and --rounds must be >= 1, --warmup >= 0", file=sys.stderr)
        return 2
    import rehabbot  # noqa: F401  (registers the ids)

    registered = [i for i in gym.registry if i.startswith("rehabbot/")]
    ids = [i if "/" in i else f"rehabbot/{i}" for i in (args.ids or registered)]
    unknown = [i for i in ids if i not in registered]
    if unknown:
        print(f"unknown id(s) {', '.join(unknown)}; valid: {', '.join(registered)}",
              file=sys.stderr)
        return 2
    rows = [measure(i, args.steps, args.rounds, args.warmup, args.seed, args.robot)
            for i in ids]
    command = script_command(__file__, argv)
    how = (f"gym.make(id), zero actions; median of {args.rounds} interleaved rounds of "
           f"{args.steps} steps against mj_step on a copy of the model and state; wrappers: "
           f"{rows[0].wrappers}; goal: physics share >= {PHYSICS_SHARE_GOAL:.0%}")
    print(f"command: {command}\nmachine: {describe_machine()}, gymnasium {gym.__version__}, "
          f"numpy {np.__version__}\n{how}\n")
    table = results_table(rows)
    print(table_markdown(table))
    if args.page is not None:
        write_page(make_document(
            title="Env-step throughput: how much of a step is physics", intro=INTRO,
            command=command, generated_by=__file__, tables=[table],
            machine=f"{describe_machine()}, gymnasium {gym.__version__}, numpy {np.__version__}",
            seeds={"reset_seed": args.seed},
            settings={"steps": args.steps, "rounds": args.rounds, "warmup": args.warmup,
                      "robot": args.robot, "wrappers": rows[0].wrappers},
            data={"rows": [asdict(row) for row in rows]}), args.page)
    if args.json is not None:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
