"""The policies that ``rehabbot evaluate`` and ``rehabbot render`` run: a model saved by
Stable-Baselines3, sb3-contrib or SBX (``rehabbot train``), the scripted expert, or uniform
random actions.

=============================== =========================================================
``load_policy(spec, env)``      ``spec`` is ``"expert"``, ``"aan"`` (assist-as-needed),
                                ``"random"`` or the path of an SB3
                                ``.zip`` (the ``.zip`` suffix may be left out, as SB3 allows)
``env_for(specs, env_id, ...)`` the env to run the policies in: ``env_id``, or the id and
                                kwargs of the models' training runs; every spec is checked
                                before any work starts
``RandomPolicy``                uniform actions from the action space, seeded
``zoo:ENV/ALGO``                a spec naming an agent shipped in the zoo
                                (:mod:`rehabbot.rl.zoo`), e.g. ``zoo:rehab-reach-v1/sac``;
                                it runs in the env (and kwargs) it was trained on
=============================== =========================================================

A model is checked against the env before it runs: its observation and action spaces must
equal the env's (:class:`PolicyError` names both otherwise). If the run directory holds
VecNormalize statistics (``vecnormalize.json``), observations are normalised with them. A
model is loaded without unpickling anything (:mod:`rehabbot.rl.safe_load`); a legacy
``vecnormalize.pkl`` is refused with a message that says how to convert it. A
model is loaded with the library of the backend its run's manifest records (``backend``),
else of the one its zip names (:func:`~rehabbot.rl.algorithms.detect_model`).
Stable-Baselines3 (or SBX) is imported only when a model is loaded.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.envs.registration import resolve_env_id
from rehabbot.rl import runs, zoo
from rehabbot.rl.algorithms import (
    BackendUnavailableError,
    PolicyError,
    algo_class,
    detect_algo,
    detect_model,
)
from rehabbot.rl.backends import saved_backend
from rehabbot.rl.safe_load import load_safely
from rehabbot.rl.vecnormalize_io import VecNormalizeStats, read_vecnormalize

POLICY_KEYWORDS = ("expert", "aan", "random")
# The scripted controllers a keyword names: (module, class).
CONTROLLERS = {"expert": ("rehabbot.rl.experts", "ScriptedExpert"),
               "aan": ("rehabbot.rl.assist_as_needed", "AssistAsNeeded")}

__all__ = ["POLICY_KEYWORDS", "LoadedPolicy", "PolicyError", "RandomPolicy", "check_action",
           "check_spaces", "detect_algo", "env_for", "load_model", "load_policy",
           "load_zoo_policy", "model_file"]


class RandomPolicy:
    """Uniform random actions from ``action_space``, seeded; SB3's ``predict`` signature."""

    def __init__(self, action_space: gym.spaces.Box, seed: int | None = None) -> None:
        self.action_space = action_space
        self.action_space.seed(seed)

    def predict(self, observation: np.ndarray, state=None, episode_start=None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.asarray(observation)
        if obs.ndim == 1:
            return self.action_space.sample(), state
        return np.stack([self.action_space.sample() for _ in range(obs.shape[0])]), state


@dataclass
class LoadedPolicy:
    """A policy ready to act, and where it came from."""

    policy: Any  # has SB3's predict(obs, state, episode_start, deterministic)
    label: str  # "expert", "random", or "<algo>" / "<algo>-seed<k>" for a model
    kind: str  # "expert" (a scripted controller: expert, aan), "random", "model" or "zoo"
    algo: str | None = None
    backend: str | None = None  # "sb3" or "sbx" for a model
    model_path: Path | None = None
    run_dir: Path | None = None
    manifest: dict = field(default_factory=dict)
    vecnormalize: VecNormalizeStats | None = None  # the run's observation normalisation
    spec: str | None = None  # what the user named it by: "expert", a path, "module:attr"

    @property
    def name(self) -> str:
        """The policy as a message names it: its label, and the spec it came from when that
        says more (``'Hold' (mymodule:Hold)``)."""
        shown = repr(self.label)
        if self.spec is not None and self.spec != self.label:
            shown += f" ({self.spec})"
        return shown

    def act(self, observation: np.ndarray, deterministic: bool = True,
            action_space: gym.spaces.Box | None = None) -> np.ndarray:
        """One action for one observation.

        The policy's ``predict`` must return ``(action, state)`` with a finite action (of
        ``action_space``'s shape, when given). Anything else, and any exception ``predict``
        raises (``SystemExit`` included), is a :class:`PolicyError` that names the policy;
        Ctrl-C (``KeyboardInterrupt``) passes through.

        Raises:
            PolicyError: naming the policy and what it did.
        """
        if self.vecnormalize is not None:
            observation = self.vecnormalize.normalize_obs(observation)
        try:
            result = self.policy.predict(observation, deterministic=deterministic)
        except SystemExit as err:
            raise PolicyError(f"policy {self.name}: its predict() called exit({err.code!r}); a "
                              "policy must return (action, state), not end the "
                              "program") from err
        except Exception as err:
            raise PolicyError(f"policy {self.name}: its predict() raised "
                              f"{type(err).__name__}: {err}") from err
        return check_action(result, self.name, action_space)

    def describe(self) -> dict:
        """JSON-ready provenance of the policy."""
        return {"label": self.label, "kind": self.kind, "algo": self.algo,
                "backend": self.backend,
                "model_path": str(self.model_path) if self.model_path else None,
                "run_dir": str(self.run_dir) if self.run_dir else None,
                "train_seed": self.manifest.get("seed"),
                "train_timesteps": self.manifest.get("timesteps_done"),
                "obs_normalized": self.vecnormalize is not None}


def _shown(value: Any) -> str:
    """A short description of what a policy returned, for a message."""
    if isinstance(value, np.ndarray):
        return f"a {value.dtype} array of shape {value.shape}"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def check_action(result: Any, name: str,
                 action_space: gym.spaces.Box | None = None) -> np.ndarray:
    """The action of ``result``, what a policy's ``predict`` returned, once checked: a pair
    ``(action, state)`` whose action is a finite numeric array (of ``action_space``'s shape,
    when given).

    Raises:
        PolicyError: naming the policy (``name``) and what it returned instead.
    """
    if not isinstance(result, tuple) or len(result) != 2:
        raise PolicyError(f"policy {name}: predict() returned {_shown(result)}, not a pair "
                          "(action, state); return `action, state` (state may be None), as "
                          "Stable-Baselines3's predict does")
    action = result[0]
    try:
        values = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise PolicyError(f"policy {name}: predict() returned the action {_shown(action)}, "
                          "which is not an array of numbers") from None
    if action_space is not None and values.shape != action_space.shape:
        raise PolicyError(f"policy {name}: predict() returned an action of shape "
                          f"{values.shape}; the env's action space is {action_space}")
    if not np.all(np.isfinite(values)):
        raise PolicyError(f"policy {name}: predict() returned a non-finite action "
                          f"{np.array2string(values, precision=3)}")
    return action


def model_file(spec: str | Path) -> Path:
    """The zip file a model spec names (SB3 accepts the path without ``.zip``)."""
    path = Path(spec)
    if path.is_dir():
        for name in (runs.MODEL_NAME, runs.BATCH_POLICY_NAME):
            if (path / name).is_file():
                return path / name
        raise PolicyError(f"{str(path)!r} is a directory without a model.zip (or the "
                          f"{runs.BATCH_POLICY_NAME} of a batched run)")
    if path.is_file():
        return path
    with_zip = path.with_name(path.name + ".zip")
    if with_zip.is_file():
        return with_zip
    raise PolicyError(f"model file {str(path)!r} not found (give 'expert', 'random' or the path "
                      "of a model .zip saved by `rehabbot train` or Stable-Baselines3)")


def _manifest(run_dir: Path | None) -> dict:
    if run_dir is None:
        return {}
    try:
        return runs.read_manifest(run_dir) or {}
    except ValueError as err:
        raise PolicyError(str(err)) from err


def check_spaces(model_obs: gym.Space, model_act: gym.Space, env: gym.Env, what: str) -> None:
    """Raise :class:`PolicyError` unless the model's spaces are the env's."""
    for name, mine, theirs in (("observation", model_obs, env.observation_space),
                               ("action", model_act, env.action_space)):
        if mine != theirs:
            env_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
            raise PolicyError(f"{what} does not fit {env_id}: its {name} space is {mine}, the "
                              f"env's is {theirs}")


def _load_normalizer(run_dir: Path | None) -> VecNormalizeStats | None:
    """The run's ``vecnormalize.json`` statistics (None without one).

    Raises:
        PolicyError: damaged statistics, or a legacy pickled ``vecnormalize.pkl`` only (it
            is not unpickled; the message says how to convert a trusted one).
    """
    path = runs.stored(run_dir / runs.VECNORMALIZE_NAME) if run_dir is not None else None
    try:
        return read_vecnormalize(path) if path is not None else None
    except DataError as err:
        raise PolicyError(str(err)) from err


def load_model(path: Path, env: gym.Env) -> LoadedPolicy:
    """A model (SB3, sb3-contrib or SBX, or the actor a batched run exported) from ``path``,
    checked against ``env``."""
    if path.suffix == ".npz":
        return _load_exported_actor(path, env)
    algo, backend = detect_model(path)
    run_dir = runs.find_run_dir(path)
    manifest = _manifest(run_dir)
    if manifest.get("backend"):
        backend = saved_backend(manifest)
    try:
        cls = algo_class(algo, backend)
    except BackendUnavailableError as err:
        raise PolicyError(f"cannot load model {str(path)!r}: it was trained with the {backend} "
                          f"backend; {err}") from err
    try:
        with warnings.catch_warnings():
            # SB3 warns that a saved n-step replay buffer class overrides ``n_steps``; acting
            # needs no replay buffer.
            warnings.filterwarnings("ignore", message=".*n_steps.*is ignored because a custom")
            model = load_safely(cls, path, env, algo, backend, manifest, device="cpu")
    except DataError:
        raise
    except Exception as err:  # SB3 raises many kinds on a damaged file
        raise PolicyError(f"cannot load model {str(path)!r}: {type(err).__name__}: "
                          f"{err}") from err
    check_spaces(model.observation_space, model.action_space, env, f"model {str(path)!r}")
    label = model_label(algo, manifest.get("seed"), path)
    return LoadedPolicy(policy=model, label=label, kind="model", algo=algo, backend=backend,
                        model_path=path,
                        run_dir=run_dir, manifest=manifest,
                        vecnormalize=_load_normalizer(run_dir))


def _load_exported_actor(path: Path, env: gym.Env) -> LoadedPolicy:
    """The ``policy.npz`` of a batched run (``--backend rsl_rl``): the deterministic actor in
    the zoo's format, run with NumPy (:mod:`rehabbot.rl.batch_training`)."""
    try:
        policy = zoo.ZooPolicy.from_file(path)
    except zoo.ZooError as err:
        raise PolicyError(str(err)) from err
    check_spaces(policy.observation_space, policy.action_space, env, f"model {str(path)!r}")
    run_dir = runs.find_run_dir(path)
    manifest = _manifest(run_dir)
    algo = policy.algo or str(manifest.get("algo", "ppo"))
    return LoadedPolicy(policy=policy, label=model_label(algo, manifest.get("seed"), path),
                        kind="model", algo=algo,
                        backend=str(policy.metadata.get("backend") or manifest.get("backend")),
                        model_path=path, run_dir=run_dir, manifest=manifest)


def model_label(algo: str, seed: Any, path: Path) -> str:
    """``<algo>`` or ``<algo>-seed<k>``: a folder name, so ``seed`` (read from a manifest)
    must be an integer >= 0.

    Raises:
        PolicyError: another seed (the message names it and the model).
    """
    if seed is None:
        return algo
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise PolicyError(f"the manifest of model {str(path)!r} has seed {seed!r}; a seed must "
                          "be an integer >= 0")
    return f"{algo}-seed{seed}"


def load_policy(spec: str | Path, env: gym.Env, seed: int | None = None) -> LoadedPolicy:
    """``"expert"``, ``"aan"`` (the assist-as-needed controller,
    :mod:`rehabbot.rl.assist_as_needed`), ``"random"`` (seeded with ``seed``) or a model file,
    for ``env``."""
    if str(spec) in CONTROLLERS:
        module, name = CONTROLLERS[str(spec)]
        try:
            controller = getattr(importlib.import_module(module), name)(env)
        except ValueError as err:
            raise PolicyError(str(err)) from err
        return LoadedPolicy(policy=controller, label=str(spec), kind="expert")
    if str(spec) == "random":
        return LoadedPolicy(policy=RandomPolicy(env.action_space, seed), label="random",
                            kind="random")
    if zoo.is_zoo_spec(spec):
        loaded = load_zoo_policy(str(spec), env)
    else:
        loaded = load_model(model_file(spec), env)
    loaded.spec = str(spec)
    return loaded


def env_for(specs: Sequence[str], env_id: str | None = None,
            env_kwargs: dict | None = None) -> tuple[str, dict]:
    """The full env id and kwargs to run every policy of ``specs`` in, checked before any
    work starts: ``env_id`` if given (with or without ``rehabbot/``), else the id of the
    models' ``rehabbot train`` runs, with their env kwargs (``env_kwargs`` override them).

    Raises:
        UsageError: an unknown id; ``expert``/``random`` alone without ``env_id``; models of
            runs on different envs without ``env_id``.
        PolicyError: a model file that is missing or not in a run directory (without
            ``env_id``), or whose manifest is damaged.
    """
    kwargs = dict(env_kwargs or {})
    if env_id is not None:
        resolved = resolve_env_id(env_id)
        for spec in specs:
            if zoo.is_zoo_spec(spec):
                _zoo_env(spec)  # UsageError / ZooError for a bad zoo spec, now
            elif spec not in POLICY_KEYWORDS:
                model_file(spec)  # PolicyError for a missing file, now
        return resolved, kwargs
    found: dict[str, tuple[str, dict]] = {}
    for spec in specs:
        if spec in POLICY_KEYWORDS:
            continue
        if zoo.is_zoo_spec(spec):
            found[spec] = _zoo_env(spec)
            continue
        path = model_file(spec)
        run_dir = runs.find_run_dir(path)
        if run_dir is None:
            raise PolicyError(f"{spec!r} is not in a `rehabbot train` run directory; give "
                              "--env ENV")
        manifest = _manifest(run_dir)
        found[spec] = (str(manifest["env_id"]), dict(manifest.get("env_kwargs") or {}))
    if not found:
        raise UsageError(f"{' and '.join(repr(s) for s in specs)} need(s) --env ENV (or a "
                         "model of a `rehabbot train` run to take it from)")
    ids = {env for env, _ in found.values()}
    if len(ids) > 1:
        listing = ", ".join(f"{spec}: {env}" for spec, (env, _) in found.items())
        raise UsageError(f"the models were trained on different envs ({listing}); give --env "
                         "ENV to run them all in one")
    saved = [saved for _, saved in found.values()]
    if env_kwargs is None and any(other != saved[0] for other in saved[1:]):
        listing = ", ".join(f"{spec}: {kw}" for spec, (_, kw) in found.items())
        raise UsageError(f"the models were trained with different env kwargs ({listing}); "
                         "give --env-kwargs to run them all in the same env")
    return resolve_env_id(ids.pop()), {**saved[0], **kwargs}


# --------------------------------------------------------------------------- zoo agents
# ``zoo:ENV/ALGO`` specs (rehabbot.rl.zoo): NumPy actors shipped with the package.


def _zoo_env(spec: str) -> tuple[str, dict]:
    """The env id and kwargs a zoo agent was trained with."""
    policy = zoo.load_spec(spec)
    return policy.env_id, dict(policy.metadata.get("env_kwargs") or {})


def load_zoo_policy(spec: str, env: gym.Env) -> LoadedPolicy:
    """The zoo agent of ``spec`` (``zoo:ENV/ALGO``), checked against ``env``."""
    policy = zoo.load_spec(spec)
    check_spaces(policy.observation_space, policy.action_space, env, f"zoo agent {spec!r}")
    meta = policy.metadata
    return LoadedPolicy(policy=policy, label=f"zoo-{policy.algo}", kind="zoo",
                        algo=policy.algo, model_path=policy.path,
                        manifest={"seed": meta.get("seed"),
                                  "timesteps_done": meta.get("training_steps")})
