"""Planning a training run: validate the arguments, find what to resume, work out every
setting, before anything is written (:func:`plan_run`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rehabbot.common.errors import RehabbotError, UsageError
from rehabbot.common.extras import install_hint
from rehabbot.rl import runs
from rehabbot.rl.algorithms import ALGO_NAMES, BACKENDS, OFF_POLICY, read_model_data
from rehabbot.rl.backends import check_backend_choice, saved_backend, sbx_available
from rehabbot.rl.hyperparams import Hyperparameters, jsonable

DEFAULT_TIMESTEPS = 200_000
DEFAULT_CHECKPOINT_FREQ = 10_000
DEFAULT_EVAL_FREQ = 10_000
DEFAULT_EVAL_EPISODES = 5
VEC_ENV_KINDS = ("dummy", "subproc", "threads")
DEFAULT_BC_EPISODES = 20  # expert episodes behaviour cloning fits when --demos is not given
# Scripted-expert episodes in the replay buffer with which the shipped off-policy settings
# (sac.yml, td3.yml, ...) were validated (docs/results/learning-v2.md): `rehabbot train` adds
# them unless --demos says otherwise.
SHIPPED_DEMOS = 20


class TrainingError(RehabbotError):
    """Training cannot go on: a damaged checkpoint, an existing run, nothing to resume."""


class TrainingUsageError(TrainingError, UsageError):
    """A bad training argument (seed, step count, resume settings that differ)."""


class NothingToResumeError(TrainingError):
    """``resume`` was asked for a run that has no checkpoint."""


@dataclass
class ResumePoint:
    checkpoint: Path
    steps: int
    replay_buffer: Path | None
    vecnormalize: Path | None


@dataclass
class RunPlan:
    env_id: str
    algo: str
    seed: int
    total_timesteps: int
    out_dir: Path
    run_dir: Path
    n_envs: int
    env_kwargs: dict[str, Any]
    hp: Hyperparameters
    normalize: dict[str, Any] | None
    checkpoint_freq: int
    eval_freq: int
    eval_episodes: int
    progress_bar: bool
    vec: str = "dummy"
    overwrite: bool = False
    resume: ResumePoint | None = None
    manifest: dict[str, Any] | None = None
    skip: str | None = None
    backend: str = "sb3"  # "sb3" or "sbx": the library that trains (and trained) the run
    demos: int = 0  # expert episodes: into the replay buffer (off-policy) or for --bc (PPO)
    bc: bool = False  # PPO: warm-start the actor by behaviour cloning on the demos


def check_demonstrations(algo: str, demos: int | None, bc: bool) -> tuple[int, bool]:
    """``(episodes, bc)`` for ``--demos`` and ``--bc``: demos fill an off-policy algorithm's
    replay buffer; PPO takes them only for behaviour cloning (``bc``, default
    :data:`DEFAULT_BC_EPISODES` episodes).

    Raises:
        TrainingUsageError: a count that is not an integer >= 0; ``bc`` with an off-policy
            algorithm; ``demos`` for PPO without ``bc``; ``bc`` with 0 episodes.
    """
    if demos is not None and (isinstance(demos, bool) or not isinstance(demos, int)
                              or demos < 0):
        raise TrainingUsageError(f"--demos must be an integer >= 0 (expert episodes), got "
                                 f"{demos!r}")
    if bc and algo in OFF_POLICY:
        raise TrainingUsageError(f"--bc is for PPO only; {ALGO_NAMES[algo]} takes the expert's "
                                 "episodes into its replay buffer with --demos N")
    if algo not in OFF_POLICY and demos and not bc:
        raise TrainingUsageError("--demos needs --bc with PPO (an on-policy algorithm has no "
                                 "replay buffer): --demos N --bc clones the expert's N episodes")
    if bc and demos == 0:
        raise TrainingUsageError("--bc needs at least one expert episode (--demos N, N >= 1)")
    episodes = (DEFAULT_BC_EPISODES if demos is None else demos) if bc else (demos or 0)
    return episodes, bool(bc)


def find_resume_point(run_dir: Path, manifest: dict[str, Any] | None) -> ResumePoint | None:
    """The newest checkpoint (by step count); model.zip of a finished run without any."""
    found = runs.checkpoints(run_dir)
    if found:
        steps, path = found[0]
        replay_buffer, vecnormalize = runs.companions(path.parent, steps)
        return ResumePoint(path, steps, replay_buffer if replay_buffer.is_file() else None,
                           runs.stored(vecnormalize))
    model = run_dir / runs.MODEL_NAME
    if model.is_file() and manifest and manifest.get("status") == "finished":
        return ResumePoint(model, int(manifest.get("timesteps_done", 0)), None,
                           runs.stored(run_dir / runs.VECNORMALIZE_NAME))
    return None


def run_is_complete(run_dir: Path, manifest: dict[str, Any] | None, steps: int) -> bool:
    """Whether the run finished at ``steps`` or more with everything written: the manifest
    says so, and model.zip (and the VecNormalize statistics of a normalised run) is there."""
    if not manifest or manifest.get("status") != "finished":
        return False
    if int(manifest.get("timesteps_done") or 0) < steps:
        return False
    if not (run_dir / runs.MODEL_NAME).is_file():
        return False
    return not manifest.get("vecnormalize") or (run_dir / runs.VECNORMALIZE_NAME).is_file()


# The library defaults the two checks below need (SB3 and SBX agree on both).
PPO_DEFAULT_N_STEPS = 2048
OFF_POLICY_DEFAULT_LEARNING_STARTS = 100


def check_run_updates(algo: str, total_timesteps: int, n_envs: int,
                      hp: Hyperparameters) -> None:
    """Refuse (``TrainingUsageError``, naming the numbers) a run too short to update its
    model: a PPO run shorter than one rollout (``n_steps x n_envs`` steps; PPO never trains on
    a partial rollout), or an off-policy run that ends before ``learning_starts`` (expert
    episodes in the buffer do not change when the first update comes)."""
    if algo in OFF_POLICY:
        starts = int(hp.kwargs.get("learning_starts", OFF_POLICY_DEFAULT_LEARNING_STARTS))
        if total_timesteps <= starts:
            raise TrainingUsageError(
                f"total_timesteps={total_timesteps} ends before learning_starts={starts}: "
                f"{algo} would save an untrained model; train for more than {starts} steps "
                "or lower learning_starts")
        return
    rollout = int(hp.kwargs.get("n_steps", PPO_DEFAULT_N_STEPS)) * n_envs
    if total_timesteps < rollout:
        raise TrainingUsageError(
            f"total_timesteps={total_timesteps} is shorter than one {algo} rollout (n_steps="
            f"{rollout // n_envs} x {n_envs} env{'s' if n_envs > 1 else ''} = {rollout} "
            f"steps): the model would never update; train for at least {rollout} steps or "
            "lower n_steps")


def plan_run(env_id: str, algo: str, seed: int, total_timesteps: int | None,
             out_dir: str | Path, *, n_envs: int | None, hp: Hyperparameters,
             env_kwargs: dict[str, Any] | None, resume: bool, overwrite: bool,
             checkpoint_freq: int | None, eval_freq: int | None, eval_episodes: int | None,
             progress_bar: bool, vec: str, backend: str = "auto", demos: int | None = None,
             bc: bool = False) -> RunPlan:
    """Validate one run and work out its settings; writes nothing.

    A new run trains on ``hp.backend``; a resumed one on the backend it was trained with
    (``backend``, the user's choice, must then be ``auto`` or that backend), and ``demos``
    and ``bc`` must be what it was started with (or not given)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise TrainingUsageError(f"seed must be an integer >= 0, got {seed!r}")
    out = Path(out_dir)
    run_dir = runs.run_directory(out, env_id, algo, seed)
    runs.check_run_dir(run_dir, out)
    if run_dir.exists() and not run_dir.is_dir():
        raise TrainingError(f"run directory {run_dir} exists and is not a directory")
    for name, value, minimum in (("total_timesteps", total_timesteps, 1),
                                 ("n_envs", n_envs, 1),
                                 ("checkpoint_freq", checkpoint_freq, 0),
                                 ("eval_freq", eval_freq, 0),
                                 ("eval_episodes", eval_episodes, 1)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < minimum):
            raise TrainingUsageError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if vec not in VEC_ENV_KINDS:
        raise TrainingUsageError(f"vec must be one of {', '.join(VEC_ENV_KINDS)}; got {vec!r}")
    choice = check_backend_choice(backend)
    episodes, bc = check_demonstrations(algo, demos, bc)

    if resume:
        if overwrite:
            raise TrainingUsageError("--resume and --overwrite exclude each other")
        manifest = runs.read_manifest(run_dir) if run_dir.is_dir() else None
        point = find_resume_point(run_dir, manifest) if run_dir.is_dir() else None
        if point is None:
            if runs.has_content(run_dir):
                raise NothingToResumeError(
                    f"nothing to resume in {run_dir} (no checkpoint yet; "
                    f"{runs.describe(run_dir)}); start it again with --overwrite")
            raise NothingToResumeError(f"nothing to resume: {run_dir} does not hold a run; "
                                       "train without --resume first")
        if manifest is None:
            raise TrainingError(f"cannot resume {run_dir}: its {runs.MANIFEST_NAME} is "
                                "missing")
        for key, mine in (("env_id", env_id), ("algo", algo)):
            if str(manifest.get(key)) != mine:
                raise TrainingUsageError(
                    f"cannot resume {run_dir}: it was trained with {key} "
                    f"{manifest.get(key)!r}, not {mine!r}")
        saved_n_envs = int(manifest.get("n_envs", 1))
        if n_envs is not None and n_envs != saved_n_envs:
            raise TrainingUsageError(f"cannot resume {run_dir} with {n_envs} envs: it was "
                                     f"trained with n_envs={saved_n_envs}")
        saved_kwargs = manifest.get("env_kwargs") or {}
        if env_kwargs is not None and json.dumps(jsonable(env_kwargs), sort_keys=True) \
                != json.dumps(jsonable(saved_kwargs), sort_keys=True):
            raise TrainingUsageError(f"cannot resume {run_dir} with env kwargs "
                                     f"{json.dumps(env_kwargs)}: it was trained with "
                                     f"{json.dumps(saved_kwargs)}")
        trained_on = saved_backend(manifest)
        if choice in BACKENDS and choice != trained_on:
            raise TrainingUsageError(f"cannot resume {run_dir} with --backend {choice}: it was "
                                     f"trained with the {trained_on} backend")
        if trained_on == "sbx" and not sbx_available():
            raise TrainingUsageError(f"cannot resume {run_dir}: it was trained with the sbx "
                                     f"backend, which is not installed ({install_hint('sbx')})")
        saved_bc = bool(manifest.get("bc"))
        # With --bc the episodes are cloned (manifest "bc"), else put in the replay buffer.
        saved_record = (manifest.get("bc") if saved_bc else manifest.get("demos")) or {}
        saved_demos = int(saved_record.get("episodes", 0))
        if (demos is not None and episodes != saved_demos) or (bc and not saved_bc):
            started = f"{saved_demos} expert episodes" + (" and --bc" if saved_bc else "")
            raise TrainingUsageError(f"cannot resume {run_dir} with different demonstrations: "
                                     f"it was started with {started} (they are part of its "
                                     "checkpoint)")
        saved_hp = manifest.get("hyperparameters") or {}
        saved_normalize = saved_hp.get("normalize", False)  # False, or VecNormalize kwargs
        normalize = None if saved_normalize in (None, False) else (
            dict(saved_normalize) if isinstance(saved_normalize, dict) else {})
        if normalize is not None and point.vecnormalize is None:
            raise TrainingError(f"cannot resume {run_dir}: checkpoint {point.checkpoint.name} "
                                "lacks its VecNormalize statistics")
        read_model_data(point.checkpoint)  # PolicyError now: unreadable, or a removed class
        total = total_timesteps if total_timesteps is not None \
            else int(manifest.get("total_timesteps", DEFAULT_TIMESTEPS))
        plan = RunPlan(
            env_id=env_id, algo=algo, seed=seed, total_timesteps=total, out_dir=out,
            run_dir=run_dir, n_envs=saved_n_envs, env_kwargs=dict(saved_kwargs), hp=hp,
            normalize=normalize,
            checkpoint_freq=checkpoint_freq if checkpoint_freq is not None
            else int(manifest.get("checkpoint_freq", DEFAULT_CHECKPOINT_FREQ)),
            eval_freq=eval_freq if eval_freq is not None
            else int(manifest.get("eval_freq", DEFAULT_EVAL_FREQ)),
            eval_episodes=eval_episodes if eval_episodes is not None
            else int(manifest.get("eval_episodes", DEFAULT_EVAL_EPISODES)),
            progress_bar=progress_bar, vec=str(manifest.get("vec_env", vec)), resume=point,
            manifest=manifest, backend=trained_on, demos=saved_demos, bc=saved_bc)
        if point.steps >= total and run_is_complete(run_dir, manifest, point.steps):
            plan.skip = (f"{run_dir}: already finished {point.steps} steps (requested "
                         f"{total}); nothing to do")
        # Otherwise a checkpoint at or past ``total`` is finished without training (the
        # final evaluation and save that an interrupt or a kill left undone).
        return plan

    if runs.has_content(run_dir) and not overwrite:
        raise TrainingError(f"{run_dir} already holds a run ({runs.describe(run_dir)}); "
                            "continue it with --resume or start over with --overwrite")
    total = total_timesteps if total_timesteps is not None \
        else (hp.n_timesteps or DEFAULT_TIMESTEPS)
    n_envs = n_envs if n_envs is not None else (hp.n_envs or 1)
    return RunPlan(
        env_id=env_id, algo=algo, seed=seed, total_timesteps=total, out_dir=out,
        run_dir=run_dir, n_envs=n_envs,
        env_kwargs=dict(env_kwargs or {}), hp=hp, normalize=hp.normalize,
        checkpoint_freq=DEFAULT_CHECKPOINT_FREQ if checkpoint_freq is None else checkpoint_freq,
        eval_freq=DEFAULT_EVAL_FREQ if eval_freq is None else eval_freq,
        eval_episodes=DEFAULT_EVAL_EPISODES if eval_episodes is None else eval_episodes,
        progress_bar=progress_bar, vec=vec, overwrite=overwrite, backend=hp.backend,
        demos=episodes, bc=bc)
