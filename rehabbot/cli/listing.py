"""``rehabbot list``: the registered env ids with their limb, task and spaces."""

from __future__ import annotations

import argparse

from rehabbot.cli.errors import EXIT_OK


def cmd_list(args: argparse.Namespace) -> int:
    """Print the registered env ids with their limb, task, spaces and description (each env
    is built once, so the spaces shown are the real ones)."""
    import gymnasium as gym

    from rehabbot.envs.registration import ENV_SPECS

    rows = [("id", "limb", "side", "task", "action", "observation", "description")]
    for env_id, (kwargs, description) in ENV_SPECS.items():
        env = gym.make(env_id)
        act, obs = env.action_space, env.observation_space
        env.close()
        # The bilateral id moves both sides.
        rows.append((env_id, kwargs["limb"], kwargs.get("side", "both"), kwargs["task_type"],
                     f"Box({float(act.low[0]):.5f}, {float(act.high[0]):.5f}, {act.shape})",
                     f"Box({obs.shape})", description))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]) - 1)]
    for row in rows:
        cells = [cell.ljust(width) for cell, width in zip(row[:-1], widths, strict=True)]
        print("  ".join([*cells, row[-1]]))
    return EXIT_OK


def add_list_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``list`` to the ``rehabbot`` subcommands."""
    listing = commands.add_parser("list", help="list the registered env ids")
    listing.set_defaults(func=cmd_list)
