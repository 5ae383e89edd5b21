"""The ``rehabbot`` command line: a thin layer over the libraries. Each subcommand parses its
arguments, calls a library function and maps its exceptions to exit codes
(:mod:`rehabbot.cli.errors`); nothing below this package imports it.

Examples::

    rehabbot list                                  # the registered env ids
    rehabbot train rehab-reach-v2 --algo sac --seeds 0 1 2  # the shipped settings
    rehabbot sweep sweeps/example.yaml             # a grid of runs on Ray Tune, resumable
    rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip expert random
    rehabbot plot runs/rehab-reach-v2               # Figs. 3-6 of the paper for your runs
    rehabbot render expert --env rehab-reach-v2 --out expert.mp4
    rehabbot demo                                  # train, evaluate, plot, render (make demo)
    rehabbot zoo list                              # the trained agents shipped with rehabbot
    rehabbot scenes
    rehabbot view upper_right --seconds 5
    rehabbot snapshot upper_right --out front.png --width 1280 --height 720

Heavy imports (Stable-Baselines3, matplotlib) happen inside the command functions so that
``rehabbot --help`` stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from rehabbot.cli.display import has_display, use_headless_gl_by_default
from rehabbot.cli.errors import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_SIGINT,
    EXIT_USAGE,
    CliError,
    quiet_third_parties,
    report,
)

__all__ = ["EXIT_FAILURE", "EXIT_OK", "EXIT_SIGINT", "EXIT_USAGE", "CliError", "build_parser",
           "has_display", "main", "use_headless_gl_by_default"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``rehabbot`` command."""
    from rehabbot.cli.demo import add_demo_parser
    from rehabbot.cli.evaluate import add_evaluate_parser
    from rehabbot.cli.listing import add_list_parser
    from rehabbot.cli.plot import add_plot_parser
    from rehabbot.cli.render import add_render_parser
    from rehabbot.cli.scenes import add_scene_parsers
    from rehabbot.cli.sweep import add_sweep_parser
    from rehabbot.cli.train import add_train_parser
    from rehabbot.cli.zoo import add_zoo_parser
    from rehabbot.common.version import VERSION

    parser = argparse.ArgumentParser(
        prog="rehabbot",
        description="RehabBot: a UR5e strapped to a humanoid patient, simulated in MuJoCo. "
                    "Train, evaluate, plot and render RL agents on its therapy exercises.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="a typical session:\n"
               "  rehabbot list\n"
               "  rehabbot train rehab-reach-v2 --algo sac --seeds 0 1 2  # the shipped settings\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip expert random\n"
               "  rehabbot plot runs/rehab-reach-v2\n"
               "  rehabbot render runs/rehab-reach-v2/sac/seed0/model.zip --out sac.mp4\n\n"
               "`rehabbot COMMAND --help` describes each command. Exit codes: 0 success, "
               "1 failure, 2 bad usage, 130 interrupted by Ctrl-C (training: resumable; "
               "143 for SIGTERM). Every failure is one line on stderr.",
    )
    parser.add_argument("--version", action="version", version=f"rehabbot {VERSION}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_list_parser(commands)
    add_train_parser(commands)
    add_sweep_parser(commands)
    add_evaluate_parser(commands)
    add_plot_parser(commands)
    add_render_parser(commands)
    add_demo_parser(commands)
    add_zoo_parser(commands)
    add_scene_parsers(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rehabbot`` command; returns the process exit code.

    Whatever goes wrong is one line on stderr and an exit code (:func:`.errors.report`):
    Ctrl-C gives 130, a library's error its code, anything unforeseen 1; never a traceback.
    """
    use_headless_gl_by_default()  # before anything imports mujoco
    try:
        args = build_parser().parse_args(argv)
        with quiet_third_parties():
            return int(args.func(args))
    except (Exception, KeyboardInterrupt) as err:  # every failure: one line
        return report(err)
