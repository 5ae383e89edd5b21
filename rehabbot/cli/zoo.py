"""``rehabbot zoo list`` and ``rehabbot zoo show ENV/ALGO``: the trained agents shipped in the
package (:mod:`rehabbot.rl.zoo`), what each was trained with and how well it did."""

from __future__ import annotations

import argparse
import json

from rehabbot.cli.errors import EXIT_OK, cli_command

ZOO_EPILOG = """\
examples:
  rehabbot zoo list
  rehabbot zoo show rehab-knee-v2/sac
  rehabbot evaluate zoo:rehab-knee-v2/sac expert --episodes 20   # the env comes from the agent

Each agent is a light NumPy actor (rehabbot/zoo/<env>/<algo>.npz: its layers, verified by a
SHA-256 of its weights); rehabbot.zoo.load(ENV, ALGO) returns it, with SB3's predict."""


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


def add_zoo_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``zoo list`` and ``zoo show`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser("zoo", help="the trained agents shipped with rehabbot",
                                 description=__doc__.split("\n\n")[0], epilog=ZOO_EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="zoo_command", required=True, metavar="{list,show}")
    sub.add_parser("list", help="one line per agent").set_defaults(func=cmd_zoo_list)
    show = sub.add_parser("show", help="one agent's metadata as JSON")
    show.add_argument("agent", metavar="ENV/ALGO", help="for example rehab-knee-v2/sac")
    show.set_defaults(func=cmd_zoo_show)
