"""Two levels of ``--help`` for a command with many options: ``-h``/``--help`` shows the
essential options and a short epilog (a screen), ``--help-all`` every option, grouped, and the
full epilog. argparse has one level only; :func:`add_help_levels` hides the other options
while ``--help`` prints."""

from __future__ import annotations

import argparse
from collections.abc import Collection
from typing import Any

HELP_ALL = "--help-all"


class _BriefHelp(argparse.Action):
    """``-h``/``--help``: the essential options and the brief epilog, then exit 0."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 essentials: Collection[str] = (), brief_epilog: str = "",
                 help: str | None = None) -> None:
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help=help)
        self.essentials = set(essentials)
        self.brief_epilog = brief_epilog

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        hidden = [action for action in parser._actions
                  if action.dest not in self.essentials and action.help != argparse.SUPPRESS
                  and not isinstance(action, (_BriefHelp, _FullHelp))]
        saved = [(action, action.help) for action in hidden]
        epilog = parser.epilog
        try:
            for action in hidden:
                action.help = argparse.SUPPRESS
            parser.epilog = self.brief_epilog
            parser.print_help()
        finally:
            for action, text in saved:
                action.help = text
            parser.epilog = epilog
        parser.exit()


class _FullHelp(argparse.Action):
    """``--help-all``: every option and the full epilog, then exit 0."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 help: str | None = None) -> None:
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        parser.print_help()
        parser.exit()


def add_help_levels(parser: argparse.ArgumentParser, essentials: Collection[str],
                    brief_epilog: str) -> None:
    """Give ``parser`` (made with ``add_help=False``) ``-h``/``--help`` showing only the
    arguments whose ``dest`` is in ``essentials`` and ``brief_epilog``, and ``--help-all``
    showing everything with the parser's own epilog."""
    parser.add_argument("-h", "--help", action=_BriefHelp, essentials=essentials,
                        brief_epilog=brief_epilog,
                        help=f"show the essential options and exit ({HELP_ALL}: all of them)")
    parser.add_argument(HELP_ALL, action=_FullHelp,
                        help="show every option, grouped, with the details, and exit")
