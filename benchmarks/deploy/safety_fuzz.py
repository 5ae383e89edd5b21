"""Fuzzing the deployment safety filter on the simulated robot: random and adversarial commands,
breaches counted on the simulated state after every decision.

Each case (an id and a robot) runs under each patient condition (:data:`CONDITIONS`) with the
env's own safety termination off (``terminate_on_safety=False``), so that a breach is counted
and the rollout goes on. Commands come in segments of one pattern (:data:`PATTERNS`), drawn
from a seeded generator, and each passes through a :class:`~rehabbot.deploy.safety_filter.
SafetyFilter` configured by :data:`FILTER_SETTINGS` on the
:class:`~rehabbot.deploy.simulator.SimulatorBackend`:

* ``policy``: a smooth random walk within the caps (what a trained policy sends);
* ``uniform``: targets drawn uniformly across the robot's hardware joint range;
* ``jump``: steps 2-50 times what the speed cap allows in one decision;
* ``non_finite``: NaN or +-inf in some joints of a command;
* ``stale_state`` / ``stale_command``: a state or a command older than the filter's limit;
* ``rom_drive``: a command that moves the cuff the way one exercised patient joint moves it,
  toward one of its bounds, 0.05-0.3 rad of robot joint motion ahead (the cuff Jacobians
  of robot and patient, recomputed every decision): straight past the range of motion;
* ``force_push``: a command that moves the cuff the way the patient's limb moves least (the
  smallest singular direction of the patient's cuff Jacobian): into the patient;
* ``oscillate``: sinusoids whose peak acceleration is 0.9-1.3 times the acceleration cap;
* ``missing``: no command for 0.5-3 watchdog timeouts (the robot's servo holds the last
  setpoint; the loop calls :meth:`~rehabbot.deploy.safety_filter.SafetyFilter.watchdog` each
  decision).

After a ``stop``, the backend is stopped (the servos hold the measured position) for
:data:`STOPPED_DECISIONS` decisions, still measured, then the episode and the filter are reset.
A breach is, after any decision:

* ``range``: a patient joint (any of the scene's, not only the exercised ones) beyond its
  anatomical range by more than the env's ``rom_tolerance_deg``: the env's own range rule
  (:meth:`~rehabbot.sim.physics.SafetyMonitor.violated_rom_joints`);
* ``force``: the cuff force above its ISO/TS 15066 limit;
* ``speed``: a measured robot joint speed above the cap plus :data:`SPEED_ALLOWANCE_RAD_S`
  (the servo's tracking: see the constant);
* ``command``: a commanded joint step above the speed cap (round-off allowance 1e-9 relative;
  for ``hold`` and ``back_off``, the step from the measured position where the command first
  drops back onto it, as the filter's rule says): must be exactly zero;
* ``other``: the env reported instability or unintended contact.

:data:`ABLATIONS` runs the same fuzz with one rule removed or loosened, to show the breach each
rule prevents. The filter's cost per call is timed in the same run (wall clock and CPU time
around every call).

Usage::

    python benchmarks/deploy/safety_fuzz.py [--commands 2000] [--cases knee reach ...]
        [--conditions healthy ...] [--seed 0] [--page docs/results/safety-filter]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.deploy.backend import RobotState
from rehabbot.deploy.safety_filter import ACTIONS, FilterConfig, SafetyFilter
from rehabbot.deploy.simulator import SimulatorBackend

# name -> (id, extra env kwargs).
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "knee": ("rehab-knee-v2", {}),
    "reach": ("rehab-reach-v2", {}),
    "reach-fr3": ("rehab-reach-v2", {"robot": "fr3"}),
    "knee-fr3": ("rehab-knee-v2", {"robot": "fr3"}),
}
# name -> PatientCondition fields.
CONDITIONS: dict[str, dict[str, Any]] = {
    "healthy": {},
    "spastic MAS 3": {"spasticity_mas": "3"},
    "resistive": {"effort": "resistive", "effort_fraction": 0.1},
    "contracture": {"stiffness_scale": 3.0, "rom_scale": 0.7},
    "tremor": {"tremor_hz": 5.0, "tremor_amplitude_nm": 1.0},
}
# What the therapist sets (the rest: the simulator's bounds and limits).
FILTER_SETTINGS: dict[str, Any] = {
    "max_speed_rad_s": 0.25, "max_accel_rad_s2": 2.5, "rom_margin_rad": math.radians(5.0),
    "hold_fraction": 0.6, "back_off_fraction": 0.8, "max_state_age_s": 0.05,
    "max_command_age_s": 0.05, "watchdog_timeout_s": 0.1, "max_patient_speed_rad_s": 0.5}
# A measured joint speed may exceed the commanded cap by this much before it counts. The
# simulated servos are impedances (the wrists' stiffness 60-200 N·m/rad): a loaded cuff that a
# hold or a back off releases, or the patient's limb (tremor, reflex, effort), moves a wrist
# joint faster than its setpoint moves. Measured here up to ~0.7 rad/s at a 0.25 rad/s cap; a
# robot driven at its own rated speeds (2.6-3.1 rad/s) shows far above it (the ablations).
SPEED_ALLOWANCE_RAD_S = 0.5
COMMAND_ROUNDOFF = 1e-9
STOPPED_DECISIONS = 5
# pattern -> (weight, shortest, longest segment in decisions).
PATTERNS: dict[str, tuple[float, int, int]] = {
    "policy": (0.18, 20, 60), "uniform": (0.08, 5, 40), "jump": (0.08, 5, 40),
    "non_finite": (0.04, 1, 1), "stale_state": (0.04, 1, 1), "stale_command": (0.04, 1, 1),
    "rom_drive": (0.22, 30, 120), "force_push": (0.18, 30, 120), "oscillate": (0.08, 30, 100),
    "missing": (0.06, 0, 0)}
BREACHES = ("range", "force", "speed", "command", "other")
NO_FORCE = {"cuff_force_limit_n": None}
# The rules on the patient's joints: the range and the patient speed cap.
NO_RANGE = {"rom_low_rad": None, "rom_high_rad": None, "patient_joint_names": None,
            "max_patient_speed_rad_s": None}
# What each rule prevents: the same fuzz with a rule removed or loosened. name -> (case,
# condition, settings (the filter's and the checks'), config overrides (the filter's alone)).
ABLATIONS: dict[str, tuple[str, str, dict[str, Any], dict[str, Any]]] = {
    "force rule off": ("knee", "healthy", {}, NO_FORCE),
    "force and patient-joint rules off": ("reach", "contracture", {},
                                          {**NO_FORCE, **NO_RANGE}),
    "patient speed cap off (FR3 knee)": ("knee-fr3", "resistive", {},
                                         {"max_patient_speed_rad_s": None}),
    "patient speed cap off (FR3 arm)": ("reach-fr3", "healthy", {},
                                        {"max_patient_speed_rad_s": None}),
    "robot caps 2.5 rad/s, 50 rad/s², no overspeed hold": (
        "reach", "healthy", {}, {"max_speed_rad_s": 2.5, "max_accel_rad_s2": 50.0,
                                 "overspeed_factor": None}),
    "robot caps doubled: 0.5 rad/s, 5 rad/s²": (
        "knee", "healthy", {"max_speed_rad_s": 0.5, "max_accel_rad_s2": 5.0}, {}),
}


def seed_of(case: str, condition: str, base: int) -> int:
    """The seed of a case under a condition (the same in the main runs and the ablations)."""
    return base + 100 * list(CASES).index(case) + list(CONDITIONS).index(condition)


INTRO = """Random and adversarial joint commands driven through {doc} on the simulated robot
and patient, with the env's own safety termination off so that a breach is counted and the
rollout goes on. Breaches are measured on the simulated state after
every decision (50 per simulated second), stopped decisions included. The filter's settings:
speed cap {speed} rad/s and acceleration cap {accel} rad/s² on every robot joint (a hold above
{overspeed} times the cap, measured), {patient} rad/s on every exercised patient joint, range
margin {margin:.1f}°, hold at {hold} and back off at {back} of the cuff's ISO/TS 15066 limit,
states and commands at most {age} s old, watchdog {watchdog} s. Cases: the knee (`rehab-knee-v2`)
and the arm's reach (`rehab-reach-v2`), each with the UR5e and the FR3 (`robot="fr3"`);
conditions: healthy, spastic (Modified Ashworth 3), resistive (10 % of the strength against
the motion), contracture (stiffness x 3, range x 0.7) and a 5 Hz, 1 N·m tremor."""


@dataclass
class FuzzResult:
    """What one case under one condition gave."""

    case: str
    condition: str
    commands: int = 0
    decisions: int = 0
    episodes: int = 0
    actions: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ACTIONS, 0))
    patterns: dict[str, int] = field(default_factory=lambda: dict.fromkeys(PATTERNS, 0))
    breaches: dict[str, int] = field(default_factory=lambda: dict.fromkeys(BREACHES, 0))
    max_force_ratio: float = 0.0
    max_speed_ratio: float = 0.0
    max_command_speed_ratio: float = 0.0
    min_rom_clearance_deg: float = math.inf
    force_at_furniture: int = 0
    first_breaches: list[dict[str, Any]] = field(default_factory=list)
    call_ns: list[int] = field(default_factory=list, repr=False)
    call_cpu_ns: list[int] = field(default_factory=list, repr=False)


class Fuzzer:
    """One backend, one filter, one generator: :meth:`run` drives ``commands`` commands."""

    def __init__(self, case: str, condition: str, seed: int,
                 settings: dict[str, Any] | None = None,
                 config_overrides: dict[str, Any] | None = None,
                 patterns: Sequence[str] | None = None) -> None:
        env_id, kwargs = CASES[case]
        self.patterns = list(PATTERNS) if patterns is None else list(patterns)
        unknown = sorted(set(self.patterns) - set(PATTERNS))
        if unknown:
            raise ValueError(f"unknown patterns {unknown}; valid: {list(PATTERNS)}")
        self.rng = np.random.default_rng(seed)
        self.backend = SimulatorBackend(env_id, terminate_on_safety=False,
                                        condition=dict(CONDITIONS[condition]), **kwargs)
        self.settings = {**FILTER_SETTINGS, **(settings or {})}
        self.config = FilterConfig.for_simulator(
            self.backend, **{**self.settings, **(config_overrides or {})})
        self.filter = SafetyFilter(self.config)
        self.result = FuzzResult(case=case, condition=condition)
        env = self.backend.env
        self.model, self.data = env.model, env.data
        handle = env.handle
        self.robot_dofs = np.asarray(handle.dof_adr)
        self.patient_dofs = np.asarray(env.scene.exercised_dof_adr)
        self.robot_site, self.patient_site = handle.cuff_site_id, handle.patient_cuff_site_id
        ranges = np.asarray(handle.robot.joint_range_rad)
        self.robot_low, self.robot_high = ranges[:, 0], ranges[:, 1]
        self.n = len(self.robot_dofs)
        self.speed_cap = float(self.settings["max_speed_rad_s"])
        self.step_cap = self.speed_cap * self.backend.control_dt_s
        self.jac = np.zeros((3, self.model.nv))
        self.force_limit_n = self.backend.cuff_force_limit_n()
        self.patient_qpos = np.asarray(env.scene.exercised_qpos_adr)
        self.is_patient = np.zeros(self.model.ngeom, dtype=bool)
        self.is_patient[np.asarray(env.scene.patient_geom_ids, dtype=int)] = True
        self.is_furniture = np.zeros(self.model.ngeom, dtype=bool)
        self.is_furniture[np.asarray(env.scene.furniture_geom_ids, dtype=int)] = True
        self.rom_low, self.rom_high = self.backend.rom_bounds_rad()
        self._seeds = iter(self.rng.integers(0, 2**31, size=1_000_000).tolist())
        self._start()

    # -- the episode ---------------------------------------------------------------------------
    def _start(self) -> None:
        self.backend.reset(seed=next(self._seeds))
        self.filter.reset(self.backend.state())
        self.result.episodes += 1

    def _measure(self, info: dict, pattern: str) -> None:
        """Count the breaches of the state after one decision."""
        result, env, data = self.result, self.backend.env, self.data
        force = float(env.safety.cuff_force_n(data))
        speed = float(np.abs(data.qvel[self.robot_dofs]).max())
        result.decisions += 1
        result.max_force_ratio = max(result.max_force_ratio, force / self.force_limit_n)
        result.max_speed_ratio = max(result.max_speed_ratio, speed / self.speed_cap)
        patient = data.qpos[self.patient_qpos]
        clearance = min(float((patient - self.rom_low).min()),
                        float((self.rom_high - patient).min()))
        result.min_rom_clearance_deg = min(result.min_rom_clearance_deg,
                                           math.degrees(clearance))
        found = []
        if env.safety.violated_rom_joints(data):
            found.append(("range", ", ".join(env.safety.violated_rom_joints(data))))
        if force > self.force_limit_n:
            found.append(("force", force))
            result.force_at_furniture += self._limb_on_furniture()
        if speed > self.speed_cap + SPEED_ALLOWANCE_RAD_S:
            found.append(("speed", speed))
        if info.get("safety_violation") in ("instability", "unintended_contact"):
            found.append(("other", info["safety_violation"]))
        self._count(found, pattern)

    def _limb_on_furniture(self) -> bool:
        """Whether the patient's body touches the furniture (chair, leg rest) now."""
        data = self.data
        if not data.ncon:
            return False
        geom = data.contact.geom
        patient, furniture = self.is_patient[geom], self.is_furniture[geom]
        return bool(((patient[:, 0] & furniture[:, 1]) | (patient[:, 1] & furniture[:, 0])).any())

    def _count(self, found: list[tuple[str, Any]], pattern: str) -> None:
        for kind, value in found:
            self.result.breaches[kind] += 1
            if len(self.result.first_breaches) < 10:
                self.result.first_breaches.append(
                    {"kind": kind, "value": value if isinstance(value, str) else float(value),
                     "pattern": pattern, "decision": self.result.decisions})

    def _command(self, q: np.ndarray, pattern: str) -> bool:
        """One decision of the robot toward ``q``; False when the episode ended (reset)."""
        self.backend.command(q)
        _obs, _reward, terminated, truncated, info = self.backend.last_step
        self._measure(info, pattern)
        if terminated or truncated:
            self._start()
            return False
        return True

    def _stopped(self, pattern: str) -> None:
        """The stop: the backend holds, measured for a few decisions; then a new episode."""
        self.backend.stop()
        hold = np.zeros(self.backend.wrapped.action_space.shape, dtype=np.float32)
        for _ in range(STOPPED_DECISIONS):
            _obs, _reward, terminated, truncated, info = self.backend.wrapped.step(hold)
            self._measure(info, pattern)
            if terminated or truncated:
                break
        self._start()

    # -- the commands --------------------------------------------------------------------------
    def _cuff_jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """The cuff's position Jacobian over the robot joints (3 x n) and the patient's
        exercised joints (3 x m), at the present state."""
        model, data, jac = self.model, self.data, self.jac
        mujoco.mj_jacSite(model, data, jac, None, self.robot_site)
        robot = jac[:, self.robot_dofs].copy()
        mujoco.mj_jacSite(model, data, jac, None, self.patient_site)
        return robot, jac[:, self.patient_dofs].copy()

    def _toward(self, state: RobotState, cartesian: np.ndarray, reach_rad: float) -> np.ndarray:
        """A command ``reach_rad`` (largest joint) along the robot motion that moves the cuff
        along ``cartesian``."""
        robot, _ = self._cuff_jacobians()
        dq = np.linalg.pinv(robot, rcond=1e-3) @ cartesian
        size = float(np.abs(dq).max())
        if size == 0.0:
            return state.q_rad.copy()
        return state.q_rad + dq * (reach_rad / size)

    def _generator(self, pattern: str) -> Callable[[RobotState, int], tuple[Any, RobotState,
                                                                          float | None]]:
        rng, n = self.rng, self.n
        last = self.filter.last_command_rad
        now = self.backend.state().time_s
        if pattern == "policy":
            velocity = np.zeros(n)

            def policy(state: RobotState, k: int) -> tuple[Any, RobotState, float | None]:
                velocity[:] = np.clip(velocity + rng.normal(0.0, 0.3, n) * self.speed_cap * 0.2,
                                      -0.8 * self.speed_cap, 0.8 * self.speed_cap)
                return (self.filter.last_command_rad + velocity * self.backend.control_dt_s,
                        state, None)
            return policy
        if pattern == "uniform":
            return lambda state, k: (rng.uniform(self.robot_low, self.robot_high), state, None)
        if pattern == "jump":
            return lambda state, k: (self.filter.last_command_rad + rng.choice([-1.0, 1.0], n)
                                     * rng.uniform(2.0, 50.0, n) * self.step_cap, state, None)
        if pattern == "non_finite":
            command = last.copy()
            bad = rng.random(n) < 0.5
            bad[rng.integers(n)] = True
            command[bad] = rng.choice([np.nan, np.inf, -np.inf], int(bad.sum()))
            return lambda state, k: (command, state, None)
        if pattern == "stale_state":
            age = self.settings["max_state_age_s"] * rng.uniform(1.01, 20.0)
            return lambda state, k: (last, dataclasses.replace(state, time_s=now - age), None)
        if pattern == "stale_command":
            age = self.settings["max_command_age_s"] * rng.uniform(1.01, 20.0)
            return lambda state, k: (last, state, state.time_s - age)
        if pattern == "rom_drive":
            joint = int(rng.integers(len(self.patient_dofs)))
            side = float(rng.choice([-1.0, 1.0]))

            def rom_drive(state: RobotState, k: int) -> tuple[Any, RobotState, float | None]:
                _, patient = self._cuff_jacobians()
                return (self._toward(state, patient[:, joint] * side, rng.uniform(0.05, 0.3)),
                        state, None)
            return rom_drive
        if pattern == "force_push":
            side = float(rng.choice([-1.0, 1.0]))

            def force_push(state: RobotState, k: int) -> tuple[Any, RobotState, float | None]:
                _, patient = self._cuff_jacobians()
                u, _s, _vt = np.linalg.svd(patient)
                return (self._toward(state, u[:, -1] * side, rng.uniform(0.05, 0.3)),
                        state, None)
            return force_push
        if pattern == "oscillate":
            hz = rng.uniform(0.5, 2.0)
            omega = 2.0 * math.pi * hz
            accel = np.asarray(self.config.max_accel_rad_s2) * rng.uniform(0.9, 1.3, n)
            amplitude = accel / omega**2 * rng.choice([-1.0, 0.0, 1.0], n)
            center, dt = last.copy(), self.backend.control_dt_s
            return lambda state, k: (center + amplitude * math.sin(omega * dt * (k + 1)),
                                     state, None)
        raise ValueError(f"pattern {pattern!r} has no generator")

    def _missing(self, pattern: str) -> None:
        """No command for a while: the servo holds its setpoint; the watchdog is asked."""
        dt = self.backend.control_dt_s
        gap = math.ceil(self.rng.uniform(0.5, 3.0) * self.config.watchdog_timeout_s / dt)
        hold = self.filter.last_command_rad
        for _ in range(gap):
            now = self.backend.state().time_s
            start, cpu = time.perf_counter_ns(), time.thread_time_ns()
            decision = self.filter.watchdog(now)
            self._timed(start, cpu)
            if decision is not None:
                self.result.actions["stop"] += 1
                self._stopped(pattern)
                return
            if not self._command(hold, pattern):
                return

    def _timed(self, start_ns: int, start_cpu_ns: int) -> None:
        """Record one call's wall-clock and CPU time (the CPU time leaves out the time the
        process waited for a CPU)."""
        cpu = time.thread_time_ns() - start_cpu_ns
        self.result.call_ns.append(time.perf_counter_ns() - start_ns)
        self.result.call_cpu_ns.append(cpu)

    def _commanded_step(self, before: np.ndarray, measured: np.ndarray,
                        decision: Any) -> float:
        """The largest joint step the decision commands [rad]: from the last command, or,
        for hold and back off, from the measured position where the command stepped back
        onto it (that part of the step asks for no motion)."""
        base = before
        if decision.action in ("hold", "back_off") and self.config.release_to_measured:
            low, high = self.config.joint_low_rad, self.config.joint_high_rad
            measured = np.clip(measured, low, high)
            base = np.where((measured - before) * (decision.q_rad - measured) >= 0.0,
                            measured, before)
        return float(np.abs(decision.q_rad - base).max())

    def run(self, commands: int) -> FuzzResult:
        names = self.patterns
        weights = np.array([PATTERNS[p][0] for p in names])
        result = self.result
        while result.commands < commands:
            pattern = names[int(self.rng.choice(len(names), p=weights / weights.sum()))]
            if pattern == "missing":
                self._missing(pattern)
                continue
            _w, shortest, longest = PATTERNS[pattern]
            length = int(self.rng.integers(shortest, longest + 1))
            make = self._generator(pattern)
            for k in range(min(length, commands - result.commands)):
                state = self.backend.state()
                command, given, command_time = make(state, k)
                before = self.filter.last_command_rad
                start, cpu = time.perf_counter_ns(), time.thread_time_ns()
                decision = self.filter.filter(given, command, state.time_s, command_time)
                self._timed(start, cpu)
                result.commands += 1
                result.patterns[pattern] += 1
                result.actions[decision.action] += 1
                if decision.action == "stop":
                    self._stopped(pattern)
                    break
                ratio = self._commanded_step(before, given.q_rad, decision) / self.step_cap
                result.max_command_speed_ratio = max(result.max_command_speed_ratio, ratio)
                if ratio > 1.0 + COMMAND_ROUNDOFF:
                    self._count([("command", ratio)], pattern)
                if not self._command(decision.q_rad, pattern):
                    break
        self.backend.close()
        return result


def run_fuzz(case: str, condition: str, commands: int, seed: int,
             settings: dict[str, Any] | None = None,
             config_overrides: dict[str, Any] | None = None,
             patterns: Sequence[str] | None = None) -> FuzzResult:
    """Fuzz one case under one condition: ``settings`` replace entries of
    :data:`FILTER_SETTINGS` (the filter's and the breach checks' caps); ``config_overrides``
    change the filter alone (``{"cuff_force_limit_n": None}`` switches its force rule off);
    ``patterns``: only these (default: all)."""
    return Fuzzer(case, condition, seed, settings, config_overrides, patterns).run(commands)


def percentile_us(values_ns: Sequence[int], q: float) -> float:
    return float(np.percentile(np.asarray(values_ns, dtype=float), q)) / 1000.0


def results_tables(results: Sequence[FuzzResult],
                   ablations: Sequence[tuple[str, FuzzResult]]) -> list[dict[str, Any]]:
    rows, breach_rows, ablation_rows = [], [], []
    for r in results:
        a = r.actions
        rows.append([r.case, r.condition, r.commands, r.decisions, a["pass"], a["clip"],
                     a["hold"], a["back_off"], a["stop"], f"{r.max_force_ratio:.3f}",
                     f"{r.max_speed_ratio:.2f}", f"{r.min_rom_clearance_deg:.1f}"])
        breach_rows.append([r.case, r.condition, *(r.breaches[b] for b in BREACHES),
                            f"{r.max_command_speed_ratio:.6f}"])
    for name, r in ablations:
        ablation_rows.append([name, r.case, r.condition, r.commands,
                              *(r.breaches[b] for b in BREACHES), r.force_at_furniture,
                              f"{r.max_force_ratio:.3f}", f"{r.max_speed_ratio:.2f}",
                              f"{r.min_rom_clearance_deg:.1f}"])
    interventions = make_table(
        "interventions", "Commands and the filter's decisions",
        ["case", "condition", "commands", "decisions", "pass", "clip", "hold", "back off",
         "stop", "max force / limit", "max speed / cap", "closest to range [deg]"],
        rows, align=["left", "left", *["right"] * 10],
        note="`decisions`: physics decisions measured (the commands the filter let through, "
             "the servo's holds while commands were missing, and the decisions held after each "
             "stop). `max speed / cap`: the largest measured robot joint speed over the speed "
             "cap. `closest to range`: the smallest distance of an exercised patient joint to "
             "its anatomical bound over the run (negative: beyond it).")
    breaches = make_table(
        "breaches", "Breaches measured on the simulated state after every decision",
        ["case", "condition", *BREACHES, "max commanded step / cap"], breach_rows,
        align=["left", "left", *["right"] * 6],
        note=f"`range`: a patient joint beyond its anatomical range + the env's tolerance (2°); "
             f"`force`: the cuff force above its ISO/TS 15066 limit; `speed`: a measured robot "
             f"joint speed above the cap + {SPEED_ALLOWANCE_RAD_S} rad/s; `command`: a "
             f"commanded step above the cap's step (round-off allowance {COMMAND_ROUNDOFF:g} "
             "relative); `other`: the env reported instability or unintended contact.")
    ablation = make_table(
        "ablations", "The same fuzz with a rule removed or loosened",
        ["change", "case", "condition", "commands", *BREACHES, "force at furniture",
         "max force / limit", "max speed / cap", "closest to range [deg]"], ablation_rows,
        align=["left", "left", "left", *["right"] * 10],
        note="The breach checks keep the caps of the main runs except in the last row, "
             "where the therapist's caps (the filter's and the checks') are doubled. "
             "`force at furniture`: force breaches while the patient's body touched the chair "
             "or the leg rest.")
    calls = [ns for r in results for ns in r.call_ns]
    cpu = [ns for r in results for ns in r.call_cpu_ns]
    cost = make_table(
        "cost", "The filter's cost per call",
        ["clock", "calls", "median [µs]", "p99 [µs]", "max [µs]"],
        [[name, len(values), f"{percentile_us(values, 50):.1f}",
          f"{percentile_us(values, 99):.1f}", f"{max(values) / 1000.0:.1f}"]
         for name, values in (("wall", calls), ("CPU", cpu))],
        align=["left", *["right"] * 4],
        note="Every `filter` and `watchdog` call of the main runs, in one Python process with "
             "the simulator stepping between calls: `wall`, `time.perf_counter_ns` around the "
             "call (it includes any time the process waited for a CPU: on a machine shared "
             "with other processes, that time makes the tail); `CPU`, the thread's CPU time "
             "(`time.thread_time_ns`), what the call itself costs. A 500 Hz servo cycle is "
             "2000 µs.")
    return [interventions, breaches, ablation, cost]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--commands", type=int, default=2000,
                        help="commands per case and condition (2000)")
    parser.add_argument("--cases", nargs="+", choices=list(CASES),
                        default=list(CASES), help=f"cases (all: {' '.join(CASES)})")
    parser.add_argument("--conditions", nargs="+", choices=list(CONDITIONS),
                        default=list(CONDITIONS), metavar="CONDITION",
                        help=f"patient conditions (all: {', '.join(CONDITIONS)})")
    add_seed_argument(parser, help_text="seed of the first run (0)")
    add_page_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.commands < 1:
        parser.error(f"--commands={args.commands} must be >= 1")
    results = []
    for case in args.cases:
        for condition in args.conditions:
            seed = seed_of(case, condition, args.seed)
            started = time.perf_counter()
            result = run_fuzz(case, condition, args.commands, seed)
            print(f"{case:10s} {condition:14s} {result.commands} commands "
                  f"{time.perf_counter() - started:.1f} s breaches {result.breaches} "
                  f"actions {result.actions}", flush=True)
            results.append(result)
    ablations = []
    for name, (case, condition, settings, overrides) in ABLATIONS.items():
        if case in args.cases and condition in args.conditions:
            result = run_fuzz(case, condition, args.commands, seed_of(case, condition, args.seed),
                              settings, overrides)
            print(f"ablation {name}: breaches {result.breaches}", flush=True)
            ablations.append((name, result))
    command = script_command(__file__, argv)
    machine = f"{describe_machine()}, numpy {np.__version__}"
    tables = results_tables(results, ablations)
    announce(command, machine)
    for table in tables:
        print(table_markdown(table), "\n")
    if args.page is not None:
        s = FILTER_SETTINGS
        intro = INTRO.format(
            doc="[the deployment safety filter](../deployment/safety-filter.md)",
            speed=s["max_speed_rad_s"], accel=s["max_accel_rad_s2"],
            margin=math.degrees(s["rom_margin_rad"]), hold=s["hold_fraction"],
            overspeed=FilterConfig.overspeed_factor, patient=s["max_patient_speed_rad_s"],
            back=s["back_off_fraction"], age=s["max_state_age_s"],
            watchdog=s["watchdog_timeout_s"])
        timing = ("call_ns", "call_cpu_ns")
        data = [{k: v for k, v in asdict(r).items() if k not in timing} for r in results]
        ablation_data = [{"change": name, **{k: v for k, v in asdict(r).items()
                                              if k not in timing}} for name, r in ablations]
        calls = [ns for r in results for ns in r.call_ns]
        cpu = [ns for r in results for ns in r.call_cpu_ns]
        write_page(make_document(
            title="The safety filter under fuzzing: breaches and cost", intro=intro,
            command=command, generated_by=__file__, tables=tables, machine=machine,
            seeds={"base_seed": args.seed, "per_run": "base + 100 x the case's index in CASES + "
                   "the condition's index in CONDITIONS (benchmarks/deploy/safety_fuzz.py)"},
            settings={"commands": args.commands, "filter": FILTER_SETTINGS,
                      "speed_allowance_rad_s": SPEED_ALLOWANCE_RAD_S,
                      "stopped_decisions": STOPPED_DECISIONS,
                      "patterns": {k: list(v) for k, v in PATTERNS.items()},
                      "conditions": {c: CONDITIONS[c] for c in args.conditions},
                      "cases": {c: [CASES[c][0], CASES[c][1]] for c in args.cases},
                      "ablations": {k: [v[0], v[1], v[2], v[3]] for k, v in ABLATIONS.items()}},
            data={"results": data, "ablations": ablation_data,
                  "cost_us": {"calls": len(calls), "median": percentile_us(calls, 50),
                              "p99": percentile_us(calls, 99),
                              "cpu_median": percentile_us(cpu, 50),
                              "cpu_p99": percentile_us(cpu, 99)}}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
