"""The single env's step before and after a change, measured in one run.

Every round times each id on both trees, in a fresh process per tree (alternating which tree
goes first, so a change of the machine's speed hits both alike), with
:func:`benchmarks.performance.step_throughput.measure`: env steps of ``gym.make(id)`` against
the raw physics of the same step. The "before" tree is a git revision checked out into a
temporary worktree; the "after" tree is this one. The figures are medians over the rounds:
the overhead [µs/step] (env time - physics time) and the physics share (physics / env time),
the ratio to compare across machines.

Usage::

    python benchmarks/performance/single_env_before_after.py --before REV [--ids ID ...]
        [--rounds 5] [--steps 300] [--page docs/results/NAME]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import make_document, make_table, write_page
from benchmarks.common.machine import describe_machine

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_IDS = ("rehabbot/rehab-reach-v0", "rehabbot/rehab-knee-v0", "rehabbot/rehab-reach-v2",
               "rehabbot/rehab-knee-v2", "rehabbot/rehab-reach-spastic-v2",
               "rehabbot/rehab-knee-resistive-v2", "rehabbot/rehab-knee-population-v2",
               "rehabbot/rehab-bilateral-v2")
# Run in a fresh process: rehabbot from TREE, the measurement from this tree.
MEASURE = """
import json, sys, warnings
warnings.simplefilter("ignore")
tree, root, ids, steps, warmup, seed = json.loads(sys.argv[1])
sys.path.insert(0, tree)
import rehabbot
assert rehabbot.__file__.startswith(tree), rehabbot.__file__
sys.path.insert(0, root)
from benchmarks.performance.step_throughput import measure
rows = {}
for env_id in ids:
    row = measure(env_id, steps, 1, warmup, seed)
    rows[env_id] = [row.overhead_us, row.physics_share]
print(json.dumps(rows))
"""


def _measure_tree(tree: Path, ids: Sequence[str], steps: int, warmup: int,
                  seed: int) -> dict[str, list[float]]:
    payload = json.dumps([str(tree), str(ROOT), list(ids), steps, warmup, seed])
    done = subprocess.run([sys.executable, "-c", MEASURE, payload], cwd=tree, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare(before: Path, ids: Sequence[str], rounds: int, steps: int, warmup: int,
            seed: int) -> dict[str, dict[str, list[list[float]]]]:
    """Per id and tree (``"before"``, ``"after"``), each round's overhead and share."""
    results: dict[str, dict[str, list[list[float]]]] = {
        i: {"before": [], "after": []} for i in ids}
    trees = {"before": before, "after": ROOT}
    for k in range(rounds):
        order = ("before", "after") if k % 2 == 0 else ("after", "before")
        for name in order:
            for env_id, values in _measure_tree(trees[name], ids, steps, warmup, seed).items():
                results[env_id][name].append(values)
        print(f"round {k + 1}/{rounds} done", flush=True)
    return results


def results_table(results: dict[str, dict[str, list[list[float]]]], revision: str) -> dict:
    cells = []
    for env_id, trees in results.items():
        before_us = statistics.median(v[0] for v in trees["before"])
        after_us = statistics.median(v[0] for v in trees["after"])
        before_share = statistics.median(v[1] for v in trees["before"])
        after_share = statistics.median(v[1] for v in trees["after"])
        cells.append([env_id, f"{before_us:.1f}", f"{after_us:.1f}",
                      f"{after_us - before_us:+.1f}", f"{before_share:.1%}",
                      f"{after_share:.1%}"])
    return make_table(
        "before_after", f"The single env's overhead: {revision} against this tree",
        ["id", "overhead before [µs/step]", "overhead after [µs/step]", "change [µs]",
         "physics share before", "physics share after"], cells,
        align=["left", *["right"] * 5],
        note="Medians over rounds that alternate which tree goes first; each round makes "
             "every id afresh in a new process per tree.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, metavar="REV",
                        help="the git revision to compare against")
    parser.add_argument("--ids", nargs="+", metavar="ID", default=list(DEFAULT_IDS))
    parser.add_argument("--rounds", type=int, default=5, help="rounds; medians are kept (5)")
    parser.add_argument("--steps", type=int, default=300, help="env steps per round (300)")
    parser.add_argument("--warmup", type=int, default=100, help="untimed steps first (100)")
    add_seed_argument(parser, help_text="reset seed (0)")
    add_page_argument(parser, "docs/results/single-env-before-after")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.rounds < 1 or args.steps < 1 or args.warmup < 0:
        print("--rounds and --steps must be >= 1, --warmup >= 0", file=sys.stderr)
        return 2
    command = script_command("benchmarks/performance/single_env_before_after.py", argv)
    machine = describe_machine()
    announce(command, machine)
    revision = subprocess.run(["git", "rev-parse", "--short", args.before], cwd=ROOT,
                              check=True, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="rehabbot-before-") as scratch:
        before = Path(scratch) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(before),
                        revision], cwd=ROOT, check=True)
        try:
            results = compare(before, args.ids, args.rounds, args.steps, args.warmup,
                              args.seed)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT,
                           check=False)
    table = results_table(results, revision)
    settings: dict[str, Any] = {"before": revision, "rounds": args.rounds,
                                "steps": args.steps, "warmup": args.warmup}
    document = make_document(
        title="The single env before and after a change",
        intro=("Each id's single env (`gym.make(id)`, zero actions) timed on two trees in "
               "one run: the revision named below and this tree, in alternating rounds."),
        command=command, generated_by="benchmarks/performance/single_env_before_after.py",
        machine=machine, seeds={"reset_seed": args.seed}, settings=settings, tables=[table],
        data={"rounds": results})
    from benchmarks.common.documents import table_markdown

    print(table_markdown(table))
    if args.page is not None:
        write_page(document, args.page)
        print(f"wrote {args.page}.json and {args.page}.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
