"""Exporting a trained model to the zoo (:func:`export_policy`): its deterministic actor read
out as the layers of its network, plain float32 arrays in the step format of
:mod:`rehabbot.rl.zoo`, written with the model's provenance and measured success rate.

============ ======================================== =========================================
backend      algorithms                                actor read
============ ======================================== =========================================
``sb3``      SAC, TD3, PPO (Stable-Baselines3); TQC,   every module of the ``MlpPolicy`` actor
             CrossQ (sb3-contrib)                      (Linear, activations, Hardtanh,
                                                       BatchNorm/BatchRenorm with their running
                                                       statistics), then tanh for SAC/TQC/CrossQ
                                                       and squashed PPO
``sbx``      SAC, TD3, PPO, TQC, CrossQ (SBX, JAX)     the flax parameters of the ``MlpPolicy``
                                                       actor (``Dense_<k>``, ``BatchRenorm_<k>``)
                                                       and its activation function
============ ======================================== =========================================

A squashed actor's output in [-1, 1] is mapped to the action box (``unscale``), an unsquashed
one clipped to it, as the library's ``predict`` does. VecNormalize statistics of a run folder
become a ``normalize`` step before the network. PyTorch, JAX and the libraries are imported
only inside the functions that read their models; :mod:`rehabbot.rl.zoo`, which runs the
files with NumPy alone, never imports this module.
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.common.version import VERSION
from rehabbot.envs.registration import NAMESPACE, POPULATION_VARIANTS, env_short_name
from rehabbot.rl import runs
from rehabbot.rl.algorithms import check_algo
from rehabbot.rl.policies import env_for, load_model, model_file
from rehabbot.rl.safe_load import is_sbx
from rehabbot.rl.zoo import (
    DEFAULT_EPISODES,
    DEFAULT_SEED,
    RESERVED_METADATA,
    ZooPolicy,
    agent_name,
    write_zoo_file,
    zoo_path,
)
from rehabbot.rl.zoo_full import ship_full_model

Op = tuple[str, dict[str, Any]]
# JAX activation function name -> zoo op (with its default parameter)
JAX_ACTIVATIONS: dict[str, Op] = {
    "relu": ("relu", {}), "tanh": ("tanh", {}), "silu": ("silu", {}), "swish": ("silu", {}),
    "sigmoid": ("sigmoid", {}), "elu": ("elu", {"alpha": 1.0}),
    "leaky_relu": ("leaky_relu", {"slope": 0.01}),
}


class ExportError(UsageError):
    """A model whose actor the zoo format cannot hold (the message says which part)."""


def _f32(value: Any) -> np.ndarray:
    """A torch tensor or JAX / NumPy array as a float32 NumPy array."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value, dtype=np.float32)


def _output_ops(action_space: gym.spaces.Box, squashed: bool) -> list[Op]:
    low, high = _f32(action_space.low), _f32(action_space.high)
    if squashed:
        return [("unscale", {"low": low, "high": high})]
    return [("clip", {"low": low, "high": high})]


# --------------------------------------------------------------------------- SB3 (PyTorch)


def _torch_module_ops(module: Any) -> list[Op]:
    """The zoo steps of one PyTorch module (a Sequential, a Linear, an activation ...)."""
    from torch import nn

    ops: list[Op] = []
    for m in module.modules():  # the module, then what it holds, in order
        name = type(m).__name__
        if isinstance(m, nn.Linear):
            bias = m.bias if m.bias is not None else np.zeros(m.out_features)
            ops.append(("dense", {"weight": _f32(m.weight), "bias": _f32(bias)}))
        elif isinstance(m, (nn.Sequential, nn.Identity, nn.Flatten, nn.Dropout)):
            continue  # a container, or nothing to do at inference on a batch of vectors
        elif name in ("ReLU", "Tanh", "SiLU", "Sigmoid"):
            ops.append((name.lower(), {}))
        elif isinstance(m, nn.ELU):
            ops.append(("elu", {"alpha": m.alpha}))
        elif isinstance(m, nn.LeakyReLU):
            ops.append(("leaky_relu", {"slope": m.negative_slope}))
        elif isinstance(m, nn.Hardtanh):
            ops.append(("clip", {"low": m.min_val, "high": m.max_val}))
        elif isinstance(m, nn.BatchNorm1d) or name == "BatchRenorm1d":
            mean = m.running_mean if isinstance(m, nn.BatchNorm1d) else m.ra_mean
            var = m.running_var if isinstance(m, nn.BatchNorm1d) else m.ra_var
            affine = getattr(m, "affine", True)
            scale = (m.weight if isinstance(m, nn.BatchNorm1d) else m.scale) if affine \
                else np.ones(mean.shape[0])
            bias = m.bias if affine else np.zeros(mean.shape[0])
            ops.append(("batch_norm", {"mean": _f32(mean), "var": _f32(var),
                                       "epsilon": m.eps, "scale": _f32(scale),
                                       "bias": _f32(bias)}))
        else:
            raise ExportError(f"the zoo cannot export a {name} layer (supported: Linear, "
                              "ReLU, Tanh, SiLU, Sigmoid, ELU, LeakyReLU, Hardtanh, "
                              "BatchNorm1d, BatchRenorm1d)")
    return ops


def sb3_actor_ops(model: Any) -> list[Op]:
    """The deterministic actor of an SB3 / sb3-contrib model (SAC, TD3, PPO, TQC, CrossQ)."""
    policy = model.policy
    if hasattr(policy, "mlp_extractor"):  # on-policy: PPO (and A2C)
        extractor = policy.pi_features_extractor
        body = [policy.mlp_extractor.policy_net, policy.action_net]
        tanh = bool(policy.squash_output)  # gSDE with squash_output: mode is tanh(mean)
    elif hasattr(policy, "actor"):
        actor = policy.actor
        extractor = actor.features_extractor
        if hasattr(actor, "latent_pi"):  # SAC, TQC, CrossQ: tanh of the Gaussian's mean
            body, tanh = [actor.latent_pi, actor.mu], True
        else:  # TD3: the tanh is the last module of mu
            body, tanh = [actor.mu], False
    else:
        raise ExportError(f"the zoo cannot export a {type(policy).__name__} policy")
    if type(extractor).__name__ != "FlattenExtractor":  # the MlpPolicy's: no parameters
        raise ExportError(f"the zoo cannot export the features extractor "
                          f"{type(extractor).__name__} (supported: FlattenExtractor)")
    ops = [op for part in body for op in _torch_module_ops(part)]
    if tanh:
        ops.append(("tanh", {}))
    return ops + _output_ops(model.action_space, bool(policy.squash_output))


# --------------------------------------------------------------------------- SBX (JAX)


def _jax_activation(function: Any) -> Op:
    name = getattr(function, "__name__", None)
    if name is None:
        # A jitted activation (flax.linen.tanh is jax.numpy.tanh) restored from a saved model
        # has no name: recognise it by its values.
        import flax.linen

        probe = np.linspace(-4.0, 4.0, 33, dtype=np.float32)
        values = np.asarray(function(probe))
        for known in JAX_ACTIVATIONS:
            if np.allclose(values, np.asarray(getattr(flax.linen, known)(probe)), atol=1e-6):
                return JAX_ACTIVATIONS[known]
        name = type(function).__name__
    if name not in JAX_ACTIVATIONS:
        raise ExportError(f"the zoo cannot export the activation {name!r} (supported: "
                          f"{', '.join(JAX_ACTIVATIONS)})")
    return JAX_ACTIVATIONS[name]


def _dense(params: Any, k: int) -> Op:
    layer = params[f"Dense_{k}"]
    return ("dense", {"weight": _f32(layer["kernel"]).T.copy(), "bias": _f32(layer["bias"])})


def sbx_actor_ops(model: Any) -> list[Op]:
    """The deterministic actor of an SBX model (SAC, TD3, PPO, TQC, CrossQ)."""
    policy = model.policy
    actor = policy.actor
    kind = f"{type(actor).__module__}.{type(actor).__name__}"
    state = policy.actor_state
    params = state.params.get("params", state.params)
    activation = _jax_activation(policy.activation_fn)
    n_hidden = len(actor.net_arch)
    mlp = [op for k in range(n_hidden) for op in (_dense(params, k), activation)]
    ops: list[Op] = []
    if kind in ("sbx.common.policies.SquashedGaussianActor",  # SAC, TQC: tanh(mean)
                "sbx.td3.policies.Actor"):  # TD3: tanh of the output layer
        ops = [*mlp, _dense(params, n_hidden), ("tanh", {})]
    elif kind == "sbx.ppo.policies.Actor":
        if actor.features_extractor is not None or actor.num_discrete_choices is not None:
            raise ExportError("the zoo exports SBX PPO with an MLP on a Box action space only")
        ops = [*mlp, _dense(params, n_hidden)]
    elif kind == "sbx.crossq.policies.Actor":
        from sbx.common.jax_layers import BatchRenorm

        stats = state.batch_stats

        def renorm(k: int) -> Op:
            name = f"BatchRenorm_{k}"
            return ("batch_norm", {"mean": _f32(stats[name]["mean"]),
                                   "var": _f32(stats[name]["var"]),
                                   "epsilon": BatchRenorm.epsilon,
                                   "scale": _f32(params[name]["scale"]),
                                   "bias": _f32(params[name]["bias"])})

        norm = bool(actor.use_batch_norm)
        ops += [renorm(0)] if norm else []
        for k in range(n_hidden):
            ops += [_dense(params, k), activation] + ([renorm(k + 1)] if norm else [])
        ops += [_dense(params, n_hidden), ("tanh", {})]
    else:
        raise ExportError(f"the zoo cannot export the SBX actor {kind}")
    return ops + _output_ops(model.action_space, bool(policy.squash_output))


# --------------------------------------------------------------------------- sources


def _manifest_metadata(manifest: dict[str, Any]) -> dict[str, Any]:
    command = manifest.get("command")
    if isinstance(command, list) and command:
        command = shlex.join([Path(str(command[0])).name, *map(str, command[1:])])
    return {key: value for key, value in {
        "env_id": manifest.get("env_id"), "env_kwargs": manifest.get("env_kwargs") or {},
        "seed": manifest.get("seed"), "training_steps": manifest.get("timesteps_done"),
        "train_command": command, "git_commit": manifest.get("git_commit"),
        "hyperparameters": manifest.get("hyperparameters"),
        "training_versions": manifest.get("versions"),
    }.items() if value is not None}


def load_source(model_or_run_dir: Any, algo: str | None = None,
                env_id: str | None = None) -> tuple[list[Op], Any, dict[str, Any]]:
    """``(ops, model, metadata)``: the actor's zoo steps, the model and its provenance, for a
    model object, or a model zip or run folder loaded as ``rehabbot evaluate`` loads it, in
    its run's env (``env_id``: the env of a loose zip)."""
    algo = check_algo(algo) if algo else None
    manifest: dict[str, Any] = {}
    stats = None
    if isinstance(model_or_run_dir, (str, Path)):
        path = model_file(model_or_run_dir)  # PolicyError: not found
        run_dir = runs.find_run_dir(path)
        run_env, env_kwargs = env_for([str(path)], None if run_dir else env_id)
        loaded = load_model(path, gym.make(run_env, **env_kwargs))
        if algo is not None and algo != loaded.algo:
            raise UsageError(f"{str(path)!r} holds a {loaded.algo} model, not {algo}")
        model, algo, manifest, stats = (loaded.policy, loaded.algo, loaded.manifest,
                                        loaded.vecnormalize)
        if isinstance(model, ZooPolicy):  # a batched run's actor, already in the zoo format
            return model.program(), model, {
                "algo": loaded.algo, "backend": loaded.backend, "seed": manifest.get("seed"),
                "training_steps": manifest.get("timesteps_done"),
                **_manifest_metadata(manifest)}
    else:
        model = model_or_run_dir
        algo = algo or check_algo(type(model).__name__)
    for name, space in (("observation", model.observation_space),
                        ("action", model.action_space)):
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ExportError(f"the zoo exports models with flat Box spaces; the {name} "
                              f"space is {space}")
    backend = "sbx" if is_sbx(model) else "sb3"
    actor = sbx_actor_ops(model) if backend == "sbx" else sb3_actor_ops(model)
    policy = model.policy
    metadata = {"algo": algo, "backend": backend,
                "policy_class": f"{type(policy).__module__}.{type(policy).__qualname__}",
                "training_steps": int(model.num_timesteps), "seed": model.seed,
                **_manifest_metadata(manifest)}
    normalize = [("normalize", {"mean": stats.obs_mean, "var": stats.obs_var,
                                "epsilon": stats.epsilon, "clip": stats.clip_obs})
                 ] if stats is not None and stats.norm_obs else []
    return normalize + actor, model, metadata


# --------------------------------------------------------------------------- export


def measure_success(policy: ZooPolicy, env_id: str, env_kwargs: Mapping[str, Any] | None,
                    episodes: int, seed: int) -> dict[str, Any]:
    """Run ``policy`` for ``episodes`` episodes reset with seeds ``seed, seed + 1, ...``;
    the success rate and what was run."""
    env = gym.make(env_id, **dict(env_kwargs or {}))
    successes = []
    try:
        for k in range(episodes):
            obs, info = env.reset(seed=seed + k)
            while True:
                obs, _reward, terminated, truncated, info = env.step(policy(obs))
                if terminated or truncated:
                    break
            successes.append(bool(info.get("is_success", False)))
    finally:
        env.close()
    return {"success_rate": float(np.mean(successes)) if successes else None,
            "evaluation": {"episodes": episodes, "seed": seed, "deterministic": True,
                           "successes": int(sum(successes))}}


def serve_base_id(meta: dict[str, Any]) -> None:
    """File an agent trained on a population id under its base id, in place: the population
    is how training drew its patients, the task and spaces are the base id's. The training id
    and patients are kept (``training_env_id``, ``training_patients``) and the agent runs
    with the base id's own patient (``env_kwargs`` without ``patients``)."""
    base_id = POPULATION_VARIANTS.get(meta["env_id"])
    if base_id is None:
        return
    env_kwargs = dict(meta.get("env_kwargs") or {})
    patients = env_kwargs.pop("patients", gym.spec(meta["env_id"]).kwargs.get("patients"))
    meta.update(training_env_id=meta["env_id"], training_patients=patients, env_id=base_id,
                env_kwargs=env_kwargs)


def export_policy(model_or_run_dir: Any, env_id: str | None = None, algo: str | None = None,
                  out_path: str | Path | None = None, metadata: Mapping[str, Any] | None = None,
                  episodes: int = DEFAULT_EPISODES, seed: int = DEFAULT_SEED,
                  full: bool = False) -> dict[str, Any]:
    """Export the deterministic actor of a trained model to the zoo file ``out_path``
    (default: the zoo's file for its env and agent name, :func:`zoo_path` and
    :func:`agent_name`: ``sac``, or ``sac-fr3`` for a run with ``robot="fr3"``).

    ``model_or_run_dir`` is an SB3 or SBX model object, a model zip, or a ``rehabbot
    train`` run folder (its manifest gives the env id, kwargs, algorithm, seed, steps and
    command, and its ``vecnormalize.json`` the observation normalisation). A run on a
    population id (``rehab-knee-population-v2``) is filed under its base id
    (:func:`serve_base_id`). ``metadata`` adds
    fields of its own (a note: how the seed was chosen); the keys the exporter writes
    (:data:`~rehabbot.rl.zoo.RESERVED_METADATA`: the env id, the algorithm, the hashes ...)
    are refused. ``full`` also keeps the model zip beside the zoo file
    (:func:`~rehabbot.rl.zoo_full.ship_full_model`, for
    :func:`~rehabbot.rl.zoo_full.load_full_model`). The exported actor then runs
    ``episodes`` episodes (seeds ``seed, seed + 1, ...``; 0: none) and its success rate is
    recorded. Returns the metadata written. Imports the model's library (PyTorch or JAX).

    Raises:
        UsageError: a reserved metadata key, a negative ``episodes`` or ``seed``, a model the
            zoo cannot hold.
        OutputError: a file cannot be written (a full disk), naming it.
    """
    reserved = sorted(RESERVED_METADATA.intersection(metadata or {}))
    if reserved:
        raise UsageError(f"the metadata {', '.join(map(repr, reserved))} cannot be set by a "
                         "note: the exporter writes it (reserved keys: "
                         f"{', '.join(sorted(RESERVED_METADATA))})")
    for name, value in (("episodes", episodes), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise UsageError(f"{name}={value!r} must be an integer >= 0")
    ops, model, meta = load_source(model_or_run_dir, algo, env_id)
    env_id = env_id or meta.get("env_id")
    if not env_id:
        raise UsageError("the env id is unknown (no run manifest): give env_id / --env")
    meta.update(env_id=f"{NAMESPACE}/{env_short_name(env_id)}", rehabbot_version=VERSION)
    serve_base_id(meta)
    meta.update(dict(metadata or {}))
    out_path = Path(out_path) if out_path is not None else zoo_path(
        meta["env_id"], agent_name(meta["algo"], meta.get("env_kwargs"), meta.get("backend")))
    if full and isinstance(model, ZooPolicy):
        raise ExportError("--full ships a Stable-Baselines3/SBX model zip; a batched run "
                          "keeps its networks in model.pt (rsl_rl), which the zoo does not "
                          "ship")
    if full:
        if not isinstance(model_or_run_dir, (str, Path)):
            raise UsageError("full=True needs the model's zip or run folder, not a model object")
        meta.update(ship_full_model(model_or_run_dir, out_path))
    written = write_zoo_file(out_path, ops, model.observation_space, model.action_space, meta)
    if episodes > 0:
        measured = measure_success(ZooPolicy.from_file(out_path), meta["env_id"],
                                   meta.get("env_kwargs"), episodes, seed)
        written = write_zoo_file(out_path, ops, model.observation_space, model.action_space,
                                 {**meta, **measured})
    return written
