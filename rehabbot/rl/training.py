"""Train agents (PPO, SAC, TD3, TQC, CrossQ) on the RehabBot envs with Stable-Baselines3 or
SBX (:mod:`rehabbot.rl.backends`): :func:`train_run` (one run, one seed), written to the run
folder of :mod:`rehabbot.rl.runs`. ``demos`` and ``bc`` start a run from the scripted
expert's episodes (:mod:`rehabbot.rl.demonstrations`).

Checkpoints, ``model.zip`` and ``manifest.json`` are written to a temporary file first and
renamed into place, so a file with its final name is always complete. SIGINT or SIGTERM
during training stops at the next env step, saves a checkpoint, marks the manifest
"interrupted" and raises :class:`TrainingInterrupted` (exit code 130 / 143 in the CLI);
``resume=True`` continues from the newest checkpoint to the requested step count, appending to
the monitor files, the evaluation log and the TensorBoard run.

Stable-Baselines3, PyTorch, SBX and JAX are imported only inside functions, so that
importing this module stays cheap.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import importlib.util
import json
import os
import signal
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, OutputError
from rehabbot.common.files import (
    atomic_write,
    atomic_write_json,
    check_writable_dir,
    naming_write_errors,
    unnamed_write_error,
)
from rehabbot.common.provenance import git_commit, now_iso, package_versions
from rehabbot.common.signals import SignalLatch, deferring_signals
from rehabbot.envs.registration import resolve_env_id
from rehabbot.rl import runs
from rehabbot.rl.algorithms import ALGO_NAMES, OFF_POLICY, algo_class, check_algo
from rehabbot.rl.backends import backend_version, backend_versions, resolve_backend
from rehabbot.rl.callbacks import callback_classes
from rehabbot.rl.hyperparams import Hyperparameters, as_hyperparameters, jsonable
from rehabbot.rl.planning import (
    NothingToResumeError,
    RunPlan,
    TrainingError,
    TrainingUsageError,
    check_run_updates,
    plan_run,
)
from rehabbot.rl.replay_buffer_io import load_replay_buffer
from rehabbot.rl.run_folder import discard_new_run, lock_run_dir, prepare_run_dir
from rehabbot.rl.safe_load import action_noise, load_run_model, save_model
from rehabbot.rl.vecnormalize_io import load_vecnormalize, save_vecnormalize

EVAL_SEED_OFFSET = 10_000
MONITOR_INFO_KEYWORDS = ("is_success", "safety_violation")
SUBPROC_START_METHOD = "spawn"


class TrainingInterrupted(Exception):  # noqa: N818  (not an error)
    """Training was stopped by a signal after saving a checkpoint (raised by ``train_run``)."""

    def __init__(self, run_dir: Path, timesteps_done: int, checkpoint: Path, signum: int) -> None:
        try:
            name = signal.Signals(signum).name
        except ValueError:
            name = f"signal {signum}"
        super().__init__(f"training in {run_dir} interrupted by {name} at {timesteps_done} "
                         f"steps; checkpoint {checkpoint}")
        self.run_dir = run_dir
        self.timesteps_done = timesteps_done
        self.checkpoint = checkpoint
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


def check_env_kwargs(env_id: str, env_kwargs: Mapping[str, Any]) -> None:
    """Build the env once so that bad ``env_kwargs`` fail before anything is written."""
    import gymnasium as gym

    mode = env_kwargs.get("render_mode")
    try:
        if mode is not None and not isinstance(mode, str):  # gym.make calls mode.endswith
            raise ValueError(f"render_mode must be a string or null, got {mode!r}")
        env = gym.make(env_id, **env_kwargs)
    except (TypeError, ValueError) as err:
        raise TrainingUsageError(f"cannot make {env_id} with env kwargs "
                                 f"{json.dumps(env_kwargs)}: {err}") from err
    env.close()


def _check_run_inputs(plan: RunPlan) -> None:
    """Build the env (and the expert, for demos) and refuse a new run too short to update its
    model (:func:`rehabbot.rl.planning.check_run_updates`) before anything is written."""
    check_env_kwargs(plan.env_id, plan.env_kwargs)
    if plan.resume is None:
        check_run_updates(plan.algo, plan.total_timesteps, plan.n_envs, plan.hp)
    if plan.demos and plan.resume is None:
        from rehabbot.rl.demonstrations import check_expert

        check_expert(plan.env_id, plan.env_kwargs)


def _make_env(env_id: str, env_kwargs: dict[str, Any], monitor_file: str | None,
              append: bool, time_offset_s: float, parent_pid: int) -> Any:
    """One Monitor-wrapped env (runs in the worker process for SubprocVecEnv)."""
    import gymnasium as gym
    from stable_baselines3.common.monitor import Monitor

    if os.getpid() != parent_pid:
        # Ctrl+C (and a scheduler's SIGTERM) may reach the whole process group; only the
        # trainer handles them. Workers exit when the trainer closes their pipes.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    env = gym.make(env_id, **env_kwargs)
    override = not (append and monitor_file is not None and os.path.isfile(monitor_file))
    monitor = Monitor if monitor_file is None else \
        naming_write_errors(Monitor, Path(monitor_file))  # it writes the file's header
    env = monitor(env, filename=monitor_file, allow_early_resets=True,
                  info_keywords=MONITOR_INFO_KEYWORDS if monitor_file is not None else (),
                  override_existing=override)
    if env.results_writer is not None:
        writer = env.results_writer
        writer.write_row = naming_write_errors(writer.write_row, Path(writer.file_handler.name))
    if time_offset_s:
        # Keep the monitor's "t" column running on from the previous segment.
        env.t_start = time.time() - time_offset_s
    return env


def _make_vec_env(plan: RunPlan, n_envs: int, seed: int, monitor_dir: Path | None,
                  append: bool = False, time_offsets: Sequence[float] = (),
                  vec: str = "dummy") -> Any:
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if vec == "threads":  # one process, the worlds' physics on threads
        from rehabbot.rl.threaded_vec_env import ThreadedVecEnv

        venv = ThreadedVecEnv(
            plan.env_id, n_envs, dict(plan.env_kwargs),
            monitor_files=None if monitor_dir is None else [
                str(monitor_dir / f"train_{i}.monitor.csv") for i in range(n_envs)],
            info_keywords=MONITOR_INFO_KEYWORDS if monitor_dir is not None else (),
            append=append, time_offsets_s=time_offsets)
        venv.seed(seed)
        return venv
    factories = [
        functools.partial(
            _make_env, plan.env_id, dict(plan.env_kwargs),
            str(monitor_dir / f"train_{i}.monitor.csv") if monitor_dir is not None else None,
            append, time_offsets[i] if i < len(time_offsets) else 0.0, os.getpid())
        for i in range(n_envs)
    ]
    # Worker processes start fresh ("spawn"): a process that forks after rendering or with
    # threads running (OpenGL, PyTorch) can hang.
    venv = SubprocVecEnv(factories, start_method=SUBPROC_START_METHOD) \
        if vec == "subproc" and n_envs > 1 else DummyVecEnv(factories)
    venv.seed(seed)
    return venv


def _progress_bar_available() -> bool:
    """Whether SB3's progress bar can run (it needs rich and tqdm)."""
    return all(importlib.util.find_spec(name) is not None for name in ("rich", "tqdm"))


class _Run:
    """The state of one executing run: its manifest and wall-clock bookkeeping."""

    def __init__(self, plan: RunPlan) -> None:
        self.plan = plan
        self.segment_start = time.monotonic()
        self.segment_started_at = now_iso()
        self.prior_wall_s = float((plan.manifest or {}).get("wall_clock_s", 0.0)) \
            if plan.resume else 0.0
        self.manifest: dict[str, Any] = {}

    def wall_clock_s(self) -> float:
        return round(self.prior_wall_s + time.monotonic() - self.segment_start, 3)

    def rel(self, path: Path) -> str:
        try:
            return path.relative_to(self.plan.run_dir).as_posix()
        except ValueError:
            return str(path)

    def write(self, **updates: Any) -> None:
        self.manifest.update(updates)
        self.manifest["wall_clock_s"] = self.wall_clock_s()
        segment = self.manifest["segments"][-1]
        segment["end_timesteps"] = self.manifest["timesteps_done"]
        segment["status"] = self.manifest["status"]
        segment["wall_clock_s"] = round(time.monotonic() - self.segment_start, 3)
        if self.manifest["status"] != "running":
            segment["ended_at"] = now_iso()
        atomic_write_json(self.plan.run_dir / runs.MANIFEST_NAME, self.manifest)

    def start_manifest(self, seeds: dict[str, int], done: int,
                       learned_from: dict[str, Any] | None = None) -> None:
        plan = self.plan
        versions = {**package_versions(), **backend_versions(plan.backend)}
        segment = {
            "started_at": self.segment_started_at, "ended_at": None,
            "start_timesteps": done, "end_timesteps": done, "status": "running",
            "resumed_from": self.rel(plan.resume.checkpoint) if plan.resume else None,
            "seeds": seeds, "wall_clock_s": 0.0, "command": list(sys.argv),
            "versions": versions, "git_commit": git_commit(),
        }
        if plan.resume is None:
            self.manifest = {
                "format_version": runs.MANIFEST_FORMAT,
                "env_id": plan.env_id,
                "algo": plan.algo,
                "backend": plan.backend,
                "backend_version": backend_version(plan.backend),
                "seed": plan.seed,
                "seeds": seeds,
                "total_timesteps": plan.total_timesteps,
                "timesteps_done": 0,
                "n_envs": plan.n_envs,
                "vec_env": plan.vec,
                "env_kwargs": jsonable(plan.env_kwargs),
                "hyperparameters": plan.hp.to_manifest(),
                "checkpoint_freq": plan.checkpoint_freq,
                "eval_freq": plan.eval_freq,
                "eval_episodes": plan.eval_episodes,
                "eval_deterministic": True,
                "demos": (learned_from or {}).get("demos"),
                "bc": (learned_from or {}).get("bc"),
                "versions": versions,
                "git_commit": git_commit(),
                "command": list(sys.argv),
                "status": "running",
                "started_at": self.segment_started_at,
                "finished_at": None,
                "wall_clock_s": 0.0,
                "resumed_from": None,
                "model": runs.MODEL_NAME,
                "vecnormalize": runs.VECNORMALIZE_NAME if plan.normalize is not None else None,
                "last_checkpoint": None,
                "segments": [segment],
            }
        else:
            self.manifest = dict(plan.manifest or {})
            self.manifest.pop("error", None)
            segments = [dict(old) for old in self.manifest.get("segments", [])]
            if segments and segments[-1].get("status") == "running":
                segments[-1]["status"] = "killed"  # ended without a word: SIGKILL, crash
            self.manifest["segments"] = [*segments, segment]
            self.manifest.update(
                total_timesteps=plan.total_timesteps, timesteps_done=done,
                checkpoint_freq=plan.checkpoint_freq, eval_freq=plan.eval_freq,
                eval_episodes=plan.eval_episodes, versions=versions,
                git_commit=git_commit(), command=list(sys.argv), status="running",
                finished_at=None, resumed_from=self.rel(plan.resume.checkpoint),
                last_checkpoint=self.rel(plan.resume.checkpoint)
                if plan.resume.checkpoint.parent.name == runs.CHECKPOINT_DIR
                else self.manifest.get("last_checkpoint"))
        self.write()


def _setup(plan: RunPlan, run: _Run) -> tuple[Any, Any, Any, int, dict[str, Any] | None]:
    """Envs and model (new or loaded) for ``plan``; returns (model, venv, eval_venv, done,
    previous evaluations)."""
    from stable_baselines3.common.vec_env import VecNormalize

    cls = algo_class(plan.algo, plan.backend)
    run_dir = plan.run_dir
    done = plan.resume.steps if plan.resume else 0
    n_envs = plan.n_envs
    time_offsets: list[float] = []
    previous_evals = None
    if plan.resume:
        per_env = done // n_envs
        time_offsets = [runs.truncate_monitor(run_dir / runs.MONITOR_DIR / f"train_{i}.monitor.csv",
                                          per_env) for i in range(n_envs)]
        previous_evals = runs.load_evaluations(run_dir / runs.EVALUATIONS_PATH, done)
    # Resumed segments use shifted env seeds so that they do not replay the same episodes.
    seeds = {"model": plan.seed + done, "train_env": plan.seed + done,
             "eval_env": plan.seed + EVAL_SEED_OFFSET + done}
    venv = _make_vec_env(plan, n_envs, seeds["train_env"], run_dir / runs.MONITOR_DIR,
                         append=plan.resume is not None, time_offsets=time_offsets,
                         vec=plan.vec)
    eval_venv = None
    try:
        if plan.eval_freq > 0:
            eval_venv = _make_vec_env(plan, 1, seeds["eval_env"], None)
        if plan.normalize is not None:
            if plan.resume is not None and plan.resume.vecnormalize is not None:
                venv = load_vecnormalize(plan.resume.vecnormalize, venv)  # DataError if bad
                venv.training = True
            else:
                venv = VecNormalize(venv, **plan.normalize)
            if eval_venv is not None:
                eval_venv = VecNormalize(eval_venv, training=False, norm_obs=venv.norm_obs,
                                         norm_reward=False, clip_obs=venv.clip_obs,
                                         gamma=venv.gamma, epsilon=venv.epsilon)
        tb_dir = str(run_dir / runs.TB_DIR)
        if plan.resume is None:
            # A copy: SB3 writes into policy_kwargs (e.g. SAC adds use_sde).
            kwargs = copy.deepcopy(plan.hp.kwargs)
            noise = action_noise(plan.hp.to_manifest(), int(venv.action_space.shape[0]))
            if noise is not None:
                kwargs["action_noise"] = noise
            kwargs.setdefault("verbose", 0)
            try:
                model = cls(plan.hp.policy, venv, seed=plan.seed, tensorboard_log=tb_dir,
                            **kwargs)
            except (TypeError, ValueError, AssertionError, KeyError) as err:
                raise TrainingUsageError(f"invalid hyperparameters for "
                                         f"{ALGO_NAMES[plan.algo]} ({plan.hp.source}): "
                                         f"{err}") from err
            learned_from = _learn_from_expert(model, plan)
        else:
            try:
                with warnings.catch_warnings():
                    # The saved n-step replay buffer class makes SB3 warn that ``n_steps`` is
                    # ignored; the buffer loaded below keeps its n-step returns.
                    warnings.filterwarnings("ignore", message=".*n_steps.*is ignored because")
                    model = load_run_model(cls, plan.resume.checkpoint, venv, plan.manifest,
                                           device="auto", tensorboard_log=tb_dir, verbose=0)
            except TrainingError:
                raise
            except DataError as err:
                raise TrainingError(f"cannot load checkpoint {plan.resume.checkpoint}: "
                                    f"{err}") from err
            except Exception as err:  # SB3 raises many kinds on a damaged or foreign file
                raise TrainingError(f"cannot load checkpoint {plan.resume.checkpoint}: "
                                    f"{type(err).__name__}: {err}") from err
            model.set_random_seed(seeds["model"])
            if plan.algo in OFF_POLICY:
                if plan.resume.replay_buffer is not None:
                    load_replay_buffer(model, plan.resume.replay_buffer)  # DataError if bad
                else:
                    print(f"warning: no replay buffer saved with {plan.resume.checkpoint}; "
                          "continuing with an empty one", file=sys.stderr)
        run.start_manifest(seeds, done, learned_from if plan.resume is None else None)
    except BaseException:
        venv.close()
        if eval_venv is not None:
            eval_venv.close()
        raise
    return model, venv, eval_venv, done, previous_evals


def _learn_from_expert(model: Any, plan: RunPlan) -> dict[str, Any]:
    """``--demos`` into the replay buffer, or ``--bc`` for PPO; the manifest's records."""
    if not plan.demos:
        return {}
    from rehabbot.rl import demonstrations

    first_seed = demonstrations.demo_seed(plan.seed)
    if plan.bc:
        episodes = demonstrations.collect_expert_episodes(plan.env_id, dict(plan.env_kwargs),
                                                          plan.demos, first_seed)
        return {"bc": demonstrations.behaviour_clone(model, plan.backend, episodes,
                                                     plan.seed)}
    return {"demos": demonstrations.fill_replay_buffer(model, plan.env_id,
                                                       dict(plan.env_kwargs), plan.demos,
                                                       first_seed)}


def execute(plan: RunPlan) -> Path:
    """Train ``plan`` (holding the run folder's lock); returns the run dir, raises
    :class:`TrainingInterrupted` on a signal. A resumed run whose checkpoint already reached
    ``plan.total_timesteps`` is only finished: model.zip, statistics and manifest written."""
    lock, created_root = lock_run_dir(plan)
    try:
        return _execute_locked(plan, created_root)
    finally:
        lock.release()


def _execute_locked(plan: RunPlan, created_root: Path | None) -> Path:
    # SIGINT/SIGTERM are latched from here on and acted on between steps: a KeyboardInterrupt
    # raised inside the native libraries set up below can be swallowed or abort the process.
    # One that comes after the last step, while the run is finished, is delivered again once
    # the run is whole (deferring_signals).
    with deferring_signals("stopping once the run is set up; nothing is saved before the "
                           "first step") as latch:
        run_dir = _execute_latched(plan, created_root, latch)
    return run_dir


def _execute_latched(plan: RunPlan, created_root: Path | None, latch: SignalLatch) -> Path:
    run_dir = plan.run_dir
    run = _Run(plan)
    try:
        import torch
        from stable_baselines3.common.callbacks import CallbackList, EvalCallback

        torch.set_num_threads(1)
        prepare_run_dir(plan)
        model, venv, eval_venv, done, previous_evals = _setup(plan, run)
        if latch.signum is not None:  # came while setting up: nothing learned, nothing saved
            venv.close()
            if eval_venv is not None:
                eval_venv.close()
            raise KeyboardInterrupt
    except BaseException:
        if plan.resume is None:  # leave nothing half-written behind
            with contextlib.suppress(OSError):
                discard_new_run(plan, created_root)
        raise
    latch.doing = "stopping at the next step and saving a checkpoint"

    checkpointer_cls, stopper_cls = callback_classes()
    n_envs = plan.n_envs

    def on_saved(steps: int, path: Path) -> None:
        run.write(timesteps_done=steps, last_checkpoint=run.rel(path))

    checkpointer = checkpointer_cls(
        max(plan.checkpoint_freq // n_envs, 1) if plan.checkpoint_freq > 0 else sys.maxsize,
        str(run_dir / runs.CHECKPOINT_DIR), on_saved)
    stopper = stopper_cls(plan.total_timesteps, exact_rollouts=plan.algo not in OFF_POLICY,
                          latch=latch)
    # The evaluation of a step runs before its checkpoint: a checkpoint at step n means that
    # the evaluation due at n is in the log (a resume from it does not skip it).
    callbacks: list[Any] = []
    if eval_venv is not None:
        evaluator = EvalCallback(eval_venv, n_eval_episodes=plan.eval_episodes,
                                 eval_freq=max(plan.eval_freq // n_envs, 1),
                                 log_path=str(run_dir / runs.EVAL_DIR), deterministic=True,
                                 verbose=0, warn=False)
        evaluator._on_step = naming_write_errors(evaluator._on_step,  # writes its .npz
                                                 run_dir / runs.EVALUATIONS_PATH)
        if previous_evals:
            evaluator.evaluations_timesteps = previous_evals["timesteps"]
            evaluator.evaluations_results = previous_evals["results"]
            evaluator.evaluations_length = previous_evals["ep_lengths"]
            evaluator.evaluations_successes = previous_evals["successes"]
        callbacks.append(evaluator)
    callbacks += [checkpointer, stopper]
    # Keep the step-based triggers aligned with the run's total step count after a resume.
    for callback in callbacks:
        callback.n_calls = done // n_envs

    progress = plan.progress_bar and _progress_bar_available()
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Training and eval env are not of the "
                                    "same type")
            try:
                if done < plan.total_timesteps:  # else only the final save is left to do
                    model.learn(plan.total_timesteps - done, callback=CallbackList(callbacks),
                                reset_num_timesteps=plan.resume is None,
                                tb_log_name=ALGO_NAMES[plan.algo], progress_bar=progress)
            except KeyboardInterrupt:  # a second signal
                latch.signum = latch.signum or signal.SIGINT
        done = int(model.num_timesteps)
        checkpointer.init_callback(model)  # a finish-only resume never ran learn
        if latch.signum is not None:
            checkpoint = checkpointer.save_now()
            run.write(status="interrupted", timesteps_done=done,
                      last_checkpoint=run.rel(checkpoint))
            raise TrainingInterrupted(run_dir, done, checkpoint, latch.signum)
        # From here a signal no longer stops the run: it is finished first, then the signal
        # is handed back (deferring_signals) to the caller's handler.
        latch.doing = "finishing the run (saving its final model), then stopping"
        checkpoint = checkpointer.save_now()  # final checkpoint, so that --resume can extend
        vec_normalize = model.get_vec_normalize_env()
        if vec_normalize is not None:
            save_vecnormalize(vec_normalize, run_dir / runs.VECNORMALIZE_NAME)
        atomic_write(run_dir / runs.MODEL_NAME, lambda stream: save_model(model, stream))
        run.write(status="finished", timesteps_done=done, finished_at=now_iso(),
                  last_checkpoint=run.rel(checkpoint))
    except (TrainingInterrupted, TrainingError):
        raise
    except BaseException as err:
        with contextlib.suppress(Exception):  # record what happened, then re-raise
            if isinstance(err, KeyboardInterrupt):  # e.g. Ctrl+C while saving after learn
                run.write(status="interrupted")
            else:
                run.write(status="failed", error=f"{type(err).__name__}: {err}")
        if unnamed_write_error(err):  # a writer of a library's own (TensorBoard's events)
            raise OutputError(f"cannot write a file in {str(run_dir)!r} (the TensorBoard "
                              f"log in {runs.TB_DIR}/, or another writer's): "
                              f"{err.strerror or err}") from err
        raise
    finally:
        venv.close()
        if eval_venv is not None:
            eval_venv.close()
    return run_dir


def train_run(env_id: str, algo: str, seed: int, total_timesteps: int | None,
              out_dir: str | Path, *, n_envs: int | None = None,
              hyperparams: str | Path | Mapping[str, Any] | Hyperparameters | None = None,
              env_kwargs: Mapping[str, Any] | None = None, resume: bool = False,
              checkpoint_freq: int | None = None, eval_freq: int | None = None,
              eval_episodes: int | None = None, progress_bar: bool = True,
              overwrite: bool = False, vec: str = "dummy", backend: str = "auto",
              demos: int | None = None, bc: bool = False) -> Path:
    """Train one agent and return its run directory ``out_dir/<env-short>/<algo>/seed<k>``
    (:func:`plan_seeds` for ``[seed]``, then :func:`execute`); a run that is already there
    (``resume`` of a finished run) is left alone. ``None`` takes the settings file's value
    (``total_timesteps``, ``n_envs``), a resumed run's own, or the default.

    ``hyperparams`` is a YAML file path, the name of a settings file shipped with the package
    (``"sac"``), a flat mapping or a :class:`Hyperparameters`;
    ``checkpoint_freq``/``eval_freq`` count env steps (0 turns them off). With ``resume``, the
    run continues from its newest checkpoint until ``total_timesteps`` (n_envs and env_kwargs
    must match the manifest; the saved model's hyperparameters apply). ``backend``: ``auto``
    (SBX if installed, else Stable-Baselines3), ``sb3`` or ``sbx``; a resumed run keeps its
    own. ``demos``: expert episodes added to an off-policy algorithm's replay buffer before
    learning, or, with ``bc`` (PPO only), cloned into PPO's actor (default
    :data:`~rehabbot.rl.planning.DEFAULT_BC_EPISODES`).

    Raises:
        UsageError: a bad id, algorithm, hyperparameter or value (``HyperparameterError``,
            ``TrainingUsageError``); nothing is written.
        TrainingError: an existing run without ``resume`` or ``overwrite``, nothing to resume,
            a damaged checkpoint; nothing is left behind for a new run.
        OutputError: ``out_dir`` cannot be written.
        TrainingInterrupted: SIGINT/SIGTERM stopped training; a checkpoint was saved.
    """
    plan = plan_seeds(env_id, algo, [seed], total_timesteps, out_dir, hyperparams=hyperparams,
                      env_kwargs=env_kwargs, resume=resume, overwrite=overwrite, n_envs=n_envs,
                      checkpoint_freq=checkpoint_freq, eval_freq=eval_freq,
                      eval_episodes=eval_episodes, progress_bar=progress_bar, vec=vec,
                      backend=backend, demos=demos, bc=bc)[0]
    return plan.run_dir if plan.skip is not None else execute(plan)


def plan_seeds(env_id: str, algo: str, seeds: Sequence[int], total_timesteps: int | None,
               out_dir: str | Path, *, hyperparams: str | Path | Mapping[str, Any]
               | Hyperparameters | None = None, env_kwargs: Mapping[str, Any] | None = None,
               resume: bool = False, overwrite: bool = False, n_envs: int | None = None,
               checkpoint_freq: int | None = None, eval_freq: int | None = None,
               eval_episodes: int | None = None, progress_bar: bool = True,
               vec: str = "dummy", backend: str = "auto", demos: int | None = None,
               bc: bool = False) -> list[RunPlan]:
    """Plan one run per seed and check everything (ids, settings, resume points, the output
    folder, the env kwargs) before any of them starts; writes nothing. The arguments are
    those of :func:`train_run`.

    With ``resume``, seeds that have no run yet are started afresh (``--resume`` with more
    seeds than were started); it is an error only if no seed has anything to resume.
    """
    # Planning imports the learning library (JAX, PyTorch): a Ctrl-C is latched until it is
    # done (see rehabbot.common.signals).
    with deferring_signals("stopping once the run is planned"):
        return _plan_seeds(env_id, algo, seeds, total_timesteps, out_dir, hyperparams,
                           env_kwargs, resume, overwrite, n_envs, checkpoint_freq, eval_freq,
                           eval_episodes, progress_bar, vec, backend, demos, bc)


def _plan_seeds(env_id: str, algo: str, seeds: Sequence[int], total_timesteps: int | None,
                out_dir: str | Path, hyperparams: Any, env_kwargs: Mapping[str, Any] | None,
                resume: bool, overwrite: bool, n_envs: int | None,
                checkpoint_freq: int | None, eval_freq: int | None,
                eval_episodes: int | None, progress_bar: bool, vec: str, backend: str,
                demos: int | None, bc: bool) -> list[RunPlan]:
    env_id = resolve_env_id(env_id)
    algo = check_algo(algo)
    hp = as_hyperparameters(hyperparams, env_id, algo, resolve_backend(backend, algo))
    if resume and overwrite:
        raise TrainingUsageError("--resume and --overwrite exclude each other")
    seeds = list(dict.fromkeys(seeds))
    for seed in seeds:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise TrainingUsageError(f"seeds must be integers >= 0, got {seed!r}")
    check_writable_dir(Path(out_dir))
    kwargs = None if env_kwargs is None else dict(env_kwargs)
    common = dict(n_envs=n_envs, hp=hp, env_kwargs=kwargs, overwrite=overwrite,
                  checkpoint_freq=checkpoint_freq, eval_freq=eval_freq,
                  eval_episodes=eval_episodes, progress_bar=progress_bar, vec=vec,
                  backend=backend, demos=demos, bc=bc)
    plans: list[RunPlan | None] = []
    missing: list[NothingToResumeError] = []
    for seed in seeds:
        try:
            plans.append(plan_run(env_id, algo, seed, total_timesteps, out_dir, resume=resume,
                                  **common))
        except NothingToResumeError as err:
            plans.append(None)
            missing.append(err)
    if missing and len(missing) == len(seeds):
        raise TrainingError(str(missing[0]) if len(seeds) == 1 else
                            f"nothing to resume for any of the seeds {seeds} under "
                            f"{runs.run_directory(out_dir, env_id, algo, seeds[0]).parent}")
    resolved: list[RunPlan] = []
    for seed, plan in zip(seeds, plans, strict=True):
        if plan is None:
            run_dir = runs.run_directory(out_dir, env_id, algo, seed)
            if runs.has_content(run_dir):
                raise TrainingError(f"nothing to resume in {run_dir} (no checkpoint yet); "
                                    "start it again with --overwrite")
            plan = plan_run(env_id, algo, seed, total_timesteps, out_dir, resume=False,
                            **common)
        resolved.append(plan)
    checked: set[str] = set()
    for plan in resolved:
        key = json.dumps([plan.env_kwargs, bool(plan.demos and plan.resume is None)],
                         sort_keys=True)
        if plan.skip is None and key not in checked:
            checked.add(key)
            _check_run_inputs(plan)
    return resolved
