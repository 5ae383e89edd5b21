"""Saving and loading models without unpickling anything.

A Stable-Baselines3 zip keeps the algorithm's attributes in its ``data`` entry as JSON, and
every attribute JSON cannot hold (spaces, schedules, classes, SBX's networks) as a base64
cloudpickle: loading such a zip runs whatever code the pickle names. RehabBot therefore:

* loads with SB3's ``custom_objects`` for **every** pickled entry of ``data``, so SB3 never
  unpickles one: spaces come from the env, the policy class is the algorithm's own that the
  zip names in its readable metadata, schedules and settings are rebuilt from the run's
  manifest (``hyperparameters.given``, the same settings that built the model) or the
  algorithm's defaults; an entry it cannot rebuild is refused (:class:`DataError` naming it).
  The weights (``*.pth``) are read by PyTorch with ``weights_only=True``;
* saves SBX (JAX) models without their pickled networks: the train states (parameters,
  optimiser states, step counts) go into the zip as a msgpack entry (:data:`JAX_STATE_ENTRY`,
  plain arrays, read with flax's msgpack reader), and the networks are rebuilt on loading.

SBX zips of earlier versions, and zips made elsewhere with pickled networks, are refused:
their weights are a pickle, i.e. code.
"""

from __future__ import annotations

import inspect
import io
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, RehabbotError
from rehabbot.rl.algorithms import (
    ALGORITHMS,
    PolicyError,
    read_model_data,
    saved_policy_class,
)
from rehabbot.rl.hyperparam_checks import SCHEDULE_KEYS

JAX_STATE_ENTRY = "rehabbot_jax_state.msgpack"
# Attributes of SBX models that are networks or JAX states (pickled by SB3): not saved in
# ``data``; the networks are rebuilt by the model's setup, the states come from the msgpack.
SBX_EXCLUDED = ("policy", "actor", "qf", "vf", "ent_coef", "ent_coef_state", "key")
SBX_MODEL_STATES = ("ent_coef_state",)
SPACE_KEYS = ("observation_space", "action_space")
# Where training stopped (last observation, episode statistics): the next ``learn`` resets
# the env and starts the statistics afresh when they are None.
RUNTIME_KEYS = ("_last_obs", "_last_episode_starts", "_last_original_obs", "ep_info_buffer",
                "ep_success_buffer")
SETTING_KEYS = ("replay_buffer_class", "rollout_buffer_class", "train_freq", "target_entropy",
                "policy_kwargs", "replay_buffer_kwargs", "rollout_buffer_kwargs")


def action_noise(hp_block: Mapping[str, Any], n_actions: int) -> Any:
    """The exploration noise of a run's ``hyperparameters`` block (None without one)."""
    import numpy as np
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    noise_type, std = hp_block.get("noise_type"), hp_block.get("noise_std")
    if noise_type is None:
        return None
    mean, sigma = np.zeros(n_actions), float(std) * np.ones(n_actions)
    if noise_type == "normal":
        return NormalActionNoise(mean=mean, sigma=sigma)
    return OrnsteinUhlenbeckActionNoise(mean=mean, sigma=sigma)


def is_sbx(model_or_class: Any) -> bool:
    cls = model_or_class if isinstance(model_or_class, type) else type(model_or_class)
    return cls.__module__.split(".")[0] == "sbx"


# --------------------------------------------------------------------------- saving


def _jax_train_states(owner: Any) -> dict[str, Any]:
    from flax.training.train_state import TrainState

    return {name: value for name, value in vars(owner).items()
            if isinstance(value, TrainState)}


def _jax_state(model: Any) -> dict[str, Any]:
    from flax import serialization

    state: dict[str, Any] = {"policy": {name: serialization.to_state_dict(value) for name, value
                                        in _jax_train_states(model.policy).items()}}
    for name in SBX_MODEL_STATES:
        if getattr(model, name, None) is not None:
            state[name] = serialization.to_state_dict(getattr(model, name))
    return state


def save_model(model: Any, stream: io.BufferedIOBase) -> None:
    """Write ``model`` as an SB3 zip to ``stream``; an SBX model's networks as plain arrays
    (:data:`JAX_STATE_ENTRY`) instead of SB3's pickle."""
    if not is_sbx(model):
        model.save(stream)
        return
    from flax import serialization

    buffer = io.BytesIO()
    model.save(buffer, exclude=[name for name in SBX_EXCLUDED if name in vars(model)])
    with zipfile.ZipFile(buffer, "a") as archive:
        archive.writestr(JAX_STATE_ENTRY, serialization.msgpack_serialize(_jax_state(model)))
    stream.write(buffer.getvalue())


# --------------------------------------------------------------------------- loading


def pickled_entries(data: Mapping[str, Any]) -> list[str]:
    """The keys of ``data`` that SB3 would unpickle (cloudpickle) when loading."""
    return sorted(key for key, value in data.items()
                  if isinstance(value, dict) and ":serialized:" in value)


def _saved_hyperparameters(algo: str, backend: str, manifest: Mapping[str, Any] | None) -> Any:
    """The run's hyperparameters rebuilt from its manifest (what the user gave), else the
    defaults; classes only from the packages the settings files may name."""
    from rehabbot.rl.hyperparams import hyperparameters_from_mapping

    block = (manifest or {}).get("hyperparameters") or {}
    given = dict(block.get("given") or {}) if isinstance(block, Mapping) else {}
    try:
        return hyperparameters_from_mapping(given, algo, source="the run's manifest",
                                            backend=backend)
    except (RehabbotError, ValueError, TypeError) as err:
        raise DataError(f"cannot rebuild the model's settings from its manifest: {err}") \
            from err


def _policy_class_from_data(cls: Any, data: Mapping[str, Any]) -> Any:
    """The policy class a zip names in its readable metadata: one of the algorithm's own
    (``policy_aliases``) by its name, else its MlpPolicy."""
    name = saved_policy_class(data)[1].rpartition(".")[2]
    own = {policy.__name__: policy for policy in cls.policy_aliases.values()}
    return own.get(name, cls.policy_aliases["MlpPolicy"])


def _default(cls: Any, key: str) -> Any:
    parameter = inspect.signature(cls.__init__).parameters.get(key)
    if parameter is None or parameter.default is inspect.Parameter.empty:
        return None
    return parameter.default


def _readable_bound(text: Any, dtype: Any) -> Any:
    """A Box bound from SB3's readable copy (numpy's ``str`` of the array, 8 decimals);
    None if it is not there or summarised (``...``)."""
    import numpy as np

    if not isinstance(text, str) or "..." in text:
        return None
    try:
        return np.array(text.replace("[", " ").replace("]", " ").split(), dtype=dtype)
    except (TypeError, ValueError):
        return None


def _check_space(path: Path, key: str, saved: Any, space: Any, env_name: str) -> None:
    """Refuse a model whose saved space (SB3's readable copy of it) is not the env's."""
    import numpy as np

    saved = saved if isinstance(saved, dict) else {}
    shape, dtype = saved.get("_shape"), saved.get("dtype")
    fits = shape is not None and tuple(shape) == tuple(getattr(space, "shape", None) or ()) \
        and (dtype is None or str(dtype) == str(getattr(space, "dtype", dtype)))
    for bound in ("low", "high"):
        value = _readable_bound(saved.get(bound), getattr(space, "dtype", None))
        mine = getattr(space, bound, None)
        if fits and value is not None and mine is not None:
            # numpy prints 8 decimals: equal up to that rounding
            fits = value.size == np.size(mine) and np.allclose(
                value.reshape(np.shape(mine)), mine, rtol=1e-6, atol=1e-8)
    if not fits:
        name = key.replace("_space", "")
        raise PolicyError(f"model {str(path)!r} does not fit {env_name}: its {name} space is "
                          f"not the env's (saved shape {shape}, {dtype}; the env's is "
                          f"{space})")


def safe_custom_objects(cls: Any, path: Path, data: Mapping[str, Any], env: Any, algo: str,
                        backend: str, manifest: Mapping[str, Any] | None) -> dict[str, Any]:
    """A replacement for every pickled entry of ``data`` (SB3's ``custom_objects``).

    Raises:
        DataError: an entry that cannot be rebuilt (it would have been unpickled: code).
        PolicyError: the saved spaces do not fit ``env``.
    """
    from stable_baselines3.common.utils import FloatSchedule

    hp = _saved_hyperparameters(algo, backend, manifest)
    spec = getattr(env, "spec", None)
    env_name = spec.id if spec is not None else type(env).__name__
    replacements: dict[str, Any] = {}
    for key in pickled_entries(data):
        if key in SPACE_KEYS:
            space = getattr(env, key)
            _check_space(path, key, data[key], space, env_name)
            replacements[key] = space
        elif key == "policy_class":
            replacements[key] = _policy_class_from_data(cls, data)
        elif key in SCHEDULE_KEYS or key == "lr_schedule" or key == "clip_range_schedule":
            source = {"lr_schedule": "learning_rate",
                      "clip_range_schedule": "clip_range"}.get(key, key)
            value = hp.kwargs.get(source, _default(cls, source))
            replacements[key] = FloatSchedule(value) if key.endswith("_schedule") \
                and value is not None else value
        elif key in RUNTIME_KEYS:
            replacements[key] = None
        elif key in SETTING_KEYS:
            replacements[key] = hp.kwargs.get(key, _default(cls, key))
        elif key == "action_noise":
            replacements[key] = action_noise(hp.to_manifest(), int(env.action_space.shape[0]))
        else:
            raise DataError(
                f"refusing to load {path}: its entry {key!r} is a Python pickle, which would "
                "run code when loaded; RehabBot loads model zips without unpickling (models "
                "saved by this version of `rehabbot train` load fine; see 'Run folders are "
                "data' in the README)")
    return replacements


def _restore_jax_state(model: Any, path: Path) -> None:
    import numpy as np
    from flax import serialization
    from jax import tree_util

    try:
        with zipfile.ZipFile(path) as archive:
            state = serialization.msgpack_restore(archive.read(JAX_STATE_ENTRY))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as err:
        raise DataError(f"{path}: no readable {JAX_STATE_ENTRY} ({err}); SBX models of "
                        "earlier versions hold their networks as a pickle and are not "
                        "loaded") from err

    def restored(target: Any, saved: Any, where: str) -> Any:
        try:
            value = serialization.from_state_dict(target, saved)
        except (ValueError, KeyError, TypeError) as err:
            raise DataError(f"{path}: {where} does not fit the model: {err}") from err
        for mine, theirs in zip(tree_util.tree_leaves(target), tree_util.tree_leaves(value),
                                strict=True):
            if np.shape(mine) != np.shape(theirs):
                raise DataError(f"{path}: {where} holds an array of shape {np.shape(theirs)} "
                                f"where the model has {np.shape(mine)}")
        return value

    saved_policy = state.get("policy") if isinstance(state, dict) else None
    targets = _jax_train_states(model.policy)
    if not isinstance(saved_policy, dict) or set(saved_policy) != set(targets):
        raise DataError(f"{path}: {JAX_STATE_ENTRY} holds {sorted(saved_policy or {})}, the "
                        f"model has {sorted(targets)}")
    for name, target in targets.items():
        setattr(model.policy, name, restored(target, saved_policy[name], f"policy.{name}"))
    for name in SBX_MODEL_STATES:
        if getattr(model, name, None) is not None and name in state:
            setattr(model, name, restored(getattr(model, name), state[name], name))


def load_safely(cls: Any, path: Path, env: Any, algo: str, backend: str,
                manifest: Mapping[str, Any] | None, **load_kwargs: Any) -> Any:
    """``cls.load(path, env, ...)`` without unpickling anything; ``env`` gives the spaces
    (a gym env or a VecEnv; ``load_kwargs`` go to ``cls.load``).

    Raises:
        DataError: a pickled entry that cannot be rebuilt, an SBX zip without its plain
            state, a damaged file; PolicyError: spaces that do not fit ``env``.
    """
    path = Path(path)
    data = read_model_data(path)  # PolicyError: unreadable, or a removed policy class
    custom = safe_custom_objects(cls, path, data, env, algo, backend, manifest)
    model = cls.load(path, env=env, custom_objects=custom, **load_kwargs)
    if is_sbx(cls):
        _restore_jax_state(model, path)
    return model


def load_run_model(cls: Any, path: Path, venv: Any, manifest: Mapping[str, Any] | None,
                   **load_kwargs: Any) -> Any:
    """A checkpoint of a run for training on (``venv``), loaded by :func:`load_safely`."""
    algo = str((manifest or {}).get("algo", ""))
    if algo not in ALGORITHMS:
        raise DataError(f"cannot load {path}: its run's manifest names algorithm {algo!r}")
    backend = "sbx" if is_sbx(cls) else "sb3"
    return load_safely(cls, path, venv, algo, backend, manifest, **load_kwargs)
