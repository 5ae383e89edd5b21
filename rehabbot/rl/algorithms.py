"""The reinforcement-learning algorithms RehabBot trains and loads, and the library classes
that implement them on each backend: Stable-Baselines3 (PyTorch; TQC and CrossQ from
sb3-contrib) or SBX (Stable-Baselines-Jax, the ``sbx-rl`` package). Which backend a run uses
is chosen in :mod:`rehabbot.rl.backends`; the libraries are imported only when a class is
asked for."""

from __future__ import annotations

import importlib
import json
import re
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, UsageError
from rehabbot.common.extras import install_hint

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
POLICY_PACKAGE_BACKENDS = {"stable_baselines3": "sb3", "sb3_contrib": "sb3", "sbx": "sbx"}
# SB3's PPO policy lives in stable_baselines3.common.policies, whose name gives no algorithm:
# PPO's saved constructor arguments tell it apart (from A2C, which rehabbot does not run).
PPO_SIGNATURE = ("clip_range", "n_epochs")


class PolicyError(DataError):
    """A policy or model cannot be loaded or does not fit the env; the message says why."""


class BackendUnavailableError(UsageError):
    """The library an algorithm needs on the chosen backend is not installed."""


# The modules of the tracking-error policy classes, which rehabbot does not define: settings and
# models that name one are refused by name.
REMOVED_POLICY_MODULES = ("rehabbot.rl.features", "rehabbot.rl.features_jax")


# The commit of rehabbot whose rl/features*.py defines the refused policy classes.
LAST_CUSTOM_NETWORK_COMMIT = "51d9d71"


def removed_policy(name: str) -> str:
    """Why the policy class ``name`` (a dotted name in a refused module) does not load."""
    return (f"the policy class {name} is refused: rehabbot does not define it (the -v2 ids "
            "observe what an agent needs, and the libraries' own MlpPolicy learns them); "
            f"rehabbot at commit {LAST_CUSTOM_NETWORK_COMMIT} defines and loads it")


def saved_policy_class(data: dict[str, Any]) -> tuple[str, str]:
    """``(module, dotted name)`` of the policy class a model zip's readable metadata names
    (its module, and the class in the qualified names of its methods)."""
    entry = data.get("policy_class")
    entry = entry if isinstance(entry, dict) else {}
    module = str(entry.get("__module__", ""))
    names = sorted({match for value in entry.values() if isinstance(value, str)
                    for match in re.findall(r"<function ([A-Za-z_]\w*)\.\w+ at ", value)})
    return module, f"{module}.{names[0]}" if names else module


def one_of(value: Any, valid: Sequence[str], what: str,
           error: type[UsageError] = UsageError) -> str:
    """``value`` in lower case; ``error`` naming it and the valid ones unless it is one."""
    name = str(value).strip().lower()
    if name not in valid:
        raise error(f"unknown {what} {value!r}; valid: {', '.join(valid)}")
    return name


def check_algo(algo: str, error: type[UsageError] = UsageError) -> str:
    """The lower-case algorithm name, one of :data:`ALGORITHMS` (else ``error``)."""
    return one_of(algo, ALGORITHMS, "algorithm", error)


def algo_class(algo: str, backend: str = "sb3") -> Any:
    """The class of ``algo`` on ``backend`` (imports its library).

    Raises:
        BackendUnavailableError: the library is not installed, or has no such class.
    """
    algo, backend = check_algo(algo), one_of(backend, BACKENDS, "backend")
    module_name, class_name = ALGO_CLASSES[(backend, algo)]
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        hint = install_hint(module_name)
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
    """The ``data`` entry of a Stable-Baselines3 / SBX model zip.

    Raises:
        PolicyError: an unreadable zip, or one saved with a policy class that rehabbot refuses
            (:data:`REMOVED_POLICY_MODULES`; the message names it).
    """
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError,
            OSError) as err:
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip "
                          f"({type(err).__name__}: {err})") from err
    if not isinstance(data, dict):
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip")
    module, name = saved_policy_class(data)
    if module in REMOVED_POLICY_MODULES:
        raise PolicyError(f"cannot load {str(path)!r}: {removed_policy(name)}")
    return data


def detect_model(path: Path) -> tuple[str, str]:
    """``(algo, backend)`` of the model zip ``path``, from its metadata: the module of the
    saved policy class (``sbx.tqc.policies`` -> tqc on sbx; SB3's PPO by the arguments it
    saved).

    Raises:
        PolicyError: not a model zip of SB3, sb3-contrib or SBX, or one of another algorithm.
    """
    data = read_model_data(path)
    module = saved_policy_class(data)[0]
    parts = module.split(".")
    backend = POLICY_PACKAGE_BACKENDS.get(parts[0])
    if backend is not None and len(parts) > 1 and parts[1] in ALGORITHMS:
        return parts[1], backend
    if module == "stable_baselines3.common.policies" and all(k in data for k in PPO_SIGNATURE):
        return "ppo", "sb3"
    raise PolicyError(f"{str(path)!r} was saved by an algorithm rehabbot does not run "
                      f"(policy module {module!r}); supported: {list(ALGORITHMS)} on "
                      f"{' or '.join(BACKENDS)}")


def detect_algo(path: Path) -> str:
    """The algorithm that saved the model zip ``path`` (see :func:`detect_model`)."""
    return detect_model(path)[0]
