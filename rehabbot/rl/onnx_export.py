"""A trained policy as one ONNX file for a robot PC (:func:`export_onnx`, ``rehabbot export
POLICY --format onnx --out FILE``), and that file run with onnxruntime
(:func:`load_onnx_policy`).

**One path.** Every policy goes through the zoo's program of steps (:mod:`rehabbot.rl.zoo`):
a zoo agent (``zoo:ENV/AGENT``) is that program already, and a trained model (a run folder, a
model zip) is turned into it by :func:`rehabbot.rl.zoo_export.export_policy`, as
``rehabbot zoo export`` does. Each step then becomes ONNX nodes, in order, in one float32
graph with a dynamic batch dimension (``observation``: ``(batch, obs_dim)`` ->
``action``: ``(batch, act_dim)``; opset 17, IR version 8, so onnxruntime 1.12 or later
runs it):

==================  =========================================================================
zoo step            ONNX nodes
==================  =========================================================================
``normalize``       Cast to double, Sub, Div, Max, Min, Cast to float (in double, as
                    VecNormalize computes it)
``tracking_error``  Sub, Div, Slice, Concat (and Mul, Tanh for the fine term)
``dense``           Gemm (``transB=1``: the weight keeps PyTorch's (out, in) shape)
``batch_norm``      Sub, Div, Mul, Add (running statistics)
activations         Relu, Tanh, Sigmoid, Elu, LeakyRelu; silu as ``x * Sigmoid(x)``
``clip``            Max, Min (per-entry bounds)
``unscale``         Add, Mul, Mul, Add: ``low + 0.5 (x + 1) (high - low)``
==================  =========================================================================

Before the file is written, onnxruntime's actions are compared with the zoo program's on
observations drawn (seeded) from the observation box; a difference above
:data:`PARITY_TOLERANCE` refuses the export (:class:`OnnxExportError`). The file is written
atomically and read back before it takes its name (:mod:`rehabbot.common.files`).

**Metadata.** The model's ``metadata_props`` hold what a robot PC needs besides the network,
each value JSON text (:data:`METADATA_KEYS`, ``docs/deployment/export.md``): the env id and
kwargs, the control rate, the observation's entry names, the action bounds and what they
mean to the controller, the robot and its joints, the control mode, the cuff-force limits,
the patient's range of motion as the safety monitor bounds it, and the provenance (the
source, the zoo weights' SHA-256, the agent's own metadata).

onnx and onnxruntime are the optional extra ``[onnx]``; they are imported inside the
functions that use them, and loading a file needs onnxruntime alone. A missing one is a
:class:`~rehabbot.common.errors.UsageError` naming ``pip install "rehabbot[onnx]"``.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.common.files import atomic_save_verified, check_output_file
from rehabbot.common.version import VERSION
from rehabbot.rl import zoo
from rehabbot.rl.policies import POLICY_KEYWORDS, check_spaces
from rehabbot.tasks.observation import ObservationLayout, tracking_slices

FORMATS = ("onnx",)
SUFFIX = ".onnx"
FORMAT_NAME = "rehabbot-onnx-policy"
FORMAT_VERSION = 1
OPSET = 17
IR_VERSION = 8  # the IR of opset 17 (onnx 1.12): onnxruntime >= 1.12 loads the file
INPUT_NAME = "observation"
OUTPUT_NAME = "action"
INSTALL_HINT = 'pip install "rehabbot[onnx]"'
#: onnxruntime's actions against the zoo program's, at export and in the parity benchmark.
PARITY_TOLERANCE = 1e-5
CHECK_OBSERVATIONS = 256  # drawn from the observation box at export
CHECK_SEED = 0
CHECK_BOUND = 10.0  # an unbounded observation entry is drawn in [-10, 10]
#: Every ``metadata_props`` key, each a JSON value, in the order written.
METADATA_KEYS = (
    "format", "format_version", "source", "env_id", "env_kwargs", "algo", "backend",
    "rehabbot_version", "weights_sha256", "control_rate_hz", "control_dt_s",
    "input_name", "output_name", "observation_names", "observation_low", "observation_high",
    "action_names", "action_low", "action_high", "controller_action_low",
    "controller_action_high", "robot", "robot_joint_names", "control_mode", "action_scale",
    "cuff_force_limits_n", "range_of_motion_rad", "rom_tolerance_deg", "ops",
    "agent_metadata",
)

__all__ = ["FORMATS", "METADATA_KEYS", "PARITY_TOLERANCE", "OnnxExportError", "OnnxPolicy",
           "build_onnx_model", "export_onnx", "load_onnx_policy", "observation_names",
           "policy_metadata", "record_episodes", "record_observations", "resolve_policy",
           "write_onnx"]


class OnnxExportError(DataError):
    """The ONNX graph built from a policy does not act as the policy (beyond
    :data:`PARITY_TOLERANCE`), or an ONNX file is not one this module wrote."""


def _require(*modules: str) -> list[Any]:
    """The modules, imported; :class:`UsageError` naming the extra when one is missing."""
    import importlib

    loaded = []
    for name in modules:
        try:
            loaded.append(importlib.import_module(name))
        except ImportError as err:
            raise UsageError(f"ONNX export and inference need {name}, which is not "
                             f"installed: {INSTALL_HINT}") from err
    return loaded


# --------------------------------------------------------------------------- the policy


def resolve_policy(spec: str | Path, env_id: str | None = None) -> tuple[zoo.ZooPolicy, str]:
    """The zoo program of ``spec`` and the source as recorded: ``zoo:ENV/AGENT`` (a shipped
    agent), a zoo ``.npz`` file, or a ``rehabbot train`` run folder or model zip (turned into
    the program by :func:`~rehabbot.rl.zoo_export.export_policy`, as ``rehabbot zoo export``
    does; ``env_id`` names the env of a zip outside a run folder). Imports the model's
    library (PyTorch or JAX) for a model.

    Raises:
        UsageError: an unknown zoo agent (the message lists those there are), ``env_id``
            with a zoo agent, a scripted controller, or a path that does not exist.
        DataError: a damaged file (:class:`~rehabbot.rl.zoo.ZooError`,
            :class:`~rehabbot.rl.algorithms.PolicyError`).
    """
    text = str(spec)
    if zoo.is_zoo_spec(text):
        if env_id is not None:
            raise UsageError(f"--env {env_id!r}: the zoo agent {text} runs in the env it was "
                             "trained in; --env names the env of a model zip outside a run "
                             "folder")
        return zoo.load_spec(text), text
    if text in POLICY_KEYWORDS:
        raise UsageError(f"policy {text!r} is a scripted controller, not a trained network: "
                         "export a zoo agent (zoo:ENV/AGENT) or a model of `rehabbot train`")
    path = Path(text)
    if not path.exists() and not path.with_name(path.name + ".zip").is_file():
        raise UsageError(f"unknown policy {text!r}: give zoo:ENV/AGENT (e.g. "
                         "zoo:rehab-knee-v2/sac; `rehabbot zoo list`), a `rehabbot train` run "
                         "folder or a model .zip (no such file or folder)")
    from rehabbot.rl import runs

    if path.suffix == zoo.SUFFIX and path.is_file() and runs.find_run_dir(path) is None:
        return zoo.load_file(path), str(path)
    from rehabbot.rl.zoo_export import export_policy

    with tempfile.TemporaryDirectory(prefix="rehabbot-onnx-") as folder:
        actor = Path(folder) / f"actor{zoo.SUFFIX}"
        export_policy(path, env_id, None, actor, episodes=0)
        return zoo.load_file(actor), str(path)


# --------------------------------------------------------------------------- the graph


class _Graph:
    """Nodes and constants of the graph being built, with unique names."""

    def __init__(self) -> None:
        from onnx import TensorProto, helper, numpy_helper

        self.helper, self.numpy_helper, self.types = helper, numpy_helper, TensorProto
        self.nodes: list[Any] = []
        self.initializers: list[Any] = []
        self._count = 0

    def name(self, stem: str) -> str:
        self._count += 1
        return f"{stem}_{self._count}"

    def const(self, value: Any, stem: str, dtype: Any = np.float32) -> str:
        name = self.name(stem)
        self.initializers.append(self.numpy_helper.from_array(np.asarray(value, dtype),
                                                              name))
        return name

    def node(self, op: str, inputs: list[str], stem: str, **attrs: Any) -> str:
        out = self.name(stem)
        self.nodes.append(self.helper.make_node(op, inputs, [out], name=out, **attrs))
        return out


def _bounded(g: _Graph, x: str, low: Any, high: Any, stem: str, dtype: Any = np.float32) -> str:
    """``min(max(x, low), high)``: NumPy's ``clip`` with per-entry bounds."""
    return g.node("Min", [g.node("Max", [x, g.const(low, f"{stem}_low", dtype)], stem),
                          g.const(high, f"{stem}_high", dtype)], stem)


def _columns(g: _Graph, x: str, part: slice) -> str:
    return g.node("Slice", [x, g.const([part.start], "start", np.int64),
                            g.const([part.stop], "stop", np.int64),
                            g.const([1], "axis", np.int64)], "columns")


def _tracking_error(g: _Graph, x: str, p: Mapping[str, np.ndarray], size: int) -> str:
    """:func:`rehabbot.rl.zoo.tracking_error_features` in float32, in its order."""
    theta_star, p_star, theta, tool = tracking_slices(size)
    scaled = g.node("Div", [g.node("Sub", [x, g.const(p["center"], "center")], "te"),
                            g.const(p["half_range"], "half_range")], "te")
    joint = g.node("Div", [g.node("Sub", [_columns(g, x, theta_star), _columns(g, x, theta)],
                                  "te"), g.const(0.5, "joint_scale")], "te")
    tool_error = g.node("Div", [g.node("Sub", [_columns(g, x, p_star), _columns(g, x, tool)],
                                       "te"), g.const(0.1, "tool_scale")], "te")
    parts = [scaled, joint, tool_error]
    fine = float(p["fine_scale_rad"])
    if not np.isnan(fine):
        parts.append(g.node("Tanh", [g.node("Mul", [joint, g.const(0.5 / fine, "fine")],
                                            "te")], "te"))
    return g.node("Concat", parts, "te", axis=1)


def _add_step(g: _Graph, x: str, name: str, p: Mapping[str, np.ndarray], size: int) -> str:
    """The nodes of one zoo step on ``x`` (``size``: the observation's length)."""
    if name == "dense":
        return g.node("Gemm", [x, g.const(p["weight"], "weight"), g.const(p["bias"], "bias")],
                      "dense", transB=1)
    simple = {"relu": "Relu", "tanh": "Tanh", "sigmoid": "Sigmoid"}
    if name in simple:
        return g.node(simple[name], [x], name)
    if name == "silu":
        return g.node("Mul", [x, g.node("Sigmoid", [x], "silu")], "silu")
    if name == "elu":
        return g.node("Elu", [x], "elu", alpha=float(np.float32(p["alpha"])))
    if name == "leaky_relu":
        return g.node("LeakyRelu", [x], "leaky_relu", alpha=float(np.float32(p["slope"])))
    if name == "clip":
        return _bounded(g, x, p["low"], p["high"], "clip")
    if name == "unscale":
        low, high = np.asarray(p["low"], np.float32), np.asarray(p["high"], np.float32)
        half = g.node("Mul", [g.const(0.5, "half"),
                              g.node("Add", [x, g.const(1.0, "one")], "unscale")], "unscale")
        return g.node("Add", [g.const(low, "low"),
                              g.node("Mul", [half, g.const(high - low, "span")], "unscale")],
                      "unscale")
    if name == "batch_norm":
        std = np.sqrt(np.asarray(p["var"], np.float32) + np.float32(p["epsilon"]))
        centred = g.node("Sub", [x, g.const(p["mean"], "mean")], "bn")
        scaled = g.node("Mul", [g.node("Div", [centred, g.const(std, "std")], "bn"),
                                g.const(p["scale"], "scale")], "bn")
        return g.node("Add", [scaled, g.const(p["bias"], "bias")], "bn")
    if name == "normalize":
        f64, clip = np.float64, float(p["clip"])
        std = np.sqrt(np.asarray(p["var"], f64) + float(p["epsilon"]))
        wide = g.node("Cast", [x], "normalize", to=g.types.DOUBLE)
        scaled = g.node("Div", [g.node("Sub", [wide, g.const(p["mean"], "mean", f64)],
                                       "normalize"), g.const(std, "std", f64)], "normalize")
        bounded = _bounded(g, scaled, -clip, clip, "normalize", f64)
        return g.node("Cast", [bounded], "normalize", to=g.types.FLOAT)
    if name == "tracking_error":
        return _tracking_error(g, x, p, size)
    raise OnnxExportError(f"the zoo step {name!r} has no ONNX translation (known: "
                          f"{', '.join(zoo.OP_PARAMS)})")


def build_onnx_model(policy: zoo.ZooPolicy, metadata: Mapping[str, Any]) -> Any:
    """The ``onnx.ModelProto`` of ``policy``'s program, with ``metadata`` (each value
    written as JSON text) in its ``metadata_props``; checked by ``onnx.checker``."""
    (onnx,) = _require("onnx")
    helper = onnx.helper
    g = _Graph()
    size, actions = policy.observation_space.shape[0], policy.action_space.shape[0]
    x = INPUT_NAME
    for name, params in policy.program():
        x = _add_step(g, x, name, params, size)
    g.nodes.append(helper.make_node("Identity", [x], [OUTPUT_NAME], name="action"))
    f32 = onnx.TensorProto.FLOAT
    graph = helper.make_graph(
        g.nodes, "rehabbot_policy",
        [helper.make_tensor_value_info(INPUT_NAME, f32, ["batch", size])],
        [helper.make_tensor_value_info(OUTPUT_NAME, f32, ["batch", actions])],
        initializer=g.initializers)
    model = helper.make_model(graph, producer_name="rehabbot", producer_version=VERSION,
                              opset_imports=[helper.make_opsetid("", OPSET)],
                              ir_version=IR_VERSION,
                              doc_string=f"{metadata.get('source')}: the deterministic actor "
                                         f"of {metadata.get('env_id')}")
    helper.set_model_props(model, {key: json.dumps(value, default=_json_default)
                                   for key, value in metadata.items()})
    onnx.checker.check_model(model, full_check=True)
    return model


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


# --------------------------------------------------------------------------- metadata


def _entry_names(layout: ObservationLayout, base: Any) -> list[str]:
    """``field[entry]`` for every entry of ``layout``: the robot's joints, the exercised
    patient joints, ``x``/``y``/``z`` (per arm), the exercises, or the arm, as the field's
    size and frame say; ``field[k]`` where none fits, ``field`` for a one-entry field."""
    arms = [h.prefix.rstrip("_") for h in base.handles]
    robot_joints = list(getattr(base, "joint_names", None) or base.robot.joint_names)
    patient_joints = list(base.scene.exercised_joints)
    xyz = [f"{arm}_{axis}" if arm else axis for arm in arms for axis in "xyz"]
    exercises = [exercise.name for exercise in base.exercises]
    names = []
    for field in layout.fields:
        if field.size == 1:
            names.append(field.name)
            continue
        entries: list[str] = [str(k) for k in range(field.size)]
        for candidates, fits in (
                (patient_joints, field.name.startswith("phi")),
                (robot_joints, field.frame == "joint"),
                (xyz, field.frame == "robot base"),
                (exercises, field.name == "exercise"),
                (arms, True)):
            if fits and len(candidates) == field.size:
                entries = candidates
                break
        names += [f"{field.name}[{entry}]" for entry in entries]
    return names


def observation_names(env: gym.Env) -> list[str]:
    """The name of every observation entry of ``env`` (its agent layout on the ``-v2`` ids,
    else the paper's; :func:`_entry_names`), e.g. ``joint_error_fine[shoulder_pan]``.

    Raises:
        DataError: the layout's size is not the observation space's.
    """
    base = env.unwrapped
    layout = getattr(base, "agent_layout", None) or base.layout
    names = _entry_names(layout, base)
    if len(names) != env.observation_space.shape[0]:
        raise DataError(f"the observation layout of {env.spec.id if env.spec else base} names "
                        f"{len(names)} entries, its space has {env.observation_space.shape[0]}")
    return names


def policy_metadata(policy: zoo.ZooPolicy, source: str) -> dict[str, Any]:
    """The ONNX file's metadata (:data:`METADATA_KEYS`), read from the env the policy was
    trained in (made with its kwargs)."""
    meta = policy.metadata
    env_kwargs = dict(meta.get("env_kwargs") or {})
    env = gym.make(policy.env_id, **env_kwargs)
    try:
        check_spaces(policy.observation_space, policy.action_space, env, source)
        base = env.unwrapped
        safety = base.safety
        low, high = safety.rom_bounds_rad
        joints = list(base.scene.patient_joint_names)
        rom = {name: [float(low[joints.index(name)]), float(high[joints.index(name)])]
               for name in base.scene.exercised_joints}
        robot_joints = list(getattr(base, "joint_names", None) or base.robot.joint_names)
        values: dict[str, Any] = {
            "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "source": source,
            "env_id": policy.env_id, "env_kwargs": env_kwargs, "algo": policy.algo,
            "backend": meta.get("backend"), "rehabbot_version": VERSION,
            "weights_sha256": meta.get("weights_sha256"),
            "control_rate_hz": 1.0 / float(base.dt), "control_dt_s": float(base.dt),
            "input_name": INPUT_NAME, "output_name": OUTPUT_NAME,
            "observation_names": observation_names(env),
            "observation_low": policy.observation_space.low.tolist(),
            "observation_high": policy.observation_space.high.tolist(),
            "action_names": robot_joints,
            "action_low": policy.action_space.low.tolist(),
            "action_high": policy.action_space.high.tolist(),
            "controller_action_low": np.asarray(base.controller.clip_low, float).tolist(),
            "controller_action_high": np.asarray(base.controller.clip_high, float).tolist(),
            "robot": base.robot.name, "robot_joint_names": robot_joints,
            "control_mode": base.config.control_mode,
            "action_scale": base.config.action_scale,
            "cuff_force_limits_n": [float(f) for f in safety.force_limits_n],
            "range_of_motion_rad": rom,
            "rom_tolerance_deg": float(safety.thresholds.rom_tolerance_deg),
            "ops": list(policy.ops), "agent_metadata": meta,
        }
    finally:
        env.close()
    if len(robot_joints) != policy.action_space.shape[0]:
        raise DataError(f"{source}: {policy.action_space.shape[0]} actions for the "
                        f"{len(robot_joints)} joints of {policy.env_id}")
    return {key: values[key] for key in METADATA_KEYS}


# --------------------------------------------------------------------------- export


def _check_observations(policy: zoo.ZooPolicy) -> np.ndarray:
    """Observations drawn uniformly from the policy's box (seeded; an unbounded entry from
    [-:data:`CHECK_BOUND`, :data:`CHECK_BOUND`])."""
    space = policy.observation_space
    low = np.maximum(space.low.astype(np.float64), -CHECK_BOUND)
    high = np.minimum(space.high.astype(np.float64), CHECK_BOUND)
    rng = np.random.default_rng(CHECK_SEED)
    return rng.uniform(low, high, (CHECK_OBSERVATIONS, low.size)).astype(np.float32)


def write_onnx(policy: zoo.ZooPolicy, out_path: str | Path, source: str) -> dict[str, Any]:
    """Write ``policy`` as the ONNX file ``out_path`` (atomically, read back before it takes
    the name); returns the metadata written.

    Raises:
        OnnxExportError: onnxruntime's actions differ from the program's by more than
            :data:`PARITY_TOLERANCE` on the check observations (nothing is written).
        UsageError: ``out_path`` does not end in ``.onnx`` or is a folder.
        OutputError: the file cannot be written, naming it.
    """
    onnx, ort = _require("onnx", "onnxruntime")
    out_path = check_output_file(Path(out_path), (SUFFIX,), "--out")
    metadata = policy_metadata(policy, source)
    model = build_onnx_model(policy, metadata)
    session = ort.InferenceSession(model.SerializeToString(), _session_options(ort),
                                   providers=["CPUExecutionProvider"])
    observations = _check_observations(policy)
    actions = session.run([OUTPUT_NAME], {INPUT_NAME: observations})[0]
    gap = float(np.max(np.abs(actions - policy.predict(observations)[0])))
    if not gap <= PARITY_TOLERANCE:
        raise OnnxExportError(f"{source}: the ONNX graph's actions differ from the policy's by "
                              f"{gap:.3g} (> {PARITY_TOLERANCE:g}) on {CHECK_OBSERVATIONS} "
                              "observations of its box; nothing was written")
    atomic_save_verified(out_path, lambda tmp: onnx.save_model(model, tmp), load_onnx_policy)
    return metadata


def export_onnx(policy: str | Path, out_path: str | Path, env_id: str | None = None,
                format: str = "onnx") -> dict[str, Any]:
    """Export ``policy`` (``zoo:ENV/AGENT``, a zoo ``.npz``, a run folder or a model zip:
    :func:`resolve_policy`) to ``out_path`` in ``format`` (``onnx``); returns the metadata
    written. The output is checked (suffix, writable folder) before the policy is loaded.

    Raises:
        UsageError: an unknown format or policy, a bad ``out_path``, a missing extra.
        OutputError: ``out_path``'s folder cannot be written.
        DataError: a damaged policy file; :class:`OnnxExportError`.
    """
    if format not in FORMATS:
        raise UsageError(f"unknown export format {format!r}; known: {', '.join(FORMATS)}")
    _require("onnx", "onnxruntime")
    check_output_file(Path(out_path), (SUFFIX,), "--out")
    zoo_policy, source = resolve_policy(policy, env_id)
    return write_onnx(zoo_policy, out_path, source)


# --------------------------------------------------------------------------- running a file


def _session_options(ort: Any) -> Any:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1  # one small network: a thread pool only costs
    options.inter_op_num_threads = 1
    return options


class OnnxPolicy:
    """An exported policy run with onnxruntime; SB3's ``predict``. ``metadata`` is the
    file's metadata (:data:`METADATA_KEYS`, decoded), ``path`` the file."""

    def __init__(self, session: Any, metadata: dict[str, Any], path: Path) -> None:
        self.session, self.metadata, self.path = session, metadata, path
        self.observation_size = len(metadata["observation_names"])
        self.action_size = len(metadata["action_low"])

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """The action for one observation (``(obs_dim,)``) or a batch (``(n, obs_dim)``)."""
        if not deterministic:
            raise UsageError("an exported policy is deterministic (its exploration noise is "
                             "not exported): call predict with deterministic=True")
        obs = np.asarray(observation, dtype=np.float32)
        size = self.observation_size
        if obs.ndim not in (1, 2) or obs.shape[-1] != size:
            raise UsageError(f"observation of shape {obs.shape} does not fit {self.path}: it "
                             f"takes ({size},) or (n, {size})")
        batch = np.ascontiguousarray(obs.reshape(1, size) if obs.ndim == 1 else obs)
        action = self.session.run([OUTPUT_NAME], {INPUT_NAME: batch})[0]
        return (action[0] if obs.ndim == 1 else action), None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.predict(observation)[0]

    def __repr__(self) -> str:
        return (f"OnnxPolicy(env_id={self.metadata.get('env_id')!r}, "
                f"source={self.metadata.get('source')!r}, path={str(self.path)!r})")


def load_onnx_policy(path: str | Path) -> OnnxPolicy:
    """An ONNX file written by :func:`export_onnx`, ready to act (onnxruntime alone).

    Raises:
        DataError: a missing file, one onnxruntime cannot read, or one without this module's
            metadata (:class:`OnnxExportError`), naming it.
        UsageError: onnxruntime is not installed.
    """
    (ort,) = _require("onnxruntime")
    path = Path(path)
    if not path.is_file():
        raise DataError(f"ONNX file {str(path)!r} not found")
    try:
        session = ort.InferenceSession(str(path), _session_options(ort),
                                       providers=["CPUExecutionProvider"])
    except Exception as err:  # onnxruntime raises its own kinds on a damaged file
        raise DataError(f"{path} is not a readable ONNX file ({type(err).__name__}: "
                        f"{str(err).strip()})") from err
    props = session.get_modelmeta().custom_metadata_map
    try:
        metadata = {key: json.loads(props[key]) for key in METADATA_KEYS}
    except KeyError as err:
        raise OnnxExportError(f"{path} is not a rehabbot policy: its metadata lacks "
                              f"{err}") from err
    except json.JSONDecodeError as err:
        raise OnnxExportError(f"{path}: unreadable metadata ({err})") from err
    if metadata["format"] != FORMAT_NAME or metadata["format_version"] != FORMAT_VERSION:
        raise OnnxExportError(f"{path} has the format {metadata['format']!r} version "
                              f"{metadata['format_version']!r}; this rehabbot reads "
                              f"{FORMAT_NAME!r} version {FORMAT_VERSION}")
    return OnnxPolicy(session, metadata, path)


# --------------------------------------------------------------------------- parity


def record_episodes(policy: Any, env_id: str, env_kwargs: Mapping[str, Any] | None,
                    episodes: int, seed: int, at_least: int = 0) -> list[np.ndarray]:
    """The observations of ``episodes`` episodes of ``policy`` (anything with SB3's
    ``predict``, run deterministic) in ``env_id``, and of more episodes until there are
    ``at_least`` in all: one float32 array ``(steps + 1, obs_dim)`` per episode (the reset
    observation and every step's); episode ``k`` is reset with seed ``seed + k``.

    Raises:
        UsageError: ``episodes`` or ``at_least`` below 0, or both 0.
    """
    if episodes < 0 or at_least < 0 or episodes == at_least == 0:
        raise UsageError(f"episodes={episodes!r} and at_least={at_least!r} must be >= 0, "
                         "one of them > 0")
    env = gym.make(env_id, **dict(env_kwargs or {}))
    recorded: list[np.ndarray] = []
    try:
        while len(recorded) < episodes or sum(map(len, recorded)) < at_least:
            obs, _info = env.reset(seed=seed + len(recorded))
            episode = [obs]
            while True:
                action, _ = policy.predict(obs, deterministic=True)
                obs, _reward, terminated, truncated, _info = env.step(action)
                episode.append(obs)
                if terminated or truncated:
                    break
            recorded.append(np.asarray(episode, dtype=np.float32))
    finally:
        env.close()
    return recorded


def record_observations(policy: Any, env_id: str, env_kwargs: Mapping[str, Any] | None,
                        episodes: int, seed: int, at_least: int = 0) -> np.ndarray:
    """The observations of :func:`record_episodes` as one float32 batch ``(n, obs_dim)``."""
    return np.concatenate(record_episodes(policy, env_id, env_kwargs, episodes, seed,
                                          at_least))
