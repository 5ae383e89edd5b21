"""Hyperparameters of the training runs: RL-Zoo-style YAML files and Python mappings,
validated against the constructors of the backend's classes, and the settings files that
ship with the package (:func:`settings_path`).

A file holds either env ids (full, or without ``rehabbot/``) mapped to hyperparameters, a
``default`` entry for every other id (as RL Zoo reads it), or one flat mapping. Keys: the SB3
constructor arguments of the algorithm plus the zoo keys ``n_timesteps``, ``n_envs``,
``policy``, ``normalize``, ``noise_type`` and ``noise_std``; ``policy`` is an SB3 alias
(``MlpPolicy``) or, as in RL Zoo, the dotted name of a policy class under
``stable_baselines3.`` (``sbx.`` for SBX); ``policy_kwargs`` may be a mapping or a zoo string
such as ``"dict(net_arch=[64, 64], activation_fn=nn.ReLU)"``, parsed without ``eval``
(:mod:`rehabbot.rl.zoo_strings`); ``learning_rate``/``clip_range``/``clip_range_vf`` may be
``"lin_<float>"``. Each value is checked against its valid range
(:mod:`rehabbot.rl.hyperparam_checks`).

Files are read for one backend (``backend="sb3"``, the default, or ``"sbx"``): keys are checked
against that library's class; for SBX, what only PyTorch can run is translated or dropped and
listed (:mod:`rehabbot.rl.sbx_settings`).

The settings shipped with the package name only the libraries' own classes and options, so
that RL Zoo reads them unchanged too (``OMP_NUM_THREADS=1 python -m rl_zoo3.train
--gym-packages rehabbot --conf-file .../sac.yml``; one PyTorch thread per process: these small
networks train many times faster so on a loaded CPU): full env ids, classes named only as
``policy``, ``policy_kwargs`` as a string of literals.
"""

from __future__ import annotations

import importlib
import inspect
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from rehabbot.common.errors import UsageError
from rehabbot.common.extras import missing_module_message
from rehabbot.envs.registration import BILATERAL_IDS, ENV_SPECS, env_short_name, resolve_env_id
from rehabbot.rl.algorithms import (
    ALGO_NAMES,
    OFF_POLICY,
    REMOVED_POLICY_MODULES,
    algo_class,
    check_algo,
    removed_policy,
)
from rehabbot.rl.hyperparam_checks import (
    SCHEDULE_KEYS,
    HyperparameterError,
    as_count,
    check_value,
    coerce_number,
    jsonable,
    parse_schedule,
)
from rehabbot.rl.zoo_strings import _resolve_torch_names, parse_python_expression

DEFAULT_POLICY = "MlpPolicy"
DEFAULT_NOISE_STD = 0.1
HYPERPARAMS_DEFAULT_SOURCE = "sb3 defaults"
DEFAULT_SOURCES = {"sb3": HYPERPARAMS_DEFAULT_SOURCE, "sbx": "sbx defaults"}
SETTINGS_FOLDER = "hyperparams"  # package data of rehabbot.rl
DEFAULT_ENTRY = "default"  # RL Zoo's entry for every env id without its own
# Packages a dotted ``policy`` may be imported from (a hyperparameter file names no other code).
POLICY_PACKAGES = ("stable_baselines3",)
SBX_POLICY_PACKAGES = ("sbx",)


def _settings_root():
    return resources.files("rehabbot.rl").joinpath(SETTINGS_FOLDER)


def settings_names() -> list[str]:
    """The settings files shipped with the package, by name (``sac``, ``ablations/sac-gsde``,
    ``sb3-defaults/ppo``, ...)."""
    root = _settings_root()
    names = []
    for entry in sorted(root.iterdir(), key=lambda e: e.name):
        if entry.is_file() and entry.name.endswith(".yml"):
            names.append(entry.name[:-4])
        elif entry.is_dir():
            names += [f"{entry.name}/{sub.name[:-4]}" for sub in sorted(
                entry.iterdir(), key=lambda e: e.name) if sub.name.endswith(".yml")]
    return names


def shipped_settings(algo: str) -> str | None:
    """The name of the settings file shipped for ``algo`` (``"sac"`` for SAC: an entry per
    ``-v2`` id), or None when there is none. ``rehabbot train`` uses it when no
    ``--hyperparams`` is given."""
    algo = check_algo(algo, HyperparameterError)
    return algo if algo in settings_names() else None


def library_defaults(algo: str) -> str:
    """The ``--hyperparams`` that trains ``algo`` with the library's defaults on any id."""
    name = f"sb3-defaults/{algo}"
    return f"--hyperparams {name}" if name in settings_names() else \
        "a --hyperparams file without entries"


def _no_entry(path: str | Path, file: Path, env_id: str, algo: str,
              entries: list[Any]) -> HyperparameterError:
    """The error for a file without an entry for ``env_id``: for a shipped file and a ``-v0``
    or ``-v1`` id, why it has none and what to train instead."""
    shipped = file.parent.resolve() == Path(str(_settings_root())).resolve()
    stem, _, version = env_id.rpartition("-")
    if shipped and version in ("v0", "v1") and f"{stem}-v2" in ENV_SPECS:
        fields = "44 fields of both arms" if env_id in BILATERAL_IDS else "23 fields"
        what = ("is the paper's reference (its observation and reward), on which a plain "
                "network does not learn" if version == "v0" else
                f"observes the paper's {fields}, from which a plain network does not learn "
                "(0 % in every configuration tried)")
        same = "the same task with the learnable -v1 reward and" if version == "v0" else \
            "the same task and reward with"
        return HyperparameterError(
            f"the shipped {file.stem!r} settings have no entry for {env_id}: it {what}; train "
            f"{stem}-v2 ({same} the agent observation), or pass {library_defaults(algo)} to "
            "train this id with the library's defaults")
    return HyperparameterError(f"hyperparameter file {str(path)!r} has no entry for {env_id} "
                               f"and no {DEFAULT_ENTRY!r} entry (entries: "
                               f"{', '.join(map(str, entries))})")


def settings_path(name: str | Path) -> Path:
    """The file ``name`` stands for: an existing path, or the name of a settings file
    shipped with the package (``"sac"`` -> ``.../rehabbot/rl/hyperparams/sac.yml``).

    Raises:
        HyperparameterError: neither (lists the shipped names).
    """
    path = Path(name)
    if path.is_file():
        return path
    text = str(name)
    if path.is_dir():
        raise HyperparameterError(f"hyperparameter file {text!r} is a directory")
    stem = text[:-4] if text.endswith(".yml") else text
    if stem in settings_names():
        return Path(str(_settings_root().joinpath(f"{stem}.yml")))
    raise HyperparameterError(f"hyperparameter file {text!r} not found (a path, or one of the "
                              f"settings shipped with rehabbot: {', '.join(settings_names())})")


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
NOISE_TYPES = ("normal", "ornstein-uhlenbeck")


# --------------------------------------------------------------------------- hyperparameters


@dataclass
class Hyperparameters:
    """The resolved contents of one hyperparameter entry for one algorithm.

    ``kwargs`` holds the SB3 constructor arguments ready to pass (schedules and torch classes
    resolved); ``given`` the same as JSON-able values, as written in the file. ``policy`` is
    what the SB3 constructor takes: an alias such as ``"MlpPolicy"``, or the class a dotted
    name stands for (:attr:`policy_name` gives it back as a string).
    """

    algo: str
    source: str = HYPERPARAMS_DEFAULT_SOURCE
    entry: str | None = None
    policy: str | type = DEFAULT_POLICY
    kwargs: dict[str, Any] = field(default_factory=dict)
    given: dict[str, Any] = field(default_factory=dict)
    n_timesteps: int | None = None
    n_envs: int | None = None
    normalize: dict[str, Any] | None = None
    noise_type: str | None = None
    noise_std: float | None = None
    backend: str = "sb3"
    # What reading the file for SBX translated or dropped (rehabbot.rl.sbx_settings.change).
    backend_changes: list[dict[str, Any]] = field(default_factory=list)

    @property
    def policy_name(self) -> str:
        """The policy as JSON: the alias, or the class by its dotted name."""
        return self.policy if isinstance(self.policy, str) else jsonable(self.policy)

    def effective_kwargs(self) -> dict[str, Any]:
        """Every constructor argument (SB3 defaults filled in) as JSON-able values."""
        cls = algo_class(self.algo, self.backend)
        effective: dict[str, Any] = {}
        for name, param in inspect.signature(cls.__init__).parameters.items():
            if name in ("self", "env", "_init_setup_model", "tensorboard_log", "seed"):
                continue
            if name == "policy":
                effective[name] = self.policy_name
            elif name in self.kwargs:
                given = self.given.get(name)
                effective[name] = given if (name in SCHEDULE_KEYS and isinstance(given, str)) \
                    else jsonable(self.kwargs[name])
            elif param.default is not inspect.Parameter.empty:
                effective[name] = jsonable(param.default)
        if self.noise_type is not None:
            effective["action_noise"] = {"type": self.noise_type, "std": self.noise_std}
        return effective

    def to_manifest(self) -> dict[str, Any]:
        """The ``hyperparameters`` block of ``manifest.json``."""
        return {
            "source": self.source,
            "entry": self.entry,
            "given": jsonable(self.given),
            "kwargs": self.effective_kwargs(),
            "policy": self.policy_name,
            "normalize": jsonable(self.normalize) if self.normalize is not None else False,
            "noise_type": self.noise_type,
            "noise_std": self.noise_std,
            "n_timesteps": self.n_timesteps,
            "n_envs": self.n_envs,
            "backend": self.backend,
            "backend_changes": jsonable(self.backend_changes),
        }


def _expression(text: str, where: str) -> Any:
    """A zoo string (:func:`parse_python_expression`); a HyperparameterError naming ``where``."""
    try:
        return parse_python_expression(text)
    except ValueError as err:
        raise HyperparameterError(f"{where}: {err}") from err


def _parse_normalize(value: Any, where: str) -> dict[str, Any] | None:
    if isinstance(value, str):
        lowered = value.strip().lower()
        if lowered in ("true", "false", "yes", "no"):
            value = lowered in ("true", "yes")
        else:
            value = _expression(value, f"{where}: normalize")
    if value is None or value is False:
        return None
    if value is True:
        return {}
    if not isinstance(value, dict):
        raise HyperparameterError(f"{where}: normalize must be true, false or a mapping of "
                            f"VecNormalize arguments, got {value!r}")
    from stable_baselines3.common.vec_env import VecNormalize

    valid = [name for name in inspect.signature(VecNormalize.__init__).parameters
             if name not in ("self", "venv", "training")]
    for key in value:
        if key not in valid:
            raise HyperparameterError(f"{where}: unknown normalize key {key!r}; valid: "
                                f"{', '.join(valid)}")
    return {key: coerce_number(item) for key, item in value.items()}


def _parse_policy_kwargs(value: Any, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, str):
        value = _expression(value, f"{where}: policy_kwargs")
    if not isinstance(value, dict):
        raise HyperparameterError(f"{where}: policy_kwargs must be a mapping or a 'dict(...)' "
                            f"string, got {value!r}")
    return {str(key): _resolve_torch_names(item) for key, item in value.items()}


def _policy_error(where: str, raw: Any, cls: Any, why: str,
                  packages: tuple[str, ...] = POLICY_PACKAGES) -> HyperparameterError:
    return HyperparameterError(
        f"{where}: policy {raw!r} {why}; valid: {', '.join(cls.policy_aliases)}, or the dotted "
        f"name of a subclass of {jsonable(cls.policy_aliases[DEFAULT_POLICY])} under "
        f"{' or '.join(f'{package}.' for package in packages)}")


def parse_policy(raw: Any, cls: Any, where: str,
                  packages: tuple[str, ...] = POLICY_PACKAGES) -> str | type:
    """An SB3 alias (kept as the string) or a dotted class name (imported, as RL Zoo does):
    only from ``packages``, and only a subclass of the algorithm's MlpPolicy."""
    if isinstance(raw, str) and raw in cls.policy_aliases:
        return raw
    if not isinstance(raw, str) or "." not in raw.strip(". "):
        raise _policy_error(where, raw, cls, "is neither an alias nor a dotted class name",
                            packages)
    module_name, _, attr = raw.strip().rpartition(".")
    if module_name in REMOVED_POLICY_MODULES:
        raise HyperparameterError(f"{where}: {removed_policy(raw.strip())}")
    if module_name.split(".")[0] not in packages:
        raise _policy_error(where, raw, cls, "is outside the packages policies may come from",
                            packages)
    try:
        policy = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError, ValueError) as err:
        raise _policy_error(where, raw, cls, f"cannot be imported ({err})", packages) from None
    base = cls.policy_aliases[DEFAULT_POLICY]
    if not (isinstance(policy, type) and issubclass(policy, base)):
        raise _policy_error(where, raw, cls, f"is not a subclass of {jsonable(base)}",
                            packages)
    return policy



def hyperparameters_from_mapping(mapping: Mapping[str, Any] | None, algo: str,
                                 source: str = "python mapping",
                                 entry: str | None = None,
                                 backend: str = "sb3") -> Hyperparameters:
    """Validate a flat mapping of hyperparameters for ``algo`` on ``backend`` (``sb3`` or
    ``sbx``; for SBX, what only PyTorch runs is translated or dropped and listed in
    ``backend_changes``, see :mod:`rehabbot.rl.sbx_settings`).

    Accepted keys: the SB3 constructor arguments of the algorithm (checked against its
    signature) and the zoo keys ``n_timesteps``, ``n_envs``, ``policy``, ``normalize``,
    ``noise_type`` and ``noise_std``. ``policy`` may be an SB3 alias or the dotted name of a
    policy class (see :func:`parse_policy`), ``policy_kwargs`` a mapping or a zoo string,
    ``learning_rate``/``clip_range``/``clip_range_vf`` ``"lin_<float>"``.

    Raises:
        HyperparameterError: an unknown key (named, with the algorithm) or a bad value.
    """
    algo = check_algo(algo, HyperparameterError)
    where = source if entry is None else f"{source} [{entry}]"
    hp = Hyperparameters(algo=algo, source=source, entry=entry, backend=backend)
    if mapping is None:
        return hp
    if not isinstance(mapping, Mapping):
        raise HyperparameterError(f"{where}: hyperparameters must be a mapping, got "
                            f"{type(mapping).__name__}")
    cls = algo_class(algo, backend)
    params = inspect.signature(cls.__init__).parameters
    sbx = backend == "sbx"
    if sbx:
        from rehabbot.rl import sbx_settings
    for key, raw in mapping.items():
        if not isinstance(key, str):
            raise HyperparameterError(f"{where}: hyperparameter names must be strings, got {key!r}")
        if key == "n_timesteps":
            hp.n_timesteps = as_count(raw, f"{where}: {key}")
        elif key == "n_envs":
            hp.n_envs = as_count(raw, f"{where}: {key}")
        elif key == "policy" and sbx and sbx_settings.is_torch_policy(raw):
            hp.policy = DEFAULT_POLICY
            hp.backend_changes.append(sbx_settings.policy_change(raw))
        elif key == "policy":
            hp.policy = parse_policy(raw, cls, where,
                                      SBX_POLICY_PACKAGES if sbx else POLICY_PACKAGES)
        elif key == "normalize":
            hp.normalize = _parse_normalize(raw, where)
        elif key == "noise_type":
            if raw is not None and raw not in NOISE_TYPES:
                raise HyperparameterError(f"{where}: noise_type must be one of "
                                    f"{', '.join(NOISE_TYPES)}, got {raw!r}")
            hp.noise_type = raw
        elif key == "noise_std":
            value = coerce_number(raw)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not (value > 0 and math.isfinite(value)):
                raise HyperparameterError(f"{where}: noise_std must be a positive number, got "
                                    f"{raw!r}")
            hp.noise_std = float(value)
        elif key in MANAGED_KEYS:
            raise HyperparameterError(f"{where}: {key!r} cannot be set in a hyperparameter "
                                      f"file ({MANAGED_KEYS[key]})")
        elif sbx and (key not in params or key == "self") \
                and (why := sbx_settings.dropped_key_reason(key, algo)) is not None:
            hp.backend_changes.append(sbx_settings.change(key, raw, None, why))
        elif key not in params or key == "self":
            valid = [name for name in params
                     if name not in ("self", *MANAGED_KEYS, *OBJECT_KEYS)]
            raise HyperparameterError(
                f"{where}: unknown hyperparameter {key!r} for {ALGO_NAMES[algo]}; valid keys: "
                f"{', '.join([*valid, *(k for k in ZOO_KEYS if k not in valid)])}")
        elif key in OBJECT_KEYS:
            if raw is not None:
                raise HyperparameterError(f"{where}: {key!r} cannot be set in a hyperparameter "
                                          f"file ({OBJECT_KEYS[key]})")
        elif key == "policy_kwargs":
            hp.kwargs[key] = _parse_policy_kwargs(raw, where)
        else:
            value = coerce_number(raw)
            default = params[key].default
            if (isinstance(default, int) and not isinstance(default, bool)
                    and isinstance(value, float) and value.is_integer()):
                value = int(value)
            value = check_value(key, value, where)
            if key == "train_freq" and isinstance(value, list):
                value = tuple(value)
            if key in SCHEDULE_KEYS:
                value = parse_schedule(value, key, where)
            hp.kwargs[key] = value
        hp.given[key] = jsonable(raw)
    if hp.noise_std is not None and hp.noise_type is None:
        raise HyperparameterError(f"{where}: noise_std needs noise_type "
                                  f"({' or '.join(NOISE_TYPES)})")
    if sbx and "policy_kwargs" in hp.kwargs:
        policy_class = hp.policy if isinstance(hp.policy, type) \
            else cls.policy_aliases[hp.policy]
        hp.kwargs["policy_kwargs"] = sbx_settings.translate_policy_kwargs(
            hp.kwargs["policy_kwargs"], policy_class, hp.backend_changes)
    if hp.noise_type is not None:
        if algo not in OFF_POLICY:
            raise HyperparameterError(f"{where}: noise_type applies to SAC and TD3 only, not "
                                f"{ALGO_NAMES[algo]}")
        if hp.noise_std is None:
            hp.noise_std = DEFAULT_NOISE_STD
    return hp


def read_yaml(path: Path, what: str, error: type[Exception], name: str | None = None) -> Any:
    """The YAML document in ``path`` (``{}`` for an empty file).

    Raises:
        Exception: of the class ``error``: PyYAML is missing, or the file is unreadable or
            not YAML (the message names ``what`` and the file, as ``name`` if given).
    """
    name = str(path) if name is None else name
    try:
        import yaml
    except ImportError as err:
        raise error(missing_module_message(f"reading a {what}", "yaml")) from err
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise error(f"cannot read {what} {name!r}: "
                    f"{getattr(err, 'strerror', None) or err}") from err
    except yaml.YAMLError as err:
        raise error(f"{what} {name!r} is not valid YAML: {' '.join(str(err).split())}") from err
    return {} if data is None else data


def _looks_like_env_key(key: Any) -> bool:
    if not isinstance(key, str):
        return False
    if key in ENV_SPECS or f"rehabbot/{key}" in ENV_SPECS:
        return True
    return "/" in key or re.search(r"-v\d+$", key) is not None


def load_hyperparameters(path: str | Path, env_id: str, algo: str,
                         backend: str = "sb3") -> Hyperparameters:
    """Read an RL-Zoo-style YAML file for ``backend``: either env ids (full or short) mapped
    to mappings of hyperparameters, or one flat mapping of hyperparameters.

    Raises:
        HyperparameterError: missing or unreadable file, invalid YAML, no entry for ``env_id``,
            unknown key or bad value (the message names the file and the key).
    """
    try:
        env_id = resolve_env_id(env_id)
    except UsageError as err:
        raise HyperparameterError(str(err)) from None
    algo = check_algo(algo, HyperparameterError)
    file = settings_path(path)
    data = read_yaml(file, "hyperparameter file", HyperparameterError, str(path))
    if not isinstance(data, dict):
        raise HyperparameterError(f"hyperparameter file {str(path)!r} must hold a mapping, "
                                  f"not a {type(data).__name__}")
    source = str(path)
    env_keys = [key for key in data if key == DEFAULT_ENTRY or _looks_like_env_key(key)]
    if not env_keys:
        return hyperparameters_from_mapping(data, algo, source=source, backend=backend)
    others = [key for key in data if key not in env_keys]
    if others:
        raise HyperparameterError(
            f"hyperparameter file {source!r} mixes env ids ({', '.join(map(str, env_keys))}) "
            f"with other top-level keys ({', '.join(map(str, others))})")
    matches = [key for key in data if key in (env_id, env_short_name(env_id))]
    if not matches and DEFAULT_ENTRY in data:
        matches = [DEFAULT_ENTRY]
    if not matches:
        raise _no_entry(path, file, env_id, algo, list(data))
    if len(matches) > 1:
        raise HyperparameterError(f"hyperparameter file {source!r} has two entries for "
                                  f"{env_id}: {', '.join(matches)}")
    entry = data[matches[0]]
    if entry is not None and not isinstance(entry, dict):
        raise HyperparameterError(f"{source} [{matches[0]}]: must be a mapping of "
                                  "hyperparameters")
    return hyperparameters_from_mapping(entry, algo, source=source, entry=matches[0],
                                        backend=backend)


def as_hyperparameters(hyperparams: Any, env_id: str, algo: str,
                       backend: str = "sb3") -> Hyperparameters:
    """``hyperparams`` (None, a :class:`Hyperparameters`, a file or name, a mapping) read for
    ``algo`` on ``backend``; a :class:`Hyperparameters` read for the other backend is read
    again from what was given."""
    if hyperparams is None:
        return Hyperparameters(algo=algo, backend=backend, source=DEFAULT_SOURCES[backend])
    if isinstance(hyperparams, Hyperparameters):
        if hyperparams.algo != algo:
            raise HyperparameterError(f"the hyperparameters are for {hyperparams.algo}, not "
                                      f"{algo}")
        if hyperparams.backend != backend:
            source = DEFAULT_SOURCES[backend] if hyperparams.source in DEFAULT_SOURCES.values() \
                else hyperparams.source
            return hyperparameters_from_mapping(hyperparams.given, algo, source=source,
                                                entry=hyperparams.entry, backend=backend)
        return hyperparams
    if isinstance(hyperparams, (str, Path)):
        return load_hyperparameters(hyperparams, env_id, algo, backend)
    if isinstance(hyperparams, Mapping):
        return hyperparameters_from_mapping(hyperparams, algo, backend=backend)
    raise HyperparameterError(f"hyperparams must be a file path, a settings name or a "
                              f"mapping, got {type(hyperparams).__name__}")
