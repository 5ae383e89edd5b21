"""``rehabbot zoo list``, ``rehabbot zoo show ENV/ALGO``, ``rehabbot zoo export RUN_DIR`` and
``rehabbot zoo fetch ENV/ALGO --from SOURCE``: the trained agents shipped in the package
(:mod:`rehabbot.rl.zoo`), what each was trained with and how well it did, how a trained model
becomes one, and how an agent's full model (not shipped) is fetched for fine-tuning."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rehabbot.cli.errors import EXIT_OK, bounded_int, cli_command, json_object

MAX_EPISODES = 100_000
MAX_SEED = 2**32 - 1

ZOO_EPILOG = """\
examples:
  rehabbot zoo list
  rehabbot zoo show rehab-knee-v2/sac
  rehabbot evaluate zoo:rehab-knee-v2/sac expert --episodes 20   # the env comes from the agent
  rehabbot zoo export runs/rehab-knee-v2/sac/seed0 --full   # env, algo: the run's manifest
  rehabbot zoo fetch rehab-knee-v2/sac --from .   # its full model, from this clone's history

Each agent is a light NumPy actor (rehabbot/zoo/<env>/<algo>.npz: its layers, verified by a
SHA-256 of its weights); rehabbot.zoo.load(ENV, ALGO) returns it, with SB3's predict. An agent
trained with another robot than the UR5e is named after both (rehab-hip-v2/sac-fr3, trained
with --env-kwargs '{"robot": "fr3"}'); it runs with the kwargs it was trained with. Its whole
model (critics included, for fine-tuning with rehabbot.zoo.load_full_model) is not in the
package: `rehabbot zoo fetch` puts a copy verified by its SHA-256 in the user's cache."""


def _share(figures: dict | None, key: str) -> str:
    """``"47/50 (94 %)"`` from ``figures[key] = [finished, of]``, ``"-"`` without it."""
    pair = (figures or {}).get(key)
    if not pair or not pair[1]:
        return "-"
    return f"{pair[0]}/{pair[1]} ({100 * pair[0] / pair[1]:.0f} %)"


def _row(env_id: str, algo: str, held_out: dict[str, dict]) -> str:
    from rehabbot.envs.registration import env_short_name
    from rehabbot.rl import zoo

    meta = zoo.load(env_id, algo).metadata
    name = f"{env_short_name(env_id)}/{algo}"
    figures = held_out.get(name)
    if figures is not None and figures.get("weights_sha256") != meta.get("weights_sha256"):
        figures = None  # measured on other weights: not this agent's figure
    training = "envelope" if str(meta.get("training_patients", "")).startswith("envelope") \
        else "one"
    return (f"{name:<28} {meta.get('backend', '-'):<4} "
            f"{meta.get('training_steps', '-')!s:>7} {meta.get('seed', '-')!s:>4} "
            f"{training:<8} {_share(figures, 'bodies'):>15} {_share(figures, 'conditions'):>15}")


def _agent(text: str) -> tuple[str, str]:
    """``ENV/ALGO`` (or ``zoo:ENV/ALGO``) as ``(env, algo)``."""
    from rehabbot.common.errors import UsageError

    name = text.removeprefix("zoo:")
    if name.count("/") < 1:
        raise UsageError(f"{text!r} is not ENV/ALGO (for example rehab-knee-v2/sac; "
                         "`rehabbot zoo list` lists them)")
    env_id, algo = name.rsplit("/", 1)
    return env_id, algo


@cli_command
def cmd_zoo_list(args: argparse.Namespace) -> int:
    """Print one line per shipped agent."""
    from rehabbot.rl import zoo

    agents = zoo.available()
    if not agents:
        print(f"the zoo ({zoo.zoo_dir()}) holds no agents")
        return EXIT_OK
    held_out = zoo.held_out_figures()
    print(f"{'agent':<28} {'lib':<4} {'steps':>7} {'seed':>4} {'patients':<8} "
          f"{'held-out bodies':>15} {'held-out conds':>15}")
    for env_id, algo in agents:
        print(_row(env_id, algo, held_out))
    print("patients: what training drew (one: the id's 1.75 m, 75 kg man; envelope: the adult "
          "envelope's training cohort). held-out: test episodes finished of those the scripted "
          "expert finished, on the envelope's test bodies and test conditions "
          "(docs/results/heldout-envelope.md); -: not measured for these weights.")
    return EXIT_OK


@cli_command
def cmd_zoo_show(args: argparse.Namespace) -> int:
    """Print one agent's metadata (JSON): env, settings, training command, evaluation."""
    from rehabbot.rl import zoo

    env_id, algo = _agent(args.agent)
    print(json.dumps(zoo.load(env_id, algo).metadata, indent=2, sort_keys=True, default=str))
    return EXIT_OK


@cli_command
def cmd_zoo_export(args: argparse.Namespace) -> int:
    """Export a model's deterministic actor to a zoo file, then measure its success rate."""
    from rehabbot.common.errors import UsageError
    from rehabbot.common.files import check_parent_exists
    from rehabbot.rl import zoo
    from rehabbot.rl.zoo_export import export_policy

    if args.out is not None:
        check_parent_exists(args.out)
        if args.out.suffix != zoo.SUFFIX:
            raise UsageError(f"--out {str(args.out)!r}: a zoo file ends in {zoo.SUFFIX}")
    meta = export_policy(args.source, args.env, args.algo, args.out, metadata=args.note,
                         episodes=args.episodes, seed=args.seed, full=args.full)
    out = args.out or zoo.zoo_path(meta["env_id"],
                                   zoo.agent_name(meta["algo"], meta.get("env_kwargs"),
                                                  meta.get("backend")))
    print(f"wrote {out}: {meta['env_id']} {meta['algo']} ({meta['backend']}), success rate "
          f"{meta.get('success_rate')} on {args.episodes} episodes, sha256 "
          f"{meta['weights_sha256'][:12]}")
    return EXIT_OK


@cli_command
def cmd_zoo_fetch(args: argparse.Namespace) -> int:
    """Put a verified copy of each agent's full model in the cache, from ``--from``."""
    from rehabbot.common.errors import UsageError
    from rehabbot.rl import zoo_full

    if bool(args.agents) == bool(args.all):
        raise UsageError("name the agents (ENV/ALGO ...) or give --all, not both")
    models = (zoo_full.full_models() if args.all
              else [zoo_full.full_model(*_agent(name)) for name in args.agents])
    if not models:
        raise UsageError("the zoo has no agent with a full model")
    for model in models:
        fetched = zoo_full.fetch_full_model(model.env_id, model.agent, args.source)
        if fetched.origin is None:
            print(f"{model.name}: already here, verified: {fetched.path}")
        else:
            print(f"{model.name}: verified (sha256 {model.sha256[:12]}) and saved to "
                  f"{fetched.path}, from {fetched.origin}")
    return EXIT_OK


def add_zoo_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``zoo list``, ``zoo show``, ``zoo export`` and ``zoo fetch`` to the ``rehabbot``
    subcommands."""
    from rehabbot.rl.zoo import DEFAULT_EPISODES, DEFAULT_SEED, ZOO_DIR_ENV
    from rehabbot.rl.zoo_full import CACHE_DIR_ENV, HISTORY_COMMIT

    parser = commands.add_parser("zoo", help="the trained agents shipped with rehabbot",
                                 description=__doc__.split("\n\n")[0], epilog=ZOO_EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="zoo_command", required=True,
                                metavar="{list,show,export,fetch}")
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
                        help=f"output file, in an existing folder (default: the package's zoo "
                             f"folder, or ${ZOO_DIR_ENV}, /<env>/<algo>.npz)")
    export.add_argument("--episodes", type=bounded_int(0, MAX_EPISODES),
                        default=DEFAULT_EPISODES, metavar="N",
                        help=f"episodes to measure the success rate on (default "
                             f"{DEFAULT_EPISODES}; 0: none; at most {MAX_EPISODES:,})")
    export.add_argument("--seed", type=bounded_int(0, MAX_SEED), default=DEFAULT_SEED,
                        metavar="S",
                        help=f"episode k is reset with seed S + k (default {DEFAULT_SEED})")
    export.add_argument("--full", action="store_true",
                        help="also keep the whole model (<algo>.zip beside the .npz, for "
                             "load_full_model and fine-tuning)")
    export.add_argument("--note", type=json_object, metavar="JSON",
                        help="metadata to add, as a JSON object (e.g. how the seed was "
                             "chosen); the keys the exporter writes (env_id, algo, ...) are "
                             "refused")
    export.set_defaults(func=cmd_zoo_export)
    fetch = sub.add_parser(
        "fetch", help="an agent's full model (for fine-tuning), verified, into the cache",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Put a copy of an agent's whole trained model (the SB3/SBX zip, critics "
                    "included, which rehabbot.zoo.load_full_model loads for fine-tuning) in "
                    f"the user's cache folder (${CACHE_DIR_ENV} overrides it). The copy is "
                    "refused unless its SHA-256 is the one the agent's metadata pins, and "
                    "appears only when verified.",
        epilog="SOURCE is one of:\n"
               "  a git clone of the rehabbot repository: its history holds every shipped\n"
               f"    agent's full model (commit {HISTORY_COMMIT}), offline\n"
               "  a folder holding <env>/<agent>.zip (or rehabbot/zoo/<env>/<agent>.zip, or\n"
               "    model.zip: a run folder)\n"
               "  a .zip file\n"
               "  an http(s) URL of the .zip, or of a folder laid out as <env>/<agent>.zip\n"
               "examples:\n"
               "  rehabbot zoo fetch rehab-knee-v2/sac --from ~/src/rehabbot\n"
               "  rehabbot zoo fetch --all --from .")
    fetch.add_argument("agents", nargs="*", metavar="ENV/ALGO",
                       help="for example rehab-knee-v2/sac")
    fetch.add_argument("--all", action="store_true",
                       help="every agent of the zoo that has a full model")
    fetch.add_argument("--from", dest="source", required=True, metavar="SOURCE",
                       help="where to copy it from (below)")
    fetch.set_defaults(func=cmd_zoo_fetch)
