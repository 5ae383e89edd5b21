"""Random-action soak test of every registered id in every control mode.

Every cell (a registered ``rehabbot/`` id x a control mode of
:data:`rehabbot.control.CONTROL_MODES`, 16 cells by default) is made with ``gym.make(env_id,
control_mode=mode)`` (the registration's ``TimeLimit`` of 1000 steps applies) and stepped
with ``env.action_space.sample()`` actions for its share of the total step budget (default
1,000,000 steps in all, split evenly: the first ``total % cells`` cells get one step more).
An episode that terminates or is truncated is reset at once. The soak looks for what a long
training run would trip over:

* **exceptions** raised by ``reset`` or ``step`` (any :class:`Exception`): the type, message,
  step, episode, env build and action are recorded, the env is closed and rebuilt and the soak
  goes on with the next episode. After 10 failures in a row without a successful step the
  cell is abandoned (status ``"abandoned"``).
* **non-finite values**: NaN or inf in the observation, the reward or any number or float
  array of ``info`` (nested dicts and lists included), after every ``step`` and ``reset``.
  Counted once per offending field per call (``non_finite_by_field`` names the fields).
* **observations outside** ``env.observation_space`` (``space.contains`` is False; a NaN is
  outside too), with the offending flat indices, values and bounds of the first one.
* **resident memory** (RSS, ``/proc/self/statm`` x page size; off Linux the peak RSS of
  ``resource.getrusage``, which can only grow): per cell, after its warm-up (the first
  ``min(1000, steps // 2)`` steps, which absorb one-off allocations) and at its end, with the
  env still open: ``rss_growth_mib`` and the same per million steps. A leak shows as a growth
  that scales with the steps in every cell; a few MiB once is allocator noise. Per process:
  from the first cell's warm-up to the end of the last cell (envs closed), over all the steps
  in between: the figure that matters for a long run in one process. With ``--workers N`` each
  worker process reports its own; the total row of the table holds their sum.
* **episode ends** by reason: ``success`` (``info["is_success"]``), each safety rule of
  ``info["safety_violation"]`` (:data:`rehabbot.safety.RULES`), ``truncation`` (time limit),
  ``exception`` (cut by an exception) and ``open`` (still running when the cell's budget ran
  out or the run was stopped); they add up to ``episodes`` (the resets that succeeded).
  Random actions mostly trip the cuff-force rule in ``joint_position`` and ``torque`` modes;
  these are the env working as specified, not problems.
* **throughput**: wall-clock and steps/s per cell (make, resets and the checks included).

Reproducibility: with the same ``--seed`` every cell runs the same episodes and actions
whatever the filters, ``--steps`` or ``--workers``: ``--env ID --mode MODE --seed S --steps
N`` replays the first N steps of that cell (e.g. up to a recorded exception). The k-th env
built in a cell (k = 0, then one more after each exception) has its first ``reset`` seeded
with ``reset_seeds[k]`` and its action space with ``action_seeds[k]``, both from
``numpy.random.SeedSequence(seed, spawn_key=(crc32(env_id), crc32(mode), purpose, k))``
(purpose 0: reset, 1: actions); its later resets continue the env's own generator, as
Gymnasium intends. The report records the seeds.

Exit code: 0 clean, 1 if any exception, non-finite value or observation outside the space was
found, 2 for bad arguments, 130 / 143 when stopped by SIGINT (Ctrl-C) / SIGTERM: the run stops
within a fraction of a second, prints the table of what was done and writes the partial report
with ``"complete": false`` (``--out`` is always written atomically: a temporary file renamed
into place).

Usage::

    python benchmarks/performance/soak.py [--steps 1000000] [--seed 0] [--env ID ...]
        [--mode MODE ...] [--workers 1] [--out FILE.json] [--quiet]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import multiprocessing
import os
import shlex
import signal
import sys
import time
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TextIO

import gymnasium as gym
import numpy as np

from rehabbot.common.signals import handling_signals
from rehabbot.envs.config import CONTROL_MODES
from rehabbot.envs.registration import ENV_SPECS

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.performance.soak_report import (
    END_REASONS,
    MAX_CONSECUTIVE_FAILURES,
    WARMUP_STEPS,
    CellReport,
    ProcessMemory,
    SoakReport,
    format_footer,
    format_header,
    format_table,
    rss_mib,
    short_id,
    write_report,
)

__all__ = [
    "DEFAULT_TOTAL_STEPS",
    "END_REASONS",
    "CellReport",
    "CellSpec",
    "ProcessMemory",
    "SoakReport",
    "build_parser",
    "main",
    "make_registered_env",
    "plan_cells",
    "run_soak",
]

DEFAULT_TOTAL_STEPS = 1_000_000
CHECK_EVERY = 256  # steps between progress updates and checks of the stop flag
MAX_EXCEPTION_EXAMPLES = 20  # per cell; the count and the counts by type cover the rest
RESET_PURPOSE, ACTION_PURPOSE = 0, 1

MakeEnv = Callable[[str, str], gym.Env]


# --------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class CellSpec:
    """One cell of the soak: an id in a control mode, its share of the steps and its seeds."""

    index: int
    env_id: str
    control_mode: str
    steps: int
    seed: int  # the run's seed; the cell's own seeds derive from it (:func:`derive_seed`)

    @property
    def warmup_steps(self) -> int:
        """Steps before the first RSS reading of the cell."""
        return max(1, min(WARMUP_STEPS, self.steps // 2))

    @property
    def name(self) -> str:
        return f"{short_id(self.env_id)}/{self.control_mode}"


def derive_seed(seed: int, env_id: str, mode: str, purpose: int, k: int = 0) -> int:
    """A 32-bit seed of the cell (env_id, mode) for ``purpose``, independent of the others."""
    key = (zlib.crc32(env_id.encode()), zlib.crc32(mode.encode()), purpose, k)
    return int(np.random.SeedSequence(seed, spawn_key=key).generate_state(1)[0])


def _unique(items: Sequence[str]) -> list[str]:
    return list(dict.fromkeys(items))


def resolve_env_ids(env_ids: Sequence[str] | None) -> list[str]:
    """Full registered ids (short ids get the ``rehabbot/`` prefix); ValueError if unknown."""
    if not env_ids:
        return list(ENV_SPECS)
    resolved = [env_id if "/" in env_id else f"rehabbot/{env_id}" for env_id in env_ids]
    for given, env_id in zip(env_ids, resolved, strict=True):
        if env_id not in ENV_SPECS:
            raise ValueError(f"unknown env id {given!r}; valid: "
                             f"{', '.join(short_id(known) for known in ENV_SPECS)}")
    return _unique(resolved)


def resolve_modes(control_modes: Sequence[str] | None) -> list[str]:
    """The control modes to run; ValueError if one is unknown."""
    if not control_modes:
        return list(CONTROL_MODES)
    for mode in control_modes:
        if mode not in CONTROL_MODES:
            raise ValueError(f"unknown control mode {mode!r}; valid: {', '.join(CONTROL_MODES)}")
    return _unique(control_modes)


def plan_cells(total_steps: int, env_ids: Sequence[str] | None = None,
               control_modes: Sequence[str] | None = None, seed: int = 0) -> list[CellSpec]:
    """The cells of a soak (ids x modes) with the step budget split evenly; ValueError for a
    bad argument (the message names the value)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed {seed!r} must be an integer >= 0")
    ids, modes = resolve_env_ids(env_ids), resolve_modes(control_modes)
    cells = [(env_id, mode) for env_id in ids for mode in modes]
    if isinstance(total_steps, bool) or not isinstance(total_steps, int) \
            or total_steps < len(cells):
        raise ValueError(f"steps {total_steps!r} must be an integer >= the number of cells "
                         f"({len(cells)})")
    share, extra = divmod(total_steps, len(cells))
    return [CellSpec(index=i, env_id=env_id, control_mode=mode, steps=share + (i < extra),
                     seed=seed) for i, (env_id, mode) in enumerate(cells)]


def make_registered_env(env_id: str, control_mode: str) -> gym.Env:
    """The default env factory: ``gym.make(env_id, control_mode=mode)``."""
    return gym.make(env_id, control_mode=control_mode)


# --------------------------------------------------------------------------- detectors


_NEVER_NON_FINITE = (bool, int, str, bytes, type(None), np.bool_, np.integer)


def non_finite_fields(value: Any, name: str) -> list[tuple[str, list[int]]]:
    """``(field, flat indices)`` of every NaN/inf in ``value``: a number, an array, or dicts,
    lists and tuples of them (other types are skipped)."""
    bad: list[tuple[str, list[int]]] = []
    _collect_non_finite(value, name, bad)
    return bad


_SKIP_EXACT = frozenset({bool, int, str, type(None)})


def _collect_non_finite(value: Any, name: str, bad: list[tuple[str, list[int]]]) -> None:
    # Ordered by frequency in the env's outputs; ABC checks (Mapping) last, they are slow.
    if type(value) in _SKIP_EXACT:
        return
    if isinstance(value, float):  # Python floats and np.float64
        if not math.isfinite(value):
            bad.append((name, []))
    elif isinstance(value, np.ndarray):
        kind = value.dtype.kind
        if kind in "fc":
            finite = np.isfinite(value)
            if not finite.all():
                bad.append((name, np.flatnonzero(~finite).tolist()))
        elif kind == "O":
            for i, item in enumerate(value.flat):
                _collect_non_finite(item, f"{name}[{i}]", bad)
    elif isinstance(value, _NEVER_NON_FINITE):
        pass
    elif isinstance(value, dict):
        for key, item in value.items():
            _collect_non_finite(item, f"{name}.{key}", bad)
    elif isinstance(value, (np.floating, np.complexfloating, complex)):
        if not np.isfinite(value):
            bad.append((name, []))
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _collect_non_finite(item, f"{name}[{i}]", bad)
    elif isinstance(value, Mapping):
        for key, item in value.items():
            _collect_non_finite(item, f"{name}.{key}", bad)


def _listed(values: Any) -> Any:
    return np.asarray(values).tolist()


def outside_details(space: gym.Space, obs: Any) -> dict[str, Any] | None:
    """None if ``obs`` is in ``space``; else what is wrong (offending flat indices, values and
    bounds for a Box)."""
    if isinstance(space, gym.spaces.Box) and isinstance(obs, np.ndarray) \
            and obs.shape == space.shape and obs.dtype == space.dtype:
        inside = (obs >= space.low) & (obs <= space.high)  # NaN fails both
        if inside.all():
            return None
    elif space.contains(obs):
        return None
    if not isinstance(space, gym.spaces.Box):
        return {"reason": f"not in {space}"}
    arr = np.asarray(obs)
    if arr.shape != space.shape:
        return {"reason": f"shape {arr.shape} != {space.shape}"}
    if not np.can_cast(arr.dtype, space.dtype):
        return {"reason": f"dtype {arr.dtype} cannot be cast to {space.dtype}"}
    bad = np.flatnonzero(~((arr >= space.low) & (arr <= space.high)))
    return {"reason": "out of bounds", "indices": bad.tolist(),
            "values": _listed(arr.flat[bad]), "low": _listed(space.low.flat[bad]),
            "high": _listed(space.high.flat[bad])}


# --------------------------------------------------------------------------- one cell


class _Stop:
    """Whether the run should stop: set by a signal handler, a KeyboardInterrupt, or (in a
    worker) by the parent through a shared event."""

    def __init__(self, event: Any = None) -> None:
        self.reason: str | None = None
        self._event = event

    def request(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason
        if self._event is not None:
            self._event.set()

    def requested(self) -> bool:
        return self.reason is not None or (self._event is not None and self._event.is_set())


@dataclass
class _Runtime:
    """What a cell needs from the process running it."""

    stop: _Stop
    memory: ProcessMemory
    add_steps: Callable[[int, str], None]  # (new steps, cell name): progress


class _CellRun:
    """Runs one cell: the env, the episode bookkeeping and the detectors."""

    def __init__(self, spec: CellSpec, make_env: MakeEnv, runtime: _Runtime) -> None:
        self.spec = spec
        self.make_env = make_env
        self.runtime = runtime
        self.report = CellReport(env_id=spec.env_id, control_mode=spec.control_mode,
                                 steps_planned=spec.steps, warmup_steps=spec.warmup_steps,
                                 pid=os.getpid())
        self.env: gym.Env | None = None
        self.reset_seed: int | None = None  # for the first reset of a new env
        self.episode_step = 0
        self.in_episode = False
        self.failures = 0  # exceptions since the last successful step
        self.reported_steps = 0

    # ----------------------------------------------------------------------- bookkeeping
    def _where(self, source: str, action: np.ndarray | None) -> dict[str, Any]:
        return {"source": source, "step": self.report.steps,  # 0-based, in the cell
                "episode": self.report.episodes - self.in_episode,  # 0-based, in the cell
                "episode_step": self.episode_step if source == "step" else None,
                "env": len(self.report.action_seeds) - (source != "make"),  # 0-based build
                "action": None if action is None else _listed(action)}

    def _exception(self, err: Exception, source: str, action: np.ndarray | None) -> None:
        report = self.report
        kind = type(err).__name__
        report.exceptions += 1
        report.exceptions_by_type[kind] = report.exceptions_by_type.get(kind, 0) + 1
        if len(report.exception_examples) < MAX_EXCEPTION_EXAMPLES:
            report.exception_examples.append(
                {"type": kind, "message": str(err), **self._where(source, action)})
        if self.in_episode:
            self._end_episode("exception")
        self.failures += 1
        self._drop_env()

    def _end_episode(self, reason: str) -> None:
        self.report.ends[reason] = self.report.ends.get(reason, 0) + 1
        self.in_episode = False

    def _check(self, source: str, obs: Any, reward: Any, info: Any,
               action: np.ndarray | None) -> None:
        report = self.report
        bad = non_finite_fields(obs, "obs") + non_finite_fields(info, "info")
        if reward is not None:
            bad += non_finite_fields(reward, "reward")
        if bad:
            report.non_finite += len(bad)
            for name, _indices in bad:
                report.non_finite_by_field[name] = report.non_finite_by_field.get(name, 0) + 1
            if report.non_finite_example is None:
                report.non_finite_example = {
                    "fields": {name: indices for name, indices in bad},
                    **self._where(source, action)}
        outside = outside_details(self.env.observation_space, obs)
        if outside is not None:
            report.obs_outside += 1
            if report.obs_outside_example is None:
                report.obs_outside_example = {**outside, **self._where(source, action)}

    # ----------------------------------------------------------------------- env
    def _drop_env(self) -> None:
        if self.env is not None:
            with contextlib.suppress(Exception):
                self.env.close()
        self.env = None

    def _build(self) -> bool:
        try:
            env = self.make_env(self.spec.env_id, self.spec.control_mode)
        except Exception as err:
            self._exception(err, "make", None)
            return False
        spec, report = self.spec, self.report
        k = len(report.action_seeds)
        self.reset_seed = derive_seed(spec.seed, spec.env_id, spec.control_mode, RESET_PURPOSE, k)
        action_seed = derive_seed(spec.seed, spec.env_id, spec.control_mode, ACTION_PURPOSE, k)
        report.reset_seeds.append(self.reset_seed)
        report.action_seeds.append(action_seed)
        env.action_space.seed(action_seed)
        self.env = env
        return True

    def _reset(self) -> bool:
        seed, self.reset_seed = self.reset_seed, None
        self.episode_step = 0
        try:
            obs, info = self.env.reset(seed=seed)
        except Exception as err:
            self._exception(err, "reset", None)
            return False
        self.report.episodes += 1
        self.in_episode = True
        self._check("reset", obs, None, info, None)
        return True

    def _step(self) -> None:
        action = self.env.action_space.sample()
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except Exception as err:
            self._exception(err, "step", action)
            return
        self._check("step", obs, reward, info, action)
        self.report.steps += 1
        self.episode_step += 1
        self.failures = 0
        if terminated or truncated:
            violation = info.get("safety_violation") if isinstance(info, Mapping) else None
            if violation:
                reason = str(violation)
            elif isinstance(info, Mapping) and info.get("is_success"):
                reason = "success"
            else:
                reason = "truncation" if truncated else "terminated"
            self._end_episode(reason)

    # ----------------------------------------------------------------------- loop
    def _progress(self) -> None:
        self.runtime.add_steps(self.report.steps - self.reported_steps, self.spec.name)
        self.reported_steps = self.report.steps

    def run(self) -> CellReport:
        spec, report, runtime = self.spec, self.report, self.runtime
        if runtime.stop.requested():
            return report
        report.status = "complete"
        start_s = time.perf_counter()
        baseline_here = False
        try:
            while report.steps < spec.steps:
                if self.failures >= MAX_CONSECUTIVE_FAILURES:
                    report.status = "abandoned"
                    break
                if self.env is None and not self._build():
                    continue
                if not self.in_episode and not self._reset():
                    continue
                self._step()
                steps = report.steps
                if steps == spec.warmup_steps and report.rss_warmup_mib is None:
                    report.rss_warmup_mib = rss_mib()
                    if runtime.memory.baseline_mib is None:
                        runtime.memory.baseline_mib = report.rss_warmup_mib
                        baseline_here = True
                if steps % CHECK_EVERY == 0:
                    self._progress()
                    if runtime.stop.requested():
                        report.status = "interrupted"
                        break
        except KeyboardInterrupt:
            report.status = "interrupted"
            runtime.stop.request("KeyboardInterrupt")
        finally:
            report.wall_s = time.perf_counter() - start_s
            self._finish(baseline_here)
        return report

    def _finish(self, baseline_here: bool) -> None:
        report, memory = self.report, self.runtime.memory
        if self.in_episode:
            self._end_episode("open")
        report.steps_per_s = report.steps / report.wall_s if report.wall_s > 0 else None
        if report.rss_warmup_mib is not None:
            report.rss_end_mib = rss_mib()
            if report.rss_end_mib is not None:
                report.rss_growth_mib = report.rss_end_mib - report.rss_warmup_mib
                after = report.steps - report.warmup_steps
                if after > 0:
                    report.rss_growth_mib_per_million_steps = report.rss_growth_mib / after * 1e6
        self._drop_env()
        self._progress()
        if memory.baseline_mib is not None:
            memory.steps_since_baseline += (report.steps - report.warmup_steps
                                            if baseline_here else report.steps)
        memory.cells += 1
        memory.end_mib = rss_mib()
        report.process = memory.to_dict()


def run_cell(spec: CellSpec, make_env: MakeEnv, runtime: _Runtime) -> CellReport:
    """Run one cell in this process (exceptions of the env are recorded, not raised)."""
    return _CellRun(spec, make_env, runtime).run()


# --------------------------------------------------------------------------- the run


def _mp_context() -> multiprocessing.context.BaseContext:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


@contextlib.contextmanager
def _stop_on_signals(stop: _Stop) -> Iterator[None]:
    """SIGINT and SIGTERM ask the run to stop (at the next check, within ``CHECK_EVERY``
    steps); the previous handlers come back afterwards. Only in the main thread."""

    def handler(signum: int, _frame: Any) -> None:
        stop.request(signal.Signals(signum).name)

    with handling_signals(handler):
        yield


def _run_serial(specs: Sequence[CellSpec], make_env: MakeEnv, stop: _Stop,
                progress: Callable[[int, str], None]) -> tuple[list[CellReport],
                                                              list[ProcessMemory]]:
    memory = ProcessMemory(pid=os.getpid())
    runtime = _Runtime(stop=stop, memory=memory, add_steps=progress)
    return [run_cell(spec, make_env, runtime) for spec in specs], [memory]


# Worker-process state, set by _init_worker.
_WORKER: dict[str, Any] = {}


def _init_worker(counter: Any, event: Any) -> None:
    # Ctrl-C reaches the whole process group: only the parent handles signals; it tells the
    # workers to stop through ``event``.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)

    def add_steps(steps: int, _name: str) -> None:
        with counter.get_lock():
            counter.value += steps

    _WORKER["runtime"] = _Runtime(stop=_Stop(event), memory=ProcessMemory(pid=os.getpid()),
                                  add_steps=add_steps)


def _worker_cell(spec: CellSpec, make_env: MakeEnv) -> CellReport:
    return run_cell(spec, make_env, _WORKER["runtime"])


def _crashed_cell(spec: CellSpec, err: BaseException) -> CellReport:
    report = CellReport(env_id=spec.env_id, control_mode=spec.control_mode,
                        steps_planned=spec.steps, status="crashed")
    kind = type(err).__name__
    report.exceptions = 1
    report.exceptions_by_type[kind] = 1
    report.exception_examples.append({"type": kind, "message": str(err), "source": "worker"})
    return report


def _run_parallel(specs: Sequence[CellSpec], make_env: MakeEnv, workers: int, stop: _Stop,
                  progress: Callable[[int, str], None]) -> tuple[list[CellReport],
                                                                list[ProcessMemory]]:
    ctx = _mp_context()
    counter, event = ctx.Value("q", 0), ctx.Event()
    stop_parent = _Stop(event)
    reported = 0
    reports: dict[int, CellReport] = {}
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(counter, event)) as pool:
        futures: dict[Future, CellSpec] = {pool.submit(_worker_cell, spec, make_env): spec
                                           for spec in specs}
        pending = set(futures)
        while pending:
            if stop.reason is not None:
                stop_parent.request(stop.reason)
            done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            for future in done:
                spec = futures[future]
                err = future.exception()
                reports[spec.index] = (_crashed_cell(spec, err) if err is not None
                                       else future.result())
            total = counter.value
            progress(total - reported, f"{len(reports)}/{len(specs)} cells done")
            reported = total
    cells = [reports[spec.index] for spec in specs]
    last: dict[int, dict[str, Any]] = {}
    for cell in cells:
        if cell.process and cell.process["cells"] > last.get(cell.pid, {}).get("cells", 0):
            last[cell.pid] = cell.process
    memories = [ProcessMemory(**{k: v for k, v in proc.items()
                                 if k in {f.name for f in dataclasses.fields(ProcessMemory)}})
                for _pid, proc in sorted(last.items())]
    return cells, memories


def run_soak(total_steps: int = DEFAULT_TOTAL_STEPS, env_ids: Sequence[str] | None = None,
             control_modes: Sequence[str] | None = None, seed: int = 0, workers: int = 1,
             make_env: MakeEnv | None = None, *,
             progress: Callable[[int, str], None] | None = None) -> SoakReport:
    """Run the soak and return its report (see the module docstring).

    ``make_env(env_id, mode)`` builds each env (default :func:`make_registered_env`; with
    ``workers > 1`` it must be picklable). ``progress(new_steps, label)`` is called every
    ``CHECK_EVERY`` steps or so. SIGINT / SIGTERM (main thread) and a KeyboardInterrupt raised
    by the env stop the run: the report then has ``complete`` False. ValueError for a bad
    argument, before anything runs."""
    specs = plan_cells(total_steps, env_ids, control_modes, seed)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers {workers!r} must be an integer >= 1")
    make_env = make_env or make_registered_env
    progress = progress or (lambda _steps, _label: None)
    started_at = datetime.now(timezone.utc).isoformat(timespec="seconds")
    stop = _Stop()
    start_s = time.perf_counter()
    with _stop_on_signals(stop):
        if workers == 1:
            cells, memories = _run_serial(specs, make_env, stop, progress)
        else:
            cells, memories = _run_parallel(specs, make_env, min(workers, len(specs)), stop,
                                            progress)
    interrupted = stop.reason or next(
        ("KeyboardInterrupt" for cell in cells if cell.status == "interrupted"), None)
    return SoakReport(seed=seed, total_steps=total_steps,
                      env_ids=_unique([spec.env_id for spec in specs]),
                      control_modes=_unique([spec.control_mode for spec in specs]),
                      workers=workers, cells=cells, processes=memories,
                      wall_s=time.perf_counter() - start_s, interrupted_by=interrupted,
                      started_at=started_at)


# --------------------------------------------------------------------------- output

class _Progress:
    """One progress line on a terminal (redrawn at most once a second), else a line per 10 %."""

    def __init__(self, total: int, stream: TextIO) -> None:
        self.total = total
        self.stream = stream
        self.done = 0
        self.start_s = time.perf_counter()
        self.last_s = 0.0
        self.tty = stream.isatty()
        self.next_fraction = 0.1

    def __call__(self, steps: int, label: str) -> None:
        self.done += steps
        now = time.perf_counter()
        fraction = self.done / self.total
        if self.tty and now - self.last_s < 1.0:
            return
        if not self.tty and fraction < self.next_fraction:
            return
        self.last_s = now
        self.next_fraction = math.floor(fraction * 10 + 1) / 10
        rate = self.done / max(now - self.start_s, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        line = (f"soak: {self.done}/{self.total} steps ({fraction:.0%}), {label}, "
                f"{rate:.0f} steps/s, ETA {eta:.0f} s")
        self.stream.write(f"\r{line}\033[K" if self.tty else f"{line}\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty and self.last_s:
            self.stream.write("\n")
            self.stream.flush()


# --------------------------------------------------------------------------- command line


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")  # one line, no usage block


def build_parser() -> argparse.ArgumentParser:
    """The soak's options."""
    parser = _Parser(prog="soak", description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=DEFAULT_TOTAL_STEPS,
                        help="env steps in total, split evenly over the cells "
                             f"(default {DEFAULT_TOTAL_STEPS})")
    parser.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    parser.add_argument("--env", action="append", metavar="ID",
                        help="only this id (repeatable; short ids like rehab-reach-v0 too)")
    parser.add_argument("--mode", action="append", metavar="MODE",
                        help=f"only this control mode (repeatable): {', '.join(CONTROL_MODES)}")
    parser.add_argument("--workers", type=int, default=1,
                        help="processes running the cells (default 1: this process)")
    parser.add_argument("--out", type=Path, metavar="FILE.json",
                        help="write the full report here (atomically)")
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    return parser


def main(argv: Sequence[str] | None = None, make_env: MakeEnv | None = None) -> int:
    """Run the soak from the command line; returns the exit code (see the module docstring).
    ``make_env`` replaces the env factory (tests)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exit_:  # --help (0) or an argparse error (2, one line on stderr)
        return exit_.code if isinstance(exit_.code, int) else 2
    try:
        specs = plan_cells(args.steps, args.env, args.mode, args.seed)
        if args.workers < 1:
            raise ValueError(f"--workers {args.workers} must be >= 1")
        if args.out is not None:
            args.out.parent.mkdir(parents=True, exist_ok=True)
    except (ValueError, OSError) as err:
        print(f"soak: error: {err}", file=sys.stderr)
        return 2
    progress = None if args.quiet else _Progress(args.steps, sys.stderr)
    if progress is not None:
        print(f"soak: {len(specs)} cells, {args.steps} steps, {args.workers} worker(s)",
              file=sys.stderr, flush=True)
    try:
        report = run_soak(args.steps, args.env, args.mode, args.seed, args.workers, make_env,
                          progress=progress)
    finally:
        if progress is not None:
            progress.close()
    report.command = shlex.join(sys.orig_argv if argv is None else [sys.argv[0], *argv])
    print(format_header(report))
    print(f"command: {report.command}")
    print()
    print(format_table(report))
    print()
    print(format_footer(report))
    sys.stdout.flush()
    if args.out is not None:
        try:
            write_report(report, args.out)
        except OSError as err:
            print(f"soak: error: could not write {args.out}: {err}", file=sys.stderr)
            return report.exit_code() or 1
        print(f"wrote {args.out}", flush=True)
    return report.exit_code()


if __name__ == "__main__":
    sys.exit(main())
