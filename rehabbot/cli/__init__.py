"""The ``rehabbot`` command line: a thin layer over the libraries. Each subcommand parses its
arguments, calls a library function and maps its exceptions to exit codes
(:mod:`rehabbot.cli.errors`); nothing below this package imports it.

Examples::

    rehabbot list                                  # the registered env ids (the registry)
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
import os
import select
import signal
import sys
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

EXIT_SIGPIPE = 128 + signal.SIGPIPE  # the reader of stdout went away, as a shell reports it

__all__ = ["EXIT_FAILURE", "EXIT_OK", "EXIT_SIGINT", "EXIT_SIGPIPE", "EXIT_USAGE",
           "TYPICAL_SESSION", "CliError", "build_parser", "has_display", "main",
           "use_headless_gl_by_default"]


# The session of `rehabbot --help`, with the extra of `pip install "rehabbot[EXTRA]"` each
# command needs (rehabbot.cli.needs; tests/test_cli_session.py runs it on a core install).
TYPICAL_SESSION = """\
a typical session, with the extra each command needs:
  rehabbot list                                           # the core install
  rehabbot train rehab-reach-v2 --algo sac --seeds 0 1 2  # [train]
  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip expert random  # [train]
  rehabbot plot runs/rehab-reach-v2                       # [plot]
  rehabbot render runs/rehab-reach-v2/sac/seed0/model.zip --out sac.mp4  # [video], [train]

pip install "rehabbot[train,plot,video]" brings them all. With "rehabbot[jax]" too, train
uses SBX (JAX) instead of Stable-Baselines3 (PyTorch), and its models need [jax] to load.
A command whose extra is missing stops at once, naming the pip install that brings it.

`rehabbot COMMAND --help` describes each command. Exit codes: 0 success, 1 failure (a
missing extra included), 2 bad usage, 130 interrupted by Ctrl-C (training: resumable; 143
for SIGTERM). Every failure is one line on stderr."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``rehabbot`` command."""
    from rehabbot.cli.calibrate import add_calibrate_parser
    from rehabbot.cli.demo import add_demo_parser
    from rehabbot.cli.deploy import add_deploy_parser
    from rehabbot.cli.evaluate import add_evaluate_parser
    from rehabbot.cli.export import add_export_parser
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
        epilog=TYPICAL_SESSION,
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
    add_export_parser(commands)
    add_calibrate_parser(commands)
    add_deploy_parser(commands)
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
    except BrokenPipeError as err:
        if stdout_is_closed():  # `rehabbot list | head`: the reader has what it wanted
            return EXIT_SIGPIPE
        return report(err)
    except (Exception, KeyboardInterrupt) as err:  # every failure: one line
        return report(err)


def stdout_is_closed() -> bool:
    """Whether the reader of stdout has gone away (a pipe closed by ``head``: polling it
    reports an error); if so, stdout is pointed at the null device so that nothing more
    fails on exit."""
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        events = poller.poll(0)
    except (AttributeError, OSError, ValueError):  # no file (captured), or no poll()
        return False
    if not any(mask & (select.POLLERR | select.POLLHUP) for _fd, mask in events):
        return False
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)
    return True
