"""``rehabbot list``: the registered env ids with their limb, side, task, the extra an id needs
beyond the core install, and a description, read from the registry
(:data:`rehabbot.envs.registration.ENV_SPECS`): nothing is built, so it takes a moment on any
install. ``--spaces`` builds every id whose extra is installed and adds its action and
observation spaces (the real ones; seconds per id)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from rehabbot.cli.errors import EXIT_OK

HEADER = ("id", "limb", "side", "task", "needs", "description")
NEEDS = HEADER.index("needs")  # the column: "[EXTRA]", or "-" on the core install
SPACES_HEADER = ("action", "observation")


def extra_installed(extra: str) -> bool:
    """Whether every module :data:`~rehabbot.common.extras.OPTIONAL_MODULES` maps to
    ``extra`` is installed (found without importing it)."""
    from rehabbot.common.extras import OPTIONAL_MODULES, is_installed

    modules = [module for module, (_dist, owner) in OPTIONAL_MODULES.items() if owner == extra]
    return all(is_installed(module) for module in modules)


def registry_rows() -> list[tuple[str, ...]]:
    """One row per registered id: id, limb, side (``both`` for the bilateral ids), task,
    ``[EXTRA]`` or ``-``, description."""
    from rehabbot.envs.registration import ENV_SPECS, required_extra

    rows = []
    for env_id, (kwargs, description) in ENV_SPECS.items():
        extra = required_extra(env_id)
        rows.append((env_id, kwargs["limb"], kwargs.get("side", "both"), kwargs["task_type"],
                     f"[{extra}]" if extra else "-", description))
    return rows


def box_text(space: Any, bounds: bool) -> str:
    """``Box(low, high, shape)`` when ``bounds`` and every entry has the same bounds, else
    ``Box(shape)``."""
    low, high = space.low.ravel(), space.high.ravel()
    if bounds and low.size and (low == low[0]).all() and (high == high[0]).all():
        return f"Box({float(low[0]):.5g}, {float(high[0]):.5g}, {space.shape})"
    return f"Box({space.shape})"


def built_spaces(env_id: str) -> tuple[str, str]:
    """The action and observation spaces of ``env_id``, built once."""
    import gymnasium as gym

    env = gym.make(env_id)
    try:
        return (box_text(env.action_space, bounds=True),
                box_text(env.observation_space, bounds=False))
    finally:
        env.close()


def with_spaces(rows: Sequence[tuple[str, ...]],
                progress: Callable[[int, int], None]) -> list[tuple[str, ...]]:
    """``rows`` with the action and observation spaces of each id inserted before its
    description; an id whose extra is not installed is not built (``needs [EXTRA]``)."""
    installed: dict[str, bool] = {}
    result = []
    for row in rows:
        needs = row[NEEDS]
        extra = needs.strip("[]") if needs != "-" else None
        if extra is not None and not installed.setdefault(extra, extra_installed(extra)):
            spaces = (f"needs {needs}", f"needs {needs}")
        else:
            spaces = built_spaces(row[0])
        result.append((*row[:-1], *spaces, row[-1]))
        progress(len(result), len(rows))
    return result


def format_rows(rows: Sequence[tuple[str, ...]]) -> list[str]:
    """Aligned columns; the last one (the description) is not padded."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]) - 1)]
    lines = []
    for row in rows:
        cells = [cell.ljust(width) for cell, width in zip(row[:-1], widths, strict=True)]
        lines.append("  ".join([*cells, row[-1]]))
    return lines


def extras_notes(rows: Sequence[tuple[str, ...]]) -> list[str]:
    """One line per extra that some ids need: how many, the install command, whether it is
    installed here."""
    from rehabbot.common.extras import extras_hint

    counts: dict[str, int] = {}
    for row in rows:
        if row[NEEDS] != "-":
            extra = row[NEEDS].strip("[]")
            counts[extra] = counts.get(extra, 0) + 1
    return [f"[{extra}]: {count} id{'s' if count > 1 else ''} need {extras_hint([extra])} "
            f"({'installed' if extra_installed(extra) else 'not installed here'})"
            for extra, count in counts.items()]


def cmd_list(args: argparse.Namespace) -> int:
    """Print the registered ids (with ``--spaces``, built, with their spaces)."""
    rows = registry_rows()
    notes = extras_notes(rows)
    if args.spaces:
        from rehabbot.cli.progress import ProgressLine

        rows = with_spaces(rows, ProgressLine("rehabbot list --spaces", unit="id"))
        header = (*HEADER[:-1], *SPACES_HEADER, HEADER[-1])
    else:
        header = HEADER
    for line in format_rows([header, *rows]):
        print(line)
    if notes:
        print()
        for note in notes:
            print(note)
    sys.stdout.flush()
    return EXIT_OK


def add_list_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``list`` to the ``rehabbot`` subcommands."""
    listing = commands.add_parser(
        "list", help="list the registered env ids (read from the registry; nothing is built)",
        description="The registered env ids with their limb, side, task, the extra an id "
                    "needs beyond the core install ([myo]: pip install \"rehabbot[myo]\") and "
                    "a description, read from the registry: nothing is built. --spaces "
                    "builds every id whose extra is installed (a few seconds each, with a "
                    "progress line on stderr) and shows its action and observation spaces.")
    listing.add_argument("--spaces", action="store_true",
                         help="build each id and show its action and observation spaces")
    listing.set_defaults(func=cmd_list)
