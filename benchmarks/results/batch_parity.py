"""The batched env (``rehabbot.batch``, MuJoCo Warp on Warp's CPU device) against the CPU env:
the scripted expert's episode of every batched id replayed in both, and safety stops forced by
constant actions, with what each env gave (the figures of ``docs/batch.md``).

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
from benchmarks.common.documents import (
    command_line,
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.analysis.batch_parity import START, replay_expert, replay_stops

INTRO = """The batched env (`rehabbot.batch`: MJX with `impl="warp"`, float32) against the CPU env
(MuJoCo, float64), on Warp's CPU device. Each id's scripted-expert episode from
`reset(seed=0, options={"exercise": 0, "weight_level": 0})` is replayed in world 0 of two
(world 1 acts otherwise, so that its contacts would show if they reached world 0). The stops
hold a constant unit action in each world of one batch, and alone on the CPU. Steps are
0-based. `tests/test_batch_parity.py` asserts the same comparisons: equal switches,
termination steps and rules, observations within 1e-3 per entry, returns within 1e-4
relative, robot work within 1e-3 relative."""

# (kwargs, unit actions held side by side): the cuff force both ways; with the highest cuff
# limit, unintended contact and range of motion.
STOPS = (({}, ([1, 0, 0, 0, 0, 0], [-1, 0, 0, 0, 0, 0])),
         ({"cuff_force_limit_n": 880.0}, ([1, 0, 0, -1, -1, -1], [1, 0, -1, 1, 1, -1])))
STOP_ID = "rehabbot/rehab-reach-v2"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page", type=Path, metavar="STEM",
                        help="write STEM.json and its page STEM.md (docs/results/batch-parity)")
    args = parser.parse_args(argv)
    import rehabbot.batch as batch  # needs the [gpu] extra: fail here, with its message

    command = command_line(__file__, argv if argv is not None else sys.argv[1:])
    print(f"command: {command}", flush=True)
    replays = []
    for env_id in batch.SUPPORTED_IDS:
        replays.append(replay_expert(env_id))
        print(replays[-1], flush=True)
    expert_table = make_table(
        "expert", "The scripted expert's episode, CPU against batched (world 0 of two)",
        ["id", "steps", "target switches", "termination step (CPU / batched)",
         "return (CPU / batched)", "max obs difference", "max reward difference per step",
         "robot work [J] (CPU / batched)"],
        [[r["id"].split("/")[1], r["steps"],
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
    tables = [expert_table, stop_table]
    for table in tables:
        print(table_markdown(table), flush=True)
    if args.page is not None:
        write_page(make_document(
            title="The batched env against the CPU env (MuJoCo Warp, CPU device)", intro=INTRO,
            command=command, generated_by=__file__, tables=tables,
            machine=describe_machine(), seeds={"reset": 0, "start": START},
            settings={"ids": list(batch.SUPPORTED_IDS), "stop_id": STOP_ID,
                      "stops": [{"kwargs": k, "unit_actions": [list(a) for a in u]}
                                for k, u in STOPS]},
            data={"expert": replays, "stops": stops}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
