"""``rehabbot sweep CONFIG.yaml``: read and check a sweep file, run its trials on Ray Tune
(:mod:`rehabbot.rl.sweep`), print a line per finished trial and a table at the end."""

from __future__ import annotations

import argparse
import shlex
import signal
import sys

from rehabbot.cli import limits
from rehabbot.cli.errors import EXIT_FAILURE, EXIT_OK, cli_command

SWEEP_EPILOG = """\
examples:
  rehabbot sweep sweeps/example.yaml                  # a local Ray with one CPU per trial
  rehabbot sweep sweeps/results-v2/sac-knee.yaml --cpus 16  # runs of the -v2 results page
  rehabbot sweep sweeps/example.yaml --dry-run        # what would run, what is done
  rehabbot sweep sweeps/example.yaml --address ray://head:10001   # an existing cluster
  rehabbot sweep sweeps/rsl-ppo-reach-v2.yaml --cpus 2   # rsl_rl PPO on the batched env

The file lists env ids, algorithms, seeds and optional hyperparameter values to cross
(docs/sweeps.md). Every trial is an ordinary run folder of `rehabbot train`:
OUT/<env>/<algo>/seed<k>, or OUT/<variant>/<env>/<algo>/seed<k> for a grid variant; OUT/sweep.json
lists every trial and its status, OUT/_ray holds Ray Tune's own files. With `backend:
rsl_rl` a trial is a run of `rehabbot train --algo ppo --backend rsl_rl` (n_envs: its worlds;
resources_per_trial: {cpu: 2, gpu: 1} on a GPU machine). Running the same command again
skips finished trials and continues interrupted ones from their newest
checkpoint (--resume does the same, and insists that OUT holds a sweep). `rehabbot plot OUT`
and benchmarks/results/results_table.py OUT read the sweep's runs.

Needs pip install "rehabbot[train,sweep]" (--dry-run: "rehabbot[train]").

exit codes: 0 every trial finished, 1 a trial failed, Ray failed or an extra is missing, 2 bad
usage (unknown key, env id or algorithm in the file), 130 interrupted (run the command again to
resume)."""


def add_sweep_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` subcommand (``func=cmd_sweep``) to ``commands``."""
    parser = commands.add_parser(
        "sweep",
        help="run a grid of envs x algorithms x seeds (x hyperparameters) on Ray Tune",
        description="Run a sweep of training runs on Ray Tune: every combination of the "
                    "file's env ids, algorithms, seeds and hyperparameter values, one "
                    "`rehabbot train` run folder each. Resumable.",
        epilog=SWEEP_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("config", metavar="CONFIG.yaml", help="the sweep file")
    parser.add_argument("--out", metavar="DIR",
                        help="root of the sweep's run folders (default: the file's `out`); "
                             "its parent folder must exist")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--cpus", type=limits.cpus, metavar="N",
                       help="CPUs of the local Ray started for the sweep (default: all, "
                            f"os.cpu_count(); at most {limits.MAX_CPUS})")
    where.add_argument("--address", metavar="ADDR",
                       help="join an existing Ray cluster instead (e.g. 'auto', "
                            "'ray://head:10001'); rehabbot must be installed on its nodes "
                            "and OUT shared with them")
    parser.add_argument("--resume", action="store_true",
                        help="continue the sweep in OUT (the default behaviour; this flag "
                             "also fails if OUT holds no sweep)")
    parser.add_argument("--dry-run", action="store_true",
                        help="check the file and list what would run; start nothing")
    parser.set_defaults(func=cmd_sweep)


@cli_command
def cmd_sweep(args: argparse.Namespace) -> int:
    """Run ``rehabbot sweep``: 0 when every trial finished, 1 if one failed, 130 when
    interrupted."""
    from rehabbot.cli.needs import NOTHING, SWEEP_MODULES, TRAIN_MODULES, require
    from rehabbot.common.files import check_parent_exists

    require("rehabbot sweep" + (" --dry-run" if args.dry_run else ""), TRAIN_MODULES,
            NOTHING if args.dry_run else SWEEP_MODULES)
    if args.out is not None:
        check_parent_exists(args.out)
    from rehabbot.rl.sweep import format_table, run_sweep
    from rehabbot.rl.sweep_config import load_sweep_config

    config = load_sweep_config(args.config)
    if args.out is not None:
        config = config.with_out(args.out)
    result = run_sweep(config, cpus=args.cpus, address=args.address, resume=args.resume,
                       dry_run=args.dry_run, command=["rehabbot", *sys.argv[1:]],
                       announce=lambda text: print(text, flush=True))
    if args.dry_run:
        return EXIT_OK
    print()
    print(format_table(result.records), flush=True)
    print(f"\nsweep.json: {result.out / 'sweep.json'}", flush=True)
    if result.interrupted:
        again = shlex.join(["rehabbot", "sweep", str(args.config),
                            *(["--out", str(args.out)] if args.out is not None else [])])
        print(f"interrupted; finished runs are kept, the others continue from their newest "
              f"checkpoint with: {again}", flush=True)
        return 128 + signal.SIGINT
    if result.failed:
        print(f"{len(result.failed)} of {len(result.records)} trials failed", file=sys.stderr,
              flush=True)
        return EXIT_FAILURE
    return EXIT_OK
