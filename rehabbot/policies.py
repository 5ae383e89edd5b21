"""The policies that ``rehabbot evaluate`` and ``rehabbot render`` run: a model saved by
Stable-Baselines3 (``rehabbot train``), the scripted expert, or uniform random actions.

=========================== =============================================================
``load_policy(spec, env)``  ``spec`` is ``"expert"``, ``"random"`` or the path of an SB3
                            ``.zip`` (the ``.zip`` suffix may be left out, as SB3 allows)
``detect_algo(path)``       ``"ppo"``, ``"sac"`` or ``"td3"``, read from the zip's metadata
``find_run_dir(path)``      the ``rehabbot train`` run directory a model file belongs to
``RandomPolicy``            uniform actions from the action space, seeded
=========================== =============================================================

A model is checked against the env before it runs: its observation and action spaces must
equal the env's (:class:`PolicyError` names both otherwise). If the run directory holds
VecNormalize statistics (``vecnormalize.pkl``), observations are normalised with them.
Stable-Baselines3 is imported only when a model is loaded.
"""

from __future__ import annotations

import json
import pickle
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

POLICY_KEYWORDS = ("expert", "random")
ALGORITHMS = ("ppo", "sac", "td3")
RUN_MANIFEST = "manifest.json"
VECNORMALIZE_FILE = "vecnormalize.pkl"


class PolicyError(ValueError):
    """A policy cannot be loaded or does not fit the env; the message says why."""


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
    kind: str  # "expert", "random" or "model"
    algo: str | None = None
    model_path: Path | None = None
    run_dir: Path | None = None
    manifest: dict = field(default_factory=dict)
    normalize_obs: Callable[[np.ndarray], np.ndarray] | None = None

    def act(self, observation: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """One action for one observation."""
        if self.normalize_obs is not None:
            observation = self.normalize_obs(observation)
        action, _ = self.policy.predict(observation, deterministic=deterministic)
        return action

    def describe(self) -> dict:
        """JSON-ready provenance of the policy."""
        return {"label": self.label, "kind": self.kind, "algo": self.algo,
                "model_path": str(self.model_path) if self.model_path else None,
                "run_dir": str(self.run_dir) if self.run_dir else None,
                "train_seed": self.manifest.get("seed"),
                "train_timesteps": self.manifest.get("timesteps_done"),
                "obs_normalized": self.normalize_obs is not None}


def model_file(spec: str | Path) -> Path:
    """The zip file a model spec names (SB3 accepts the path without ``.zip``)."""
    path = Path(spec)
    if path.is_dir():
        if (path / "model.zip").is_file():
            return path / "model.zip"
        raise PolicyError(f"{str(path)!r} is a directory without a model.zip")
    if path.is_file():
        return path
    with_zip = path.with_name(path.name + ".zip")
    if with_zip.is_file():
        return with_zip
    raise PolicyError(f"model file {str(path)!r} not found (give 'expert', 'random' or the path "
                      "of a model .zip saved by `rehabbot train` or Stable-Baselines3)")


def detect_algo(path: Path) -> str:
    """The SB3 algorithm that saved ``path``, from the arguments in the zip's metadata."""
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError,
            OSError) as err:
        raise PolicyError(f"{str(path)!r} is not a Stable-Baselines3 model zip "
                          f"({type(err).__name__}: {err})") from err
    # Each algorithm saves its own constructor arguments: they tell the three apart.
    signatures = {"td3": ("policy_delay", "target_policy_noise"),
                  "sac": ("target_entropy", "ent_coef"),
                  "ppo": ("clip_range", "n_epochs")}
    for algo, keys in signatures.items():
        if all(key in data for key in keys):
            return algo
    policy_class = data.get("policy_class", {})
    module = policy_class.get("__module__", "") if isinstance(policy_class, dict) else ""
    raise PolicyError(f"{str(path)!r} was saved by an algorithm rehabbot does not run "
                      f"(policy module {module!r}); supported: {list(ALGORITHMS)}")


def find_run_dir(path: Path) -> Path | None:
    """The ``rehabbot train`` run directory of a model (its own or its parent folder, for
    ``checkpoints/``), recognised by its manifest; None for a loose model file."""
    for folder in (path.parent, path.parent.parent):
        if (folder / RUN_MANIFEST).is_file():
            return folder
    return None


def _read_manifest(run_dir: Path | None) -> dict:
    if run_dir is None:
        return {}
    try:
        return json.loads((run_dir / RUN_MANIFEST).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise PolicyError(f"corrupt run manifest {str(run_dir / RUN_MANIFEST)!r}: {err}") from err


def _algorithm_class(algo: str):
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]


def check_spaces(model_obs: gym.Space, model_act: gym.Space, env: gym.Env, what: str) -> None:
    """Raise :class:`PolicyError` unless the model's spaces are the env's."""
    for name, mine, theirs in (("observation", model_obs, env.observation_space),
                               ("action", model_act, env.action_space)):
        if mine != theirs:
            env_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
            raise PolicyError(f"{what} does not fit {env_id}: its {name} space is {mine}, the "
                              f"env's is {theirs}")


def _load_normalizer(run_dir: Path | None) -> Callable[[np.ndarray], np.ndarray] | None:
    if run_dir is None or not (run_dir / VECNORMALIZE_FILE).is_file():
        return None
    try:
        with open(run_dir / VECNORMALIZE_FILE, "rb") as handle:
            stats = pickle.load(handle)
        stats.training = False
        return stats.normalize_obs
    except Exception as err:
        raise PolicyError(f"corrupt normalisation statistics "
                          f"{str(run_dir / VECNORMALIZE_FILE)!r}: {err}") from err


def load_model(path: Path, env: gym.Env) -> LoadedPolicy:
    """An SB3 model from ``path``, checked against ``env``."""
    algo = detect_algo(path)
    run_dir = find_run_dir(path)
    manifest = _read_manifest(run_dir)
    try:
        with warnings.catch_warnings():
            # SB3 warns that a saved n-step replay buffer class overrides ``n_steps``; acting
            # needs no replay buffer.
            warnings.filterwarnings("ignore", message=".*n_steps.*is ignored because a custom")
            model = _algorithm_class(algo).load(path, device="cpu")
    except Exception as err:  # SB3 raises many kinds on a damaged file
        raise PolicyError(f"cannot load model {str(path)!r}: {type(err).__name__}: "
                          f"{err}") from err
    check_spaces(model.observation_space, model.action_space, env, f"model {str(path)!r}")
    seed = manifest.get("seed")
    label = algo if seed is None else f"{algo}-seed{seed}"
    return LoadedPolicy(policy=model, label=label, kind="model", algo=algo, model_path=path,
                        run_dir=run_dir, manifest=manifest,
                        normalize_obs=_load_normalizer(run_dir))


def load_policy(spec: str | Path, env: gym.Env, seed: int | None = None) -> LoadedPolicy:
    """``"expert"``, ``"random"`` (seeded with ``seed``) or a model file, for ``env``."""
    if str(spec) == "expert":
        from rehabbot.experts import ScriptedExpert

        try:
            expert = ScriptedExpert(env)
        except ValueError as err:
            raise PolicyError(str(err)) from err
        return LoadedPolicy(policy=expert, label="expert", kind="expert")
    if str(spec) == "random":
        return LoadedPolicy(policy=RandomPolicy(env.action_space, seed), label="random",
                            kind="random")
    return load_model(model_file(spec), env)
