"""VecNormalize statistics as JSON, never pickle.

Stable-Baselines3's ``VecNormalize.save`` pickles the whole wrapper, and unpickling a file
runs whatever code it names: a run folder from elsewhere could run a command through
``evaluate`` or ``train --resume``. Here only the numbers are written (running means,
variances and counts, clipping, gamma, epsilon, the switches) as JSON, and read back into a
fresh ``VecNormalize`` (:func:`load_vecnormalize`) or as plain arrays
(:func:`read_vecnormalize`).

Run folders of earlier versions hold ``vecnormalize.pkl``; they are refused with a message
that says how to convert them (:func:`convert_legacy_pickle`, for a file you trust).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError
from rehabbot.common.files import atomic_write_json

FORMAT = "rehabbot-vecnormalize"
FORMAT_VERSION = 1
LEGACY_SUFFIX = ".pkl"


@dataclass
class VecNormalizeStats:
    """What a VecNormalize wrapper needs: the switches, the constants, the running stats."""

    norm_obs: bool
    norm_reward: bool
    clip_obs: float
    clip_reward: float
    gamma: float
    epsilon: float
    obs_mean: np.ndarray
    obs_var: np.ndarray
    obs_count: float
    ret_mean: float
    ret_var: float
    ret_count: float

    def normalize_obs(self, observation: np.ndarray) -> np.ndarray:
        """``clip((obs - mean) / sqrt(var + epsilon), ±clip_obs)`` as VecNormalize does."""
        obs = np.asarray(observation, dtype=np.float64)
        if not self.norm_obs:
            return obs.astype(np.float32)
        scaled = (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs).astype(np.float32)


def save_vecnormalize(venv: Any, path: str | Path) -> None:
    """Write the statistics of ``venv`` (a ``VecNormalize`` of Box observations) to ``path``
    as JSON (atomically)."""
    def rms(stats: Any) -> dict[str, Any]:  # a float vector (observations) or float (returns)
        return {"mean": np.asarray(stats.mean, dtype=np.float64).tolist(),
                "var": np.asarray(stats.var, dtype=np.float64).tolist(),
                "count": float(stats.count)}

    atomic_write_json(Path(path), {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "norm_obs": bool(venv.norm_obs), "norm_reward": bool(venv.norm_reward),
        **{key: float(getattr(venv, key)) for key in ("clip_obs", "clip_reward", "gamma",
                                                      "epsilon")},
        "obs_rms": rms(venv.obs_rms), "ret_rms": rms(venv.ret_rms)})


def _number(data: dict[str, Any], key: str, path: Path) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise DataError(f"{path} is not a VecNormalize statistics file: {key} is {value!r}")
    return float(value)


def _vector(values: Any, key: str, path: Path) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DataError(f"{path} is not a VecNormalize statistics file: {key}: {err}") from err
    if array.ndim != 1 or not np.all(np.isfinite(array)):
        raise DataError(f"{path} is not a VecNormalize statistics file: {key} is not a finite "
                        "vector")
    return array


def read_vecnormalize(path: str | Path) -> VecNormalizeStats:
    """The statistics in a file of :func:`save_vecnormalize`.

    Raises:
        DataError: a legacy ``.pkl`` (not read: it is code), or a file that is not such a
            JSON file; the message names it.
    """
    path = Path(path)
    if path.suffix == LEGACY_SUFFIX:
        raise DataError(  # a pickle is code
            f"{path} is a pickled VecNormalize file of an earlier RehabBot; loading a pickle "
            "runs code, so it is not read. If you trust the file, convert it once with: python "
            f"-c \"from rehabbot.rl.vecnormalize_io import convert_legacy_pickle as c; "
            f"c('{path}')\"")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataError(f"cannot read VecNormalize statistics {path}: {err}") from err
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise DataError(f"{path} is not a VecNormalize statistics file of RehabBot")
    obs, ret = data.get("obs_rms"), data.get("ret_rms")
    if not isinstance(obs, dict) or not isinstance(ret, dict):
        raise DataError(f"{path} is not a VecNormalize statistics file: no obs_rms/ret_rms")
    mean, var = _vector(obs.get("mean"), "obs_rms.mean", path), _vector(
        obs.get("var"), "obs_rms.var", path)
    if mean.shape != var.shape:
        raise DataError(f"{path}: obs_rms.mean and obs_rms.var differ in length")
    return VecNormalizeStats(
        norm_obs=bool(data.get("norm_obs")), norm_reward=bool(data.get("norm_reward")),
        clip_obs=_number(data, "clip_obs", path), clip_reward=_number(data, "clip_reward", path),
        gamma=_number(data, "gamma", path), epsilon=_number(data, "epsilon", path),
        obs_mean=mean, obs_var=var, obs_count=_number(obs, "count", path),
        ret_mean=_number(ret, "mean", path), ret_var=_number(ret, "var", path),
        ret_count=_number(ret, "count", path))


def load_vecnormalize(path: str | Path, venv: Any) -> Any:
    """A ``VecNormalize`` around ``venv`` with the statistics of ``path`` (training on).

    Raises:
        DataError: as :func:`read_vecnormalize`, or statistics whose length differs from the
            observation's.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    stats = read_vecnormalize(path)
    wrapper = VecNormalize(venv, norm_obs=stats.norm_obs, norm_reward=stats.norm_reward,
                           clip_obs=stats.clip_obs, clip_reward=stats.clip_reward,
                           gamma=stats.gamma, epsilon=stats.epsilon)
    if stats.obs_mean.shape != np.shape(wrapper.obs_rms.mean):
        raise DataError(f"{path}: statistics for {stats.obs_mean.shape[0]} observation values, "
                        f"the env has {np.shape(wrapper.obs_rms.mean)}")
    wrapper.obs_rms.mean, wrapper.obs_rms.var = stats.obs_mean.copy(), stats.obs_var.copy()
    wrapper.obs_rms.count = stats.obs_count
    wrapper.ret_rms.mean, wrapper.ret_rms.var = np.float64(stats.ret_mean), np.float64(
        stats.ret_var)
    wrapper.ret_rms.count = stats.ret_count
    return wrapper


def convert_legacy_pickle(path: str | Path) -> Path:
    """Convert a trusted ``vecnormalize*.pkl`` of an earlier version to JSON beside it;
    returns the new file. UNPICKLES ``path``: only for files you made yourself."""
    import pickle

    path = Path(path)
    with open(path, "rb") as handle:
        venv = pickle.load(handle)  # the caller trusts this file (see the docstring)
    target = path.with_suffix(".json")
    save_vecnormalize(venv, target)
    return target
