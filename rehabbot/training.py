"""Train Stable-Baselines3 agents (PPO, SAC, TD3) on the RehabBot envs: ``rehabbot train``.

=============================== ==========================================================
``train_run(env_id, algo, ...)`` one training run (one seed); returns its run directory
``add_train_parser(commands)``   adds the ``train`` subcommand to an argparse subparsers object
``cmd_train(args)``              runs the subcommand: every seed in turn; returns the exit code
``load_hyperparameters(...)``    reads an RL-Zoo-style YAML file into :class:`Hyperparameters`
``hyperparameters_from_mapping`` the same from a Python mapping
``parse_python_expression(s)``   the safe parser of zoo strings like ``"dict(net_arch=[64])"``
``run_summary(run_dir)``         the one-line summary printed after a run
=============================== ==========================================================

Every run writes one directory, which ``rehabbot evaluate`` and ``rehabbot plot`` read::

    OUT/<env-short>/<algo>/seed<k>/
        manifest.json                      what ran, how far it got, with which versions
        monitor/train_<i>.monitor.csv      SB3 Monitor of training sub-env i
                                           (info keywords: is_success, safety_violation)
        eval/evaluations.npz               SB3 EvalCallback log (deterministic episodes)
        tb/<ALGO>_1/                       TensorBoard event files
        checkpoints/rl_model_<n>_steps.zip (+ rl_model_replay_buffer_<n>_steps.pkl, newest
                                           only, for SAC/TD3; + rl_model_vecnormalize_<n>_steps.pkl)
        model.zip                          the final model (once the run has finished)
        vecnormalize.pkl                   the final VecNormalize statistics (if normalized)

Checkpoints, ``model.zip`` and ``manifest.json`` are written to a temporary file first and
renamed into place, so a file with its final name is always complete. SIGINT or SIGTERM
during training stops at the next env step, saves a checkpoint, marks the manifest
"interrupted" and makes ``cmd_train`` return 130 (SIGINT) or 143 (SIGTERM); ``--resume``
continues from the newest checkpoint to the requested step count, appending to the monitor
files, the evaluation log and the TensorBoard run.

Stable-Baselines3, PyTorch and PyYAML are imported only inside functions, so that importing
this module (as ``rehabbot --help`` does) stays cheap.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import copy
import csv
import functools
import inspect
import io
import json
import math
import os
import platform
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rehabbot.registration import ENV_SPECS

__all__ = [
    "ALGORITHMS",
    "Hyperparameters",
    "TrainingError",
    "TrainingInterrupted",
    "add_train_parser",
    "cmd_train",
    "hyperparameters_from_mapping",
    "load_hyperparameters",
    "parse_python_expression",
    "resolve_env_id",
    "run_directory",
    "run_summary",
    "train_run",
]

ALGORITHMS = ("ppo", "sac", "td3")
OFF_POLICY = frozenset({"sac", "td3"})
ALGO_NAMES = {"ppo": "PPO", "sac": "SAC", "td3": "TD3"}

DEFAULT_TIMESTEPS = 200_000
DEFAULT_SEEDS = (0,)
DEFAULT_OUT = "runs"
DEFAULT_CHECKPOINT_FREQ = 10_000
DEFAULT_EVAL_FREQ = 10_000
DEFAULT_EVAL_EPISODES = 5
DEFAULT_POLICY = "MlpPolicy"
EVAL_SEED_OFFSET = 10_000
DEFAULT_NOISE_STD = 0.1

MONITOR_INFO_KEYWORDS = ("is_success", "safety_violation")
MANIFEST_NAME = "manifest.json"
MODEL_NAME = "model.zip"
VECNORMALIZE_NAME = "vecnormalize.pkl"
CHECKPOINT_DIR = "checkpoints"
MONITOR_DIR = "monitor"
EVAL_DIR = "eval"
TB_DIR = "tb"
CHECKPOINT_PREFIX = "rl_model"
CHECKPOINT_RE = re.compile(rf"^{CHECKPOINT_PREFIX}_(\d+)_steps\.zip$")
MANIFEST_FORMAT = 1
HYPERPARAMS_DEFAULT_SOURCE = "sb3 defaults"

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

# Keys of RL-Zoo-style files that are not SB3 constructor arguments.
ZOO_KEYS = ("n_timesteps", "n_envs", "policy", "normalize", "noise_type", "noise_std")
# Constructor arguments that `rehabbot train` sets itself.
MANAGED_KEYS = {
    "env": "the env is the ENV argument",
    "seed": "use --seeds",
    "tensorboard_log": "TensorBoard logs go to RUN_DIR/tb",
    "_init_setup_model": "internal to Stable-Baselines3",
}
# Constructor arguments that need Python objects, which a YAML file cannot hold.
OBJECT_KEYS = {
    "action_noise": "use noise_type and noise_std",
    "replay_buffer_class": "not supported in hyperparameter files",
    "rollout_buffer_class": "not supported in hyperparameter files",
}
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf")
NOISE_TYPES = ("normal", "ornstein-uhlenbeck")
# Names a zoo string may use, and the torch classes they stand for.
TORCH_NAMES = {
    **{f"{prefix}{name}": ("torch.nn", name)
       for prefix in ("nn.", "th.nn.", "torch.nn.")
       for name in ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU", "GELU")},
    **{f"{prefix}{name}": ("torch.optim", name)
       for prefix in ("optim.", "th.optim.", "torch.optim.")
       for name in ("Adam", "AdamW", "RMSprop", "SGD")},
    # RehabBot's own features extractor (observation + tracking errors).
    **{name: ("rehabbot.features", "TrackingErrorFeatures")
       for name in ("TrackingErrorFeatures", "rehabbot.features.TrackingErrorFeatures")},
}
_NUMBER_RE = re.compile(r"^[+-]?(?:\d[\d_]*(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$")
_INT_RE = re.compile(r"^[+-]?\d[\d_]*$")


class TrainingError(ValueError):
    """A user error (bad id, file or option); ``cmd_train`` reports it as one line."""

    def __init__(self, message: str, exit_code: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


class TrainingInterrupted(Exception):  # noqa: N818  (not an error)
    """Training was stopped by a signal after saving a checkpoint (raised by ``train_run``)."""

    def __init__(self, run_dir: Path, timesteps_done: int, checkpoint: Path, signum: int) -> None:
        try:
            name = signal.Signals(signum).name
        except ValueError:
            name = f"signal {signum}"
        super().__init__(f"training in {run_dir} interrupted by {name} at {timesteps_done} "
                         f"steps; checkpoint {checkpoint}")
        self.run_dir = run_dir
        self.timesteps_done = timesteps_done
        self.checkpoint = checkpoint
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


# --------------------------------------------------------------------------- names and paths


def resolve_env_id(name: str) -> str:
    """The full registered id for ``name`` (full, or without the ``rehabbot/`` prefix)."""
    candidates = (name, f"rehabbot/{name}")
    for candidate in candidates:
        if candidate in ENV_SPECS:
            return candidate
    raise TrainingError(
        f"unknown env id {name!r}; valid ids: {', '.join(ENV_SPECS)} "
        "(the 'rehabbot/' prefix may be left out)",
        EXIT_USAGE,
    )


def env_short_name(env_id: str) -> str:
    """``rehabbot/rehab-reach-v0`` -> ``rehab-reach-v0``."""
    return env_id.split("/", 1)[-1]


def check_algo(algo: str) -> str:
    """The lower-case algorithm name; :class:`TrainingError` unless it is ppo, sac or td3."""
    name = str(algo).strip().lower()
    if name not in ALGORITHMS:
        raise TrainingError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGORITHMS)}",
                            EXIT_USAGE)
    return name


def run_directory(out_dir: str | Path, env_id: str, algo: str, seed: int) -> Path:
    """``OUT/<env-short>/<algo>/seed<k>``."""
    return Path(out_dir) / env_short_name(env_id) / algo.lower() / f"seed{int(seed)}"


def algo_class(algo: str) -> Any:
    """The Stable-Baselines3 class of ``algo`` (imports SB3)."""
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[check_algo(algo)]


# --------------------------------------------------------------------------- safe zoo strings


def parse_python_expression(text: str) -> Any:
    """Evaluate a zoo-style string such as ``"dict(net_arch=[64, 64], activation_fn=nn.ReLU)"``
    without ``eval``: only ``dict(key=value, ...)`` calls, ``{...}`` dicts, lists, tuples,
    numbers, strings, booleans, ``None`` and the torch names of :data:`TORCH_NAMES` are
    accepted.

    Raises:
        ValueError: anything else (names the offending part).
    """
    try:
        tree = ast.parse(str(text).strip(), mode="eval")
    except SyntaxError as err:
        raise ValueError(f"not a valid expression: {text!r} ({err.msg})") from err
    return _literal(tree.body)


def _dotted_name(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted_name(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def _literal(node: ast.AST) -> Any:
    if isinstance(node, ast.Constant) and (
        node.value is None or isinstance(node.value, (bool, int, float, str))
    ):
        return node.value
    if isinstance(node, ast.List):
        return [_literal(item) for item in node.elts]
    if isinstance(node, ast.Tuple):
        return tuple(_literal(item) for item in node.elts)
    if isinstance(node, ast.Dict) and all(key is not None for key in node.keys):
        return {_literal(key): _literal(value) for key, value in zip(node.keys, node.values,
                                                                      strict=True)}
    if (isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd))
            and isinstance(node.operand, ast.Constant)
            and isinstance(node.operand.value, (int, float))
            and not isinstance(node.operand.value, bool)):
        value = node.operand.value
        return -value if isinstance(node.op, ast.USub) else value
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "dict" and not node.args
            and all(keyword.arg is not None for keyword in node.keywords)):
        return {keyword.arg: _literal(keyword.value) for keyword in node.keywords}
    dotted = _dotted_name(node)
    if dotted is not None and dotted in TORCH_NAMES:
        return _torch_object(dotted)
    allowed = sorted({name for name in TORCH_NAMES if name.startswith(("nn.", "optim."))})
    raise ValueError(
        f"{ast.unparse(node)!r} is not allowed: only dict(...), literals, lists, tuples and "
        f"the names {', '.join(allowed)}"
    )


def _torch_object(name: str) -> Any:
    module_name, attr = TORCH_NAMES[name]
    import importlib

    return getattr(importlib.import_module(module_name), attr)


def _resolve_torch_names(value: Any) -> Any:
    """Replace strings like ``"nn.ReLU"`` (from a YAML mapping) by the torch classes."""
    if isinstance(value, str) and value.strip() in TORCH_NAMES:
        return _torch_object(value.strip())
    if isinstance(value, dict):
        return {key: _resolve_torch_names(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_resolve_torch_names(item) for item in value]
    return value


# --------------------------------------------------------------------------- hyperparameters


@dataclass
class Hyperparameters:
    """The resolved contents of one hyperparameter entry for one algorithm.

    ``kwargs`` holds the SB3 constructor arguments ready to pass (schedules and torch classes
    resolved); ``given`` the same as JSON-able values, as written in the file.
    """

    algo: str
    source: str = HYPERPARAMS_DEFAULT_SOURCE
    entry: str | None = None
    policy: str = DEFAULT_POLICY
    kwargs: dict[str, Any] = field(default_factory=dict)
    given: dict[str, Any] = field(default_factory=dict)
    n_timesteps: int | None = None
    n_envs: int | None = None
    normalize: dict[str, Any] | None = None
    noise_type: str | None = None
    noise_std: float | None = None

    def effective_kwargs(self) -> dict[str, Any]:
        """Every constructor argument (SB3 defaults filled in) as JSON-able values."""
        cls = algo_class(self.algo)
        effective: dict[str, Any] = {}
        for name, param in inspect.signature(cls.__init__).parameters.items():
            if name in ("self", "env", "_init_setup_model", "tensorboard_log", "seed"):
                continue
            if name == "policy":
                effective[name] = self.policy
            elif name in self.kwargs:
                given = self.given.get(name)
                effective[name] = given if (name in SCHEDULE_KEYS and isinstance(given, str)) \
                    else _jsonable(self.kwargs[name])
            elif param.default is not inspect.Parameter.empty:
                effective[name] = _jsonable(param.default)
        if self.noise_type is not None:
            effective["action_noise"] = {"type": self.noise_type, "std": self.noise_std}
        return effective

    def to_manifest(self) -> dict[str, Any]:
        """The ``hyperparameters`` block of ``manifest.json``."""
        return {
            "source": self.source,
            "entry": self.entry,
            "given": _jsonable(self.given),
            "kwargs": self.effective_kwargs(),
            "policy": self.policy,
            "normalize": _jsonable(self.normalize) if self.normalize is not None else False,
            "noise_type": self.noise_type,
            "noise_std": self.noise_std,
            "n_timesteps": self.n_timesteps,
            "n_envs": self.n_envs,
        }


def _coerce_number(value: Any) -> Any:
    """``"3e-4"`` -> 0.0003 and ``"1_000"`` -> 1000 (PyYAML reads ``3e-4`` as a string)."""
    if isinstance(value, str) and _NUMBER_RE.match(value.strip()):
        text = value.strip().replace("_", "")
        return int(text) if _INT_RE.match(text) else float(text)
    return value


def _as_count(value: Any, key: str, where: str, minimum: int = 1) -> int:
    value = _coerce_number(value)
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise TrainingError(f"{where}: {key} must be an integer >= {minimum}, got {value!r}",
                            EXIT_USAGE)
    return value


def _parse_normalize(value: Any, where: str) -> dict[str, Any] | None:
    if isinstance(value, str):
        lowered = value.strip().lower()
        if lowered in ("true", "false", "yes", "no"):
            value = lowered in ("true", "yes")
        else:
            try:
                value = parse_python_expression(value)
            except ValueError as err:
                raise TrainingError(f"{where}: normalize: {err}", EXIT_USAGE) from err
    if value is None or value is False:
        return None
    if value is True:
        return {}
    if not isinstance(value, dict):
        raise TrainingError(f"{where}: normalize must be true, false or a mapping of "
                            f"VecNormalize arguments, got {value!r}", EXIT_USAGE)
    from stable_baselines3.common.vec_env import VecNormalize

    valid = [name for name in inspect.signature(VecNormalize.__init__).parameters
             if name not in ("self", "venv", "training")]
    for key in value:
        if key not in valid:
            raise TrainingError(f"{where}: unknown normalize key {key!r}; valid: "
                                f"{', '.join(valid)}", EXIT_USAGE)
    return {key: _coerce_number(item) for key, item in value.items()}


def _parse_policy_kwargs(value: Any, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, str):
        try:
            value = parse_python_expression(value)
        except ValueError as err:
            raise TrainingError(f"{where}: policy_kwargs: {err}", EXIT_USAGE) from err
    if not isinstance(value, dict):
        raise TrainingError(f"{where}: policy_kwargs must be a mapping or a 'dict(...)' "
                            f"string, got {value!r}", EXIT_USAGE)
    return {str(key): _resolve_torch_names(item) for key, item in value.items()}


def _parse_schedule(value: Any, key: str, where: str) -> Any:
    if isinstance(value, str) and value.strip().startswith("lin_"):
        try:
            start = float(value.strip()[len("lin_"):])
        except ValueError as err:
            raise TrainingError(f"{where}: {key}: bad linear schedule {value!r} "
                                "(expected lin_<float>, e.g. lin_3e-4)", EXIT_USAGE) from err
        if not math.isfinite(start):
            raise TrainingError(f"{where}: {key}: bad linear schedule {value!r}", EXIT_USAGE)
        from stable_baselines3.common.utils import LinearSchedule

        # progress_remaining goes 1 -> 0 over the run: start -> 0, linearly.
        return LinearSchedule(start, 0.0, 1.0)
    return value


def hyperparameters_from_mapping(mapping: Mapping[str, Any] | None, algo: str,
                                 source: str = "python mapping",
                                 entry: str | None = None) -> Hyperparameters:
    """Validate a flat mapping of hyperparameters for ``algo``.

    Accepted keys: the SB3 constructor arguments of the algorithm (checked against its
    signature) and the zoo keys ``n_timesteps``, ``n_envs``, ``policy``, ``normalize``,
    ``noise_type`` and ``noise_std``. ``policy_kwargs`` may be a mapping or a zoo string,
    ``learning_rate``/``clip_range``/``clip_range_vf`` may be ``"lin_<float>"``.

    Raises:
        TrainingError: an unknown key (named, with the algorithm) or a bad value.
    """
    algo = check_algo(algo)
    where = source if entry is None else f"{source} [{entry}]"
    hp = Hyperparameters(algo=algo, source=source, entry=entry)
    if mapping is None:
        return hp
    if not isinstance(mapping, Mapping):
        raise TrainingError(f"{where}: hyperparameters must be a mapping, got "
                            f"{type(mapping).__name__}", EXIT_USAGE)
    cls = algo_class(algo)
    params = inspect.signature(cls.__init__).parameters
    noise_std_given = False
    for key, raw in mapping.items():
        if not isinstance(key, str):
            raise TrainingError(f"{where}: hyperparameter names must be strings, got {key!r}",
                                EXIT_USAGE)
        if key == "n_timesteps":
            hp.n_timesteps = _as_count(raw, key, where)
        elif key == "n_envs":
            hp.n_envs = _as_count(raw, key, where)
        elif key == "policy":
            if not isinstance(raw, str) or raw not in cls.policy_aliases:
                raise TrainingError(f"{where}: policy must be one of "
                                    f"{', '.join(cls.policy_aliases)}, got {raw!r}", EXIT_USAGE)
            hp.policy = raw
        elif key == "normalize":
            hp.normalize = _parse_normalize(raw, where)
        elif key == "noise_type":
            if raw is not None and raw not in NOISE_TYPES:
                raise TrainingError(f"{where}: noise_type must be one of "
                                    f"{', '.join(NOISE_TYPES)}, got {raw!r}", EXIT_USAGE)
            hp.noise_type = raw
        elif key == "noise_std":
            value = _coerce_number(raw)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not (value > 0 and math.isfinite(value)):
                raise TrainingError(f"{where}: noise_std must be a positive number, got "
                                    f"{raw!r}", EXIT_USAGE)
            hp.noise_std = float(value)
            noise_std_given = True
        elif key in MANAGED_KEYS:
            raise TrainingError(f"{where}: {key!r} cannot be set in a hyperparameter file "
                                f"({MANAGED_KEYS[key]})", EXIT_USAGE)
        elif key not in params or key == "self":
            valid = [name for name in params
                     if name not in ("self", *MANAGED_KEYS, *OBJECT_KEYS)]
            raise TrainingError(
                f"{where}: unknown hyperparameter {key!r} for {ALGO_NAMES[algo]}; valid keys: "
                f"{', '.join([*valid, *(k for k in ZOO_KEYS if k not in valid)])}",
                EXIT_USAGE,
            )
        elif key in OBJECT_KEYS:
            if raw is not None:
                raise TrainingError(f"{where}: {key!r} cannot be set in a hyperparameter file "
                                    f"({OBJECT_KEYS[key]})", EXIT_USAGE)
        elif key == "policy_kwargs":
            hp.kwargs[key] = _parse_policy_kwargs(raw, where)
        else:
            value = _coerce_number(raw)
            default = params[key].default
            if (isinstance(default, int) and not isinstance(default, bool)
                    and isinstance(value, float) and value.is_integer()):
                value = int(value)
            if key == "train_freq" and isinstance(value, list):
                value = tuple(value)
            if key in SCHEDULE_KEYS:
                value = _parse_schedule(value, key, where)
            hp.kwargs[key] = value
        hp.given[key] = _jsonable(raw)
    if noise_std_given and hp.noise_type is None:
        raise TrainingError(f"{where}: noise_std needs noise_type ({' or '.join(NOISE_TYPES)})",
                            EXIT_USAGE)
    if hp.noise_type is not None:
        if algo not in OFF_POLICY:
            raise TrainingError(f"{where}: noise_type applies to SAC and TD3 only, not "
                                f"{ALGO_NAMES[algo]}", EXIT_USAGE)
        if hp.noise_std is None:
            hp.noise_std = DEFAULT_NOISE_STD
    return hp


def _looks_like_env_key(key: Any) -> bool:
    if not isinstance(key, str):
        return False
    if key in ENV_SPECS or f"rehabbot/{key}" in ENV_SPECS:
        return True
    return "/" in key or re.search(r"-v\d+$", key) is not None


def load_hyperparameters(path: str | Path, env_id: str, algo: str) -> Hyperparameters:
    """Read an RL-Zoo-style YAML file: either env ids (full or short) mapped to mappings of
    hyperparameters, or one flat mapping of hyperparameters.

    Raises:
        TrainingError: missing or unreadable file, invalid YAML, no entry for ``env_id``,
            unknown key or bad value (the message names the file and the key).
    """
    env_id = resolve_env_id(env_id)
    algo = check_algo(algo)
    file = Path(path)
    if not file.is_file():
        what = "is a directory" if file.is_dir() else "not found"
        raise TrainingError(f"hyperparameter file {str(path)!r} {what}", EXIT_USAGE)
    try:
        import yaml
    except ImportError as err:
        raise TrainingError("reading hyperparameter files needs PyYAML: pip install pyyaml"
                            ) from err
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise TrainingError(f"cannot read hyperparameter file {str(path)!r}: {err}",
                            EXIT_USAGE) from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        detail = " ".join(str(err).split())
        raise TrainingError(f"hyperparameter file {str(path)!r} is not valid YAML: {detail}",
                            EXIT_USAGE) from err
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise TrainingError(f"hyperparameter file {str(path)!r} must hold a mapping, not a "
                            f"{type(data).__name__}", EXIT_USAGE)
    source = str(path)
    env_keys = [key for key in data if _looks_like_env_key(key)]
    if not env_keys:
        return hyperparameters_from_mapping(data, algo, source=source)
    others = [key for key in data if key not in env_keys]
    if others:
        raise TrainingError(
            f"hyperparameter file {source!r} mixes env ids ({', '.join(map(str, env_keys))}) "
            f"with other top-level keys ({', '.join(map(str, others))})", EXIT_USAGE)
    matches = [key for key in data if key in (env_id, env_short_name(env_id))]
    if not matches:
        raise TrainingError(f"hyperparameter file {source!r} has no entry for {env_id} "
                            f"(entries: {', '.join(map(str, data))})", EXIT_USAGE)
    if len(matches) > 1:
        raise TrainingError(f"hyperparameter file {source!r} has two entries for {env_id}: "
                            f"{', '.join(matches)}", EXIT_USAGE)
    entry = data[matches[0]]
    if entry is not None and not isinstance(entry, dict):
        raise TrainingError(f"{source} [{matches[0]}]: must be a mapping of hyperparameters",
                            EXIT_USAGE)
    return hyperparameters_from_mapping(entry, algo, source=source, entry=matches[0])


def _as_hyperparameters(hyperparams: Any, env_id: str, algo: str) -> Hyperparameters:
    if hyperparams is None:
        return Hyperparameters(algo=algo)
    if isinstance(hyperparams, Hyperparameters):
        if hyperparams.algo != algo:
            raise TrainingError(f"the hyperparameters are for {hyperparams.algo}, not {algo}",
                                EXIT_USAGE)
        return hyperparams
    if isinstance(hyperparams, (str, Path)):
        return load_hyperparameters(hyperparams, env_id, algo)
    if isinstance(hyperparams, Mapping):
        return hyperparameters_from_mapping(hyperparams, algo)
    raise TrainingError(f"hyperparams must be a file path or a mapping, got "
                        f"{type(hyperparams).__name__}", EXIT_USAGE)


# --------------------------------------------------------------------------- small helpers


def _jsonable(value: Any) -> Any:
    """A JSON-able version of a hyperparameter value (classes by dotted name)."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, Mapping):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(item) for item in value]
    if isinstance(value, type):
        return f"{value.__module__}.{value.__qualname__}"
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        return _jsonable(item())
    return repr(value)


def _now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _temp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def atomic_write(path: Path, write: Callable[[io.BufferedWriter], None]) -> None:
    """Write ``path`` via a temporary file in the same folder and ``os.replace``."""
    tmp = _temp_path(path)
    try:
        with open(tmp, "wb") as stream:
            write(stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _fsync_dir(path.parent)


def _atomic_save_to_path(path: Path, save: Callable[[str], None]) -> None:
    """Like :func:`atomic_write` for savers that take a file name (VecNormalize.save)."""
    tmp = _temp_path(path)
    try:
        save(str(tmp))
        with open(tmp, "rb+") as stream:
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    text = json.dumps(data, indent=2, sort_keys=False) + "\n"
    atomic_write(path, lambda stream: stream.write(text.encode("utf-8")))


def _read_manifest(run_dir: Path) -> dict[str, Any] | None:
    path = run_dir / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise TrainingError(f"{path} is not a readable manifest: {err}") from err
    if not isinstance(manifest, dict):
        raise TrainingError(f"{path} is not a JSON object")
    return manifest


@functools.cache
def package_versions() -> dict[str, str | None]:
    """Versions of Python and of the packages a result depends on."""
    from importlib import metadata

    import rehabbot

    versions: dict[str, str | None] = {"python": platform.python_version(),
                                       "rehabbot": rehabbot.__version__}
    for key, dist in (("stable_baselines3", "stable-baselines3"), ("torch", "torch"),
                      ("gymnasium", "gymnasium"), ("mujoco", "mujoco"), ("numpy", "numpy")):
        try:
            versions[key] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[key] = None
    return versions


@functools.cache
def _git_commit() -> str | None:
    """HEAD of the rehabbot checkout, or None (not a git checkout, no git, timeout)."""
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():
        return None
    try:
        result = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                                capture_output=True, text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    commit = result.stdout.strip()
    return commit if result.returncode == 0 and re.fullmatch(r"[0-9a-f]{40,64}", commit) \
        else None


def _format_duration(seconds: float) -> str:
    seconds = max(0.0, float(seconds))
    if seconds < 60:
        return f"{seconds:.1f} s"
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"


def _check_out_dir(out_dir: Path) -> None:
    """:class:`TrainingError` unless ``out_dir`` is (or can be created as) a writable folder."""
    path = Path(out_dir)
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "is not a directory" if probe == path else f"cannot be created: {probe} is a file"
        raise TrainingError(f"output directory {str(out_dir)!r} {what}")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise TrainingError(f"output directory {str(out_dir)!r} is not writable "
                            f"(no write permission on {probe})")


def _parse_env_kwargs(text: str | None) -> dict[str, Any] | None:
    if text is None:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise TrainingError(f"--env-kwargs is not valid JSON: {err}", EXIT_USAGE) from err
    if not isinstance(value, dict):
        raise TrainingError(f"--env-kwargs must be a JSON object, got {text!r}", EXIT_USAGE)
    return value


def _check_env(env_id: str, env_kwargs: Mapping[str, Any]) -> None:
    """Build the env once so that bad ``env_kwargs`` fail before anything is written."""
    import gymnasium as gym

    try:
        env = gym.make(env_id, **env_kwargs)
    except (TypeError, ValueError) as err:
        raise TrainingError(f"cannot make {env_id} with env kwargs {json.dumps(env_kwargs)}: "
                            f"{err}", EXIT_USAGE) from err
    env.close()


def _mapping_equal(a: Any, b: Any) -> bool:
    return json.dumps(_jsonable(a), sort_keys=True) == json.dumps(_jsonable(b), sort_keys=True)


# --------------------------------------------------------------------------- run planning


@dataclass
class _ResumePoint:
    checkpoint: Path
    steps: int
    replay_buffer: Path | None
    vecnormalize: Path | None


@dataclass
class _RunPlan:
    env_id: str
    algo: str
    seed: int
    total_timesteps: int
    out_dir: Path
    run_dir: Path
    n_envs: int
    env_kwargs: dict[str, Any]
    hp: Hyperparameters
    normalize: dict[str, Any] | None
    checkpoint_freq: int
    eval_freq: int
    eval_episodes: int
    progress_bar: bool
    vec: str = "dummy"
    overwrite: bool = False
    resume: _ResumePoint | None = None
    manifest: dict[str, Any] | None = None
    skip: str | None = None


class _NothingToResumeError(TrainingError):
    pass


def _checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    folder = run_dir / CHECKPOINT_DIR
    if not folder.is_dir():
        return []
    found = []
    for path in folder.iterdir():
        match = CHECKPOINT_RE.match(path.name)
        if match and path.is_file():
            found.append((int(match.group(1)), path))
    return sorted(found, reverse=True)


def _companions(checkpoint_dir: Path, steps: int) -> tuple[Path, Path]:
    return (checkpoint_dir / f"{CHECKPOINT_PREFIX}_replay_buffer_{steps}_steps.pkl",
            checkpoint_dir / f"{CHECKPOINT_PREFIX}_vecnormalize_{steps}_steps.pkl")


def _find_resume_point(run_dir: Path, manifest: dict[str, Any] | None) -> _ResumePoint | None:
    """The newest checkpoint (by step count); model.zip of a finished run without any."""
    found = _checkpoints(run_dir)
    if found:
        steps, path = found[0]
        replay_buffer, vecnormalize = _companions(path.parent, steps)
        return _ResumePoint(path, steps, replay_buffer if replay_buffer.is_file() else None,
                            vecnormalize if vecnormalize.is_file() else None)
    model = run_dir / MODEL_NAME
    if model.is_file() and manifest and manifest.get("status") == "finished":
        vecnormalize = run_dir / VECNORMALIZE_NAME
        return _ResumePoint(model, int(manifest.get("timesteps_done", 0)), None,
                            vecnormalize if vecnormalize.is_file() else None)
    return None


def _describe_existing(run_dir: Path) -> str:
    try:
        manifest = _read_manifest(run_dir)
    except TrainingError:
        manifest = None
    if manifest:
        return (f"status {manifest.get('status')}, {manifest.get('timesteps_done')} of "
                f"{manifest.get('total_timesteps')} steps")
    return "files but no manifest"


def _plan_run(env_id: str, algo: str, seed: int, total_timesteps: int | None,
              out_dir: str | Path, *, n_envs: int | None, hp: Hyperparameters,
              env_kwargs: dict[str, Any] | None, resume: bool, overwrite: bool,
              checkpoint_freq: int | None, eval_freq: int | None, eval_episodes: int | None,
              progress_bar: bool, vec: str) -> _RunPlan:
    """Validate one run and work out its settings; writes nothing."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise TrainingError(f"seed must be an integer >= 0, got {seed!r}", EXIT_USAGE)
    out = Path(out_dir)
    run_dir = run_directory(out, env_id, algo, seed)
    if run_dir.exists() and not run_dir.is_dir():
        raise TrainingError(f"run directory {run_dir} exists and is not a directory")
    for name, value, minimum in (("total_timesteps", total_timesteps, 1),
                                 ("n_envs", n_envs, 1),
                                 ("checkpoint_freq", checkpoint_freq, 0),
                                 ("eval_freq", eval_freq, 0),
                                 ("eval_episodes", eval_episodes, 1)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < minimum):
            raise TrainingError(f"{name} must be an integer >= {minimum}, got {value!r}",
                                EXIT_USAGE)
    if vec not in ("dummy", "subproc"):
        raise TrainingError(f"vec must be 'dummy' or 'subproc', got {vec!r}", EXIT_USAGE)

    if resume:
        if overwrite:
            raise TrainingError("--resume and --overwrite exclude each other", EXIT_USAGE)
        manifest = _read_manifest(run_dir) if run_dir.is_dir() else None
        point = _find_resume_point(run_dir, manifest) if run_dir.is_dir() else None
        if point is None:
            if run_dir.is_dir() and any(run_dir.iterdir()):
                raise _NothingToResumeError(
                    f"nothing to resume in {run_dir} (no checkpoint yet; "
                    f"{_describe_existing(run_dir)}); start it again with --overwrite")
            raise _NothingToResumeError(f"nothing to resume: {run_dir} does not hold a run; "
                                   "train without --resume first")
        if manifest is None:
            raise TrainingError(f"cannot resume {run_dir}: its {MANIFEST_NAME} is missing")
        for key, mine in (("env_id", env_id), ("algo", algo)):
            if str(manifest.get(key)) != mine:
                raise TrainingError(
                    f"cannot resume {run_dir}: it was trained with {key} "
                    f"{manifest.get(key)!r}, not {mine!r}", EXIT_USAGE)
        saved_n_envs = int(manifest.get("n_envs", 1))
        if n_envs is not None and n_envs != saved_n_envs:
            raise TrainingError(f"cannot resume {run_dir} with {n_envs} envs: it was trained "
                                f"with n_envs={saved_n_envs}", EXIT_USAGE)
        saved_kwargs = manifest.get("env_kwargs") or {}
        if env_kwargs is not None and not _mapping_equal(env_kwargs, saved_kwargs):
            raise TrainingError(f"cannot resume {run_dir} with env kwargs "
                                f"{json.dumps(env_kwargs)}: it was trained with "
                                f"{json.dumps(saved_kwargs)}", EXIT_USAGE)
        saved_hp = manifest.get("hyperparameters") or {}
        saved_normalize = saved_hp.get("normalize", False)  # False, or VecNormalize kwargs
        normalize = None if saved_normalize in (None, False) else (
            dict(saved_normalize) if isinstance(saved_normalize, dict) else {})
        if normalize is not None and point.vecnormalize is None:
            raise TrainingError(f"cannot resume {run_dir}: checkpoint {point.checkpoint.name} "
                                "lacks its VecNormalize statistics")
        total = total_timesteps if total_timesteps is not None \
            else int(manifest.get("total_timesteps", DEFAULT_TIMESTEPS))
        plan = _RunPlan(
            env_id=env_id, algo=algo, seed=seed, total_timesteps=total, out_dir=out,
            run_dir=run_dir, n_envs=saved_n_envs, env_kwargs=dict(saved_kwargs), hp=hp,
            normalize=normalize,
            checkpoint_freq=checkpoint_freq if checkpoint_freq is not None
            else int(manifest.get("checkpoint_freq", DEFAULT_CHECKPOINT_FREQ)),
            eval_freq=eval_freq if eval_freq is not None
            else int(manifest.get("eval_freq", DEFAULT_EVAL_FREQ)),
            eval_episodes=eval_episodes if eval_episodes is not None
            else int(manifest.get("eval_episodes", DEFAULT_EVAL_EPISODES)),
            progress_bar=progress_bar, vec=str(manifest.get("vec_env", vec)), resume=point,
            manifest=manifest)
        if point.steps >= total:
            status = manifest.get("status")
            plan.skip = (f"{run_dir}: already {'finished' if status == 'finished' else 'at'} "
                         f"{point.steps} steps (requested {total}); nothing to do")
        return plan

    if run_dir.is_dir() and any(run_dir.iterdir()) and not overwrite:
        raise TrainingError(f"{run_dir} already holds a run ({_describe_existing(run_dir)}); "
                            "continue it with --resume or start over with --overwrite")
    total = total_timesteps if total_timesteps is not None \
        else (hp.n_timesteps or DEFAULT_TIMESTEPS)
    return _RunPlan(
        env_id=env_id, algo=algo, seed=seed, total_timesteps=total, out_dir=out,
        run_dir=run_dir, n_envs=n_envs if n_envs is not None else (hp.n_envs or 1),
        env_kwargs=dict(env_kwargs or {}), hp=hp, normalize=hp.normalize,
        checkpoint_freq=DEFAULT_CHECKPOINT_FREQ if checkpoint_freq is None else checkpoint_freq,
        eval_freq=DEFAULT_EVAL_FREQ if eval_freq is None else eval_freq,
        eval_episodes=DEFAULT_EVAL_EPISODES if eval_episodes is None else eval_episodes,
        progress_bar=progress_bar, vec=vec, overwrite=overwrite)


# --------------------------------------------------------------------------- envs


def _make_env(env_id: str, env_kwargs: dict[str, Any], monitor_file: str | None,
              append: bool, time_offset_s: float, parent_pid: int) -> Any:
    """One Monitor-wrapped env (runs in the worker process for SubprocVecEnv)."""
    import gymnasium as gym
    from stable_baselines3.common.monitor import Monitor

    import rehabbot  # noqa: F401  (registers the ids in a fresh worker process)

    if os.getpid() != parent_pid:
        # Ctrl+C (and a scheduler's SIGTERM) may reach the whole process group; only the
        # trainer handles them. Workers exit when the trainer closes their pipes.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    env = gym.make(env_id, **env_kwargs)
    override = not (append and monitor_file is not None and os.path.isfile(monitor_file))
    env = Monitor(env, filename=monitor_file, allow_early_resets=True,
                  info_keywords=MONITOR_INFO_KEYWORDS if monitor_file is not None else (),
                  override_existing=override)
    if time_offset_s:
        # Keep the monitor's "t" column running on from the previous segment.
        env.t_start = time.time() - time_offset_s
    return env


def _make_vec_env(plan: _RunPlan, n_envs: int, seed: int, monitor_dir: Path | None,
                  append: bool = False, time_offsets: Sequence[float] = (),
                  vec: str = "dummy") -> Any:
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    factories = [
        functools.partial(
            _make_env, plan.env_id, dict(plan.env_kwargs),
            str(monitor_dir / f"train_{i}.monitor.csv") if monitor_dir is not None else None,
            append, time_offsets[i] if i < len(time_offsets) else 0.0, os.getpid())
        for i in range(n_envs)
    ]
    venv = SubprocVecEnv(factories) if vec == "subproc" and n_envs > 1 \
        else DummyVecEnv(factories)
    venv.seed(seed)
    return venv


def _truncate_monitor(path: Path, max_steps: int) -> float:
    """Drop rows past ``max_steps`` env steps (written after the checkpoint we resume from);
    returns the ``t`` of the last row kept (0 if none)."""
    if not path.is_file():
        return 0.0
    with path.open(newline="", encoding="utf-8") as stream:
        header = stream.readline()
        reader = csv.reader(stream)
        try:
            columns = next(reader)
        except StopIteration:
            return 0.0
        rows = list(reader)
    try:
        l_col, t_col = columns.index("l"), columns.index("t")
    except ValueError:
        return 0.0
    kept, steps, last_t = [], 0, 0.0
    for row in rows:
        try:
            length, t = int(float(row[l_col])), float(row[t_col])
        except (IndexError, ValueError):
            break
        if steps + length > max_steps:
            break
        steps += length
        last_t = t
        kept.append(row)
    if len(kept) != len(rows):
        out = io.StringIO(newline="")
        out.write(header)
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(kept)
        atomic_write(path, lambda stream: stream.write(out.getvalue().encode("utf-8")))
    return last_t


def _load_evaluations(path: Path, max_steps: int) -> dict[str, list] | None:
    import numpy as np

    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            timesteps = [int(t) for t in data["timesteps"]]
            keep = [i for i, t in enumerate(timesteps) if t <= max_steps]
            result = {
                "timesteps": [timesteps[i] for i in keep],
                "results": [list(map(float, data["results"][i])) for i in keep],
                "ep_lengths": [list(map(int, data["ep_lengths"][i])) for i in keep],
                "successes": [list(map(bool, data["successes"][i])) for i in keep]
                if "successes" in data.files and len(data["successes"]) == len(timesteps)
                else [],
            }
    except (OSError, KeyError, ValueError, EOFError) as err:
        warnings.warn(f"ignoring unreadable {path}: {err}", stacklevel=2)
        return None
    return result


def _action_noise(hp_block: Mapping[str, Any], n_actions: int) -> Any:
    import numpy as np
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    noise_type, std = hp_block.get("noise_type"), hp_block.get("noise_std")
    if noise_type is None:
        return None
    mean, sigma = np.zeros(n_actions), float(std) * np.ones(n_actions)
    if noise_type == "normal":
        return NormalActionNoise(mean=mean, sigma=sigma)
    return OrnsteinUhlenbeckActionNoise(mean=mean, sigma=sigma)


# --------------------------------------------------------------------------- callbacks


@functools.cache
def _callback_classes() -> tuple[type, type]:
    """SB3 callback subclasses, defined lazily so that SB3 is imported only when training."""
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class Checkpointer(CheckpointCallback):
        """SB3's CheckpointCallback with atomic files, the newest replay buffer kept only
        (each one holds the whole buffer), and a hook that updates the manifest."""

        def __init__(self, save_freq: int, save_path: str,
                     on_saved: Callable[[int, Path], None]) -> None:
            super().__init__(save_freq, save_path, name_prefix=CHECKPOINT_PREFIX,
                             save_replay_buffer=True, save_vecnormalize=True, verbose=0)
            self.on_saved = on_saved
            self.last_saved: tuple[int, Path] | None = None

        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq == 0:
                self.save_now()
            return True

        def save_now(self) -> Path:
            steps = int(self.model.num_timesteps)
            if self.last_saved is not None and self.last_saved[0] == steps:
                return self.last_saved[1]
            folder = Path(self.save_path)
            folder.mkdir(parents=True, exist_ok=True)
            replay_path, vecnormalize_path = _companions(folder, steps)
            if getattr(self.model, "replay_buffer", None) is not None:
                atomic_write(replay_path, self.model.save_replay_buffer)
            vec_normalize = self.model.get_vec_normalize_env()
            if vec_normalize is not None:
                _atomic_save_to_path(vecnormalize_path, vec_normalize.save)
            model_path = folder / f"{CHECKPOINT_PREFIX}_{steps}_steps.zip"
            atomic_write(model_path, self.model.save)  # last: a zip marks a full checkpoint
            for old in folder.glob(f"{CHECKPOINT_PREFIX}_replay_buffer_*_steps.pkl"):
                if old != replay_path:
                    with contextlib.suppress(OSError):
                        old.unlink()
            self.last_saved = (steps, model_path)
            self.on_saved(steps, model_path)
            return model_path

    class Stopper(BaseCallback):
        """Stops ``learn`` after a signal, and PPO exactly at the requested step count."""

        def __init__(self, target: int, exact_rollouts: bool) -> None:
            super().__init__(verbose=0)
            self.target = target
            self.exact_rollouts = exact_rollouts
            self.stop_signal: int | None = None

        def _on_step(self) -> bool:
            if self.stop_signal is not None:
                return False
            if self.exact_rollouts and self.model.num_timesteps >= self.target:
                n_steps, n_rollout = self.locals.get("n_steps"), self.locals.get(
                    "n_rollout_steps")
                # A rollout that is about to fill up is trained on; a partial one is dropped.
                if n_steps is not None and n_rollout is not None and n_steps + 1 < n_rollout:
                    return False
            return True

    return Checkpointer, Stopper


@contextlib.contextmanager
def handling_signals(handler: Callable[[int, Any], None]):
    """Install ``handler`` for SIGINT and SIGTERM (only in the main thread: elsewhere this is
    a no-op); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signums = (signal.SIGINT, signal.SIGTERM)
    previous = {signum: signal.getsignal(signum) for signum in signums}
    for signum in signums:
        signal.signal(signum, handler)
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old if old is not None else signal.SIG_DFL)


@contextlib.contextmanager
def _stop_on_signals(stopper: Any):
    """SIGINT/SIGTERM ask ``stopper`` to stop at the next step; a second one raises
    KeyboardInterrupt. The previous handlers come back afterwards."""

    def handler(signum: int, _frame: Any) -> None:
        if stopper.stop_signal is None:
            stopper.stop_signal = signum
            print(f"\nreceived {signal.Signals(signum).name}: stopping at the next step and "
                  "saving a checkpoint (send it again to stop at once)", file=sys.stderr,
                  flush=True)
        else:
            raise KeyboardInterrupt

    with handling_signals(handler):
        yield


# --------------------------------------------------------------------------- one run


def _progress_bar_available() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


def _make_dirs(path: Path) -> Path | None:
    """``mkdir -p path``; returns the topmost folder it created (None if all existed)."""
    missing = []
    probe = path
    while not probe.exists():
        missing.append(probe)
        probe = probe.parent
    path.mkdir(parents=True, exist_ok=True)
    return missing[-1] if missing else None


class _Run:
    """The state of one executing run: its manifest and wall-clock bookkeeping."""

    def __init__(self, plan: _RunPlan) -> None:
        self.plan = plan
        self.segment_start = time.monotonic()
        self.segment_started_at = _now_iso()
        self.prior_wall_s = float((plan.manifest or {}).get("wall_clock_s", 0.0)) \
            if plan.resume else 0.0
        self.manifest: dict[str, Any] = {}

    def wall_clock_s(self) -> float:
        return round(self.prior_wall_s + time.monotonic() - self.segment_start, 3)

    def rel(self, path: Path) -> str:
        try:
            return path.relative_to(self.plan.run_dir).as_posix()
        except ValueError:
            return str(path)

    def write(self, **updates: Any) -> None:
        self.manifest.update(updates)
        self.manifest["wall_clock_s"] = self.wall_clock_s()
        segment = self.manifest["segments"][-1]
        segment["end_timesteps"] = self.manifest["timesteps_done"]
        segment["status"] = self.manifest["status"]
        segment["wall_clock_s"] = round(time.monotonic() - self.segment_start, 3)
        if self.manifest["status"] != "running":
            segment["ended_at"] = _now_iso()
        _write_json_atomic(self.plan.run_dir / MANIFEST_NAME, self.manifest)

    def start_manifest(self, seeds: dict[str, int], done: int) -> None:
        plan = self.plan
        segment = {
            "started_at": self.segment_started_at, "ended_at": None,
            "start_timesteps": done, "end_timesteps": done, "status": "running",
            "resumed_from": self.rel(plan.resume.checkpoint) if plan.resume else None,
            "seeds": seeds, "wall_clock_s": 0.0, "command": list(sys.argv),
            "versions": package_versions(), "git_commit": _git_commit(),
        }
        if plan.resume is None:
            self.manifest = {
                "format_version": MANIFEST_FORMAT,
                "env_id": plan.env_id,
                "algo": plan.algo,
                "seed": plan.seed,
                "seeds": seeds,
                "total_timesteps": plan.total_timesteps,
                "timesteps_done": 0,
                "n_envs": plan.n_envs,
                "vec_env": plan.vec,
                "env_kwargs": _jsonable(plan.env_kwargs),
                "hyperparameters": plan.hp.to_manifest(),
                "checkpoint_freq": plan.checkpoint_freq,
                "eval_freq": plan.eval_freq,
                "eval_episodes": plan.eval_episodes,
                "eval_deterministic": True,
                "versions": package_versions(),
                "git_commit": _git_commit(),
                "command": list(sys.argv),
                "status": "running",
                "started_at": self.segment_started_at,
                "finished_at": None,
                "wall_clock_s": 0.0,
                "resumed_from": None,
                "model": MODEL_NAME,
                "vecnormalize": VECNORMALIZE_NAME if plan.normalize is not None else None,
                "last_checkpoint": None,
                "segments": [segment],
            }
        else:
            self.manifest = dict(plan.manifest or {})
            self.manifest.pop("error", None)
            segments = [dict(old) for old in self.manifest.get("segments", [])]
            if segments and segments[-1].get("status") == "running":
                segments[-1]["status"] = "killed"  # ended without a word: SIGKILL, crash
            self.manifest["segments"] = [*segments, segment]
            self.manifest.update(
                total_timesteps=plan.total_timesteps, timesteps_done=done,
                checkpoint_freq=plan.checkpoint_freq, eval_freq=plan.eval_freq,
                eval_episodes=plan.eval_episodes, versions=package_versions(),
                git_commit=_git_commit(), command=list(sys.argv), status="running",
                finished_at=None, resumed_from=self.rel(plan.resume.checkpoint),
                last_checkpoint=self.rel(plan.resume.checkpoint)
                if plan.resume.checkpoint.parent.name == CHECKPOINT_DIR
                else self.manifest.get("last_checkpoint"))
        self.write()


def _setup(plan: _RunPlan, run: _Run) -> tuple[Any, Any, Any, int, dict[str, Any] | None]:
    """Envs and model (new or loaded) for ``plan``; returns (model, venv, eval_venv, done,
    previous evaluations)."""
    from stable_baselines3.common.vec_env import VecNormalize

    cls = algo_class(plan.algo)
    run_dir = plan.run_dir
    done = plan.resume.steps if plan.resume else 0
    n_envs = plan.n_envs
    time_offsets: list[float] = []
    previous_evals = None
    if plan.resume:
        per_env = done // n_envs
        time_offsets = [_truncate_monitor(run_dir / MONITOR_DIR / f"train_{i}.monitor.csv",
                                          per_env) for i in range(n_envs)]
        previous_evals = _load_evaluations(run_dir / EVAL_DIR / "evaluations.npz", done)
    # Resumed segments use shifted env seeds so that they do not replay the same episodes.
    seeds = {"model": plan.seed + done, "train_env": plan.seed + done,
             "eval_env": plan.seed + EVAL_SEED_OFFSET + done}
    venv = _make_vec_env(plan, n_envs, seeds["train_env"], run_dir / MONITOR_DIR,
                         append=plan.resume is not None, time_offsets=time_offsets,
                         vec=plan.vec)
    eval_venv = None
    try:
        if plan.eval_freq > 0:
            eval_venv = _make_vec_env(plan, 1, seeds["eval_env"], None)
        if plan.normalize is not None:
            if plan.resume is not None and plan.resume.vecnormalize is not None:
                venv = VecNormalize.load(str(plan.resume.vecnormalize), venv)
                venv.training = True
            else:
                venv = VecNormalize(venv, **plan.normalize)
            if eval_venv is not None:
                eval_venv = VecNormalize(eval_venv, training=False, norm_obs=venv.norm_obs,
                                         norm_reward=False, clip_obs=venv.clip_obs,
                                         gamma=venv.gamma, epsilon=venv.epsilon)
        tb_dir = str(run_dir / TB_DIR)
        if plan.resume is None:
            # A copy: SB3 writes into policy_kwargs (e.g. SAC adds use_sde).
            kwargs = copy.deepcopy(plan.hp.kwargs)
            noise = _action_noise(plan.hp.to_manifest(), int(venv.action_space.shape[0]))
            if noise is not None:
                kwargs["action_noise"] = noise
            kwargs.setdefault("verbose", 0)
            try:
                model = cls(plan.hp.policy, venv, seed=plan.seed, tensorboard_log=tb_dir,
                            **kwargs)
            except (TypeError, ValueError, AssertionError, KeyError) as err:
                raise TrainingError(f"invalid hyperparameters for {ALGO_NAMES[plan.algo]} "
                                    f"({plan.hp.source}): {err}", EXIT_USAGE) from err
        else:
            try:
                with warnings.catch_warnings():
                    # The saved n-step replay buffer class makes SB3 warn that ``n_steps`` is
                    # ignored; the buffer loaded below keeps its n-step returns.
                    warnings.filterwarnings("ignore", message=".*n_steps.*is ignored because")
                    model = cls.load(str(plan.resume.checkpoint), env=venv, device="auto",
                                     tensorboard_log=tb_dir, verbose=0)
            except Exception as err:  # SB3 raises many kinds on a damaged or foreign file
                raise TrainingError(f"cannot load checkpoint {plan.resume.checkpoint}: "
                                    f"{type(err).__name__}: {err}") from err
            model.set_random_seed(seeds["model"])
            if plan.algo in OFF_POLICY:
                if plan.resume.replay_buffer is not None:
                    try:
                        model.load_replay_buffer(str(plan.resume.replay_buffer))
                    except Exception as err:  # a damaged pickle raises many kinds
                        raise TrainingError(
                            f"cannot load replay buffer {plan.resume.replay_buffer}: "
                            f"{type(err).__name__}: {err} (delete it to resume with an "
                            "empty buffer)") from err
                else:
                    print(f"warning: no replay buffer saved with {plan.resume.checkpoint}; "
                          "continuing with an empty one", file=sys.stderr)
        run.start_manifest(seeds, done)
    except BaseException:
        venv.close()
        if eval_venv is not None:
            eval_venv.close()
        raise
    return model, venv, eval_venv, done, previous_evals


def _execute(plan: _RunPlan) -> Path:
    """Train ``plan``; returns the run dir, raises :class:`TrainingInterrupted` on a signal."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList, EvalCallback

    torch.set_num_threads(1)
    run_dir = plan.run_dir
    run = _Run(plan)
    created_root: Path | None = None
    if plan.resume is not None:  # temporary files of a process that was killed mid-write
        for stale in (*run_dir.glob(".*.tmp"), *(run_dir / CHECKPOINT_DIR).glob(".*.tmp")):
            with contextlib.suppress(OSError):
                stale.unlink()
    try:
        if plan.resume is None:
            if plan.overwrite and run_dir.exists():
                shutil.rmtree(run_dir)
            created_root = _make_dirs(run_dir)
            for sub in (MONITOR_DIR, CHECKPOINT_DIR):
                (run_dir / sub).mkdir(exist_ok=True)
        model, venv, eval_venv, done, previous_evals = _setup(plan, run)
    except BaseException:
        if plan.resume is None:  # leave nothing half-written behind
            if created_root is not None:
                shutil.rmtree(created_root, ignore_errors=True)
            elif run_dir.is_dir():
                for child in run_dir.iterdir():
                    if child.is_dir():
                        shutil.rmtree(child, ignore_errors=True)
                    else:
                        child.unlink(missing_ok=True)
        raise

    checkpointer_cls, stopper_cls = _callback_classes()
    n_envs = plan.n_envs

    def on_saved(steps: int, path: Path) -> None:
        run.write(timesteps_done=steps, last_checkpoint=run.rel(path))

    checkpointer = checkpointer_cls(
        max(plan.checkpoint_freq // n_envs, 1) if plan.checkpoint_freq > 0 else sys.maxsize,
        str(run_dir / CHECKPOINT_DIR), on_saved)
    stopper = stopper_cls(plan.total_timesteps, exact_rollouts=plan.algo not in OFF_POLICY)
    callbacks: list[Any] = [checkpointer]
    if eval_venv is not None:
        evaluator = EvalCallback(eval_venv, n_eval_episodes=plan.eval_episodes,
                                 eval_freq=max(plan.eval_freq // n_envs, 1),
                                 log_path=str(run_dir / EVAL_DIR), deterministic=True,
                                 verbose=0, warn=False)
        if previous_evals:
            evaluator.evaluations_timesteps = previous_evals["timesteps"]
            evaluator.evaluations_results = previous_evals["results"]
            evaluator.evaluations_length = previous_evals["ep_lengths"]
            evaluator.evaluations_successes = previous_evals["successes"]
        callbacks.append(evaluator)
    callbacks.append(stopper)
    # Keep the step-based triggers aligned with the run's total step count after a resume.
    for callback in callbacks:
        callback.n_calls = done // n_envs

    progress = plan.progress_bar and _progress_bar_available()
    try:
        with _stop_on_signals(stopper), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Training and eval env are not of the "
                                    "same type")
            try:
                model.learn(plan.total_timesteps - done, callback=CallbackList(callbacks),
                            reset_num_timesteps=plan.resume is None,
                            tb_log_name=ALGO_NAMES[plan.algo], progress_bar=progress)
            except KeyboardInterrupt:
                stopper.stop_signal = stopper.stop_signal or signal.SIGINT
        done = int(model.num_timesteps)
        if stopper.stop_signal is not None:
            checkpoint = checkpointer.save_now()
            run.write(status="interrupted", timesteps_done=done,
                      last_checkpoint=run.rel(checkpoint))
            raise TrainingInterrupted(run_dir, done, checkpoint, stopper.stop_signal)
        checkpoint = checkpointer.save_now()  # final checkpoint, so that --resume can extend
        atomic_write(run_dir / MODEL_NAME, model.save)
        vec_normalize = model.get_vec_normalize_env()
        if vec_normalize is not None:
            _atomic_save_to_path(run_dir / VECNORMALIZE_NAME, vec_normalize.save)
        run.write(status="finished", timesteps_done=done, finished_at=_now_iso(),
                  last_checkpoint=run.rel(checkpoint))
    except (TrainingInterrupted, TrainingError):
        raise
    except BaseException as err:
        with contextlib.suppress(Exception):  # record what happened, then re-raise
            if isinstance(err, KeyboardInterrupt):  # e.g. Ctrl+C while saving after learn
                run.write(status="interrupted")
            else:
                run.write(status="failed", error=f"{type(err).__name__}: {err}")
        raise
    finally:
        venv.close()
        if eval_venv is not None:
            eval_venv.close()
    return run_dir


def train_run(env_id: str, algo: str, seed: int, total_timesteps: int, out_dir: str | Path,
              *, n_envs: int = 1, hyperparams: str | Path | Mapping[str, Any] | Hyperparameters
              | None = None, env_kwargs: Mapping[str, Any] | None = None, resume: bool = False,
              checkpoint_freq: int = DEFAULT_CHECKPOINT_FREQ,
              eval_freq: int = DEFAULT_EVAL_FREQ, eval_episodes: int = DEFAULT_EVAL_EPISODES,
              progress_bar: bool = True, overwrite: bool = False, vec: str = "dummy") -> Path:
    """Train one agent and return its run directory ``out_dir/<env-short>/<algo>/seed<k>``.

    ``hyperparams`` is a YAML file path, a flat mapping or a :class:`Hyperparameters`;
    ``checkpoint_freq``/``eval_freq`` count env steps (0 turns them off). With ``resume``, the
    run continues from its newest checkpoint until ``total_timesteps`` (n_envs and env_kwargs
    must match the manifest; the saved model's hyperparameters apply); a run that is already
    there is left alone.

    Raises:
        TrainingError: a user error (bad id, file, value; existing run without ``resume`` or
            ``overwrite``; nothing to resume); nothing is left behind for a new run.
        TrainingInterrupted: SIGINT/SIGTERM stopped training; a checkpoint was saved.
    """
    env_id = resolve_env_id(env_id)
    algo = check_algo(algo)
    hp = _as_hyperparameters(hyperparams, env_id, algo)
    kwargs = None if env_kwargs is None else dict(env_kwargs)
    _check_out_dir(Path(out_dir))
    plan = _plan_run(env_id, algo, seed, total_timesteps, out_dir, n_envs=n_envs, hp=hp,
                     env_kwargs=kwargs, resume=resume, overwrite=overwrite,
                     checkpoint_freq=checkpoint_freq, eval_freq=eval_freq,
                     eval_episodes=eval_episodes, progress_bar=progress_bar, vec=vec)
    if plan.skip is not None:
        return plan.run_dir
    _check_env(env_id, plan.env_kwargs)
    return _execute(plan)


def run_summary(run_dir: str | Path) -> str:
    """``DIR: N steps, wall-clock W, last eval at S steps: success X%, mean return R``."""
    import numpy as np

    path = Path(run_dir)
    manifest = _read_manifest(path) or {}
    parts = [f"{path}: {manifest.get('timesteps_done', '?')} steps",
             f"{_format_duration(float(manifest.get('wall_clock_s', 0.0)))} wall-clock"]
    evaluations = path / EVAL_DIR / "evaluations.npz"
    text = "no evaluation"
    if evaluations.is_file():
        try:
            with np.load(evaluations, allow_pickle=False) as data:
                if len(data["timesteps"]):
                    ret = float(np.mean(data["results"][-1]))
                    text = f"last eval at {int(data['timesteps'][-1])} steps: "
                    if "successes" in data.files and len(data["successes"]):
                        text += f"success {100 * float(np.mean(data['successes'][-1])):.0f}%, "
                    text += f"mean return {ret:.1f}"
        except (OSError, KeyError, ValueError):
            text = "evaluation log unreadable"
    parts.append(text)
    return ", ".join(parts)


# --------------------------------------------------------------------------- command line


def _count(text: str) -> int:
    """A step count: 200000, 200_000 or 2e5."""
    value = _coerce_number(text)
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int):
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}")
    return value


def _positive_count(text: str) -> int:
    value = _count(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return value


def _non_negative_count(text: str) -> int:
    value = _count(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


TRAIN_EPILOG = """\
examples:
  rehabbot train rehab-reach-v0 --algo sac
  rehabbot train rehabbot/rehab-knee-v0 --algo td3 --timesteps 500000 --seeds 0 1 2 \\
      --hyperparams hyperparams/td3.yml
  rehabbot train rehab-hip-v0 --algo ppo --n-envs 8 --hyperparams hyperparams/ppo.yml \\
      --out runs/ppo-sweep
  rehabbot train rehab-reach-v0 --algo sac --env-kwargs '{"weight_level": 2}'
  rehabbot train rehab-reach-v0 --algo sac --timesteps 400000 --resume   # continue a run

Each seed writes OUT/<env>/<algo>/seed<k>/ with manifest.json, monitor/train_<i>.monitor.csv,
eval/evaluations.npz, tb/ (tensorboard --logdir OUT), checkpoints/ and, at the end, model.zip.
Ctrl+C (or SIGTERM) saves a checkpoint and prints the command that resumes; exit code 130
(143 for SIGTERM). --resume continues every seed from its newest checkpoint to --timesteps
(default: the total it was started with); settings come from the run's manifest. SAC/TD3
checkpoints keep the replay buffer of the newest checkpoint only (it can take hundreds of MB).
Runs end at exactly N steps (with one env); PPO does not train on a last, partial rollout.

Hyperparameter files are RL-Zoo-style YAML: env ids (full or short) mapped to hyperparameters,
or one flat mapping. Keys: the SB3 constructor arguments of the algorithm, plus n_timesteps,
n_envs, policy, normalize (true or VecNormalize arguments), noise_type (normal |
ornstein-uhlenbeck) and noise_std (SAC/TD3). policy_kwargs may be a mapping or a string such
as "dict(net_arch=[64, 64], activation_fn=nn.ReLU)"; learning_rate may be "lin_3e-4" (linear
decay to 0). hyperparams/{ppo,sac,td3}.yml hold the settings of the README results;
hyperparams/sb3-defaults/ spells out the SB3 defaults as a template.

exit codes: 0 done, 1 runtime failure, 2 bad usage, 130/143 interrupted (resumable)."""


def add_train_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``train`` subcommand (``func=cmd_train``) to ``commands``."""
    parser = commands.add_parser(
        "train",
        help="train a Stable-Baselines3 agent (PPO, SAC, TD3) on an env",
        description="Train a Stable-Baselines3 agent on a RehabBot env, one run per seed, "
                    "with checkpoints, evaluation, TensorBoard logs and a manifest.",
        epilog=TRAIN_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("env", metavar="ENV",
                        help=f"env id, with or without 'rehabbot/': {', '.join(ENV_SPECS)}")
    parser.add_argument("--algo", required=True, metavar="{" + ",".join(ALGORITHMS) + "}",
                        help="the algorithm")
    parser.add_argument("--timesteps", type=_positive_count, metavar="N",
                        help="env steps per run (default: the hyperparameter file's "
                             f"n_timesteps, else {DEFAULT_TIMESTEPS}; with --resume, the "
                             "run's own total)")
    parser.add_argument("--seeds", type=int, nargs="+", metavar="K",
                        help="seeds, trained one after the other (default: 0)")
    parser.add_argument("--n-envs", type=_positive_count, metavar="K",
                        help="parallel training envs (default: the file's n_envs, else 1)")
    parser.add_argument("--vec", choices=("dummy", "subproc"), default="dummy",
                        help="vector env: in-process (dummy, default) or one process per env")
    parser.add_argument("--hyperparams", metavar="FILE.yaml",
                        help="RL-Zoo-style hyperparameter file (default: SB3's defaults)")
    parser.add_argument("--env-kwargs", metavar="JSON",
                        help="keyword arguments for the env, as a JSON object")
    parser.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                        help=f"root of the run directories (default: {DEFAULT_OUT})")
    parser.add_argument("--resume", action="store_true",
                        help="continue each seed's run from its newest checkpoint")
    parser.add_argument("--overwrite", action="store_true",
                        help="delete an existing run directory and start again")
    parser.add_argument("--checkpoint-freq", type=_non_negative_count, metavar="N",
                        help=f"checkpoint every N env steps, 0: only at the end (default: "
                             f"{DEFAULT_CHECKPOINT_FREQ})")
    parser.add_argument("--eval-freq", type=_non_negative_count, metavar="N",
                        help=f"evaluate every N env steps on a separate env, 0: never "
                             f"(default: {DEFAULT_EVAL_FREQ})")
    parser.add_argument("--eval-episodes", type=_positive_count, metavar="N",
                        help=f"deterministic episodes per evaluation (default: "
                             f"{DEFAULT_EVAL_EPISODES})")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bar")
    parser.set_defaults(func=cmd_train)


def _resume_command(args: argparse.Namespace, env_id: str, algo: str, seeds: Sequence[int],
                    total: int) -> str:
    return shlex.join(["rehabbot", "train", env_short_name(env_id), "--algo", algo,
                       "--timesteps", str(total), "--seeds", *map(str, seeds),
                       "--out", str(args.out), "--resume"])


def _plans_from_args(args: argparse.Namespace) -> list[_RunPlan]:
    algo = check_algo(args.algo)
    env_id = resolve_env_id(args.env)
    env_kwargs = _parse_env_kwargs(args.env_kwargs)
    hp = load_hyperparameters(args.hyperparams, env_id, algo) if args.hyperparams \
        else Hyperparameters(algo=algo)
    if args.resume and args.overwrite:
        raise TrainingError("--resume and --overwrite exclude each other", EXIT_USAGE)
    seeds = list(dict.fromkeys(args.seeds if args.seeds else DEFAULT_SEEDS))
    for seed in seeds:
        if seed < 0:
            raise TrainingError(f"seeds must be >= 0, got {seed}", EXIT_USAGE)
    _check_out_dir(Path(args.out))
    common = dict(n_envs=args.n_envs, hp=hp, env_kwargs=env_kwargs,
                  overwrite=args.overwrite, checkpoint_freq=args.checkpoint_freq,
                  eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                  progress_bar=not args.no_progress, vec=args.vec)
    plans: list[_RunPlan | None] = []
    missing: list[_NothingToResumeError] = []
    for seed in seeds:
        try:
            plans.append(_plan_run(env_id, algo, seed, args.timesteps, args.out,
                                   resume=args.resume, **common))
        except _NothingToResumeError as err:
            plans.append(None)
            missing.append(err)
    if missing and len(missing) == len(seeds):
        raise TrainingError(str(missing[0]) if len(seeds) == 1 else
                            f"nothing to resume for any of the seeds {seeds} under "
                            f"{run_directory(args.out, env_id, algo, seeds[0]).parent}")
    resolved: list[_RunPlan] = []
    for seed, plan in zip(seeds, plans, strict=True):
        if plan is None:  # --resume with more seeds than were started: start these afresh
            run_dir = run_directory(args.out, env_id, algo, seed)
            if run_dir.is_dir() and any(run_dir.iterdir()):
                raise TrainingError(f"nothing to resume in {run_dir} (no checkpoint yet); "
                                    "start it again with --overwrite")
            plan = _plan_run(env_id, algo, seed, args.timesteps, args.out, resume=False,
                             **common)
        resolved.append(plan)
    for env_kwargs_checked in {json.dumps(p.env_kwargs, sort_keys=True)
                               for p in resolved if p.skip is None}:
        _check_env(env_id, json.loads(env_kwargs_checked))
    return resolved


def cmd_train(args: argparse.Namespace) -> int:
    """Run ``rehabbot train``: each seed in turn; 0 when done, 130/143 when interrupted."""
    from rehabbot.cli import CliError

    try:
        plans = _plans_from_args(args)
    except TrainingError as err:
        raise CliError(str(err), err.exit_code) from err
    for plan in plans:
        if plan.skip is not None:
            print(plan.skip, flush=True)
            continue
        if plan.resume:
            action, source = "resuming", "the checkpoint's"
            start = f"from {plan.resume.steps} "
        else:
            action, source, start = "training", plan.hp.source, ""
        envs = f"{plan.n_envs} env{'s' if plan.n_envs > 1 else ''}"
        print(f"{plan.run_dir}: {action} {plan.algo} on {plan.env_id}, seed {plan.seed}, "
              f"{start}to {plan.total_timesteps} steps ({envs}, hyperparameters: {source})",
              flush=True)
        try:
            run_dir = _execute(plan)
        except TrainingError as err:
            raise CliError(str(err), err.exit_code) from err
        except TrainingInterrupted as err:
            command = _resume_command(args, plan.env_id, plan.algo, [p.seed for p in plans],
                                      plan.total_timesteps)
            print(f"{err.run_dir}: interrupted at {err.timesteps_done} steps, checkpoint "
                  f"{err.checkpoint}; resume with: {command}", flush=True)
            return err.exit_code
        except KeyboardInterrupt:  # outside learn: while setting up or saving at the end
            newest = _checkpoints(plan.run_dir)
            if newest:
                command = _resume_command(args, plan.env_id, plan.algo,
                                          [p.seed for p in plans], plan.total_timesteps)
                print(f"{plan.run_dir}: interrupted; newest checkpoint {newest[0][1]}; resume "
                      f"with: {command}", flush=True)
            else:
                print(f"{plan.run_dir}: interrupted before the first checkpoint", flush=True)
            return 128 + signal.SIGINT
        print(run_summary(run_dir), flush=True)
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m rehabbot.training [train] ENV --algo ...`` (the same as ``rehabbot train``)."""
    parser = argparse.ArgumentParser(prog="python -m rehabbot.training")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_train_parser(commands)
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] != "train":
        argv = ["train", *argv]
    args = parser.parse_args(argv)
    from rehabbot.cli import CliError, use_headless_gl_by_default

    use_headless_gl_by_default()
    try:
        return int(args.func(args))
    except CliError as err:
        print(f"rehabbot: error: {' '.join(str(err).split())}", file=sys.stderr)
        return err.exit_code


if __name__ == "__main__":
    from rehabbot.training import main as _main

    sys.exit(_main())
