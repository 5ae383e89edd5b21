"""Settings files for the SBX backend: the same RL-Zoo-style files as for Stable-Baselines3,
with what only PyTorch can run translated or dropped, and every change listed.

A settings file is written for Stable-Baselines3 (RL Zoo reads the shipped ones unchanged),
so :func:`rehabbot.rl.hyperparams.hyperparameters_from_mapping` reads it for SBX with these
rules, and the run's manifest lists each change (``hyperparameters.backend_changes``: the key,
what was given, what is used instead or ``null`` when dropped, and why):

- ``policy``, a PyTorch policy class (SB3's or sb3-contrib's): SBX's ``MlpPolicy`` (the SBX
  network reads the observation as it is).
- ``policy_kwargs``:

  - ``features_extractor_class/_kwargs``: dropped (SBX's MLP policies have no extractor);
  - ``activation_fn`` (``nn.ReLU``, …): the Flax function of the same name
    (``flax.linen.relu``);
  - ``optimizer_class`` (``optim.Adam``): the Optax optimizer (``optax.adam``); its kwargs
    renamed (``betas`` -> ``b1``, ``b2``; ``alpha`` -> ``decay``) or dropped if Optax has no
    such argument;
  - ``batch_norm_momentum`` (CrossQ): ``1 - m``: PyTorch weighs the new batch by ``m`` (SB3's
    default 0.01), Flax the running average (SBX's 0.99);
  - any other key SBX's policy lacks: dropped (e.g. PPO's ``full_std``, CrossQ's
    ``batch_norm_eps``).

- an SB3 constructor argument that SBX's class lacks: dropped (SAC/TQC
  ``target_update_interval``: SBX updates the target networks every gradient step;
  ``optimize_memory_usage``; PPO's ``stats_window_size``).

Everything else means the same on both backends and is kept, including ``n_steps`` (n-step
returns: SBX uses SB3's n-step replay buffer), ``train_freq``/``gradient_steps`` (SBX runs the
gradient steps of one call in a single compiled loop), ``normalize`` and the action noise.
Keys only SBX has (``qf_learning_rate``, ``policy_delay`` for SAC, ``param_resets``,
``layer_norm``/``dropout_rate`` in ``policy_kwargs``) are accepted on the SBX backend only.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

from rehabbot.rl.hyperparam_checks import jsonable

TORCH_POLICY_PACKAGES = ("stable_baselines3", "sb3_contrib")
SBX_POLICY = "MlpPolicy"
EXTRACTOR_KEYS = ("features_extractor_class", "features_extractor_kwargs")
# policy_kwargs key -> (JAX module, its names of the torch classes, what they are, SBX's default)
JAX_EQUIVALENTS = {
    "activation_fn": ("flax.linen", {"ReLU": "relu", "Tanh": "tanh", "ELU": "elu",
                                     "LeakyReLU": "leaky_relu", "SiLU": "silu", "GELU": "gelu"},
                      "Flax function", "SBX's default activation"),
    "optimizer_class": ("optax", {"Adam": "adam", "AdamW": "adamw", "RMSprop": "rmsprop",
                                  "SGD": "sgd"}, "Optax optimizer", "SBX's default (optax.adam)"),
}
OPTIMIZER_RENAMES = {"alpha": "decay"}  # torch.optim.RMSprop(alpha) is optax.rmsprop(decay)
KEY_REASONS = {
    "target_update_interval": "SBX updates the target networks after every gradient step",
    "optimize_memory_usage": "SBX's replay buffer has no memory-optimised variant",
    "stats_window_size": "SBX's PPO has no such argument (it keeps the last 100 episodes)",
}


def change(key: str, given: Any, used: Any, why: str) -> dict[str, Any]:
    """One entry of the manifest's ``backend_changes`` (``used`` None: dropped)."""
    return {"key": key, "given": jsonable(given), "used": jsonable(used), "why": why}


def is_torch_policy(raw: Any) -> bool:
    """Whether a ``policy`` value names a PyTorch policy class (a dotted name under
    stable_baselines3 or sb3_contrib, or such a class itself)."""
    if isinstance(raw, type):
        return raw.__module__.split(".")[0] in TORCH_POLICY_PACKAGES
    return isinstance(raw, str) and "." in raw.strip(". ") and \
        raw.strip().split(".")[0] in TORCH_POLICY_PACKAGES


def policy_change(raw: Any) -> dict[str, Any]:
    """The change record for a PyTorch ``policy`` replaced by SBX's MlpPolicy."""
    return change("policy", raw, SBX_POLICY,
                  "a PyTorch policy class cannot run on JAX; SBX's MlpPolicy takes its place "
                  "(without a features extractor: the network reads the observation as it is)")


def dropped_key_reason(key: str, algo: str) -> str | None:
    """Why an SB3 constructor argument that SBX's class lacks is dropped; None if ``key`` is
    not an argument of the SB3 class either (then it is simply unknown)."""
    from rehabbot.rl.algorithms import ALGO_NAMES, BackendUnavailableError, algo_class

    try:
        sb3_params = inspect.signature(algo_class(algo, "sb3").__init__).parameters
    except BackendUnavailableError:
        return None
    if key not in sb3_params or key == "self":
        return None
    return KEY_REASONS.get(key, f"an argument of Stable-Baselines3's {ALGO_NAMES[algo]} that "
                                f"SBX's {ALGO_NAMES[algo]} does not have")


def _jax_equivalent(key: str, value: Any) -> Any | None:
    """The Flax activation or Optax optimizer of a torch class (None: none of that name)."""
    module, names, _, _ = JAX_EQUIVALENTS[key]
    name = names.get(getattr(value, "__name__", ""))
    return None if name is None else getattr(importlib.import_module(module), name)


def _is_torch(value: Any) -> bool:
    return isinstance(value, type) and value.__module__.split(".")[0] == "torch"


def _optimizer_kwargs(given: dict[str, Any], optimizer: Any,
                      changes: list[dict[str, Any]]) -> dict[str, Any]:
    """Torch optimizer arguments as Optax's (``betas`` -> ``b1``, ``b2``)."""
    params = inspect.signature(optimizer).parameters
    out: dict[str, Any] = {}
    for key, value in given.items():
        where = f"policy_kwargs.optimizer_kwargs.{key}"
        if key == "betas" and "b1" in params and isinstance(value, (list, tuple)) \
                and len(value) == 2:
            out["b1"], out["b2"] = value
            changes.append(change(where, value, {"b1": value[0], "b2": value[1]},
                                  "Optax names Adam's betas b1 and b2"))
        elif OPTIMIZER_RENAMES.get(key) in params:
            out[OPTIMIZER_RENAMES[key]] = value
            changes.append(change(where, value, {OPTIMIZER_RENAMES[key]: value},
                                  f"Optax calls {key} {OPTIMIZER_RENAMES[key]}"))
        elif key in params and key != "learning_rate":
            out[key] = value
        else:
            changes.append(change(where, value, None, f"optax.{optimizer.__name__} has no "
                                                      f"argument {key!r}"))
    return out


def translate_policy_kwargs(kwargs: dict[str, Any], policy_class: type,
                            changes: list[dict[str, Any]]) -> dict[str, Any]:
    """``policy_kwargs`` parsed for SB3 (torch classes resolved) as SBX's ``policy_class``
    takes them; appends a record to ``changes`` for each key translated or dropped."""
    params = inspect.signature(policy_class.__init__).parameters
    out: dict[str, Any] = {}
    optimizer = None
    for key, value in kwargs.items():
        where = f"policy_kwargs.{key}"
        if key in EXTRACTOR_KEYS:
            changes.append(change(where, value, None, "SBX's MLP policies have no features "
                                  "extractor: the network reads the observation as it is"))
        elif key in JAX_EQUIVALENTS and _is_torch(value):
            module, _, what, default = JAX_EQUIVALENTS[key]
            used = _jax_equivalent(key, value)
            if used is None:
                changes.append(change(where, value, None, f"no {what} of that name; {default} "
                                      "is used"))
            else:
                out[key] = used
                changes.append(change(where, value, f"{module}.{used.__name__}",
                                      f"the {what} of the PyTorch class"
                                      + (" (tanh approximation)" if value.__name__ == "GELU"
                                         else "")))
            optimizer = used if key == "optimizer_class" else optimizer
        elif key == "batch_norm_momentum" and key in params and isinstance(value, (int, float)):
            out[key] = 1.0 - float(value)
            changes.append(change(where, value, out[key], "PyTorch's batch-norm momentum weighs "
                                  "the new batch, Flax's the running average: 1 - m"))
        elif key not in params or key == "self":
            changes.append(change(where, value, None, f"not an argument of SBX's "
                                                      f"{policy_class.__name__}"))
        else:
            out[key] = value
    given_opt = out.get("optimizer_kwargs")
    if isinstance(given_opt, dict) and given_opt:
        if optimizer is None:
            import optax

            optimizer = out.get("optimizer_class", optax.adam)
        if callable(optimizer) and not isinstance(optimizer, type):
            out["optimizer_kwargs"] = _optimizer_kwargs(given_opt, optimizer, changes)
    return out
