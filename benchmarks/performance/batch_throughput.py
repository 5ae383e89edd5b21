"""Throughput of the batched env (``rehabbot.batch``, MuJoCo Warp) against the number of worlds,
and of the CPU env on the same machine in the same run.

For each ``--num-envs`` N, ``jax.jit(jax.vmap(env.step_auto_reset))`` steps N worlds taking
random unit actions (drawn once per round, outside the timed region), after two warm-up calls
that compile it. A round is ``--steps`` batched steps; the figure is the median of
``--rounds`` rounds. Env steps/s = N x steps / time; physics steps/s = env steps/s x
``frame_skip`` (each env step is ``frame_skip`` MuJoCo Warp steps of every world). The CPU
baseline is ``gym.make(id)`` stepped with random actions in one process (auto-reset), timed
the same way, so the ratio batched / CPU is measured in one run on one machine.

Usage::

    python benchmarks/performance/batch_throughput.py [--env rehab-reach-v2 ...]
        [--num-envs 1 16 256 1024 4096 8192] [--steps 20] [--rounds 3]
        [--page docs/results/batch-throughput]

Needs ``pip install "rehabbot[gpu]"``; on a CUDA host also ``jax[cuda12]``: JAX then runs on
the GPU, and the page names the device. Several ``--env`` ids give a table each, from one run
on one machine.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import gymnasium as gym
import numpy as np

import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.batch.env_tables import check_id
from rehabbot.envs.registration import resolve_env_id

DEFAULT_WORLDS = (1, 16, 256, 1024, 4096, 8192)
INTRO = """Env steps per second of the batched env (`rehabbot.batch`, MJX with `impl="warp"`)
against the number of worlds stepped together, and of the CPU env (`gym.make`, one process)
on the same machine in the same run. Physics steps/s = env steps/s x frame_skip (10 MuJoCo
steps of 2 ms per env step). Random unit actions; done worlds start a new episode in the same
step. Medians of the rounds. The device is the one JAX ran on: where it is a CPU, these are
Warp's CPU kernels, not a GPU's figures."""


def time_cpu(env_id: str, steps: int, rounds: int, seed: int) -> list[float]:
    """Env steps/s of the CPU env, one per round."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    rates = []
    for _ in range(rounds):
        actions = rng.uniform(-1, 1, (steps, *env.action_space.shape)).astype(np.float32)
        start = time.perf_counter()
        for action in actions:
            _obs, _r, terminated, truncated, _info = env.step(action)
            if terminated or truncated:
                env.reset()
        rates.append(steps / (time.perf_counter() - start))
    env.close()
    return rates


def time_batched(env_id: str, worlds: int, steps: int, rounds: int, seed: int
                 ) -> dict[str, Any]:
    """Env steps/s of ``worlds`` batched worlds, one per round, and the compile time."""
    import jax

    import rehabbot.batch as batch
    from rehabbot.batch.vector import CONTACTS_PER_WORLD

    env = batch.make(env_id, naconmax=CONTACTS_PER_WORLD * worlds)
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step_auto_reset))
    key = jax.random.key(seed)
    state = reset(jax.random.split(key, worlds))
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    # Warm-up with inputs like the timed ones (a device array, a stepped state: the state
    # that reset returns is traced once more), so that no timed call compiles.
    for _ in range(2):
        state = step(state, jax.device_put(np.zeros((worlds, env.action_size), np.float32)))
        jax.block_until_ready(state.obs)
    compile_s = time.perf_counter() - start
    rates = []
    for _ in range(rounds):
        actions = [jax.device_put(rng.uniform(-1, 1, (worlds, env.action_size))
                                  .astype(np.float32)) for _ in range(steps)]
        start = time.perf_counter()
        for action in actions:
            state = step(state, action)
        jax.block_until_ready(state.obs)
        rates.append(worlds * steps / (time.perf_counter() - start))
    return {"worlds": worlds, "rates": rates, "compile_s": compile_s,
            "frame_skip": env.tables.frame_skip, "device": str(jax.devices()[0])}


def measure(env_id: str, args: argparse.Namespace) -> dict[str, Any]:
    """The CPU env's rates and every ``--num-envs`` batch's, for one id."""
    cpu_rates = time_cpu(env_id, args.cpu_steps, args.rounds, args.seed)
    print(f"{env_id}: CPU env {statistics.median(cpu_rates):.0f} env steps/s", flush=True)
    results = []
    for worlds in args.num_envs:
        result = time_batched(env_id, worlds, args.steps, args.rounds, args.seed)
        result["median"] = statistics.median(result["rates"])
        results.append(result)
        print(f"{env_id}: {worlds} worlds: {result['median']:.0f} env steps/s "
              f"(compiled in {result['compile_s']:.1f} s)", flush=True)
    return {"env_id": env_id, "cpu_rates": cpu_rates, "batched": results}


def throughput_table(entry: dict[str, Any]) -> dict[str, Any]:
    """One id's table: the CPU env's row, then a row per number of worlds."""
    cpu = statistics.median(entry["cpu_rates"])
    results = entry["batched"]
    frame_skip = results[0]["frame_skip"] if results else 10
    rows = [["CPU env (1 process)", "-", f"{cpu:,.0f}", f"{cpu * frame_skip:,.0f}", "1.00",
             "-"]]
    rows += [[f"batched, {r['device']}", f"{r['worlds']:,}", f"{r['median']:,.0f}",
              f"{r['median'] * r['frame_skip']:,.0f}", f"{r['median'] / cpu:.2f}",
              f"{r['compile_s']:.1f}"] for r in results]
    name = entry["env_id"].split("/")[1]
    return make_table(f"throughput/{name}", f"{name}: env and physics steps/s",
                      ["env", "worlds", "env steps/s", "physics steps/s", "x CPU env",
                       "compile [s]"], rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", nargs="+", default=["rehab-reach-v2"], metavar="ID",
                        help="batched -v2 ids, a table each (default: %(default)s)")
    parser.add_argument("--num-envs", type=int, nargs="+", default=list(DEFAULT_WORLDS),
                        metavar="N", help="worlds per batch (default: %(default)s)")
    parser.add_argument("--steps", type=int, default=20, help="batched steps per round")
    parser.add_argument("--cpu-steps", type=int, default=500, help="CPU env steps per round")
    parser.add_argument("--rounds", type=int, default=3)
    add_seed_argument(parser)
    add_page_argument(parser)
    args = parser.parse_args(argv)
    for name in ("steps", "cpu_steps", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if any(n < 1 for n in args.num_envs):
        parser.error(f"--num-envs must be >= 1, got {args.num_envs}")
    try:  # an unknown or unbatched id is refused before anything is timed
        env_ids = [resolve_env_id(name) for name in args.env]
        for env_id in env_ids:
            check_id(env_id)
    except ValueError as err:
        parser.error(str(err))
    command = script_command(__file__, argv)
    announce(command)
    tables, measured, device = [], [], "-"
    for env_id in env_ids:
        entry = measure(env_id, args)
        measured.append(entry)
        device = entry["batched"][0]["device"] if entry["batched"] else device
        tables.append(throughput_table(entry))
        print(table_markdown(tables[-1]), flush=True)
    if args.page is not None:
        write_page(make_document(
            title=f"Batched throughput ({device})", intro=INTRO, command=command,
            generated_by=__file__, tables=tables, machine=describe_machine(),
            seeds={"actions": args.seed},
            settings={"env_ids": env_ids, "num_envs": args.num_envs, "steps": args.steps,
                      "cpu_steps": args.cpu_steps, "rounds": args.rounds,
                      "device": device},
            data={"envs": measured}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
