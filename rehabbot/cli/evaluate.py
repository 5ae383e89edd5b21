"""``rehabbot evaluate MODEL|expert|aan|random ...``: every policy on the same episodes of one env,
a table of clinical figures, and per policy ``evaluation.json`` and ``trace.npz``
(:mod:`rehabbot.analysis.evaluation`). Every argument is checked, every model loaded and the
output folder probed before the first episode runs."""

from __future__ import annotations

import argparse
from pathlib import Path

from rehabbot.cli.errors import (
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    cli_command,
    env_kwargs_object,
    non_negative_int,
)

DEFAULT_EPISODES = 10


def add_evaluate_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``evaluate`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser(
        "evaluate", help="evaluate trained models, the scripted expert, the assist-as-needed "
             "controller or random actions",
        description="Clinical evaluation of policies on the same episodes of one env. Prints "
                    "a table and writes JSON.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip\n"
               "  rehabbot evaluate expert random --env rehab-reach-v2 --episodes 20\n"
               "  rehabbot evaluate zoo:rehab-reach-v1/ppo expert\n"
               "  rehabbot evaluate zoo:rehab-reach-v1/sac aan expert --env "
               "rehab-reach-spastic-v1\n"
               "  rehabbot evaluate expert --env rehab-reach-population-v1 --env-kwargs "
               "'{\"patients\": \"test\"}'\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip expert random "
               "--episodes 20\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip --env-kwargs "
               "'{\"weight_level\": 4, \"profile\": {\"height_m\": 1.6, \"mass_kg\": 55, "
               "\"sex\": \"female\"}}'\n\n"
               "The env is --env, or the one the models were trained on (from their run's "
               "manifest.json, or the zoo agent's file). Each policy's files go to "
               "OUT/<label>/evaluation.json and OUT/<label>/trace.npz; with several "
               "policies, OUT/comparison.md.")
    parser.add_argument("policies", nargs="+", metavar="MODEL|zoo:ENV/ALGO|expert|aan|random",
                        help="a model .zip saved by `rehabbot train` (or any SB3 PPO/SAC/TD3 "
                             "zip), an agent shipped in the zoo (zoo:rehab-reach-v1/ppo; "
                             "rehabbot zoo list), 'expert' (scripted expert), 'aan' "
                             "(assist-as-needed controller) or 'random'")
    parser.add_argument("--env", metavar="ENV",
                        help="env id, with or without 'rehabbot/' (default: the env the "
                             "models were trained on; required for expert, aan and random alone)")
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, metavar="N",
                        help=f"episodes per policy (default: {DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=non_negative_int, default=0, metavar="S",
                        help="episode k is reset with seed S + k (default: 0; S >= 0)")
    parser.add_argument("--stochastic", action="store_true",
                        help="sample the model's actions instead of using its mean")
    parser.add_argument("--env-kwargs", type=env_kwargs_object, default=None, metavar="JSON",
                        help="RehabEnv keyword arguments (override the training run's), e.g. "
                             "'{\"weight_level\": 4}'")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="output folder (default: <run>/evaluation for one model of a "
                             "training run, else runs/evaluation/<env>)")
    parser.set_defaults(func=cmd_evaluate)


@cli_command
def cmd_evaluate(args: argparse.Namespace) -> int:
    """Run ``rehabbot evaluate``."""
    from rehabbot.analysis import evaluation
    from rehabbot.common.files import check_writable_dir
    from rehabbot.rl.policies import env_for

    if args.episodes < 1:
        raise CliError(f"--episodes {args.episodes} must be >= 1", EXIT_USAGE)
    env_id, _kwargs = env_for(args.policies, args.env, args.env_kwargs)  # checks every spec
    out_dir = args.out or evaluation.default_out_dir(args.policies, env_id)
    check_writable_dir(out_dir)
    results = evaluation.evaluate_policies(args.policies, args.env, args.episodes, args.seed,
                                           args.env_kwargs, deterministic=not args.stochastic)
    reports = []
    for report, trace in results:
        json_path, trace_path = evaluation.save_report(
            report, trace, evaluation.label_dir(out_dir, report["policy"]["label"]))
        print(f"{report['policy']['label']}: wrote {json_path} and {trace_path}")
        reports.append(report)
    table = evaluation.format_table(reports)
    print(f"\n{reports[0]['env_id']}, {args.episodes} episodes per policy\n\n{table}")
    if len(reports) > 1:
        evaluation.write_comparison(out_dir, reports)
    return EXIT_OK
