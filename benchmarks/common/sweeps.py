"""Which training runs a sweep file makes, as keys a results table's runs can be compared with.

A run's key is what decides what it learned: the env id, its env kwargs (the robot ...), the
algorithm, the training seed, the steps, the backend, the expert episodes it saw and whether
its actor was cloned from them first. :func:`sweep_keys` expands a sweep file with the
package's own loader (:func:`rehabbot.rl.sweep_config.load_sweep_config`), so a results page
that names a sweep file can be checked against exactly what ``rehabbot sweep FILE`` trains.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

RunKey = tuple[str, str, str, int, int, str, int, bool]
KEY_FIELDS = ("env", "env kwargs", "algo", "seed", "timesteps", "backend", "demos", "bc")


def kwargs_text(env_kwargs: Mapping[str, Any] | None) -> str:
    """Env kwargs as one cell: sorted JSON, ``-`` for none."""
    return json.dumps(dict(env_kwargs), sort_keys=True) if env_kwargs else "-"


def run_key(env_id: str, env_kwargs: Mapping[str, Any] | None, algo: str, seed: int,
            timesteps: int, backend: str, demos: int | None, bc: bool | None) -> RunKey:
    """The key of one training run (ids with the ``rehabbot/`` namespace)."""
    full_id = env_id if "/" in env_id else f"rehabbot/{env_id}"
    return (full_id, kwargs_text(env_kwargs), algo, int(seed), int(timesteps), backend,
            int(demos or 0), bool(bc))


def sweep_keys(path: str | Path) -> list[RunKey]:
    """The key of every trial of the sweep file ``path`` (its backend as written: a sweep
    that a results page names must say ``backend: sbx`` or ``sb3``, not leave it to what is
    installed)."""
    from rehabbot.rl.sweep_config import load_sweep_config

    return [run_key(trial.env_id, trial.env_kwargs, trial.algo, trial.seed,
                    trial_timesteps(trial), trial.backend or "auto", trial.demos, trial.bc)
            for trial in load_sweep_config(path).trials()]


def trial_timesteps(trial: Any) -> int:
    """The steps a trial's run does: its ``timesteps``, except that a batched (rsl_rl) run
    trains whole PPO iterations of ``n_envs`` x ``num_steps_per_env`` steps, so its total is
    rounded up to a whole iteration (1 000 000 steps of 256 worlds x 24: 1 001 472)."""
    if not trial.batched:
        return int(trial.total_timesteps)
    per_iteration = trial.n_envs * trial.build_rsl_settings().num_steps_per_env
    return -(-int(trial.total_timesteps) // per_iteration) * per_iteration


def row_key(row: Mapping[str, Any]) -> RunKey:
    """The key of a runs-table row given as ``{column: cell}`` (columns :data:`KEY_FIELDS`)."""
    kwargs = row["env kwargs"]
    return run_key(row["env"], None if kwargs == "-" else json.loads(kwargs), row["algo"],
                   row["seed"], row["timesteps"], row["backend"], row["demos"],
                   row["bc"] == "yes" or row["bc"] is True)
