"""The YAML file of ``rehabbot sweep``: read it, check every key and value before anything
runs (:func:`load_sweep_config`), and expand it into trials (:meth:`SweepConfig.trials`).

A sweep crosses env ids × algorithms × seeds, and optionally hyperparameter values
(``grid``); docs/sweeps.md describes every key. Each trial is one run of
:func:`rehabbot.rl.training.train_run`:

* without a grid: ``OUT/<env>/<algo>/seed<k>`` (the folder of ``rehabbot train --out OUT``);
* a grid variant: ``OUT/<variant>/<env>/<algo>/seed<k>``, where ``<variant>`` names the
  overrides (``learning_rate=0.001,batch_size=128``) and the run's hyperparameter source reads
  ``<file> [<variant>]``, so the results table keeps variants apart.

An algorithm with ``backend: rsl_rl`` (PPO only) trains on the batched env instead, one run of
:func:`rehabbot.rl.batch_training.train_batched` per trial, in the same folders: ``n_envs``
counts its worlds, ``hyperparams`` is a YAML file of
:class:`~rehabbot.rl.batch_training.RslPpoSettings` fields and ``grid`` crosses those fields;
the keys of the CPU trainers it has no use for are refused by name.

This module imports neither Ray nor Stable-Baselines3 (nor JAX or PyTorch).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import itertools
import json
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rehabbot.common.errors import UsageError
from rehabbot.envs.registration import env_short_name, resolve_env_id
from rehabbot.rl import runs
from rehabbot.rl.algorithms import ALGORITHMS, check_algo, one_of
from rehabbot.rl.backends import BACKEND_CHOICES, DEFAULT_BACKEND, resolve_backend
from rehabbot.rl.batch_training import BACKEND as BATCH_BACKEND
from rehabbot.rl.batch_training import DEFAULT_NUM_ENVS as DEFAULT_BATCH_ENVS
from rehabbot.rl.batch_training import DEFAULT_TIMESTEPS as DEFAULT_BATCH_TIMESTEPS
from rehabbot.rl.batch_training import RslPpoSettings, read_settings
from rehabbot.rl.hyperparam_checks import as_count
from rehabbot.rl.hyperparams import (
    Hyperparameters,
    as_hyperparameters,
    coerce_number,
    hyperparameters_from_mapping,
    jsonable,
    read_yaml,
)
from rehabbot.rl.planning import DEFAULT_TIMESTEPS

SWEEP_KEYS = ("out", "envs", "algos", "seeds", "timesteps", "hyperparams", "grid",
              "env_kwargs", "eval_freq", "eval_episodes", "checkpoint_freq", "n_envs",
              "backend", "demos", "bc", "resources_per_trial")
REQUIRED_KEYS = ("envs", "algos", "seeds")
SWEEP_BACKENDS = (*BACKEND_CHOICES, BATCH_BACKEND)
# Keys of the CPU trainers that a batched (rsl_rl) trial has no use for; 0 or false is allowed,
# as `rehabbot train --backend rsl_rl` allows --eval-freq 0.
CPU_ONLY_KEYS = ("eval_freq", "eval_episodes", "demos", "bc")
# Keys a sweep file may not hold, with what to write instead.
MISNAMED_KEYS = {"num_envs": "n_envs (the batched worlds of backend rsl_rl, as "
                             "`rehabbot train --num-envs` is --n-envs)"}
DEFAULT_OUT = "runs/sweep"
DEFAULT_RESOURCES: dict[str, float] = {"cpu": 1}
RAY_DIR = "_ray"
SWEEP_FILE = "sweep.json"
MAX_VARIANT_CHARS = 80
_UNSAFE = re.compile(r"[^A-Za-z0-9._+=,-]")


class SweepConfigError(UsageError):
    """A sweep file that cannot be read or holds a bad key or value (CLI exit code 2)."""


@contextlib.contextmanager
def naming(where: str) -> Iterator[None]:
    """A :class:`UsageError` raised inside, as a :class:`SweepConfigError` that names
    ``where`` (the file and the setting)."""
    try:
        yield
    except UsageError as err:
        raise SweepConfigError(f"{where}: {err}") from err


@dataclass(frozen=True)
class Trial:
    """One run of the sweep: what :func:`train_run` gets, and where its folder is."""

    env_id: str
    algo: str
    seed: int
    total_timesteps: int
    out_dir: Path
    variant: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    hyperparams: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] | None = None
    n_envs: int | None = None
    eval_freq: int | None = None
    eval_episodes: int | None = None
    checkpoint_freq: int | None = None
    backend: str | None = None
    demos: int | None = None
    bc: bool | None = None

    @property
    def batched(self) -> bool:
        """Whether the trial trains rsl_rl's PPO on the batched env."""
        return self.backend == BATCH_BACKEND

    @property
    def run_dir(self) -> Path:
        """The run folder :func:`train_run` (or :func:`train_batched`) writes."""
        return runs.run_directory(self.out_dir, self.env_id, self.algo, self.seed)

    @property
    def key(self) -> str:
        """``[<variant>/]<env>/<algo>/seed<k>``: the run folder below the sweep's ``out``."""
        parts = [self.variant] if self.variant else []
        return "/".join([*parts, env_short_name(self.env_id), self.algo, f"seed{self.seed}"])

    def build_hyperparameters(self) -> Hyperparameters:
        """The run's settings: the file's entry with the variant's overrides on top, read
        for the backend that trains it here (not for a batched trial:
        :meth:`build_rsl_settings`)."""
        if self.batched:
            raise UsageError(f"{self.key} trains on the {BATCH_BACKEND} backend: its settings "
                             "are build_rsl_settings()")
        return hyperparameters_from_mapping(self.hyperparams["given"], self.algo,
                                            source=self.hyperparams["source"],
                                            entry=self.hyperparams["entry"],
                                            backend=resolve_backend(self.backend or
                                                                    DEFAULT_BACKEND, self.algo))

    def build_rsl_settings(self) -> RslPpoSettings:
        """A batched trial's rsl_rl PPO settings: the file's with the variant's overrides on
        top (:class:`UsageError` naming a bad one)."""
        return RslPpoSettings.from_mapping(self.hyperparams["given"])

    def to_json(self) -> dict[str, Any]:
        """The trial as JSON-able data (the Ray trial's config, an entry of sweep.json)."""
        return {"key": self.key, **jsonable(dataclasses.asdict(self)),
                "out_dir": str(self.out_dir), "run_dir": str(self.run_dir)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Trial:
        """The inverse of :meth:`to_json`."""
        values = {item.name: data[item.name] for item in dataclasses.fields(cls)}
        return cls(**{**values, "out_dir": Path(data["out_dir"])})


@dataclass(frozen=True)
class SweepConfig:
    """A checked sweep file. Per-algorithm settings are dicts keyed by algorithm."""

    source: str
    out: Path
    envs: tuple[str, ...]
    algos: tuple[str, ...]
    seeds: tuple[int, ...]
    timesteps: dict[str, int | None]
    hyperparams: dict[str, str | None]
    grid: dict[str, dict[str, list[Any]]]
    env_kwargs: dict[str, Any] | None
    n_envs: dict[str, int | None]
    backend: dict[str, str | None]
    demos: dict[str, int | None]
    bc: dict[str, bool | None]
    eval_freq: int | None = None
    eval_episodes: int | None = None
    checkpoint_freq: int | None = None
    resources_per_trial: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_RESOURCES))
    raw: dict[str, Any] = field(default_factory=dict)

    def with_out(self, out: str | Path) -> SweepConfig:
        """The same sweep written below ``out`` (the CLI's ``--out``)."""
        return dataclasses.replace(self, out=Path(out).expanduser().absolute(),
                                   raw={**self.raw, "out": str(out)})

    def trials(self) -> list[Trial]:
        """Every trial, in the order env, algorithm, variant, seed.

        Raises:
            SweepConfigError: a hyperparameter file or a grid value that does not load for an
                env and algorithm (the message names them).
        """
        trials: list[Trial] = []
        for env_id in self.envs:
            for algo in self.algos:
                if self.backend[algo] == BATCH_BACKEND:
                    trials += self._batch_trials(env_id, algo)
                    continue
                with naming(f"{self.source}: backend of {algo}"):
                    backend = resolve_backend(self.backend[algo] or DEFAULT_BACKEND, algo)
                with naming(f"{self.source}: hyperparams of {algo} on {env_short_name(env_id)}"):
                    base = as_hyperparameters(self.hyperparams[algo], env_id, algo, backend)
                for variant, overrides in variants(self.grid.get(algo, {})):
                    trials += self._trials_of(env_id, algo, base, backend, variant,
                                              overrides)
        return trials

    def _trials_of(self, env_id: str, algo: str, base: Hyperparameters, backend: str,
                   variant: str | None, overrides: dict[str, Any]) -> list[Trial]:
        source = base.source if variant is None else f"{base.source} [{variant}]"
        given = {**base.given, **jsonable(overrides)}
        with naming(f"{self.source}: grid of {algo} on {env_short_name(env_id)}"):
            hp = hyperparameters_from_mapping(given, algo, source=source, entry=base.entry,
                                              backend=backend)
        total = self.timesteps[algo] or hp.n_timesteps or DEFAULT_TIMESTEPS
        out_dir = self.out / variant if variant else self.out
        return [Trial(env_id=env_id, algo=algo, seed=seed, total_timesteps=total,
                      out_dir=out_dir, variant=variant, overrides=dict(overrides),
                      hyperparams={"source": source, "entry": base.entry, "given": given},
                      env_kwargs=self.env_kwargs, n_envs=self.n_envs[algo],
                      eval_freq=self.eval_freq, eval_episodes=self.eval_episodes,
                      checkpoint_freq=self.checkpoint_freq, backend=self.backend[algo],
                      demos=self.demos[algo], bc=self.bc[algo])
                for seed in self.seeds]


    def _batch_trials(self, env_id: str, algo: str) -> list[Trial]:
        """The trials of a ``backend: rsl_rl`` algorithm on ``env_id``: its settings file (or
        rsl_rl's defaults of :class:`RslPpoSettings`) with each grid variant on top, checked
        here."""
        path = self.hyperparams[algo]
        where = f"{self.source}: hyperparams of {algo} on {env_short_name(env_id)}"
        with naming(where):
            base = read_settings(path, env_id, label="rsl_rl PPO settings file")
            RslPpoSettings.from_mapping(base)
        file_source = path if path is not None else "rsl_rl PPO defaults"
        trials: list[Trial] = []
        for variant, overrides in variants(self.grid.get(algo, {})):
            given = {**jsonable(base), **jsonable(overrides)}
            with naming(f"{self.source}: grid of {algo} on {env_short_name(env_id)}"):
                RslPpoSettings.from_mapping(given)
            source = file_source if variant is None else f"{file_source} [{variant}]"
            trials += [Trial(env_id=env_id, algo=algo, seed=seed,
                             total_timesteps=self.timesteps[algo] or DEFAULT_BATCH_TIMESTEPS,
                             out_dir=self.out / variant if variant else self.out,
                             variant=variant, overrides=dict(overrides),
                             hyperparams={"source": source, "entry": None, "given": given},
                             env_kwargs=self.env_kwargs,
                             n_envs=self.n_envs[algo] or DEFAULT_BATCH_ENVS,
                             checkpoint_freq=self.checkpoint_freq, backend=BATCH_BACKEND)
                       for seed in self.seeds]
        return trials


def variant_name(overrides: Mapping[str, Any]) -> str:
    """``learning_rate=0.001,batch_size=128``: a folder name for a grid point (characters
    other than letters, digits and ``._+=,-`` become ``_``; long names end in a hash)."""
    parts = []
    for key, value in overrides.items():
        text = value if isinstance(value, str) else json.dumps(jsonable(value),
                                                               separators=(",", ":"))
        parts.append(f"{key}={text}")
    name = _UNSAFE.sub("_", ",".join(parts))
    if len(name) > MAX_VARIANT_CHARS:
        name = f"{name[:MAX_VARIANT_CHARS - 9]}-{_digest(name)}"
    return name


def _digest(text: str) -> str:
    return hashlib.sha1(text.encode("utf-8")).hexdigest()[:8]


def variants(grid: Mapping[str, list[Any]]) -> list[tuple[str | None, dict[str, Any]]]:
    """Every combination of the grid's values as (variant name, overrides); one
    ``(None, {})`` without a grid."""
    if not grid:
        return [(None, {})]
    found: list[tuple[str | None, dict[str, Any]]] = []
    for values in itertools.product(*grid.values()):
        overrides = dict(zip(grid, values, strict=True))
        name = variant_name(overrides)
        if name in (other for other, _ in found):  # two values that read the same as a folder
            name = f"{name}-{_digest(json.dumps(jsonable(overrides), sort_keys=True))}"
        found.append((name, overrides))
    return found


# --------------------------------------------------------------------------- parsing


def _count(value: Any, where: str, minimum: int) -> int:
    return as_count(value, where, minimum, SweepConfigError)


def _optional_count(data: Mapping[str, Any], key: str, where: str, minimum: int) -> int | None:
    value = data.get(key)
    return None if value is None else _count(value, f"{where}: {key}", minimum)


def _names(data: Mapping[str, Any], key: str, where: str) -> list[Any]:
    value = data[key]
    if isinstance(value, (str, int)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value:
        raise SweepConfigError(f"{where}: {key} must be a non-empty list, got {value!r}")
    return list(dict.fromkeys(value))


def _check_algo_name(name: Any, where: str) -> str:
    with naming(where):
        return check_algo(name)


def _per_algo(data: Mapping[str, Any], key: str, algos: tuple[str, ...], where: str,
              parse: Any) -> dict[str, Any]:
    """``key: value`` for every algorithm, or ``key: {algo: value, ...}`` (unlisted
    algorithms get None)."""
    value = data.get(key)
    if isinstance(value, Mapping):
        per = {}
        for algo, item in value.items():
            name = _check_algo_name(algo, f"{where}: {key}")
            if name not in algos:
                raise SweepConfigError(f"{where}: {key} names algorithm {name!r}, which is not "
                                       f"in algos ({', '.join(algos)})")
            per[name] = None if item is None else parse(item, f"{where}: {key}.{name}")
        return {algo: per.get(algo) for algo in algos}
    parsed = None if value is None else parse(value, f"{where}: {key}")
    return dict.fromkeys(algos, parsed)


def _settings_name(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise SweepConfigError(f"{where} must be a settings name or a file path, got {value!r}")
    return value


def _backend_choice(value: Any, where: str) -> str:
    with naming(where):
        return one_of(value, SWEEP_BACKENDS, "backend")


def _flag(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise SweepConfigError(f"{where} must be true or false, got {value!r}")
    return value


def _grid_values(grid: Any, where: str) -> dict[str, list[Any]]:
    if not isinstance(grid, Mapping):
        raise SweepConfigError(f"{where} must map hyperparameter names to lists of values, got "
                               f"{grid!r}")
    parsed = {}
    for name, values in grid.items():
        if not isinstance(name, str):
            raise SweepConfigError(f"{where}: hyperparameter names must be strings, got "
                                   f"{name!r}")
        if not isinstance(values, list) or not values:
            raise SweepConfigError(f"{where}.{name} must be a non-empty list of values, got "
                                   f"{values!r}")
        parsed[name] = list(values)
    return parsed


def _grid(data: Mapping[str, Any], algos: tuple[str, ...], where: str
          ) -> dict[str, dict[str, list[Any]]]:
    grid = data.get("grid")
    if grid is None:
        return {}
    if not isinstance(grid, Mapping):
        raise SweepConfigError(f"{where}: grid must be a mapping, got {grid!r}")
    algo_keys = [key for key in grid if isinstance(key, str) and key.lower() in ALGORITHMS]
    if not algo_keys:  # one grid for every algorithm
        values = _grid_values(grid, f"{where}: grid")
        return dict.fromkeys(algos, values) if values else {}
    if len(algo_keys) != len(grid):
        others = [key for key in grid if key not in algo_keys]
        raise SweepConfigError(f"{where}: grid mixes algorithms ({', '.join(algo_keys)}) with "
                               f"hyperparameter names ({', '.join(map(str, others))})")
    per: dict[str, dict[str, list[Any]]] = {}
    for key, values in grid.items():
        algo = key.lower()
        if algo not in algos:
            raise SweepConfigError(f"{where}: grid names algorithm {algo!r}, which is not in "
                                   f"algos ({', '.join(algos)})")
        parsed = _grid_values(values or {}, f"{where}: grid.{algo}")
        if parsed:
            per[algo] = parsed
    return per


def _resources(value: Any, where: str) -> dict[str, float]:
    if value is None:
        return dict(DEFAULT_RESOURCES)
    if not isinstance(value, Mapping) or not value:
        raise SweepConfigError(f"{where}: resources_per_trial must be a mapping such as "
                               f"{{cpu: 1, gpu: 0}}, got {value!r}")
    parsed: dict[str, float] = {}
    for name, amount in value.items():
        number = coerce_number(amount)
        if not isinstance(name, str) or isinstance(number, bool) \
                or not isinstance(number, (int, float)) or number < 0:
            raise SweepConfigError(f"{where}: resources_per_trial.{name} must be a number >= 0, "
                                   f"got {amount!r}")
        parsed[name.lower() if name.lower() in ("cpu", "gpu") else name] = number
    return parsed


def _is_set(value: Any) -> bool:
    """Whether a CPU trainer's key asks for something (0 and false ask for nothing)."""
    return value is not None and value is not False and value != 0


def _check_batch_keys(config: SweepConfig) -> None:
    """Refuse, by name, what a ``backend: rsl_rl`` algorithm cannot do: an algorithm other
    than PPO, and the keys of the CPU trainers (evaluation during training, expert episodes,
    behaviour cloning), which the batched trainer would otherwise ignore."""
    for algo in config.algos:
        if config.backend[algo] != BATCH_BACKEND:
            continue
        if algo != "ppo":
            raise SweepConfigError(f"{config.source}: backend: {BATCH_BACKEND} trains ppo only, "
                                   f"not {algo!r} (give {algo} another backend: "
                                   f"{{backend: {{ppo: {BATCH_BACKEND}, {algo}: auto}}}})")
        asked = {"eval_freq": config.eval_freq, "eval_episodes": config.eval_episodes,
                 "demos": config.demos[algo], "bc": config.bc[algo]}
        for key in CPU_ONLY_KEYS:
            if _is_set(asked[key]):
                raise SweepConfigError(
                    f"{config.source}: {key}={asked[key]!r} is not used by backend "
                    f"{BATCH_BACKEND} of {algo} (the batched trainer neither evaluates during "
                    "training nor learns from expert episodes; evaluate its runs with "
                    "`rehabbot evaluate RUN_DIR`): remove it, or sweep the other algorithms "
                    "in a file of their own")


def parse_sweep_config(data: Any, source: str = "sweep config") -> SweepConfig:
    """Check a sweep's mapping (as read from YAML) and return it as a :class:`SweepConfig`.

    Relative paths (``out``, hyperparameter files) are relative to the current folder, as
    for ``rehabbot train``.

    Raises:
        SweepConfigError: an unknown key, env id or algorithm, a missing key or a bad value;
            the one-line message names it.
    """
    if not isinstance(data, Mapping):
        raise SweepConfigError(f"{source} must hold a mapping of settings, not "
                               f"{type(data).__name__}")
    misnamed = [key for key in data if key in MISNAMED_KEYS]
    if misnamed:
        raise SweepConfigError(f"{source}: unknown key {misnamed[0]!r}: write "
                               f"{MISNAMED_KEYS[misnamed[0]]}")
    unknown = [key for key in data if key not in SWEEP_KEYS]
    if unknown:
        raise SweepConfigError(f"{source}: unknown key {unknown[0]!r} (valid keys: "
                               f"{', '.join(SWEEP_KEYS)})")
    missing = [key for key in REQUIRED_KEYS if key not in data]
    if missing:
        raise SweepConfigError(f"{source}: missing key {missing[0]!r} (required: "
                               f"{', '.join(REQUIRED_KEYS)})")
    with naming(f"{source}: envs"):
        envs = [resolve_env_id(str(name)) for name in _names(data, "envs", source)]
    algos = tuple(dict.fromkeys(_check_algo_name(name, f"{source}: algos")
                                for name in _names(data, "algos", source)))
    seeds = tuple(_count(seed, f"{source}: seeds", 0) for seed in _names(data, "seeds", source))
    env_kwargs = data.get("env_kwargs")
    if env_kwargs is not None and not isinstance(env_kwargs, Mapping):
        raise SweepConfigError(f"{source}: env_kwargs must be a mapping, got {env_kwargs!r}")
    out = data.get("out", DEFAULT_OUT)
    if not isinstance(out, str) or not out:
        raise SweepConfigError(f"{source}: out must be a folder path, got {out!r}")
    config = SweepConfig(
        source=source, out=Path(out).expanduser().absolute(),
        envs=tuple(dict.fromkeys(envs)), algos=algos, seeds=tuple(dict.fromkeys(seeds)),
        timesteps=_per_algo(data, "timesteps", algos, source,
                            lambda value, where: _count(value, where, 1)),
        hyperparams=_per_algo(data, "hyperparams", algos, source, _settings_name),
        grid=_grid(data, algos, source),
        env_kwargs=None if env_kwargs is None else jsonable(dict(env_kwargs)),
        n_envs=_per_algo(data, "n_envs", algos, source,
                         lambda value, where: _count(value, where, 1)),
        backend=_per_algo(data, "backend", algos, source, _backend_choice),
        demos=_per_algo(data, "demos", algos, source,
                        lambda value, where: _count(value, where, 0)),
        bc=_per_algo(data, "bc", algos, source, _flag),
        eval_freq=_optional_count(data, "eval_freq", source, 0),
        eval_episodes=_optional_count(data, "eval_episodes", source, 1),
        checkpoint_freq=_optional_count(data, "checkpoint_freq", source, 0),
        resources_per_trial=_resources(data.get("resources_per_trial"), source),
        raw=jsonable(dict(data)),
    )
    _check_batch_keys(config)
    return config


def load_sweep_config(path: str | Path) -> SweepConfig:
    """Read and check a sweep's YAML file (see :func:`parse_sweep_config`).

    Raises:
        SweepConfigError: the file is missing, unreadable, not YAML, or holds a bad setting.
    """
    return parse_sweep_config(read_yaml(Path(path), "sweep file", SweepConfigError),
                              source=str(path))
