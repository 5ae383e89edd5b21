"""Training speed of every algorithm on both backends: env steps per second of ``learn``,
Stable-Baselines3 (PyTorch) next to SBX (JAX), measured in one run on one env.

Each (algorithm, backend) model is built with ``MlpPolicy`` and the same settings on both
backends: hidden layers ``--net-arch`` for actor and critic (64 x 64, the size of the shipped
settings files; the libraries' default is 256 x 256 for the off-policy algorithms, where the
networks' arithmetic rather than Python dominates a CPU's time per step); the off-policy
algorithms (sac, td3, tqc, crossq) with ``train_freq=4, gradient_steps=4`` (one update per
env step, four at a time), ``learning_starts=100``, batch 256; PPO with ``n_steps=512``,
batch 64, 10 epochs. Everything else is the library's default. Then:

* **warm-up**: ``learn(--warmup)`` once, untimed for the rate. It includes the first
  gradient updates, so SBX's just-in-time compilation happens here; its wall-clock is
  reported on its own (``warm-up [s]``: compile plus the warm-up steps), and so is the
  compile time it implies (``compile ≈ [s]``: the warm-up's wall-clock minus its steps at the
  timed rate; for SB3, which compiles nothing, this stays near 0).
* **timed**: ``--rounds`` rounds; in each, every model learns ``--steps / --rounds`` more
  steps in turn (``reset_num_timesteps=False``), so that a change of the machine's speed
  (other processes) hits every model alike. ``steps/s`` = timed steps / timed seconds.

The table gives steps/s per algorithm for both backends side by side, their ratio, and each
rate as a multiple of SB3 SAC's (the baseline, measured in the same run). PyTorch runs with
one thread (as ``rehabbot train`` does); run it with ``OMP_NUM_THREADS=1
XLA_FLAGS=--xla_cpu_multi_thread_eigen=false`` for one-thread JAX. Absolute rates depend on
the machine; only the ratios compare across machines.

Usage::

    python benchmarks/performance/training_speed.py [--steps 2048] [--algos sac td3 ppo tqc crossq]
        [--backends sb3 sbx] [--rounds 4] [--warmup 512] [--env rehabbot/rehab-reach-v0]
        [--net-arch 64 64] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from rehabbot.common.text_tables import markdown_table

ALGOS = ("sac", "td3", "ppo", "tqc", "crossq")
BACKENDS = ("sb3", "sbx")
BASELINE = ("sac", "sb3")
PPO_N_STEPS = 512
OFF_POLICY_SETTINGS = {"train_freq": 4, "gradient_steps": 4, "learning_starts": 100,
                       "batch_size": 256}
PPO_SETTINGS = {"n_steps": PPO_N_STEPS, "batch_size": 64, "n_epochs": 10}


@dataclass
class Row:
    """One model's figures."""

    algo: str
    backend: str
    library_version: str | None
    warmup_s: float
    warmup_steps: int
    compile_s: float  # warm-up wall-clock minus its steps at the timed rate
    timed_steps: int
    timed_s: float
    steps_per_s: float


def settings(algo: str, net_arch: list[int], buffer_size: int) -> dict[str, Any]:
    """The constructor arguments of ``algo`` in this benchmark (the same on both backends)."""
    if algo == "ppo":
        return {**PPO_SETTINGS, "policy_kwargs": {"net_arch": net_arch}}
    return {**OFF_POLICY_SETTINGS, "buffer_size": buffer_size,
            "policy_kwargs": {"net_arch": net_arch}}


def build(algo: str, backend: str, env_id: str, net_arch: list[int], buffer_size: int,
          seed: int) -> Any:
    """A fresh model of ``algo`` on ``backend`` in a new env of ``env_id``."""
    import gymnasium as gym

    from rehabbot.rl.algorithms import algo_class

    env = gym.make(env_id)
    return algo_class(algo, backend)("MlpPolicy", env, seed=seed, verbose=0,
                                     **settings(algo, net_arch, buffer_size))


def chunk_size(algo: str, steps: int, rounds: int) -> int:
    """Steps per round: PPO learns whole rollouts."""
    per_round = max(steps // rounds, 1)
    if algo == "ppo":
        per_round = max(PPO_N_STEPS, per_round // PPO_N_STEPS * PPO_N_STEPS)
    return per_round


def measure(algos: Sequence[str], backends: Sequence[str], env_id: str, steps: int,
            rounds: int, warmup: int, net_arch: list[int], seed: int) -> list[Row]:
    """Warm every model up, then time ``rounds`` interleaved rounds of learning."""
    from rehabbot.rl.backends import backend_version

    buffer_size = warmup + steps + PPO_N_STEPS
    models: dict[tuple[str, str], Any] = {}
    warmup_s: dict[tuple[str, str], float] = {}
    warmup_steps: dict[tuple[str, str], int] = {}
    for algo in algos:
        for backend in backends:
            model = build(algo, backend, env_id, net_arch, buffer_size, seed)
            start = time.perf_counter()
            model.learn(max(warmup, PPO_N_STEPS) if algo == "ppo" else warmup)
            warmup_s[(algo, backend)] = time.perf_counter() - start
            warmup_steps[(algo, backend)] = int(model.num_timesteps)
            models[(algo, backend)] = model
            print(f"warmed up {algo} on {backend} in {warmup_s[(algo, backend)]:.1f} s",
                  file=sys.stderr, flush=True)
    timed_s = dict.fromkeys(models, 0.0)
    timed_steps = dict.fromkeys(models, 0)
    for _ in range(rounds):
        for key, model in models.items():
            chunk = chunk_size(key[0], steps, rounds)
            before = int(model.num_timesteps)
            start = time.perf_counter()
            model.learn(chunk, reset_num_timesteps=False)
            timed_s[key] += time.perf_counter() - start
            timed_steps[key] += int(model.num_timesteps) - before
    rows = []
    for (algo, backend), model in models.items():
        model.get_env().close()
        rate = timed_steps[(algo, backend)] / timed_s[(algo, backend)]
        key = (algo, backend)
        rows.append(Row(algo=algo, backend=backend, library_version=backend_version(backend),
                        warmup_s=warmup_s[key], warmup_steps=warmup_steps[key],
                        compile_s=max(0.0, warmup_s[key] - warmup_steps[key] / rate),
                        timed_steps=timed_steps[(algo, backend)],
                        timed_s=timed_s[(algo, backend)], steps_per_s=rate))
    return rows


def speed_table(rows: Sequence[Row], backends: Sequence[str]) -> str:
    """Markdown (:mod:`rehabbot.common.text_tables`): one line per algorithm, the backends side by
    side."""
    by_key = {(row.algo, row.backend): row for row in rows}
    baseline = by_key.get(BASELINE)
    header = ["algo"]
    header += [f"{b} steps/s" for b in backends]
    if len(backends) == 2:
        header.append(f"{backends[1]} / {backends[0]}")
    header += [f"{b} warm-up [s]" for b in backends]
    header += [f"{b} compile ≈ [s]" for b in backends]
    header += [f"{b} × SB3 SAC" for b in backends]
    lines = []
    for algo in dict.fromkeys(row.algo for row in rows):
        cells = [algo]
        mine = [by_key.get((algo, b)) for b in backends]
        cells += [f"{r.steps_per_s:.0f}" if r else "–" for r in mine]
        if len(backends) == 2:
            cells.append(f"{mine[1].steps_per_s / mine[0].steps_per_s:.2f}"
                         if mine[0] and mine[1] else "–")
        cells += [f"{r.warmup_s:.1f}" if r else "–" for r in mine]
        cells += [f"{r.compile_s:.1f}" if r else "–" for r in mine]
        cells += [f"{r.steps_per_s / baseline.steps_per_s:.2f}" if r and baseline else "–"
                  for r in mine]
        lines.append(cells)
    return markdown_table(header, lines, align=["left", *["right"] * (len(header) - 1)])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2048,
                        help="timed env steps per model (2048)")
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), metavar="ALGO",
                        help=f"algorithms ({' '.join(ALGOS)})")
    parser.add_argument("--backends", nargs="+", default=list(BACKENDS), metavar="B",
                        help="backends (sb3 sbx)")
    parser.add_argument("--rounds", type=int, default=4,
                        help="interleaved timed rounds (4)")
    parser.add_argument("--warmup", type=int, default=512,
                        help="untimed steps first, compilation included (512)")
    parser.add_argument("--env", default="rehabbot/rehab-reach-v0", metavar="ID",
                        help="env id (rehabbot/rehab-reach-v0)")
    parser.add_argument("--net-arch", type=int, nargs="+", default=[64, 64], metavar="N",
                        help="hidden layers of every network (64 64)")
    parser.add_argument("--seed", type=int, default=0, help="model seed (0)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the rows as JSON")
    return parser


def check(args: argparse.Namespace) -> str | None:
    """Why the arguments cannot run (None if they can)."""
    bad_algos = [a for a in args.algos if a not in ALGOS]
    bad_backends = [b for b in args.backends if b not in BACKENDS]
    if bad_algos:
        return f"unknown algorithm(s) {', '.join(bad_algos)}; valid: {', '.join(ALGOS)}"
    if bad_backends:
        return f"unknown backend(s) {', '.join(bad_backends)}; valid: {', '.join(BACKENDS)}"
    if args.steps < 1 or args.rounds < 1 or args.warmup < 1 or min(args.net_arch) < 1:
        return "--steps, --rounds, --warmup and --net-arch must be >= 1"
    if "sbx" in args.backends:
        from rehabbot.rl.backends import sbx_available

        if not sbx_available():
            return "the sbx backend needs sbx-rl and jax: pip install 'rehabbot[jax]' (or " \
                   "--backends sb3)"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.algos = list(dict.fromkeys(a.lower() for a in args.algos))
    args.backends = list(dict.fromkeys(b.lower() for b in args.backends))
    problem = check(args)
    if problem is not None:
        print(problem, file=sys.stderr)
        return 2
    import gymnasium as gym
    import torch

    import rehabbot  # noqa: F401  (registers the ids)

    if args.env not in gym.registry:
        print(f"unknown env id {args.env}", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    rows = measure(args.algos, args.backends, args.env, args.steps, args.rounds, args.warmup,
                   list(args.net_arch), args.seed)
    versions = ", ".join(f"{r.backend} {r.library_version}" for r in
                         {r.backend: r for r in rows}.values())
    print(f"command: {shlex.join([Path(sys.argv[0]).as_posix(), *(argv or sys.argv[1:])])}")
    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, python "
          f"{platform.python_version()}; {versions}; OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS', '-')}, XLA_FLAGS="
          f"{os.environ.get('XLA_FLAGS', '-')}")
    print(f"{args.env}, MlpPolicy {args.net_arch}; off-policy train_freq=4, "
          f"gradient_steps=4; PPO n_steps={PPO_N_STEPS}; {args.steps} timed steps per model "
          f"in {args.rounds} interleaved rounds after {args.warmup} warm-up steps (the warm-up "
          "includes JIT compilation)\n")
    print(speed_table(rows, args.backends))
    if args.json is not None:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
