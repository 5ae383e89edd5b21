"""The batched env (``rehabbot.batch``, MuJoCo Warp on Warp's CPU device) against the CPU env:
the scripted expert's episode of every batched id replayed in both (the healthy ids, then the
condition ids and a grade-4 spastic arm), safety stops forced by constant actions, and the
tremor's statistics while the robot holds still, with what each env gave (the figures of
``docs/batch.md``).

    python benchmarks/results/batch_parity.py [--page docs/results/batch-parity]

Needs ``pip install "rehabbot[gpu]"``. Warp compiles its kernels once (about a minute, cached
in ``~/.cache/warp``); the replays then take a few minutes on the CPU.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.batch_parity import (
    START,
    band_rms,
    hold_still,
    replay_expert,
    replay_population,
    replay_stops,
    tremor_spectrum,
)
from benchmarks.common.cli import add_page_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine

INTRO = """The batched env (`rehabbot.batch`: MJX with `impl="warp"`, float32) against the CPU env
(MuJoCo, float64), on Warp's CPU device. Each id's scripted-expert episode from
`reset(seed=0, options={"exercise": 0, "weight_level": 0})` is replayed in world 0 of two
(world 1 acts otherwise, so that its contacts would show if they reached world 0). The stops
hold a constant unit action in each world of one batch, and alone on the CPU. Steps are
0-based. `tests/test_batch_parity.py` asserts the same comparisons: equal switches,
termination steps and rules, observations within 1e-3 per entry, returns within 1e-4
relative, robot work within 1e-3 relative; `tests/test_batch_conditions.py` asserts them, and
the patient's work within 1e-3 relative, for three of the conditions below. The tremor draws
its random numbers from JAX keys in the batched env and from `np_random` on the CPU, so it is
compared by its statistics: the robot holds still and batched world k starts its tremor where
CPU seed k drew it. In the conditions' table, `rehab-reach-tremor-v2` therefore runs on
different random streams in the two envs: its switches, termination and return agree, its
observations and work need not. In `rehab-hip-spastic-v2` the expert moves too slowly for the
grade-2 reflex to fire (no patient work).

The populations' table replays every patient of both shipped populations of each population
id at once, patient k in world k of one batch, each world its own patient's CPU episode from
`reset(seed=0, options={"exercise": 0, "weight_level": 0, "patient": k})`. Its differences
are the largest over the population's patients without tremor; a tremor patient's random
streams differ, as above, so its switches and termination are counted apart.

The expert's table also replays the two-arm id, `rehab-bilateral-v2`, on its symmetric
(entry 0) and alternating (entry 2) exercises."""

# (kwargs, unit actions held side by side): the cuff force both ways; with the highest cuff
# limit, unintended contact and range of motion.
STOPS = (({}, ([1, 0, 0, 0, 0, 0], [-1, 0, 0, 0, 0, 0])),
         ({"cuff_force_limit_n": 880.0}, ([1, 0, 0, -1, -1, -1], [1, 0, -1, 1, 1, -1])))
STOP_ID = "rehabbot/rehab-reach-v2"
# The condition replays: the strongest stretch reflex (MAS 4) on the arm through condition=,
# then every batched condition id (rehabbot.batch.env_tables.CONDITION_IDS).
MAS4_CASE = ("rehabbot/rehab-reach-v2", {"condition": {"spasticity_mas": "4"}})
TREMOR_ID, TREMOR_STEPS, TREMOR_SEEDS = "rehabbot/rehab-reach-tremor-v2", 200, tuple(range(8))
POPULATION_NAMES = ("train", "test")
# The two-arm id: its symmetric and alternating exercises (entries 0 and 2 of its table).
BILATERAL_CASES = (("rehabbot/rehab-bilateral-v2", {"exercise": 0, "weight_level": 0}),
                   ("rehabbot/rehab-bilateral-v2", {"exercise": 2, "weight_level": 0}))
# The progress reward's optional terms switched on (smoothness of the action, robot effort).
REWARD_CASE = ("rehabbot/rehab-reach-v2",
               {"reward": {"design": "progress", "smoothness_weight": 2.0, "effort_weight": 1.0}})


def population_replays(env_id: str, name: str) -> dict:
    """Every patient of population ``name`` of ``env_id`` replayed side by side."""
    import gymnasium as gym

    population = gym.make(env_id, patients=name).unwrapped.population
    rows = replay_population(env_id, range(len(population.patients)), patients=name)
    tremor = [k for k, (_profile, condition) in enumerate(population.patients)
              if condition.tremor_hz > 0 and condition.tremor_amplitude_nm > 0]
    return {"id": env_id, "population": name, "tremor_patients": tremor,
            "conditions": [c.describe() for c in population.conditions],
            "profiles_m": [p.height_m for p in population.profiles], "rows": rows}


def population_row(result: dict) -> list:
    """A row of the populations' table."""
    rows, tremor = result["rows"], set(result["tremor_patients"])
    def same(group: list[dict]) -> str:
        count = sum(r["switches_cpu"] == r["switches_batched"]
                    and r["end_cpu"] == r["end_batched"]
                    and r["stop_batched"] == (r["stop_cpu"] or 0) for r in group)
        return f"{count} of {len(group)}"

    steady = [r for r in rows if r["patient"] not in tremor]
    trembling = [r for r in rows if r["patient"] in tremor]
    work_error = max(abs(r["patient_work_batched_j"] - r["patient_work_cpu_j"]) for r in steady)
    return [result["id"].split("/")[1], result["population"],
            f"{len(result['profiles_m'])} x {len(result['conditions'])} = {len(rows)}",
            same(steady), same(trembling),
            f"{min(r['end_cpu'] for r in rows)} - {max(r['end_cpu'] for r in rows)}",
            f"{max(r['obs_error'] for r in steady):.1e}",
            f"{max(abs(r['return_batched'] / r['return_cpu'] - 1) for r in steady):.1e}",
            f"{work_error:.1e}",
            f"{max(abs(r['patient_work_cpu_j']) for r in steady):.2f}"]


def tremor_rows() -> tuple[list[list], dict]:
    """The tremor hold: per env, the spectral peak and the RMS of the joint angles in the
    tremor band; the data."""
    import gymnasium as gym

    condition = gym.make(TREMOR_ID).unwrapped.config.condition
    hold = hold_still(TREMOR_ID, TREMOR_STEPS, TREMOR_SEEDS)
    hz, dt_s = condition.tremor_hz, hold["dt_s"]
    rows, data = [], {"tremor_hz": hz, "steps": TREMOR_STEPS, "seeds": list(TREMOR_SEEDS)}
    for name in ("cpu", "batched"):
        freqs, power = tremor_spectrum(hold[name], dt_s)
        peak = float(freqs[freqs > 1.0][power[freqs > 1.0].argmax()])
        band = band_rms(hold[name], dt_s, hz - 1.0, hz + 1.0)
        runs = [band_rms(hold[name][:, k:k + 1], dt_s, hz - 1.0, hz + 1.0)
                for k in range(len(TREMOR_SEEDS))]
        rows.append([name, f"{peak:.2f}", f"{1e3 * band:.3f}",
                     f"{1e3 * min(runs):.3f} - {1e3 * max(runs):.3f}"])
        data[name] = {"peak_hz": peak, "band_rms_rad": band, "run_band_rms_rad": runs}
    return rows, data


def condition_row(r: dict) -> list:
    """A row of the conditions' table."""
    condition = r.get("kwargs", {}).get("condition")
    name = r["id"].split("/")[1] + (f" ({', '.join(f'{k}={v}' for k, v in condition.items())})"
                                    if condition else "")
    return [name, r["steps"],
            f"{len(r['switches_cpu'])}, " + ("the same" if r["switches_cpu"] ==
                                             r["switches_batched"] else "DIFFERENT"),
            f"{r['end_cpu']} / {r['end_batched']}",
            f"{r['return_cpu']:.6f} / {r['return_batched']:.6f}", f"{r['obs_error']:.1e}",
            f"{r['patient_work_cpu_j']:.4f} / {r['patient_work_batched_j']:.4f}",
            f"{r['robot_work_cpu_j']:.4f} / {r['robot_work_batched_j']:.4f}"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_page_argument(parser, "docs/results/batch-parity")
    args = parser.parse_args(argv)
    import rehabbot.batch as batch  # needs the [gpu] extra: fail here, with its message
    from rehabbot.batch.env_tables import CONDITION_IDS, POPULATION_IDS

    cases = (MAS4_CASE, *((env_id, {}) for env_id in CONDITION_IDS))

    command = script_command(__file__, argv)
    announce(command)
    replays = []
    for env_id in batch.SUPPORTED_IDS:
        replays.append({**replay_expert(env_id), "kwargs": {}})
        print(replays[-1], flush=True)
    replays.append({**replay_expert(REWARD_CASE[0], **REWARD_CASE[1]), "kwargs": REWARD_CASE[1]})
    print(replays[-1], flush=True)
    for env_id, start in BILATERAL_CASES:
        replays.append({**replay_expert(env_id, start=start), "kwargs": {}})
        print(replays[-1], flush=True)
    expert_table = make_table(
        "expert", "The scripted expert's episode, CPU against batched (world 0 of two)",
        ["id", "steps", "target switches", "termination step (CPU / batched)",
         "return (CPU / batched)", "max obs difference", "max reward difference per step",
         "robot work [J] (CPU / batched)"],
        [[r["id"].split("/")[1] + (" (reward: smoothness_weight 2, effort_weight 1)"
                                   if r["kwargs"] else "")
          + (f" (exercise {r['start']['exercise']})" if "bilateral" in r["id"] else ""),
          r["steps"],
          f"{len(r['switches_cpu'])}, " + ("the same" if r["switches_cpu"] ==
                                           r["switches_batched"] else "DIFFERENT"),
          f"{r['end_cpu']} / {r['end_batched']}",
          f"{r['return_cpu']:.6f} / {r['return_batched']:.6f}", f"{r['obs_error']:.1e}",
          f"{r['reward_error']:.1e}",
          f"{r['robot_work_cpu_j']:.4f} / {r['robot_work_batched_j']:.4f}"] for r in replays])
    stops = []
    for kwargs, unit_actions in STOPS:
        stops += replay_stops(STOP_ID, unit_actions, **kwargs)
        print(stops[-2:], flush=True)
    stop_table = make_table(
        "stops", f"Safety stops on {STOP_ID.split('/')[1]}, a constant unit action per world",
        ["unit action", "kwargs", "stop step (CPU / batched)", "rule (CPU / batched)",
         "last reward (CPU / batched)", "return (CPU / batched)"],
        [[str(r["unit_action"]), ", ".join(f"{k}={v:g}" for k, v in r["kwargs"].items()) or "-",
          f"{r['stop_cpu']} / {r['stop_batched']}", f"{r['rule_cpu']} / {r['rule_batched']}",
          f"{r['last_reward_cpu']:.4f} / {r['last_reward_batched']:.4f}",
          f"{r['return_cpu']:.4f} / {r['return_batched']:.4f}"] for r in stops])
    conditions = []
    for env_id, kwargs in cases:
        conditions.append({**replay_expert(env_id, **kwargs), "kwargs": kwargs})
        print(conditions[-1], flush=True)
    condition_table = make_table(
        "conditions", "Patient conditions: the scripted expert's episode, CPU against batched",
        ["id (condition)", "steps", "target switches", "termination step (CPU / batched)",
         "return (CPU / batched)", "max obs difference", "patient work [J] (CPU / batched)",
         "robot work [J] (CPU / batched)"], [condition_row(r) for r in conditions])
    populations = []
    for env_id in POPULATION_IDS:
        for name in POPULATION_NAMES:
            populations.append(population_replays(env_id, name))
            print(population_row(populations[-1]), flush=True)
    population_table = make_table(
        "populations", "Populations: every patient's scripted-expert episode, CPU against "
        "batched, all patients of a population side by side in one batch",
        ["id", "population", "patients (profiles x conditions)",
         "same switches, termination and stop", "... with tremor (other random streams)",
         "termination steps (CPU)",
         "max obs difference", "max return difference (relative)",
         "max patient work difference [J]", "largest patient work [J]"],
        [population_row(p) for p in populations])
    rows, tremor = tremor_rows()
    tremor_table = make_table(
        "tremor", f"Tremor ({TREMOR_ID.split('/')[1]}, {tremor['tremor_hz']:g} Hz): the "
        f"patient's joint angles while the robot holds still {TREMOR_STEPS} steps, "
        f"{len(TREMOR_SEEDS)} runs",
        ["env", "spectral peak [Hz]", "RMS in tremor_hz +- 1 Hz [mrad]",
         "RMS per run [mrad], lowest - highest"], rows)
    tables = [expert_table, stop_table, condition_table, population_table, tremor_table]
    for table in tables:
        print(table_markdown(table), flush=True)
    if args.page is not None:
        write_page(make_document(
            title="The batched env against the CPU env (MuJoCo Warp, CPU device)", intro=INTRO,
            command=command, generated_by=__file__, tables=tables,
            machine=describe_machine(), seeds={"reset": 0, "start": START},
            settings={"ids": list(batch.SUPPORTED_IDS), "stop_id": STOP_ID,
                      "reward_case": {"id": REWARD_CASE[0], "kwargs": REWARD_CASE[1]},
                      "bilateral_cases": [{"id": i, "start": s} for i, s in BILATERAL_CASES],
                      "conditions": [{"id": i, "kwargs": k} for i, k in cases],
                      "populations": {"ids": list(POPULATION_IDS),
                                      "names": list(POPULATION_NAMES)},
                      "tremor": {"id": TREMOR_ID, "steps": TREMOR_STEPS,
                                 "seeds": list(TREMOR_SEEDS)},
                      "stops": [{"kwargs": k, "unit_actions": [list(a) for a in u]}
                                for k, u in STOPS]},
            data={"expert": replays, "stops": stops, "conditions": conditions,
                  "populations": populations, "tremor": tremor}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
