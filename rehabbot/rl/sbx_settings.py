"""Settings files for the SBX backend: the same RL-Zoo-style files as for Stable-Baselines3,
with what only PyTorch can run translated or dropped, and every change listed.

A settings file is written for Stable-Baselines3 (RL Zoo reads the shipped ones unchanged),
so :func:`rehabbot.rl.hyperparams.hyperparameters_from_mapping` reads it for SBX with these
rules, and the run's manifest lists each change (``hyperparameters.backend_changes``: the key,
what was given, what is used instead or ``null`` when dropped, and why):

=================================== =======================================================
``policy``: a PyTorch policy class  SBX's ``MlpPolicy`` (the SBX network reads the
(SB3's or sb3-contrib's)            observation as it is)
``policy_kwargs``:
  ``features_extractor_class/_kwargs`` dropped (SBX's MLP policies have no extractor)
  ``activation_fn`` (``nn.ReLU``, …) the Flax function of the same name (``flax.linen.relu``)
  ``optimizer_class`` (``optim.Adam``) the Optax optimizer (``optax.adam``); its kwargs
                                    renamed (``betas`` -> ``b1``, ``b2``; ``alpha`` ->
                                    ``decay``) or dropped if Optax has no such argument
  ``batch_norm_momentum`` (CrossQ)  ``1 - m``: PyTorch weighs the new batch by ``m`` (SB3's
                                    default 0.01), Flax the running average (SBX's 0.99)
  any other key SBX's policy lacks  dropped (e.g. PPO's ``full_std``, CrossQ's
                                    ``batch_norm_eps``)
an SB3 constructor argument that    dropped (SAC/TQC ``target_update_interval``: SBX updates
SBX's class lacks                   the target networks every gradient step;
                                    ``optimize_memory_usage``; PPO's ``stats_window_size``)
=================================== =======================================================

Everything else means the same on both backends and is kept, including ``n_steps`` (n-step
returns: SBX uses SB3's n-step replay buffer), ``train_freq``/``gradient_steps`` (SBX runs the
gradient steps of one call in a single compiled loop), ``normalize`` and the action noise.
Keys only SBX has (``qf_learning_rate``, ``policy_delay`` for SAC, ``param_resets``,
``layer_norm``/``dropout_rate`` in ``policy_kwargs``) are accepted on the SBX backend only.
"""

from __future__ import annotations

import inspect
from typing import Any

TORCH_POLICY_PACKAGES = ("stable_baselines3", "sb3_contrib")
SBX_POLICY = "MlpPolicy"
EXTRACTOR_KEYS = ("features_extractor_class", "features_extractor_kwargs")
ACTIVATIONS = {"ReLU": "relu", "Tanh": "tanh", "ELU": "elu", "LeakyReLU": "leaky_relu",
               "SiLU": "silu", "GELU": "gelu"}
OPTIMIZERS = {"Adam": "adam", "AdamW": "adamw", "RMSprop": "rmsprop", "SGD": "sgd"}
OPTIMIZER_RENAMES = {"alpha": "decay"}  # torch.optim.RMSprop(alpha) is optax.rmsprop(decay)
KEY_REASONS = {
    "target_update_interval": "SBX updates the target networks after every gradient step",
    "optimize_memory_usage": "SBX's replay buffer has no memory-optimised variant",
    "stats_window_size": "SBX's PPO has no such argument (it keeps the last 100 episodes)",
}


def change(key: str, given: Any, used: Any, why: str) -> dict[str, Any]:
    """One entry of the manifest's ``backend_changes`` (``used`` None: dropped)."""
    return {"key": key, "given": _name(given), "used": _name(used), "why": why}


def _name(value: Any) -> Any:
    if callable(value) and isinstance(getattr(value, "__qualname__", None), str):
        return f"{value.__module__}.{value.__qualname__}"
    if isinstance(value, dict):
        return {str(k): _name(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_name(v) for v in value]
    return value


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


def _flax_activation(value: Any) -> Any | None:
    name = ACTIVATIONS.get(getattr(value, "__name__", ""))
    if name is None:
        return None
    import flax.linen

    return getattr(flax.linen, name)


def _optax_optimizer(value: Any) -> Any | None:
    name = OPTIMIZERS.get(getattr(value, "__name__", ""))
    if name is None:
        return None
    import optax

    return getattr(optax, name)


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


def _init_params(cls: type) -> dict[str, inspect.Parameter]:
    """The keyword arguments ``cls`` takes, through the classes whose ``__init__`` passes
    ``**kwargs`` on to its base."""
    params: dict[str, inspect.Parameter] = {}
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        own = inspect.signature(klass.__init__).parameters
        params.update({k: v for k, v in own.items() if v.kind not in (v.VAR_POSITIONAL,
                                                                          v.VAR_KEYWORD)})
        if not any(v.kind is v.VAR_KEYWORD for v in own.values()):
            break
    return params


def translate_policy_kwargs(kwargs: dict[str, Any], policy_class: type,
                            changes: list[dict[str, Any]]) -> dict[str, Any]:
    """``policy_kwargs`` parsed for SB3 (torch classes resolved) as SBX's ``policy_class``
    takes them; appends a record to ``changes`` for each key translated or dropped."""
    params = _init_params(policy_class)
    out: dict[str, Any] = {}
    optimizer = None
    for key, value in kwargs.items():
        where = f"policy_kwargs.{key}"
        if key in EXTRACTOR_KEYS:
            changes.append(change(where, value, None, "SBX's MLP policies have no features "
                                  "extractor: the network reads the observation as it is"))
        elif key == "activation_fn" and _is_torch(value):
            flax_fn = _flax_activation(value)
            if flax_fn is None:
                changes.append(change(where, value, None, "no Flax function of that name; "
                                      "SBX's default activation is used"))
            else:
                out[key] = flax_fn
                changes.append(change(where, value, f"flax.linen.{flax_fn.__name__}",
                                      "the Flax function of the PyTorch module"
                                      + (" (tanh approximation)" if value.__name__ == "GELU"
                                         else "")))
        elif key == "optimizer_class" and _is_torch(value):
            optimizer = _optax_optimizer(value)
            if optimizer is None:
                changes.append(change(where, value, None, "no Optax optimizer of that name; "
                                      "SBX's default (optax.adam) is used"))
            else:
                out[key] = optimizer
                changes.append(change(where, value, f"optax.{optimizer.__name__}",
                                      "the Optax optimizer of the PyTorch one"))
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
