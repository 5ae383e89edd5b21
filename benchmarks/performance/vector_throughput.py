"""The CPU vector env against Gymnasium's ``SyncVectorEnv`` of the same id, and against the
raw physics of the same worlds.

For each id, ``N`` worlds take zero actions in three ways, timed in rounds that alternate
their order (so a change of the machine's speed hits all alike); the figures are medians over
the rounds, in microseconds per world-step (one world advanced by one decision):

* ``sync``: ``gym.make_vec(id, N, vectorization_mode="sync")``, Gymnasium's reference;
* ``vector``: ``gym.make_vec(id, N, vectorization_mode="vector_entry_point")``,
  :class:`rehabbot.envs.vector.RehabVectorEnv`, its physics on ``--threads`` threads;
* ``physics``: ``mujoco.mj_step(model, data, nstep=frame_skip)`` on copies of the ``N``
  worlds' models and states, split over the same threads as the vector env splits them:
  what the vector env would cost if everything but MuJoCo were free.

``speedup`` is sync / vector; ``physics share`` is physics / vector (the goal: at least 90 %);
``bound`` is sync / physics, the speedup no overhead at all would give.

Usage::

    python benchmarks/performance/vector_throughput.py [--ids ID ...] [--num-envs 16]
        [--threads T] [--steps 100] [--rounds 5] [--page docs/results/vector-throughput]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import make_document, make_table, table_markdown, write_page
from benchmarks.common.machine import describe_machine
from benchmarks.performance.step_throughput import _physics_copy

PHYSICS_SHARE_GOAL = 0.90
SPEEDUP_GOAL = 2.5
DEFAULT_IDS = ("rehabbot/rehab-reach-v2", "rehabbot/rehab-knee-v2", "rehabbot/rehab-hip-v2",
               "rehabbot/rehab-reach-spastic-v2", "rehabbot/rehab-knee-resistive-v2",
               "rehabbot/rehab-reach-population-v2", "rehabbot/rehab-bilateral-v2",
               "rehabbot/rehab-knee-v0")


def _time_vector(vec: Any, action: np.ndarray, steps: int) -> float:
    clock, step = time.perf_counter, vec.step
    start = clock()
    for _ in range(steps):
        step(action)
    return clock() - start


def _time_physics(worlds: list[tuple[Any, Any, int]], chunks: list[list[int]],
                  pool: ThreadPoolExecutor | None, steps: int) -> float:
    def run(chunk: list[int]) -> None:
        for i in chunk:
            model, data, frame_skip = worlds[i]
            mujoco.mj_step(model, data, nstep=frame_skip)

    clock = time.perf_counter
    start = clock()
    for _ in range(steps):
        futures = [pool.submit(run, chunk) for chunk in chunks[1:]] if pool else []
        run(chunks[0])
        for future in futures:
            future.result()
    return clock() - start


def measure(env_id: str, num_envs: int, threads: int | None, steps: int, rounds: int,
            warmup: int, seed: int) -> dict[str, Any]:
    """One id's medians (µs per world-step) and per-round times."""
    vector = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                          threads=threads)
    sync = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync")
    base = vector.unwrapped
    pool = ThreadPoolExecutor(base.threads - 1) if base.threads > 1 else None
    try:
        vector.reset(seed=seed)
        sync.reset(seed=seed)
        worlds = [(*_physics_copy(env), int(env.frame_skip)) for env in base.envs]
        chunks = [chunk.tolist() for chunk in
                  np.array_split(np.arange(num_envs), base.threads)]
        action = np.zeros(vector.action_space.shape, vector.action_space.dtype)
        _time_vector(vector, action, warmup)
        _time_vector(sync, action, warmup)
        _time_physics(worlds, chunks, pool, warmup)
        times: dict[str, list[float]] = {"sync": [], "vector": [], "physics": []}
        runners = {"sync": lambda: _time_vector(sync, action, steps),
                   "vector": lambda: _time_vector(vector, action, steps),
                   "physics": lambda: _time_physics(worlds, chunks, pool, steps)}
        for k in range(rounds):
            order = list(runners) if k % 2 == 0 else list(reversed(runners))
            for name in order:
                times[name].append(runners[name]() / (steps * num_envs) * 1e6)
        threads_used = base.threads
    finally:
        vector.close()
        sync.close()
        if pool is not None:
            pool.shutdown()
    median = {name: statistics.median(values) for name, values in times.items()}
    return {"env_id": env_id, "num_envs": num_envs, "threads": threads_used,
            "us_per_world_step": median, "rounds_us": times,
            "speedup": median["sync"] / median["vector"],
            "physics_share": median["physics"] / median["vector"],
            "bound": median["sync"] / median["physics"]}


def results_table(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    cells = []
    for row in rows:
        us = row["us_per_world_step"]
        speedup = f"{row['speedup']:.2f}x" + ("" if row["speedup"] >= SPEEDUP_GOAL
                                              else " (< goal)")
        share = f"{row['physics_share']:.0%}" + ("" if row["physics_share"]
                                                 >= PHYSICS_SHARE_GOAL else " (< goal)")
        cells.append([row["env_id"], f"{us['sync']:.0f}", f"{us['vector']:.0f}",
                      f"{us['physics']:.0f}", speedup, share, f"{row['bound']:.2f}x",
                      f"{1e6 / us['vector']:.0f}"])
    return make_table(
        "vector", "The vector env against SyncVectorEnv and against its physics",
        ["id", "sync [µs/world-step]", "vector [µs/world-step]",
         "physics [µs/world-step]", "speedup", "physics share", "bound",
         "vector world-steps/s"], cells, align=["left", *["right"] * 7],
        note=f"Medians over interleaved rounds of the same run. speedup = sync / vector (the "
             f"goal: at least {SPEEDUP_GOAL}x); physics share = physics / vector (the goal: "
             f"at least {PHYSICS_SHARE_GOAL:.0%}); bound = sync / physics, the speedup with "
             "no overhead at all.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", metavar="ID", default=list(DEFAULT_IDS))
    parser.add_argument("--num-envs", type=int, default=16, help="worlds (16)")
    parser.add_argument("--threads", type=int, help="default: one per usable CPU")
    parser.add_argument("--steps", type=int, default=100, help="vector steps per round (100)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds; medians are kept (5)")
    parser.add_argument("--warmup", type=int, default=20, help="untimed steps first (20)")
    add_seed_argument(parser, help_text="reset seed (0)")
    add_page_argument(parser, "docs/results/vector-throughput")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if min(args.num_envs, args.steps, args.rounds) < 1 or args.warmup < 0:
        print("--num-envs, --steps and --rounds must be >= 1, --warmup >= 0",
              file=sys.stderr)
        return 2
    import rehabbot  # noqa: F401  (registers the ids)

    command = script_command("benchmarks/performance/vector_throughput.py", argv)
    machine = describe_machine()
    announce(command, machine)
    rows = []
    for env_id in args.ids:
        rows.append(measure(env_id, args.num_envs, args.threads, args.steps, args.rounds,
                            args.warmup, args.seed))
        print(f"{env_id}: {rows[-1]['speedup']:.2f}x", flush=True)
    table = results_table(rows)
    print(table_markdown(table))
    if args.page is not None:
        document = make_document(
            title="The CPU vector env: throughput against SyncVectorEnv",
            intro=("`gym.make_vec(id, N, vectorization_mode=\"vector_entry_point\")` "
                   "(`rehabbot.envs.vector.RehabVectorEnv`: the worlds' physics on threads, "
                   "the rest of each step per world on the calling thread) against "
                   "Gymnasium's `SyncVectorEnv` of the same id, and against the raw MuJoCo "
                   "steps of the same worlds split over the same threads. Zero actions; "
                   "episodes that end restart as the vector envs restart them."),
            command=command, generated_by="benchmarks/performance/vector_throughput.py",
            machine=machine, seeds={"reset_seed": args.seed},
            settings={"num_envs": args.num_envs, "threads": rows[0]["threads"],
                      "steps": args.steps, "rounds": args.rounds, "warmup": args.warmup},
            tables=[table], data={"rows": rows})
        write_page(document, args.page)
        print(f"wrote {args.page}.json and {args.page}.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
