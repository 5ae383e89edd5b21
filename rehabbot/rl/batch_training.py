"""PPO on the batched env (``rehabbot train ID --algo ppo --backend rsl_rl --num-envs N``):
`rsl_rl <https://github.com/leggedrobotics/rsl_rl>`_'s PPO (``rsl-rl-lib``, PyTorch, plain
MLPs) on thousands of MuJoCo Warp worlds (:class:`~rehabbot.rl.rsl_vec_env.RslVecEnv`),
written to the same run folder as every ``rehabbot train`` run.

Why rsl_rl and not Brax: Brax 0.14.2, the newest release, does not run on the JAX that
MuJoCo Warp's MJX path is installed with here (0.10): its PPO calls
``jax.device_put_replicated``, which JAX 0.10 removed (google/brax#671), and its pmapped
training epoch fails on the batched state under JAX's new ``pmap``. rsl_rl is what Isaac Lab,
mjlab and MyoSuite 3 train MuJoCo Warp envs with, and its PyTorch actor exports to the zoo like
our Stable-Baselines3 actors.

::

    OUT/<env-short>/ppo/seed<k>/
        manifest.json                       what ran (backend "rsl_rl"), how far, versions
        training_log.csv                    one row per PPO iteration (episodes that ended in it)
        checkpoints/rsl_ppo_<n>_steps.pt    actor, critic, optimizer, iteration, RNG (torch
                                            state dicts, loaded with weights_only=True)
        model.pt                            the final actor-critic (same contents)
        policy.npz                          the deterministic actor in the zoo's format: what
                                            ``rehabbot evaluate`` and ``rehabbot render`` run
                                            on the CPU env, with NumPy alone

A run stops at a signal after its PPO iteration, saving a checkpoint; ``--resume`` goes on from
the newest one (the networks, optimizer and PyTorch RNG are restored; the worlds start new
episodes from the key of the seed and the iteration).

A wall-clock budget (``--time-limit-s S``) ends a run, as finished, after the first PPO
iteration that ends past ``S`` seconds (``stopped_by: "time_limit"`` in the manifest). The
clock is the manifest's ``wall_clock_s``: from the start of building the batched env (MuJoCo
Warp's compilation included), summed over the segments of a resumed run.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.common.files import FolderLock, atomic_write, atomic_write_json, remove_contents
from rehabbot.common.provenance import (
    distribution_version,
    git_commit,
    now_iso,
    package_versions,
)
from rehabbot.common.signals import SignalLatch, handling_signals
from rehabbot.envs.registration import NAMESPACE, env_short_name, resolve_env_id
from rehabbot.rl import runs
from rehabbot.rl.hyperparam_checks import coerce_number

BACKEND = "rsl_rl"
ALGO = "ppo"
POLICY_NAME = runs.BATCH_POLICY_NAME
FULL_MODEL_NAME = "model.pt"
LOG_NAME = "training_log.csv"
CHECKPOINT_PREFIX = "rsl_ppo"
DEFAULT_NUM_ENVS = 4096
DEFAULT_TIMESTEPS = 50_000_000
# The modules a batched run imports (all from the `gpu` extra), checked before a sweep starts.
BATCH_MODULES = ("jax", "warp", "torch", "tensordict", "rsl_rl")
BATCH_EXTRA_HINT = 'pip install "rehabbot[gpu]"'
# The packages a batched run depends on, recorded in its manifest.
BATCH_PACKAGES = ("rsl-rl-lib", "torch", "tensordict", "jax", "jaxlib", "mujoco-mjx",
                  "warp-lang")
LOG_FIELDS = ("iteration", "timesteps", "wall_clock_s", "episodes", "mean_return",
              "mean_length", "success_rate", "safety_stop_rate", "value_loss",
              "surrogate_loss", "entropy", "learning_rate", "action_std")


@dataclass(frozen=True)
class RslPpoSettings:
    """rsl_rl PPO's settings: its own defaults (as Isaac Lab's and mjlab's tasks use them),
    with our network sizes and the initial action noise of the shipped PPO settings
    (``log_std_init=-1``: a standard deviation of e^-1 = 0.37 of the unit action; at 1.0 most
    exploratory actions would be clipped at the bounds), and no observation normalisation:
    the ``-v2`` observation is already scaled (every entry within [-2, 2]), and rsl_rl's
    running normalisation divided the near-constant entries (joint speeds at rest) by
    ``std + 0.01``, so that small weight changes moved the policy far, and the adaptive
    learning rate fell to its floor (1e-5) in the first iteration and stayed there."""

    num_steps_per_env: int = 24
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    learning_rate: float = 1e-3
    schedule: str = "adaptive"
    desired_kl: float = 0.01
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.005
    clip_param: float = 0.2
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    init_noise_std: float = 0.37
    actor_hidden_dims: tuple[int, ...] = (256, 256, 128)
    critic_hidden_dims: tuple[int, ...] = (256, 256, 128)
    activation: str = "elu"
    obs_normalization: bool = False

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> RslPpoSettings:
        """Settings with ``values`` replacing defaults (:class:`UsageError` naming an unknown
        key or a bad value)."""
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(values) - known)
        if unknown:
            raise UsageError(f"unknown rsl_rl PPO settings {unknown}; known: {sorted(known)}")
        defaults = asdict(cls())
        merged = {**defaults, **{key: _number_like(value, defaults[key])
                                 for key, value in values.items()}}
        for key in ("actor_hidden_dims", "critic_hidden_dims"):
            merged[key] = tuple(merged[key])
        settings = cls(**merged)
        settings.check()
        return settings

    def check(self) -> None:
        for name in ("num_steps_per_env", "num_learning_epochs", "num_mini_batches"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise UsageError(f"{name}={value!r} must be a positive integer")
        for name in ("learning_rate", "gamma", "lam", "clip_param", "init_noise_std"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise UsageError(f"{name}={value!r} must be a positive number")
        if self.schedule not in ("adaptive", "fixed"):
            raise UsageError(f"schedule={self.schedule!r} must be 'adaptive' or 'fixed'")

    def train_cfg(self) -> dict[str, Any]:
        """rsl_rl's configuration dictionary for ``PPO.construct_algorithm``."""
        model = {"class_name": "rsl_rl.models.MLPModel", "activation": self.activation,
                 "obs_normalization": self.obs_normalization}
        return {
            "algorithm": {"class_name": "rsl_rl.algorithms.PPO",
                          "num_learning_epochs": self.num_learning_epochs,
                          "num_mini_batches": self.num_mini_batches,
                          "learning_rate": self.learning_rate, "schedule": self.schedule,
                          "desired_kl": self.desired_kl, "gamma": self.gamma, "lam": self.lam,
                          "entropy_coef": self.entropy_coef, "clip_param": self.clip_param,
                          "value_loss_coef": self.value_loss_coef,
                          "max_grad_norm": self.max_grad_norm},
            "actor": {**model, "hidden_dims": list(self.actor_hidden_dims),
                      "distribution_cfg": {
                          "class_name": "rsl_rl.modules.distribution.GaussianDistribution",
                          "init_std": self.init_noise_std}},
            "critic": {**model, "hidden_dims": list(self.critic_hidden_dims)},
            "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
            "num_steps_per_env": self.num_steps_per_env,
            "multi_gpu": None,
        }


def _number_like(value: Any, default: Any) -> Any:
    """``value``, read as a number where the default is one (PyYAML reads ``3e-4`` as the
    string ``"3e-4"``)."""
    if isinstance(default, (int, float)) and not isinstance(default, bool):
        return coerce_number(value)
    return value


def read_settings(path: str | Path | None, env_id: str,
                  label: str = "--hyperparams") -> dict[str, Any]:
    """rsl_rl PPO settings from a YAML file: a mapping of :class:`RslPpoSettings` fields, or
    of env ids (with or without ``rehabbot/``) to such mappings; {} without a file. ``label``
    names the file's setting in errors.

    Raises:
        UsageError: the file cannot be read, is not YAML or holds no mapping.
    """
    if path is None:
        return {}
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        raise UsageError(f"cannot read {label} {str(path)!r}: {err}") from err
    if not isinstance(data, dict):
        raise UsageError(f"{label} {str(path)!r} must hold a mapping of rsl_rl PPO settings")
    for key in (env_id, env_short_name(env_id)):
        if isinstance(data.get(key), dict):
            return dict(data[key])
    return data


def missing_modules() -> list[str]:
    """The modules of :data:`BATCH_MODULES` that cannot be imported here (found without
    importing them)."""
    import importlib.util

    return [name for name in BATCH_MODULES if importlib.util.find_spec(name) is None]


def share_gpu_with_torch() -> None:
    """Keep JAX from taking 75 % of the GPU's memory when it starts (its default), which
    PyTorch's learner then lacks; a user's own ``XLA_PYTHON_CLIENT_PREALLOCATE`` is kept.
    Call before JAX is imported."""
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")


@dataclass
class BatchRunPlan:
    """One seed's batched PPO run."""

    env_id: str
    seed: int
    total_timesteps: int
    out_dir: Path
    num_envs: int = DEFAULT_NUM_ENVS
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    settings: RslPpoSettings = field(default_factory=RslPpoSettings)
    checkpoint_freq: int = 1_000_000
    resume: bool = False
    overwrite: bool = False
    device: str | None = None  # torch device of the learner: JAX's device when None
    time_limit_s: float | None = None  # wall-clock budget (module docstring); None: no limit

    def __post_init__(self) -> None:
        self.env_id = resolve_env_id(self.env_id)
        for name in ("seed", "total_timesteps", "num_envs", "checkpoint_freq"):
            value = getattr(self, name)
            low = 0 if name in ("seed", "checkpoint_freq") else 1
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise UsageError(f"{name}={value!r} must be an integer >= {low}")
        limit = self.time_limit_s
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int | float)
                                  or not math.isfinite(limit) or limit <= 0):
            raise UsageError(f"time_limit_s={limit!r} must be a number of seconds > 0")
        if self.resume and self.overwrite:
            raise UsageError("--resume and --overwrite exclude each other")
        self.out_dir = Path(self.out_dir)
        self.settings.check()

    @property
    def run_dir(self) -> Path:
        return runs.run_directory(self.out_dir, self.env_id, ALGO, self.seed)

    @property
    def steps_per_iteration(self) -> int:
        return self.num_envs * self.settings.num_steps_per_env


class BatchTrainingInterrupted(Exception):  # noqa: N818  (not an error)
    """A signal stopped the run after saving a checkpoint."""

    def __init__(self, run_dir: Path, timesteps_done: int, checkpoint: Path, signum: int) -> None:
        super().__init__(f"training in {run_dir} interrupted at {timesteps_done} steps; "
                         f"checkpoint {checkpoint}")
        self.run_dir, self.timesteps_done = run_dir, timesteps_done
        self.checkpoint, self.signum = checkpoint, int(signum)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def checkpoint_path(run_dir: Path, steps: int) -> Path:
    return run_dir / runs.CHECKPOINT_DIR / f"{CHECKPOINT_PREFIX}_{steps}_steps.pt"


def newest_checkpoint(run_dir: Path) -> tuple[int, Path] | None:
    """``(steps, path)`` of the run's newest checkpoint, or None."""
    found = []
    for path in (run_dir / runs.CHECKPOINT_DIR).glob(f"{CHECKPOINT_PREFIX}_*_steps.pt"):
        middle = path.name[len(CHECKPOINT_PREFIX) + 1:-len("_steps.pt")]
        if middle.isdigit():
            found.append((int(middle), path))
    return max(found) if found else None


def resume_point(run_dir: Path, manifest: Mapping[str, Any] | None) -> tuple[int, Path] | None:
    """``(steps, path)`` to resume from: the newest checkpoint, or the final model.pt of a
    finished run (saved at its end, with the same contents) when that is newer; None when
    there is neither."""
    found = newest_checkpoint(run_dir)
    model = run_dir / FULL_MODEL_NAME
    if manifest and manifest.get("status") == "finished" and model.is_file():
        done = int(manifest.get("timesteps_done") or 0)
        if found is None or done > found[0]:
            return done, model
    return found


def batch_versions() -> dict[str, str | None]:
    return {**package_versions(), **{name: distribution_version(name)
                                     for name in BATCH_PACKAGES}}


# --------------------------------------------------------------------------- actor export


def actor_program(actor: Any, action_low: np.ndarray, action_high: np.ndarray
                  ) -> list[tuple[str, dict[str, Any]]]:
    """The deterministic actor of rsl_rl's ``MLPModel`` as zoo steps: its empirical
    normalisation ``(x - mean) / (std + eps)``, the MLP, and the clip to the action box that
    the env applies to a Gaussian policy's mean."""
    from rehabbot.rl.zoo_export import _f32, _torch_module_ops

    ops: list[tuple[str, dict[str, Any]]] = []
    if actor.obs_normalization:
        norm = actor.obs_normalizer
        scale = np.asarray(_f32(norm.std), np.float64) + float(norm.eps)
        ops.append(("normalize", {"mean": _f32(norm.mean), "var": scale * scale,
                                  "epsilon": 0.0, "clip": np.inf}))
    # Layer by layer: rsl_rl's MLP holds one activation module at several places, which
    # ``Module.modules()`` would yield once.
    for layer in actor.mlp:
        ops += _torch_module_ops(layer)
    ops.append(("clip", {"low": _f32(action_low), "high": _f32(action_high)}))
    return ops


def write_policy(run_dir: Path, actor: Any, vec: Any, manifest: Mapping[str, Any]) -> Path:
    """Write ``policy.npz`` (zoo format) for the CPU env of the run."""
    import gymnasium as gym

    from rehabbot.rl.zoo import write_zoo_file

    cpu = vec.batched.cpu_env
    ops = actor_program(actor, cpu.action_space.low, cpu.action_space.high)
    observation_space = cpu.observation_space
    assert isinstance(observation_space, gym.spaces.Box)
    metadata = {"env_id": f"{NAMESPACE}/{env_short_name(manifest['env_id'])}",
                "env_kwargs": manifest.get("env_kwargs") or {}, "algo": ALGO,
                "backend": BACKEND, "seed": manifest["seed"],
                "training_steps": manifest["timesteps_done"],
                "train_command": " ".join(manifest.get("command") or []),
                "git_commit": manifest.get("git_commit"),
                "hyperparameters": manifest.get("hyperparameters"),
                "training_versions": manifest.get("versions")}
    path = run_dir / POLICY_NAME
    write_zoo_file(path, ops, observation_space, cpu.action_space, metadata)
    return path


# --------------------------------------------------------------------------- the run


class _Log:
    """``training_log.csv``, appended one row per iteration (kept on resume)."""

    def __init__(self, path: Path, keep_until: int | None) -> None:
        self.path = path
        rows = []
        if keep_until is not None and path.is_file():
            with path.open(newline="", encoding="utf-8") as handle:
                rows = [row for row in csv.DictReader(handle)
                        if int(float(row["timesteps"])) <= keep_until]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=LOG_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
        atomic_write(path, lambda handle: handle.write(buffer.getvalue().encode()))

    def append(self, row: Mapping[str, Any]) -> None:
        with self.path.open("a", newline="", encoding="utf-8") as handle:
            csv.DictWriter(handle, fieldnames=LOG_FIELDS).writerow(
                {key: row.get(key) for key in LOG_FIELDS})


def _save_checkpoint(alg: Any, path: Path, iteration: int, steps: int) -> None:
    import torch

    state = {**alg.save(), "iteration": iteration, "timesteps_done": steps,
             "torch_rng_state": torch.get_rng_state()}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda handle: torch.save(state, handle))


def _load_checkpoint(alg: Any, path: Path) -> tuple[int, int]:
    import torch

    state = torch.load(path, weights_only=True, map_location=alg.device)
    alg.load(state, None, strict=True)
    torch.set_rng_state(state["torch_rng_state"].cpu())
    return int(state["iteration"]), int(state["timesteps_done"])


def _plan_start(plan: BatchRunPlan) -> tuple[dict[str, Any] | None, tuple[int, Path] | None]:
    """The manifest to continue and the checkpoint to resume from (None, None: a new run).

    Raises:
        UsageError: a run already there without --resume/--overwrite; --resume of a run
            that has no checkpoint, of another backend, or whose settings differ.
    """
    run_dir = plan.run_dir
    manifest = runs.read_manifest(run_dir) if run_dir.is_dir() else None
    if plan.resume:
        if manifest is None:
            raise UsageError(f"{run_dir} holds no run to resume")
        if manifest.get("backend") != BACKEND:
            raise UsageError(f"{run_dir} was trained with the {manifest.get('backend')!r} "
                             f"backend, not {BACKEND}")
        for key, mine in (("n_envs", plan.num_envs), ("env_kwargs", plan.env_kwargs),
                          ("hyperparameters", _settings_json(plan.settings))):
            if manifest.get(key) != mine:
                raise UsageError(f"--resume with {key} {mine!r}, but {run_dir} was trained "
                                 f"with {manifest.get(key)!r}")
        used_s = float(manifest.get("wall_clock_s", 0.0))
        if plan.time_limit_s is not None and used_s >= plan.time_limit_s:
            raise UsageError(f"--time-limit-s {plan.time_limit_s:g}: {run_dir} has already "
                             f"trained for {used_s:g} s")
        return manifest, resume_point(run_dir, manifest)
    if run_dir.is_dir() and runs.has_content(run_dir) and not plan.overwrite:
        raise UsageError(f"{run_dir} already holds a run ({runs.describe(run_dir)}); continue "
                         "it with --resume or start over with --overwrite")
    return None, None


def _settings_json(settings: RslPpoSettings) -> dict[str, Any]:
    values = asdict(settings)
    for key in ("actor_hidden_dims", "critic_hidden_dims"):
        values[key] = list(values[key])
    return values


def train_batched(plan: BatchRunPlan,
                  report: Callable[[dict[str, Any]], None] | None = None) -> Path:
    """Train ``plan`` (module docstring); returns the run folder. ``report`` gets each
    iteration's log row.

    Raises:
        UsageError: bad settings, or a run folder that does not fit (see :func:`_plan_start`).
        BatchTrainingInterrupted: SIGINT/SIGTERM, after a checkpoint was saved.
    """
    from rehabbot.rl.rsl_vec_env import RslVecEnv

    started = time.monotonic()  # the run's clock includes building (compiling) the worlds
    old_manifest, resume_from = _plan_start(plan)
    latch = SignalLatch("stopping once the worlds are built; nothing is trained or written")
    with handling_signals(latch):  # compiling is not cut short: a signal is acted on after it
        try:
            vec = RslVecEnv(plan.env_id, plan.num_envs, plan.seed, plan.env_kwargs)
        except ValueError as err:  # an id, kwarg or condition the batched env does not build
            raise UsageError(f"--backend {BACKEND}: {err}") from err
    if latch.signum is not None:
        raise KeyboardInterrupt
    latch.doing = "saving a checkpoint after this PPO iteration"
    run_dir = plan.run_dir
    runs.check_run_dir(run_dir, plan.out_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    lock = FolderLock(run_dir, runs.LOCK_NAME).acquire("run folder")
    try:
        if old_manifest is None and plan.overwrite:
            remove_contents(run_dir, keep=(runs.LOCK_NAME,))
        with handling_signals(latch):
            run_dir = _train_locked(plan, vec, old_manifest, resume_from, latch, report,
                                    started)
    finally:
        lock.release()
    if latch.signum is not None:  # came while the finished run saved: hand it to the caller
        signal.raise_signal(latch.signum)
    return run_dir


def _train_locked(plan: BatchRunPlan, vec: Any, old: dict[str, Any] | None,
                  resume_from: tuple[int, Path] | None, latch: SignalLatch,
                  report: Callable[[dict[str, Any]], None] | None,
                  started: float) -> Path:
    import jax
    import torch
    from rsl_rl.algorithms import PPO

    run_dir = plan.run_dir
    torch.manual_seed(plan.seed)
    device = plan.device or str(vec.device)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl_rl prints the networks
        alg = PPO.construct_algorithm(vec.get_observations(), vec,
                                      plan.settings.train_cfg(), device)
    iteration, done = 0, 0
    if resume_from is not None:
        iteration, done = _load_checkpoint(alg, resume_from[1])
        vec.reset(plan.seed + iteration)
    prior_wall = float((old or {}).get("wall_clock_s", 0.0))
    command = list(sys.argv)
    manifest: dict[str, Any] = dict(old or {}) if old else {
        "format_version": runs.MANIFEST_FORMAT, "env_id": plan.env_id, "algo": ALGO,
        "backend": BACKEND, "backend_version": distribution_version("rsl-rl-lib"),
        "seed": plan.seed, "seeds": {"jax_worlds": plan.seed, "torch": plan.seed},
        "n_envs": plan.num_envs, "vec_env": "rehabbot.batch (MuJoCo Warp)",
        "env_kwargs": dict(plan.env_kwargs),
        "hyperparameters": _settings_json(plan.settings), "started_at": now_iso(),
        "model": POLICY_NAME, "full_model": FULL_MODEL_NAME, "segments": []}
    manifest.update(total_timesteps=plan.total_timesteps, timesteps_done=done,
                    time_limit_s=plan.time_limit_s, stopped_by=None,
                    iterations_done=iteration, status="running", finished_at=None,
                    device={"jax": str(jax.devices()[0]), "torch": device},
                    versions=batch_versions(), git_commit=git_commit(), command=command,
                    resumed_from=(resume_from[1].relative_to(run_dir).as_posix()
                                  if resume_from else None))
    manifest["segments"] = [*manifest.get("segments", []),
                            {"started_at": now_iso(), "start_timesteps": done,
                             "command": command}]

    def write(**updates: Any) -> None:
        manifest.update(updates, wall_clock_s=round(prior_wall + time.monotonic() - started, 3))
        manifest["segments"][-1].update(end_timesteps=manifest["timesteps_done"],
                                        status=manifest["status"])
        atomic_write_json(run_dir / runs.MANIFEST_NAME, manifest)

    write()
    log = _Log(run_dir / LOG_NAME, done if resume_from else None)
    next_checkpoint = (done // plan.checkpoint_freq + 1) * plan.checkpoint_freq \
        if plan.checkpoint_freq else None
    obs = vec.get_observations().to(device)
    alg.train_mode()
    try:
        while done < plan.total_timesteps:
            with torch.inference_mode():
                for _ in range(plan.settings.num_steps_per_env):
                    actions = alg.act(obs)
                    obs, rewards, dones, extras = vec.step(actions.to(vec.device))
                    obs, rewards, dones = obs.to(device), rewards.to(device), dones.to(device)
                    alg.process_env_step(obs, rewards, dones, extras)
                alg.compute_returns(obs)
            losses = alg.update()
            iteration += 1
            done += plan.steps_per_iteration
            row = {"iteration": iteration, "timesteps": done,
                   "wall_clock_s": round(prior_wall + time.monotonic() - started, 3),
                   **vec.finished.take().summary(),
                   "value_loss": losses.get("value"), "surrogate_loss": losses.get("surrogate"),
                   "entropy": losses.get("entropy"),
                   "learning_rate": float(alg.learning_rate),
                   "action_std": float(alg.get_policy().output_std.detach().mean())}
            log.append(row)
            if report is not None:
                report(row)
            due = next_checkpoint is not None and done >= next_checkpoint
            if due or latch.signum is not None:
                path = checkpoint_path(run_dir, done)
                _save_checkpoint(alg, path, iteration, done)
                write(timesteps_done=done, iterations_done=iteration,
                      last_checkpoint=path.relative_to(run_dir).as_posix())
                if next_checkpoint is not None:
                    next_checkpoint = (done // plan.checkpoint_freq + 1) * plan.checkpoint_freq
                if latch.signum is not None:
                    write(status="interrupted")
                    raise BatchTrainingInterrupted(run_dir, done, path, latch.signum)
            else:
                write(timesteps_done=done, iterations_done=iteration)
            if plan.time_limit_s is not None and row["wall_clock_s"] >= plan.time_limit_s:
                manifest["stopped_by"] = "time_limit"
                break
    except BatchTrainingInterrupted:
        raise
    except BaseException as err:
        write(status="failed", error=f"{type(err).__name__}: {err}")
        raise
    # From here a signal no longer stops the run: it is finished first, then the signal is
    # handed back to the caller's handler (train_batched).
    latch.doing = "finishing the run (saving its final model), then stopping"
    _save_checkpoint(alg, run_dir / FULL_MODEL_NAME, iteration, done)
    alg.eval_mode()
    write(status="finished", finished_at=now_iso(), timesteps_done=done,
          iterations_done=iteration, stopped_by=manifest["stopped_by"] or "timesteps")
    write_policy(run_dir, alg.get_policy().to("cpu"), vec, manifest)
    return run_dir
