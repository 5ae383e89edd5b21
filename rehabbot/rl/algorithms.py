"""The reinforcement-learning algorithms RehabBot trains and loads, and the library classes
that implement them on each backend: Stable-Baselines3 (PyTorch; TQC and CrossQ from
sb3-contrib) or SBX (Stable-Baselines-Jax, the ``sbx-rl`` package). Which backend a run uses
is chosen in :mod:`rehabbot.rl.backends`; the libraries are imported only when a class is
asked for."""

from __future__ import annotations

import importlib
import json
import zipfile
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, UsageError

ALGORITHMS = ("ppo", "sac", "td3", "tqc", "crossq")
OFF_POLICY = frozenset({"sac", "td3", "tqc", "crossq"})
ALGO_NAMES = {"ppo": "PPO", "sac": "SAC", "td3": "TD3", "tqc": "TQC", "crossq": "CrossQ"}
BACKENDS = ("sb3", "sbx")
# (backend, algo) -> (module, class).
ALGO_CLASSES = {
    **{("sb3", algo): ("stable_baselines3", ALGO_NAMES[algo]) for algo in ("ppo", "sac", "td3")},
    **{("sb3", algo): ("sb3_contrib", ALGO_NAMES[algo]) for algo in ("tqc", "crossq")},
    **{("sbx", algo): ("sbx", ALGO_NAMES[algo]) for algo in ALGORITHMS},
}
# The pip package that provides each module.
DISTRIBUTIONS = {"stable_baselines3": "stable-baselines3", "sb3_contrib": "sb3-contrib",
                 "sbx": "sbx-rl"}
# Top-level package of a saved model's policy class -> backend.
POLICY_PACKAGE_BACKENDS = {"stable_baselines3": "sb3", "sb3_contrib": "sb3", "rehabbot": "sb3",
                           "sbx": "sbx"}
# RehabBot's own policy modules for SBX (the rest of rehabbot's are PyTorch policies).
SBX_POLICY_MODULES = ("rehabbot.rl.features_jax",)


def policy_module_backend(module: str) -> str | None:
    """The backend whose policy classes live in ``module`` (None: not a known one)."""
    if module in SBX_POLICY_MODULES:
        return "sbx"
    return POLICY_PACKAGE_BACKENDS.get(module.split(".")[0])

# Each SB3 algorithm saves its own constructor arguments: they tell the three apart when the
# policy class is RehabBot's own (rehabbot.rl.features), whose module names no algorithm.
SIGNATURE_KEYS = {"td3": ("policy_delay", "target_policy_noise"),
                  "tqc": ("top_quantiles_to_drop_per_net",),
                  "sac": ("target_entropy", "ent_coef", "target_update_interval"),
                  "ppo": ("clip_range", "n_epochs")}


class PolicyError(DataError):
    """A policy or model cannot be loaded or does not fit the env; the message says why."""


class BackendUnavailableError(UsageError):
    """The library an algorithm needs on the chosen backend is not installed."""


def check_algo(algo: str) -> str:
    """The lower-case algorithm name; :class:`UsageError` unless it is one of
    :data:`ALGORITHMS`."""
    name = str(algo).strip().lower()
    if name not in ALGORITHMS:
        raise UsageError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGORITHMS)}")
    return name


def check_backend(backend: str) -> str:
    """The lower-case backend name; :class:`UsageError` unless it is sb3 or sbx."""
    name = str(backend).strip().lower()
    if name not in BACKENDS:
        raise UsageError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    return name


def algo_class(algo: str, backend: str = "sb3") -> Any:
    """The class of ``algo`` on ``backend`` (imports its library).

    Raises:
        BackendUnavailableError: the library is not installed, or has no such class.
    """
    algo, backend = check_algo(algo), check_backend(backend)
    module_name, class_name = ALGO_CLASSES[(backend, algo)]
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        hint = "pip install 'rehabbot[jax]'" if backend == "sbx" \
            else f"pip install {DISTRIBUTIONS[module_name]}"
        raise BackendUnavailableError(
            f"{ALGO_NAMES[algo]} on the {backend} backend needs the {DISTRIBUTIONS[module_name]} "
            f"package, which is not installed ({hint})") from err
    cls = getattr(module, class_name, None)
    if cls is None:
        raise BackendUnavailableError(
            f"{ALGO_NAMES[algo]} is not in the installed {DISTRIBUTIONS[module_name]}; "
            f"upgrade it, or use {'--backend sbx' if backend == 'sb3' else '--backend sb3'}")
    return cls


def read_model_data(path: Path) -> dict[str, Any]:
    """The ``data`` entry of a Stable-Baselines3 / SBX model zip (PolicyError if unreadable)."""
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError,
            OSError) as err:
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip "
                          f"({type(err).__name__}: {err})") from err
    if not isinstance(data, dict):
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip")
    return data


def detect_model(path: Path) -> tuple[str, str]:
    """``(algo, backend)`` of the model zip ``path``, from its metadata: the module of the
    saved policy class (``sbx.tqc.policies`` -> tqc on sbx), else the constructor arguments
    the algorithm saved.

    Raises:
        PolicyError: not a model zip of SB3, sb3-contrib or SBX, or one of another algorithm.
    """
    data = read_model_data(path)
    policy_class = data.get("policy_class", {})
    module = policy_class.get("__module__", "") if isinstance(policy_class, dict) else ""
    parts = str(module).split(".")
    backend = policy_module_backend(str(module))
    if backend is not None and len(parts) > 1 and parts[1] in ALGORITHMS:
        return parts[1], backend
    if module in SBX_POLICY_MODULES and policy_class.get("ALGO") in ALGORITHMS:
        return policy_class["ALGO"], backend  # rehabbot.rl.features_jax names its algorithm
    if backend is not None:
        for algo, keys in SIGNATURE_KEYS.items():
            if all(key in data for key in keys):
                return algo, backend
    raise PolicyError(f"{str(path)!r} was saved by an algorithm rehabbot does not run "
                      f"(policy module {module!r}); supported: {list(ALGORITHMS)} on "
                      f"{' or '.join(BACKENDS)}")


def detect_algo(path: Path) -> str:
    """The algorithm that saved the model zip ``path`` (see :func:`detect_model`)."""
    return detect_model(path)[0]
