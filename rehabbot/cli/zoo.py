"""``rehabbot zoo list``, ``rehabbot zoo show ENV/ALGO`` and ``rehabbot zoo export RUN_DIR``:
the trained agents shipped in the package (:mod:`rehabbot.rl.zoo`), what each was trained with
and how well it did, and how a trained model becomes one."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rehabbot.cli.errors import EXIT_OK, cli_command, json_object

ZOO_EPILOG = """\
examples:
  rehabbot zoo list
  rehabbot zoo show rehab-knee-v2/sac
  rehabbot evaluate zoo:rehab-knee-v2/sac expert --episodes 20   # the env comes from the agent
  rehabbot zoo export runs/rehab-knee-v2/sac/seed0 --full   # env, algo: the run's manifest

Each agent is a light NumPy actor (rehabbot/zoo/<env>/<algo>.npz: its layers, verified by a
SHA-256 of its weights); rehabbot.zoo.load(ENV, ALGO) returns it, with SB3's predict. An agent
trained with another robot than the UR5e is named after both (rehab-hip-v2/sac-fr3, trained
with --env-kwargs '{"robot": "fr3"}'); it runs with the kwargs it was trained with."""


def _row(env_id: str, algo: str) -> str:
    from rehabbot.envs.registration import env_short_name
    from rehabbot.rl import zoo

    meta = zoo.load(env_id, algo).metadata
    evaluation = meta.get("evaluation") or {}
    success = meta.get("success_rate")
    share = "-" if success is None else f"{100 * float(success):.0f} %"
    policy = str(meta.get("policy_class", "-")).rsplit(".", 1)[-1]
    return (f"{env_short_name(env_id) + '/' + algo:<32} {meta.get('backend', '-'):<4} "
            f"{policy:<36} {meta.get('training_steps', '-')!s:>7} "
            f"{meta.get('seed', '-')!s:>4} {share:>6} of {evaluation.get('episodes', '-')}")


@cli_command
def cmd_zoo_list(args: argparse.Namespace) -> int:
    """Print one line per shipped agent."""
    from rehabbot.rl import zoo

    agents = zoo.available()
    if not agents:
        print(f"the zoo ({zoo.zoo_dir()}) holds no agents")
        return EXIT_OK
    print(f"{'agent':<32} {'lib':<4} {'policy':<36} {'steps':>7} {'seed':>4} success")
    for env_id, algo in agents:
        print(_row(env_id, algo))
    return EXIT_OK


@cli_command
def cmd_zoo_show(args: argparse.Namespace) -> int:
    """Print one agent's metadata (JSON): env, settings, training command, evaluation."""
    from rehabbot.common.errors import UsageError
    from rehabbot.rl import zoo

    name = args.agent.removeprefix("zoo:")
    if name.count("/") < 1:
        raise UsageError(f"{args.agent!r} is not ENV/ALGO (for example rehab-knee-v2/sac; "
                         "`rehabbot zoo list` lists them)")
    env_id, algo = name.rsplit("/", 1)
    print(json.dumps(zoo.load(env_id, algo).metadata, indent=2, sort_keys=True, default=str))
    return EXIT_OK


@cli_command
def cmd_zoo_export(args: argparse.Namespace) -> int:
    """Export a model's deterministic actor to a zoo file, then measure its success rate."""
    from rehabbot.rl import zoo
    from rehabbot.rl.zoo_export import export_policy

    meta = export_policy(args.source, args.env, args.algo, args.out, metadata=args.note,
                         episodes=args.episodes, seed=args.seed, full=args.full)
    out = args.out or zoo.zoo_path(meta["env_id"],
                                   zoo.agent_name(meta["algo"], meta.get("env_kwargs"),
                                                  meta.get("backend")))
    print(f"wrote {out}: {meta['env_id']} {meta['algo']} ({meta['backend']}), success rate "
          f"{meta.get('success_rate')} on {args.episodes} episodes, sha256 "
          f"{meta['weights_sha256'][:12]}")
    return EXIT_OK


def add_zoo_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``zoo list``, ``zoo show`` and ``zoo export`` to the ``rehabbot`` subcommands."""
    from rehabbot.rl.zoo import DEFAULT_EPISODES, DEFAULT_SEED, ZOO_DIR_ENV

    parser = commands.add_parser("zoo", help="the trained agents shipped with rehabbot",
                                 description=__doc__.split("\n\n")[0], epilog=ZOO_EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="zoo_command", required=True,
                                metavar="{list,show,export}")
    sub.add_parser("list", help="one line per agent").set_defaults(func=cmd_zoo_list)
    show = sub.add_parser("show", help="one agent's metadata as JSON")
    show.add_argument("agent", metavar="ENV/ALGO", help="for example rehab-knee-v2/sac")
    show.set_defaults(func=cmd_zoo_show)
    export = sub.add_parser(
        "export", help="a trained model's deterministic actor as a zoo file",
        description="Export a model (a `rehabbot train` run folder or a model zip, SB3 or "
                    "SBX) to <zoo>/<env>/<algo>.npz, then measure its success rate.")
    export.add_argument("source", type=Path, metavar="RUN_DIR|MODEL.zip")
    export.add_argument("--env", metavar="ID", help="env id (default: the run's manifest)")
    export.add_argument("--algo", help="sac, td3, ppo, tqc or crossq (default: the manifest)")
    export.add_argument("--out", type=Path, metavar="FILE.npz",
                        help=f"output file (default: the package's zoo folder, or "
                             f"${ZOO_DIR_ENV}, /<env>/<algo>.npz)")
    export.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, metavar="N",
                        help=f"episodes to measure the success rate on (default "
                             f"{DEFAULT_EPISODES}; 0: none)")
    export.add_argument("--seed", type=int, default=DEFAULT_SEED, metavar="S",
                        help=f"episode k is reset with seed S + k (default {DEFAULT_SEED})")
    export.add_argument("--full", action="store_true",
                        help="also keep the whole model (<algo>.zip beside the .npz, for "
                             "load_full_model and fine-tuning)")
    export.add_argument("--note", type=json_object, metavar="JSON",
                        help="metadata to add, as a JSON object (e.g. how the seed was chosen)")
    export.set_defaults(func=cmd_zoo_export)
