"""What a new patient every episode costs: an envelope cohort against one fixed patient.

For each base id, two envs made the way users make them:

* ``fixed``: ``gym.make(id)``, the one patient of the id;
* ``bodies``: ``gym.make(population id, patients="envelope-train", conditions=0)``, one of the
  training cohort's 10 bodies, healthy, drawn at every reset: the cost of switching alone;
* ``cohort``: ``gym.make(population id, patients="envelope-train")``, a patient of the
  envelope's training cohort (:mod:`rehabbot.sim.envelope`) drawn at every reset: switching,
  and the conditions' own torques (reflex, tremor, effort) every physics step.

Both take zero actions and are reset every ``--episode-steps`` steps (50 by default: a patient
switch every second of simulated time, several times more often than in training, where
episodes last 200-1000 steps), so the cohort env pays its switches in full. A round is
``--steps`` steps of each env, timed back to back; rounds alternate which env goes first, so a
change of the machine's speed (other processes) hits both alike. The figures are medians over
``--rounds`` rounds:

* ``bodies / fixed`` and ``cohort / fixed``: each env's steps/s over the fixed env's, in the
  same rounds;
* ``build``: the wall-clock of building every patient of the cohort once (each patient's env
  is built the first time it is drawn and kept, so this is paid once per process, not per
  episode) and the memory the built patients' MuJoCo models and data hold (their buffers,
  exact sizes from MuJoCo; each data's arena, reserved for contacts and constraints and
  touched only as far as a step uses it, is reported apart).

Usage::

    python benchmarks/performance/patient_switch_throughput.py [--ids ID ...] [--steps 2000]
        [--rounds 5] [--episode-steps 50] [--page docs/results/patient-switch-throughput]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine

DEFAULT_IDS = ("rehab-reach-v2", "rehab-reach-l-v2", "rehab-hip-v2", "rehab-knee-v2")
COHORT = "envelope-train"
INTRO = """The cost of drawing a new patient every episode from the envelope's training cohort
(`patients="envelope-train"`: 10 bodies x 10 conditions), against the id's one fixed patient,
all made with `gym.make`, zero actions, reset every few steps so the cohort envs switch
patient far more often than training does (its episodes last 200-1000 steps). Rounds of the
envs alternate their order; the figures are medians over the rounds. Each patient's env is
built the first time it is drawn and kept: that build is paid once per process (the `build`
columns), not per episode."""


@dataclass
class Row:
    """One line of the table."""

    env_id: str
    patients: int
    refused: int
    fixed_steps_per_s: float
    bodies_steps_per_s: float
    cohort_steps_per_s: float
    bodies_ratio: float
    ratio: float
    ratios: list[float]
    build_s: float
    build_mb: float
    arena_mb: float


def time_steps(env: gym.Env, action: np.ndarray, steps: int, episode_steps: int,
               seed: int) -> float:
    """Seconds for ``steps`` steps with ``action``, resetting every ``episode_steps`` steps
    (and when an episode ends) with seeds counting up from ``seed``."""
    step, reset, clock = env.step, env.reset, time.perf_counter
    start = clock()
    since = 0
    for k in range(steps):
        _obs, _reward, terminated, truncated, _info = step(action)
        since += 1
        if terminated or truncated or since == episode_steps:
            reset(seed=seed + k)
            since = 0
    return clock() - start


def mujoco_bytes(env: gym.Env) -> tuple[int, int]:
    """The bytes of an env's MuJoCo model and data buffers, and of its data's arena."""
    model, data = env.unwrapped.model, env.unwrapped.data
    return int(model.nbuffer + data.nbuffer), int(data.narena)


def population_id(env_id: str) -> str:
    """The population id of a base -v2 id (``rehab-knee-v2`` -> ``rehab-knee-population-v2``)."""
    from rehabbot.envs.registration import POPULATION_VARIANTS

    for pop_id, base in POPULATION_VARIANTS.items():
        if base == env_id:
            return pop_id
    raise ValueError(f"{env_id} has no population id; valid: "
                     f"{sorted(set(POPULATION_VARIANTS.values()))}")


def measure(env_id: str, steps: int, rounds: int, episode_steps: int, seed: int) -> Row:
    fixed = gym.make(env_id)
    bodies = gym.make(population_id(env_id), patients=COHORT, conditions=0)
    bodies.unwrapped.build_all()
    start = time.perf_counter()
    cohort = gym.make(population_id(env_id), patients=COHORT)
    cohort.unwrapped.build_all()
    build_s = time.perf_counter() - start
    population = cohort.unwrapped
    sizes = np.array([mujoco_bytes(population.patient_env(k))
                      for k in population.feasible_patients])
    build_mb, arena_mb = (float(v) for v in sizes.sum(axis=0) / 2**20)
    envs = (fixed, bodies, cohort)
    try:
        action = np.zeros(fixed.action_space.shape, dtype=fixed.action_space.dtype)
        for env in envs:
            env.reset(seed=seed)
            time_steps(env, action, episode_steps * 4, episode_steps, seed)
        times: list[list[float]] = [[], [], []]
        for k in range(rounds):
            order = list(range(len(envs))) if k % 2 == 0 else list(range(len(envs)))[::-1]
            for i in order:
                envs[i].reset(seed=seed + k)
                times[i].append(time_steps(envs[i], action, steps, episode_steps,
                                           seed + 1000 * k))
        patients, refused = len(population.population.patients), len(population.refused_patients)
    finally:
        for env in envs:
            env.close()
    fixed_s, bodies_s, cohort_s = times
    ratios = [f / c for f, c in zip(fixed_s, cohort_s, strict=True)]
    return Row(env_id=env_id, patients=patients, refused=refused,
               fixed_steps_per_s=steps / statistics.median(fixed_s),
               bodies_steps_per_s=steps / statistics.median(bodies_s),
               cohort_steps_per_s=steps / statistics.median(cohort_s),
               bodies_ratio=statistics.median(
                   f / b for f, b in zip(fixed_s, bodies_s, strict=True)),
               ratio=statistics.median(ratios), ratios=ratios, build_s=build_s,
               build_mb=build_mb, arena_mb=arena_mb)


def results_table(rows: Sequence[Row], episode_steps: int) -> dict[str, Any]:
    cells = [[row.env_id, f"{row.patients - row.refused} of {row.patients}",
              f"{row.fixed_steps_per_s:.0f}", f"{row.bodies_steps_per_s:.0f}",
              f"{row.bodies_ratio:.2f}", f"{row.cohort_steps_per_s:.0f}",
              f"{row.ratio:.2f}", f"{row.build_s:.1f}", f"{row.build_mb:.0f}",
              f"{row.arena_mb:.0f}"] for row in rows]
    return make_table(
        "switch", "A patient of the envelope cohort each episode against one fixed patient",
        ["id", "patients (taken of cohort)", "fixed steps/s", "bodies steps/s",
         "bodies / fixed", "cohort steps/s", "cohort / fixed", "build [s]", "held [MB]",
         "arenas reserved [MB]"],
        cells, align=["left", *["right"] * 9],
        note=f"Reset every {episode_steps} steps in every env. `bodies`: the cohort's 10 "
             "bodies, healthy (switching alone); `cohort`: every patient of the cohort "
             "(switching and the conditions' torques). A ratio is the median over "
             "interleaved rounds of the two envs' rates in the same round; "
             "`build` is the one-off cost of building every patient the scene takes (the "
             "patients it refuses, e.g. a heavy patient resisting harder than the cuff may "
             "hold, are not in the cohort for that scene); `held`, the MuJoCo model and data "
             "buffers those patients keep; `arenas reserved`, their data's arenas (contact "
             "and constraint scratch space, touched only as far as a step uses it).")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", metavar="ID", default=list(DEFAULT_IDS),
                        help=f"base -v2 ids (default: {' '.join(DEFAULT_IDS)})")
    parser.add_argument("--steps", type=int, default=2000, help="steps per round (2000)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds; medians are kept (5)")
    parser.add_argument("--episode-steps", type=int, default=50,
                        help="reset every N steps (50)")
    add_seed_argument(parser, help_text="first reset seed (0)")
    add_page_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("steps", "rounds", "episode_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')}={getattr(args, name)} must be >= 1")
    import rehabbot  # noqa: F401  (registers the ids)

    ids = [i if "/" in i else f"rehabbot/{i}" for i in args.ids]
    for env_id in ids:
        try:
            population_id(env_id)
        except ValueError as err:
            parser.error(str(err))
    rows = [measure(i, args.steps, args.rounds, args.episode_steps, args.seed) for i in ids]
    command = script_command(__file__, argv)
    machine = f"{describe_machine()}, gymnasium {gym.__version__}, numpy {np.__version__}"
    announce(command, machine)
    table = results_table(rows, args.episode_steps)
    print(table_markdown(table))
    if args.page is not None:
        write_page(make_document(
            title="A new patient every episode: the cost against a fixed patient", intro=INTRO,
            command=command, generated_by=__file__, tables=[table], machine=machine,
            seeds={"reset_seed": args.seed},
            settings={"steps": args.steps, "rounds": args.rounds,
                      "episode_steps": args.episode_steps, "cohort": COHORT},
            data={"rows": [asdict(row) for row in rows]}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
