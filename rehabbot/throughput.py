"""Env step throughput of every registered id, against the raw physics of the same model.

For each ``rehabbot/`` id the env is made with ``gym.make`` (the wrapped env users get) and
stepped with a fixed policy: zero actions by default, or ``env.action_space.sample()`` actions
drawn before timing (``--actions random``). Episodes that end inside the timed loop are reset
there (their cost is part of the env's), and the resets are counted. The physics baseline is
the same number of ``mujoco.mj_step(model, data, nstep=frame_skip)`` calls on the env's own
model, in a fresh ``MjData`` copied from the env's reset state, its controls held at the home
setpoints (the zero action's). Each repeat starts both from ``env.reset(seed=...)`` (untimed)
and alternates env and physics every ``--chunk`` steps, so that other processes slow both
alike. Steps/s are the medians of the repeats; the physics share and the overhead are the
medians of each repeat's own env/physics pair.

``physics share`` is physics time / env time per env step, the part of a step spent in
``mj_step`` (the issue's goal: >= 85 %); ``overhead`` is the rest of the step (Python, NumPy,
wrappers, resets); ``x realtime`` is env steps/s x ``dt``. With ``--actions random`` the env's
robot moves while the baseline holds still, so the overhead then also holds the extra physics
of moving (more constraints and contacts) and the resets of safety terminations.

Usage (``rehabbot bench`` takes the same options)::

    python benchmarks/step_throughput.py [--steps 2000] [--repeats 5] [--warmup 100]
                                         [--chunk 100] [--actions zero|random] [--seed 0]
                                         [--ids ID ...] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

PHYSICS_SHARE_GOAL = 0.85


@dataclass
class StepRow:
    """One line of the benchmark table."""

    env_id: str
    frame_skip: int
    dt_s: float
    env_steps_per_s: float
    physics_steps_per_s: float  # env-step units: calls of mj_step(nstep=frame_skip)
    physics_share: float  # physics time / env time per env step (median of the repeats)
    realtime_factor: float  # env steps/s x dt
    overhead_us_per_step: float  # env time - physics time per env step (median of the repeats)
    resets_per_repeat: int
    terminated_per_repeat: int
    truncated_per_repeat: int
    reset_ms_mean: float | None  # mean wall time of one in-loop env.reset(); None: no reset
    env_steps_per_s_repeats: list[float] = field(default_factory=list)
    physics_steps_per_s_repeats: list[float] = field(default_factory=list)


def make_actions(env: gym.Env, kind: str, steps: int, seed: int) -> np.ndarray:
    """``steps`` actions, one per row: zeros, or samples of the (seeded) action space."""
    shape = env.action_space.shape
    if kind == "zero":
        return np.zeros((steps, *shape), dtype=np.float32)
    env.action_space.seed(seed)
    return np.stack([env.action_space.sample() for _ in range(steps)]).astype(np.float32)


@dataclass
class EpisodeCounts:
    """Episode ends met inside the timed env steps, and the time of their resets."""

    resets: int = 0
    terminated: int = 0
    truncated: int = 0
    reset_s: float = 0.0


def time_env(env: gym.Env, actions: np.ndarray, counts: EpisodeCounts) -> float:
    """Wall time of one env step per row of ``actions`` from the env's current state, the
    resets of episodes that end inside the loop included (and counted into ``counts``)."""
    perf_counter = time.perf_counter
    step = env.step
    start_s = perf_counter()
    for action in actions:
        _obs, _reward, terminated, truncated, _info = step(action)
        if terminated or truncated:
            reset_start_s = perf_counter()
            env.reset()
            counts.reset_s += perf_counter() - reset_start_s
            counts.resets += 1
            counts.terminated += bool(terminated)
            counts.truncated += bool(truncated) and not terminated
    return perf_counter() - start_s


def time_physics(model: mujoco.MjModel, data: mujoco.MjData, frame_skip: int,
                 steps: int) -> float:
    """Wall time of ``steps`` ``mj_step(nstep=frame_skip)`` calls from ``data``'s state."""
    mj_step = mujoco.mj_step
    start_s = time.perf_counter()
    for _ in range(steps):
        mj_step(model, data, nstep=frame_skip)
    return time.perf_counter() - start_s


def time_repeat(env: gym.Env, data: mujoco.MjData, actions: np.ndarray, seed: int,
                chunk: int, physics_first: bool) -> tuple[float, float, EpisodeCounts]:
    """One repeat: ``len(actions)`` env steps and as many physics calls, both from the state
    of ``env.reset(seed=seed)`` (untimed), interleaved in chunks of ``chunk`` steps so that a
    change of the machine's speed (other processes) hits both alike."""
    env.reset(seed=seed)
    base = env.unwrapped
    model, frame_skip = base.model, int(base.frame_skip)
    mujoco.mj_copyData(data, model, base.data)
    counts = EpisodeCounts()
    env_s = physics_s = 0.0
    for first in range(0, len(actions), chunk):
        block = actions[first:first + chunk]
        if physics_first:
            physics_s += time_physics(model, data, frame_skip, len(block))
        env_s += time_env(env, block, counts)
        if not physics_first:
            physics_s += time_physics(model, data, frame_skip, len(block))
        physics_first = not physics_first
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise RuntimeError(f"physics diverged (non-finite state) at t={data.time:.3f} s")
    return env_s, physics_s, counts


def measure_id(env_id: str, steps: int, repeats: int, warmup: int, chunk: int,
               action_kind: str, seed: int) -> StepRow:
    """Interleaved env / physics repeats of one id; medians of each."""
    env = gym.make(env_id)
    try:
        env.reset(seed=seed)
        base = env.unwrapped
        model, frame_skip, dt_s = base.model, int(base.frame_skip), float(base.dt_s)
        data = mujoco.MjData(model)
        actions = make_actions(env, action_kind, steps, seed)
        if warmup:
            time_repeat(env, data, actions[:warmup], seed, chunk, physics_first=False)
        env_s: list[float] = []
        physics_s: list[float] = []
        counts = EpisodeCounts()
        for repeat in range(repeats):
            elapsed_env_s, elapsed_physics_s, counts = time_repeat(
                env, data, actions, seed, chunk, physics_first=bool(repeat % 2))
            env_s.append(elapsed_env_s)
            physics_s.append(elapsed_physics_s)
    finally:
        env.close()
    # Rates: median of each. Share and overhead: median over the repeats of each repeat's own
    # pair, whose env and physics times were taken side by side.
    env_rate = steps / statistics.median(env_s)
    return StepRow(
        env_id=env_id,
        frame_skip=frame_skip,
        dt_s=dt_s,
        env_steps_per_s=env_rate,
        physics_steps_per_s=steps / statistics.median(physics_s),
        physics_share=statistics.median(p / e for e, p in zip(env_s, physics_s, strict=True)),
        realtime_factor=env_rate * dt_s,
        overhead_us_per_step=statistics.median(
            (e - p) / steps * 1e6 for e, p in zip(env_s, physics_s, strict=True)),
        resets_per_repeat=counts.resets,
        terminated_per_repeat=counts.terminated,
        truncated_per_repeat=counts.truncated,
        reset_ms_mean=counts.reset_s / counts.resets * 1e3 if counts.resets else None,
        env_steps_per_s_repeats=[steps / s for s in env_s],
        physics_steps_per_s_repeats=[steps / s for s in physics_s],
    )


def format_table(rows: Sequence[StepRow]) -> str:
    """Markdown table of the rows."""
    header = ("| id | env steps/s | physics steps/s | physics share | overhead [µs/step] "
              "| x realtime | resets (term/trunc) | reset [ms] |")
    lines = [header, "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        goal = "" if row.physics_share >= PHYSICS_SHARE_GOAL else " (< goal)"
        reset_ms = "-" if row.reset_ms_mean is None else f"{row.reset_ms_mean:.2f}"
        lines.append(
            f"| {row.env_id} | {row.env_steps_per_s:.0f} | {row.physics_steps_per_s:.0f} "
            f"| {row.physics_share:.1%}{goal} | {row.overhead_us_per_step:.1f} "
            f"| {row.realtime_factor:.1f} "
            f"| {row.resets_per_repeat} ({row.terminated_per_repeat}/"
            f"{row.truncated_per_repeat}) | {reset_ms} |"
        )
    return "\n".join(lines)


def machine_info() -> dict[str, str | int | None]:
    """Where the numbers come from."""
    return {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "cpu_count": os.cpu_count(),
        "python_version": platform.python_version(),
        "mujoco_version": mujoco.__version__,
        "gymnasium_version": gym.__version__,
        "numpy_version": np.__version__,
    }


def build_parser() -> argparse.ArgumentParser:
    """Command-line options of the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return parser


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The benchmark's options (shared by the script and ``rehabbot bench``)."""
    parser.add_argument("--steps", type=int, default=2000, help="timed env steps per repeat")
    parser.add_argument("--repeats", type=int, default=5,
                        help="interleaved env/physics repeats; the median is kept")
    parser.add_argument("--warmup", type=int, default=100,
                        help="untimed env steps (and physics calls) first, per id")
    parser.add_argument("--chunk", type=int, default=100,
                        help="env and physics alternate every this many steps in a repeat")
    parser.add_argument("--actions", choices=("zero", "random"), default="zero",
                        help="zero actions, or action_space.sample() drawn before timing")
    parser.add_argument("--seed", type=int, default=0, help="env.reset and action seed")
    parser.add_argument("--ids", nargs="+", metavar="ID",
                        help="default: every id under rehabbot/")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write results as JSON")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print the table; returns the exit code."""
    return run(build_parser().parse_args(argv), argv)


def run(args: argparse.Namespace, argv: Sequence[str] | None = None) -> int:
    """Run the benchmark with parsed options and print the table; returns the exit code."""
    if args.steps < 1 or args.repeats < 1 or args.chunk < 1 or args.warmup < 0:
        print("--steps, --repeats and --chunk must be >= 1, --warmup >= 0", file=sys.stderr)
        return 2
    import rehabbot  # noqa: F401  (registers the ids)
    from rehabbot.registration import ENV_SPECS

    ids = [env_id if "/" in env_id else f"rehabbot/{env_id}"
           for env_id in (args.ids or ENV_SPECS)]
    unknown = [env_id for env_id in ids if env_id not in ENV_SPECS]
    if unknown:
        print(f"unknown id(s) {', '.join(unknown)}; valid: {', '.join(ENV_SPECS)}",
              file=sys.stderr)
        return 2
    warmup = min(args.warmup, args.steps)
    rows = [measure_id(env_id, args.steps, args.repeats, warmup, args.chunk, args.actions,
                       args.seed) for env_id in ids]
    machine = machine_info()
    command = shlex.join(sys.orig_argv if argv is None else [sys.argv[0], *argv])
    print(f"command: `{command}`")
    print(
        f"machine: {machine['platform']}, {machine['cpu_count']} CPUs; "
        f"python {machine['python_version']}, mujoco {machine['mujoco_version']}, "
        f"gymnasium {machine['gymnasium_version']}, numpy {machine['numpy_version']}"
    )
    print(
        f"{args.steps} env steps x median of {args.repeats} repeats per id, env and physics "
        f"alternating every {args.chunk} steps, after {warmup} warm-up steps; "
        f"{args.actions} actions, seed {args.seed}; "
        f"goal: physics share >= {PHYSICS_SHARE_GOAL:.0%}"
    )
    print()
    print(format_table(rows))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        payload = {
            "command": command,
            **machine,
            "steps": args.steps,
            "repeats": args.repeats,
            "warmup": warmup,
            "chunk": args.chunk,
            "actions": args.actions,
            "seed": args.seed,
            "physics_share_goal": PHYSICS_SHARE_GOAL,
            "rows": [asdict(row) for row in rows],
        }
        args.json.write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
