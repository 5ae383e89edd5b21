"""The reinforcement-learning algorithms RehabBot trains and loads (Stable-Baselines3)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, UsageError

ALGORITHMS = ("ppo", "sac", "td3")
OFF_POLICY = frozenset({"sac", "td3"})
ALGO_NAMES = {"ppo": "PPO", "sac": "SAC", "td3": "TD3"}
# Each algorithm saves its own constructor arguments: they tell the three apart.
SIGNATURE_KEYS = {"td3": ("policy_delay", "target_policy_noise"),
                  "sac": ("target_entropy", "ent_coef"),
                  "ppo": ("clip_range", "n_epochs")}


class PolicyError(DataError):
    """A policy or model cannot be loaded or does not fit the env; the message says why."""


def check_algo(algo: str) -> str:
    """The lower-case algorithm name; :class:`UsageError` unless it is ppo, sac or td3."""
    name = str(algo).strip().lower()
    if name not in ALGORITHMS:
        raise UsageError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGORITHMS)}")
    return name


def algo_class(algo: str) -> Any:
    """The Stable-Baselines3 class of ``algo`` (imports SB3)."""
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[check_algo(algo)]


def detect_algo(path: Path) -> str:
    """The SB3 algorithm that saved the model zip ``path``, from its metadata.

    Raises:
        PolicyError: not a Stable-Baselines3 model zip, or one of another algorithm.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError,
            OSError) as err:
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip "
                          f"({type(err).__name__}: {err})") from err
    for algo, keys in SIGNATURE_KEYS.items():
        if all(key in data for key in keys):
            return algo
    policy_class = data.get("policy_class", {})
    module = policy_class.get("__module__", "") if isinstance(policy_class, dict) else ""
    raise PolicyError(f"{str(path)!r} was saved by an algorithm rehabbot does not run "
                      f"(policy module {module!r}); supported: {list(ALGORITHMS)}")
