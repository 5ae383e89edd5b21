"""A zoo of trained agents shipped with the package: each one is the deterministic actor of a
trained model, exported to a small ``.npz`` of float32 arrays and run with NumPy alone (no
PyTorch, JAX or Stable-Baselines3, no download).

==================================== ===========================================================
``load(env_id, algo)``               the shipped agent as a :class:`ZooPolicy` (SB3's
                                     ``predict``); also ``rehabbot.zoo.load``
``available()``                      the ``(env_id, algo)`` pairs shipped
``load_file(path)``                  an agent from any zoo file
``load_full_model(env_id, algo)``    the whole trained SB3/SBX model behind an agent, for
                                     ``learn`` (fine-tuning), critics included: not shipped in
                                     the package, fetched once (:mod:`rehabbot.rl.zoo_full`,
                                     ``rehabbot zoo fetch``)
``zoo_export.export_policy(...)``    write a zoo file (:mod:`rehabbot.rl.zoo_export`; ``model,
                                     env_id, algo, out_path, metadata``) from a trained SB3
                                     model (SAC, TD3, PPO; TQC, CrossQ from sb3-contrib) or SBX
                                     model (SAC, TD3, PPO, TQC, CrossQ), a model zip or a run
                                     folder (``rehabbot zoo export RUN_DIR``; default output:
                                     the zoo folder of the package)
==================================== ===========================================================

**Where the files are.** ``rehabbot/zoo/<env-short-name>/<algo>.npz`` (package data; e.g.
``rehabbot/zoo/rehab-reach-v1/sac.npz``), or the folder named by the environment variable
``REHABBOT_ZOO_DIR``. ``rehabbot/zoo/__init__.py`` only re-exports the loader from here, so
that the loading code stays in the ``rl`` layer and the data folder imports nothing else.
``rehabbot evaluate zoo:rehab-reach-v1/sac`` and ``rehabbot render zoo:rehab-reach-v1/sac``
run an agent in the env it was trained on (:mod:`rehabbot.rl.policies`).

**What a file holds.** The actor as a program of steps, run in order on a batch of
observations: ``ops`` (a string array) names the steps, and ``op<k>.<param>`` hold their
parameters:

================== =========================================================================
``normalize``      VecNormalize's ``clip((x - mean) / sqrt(var + epsilon), -clip, clip)``
``tracking_error`` the input of the ``-v1`` agents' networks (:func:`tracking_error_features`;
                   ``center``, ``half_range``, ``fine_scale_rad``: NaN for none)
``dense``          ``x @ weight.T + bias`` (``weight`` has PyTorch's (out, in) shape)
``batch_norm``     ``(x - mean) / sqrt(var + epsilon) * scale + bias`` (running statistics)
activations        ``relu``, ``tanh``, ``elu`` (``alpha``), ``leaky_relu`` (``slope``),
                   ``silu``, ``sigmoid``
``clip``           ``clip(x, low, high)``
``unscale``        ``low + (x + 1) / 2 * (high - low)``: a squashed action to the action box
================== =========================================================================

plus ``observation_low``/``observation_high`` and ``action_low``/``action_high`` (the
spaces, checked against the env) and ``metadata``, a JSON string: env id and kwargs,
algorithm, backend, training steps and seed, the success rate measured on the exported
actor, the command that trained it, the rehabbot version, and ``weights_sha256``, the
SHA-256 of every other array (name, dtype, shape and bytes). A file whose arrays do not match
that hash, or that lacks an array, is refused with :class:`ZooError` naming the file.

**Which env a file names.** Its ``env_id`` is made (``gym.make``) to run and fine-tune the
agent, and Gymnasium's ``gym.make("module:id")`` imports ``module``: so a file's ``env_id``
must be a registered ``rehabbot/`` id, exactly (no ``module:`` part), and :func:`load`
checks it against the id asked for, whole. The keys the exporter writes
(:data:`RESERVED_METADATA`) cannot be set by a user's note (``rehabbot zoo export --note``).

The actor is deterministic: ``predict(..., deterministic=False)`` raises
:class:`~rehabbot.common.errors.UsageError` (a ``ValueError``), since the exploration noise
of the trained model is not exported.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.common.files import atomic_save_verified
from rehabbot.envs.registration import NAMESPACE, env_short_name
from rehabbot.tasks.observation import tracking_slices

ZOO_DIR = Path(__file__).resolve().parents[1] / "zoo"
ZOO_DIR_ENV = "REHABBOT_ZOO_DIR"
ZOO_PREFIX = "zoo:"
SUFFIX = ".npz"
FORMAT_VERSION = 1
METADATA_KEY = "metadata"
# Backends whose agents trained on the batched env (rehabbot.rl.batch_training): their zoo
# names say so (agent_name).
BATCHED_BACKENDS = ("rsl_rl",)
DEFAULT_EPISODES = 20
DEFAULT_SEED = 1000
#: The metadata keys the exporter and the writer fill in (provenance, the env the agent runs
#: in, the hashes that bind the arrays and the full model): never taken from a user's note.
RESERVED_METADATA = frozenset({
    "env_id", "env_kwargs", "algo", "backend", "policy_class", "training_steps", "seed",
    "train_command", "git_commit", "hyperparameters", "training_versions",
    "rehabbot_version", "format", "weights_sha256", "full_model_sha256", "success_rate",
    "evaluation", "training_env_id", "training_patients",
})
# op name -> the parameters it needs
OP_PARAMS: dict[str, tuple[str, ...]] = {
    "normalize": ("mean", "var", "epsilon", "clip"),
    "tracking_error": ("center", "half_range", "fine_scale_rad"),
    "dense": ("weight", "bias"),
    "batch_norm": ("mean", "var", "epsilon", "scale", "bias"),
    "relu": (), "tanh": (), "silu": (), "sigmoid": (),
    "elu": ("alpha",), "leaky_relu": ("slope",),
    "clip": ("low", "high"),
    "unscale": ("low", "high"),
}

__all__ = ["RESERVED_METADATA", "ZOO_DIR", "ZOO_PREFIX", "ZooError", "ZooPolicy",
           "available", "check_env_id", "is_zoo_spec", "load", "load_file", "load_spec",
           "parse_spec", "weights_sha256", "write_zoo_file", "zoo_dir", "zoo_path"]


class ZooError(DataError):
    """A zoo file is missing, damaged, tampered with or of another format; names the file."""


# --------------------------------------------------------------------------- the program


def tracking_error_features(obs: np.ndarray, center: np.ndarray, half_range: np.ndarray,
                            fine_scale_rad: float | None) -> np.ndarray:
    """``[(obs - center) / half_range, (theta* - theta) / 0.5 rad, (p* - p) / 0.1 m]``, plus
    ``tanh((theta* - theta) / fine_scale_rad)`` when given, for a float32 batch of the paper's
    observation layout (:func:`rehabbot.tasks.observation.tracking_slices`): the features that
    the networks of the ``-v1`` agents read (``TrackingErrorFeatures`` of rehabbot at commit
    51d9d71), in float32 and in their order of operations, so
    that the shipped agents act as they were trained."""
    theta_star, p_star, theta, p = tracking_slices(obs.shape[1])
    joint_error = (obs[:, theta_star] - obs[:, theta]) / 0.5
    parts = [(obs - center) / half_range, joint_error, (obs[:, p_star] - obs[:, p]) / 0.1]
    if fine_scale_rad is not None:
        parts.append(np.tanh(joint_error * (0.5 / fine_scale_rad)))
    return np.concatenate(parts, axis=1).astype(np.float32, copy=False)


# The steps without parameters, in float32.
ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "relu": lambda x: np.maximum(x, np.float32(0)), "tanh": np.tanh,
    "sigmoid": lambda x: np.float32(1) / (np.float32(1) + np.exp(-x)),
    "silu": lambda x: x / (np.float32(1) + np.exp(-x)),
}


def _op(name: str, p: Mapping[str, np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
    """The function of one step of the actor's program."""
    f32 = np.float32
    if name == "dense":
        weight, bias = p["weight"], p["bias"]
        return lambda x: x @ weight.T + bias
    if name in ACTIVATIONS:
        return ACTIVATIONS[name]
    if name == "elu":
        alpha = f32(p["alpha"])
        return lambda x: np.where(x > 0, x, alpha * np.expm1(np.minimum(x, f32(0))))
    if name == "leaky_relu":
        slope = f32(p["slope"])
        return lambda x: np.where(x >= 0, x, slope * x)
    if name == "clip":
        low, high = p["low"], p["high"]
        return lambda x: np.clip(x, low, high)
    if name == "unscale":
        low, high = p["low"], p["high"]
        return lambda x: low + (f32(0.5) * (x + f32(1.0)) * (high - low))
    if name == "batch_norm":
        mean, scale, bias = p["mean"], p["scale"], p["bias"]
        std = np.sqrt(p["var"] + f32(p["epsilon"]))
        return lambda x: (x - mean) / std * scale + bias
    if name == "normalize":
        mean, clip = p["mean"].astype(np.float64), float(p["clip"])
        std = np.sqrt(p["var"].astype(np.float64) + float(p["epsilon"]))
        return lambda x: np.clip((x - mean) / std, -clip, clip).astype(f32)
    if name == "tracking_error":
        center, half_range = p["center"], p["half_range"]
        fine = float(p["fine_scale_rad"])
        fine_scale = None if np.isnan(fine) else fine
        return lambda x: tracking_error_features(x, center, half_range, fine_scale)
    raise KeyError(name)


def weights_sha256(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over every array but the metadata: name, dtype, shape and bytes, by name."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        if name == METADATA_KEY:
            continue
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def _program_arrays(ops: Sequence[tuple[str, Mapping[str, Any]]]) -> dict[str, np.ndarray]:
    arrays: dict[str, np.ndarray] = {"ops": np.array([name for name, _ in ops], dtype=str)}
    for k, (name, params) in enumerate(ops):
        if name not in OP_PARAMS:
            raise ValueError(f"unknown zoo op {name!r}; known: {', '.join(OP_PARAMS)}")
        missing = set(OP_PARAMS[name]) - set(params)
        if missing:
            raise ValueError(f"zoo op {name!r} lacks {', '.join(sorted(missing))}")
        for key in OP_PARAMS[name]:
            arrays[f"op{k}.{key}"] = np.asarray(params[key], dtype=np.float32)
    return arrays


def write_zoo_file(path: Path, ops: Sequence[tuple[str, Mapping[str, Any]]],
                   observation_space: gym.spaces.Box, action_space: gym.spaces.Box,
                   metadata: Mapping[str, Any]) -> dict[str, Any]:
    """Write the program ``ops`` (``(name, params)`` pairs) with the spaces and
    ``metadata`` to ``path`` (atomically, read back before it takes the name); returns the
    metadata written, with the format version and ``weights_sha256`` filled in.

    Raises:
        ZooError: a metadata ``env_id`` that is not a registered id (:func:`check_env_id`).
        OutputError: the file cannot be written (a full disk), naming it.
    """
    if "env_id" in metadata:
        check_env_id(metadata["env_id"], path)
    arrays = _program_arrays(ops)
    arrays.update(observation_low=np.asarray(observation_space.low, np.float32),
                  observation_high=np.asarray(observation_space.high, np.float32),
                  action_low=np.asarray(action_space.low, np.float32),
                  action_high=np.asarray(action_space.high, np.float32))
    meta = {**dict(metadata), "format": FORMAT_VERSION, "weights_sha256": weights_sha256(arrays)}
    arrays[METADATA_KEY] = np.array(json.dumps(meta, sort_keys=True, default=_json_default))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Read back before the rename; a full disk is an OutputError naming the file.
    atomic_save_verified(path, lambda tmp: _save_arrays(tmp, arrays), ZooPolicy.from_file)
    return meta


def _save_arrays(path: str, arrays: Mapping[str, np.ndarray]) -> None:
    with open(path, "wb") as stream:  # a stream: NumPy adds no .npz to the name
        np.savez_compressed(stream, **arrays)


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


# --------------------------------------------------------------------------- the policy


class ZooPolicy:
    """A deterministic actor read from a zoo file, run with NumPy; SB3's ``predict``.

    ``metadata`` (dict), ``env_id``, ``algo``, ``path``, ``observation_space`` and
    ``action_space`` (gymnasium Boxes) describe it.
    """

    def __init__(self, arrays: Mapping[str, np.ndarray], metadata: Mapping[str, Any],
                 path: Path | None = None) -> None:
        self.path = Path(path) if path is not None else None
        self.metadata = dict(metadata)
        self.env_id = str(self.metadata.get("env_id", ""))
        self.algo = str(self.metadata.get("algo", ""))
        where = str(self.path) if self.path is not None else "zoo arrays"
        try:
            self.observation_space = gym.spaces.Box(arrays["observation_low"],
                                                    arrays["observation_high"],
                                                    dtype=np.float32)
            self.action_space = gym.spaces.Box(arrays["action_low"], arrays["action_high"],
                                               dtype=np.float32)
            names = [str(name) for name in np.atleast_1d(arrays["ops"])]
            unknown = [name for name in names if name not in OP_PARAMS]
            if unknown:
                raise ValueError(f"unknown ops {unknown}")
            self._ops, self._params = [], []
            for k, name in enumerate(names):
                params = {key: np.asarray(arrays[f"op{k}.{key}"])
                          for key in OP_PARAMS[name]}
                self._params.append(params)
                self._ops.append(_op(name, params))
        except KeyError as err:
            raise ZooError(f"{where} is not a valid zoo file: it lacks {err}") from err
        except ValueError as err:
            raise ZooError(f"{where} is not a valid zoo file: {err}") from err
        self.ops = tuple(names)

    def program(self) -> list[tuple[str, dict[str, np.ndarray]]]:
        """The actor's steps as ``(name, params)`` pairs, as :func:`write_zoo_file` takes
        them (to write the same actor again with other metadata)."""
        return [(name, dict(params)) for name, params in zip(self.ops, self._params,
                                                              strict=True)]

    @classmethod
    def from_file(cls, path: str | Path) -> ZooPolicy:
        """Read and verify a zoo file (:class:`ZooError` naming it if it is bad)."""
        path = Path(path)
        if not path.is_file():
            raise ZooError(f"zoo file {str(path)!r} not found")
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as err:
            raise ZooError(f"{path} is not a readable zoo file ({type(err).__name__}: "
                           f"{err})") from err
        if METADATA_KEY not in arrays:
            raise ZooError(f"{path} is not a valid zoo file: it lacks {METADATA_KEY}")
        try:
            metadata = json.loads(str(arrays[METADATA_KEY]))
        except json.JSONDecodeError as err:
            raise ZooError(f"{path} is not a valid zoo file: unreadable metadata ({err})"
                           ) from err
        if not isinstance(metadata, dict):
            raise ZooError(f"{path} is not a valid zoo file: metadata is not a JSON object")
        if metadata.get("format") != FORMAT_VERSION:
            raise ZooError(f"{path} has zoo format {metadata.get('format')!r}; this rehabbot "
                           f"reads format {FORMAT_VERSION}")
        if "env_id" in metadata:
            check_env_id(metadata["env_id"], path)
        policy = cls(arrays, metadata, path)  # ZooError: an array it lacks, an unknown op
        expected = metadata.get("weights_sha256")
        actual = weights_sha256(arrays)
        if expected != actual:
            raise ZooError(f"{path} is damaged or was modified: its arrays' sha256 is "
                           f"{actual}, its metadata says {expected}")
        return policy

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """The action for one observation (shape ``(obs_dim,)``) or a batch (``(n,
        obs_dim)``, e.g. from a vector env); SB3's signature. Deterministic only."""
        if not deterministic:
            raise UsageError("zoo agents are deterministic (their exploration noise is not "
                             "exported): call predict with deterministic=True")
        obs = np.asarray(observation, dtype=np.float32)
        size = self.observation_space.shape[0]
        if obs.ndim not in (1, 2) or obs.shape[-1] != size:
            raise UsageError(f"observation of shape {obs.shape} does not fit this zoo agent: "
                             f"it takes ({size},) or (n, {size})")
        x = obs.reshape(1, size) if obs.ndim == 1 else obs
        for op in self._ops:
            x = op(x)
        action = np.asarray(x, dtype=np.float32)
        return (action[0] if obs.ndim == 1 else action), None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.predict(observation)[0]

    def __repr__(self) -> str:
        return (f"ZooPolicy(env_id={self.env_id!r}, algo={self.algo!r}, "
                f"ops={len(self.ops)}, path={str(self.path) if self.path else None!r})")


# --------------------------------------------------------------------------- the zoo


def zoo_dir() -> Path:
    """The folder of zoo files: ``$REHABBOT_ZOO_DIR`` if set, else the package's."""
    override = os.environ.get(ZOO_DIR_ENV)
    return Path(override) if override else ZOO_DIR


def check_env_id(env_id: object, path: str | Path) -> str:
    """``env_id`` if it is a registered ``rehabbot/`` id, exactly: the id a zoo file may name.

    Raises:
        ZooError: anything else (an unregistered id, another namespace, a ``module:`` prefix,
            which ``gym.make`` would import), naming the file ``path`` and the value.
    """
    if (not isinstance(env_id, str) or not env_id.startswith(f"{NAMESPACE}/")
            or env_id not in gym.registry):
        raise ZooError(f"{path} names the env {env_id!r}, which is not a registered "
                       f"{NAMESPACE}/ id; a zoo file names one exactly")
    return env_id


def _short(env_id: str) -> str:
    """The short name of an id asked for: ``rehab-knee-v2`` or ``rehabbot/rehab-knee-v2``
    (nothing else: another namespace or a ``module:`` prefix is a :class:`UsageError`)."""
    text = str(env_id).strip()
    namespace, sep, short = text.rpartition("/")
    if sep and namespace != NAMESPACE:
        raise UsageError(f"{env_id!r} is not a {NAMESPACE} id (ENV is rehab-knee-v2 or "
                         f"{NAMESPACE}/rehab-knee-v2); zoo: specs name files inside the zoo "
                         "only")
    return _check_zoo_name(short, "env")


# The two parts of a zoo file's path: folder names, never a way out of the zoo.
ZOO_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9._-]{0,99}$")


def _check_zoo_name(value: str, what: str) -> str:
    if not ZOO_NAME_RE.match(value) or ".." in value:
        raise UsageError(f"zoo {what} {value!r} is not a zoo name (lower-case letters, digits, "
                         "'.', '_' and '-'); zoo: specs name files inside the zoo only")
    return value


def zoo_path(env_id: str, algo: str, root: Path | None = None) -> Path:
    """``<zoo>/<env-short-name>/<algo>.npz`` (whether or not it exists), always inside the
    zoo.

    Raises:
        UsageError: an env or algorithm that is not a plain name (``../``, ``/``, ...).
    """
    base = Path(root or zoo_dir())
    env = _check_zoo_name(_short(env_id), "env")
    name = _check_zoo_name(str(algo).strip().lower(), "algorithm")
    return base / env / f"{name}{SUFFIX}"


def agent_name(algo: str, env_kwargs: Mapping[str, Any] | None = None,
               backend: str | None = None) -> str:
    """The zoo's name of an agent: its algorithm (``sac``), followed by the robot for one
    trained with another robot than the ids' UR5e (``sac-fr3``: ``zoo:rehab-hip-v2/sac-fr3``,
    trained and run with ``robot="fr3"``), and by ``rsl_rl`` for one trained on the batched
    env (``ppo-rsl_rl``), so that it never takes the place of the CPU-trained agent."""
    robot = (env_kwargs or {}).get("robot")
    name = str(algo).strip().lower()
    name = name if robot in (None, "ur5e") else f"{name}-{robot}"
    return f"{name}-{backend}" if backend in BATCHED_BACKENDS else name


HELD_OUT_FILE = "heldout.json"


def held_out_figures() -> dict[str, dict[str, Any]]:
    """Each zoo agent's held-out figures (``"rehab-knee-v2/sac"`` -> ``{"bodies": [finished,
    of], "conditions": [finished, of], "weights_sha256": ...}``: the test episodes it finished
    out of those the scripted expert finished, on the envelope's test bodies and on its test
    conditions), from the zoo's ``heldout.json``, which
    ``benchmarks/results/heldout_results.py --zoo-figures`` writes with
    ``docs/results/heldout-envelope.md``. An entry counts only while its weights' SHA-256 is
    the shipped agent's (a retrained agent has no figure until it is evaluated again); ``{}``
    without the file."""
    path = zoo_dir() / HELD_OUT_FILE
    if not path.is_file():
        return {}
    try:
        agents = json.loads(path.read_text(encoding="utf-8")).get("agents", {})
    except (ValueError, AttributeError) as err:
        raise ZooError(f"{path} is not a held-out figures file (a JSON object with "
                       f"'agents'): {err}") from None
    if not isinstance(agents, dict):
        raise ZooError(f"{path}: 'agents' must be an object, got {type(agents).__name__}")
    return {name: figures for name, figures in agents.items() if isinstance(figures, dict)}


def available() -> list[tuple[str, str]]:
    """The ``(env_id, algo)`` of every agent in the zoo, sorted (full ids, e.g.
    ``("rehabbot/rehab-reach-v1", "sac")``)."""
    root = zoo_dir()
    if not root.is_dir():
        return []
    return sorted((f"{NAMESPACE}/{path.parent.name}", path.stem)
                  for path in root.glob(f"*/*{SUFFIX}") if path.is_file())


def _listing() -> str:
    shipped = available()
    if not shipped:
        return (f"the zoo ({zoo_dir()}) holds no agents yet; build one with `rehabbot zoo "
                "export RUN_DIR`")
    return "available: " + ", ".join(f"{env_short_name(e)}/{a}" for e, a in shipped)


def load(env_id: str, algo: str) -> ZooPolicy:
    """The zoo's agent for ``env_id`` (with or without ``rehabbot/``) and ``algo``.

    Raises:
        UsageError: no such agent (the message lists those there are).
        ZooError: its file is damaged, tampered with or for another env.
    """
    path = zoo_path(env_id, algo)
    if not path.is_file():
        raise UsageError(f"the zoo has no agent {_short(env_id)}/{str(algo).strip().lower()}; "
                         f"{_listing()}")
    policy = ZooPolicy.from_file(path)  # ZooError: an env_id that is not a registered id
    wanted = f"{NAMESPACE}/{_short(env_id)}"
    if policy.env_id != wanted:
        raise ZooError(f"{path} holds an agent for {policy.env_id!r}, not {wanted!r}")
    name = agent_name(policy.algo, policy.metadata.get("env_kwargs"),
                      policy.metadata.get("backend"))
    if name != path.stem:
        raise ZooError(f"{path} holds the agent {name!r} (algorithm {policy.algo!r}, env kwargs "
                       f"{policy.metadata.get('env_kwargs')}), not {path.stem!r}")
    return policy


def load_file(path: str | Path) -> ZooPolicy:
    """The agent of any zoo file (verified, :class:`ZooError` if bad)."""
    return ZooPolicy.from_file(path)


def is_zoo_spec(spec: object) -> bool:
    """Whether a policy spec names a zoo agent (``zoo:ENV/ALGO``)."""
    return str(spec).startswith(ZOO_PREFIX)


def parse_spec(spec: str) -> tuple[str, str]:
    """``zoo:rehab-reach-v1/sac`` (or ``zoo:rehabbot/rehab-reach-v1/sac``) -> the full env id
    and the algorithm; :class:`UsageError` if malformed."""
    body = str(spec)[len(ZOO_PREFIX):] if is_zoo_spec(spec) else str(spec)
    env, sep, algo = body.strip().rpartition("/")
    if not sep or not env or not algo:
        raise UsageError(f"zoo spec {spec!r} must read zoo:ENV/ALGO, e.g. "
                         f"zoo:rehab-reach-v1/sac; {_listing()}")
    return f"{NAMESPACE}/{_short(env)}", algo.lower()


def load_spec(spec: str) -> ZooPolicy:
    """The agent a ``zoo:ENV/ALGO`` spec names."""
    return load(*parse_spec(spec))
