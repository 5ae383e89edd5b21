"""The command-line bootstrap every benchmark script shares: the ``--seed`` and ``--page``
options, the exact command a run records, and the line that announces it.

A script run by its path (``python benchmarks/results/x.py``) puts the repository root on
``sys.path`` before it imports this module (two lines of its own: nothing under
``benchmarks`` is importable before them)::

    if not __package__:  # run as a script: make `benchmarks` importable
        sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

Every script then builds its parser with :func:`add_seed_argument` and
:func:`add_page_argument`, records :func:`script_command` in its results document and prints
it with :func:`announce` before the work starts.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from benchmarks.common.documents import command_line

PAGE_HELP = "write the results document STEM.json and its page STEM.md"


def add_seed_argument(parser: argparse.ArgumentParser, default: int | None = 0,
                      help_text: str | None = None) -> None:
    """``--seed`` (an int, ``default``): the seed a script's figures come from."""
    parser.add_argument("--seed", type=int, default=default, help=help_text)


def add_page_argument(parser: argparse.ArgumentParser, example: str | None = None) -> None:
    """``--page STEM``: write the results document ``STEM.json`` and its Markdown page
    ``STEM.md`` (:func:`benchmarks.common.documents.write_page`); ``example``, the page the
    published figures live in, is named in the help."""
    parser.add_argument("--page", type=Path, metavar="STEM",
                        help=PAGE_HELP if example is None else f"{PAGE_HELP} ({example})")


def script_command(script: str | Path, argv: Sequence[str] | None) -> str:
    """The command, run from the repository root, that repeats this run of ``script``
    (``argv``: the arguments given to ``main``; None for the process's own)."""
    return command_line(script, argv if argv is not None else sys.argv[1:])


def announce(command: str, machine: str | None = None) -> None:
    """Print the run's command first (flushed: a long run shows it at once), and the machine
    it times on, followed by a blank line, when given."""
    if machine is None:
        print(f"command: {command}", flush=True)
    else:
        print(f"command: {command}\nmachine: {machine}\n", flush=True)
