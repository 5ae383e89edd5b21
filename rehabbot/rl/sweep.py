"""Sweeps on Ray Tune: env ids × algorithms × seeds (× hyperparameter values), each trial an
ordinary run folder written by :func:`rehabbot.rl.training.train_run` (:func:`run_sweep`).

The sweep's file is read and checked by :mod:`rehabbot.rl.sweep_config`; docs/sweeps.md
describes it. Ray runs one trial per CPU by default (``resources_per_trial``; ``gpu: 1``
gives a trial a GPU of its own), on a local Ray started for the sweep or on an existing cluster
(``address``). Each trial calls ``train_run`` in its Ray worker, or, for ``backend: rsl_rl``,
:func:`~rehabbot.rl.batch_training.train_batched` (rsl_rl's PPO on the batched env), which
writes the same run folder.

**Resuming is our own, not Ray's.** Before Ray starts, every trial's run folder is
inspected (:func:`trial_state`): a finished run that reached its step count is skipped; a run
with a checkpoint (interrupted, killed, or asked for more steps) is continued with
``train_run(..., resume=True)`` (a batched run: ``BatchRunPlan(resume=True)``); a folder that
holds no checkpoint yet is started again; an absent one is started. Each invocation is a fresh
Ray Tune experiment of the trials left (``Tuner.restore`` is not used): the run folders,
written atomically by ``train_run``, are the only state, so a sweep resumes after Ctrl-C, a
crash of the driver, a lost Ray cluster or an edited sweep file (more seeds, more steps) alike.

Ray Tune's files go to ``OUT/_ray/<experiment>`` (its ``storage_path``; never
``~/ray_results``), with a copy of the trials' stdout/stderr in ``logs/`` for a local Ray; the
session folder of a local Ray (sockets, object store) stays in Ray's temp folder, whose Unix
socket paths must be short. ``OUT/sweep.json`` lists every trial, its settings, its run folder
and its status, and is rewritten as trials finish. Ray is imported only inside functions.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rehabbot.common.errors import DataError, RehabbotError, UsageError
from rehabbot.common.extras import install_hint
from rehabbot.common.files import atomic_write_json, check_writable_dir
from rehabbot.common.provenance import now_iso
from rehabbot.common.signals import keeping_signal_handlers
from rehabbot.common.text_tables import text_table
from rehabbot.rl import batch_training, runs
from rehabbot.rl.algorithms import BackendUnavailableError
from rehabbot.rl.backends import DEFAULT_BACKEND
from rehabbot.rl.planning import check_demonstrations, find_resume_point, run_is_complete
from rehabbot.rl.sweep_config import (
    RAY_DIR,
    SWEEP_FILE,
    SweepConfig,
    Trial,
    naming,
)

SWEEP_FORMAT = 1
# Environment of the sweep's Ray: no usage statistics sent; no Tune loggers writing
# TensorBoard files under OUT (they would mix with the runs' own in `tensorboard --logdir`);
# Tune's legacy console output, which verbose=0 silences (the new one prints a banner).
RAY_ENV_DEFAULTS = {"RAY_USAGE_STATS_ENABLED": "0", "TUNE_DISABLE_AUTO_CALLBACK_LOGGERS": "1",
                    "RAY_CHDIR_TO_TRIAL_DIR": "0", "RAY_AIR_NEW_OUTPUT": "0"}
Announce = Callable[[str], None]


class SweepError(RehabbotError):
    """The sweep cannot run: Ray is missing or failed (CLI exit code 1)."""


class SweepUsageError(SweepError, UsageError):
    """A bad sweep argument: resources that no trial can get, nothing to resume (exit 2)."""


@dataclass
class SweepResult:
    """What :func:`run_sweep` did: one record per trial (the entries of sweep.json)."""

    out: Path
    records: list[dict[str, Any]]
    interrupted: bool = False

    @property
    def failed(self) -> list[dict[str, Any]]:
        """The records of trials that failed."""
        return [r for r in self.records if r["status"] == "failed"]


# --------------------------------------------------------------------------- run folders


def trial_state(trial: Trial) -> str:
    """What a trial's run folder needs: ``complete`` (finished at its step count: skip),
    ``resume`` (a checkpoint to continue from), ``restart`` (files but no checkpoint: start
    again) or ``new`` (nothing there)."""
    run_dir = trial.run_dir
    if not runs.has_content(run_dir):
        return "new"
    try:
        manifest = runs.read_manifest(run_dir)
    except DataError:
        return "resume"  # train_run names the damaged manifest
    if trial.batched:
        return _batch_state(run_dir, manifest, trial.total_timesteps)
    if run_is_complete(run_dir, manifest, trial.total_timesteps):
        return "complete"
    if find_resume_point(run_dir, manifest) is not None:
        return "resume"
    return "restart"


def _batch_state(run_dir: Path, manifest: Mapping[str, Any] | None, steps: int) -> str:
    """:func:`trial_state` of a batched (rsl_rl) run: ``complete`` when its manifest says
    finished at ``steps`` or more and its actor (policy.npz) and model.pt are written;
    ``resume`` from its newest checkpoint (or the model.pt of a finished run asked for more
    steps), and for a run of another backend (which
    :func:`~rehabbot.rl.batch_training.train_batched` then refuses by name instead of
    overwriting it); else ``restart``."""
    if manifest and manifest.get("backend") != batch_training.BACKEND:
        return "resume"
    if manifest and manifest.get("status") == "finished" \
            and int(manifest.get("timesteps_done") or 0) >= steps \
            and (run_dir / batch_training.POLICY_NAME).is_file() \
            and (run_dir / batch_training.FULL_MODEL_NAME).is_file():
        return "complete"
    found = batch_training.resume_point(run_dir, manifest)
    return "resume" if found is not None else "restart"


def run_status(trial: Trial) -> dict[str, Any]:
    """Status, steps done and wall-clock of the trial's run folder, from its manifest."""
    try:
        manifest = runs.read_manifest(trial.run_dir) if trial.run_dir.is_dir() else None
    except DataError as err:
        return {"status": "failed", "timesteps_done": None, "wall_clock_s": None,
                "error": str(err)}
    if manifest is None:
        return {"status": "pending", "timesteps_done": None, "wall_clock_s": None,
                "error": None}
    done = manifest.get("timesteps_done")
    finished = trial_state(trial) == "complete"
    status = "finished" if finished else (
        "failed" if manifest.get("status") == "failed" else "interrupted")
    return {"status": status, "timesteps_done": done,
            "wall_clock_s": manifest.get("wall_clock_s"),
            "error": manifest.get("error") if status == "failed" else None}


def run_trial(spec: Mapping[str, Any], command: Sequence[str] = ()) -> dict[str, Any]:
    """Run one trial in this process (what a Ray worker does): start, continue or skip its
    run folder with :func:`train_run`; returns its record (status, steps, wall-clock, error).

    Errors of the run are caught and returned as ``status: failed`` with a one-line
    ``error``. ``command`` (the sweep's command line) is what the run's manifest records.
    """
    from rehabbot.rl.training import train_run

    trial = Trial.from_json(spec)
    state = trial_state(trial)
    action = {"complete": "skipped", "resume": "resumed", "restart": "restarted",
              "new": "trained"}[state]
    started = time.monotonic()
    error = None
    if state != "complete":
        saved_argv = sys.argv
        if command:
            sys.argv = list(command)
        try:
            if trial.batched:
                _train_batched_trial(trial, state)
            else:
                train_run(trial.env_id, trial.algo, trial.seed, trial.total_timesteps,
                          trial.out_dir, n_envs=trial.n_envs,
                          hyperparams=trial.build_hyperparameters(),
                          env_kwargs=trial.env_kwargs, resume=state == "resume",
                          overwrite=state == "restart", eval_freq=trial.eval_freq,
                          eval_episodes=trial.eval_episodes,
                          checkpoint_freq=trial.checkpoint_freq, progress_bar=False,
                          backend=trial.backend or DEFAULT_BACKEND, demos=trial.demos,
                          bc=bool(trial.bc))
        except Exception as err:  # a trial's failure is reported, not raised
            error = " ".join(f"{type(err).__name__}: {err}".split())
        finally:
            sys.argv = saved_argv
    record = {**run_status(trial), "action": action,
              "trial_wall_clock_s": round(time.monotonic() - started, 3)}
    if error is not None:
        record.update(status="failed", error=error)
    elif state != "complete" and record["status"] != "finished":
        record.update(status="failed", error=f"{trial.run_dir} did not finish "
                                             f"({runs.describe(trial.run_dir)})")
    return record


def _train_batched_trial(trial: Trial, state: str) -> Path:
    """Train a batched trial with :func:`~rehabbot.rl.batch_training.train_batched`: the run
    folder ``rehabbot train --backend rsl_rl`` writes, resumed from its newest checkpoint for
    ``state == "resume"``, started over for ``"restart"``."""
    batch_training.share_gpu_with_torch()
    kwargs = {} if trial.checkpoint_freq is None else {"checkpoint_freq": trial.checkpoint_freq}
    plan = batch_training.BatchRunPlan(
        trial.env_id, seed=trial.seed, total_timesteps=trial.total_timesteps,
        out_dir=trial.out_dir, num_envs=trial.n_envs or batch_training.DEFAULT_NUM_ENVS,
        env_kwargs=dict(trial.env_kwargs or {}), settings=trial.build_rsl_settings(),
        resume=state == "resume", overwrite=state == "restart", **kwargs)
    return batch_training.train_batched(plan)


def _ray_trial(config: dict[str, Any]) -> None:
    """The Ray Tune trainable: one trial, one report."""
    from ray import tune

    tune.report(run_trial(config["trial"], config.get("command", ())))


# --------------------------------------------------------------------------- sweep.json


def _record(trial: Trial, status: dict[str, Any], out: Path) -> dict[str, Any]:
    data = trial.to_json()
    for key in ("out_dir", "run_dir"):
        path = Path(data[key])
        data[key] = path.relative_to(out).as_posix() if path.is_relative_to(out) else str(path)
    return {**data, "action": None, "error": None, **status}


class _SweepState:
    """The driver's view of the sweep: records by key, sweep.json, progress lines."""

    def __init__(self, config: SweepConfig, trials: list[Trial], command: Sequence[str],
                 announce: Announce) -> None:
        self.config = config
        self.trials = {trial.key: trial for trial in trials}
        self.records = {trial.key: _record(trial, run_status(trial), config.out)
                        for trial in trials}
        self.command = list(command)
        self.announce = announce
        self.to_run: list[str] = []
        self.reported: set[str] = set()
        self.experiment: str | None = None
        self.address: str | None = None

    def update(self, key: str, values: Mapping[str, Any]) -> None:
        self.records[key].update({k: values[k] for k in (
            "status", "timesteps_done", "wall_clock_s", "error", "action") if k in values})

    def finish(self, key: str, values: Mapping[str, Any]) -> None:
        """Record a trial's end, print its line and rewrite sweep.json."""
        self.update(key, values)
        self.reported.add(key)
        record = self.records[key]
        run_dir = self.trials[key].run_dir
        line = f"[{len(self.reported)}/{len(self.to_run)}] {key}: {record['status']} " \
               f"({record.get('action') or 'not run'}): "
        if record["status"] == "finished":  # steps, wall-clock and the last evaluation
            line += runs.run_summary(run_dir)[len(f"{run_dir}: "):]
        else:
            line += f"{record['timesteps_done'] or 0} of {record['total_timesteps']} steps"
            if record["error"]:
                line += f"; {record['error']}"
        self.announce(line)
        self.write()

    def write(self) -> None:
        atomic_write_json(self.config.out / SWEEP_FILE, {
            "format_version": SWEEP_FORMAT,
            "config": self.config.source,
            "settings": self.config.raw,
            "out": str(self.config.out),
            "command": self.command,
            "ray": {"address": self.address, "storage_path": RAY_DIR,
                    "experiment": self.experiment},
            "updated_at": now_iso(),
            "trials": list(self.records.values()),
        })


def _progress_callback(state: _SweepState) -> Any:
    """A Ray Tune callback that feeds finished trials to ``state`` (in the driver)."""
    from ray.tune import Callback

    class SweepProgress(Callback):
        def on_trial_result(self, iteration: int, trials: list, trial: Any, result: dict,
                            **info: Any) -> None:
            state.update(trial.config["trial"]["key"], result)

        def on_trial_complete(self, iteration: int, trials: list, trial: Any,
                              **info: Any) -> None:
            state.finish(trial.config["trial"]["key"], trial.last_result or {})

        def on_trial_error(self, iteration: int, trials: list, trial: Any,
                           **info: Any) -> None:
            error = trial.get_error() if hasattr(trial, "get_error") else None
            text = " ".join(str(error).split())[-500:] if error else "the Ray trial failed"
            key = trial.config["trial"]["key"]
            state.finish(key, {**run_status(state.trials[key]), "status": "failed",
                               "error": text})

    return SweepProgress()


# --------------------------------------------------------------------------- the sweep


def check_sweep(config: SweepConfig) -> list[Trial]:
    """Every trial of ``config``, checked before anything runs: hyperparameter files and grid
    values, ``demos`` and ``bc``, the env kwargs (each env is built once), the output folder.

    Raises:
        SweepConfigError: a bad setting (names it).
        OutputError: the output folder cannot be written.
    """
    from rehabbot.rl.training import check_env_kwargs

    trials = config.trials()
    for algo in config.algos:
        with naming(f"{config.source}: {algo}"):
            check_demonstrations(algo, config.demos[algo], bool(config.bc[algo]))
    for env_id in config.envs if config.env_kwargs is not None else ():
        with naming(f"{config.source}: env_kwargs"):
            check_env_kwargs(env_id, config.env_kwargs)
    check_writable_dir(config.out)
    return trials


def check_batch_modules(trials: Sequence[Trial]) -> None:
    """Refuse batched (rsl_rl) trials to run on a local Ray without the modules they import
    (JAX, Warp, PyTorch, rsl_rl), before Ray starts rather than in every trial.

    Raises:
        BackendUnavailableError: naming the missing modules and the extra that installs them.
    """
    missing = batch_training.missing_modules() if any(t.batched for t in trials) else []
    if missing:
        raise BackendUnavailableError(
            f"backend {batch_training.BACKEND} needs {', '.join(missing)}, which "
            f"{'is' if len(missing) == 1 else 'are'} not installed "
            f"({batch_training.BATCH_EXTRA_HINT})")


def _init_ray(address: str | None, cpus: int | None) -> tuple[bool, Path | None]:
    """Connect to ``address`` or start a local Ray of ``cpus`` CPUs; returns whether it was
    started here and Ray's session folder (sockets and logs, in Ray's temp folder)."""
    import ray

    if ray.is_initialized():
        return False, None
    kwargs: dict[str, Any] = dict(include_dashboard=False, log_to_driver=False,
                                  logging_level=logging.ERROR)
    if address is not None:
        kwargs["address"] = address
    else:
        kwargs["num_cpus"] = cpus
    try:
        context = ray.init(**kwargs)
    except (ConnectionError, RuntimeError, ValueError) as err:
        where = f"the Ray cluster at {address}" if address else "a local Ray"
        raise SweepError(f"cannot start {where}: {' '.join(str(err).split())}") from err
    info = getattr(context, "address_info", None) or {}
    session = info.get("session_dir")
    return True, Path(session) if session and address is None else None


def _keep_worker_logs(session_dir: Path | None, destination: Path) -> None:
    """Copy the trials' stdout/stderr (Ray's non-empty ``worker-*.out|err``) next to the
    experiment: Ray's session folder stays in its temp folder (Unix sockets there need a
    short path) and is removed by the operating system sooner or later."""
    logs = session_dir / "logs" if session_dir is not None else None
    if logs is None or not logs.is_dir():
        return
    for path in sorted(logs.glob("worker-*")):
        try:
            if path.suffix in (".out", ".err") and path.stat().st_size > 0:
                destination.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, destination / path.name)
        except OSError:
            continue


def check_local_resources(asked: Mapping[str, float], available: Mapping[str, float]) -> None:
    """Refuse ``resources_per_trial`` that the local Ray (``ray.cluster_resources()``:
    ``CPU``, ``GPU``, ``memory``, custom names) cannot give one trial: Ray Tune would wait for
    them for ever. ``gpu: 1`` on a machine where Ray finds no GPU is the likely case.

    Raises:
        SweepUsageError: naming the resource, what a trial asks and what the local Ray has.
    """
    for name, amount in asked.items():
        key = name.upper() if name.lower() in ("cpu", "gpu") else name
        have = float(available.get(key, 0.0))
        if amount > have:
            hint = "; Ray finds no GPU here (CUDA_VISIBLE_DEVICES, drivers): remove gpu or " \
                   "run the sweep on a GPU machine" if key == "GPU" and have == 0 else ""
            raise SweepUsageError(f"resources_per_trial asks for {name}: {amount:g} per trial, "
                                  f"but the local Ray has {have:g}{hint}")


def _run_on_ray(state: _SweepState, pending: list[Trial], address: str | None,
                cpus: int | None) -> bool:
    """Run ``pending`` as one Ray Tune experiment; returns whether it was interrupted."""
    for name, value in RAY_ENV_DEFAULTS.items():
        os.environ.setdefault(name, value)
    try:
        import ray
        from ray import tune
    except ImportError as err:
        raise SweepError(f"rehabbot sweep needs Ray Tune: {install_hint('ray')}"
                         ) from err
    resources = state.config.resources_per_trial
    started, session_dir = _init_ray(address, cpus)
    state.address = address or "local"
    state.experiment = f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"
    logging.getLogger("ray").setLevel(logging.ERROR)
    interrupted = False
    try:
        if started and address is None:
            check_local_resources(resources, ray.cluster_resources())
        tuner = tune.Tuner(
            tune.with_resources(_ray_trial, dict(resources)),
            param_space={"command": state.command,
                         "trial": tune.grid_search([t.to_json() for t in pending])},
            tune_config=tune.TuneConfig(  # trials named by their run folder below OUT
                trial_name_creator=lambda trial: str(trial.config["trial"]["key"]),
                trial_dirname_creator=lambda trial: f"trial_{trial.trial_id}"),
            run_config=tune.RunConfig(
                name=state.experiment, storage_path=str(state.config.out / RAY_DIR),
                verbose=0, callbacks=[_progress_callback(state)],
                failure_config=tune.FailureConfig(max_failures=0)),
        )
        state.write()
        tuner.fit()
    except KeyboardInterrupt:
        interrupted = True
    except tune.TuneError as err:
        raise SweepError(f"Ray Tune failed: {' '.join(str(err).split())}") from err
    finally:
        if started:
            ray.shutdown()
            _keep_worker_logs(session_dir, state.config.out / RAY_DIR / state.experiment
                              / "logs")
    for trial in pending:  # stopped by Ctrl-C (Tune ends the experiment) or never reported
        if trial.key not in state.reported:
            interrupted = True
            state.update(trial.key, {**run_status(trial), "action": "stopped"})
    return interrupted


def run_sweep(config: SweepConfig, *, cpus: int | None = None, address: str | None = None,
              resume: bool = False, dry_run: bool = False, command: Sequence[str] = (),
              announce: Announce = print) -> SweepResult:
    """Run every trial of ``config`` that is not complete yet, on Ray Tune.

    ``cpus`` sizes a local Ray (default ``os.cpu_count()``); ``address`` joins an existing
    cluster instead. With ``resume`` the output folder must hold a previous sweep
    (``sweep.json``); without it the sweep resumes all the same. ``dry_run`` only reports
    what would run. Writes ``OUT/sweep.json``; returns every trial's record.

    Raises:
        SweepConfigError: a bad setting in the sweep file (checked before anything runs).
        SweepUsageError: ``cpus`` with ``address``, too few CPUs (or GPUs) for a trial,
            nothing to resume.
        BackendUnavailableError: batched trials to run on a local Ray without JAX, Warp or
            rsl_rl installed.
        SweepError: Ray is missing, cannot start or fails.
        OutputError: the output folder cannot be written.
    """
    if address is not None and cpus is not None:
        raise SweepUsageError("--cpus sizes a local Ray; with --address the cluster has its "
                              "own CPUs")
    if cpus is not None and (isinstance(cpus, bool) or not isinstance(cpus, int) or cpus < 1):
        raise SweepUsageError(f"cpus must be an integer >= 1, got {cpus!r}")
    if resume and not (config.out / SWEEP_FILE).is_file():
        raise SweepUsageError(f"nothing to resume: {config.out} holds no {SWEEP_FILE}; run the "
                              "sweep without --resume first")
    local_cpus = None if address is not None else (cpus or os.cpu_count() or 1)
    per_trial = config.resources_per_trial.get("cpu", 0)
    if local_cpus is not None and per_trial > local_cpus:
        raise SweepUsageError(f"resources_per_trial asks for {per_trial} CPUs per trial, but "
                              f"the local Ray has {local_cpus}; raise --cpus")
    trials = check_sweep(config)
    state = _SweepState(config, trials, command or sys.argv, announce)
    states = {trial.key: trial_state(trial) for trial in trials}
    pending = [trial for trial in trials if states[trial.key] != "complete"]
    if address is None and not dry_run:
        check_batch_modules(pending)
    for trial in trials:
        if states[trial.key] == "complete":
            state.update(trial.key, {"action": "skipped"})
    counts = {name: sum(1 for s in states.values() if s == name)
              for name in ("complete", "resume", "restart", "new")}
    announce(f"sweep {config.source}: {len(trials)} trials in {config.out}: "
             f"{counts['complete']} complete, {counts['resume']} to resume, "
             f"{counts['new'] + counts['restart']} to start")
    state.to_run = [trial.key for trial in pending]
    interrupted = False
    if dry_run:
        for trial in pending:
            announce(f"  would {'resume' if states[trial.key] == 'resume' else 'train'} "
                     f"{trial.key} to {trial.total_timesteps} steps")
    elif pending:
        where = f"the Ray cluster at {address}" if address else f"a local Ray ({local_cpus} CPUs)"
        announce(f"running {len(pending)} trials on {where}, resources per trial "
                 f"{config.resources_per_trial}; Ray's files in {config.out / RAY_DIR}")
        # ray.init leaves a SIGTERM handler and Tuner.fit a SIGINT handler of their own behind,
        # which would swallow a later signal in the same process.
        with keeping_signal_handlers():
            interrupted = _run_on_ray(state, pending, address, local_cpus)
    if not dry_run:
        state.write()
    return SweepResult(out=config.out, records=list(state.records.values()),
                       interrupted=interrupted)


def format_table(records: Sequence[Mapping[str, Any]]) -> str:
    """The trials as a plain-text table (:func:`rehabbot.common.text_tables.text_table`): run
    folder, status, what was done, steps, wall-clock."""
    rows = []
    for record in records:
        steps = f"{record.get('timesteps_done') or 0}/{record['total_timesteps']}"
        wall = record.get("wall_clock_s")
        rows.append([record["key"], record["status"], record.get("action") or None, steps,
                     runs.format_duration(float(wall)) if wall is not None else None])
    return text_table(["trial", "status", "action", "steps", "wall-clock"], rows)
