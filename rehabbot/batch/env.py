"""The batched ``-v2`` env: one CPU env's step as pure JAX functions on MJX with
``impl="warp"`` (MuJoCo Warp), in MuJoCo Playground's interface: ``reset(rng) -> State`` and
``step(state, action) -> State``, both ``jax.jit``- and ``jax.vmap``-able.

Every number comes from the CPU env (:mod:`rehabbot.batch.env_tables`,
:mod:`rehabbot.batch.patient_tables`); one step does what
:meth:`rehabbot.envs.core.RehabEnvCore.step` does:

1. the unit action is clipped to [-1, 1], mapped onto the controller's box and added to the
   servo setpoints (``joint_delta``), made the setpoints (``joint_position``) or their speeds
   (``joint_velocity``), which are clipped to the setpoint bounds; or motor torques
   (``torque``);
2. ``frame_skip`` MuJoCo Warp steps (``jax.lax.scan``), each after the patient's torques of
   its condition (:mod:`rehabbot.batch.patient_drive`; none for a healthy patient);
3. the safety rules in the CPU order: instability (judged from the values, since MuJoCo
   Warp neither warns nor resets on a bad acceleration: a non-finite state, a joint faster
   than the blow-up speed, a non-finite or blow-up cuff force, or a paper observation
   outside the healthy box), range of motion, cuff force, unintended contact;
4. the progress reward with the ``"hold"`` safety penalty (its hold gap in the state) and its
   optional smoothness and effort terms, and the target switch: the laws of
   :mod:`rehabbot.laws.reward` and :mod:`rehabbot.laws.targets`, as on the CPU;
5. the agent observation: ``tanh`` or a clip of the CPU env's affine map.

The cuffs' forces, the work meters and the contact rule are read by
:mod:`rehabbot.batch.cuffs`; the model MuJoCo Warp steps is :mod:`rehabbot.batch.model`'s.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import mjx

from rehabbot.batch.cuffs import METER_KEYS, CuffReadings
from rehabbot.batch.env_tables import POPULATION_IDS, RULE_CODES, EnvTables, check_id, read_tables
from rehabbot.batch.model import physics_model
from rehabbot.batch.patient_drive import BatchedPatientDrive
from rehabbot.batch.patient_stack import PatientStack, stack_patients
from rehabbot.batch.patient_tables import read_patient_tables
from rehabbot.batch.state import State
from rehabbot.laws import reward as laws
from rehabbot.laws.control import SETPOINT_LAWS, clip_to_box, motor_torque_nm, native_action
from rehabbot.laws.safety import (
    beyond_range,
    blown_up,
    fastest_speed_rad_s,
    first_rule,
    outside_box,
    over_force_limit,
)
from rehabbot.laws.targets import largest_error_rad, switch_target
from rehabbot.laws.work import assistance_ratio
from rehabbot.sim.scene import WEIGHT_LEVELS

# A non-finite cuff force reads as this in the agent observation (as the CPU env does).
NONFINITE_FORCE_N = 1e9
INSTABILITY = RULE_CODES["instability"]
REWARD_TERMS = ("reward_progress", "reward_bonus", "reward_time", "reward_safety",
                "reward_smoothness", "reward_effort")


def _f32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.float32))


def _i32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.int32))


class BatchedRehabEnv:
    """A ``-v2`` id as a functional env (module docstring); make it with
    :func:`rehabbot.batch.make`.

    A population id (:data:`~rehabbot.batch.env_tables.POPULATION_IDS`) holds every patient of
    its population (:mod:`rehabbot.batch.patient_stack`): each world draws its patient at every
    reset, and ``info["patient"]`` and ``metrics["patient"]`` name it (an index into
    ``cpu_env.population.patients``, as the CPU env's ``info["patient"]``).

    Attributes:
        tables: the first patient's tables (the fields every patient shares, and that
            patient's own); ``patients.arrays`` holds every patient's.
        patient_envs: the CPU env of every patient (one for a single-patient id).

    Args:
        env_id: the registered id.
        naconmax: contact slots of all worlds together (MuJoCo Warp shares them between the
            worlds); at least the contacts of every world at once.
        njmax: constraint rows per world.
        **kwargs: the CPU env's keyword arguments (``gym.make(env_id, **kwargs)``).
    """

    def __init__(self, env_id: str, *, naconmax: int = 8192, njmax: int = 64,
                 **kwargs: Any) -> None:
        for name, value in (("naconmax", naconmax), ("njmax", njmax)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} must be a positive integer")
        check_id(env_id)
        cpu = gym.make(env_id, **kwargs).unwrapped
        if env_id in POPULATION_IDS:
            if cpu.population.skip_infeasible and cpu.feasible_patients != tuple(
                    range(len(cpu.population.patients))):
                raise ValueError(
                    f"population {cpu.population.name!r} leaves out patients its scene "
                    f"refuses ({sorted(cpu.refused_patients)}); the batched env draws from "
                    "every patient of a population: pass one whose patients all do the "
                    "exercises, or train on the CPU env")
            envs = [cpu.patient_env(k) for k in range(len(cpu.population.patients))]
        else:
            envs = [cpu]
        tables = [read_tables(env_id, env) for env in envs]
        self.patients: PatientStack = stack_patients(
            tables, envs, lambda env: physics_model(env.model, tables[0]))
        self.tables: EnvTables = self.patients.shared
        self.is_population = env_id in POPULATION_IDS
        drives = [read_patient_tables(env) for env in envs]
        # The conditions' torques on the patient's joints (None: no patient applies any).
        self.patient = BatchedPatientDrive(drives) \
            if any(d is not None for d in drives) else None
        self.cpu_env = cpu
        self.patient_envs = envs
        self.mj_model: mujoco.MjModel = physics_model(envs[0].model, self.tables)
        self.mjx_model = self.patients.models.base
        self.naconmax, self.njmax = naconmax, njmax
        self.action_size = int(cpu.action_space.shape[0])
        self.observation_size = int(cpu.observation_space.shape[0])
        self.dt_s = float(cpu.dt_s)
        # The two-arm reward's sync term (BilateralReward), when its weight is set.
        self.has_sync = self.tables.arms > 1 and self.tables.sync_weight > 0
        self._build_arrays(self.tables)

    def _build_arrays(self, t: EnvTables) -> None:
        self._servo, self._dof, self._qpos = _i32(t.servo_ids), _i32(t.dof_adr), _i32(t.qpos_adr)
        self._motor, self._torque_limit = _i32(t.motor_ids), _f32(t.torque_limit_nm)
        self._center, self._half = _f32(t.action_center), _f32(t.action_half)
        self._rot_t = _f32(t.base_rot_t)  # (arms, 3, 3)
        self._tool_sites = _i32(t.tool_sites)
        self._cuff_limits = _f32(t.cuff_force_limits_n)
        self._phi = _i32(t.phi_adr)
        self.cuffs = CuffReadings(t)
        self._patient_qpos = _i32(t.patient_qpos_adr)
        self._bounded_low, self._bounded_high = _f32(t.bounded_low), _f32(t.bounded_high)
        self._action_range = _f32(t.reward_action_range)
        self._reward_torque_limit = _f32(t.reward_torque_limit_nm)
        # Per patient (leading axis): the tables a profile or a condition changes.
        a = self.patients.arrays
        home_ctrl = np.zeros((*a["home_setpoints_rad"].shape[:2], self.mj_model.nu))
        home_ctrl[:, :, t.servo_ids] = a["home_setpoints_rad"]
        self._per_patient = {
            "low": _f32(a["setpoint_low_rad"]), "high": _f32(a["setpoint_high_rad"]),
            "home_qpos": _f32(a["home_qpos"]), "home_ctrl": _f32(home_ctrl),  # [p, level]
            "base": _f32(a["base_pos_m"]),
            "box_low": jp.asarray(a["healthy_low"]), "box_high": jp.asarray(a["healthy_high"]),
            "targets": _f32(a["targets_rad"]), "tools": _f32(a["tool_targets_m"]),
            "count": _i32(a["num_targets"]), "rests": _f32(a["rests_rad"]),
            "rom_low": _f32(a["rom_low_rad"]), "rom_high": _f32(a["rom_high_rad"]),
            "matrix": _f32(a["agent_matrix"]), "segments": _f32(a["segments_rad"]),
        }
        # [patient, level]: the MJX model leaves a patient or a weight level changes.
        models = self.patients.models
        self._model_leaves = jax.tree_util.tree_leaves(models.base)
        self._model_rows = {i: jp.asarray(rows, dtype=self._model_leaves[i].dtype)
                            for i, rows in models.rows.items()}
        # [patient, level]: what a fresh MjData holds from the model and no step recomputes.
        self._data_rows = {name: jp.asarray(rows, dtype=np.float32 if rows.dtype.kind == "f"
                                            else rows.dtype)
                           for name, rows in models.data_rows.items()}

    def _of(self, patient: jax.Array) -> dict[str, jax.Array]:
        """The per-patient tables of the world's ``patient``."""
        return {name: rows[patient] for name, rows in self._per_patient.items()}

    # -- pieces ------------------------------------------------------------------------------
    def _model(self, patient: jax.Array, level: jax.Array) -> Any:
        """The MJX model of ``patient`` at weight ``level``; under ``jax.vmap`` the fields they
        change are per world (MuJoCo Warp's batched model fields)."""
        leaves = list(self._model_leaves)
        for i, rows in self._model_rows.items():
            leaves[i] = rows[patient, level]
        return self.patients.models.treedef.unflatten(leaves)

    def _dynamic(self, w: dict, data: Any) -> tuple[jax.Array, jax.Array]:
        """theta (the robot's joint angles) and the paper observation's theta, p, phi."""
        theta = data.qpos[self._qpos]
        tools = data.site_xpos[self._tool_sites] - w["base"]  # (arms, 3)
        p = jp.einsum("aij,aj->ai", self._rot_t, tools).reshape(-1)
        return theta, jp.concatenate([theta, p, data.qpos[self._phi]])

    def _work_metrics(self, meter: dict) -> dict[str, jax.Array]:
        """The work entries of the CPU env's ``info``: a patient without a drive does no work
        (so the robot's share of the positive work, the assistance ratio, is 1); with one,
        also the last physics step's ``patient_torque_nm``."""
        if self.patient is None:
            return {"robot_work_j": meter["robot_work_j"],
                    "patient_work_j": jp.zeros((), jp.float32),
                    "assistance_ratio": jp.ones((), jp.float32),
                    "patient_torque_nm": jp.zeros(self.tables.phi_adr.shape[0], jp.float32)}
        robot, patient = meter["robot_positive_work_j"], meter["patient_positive_work_j"]
        ratio = assistance_ratio(jp, robot, patient)
        return {"robot_work_j": meter["robot_work_j"], "patient_work_j": meter["patient_work_j"],
                "assistance_ratio": ratio,
                "patient_torque_nm": self.patient.exercised_torque(meter)}

    def _optional_terms(self, native: jax.Array, previous: jax.Array,
                        data: Any) -> tuple[jax.Array, jax.Array]:
        """The reward's ``smoothness`` and ``effort`` terms (0 where the weight is 0)."""
        t = self.tables
        zero = jp.zeros((), jp.float32)
        smoothness = laws.smoothness_term(native, previous, self._action_range,
                                          t.smoothness_weight) if t.smoothness_weight else zero
        effort = laws.effort_term(data.qfrc_actuator[self._dof], self._reward_torque_limit,
                                  t.effort_weight) if t.effort_weight else zero
        return smoothness, effort

    def _per_arm(self, values: jax.Array) -> jax.Array:
        """``values`` over every arm's joints, one row per arm ``(arms, joints)``."""
        return values.reshape(self.tables.arms, -1)

    def _arm_distances(self, theta: jax.Array, target: jax.Array) -> jax.Array:
        """Each arm's ``||theta_k - target_k||`` (arms,)."""
        return jp.linalg.norm(self._per_arm(theta - target), axis=1)

    def _leads(self, setpoint: jax.Array, theta: jax.Array, qvel: jax.Array) -> jax.Array:
        """How far [rad] each arm's joints may still travel if the agent holds still
        (``Controller.hold_travel_rad``): to the setpoints, or in ``torque`` mode the sag and
        braking allowance. ``(arms,)``."""
        t = self.tables
        if t.control_mode == "torque":
            return t.hold_sag_rad + t.hold_brake_s * jp.linalg.norm(self._per_arm(qvel),
                                                                    axis=1)
        return self._arm_distances(setpoint, theta)

    def _in_segment(self, w: dict, exercise: jax.Array, target: jax.Array,
                    distances: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Each arm's share of target ``target``'s segment done (arms,) and the arms' sync
        gap."""
        t = self.tables
        lengths = w["segments"][exercise, target]
        fractions = laws.segment_fraction(distances, lengths)
        moving = laws.moves_in_segment(lengths, t.target_tolerance_rad)
        return fractions, laws.sync_gap(fractions[0], fractions[1], moving[0], moving[1],
                                        t.sync_tolerance)

    def _hold_cost(self, w: dict, exercise: jax.Array, target: jax.Array, steps: Any,
                   leads: jax.Array, sync_gap: jax.Array | None) -> jax.Array:
        """``B(s)``: the most that holding still for ``steps`` steps from a state whose active
        target is ``target`` costs (with the sync term when the arms' ``sync_gap`` is given)."""
        t = self.tables
        hold = laws.progress_hold_cost(steps, leads, t.time_cost, t.smoothness_weight,
                                       t.effort_weight, t.progress_weight)
        if sync_gap is None:
            return hold
        lengths = w["segments"][exercise, target]
        reach = laws.sync_hold_gap(sync_gap, leads[0], leads[1], lengths[0], lengths[1],
                                   t.target_tolerance_rad)
        return laws.bilateral_hold_cost(hold, steps, reach, t.sync_weight)

    def _paper(self, w: dict, exercise: jax.Array, index: jax.Array, dynamic: jax.Array,
               level: jax.Array) -> jax.Array:
        """The paper observation (float32), in the CPU layout's order."""
        t = self.tables
        fields = {"theta_star": w["targets"][exercise, index],
                  "p_star": w["tools"][exercise, index],
                  "e": exercise.astype(jp.float32)[None],
                  "l": level.astype(jp.float32)[None]}
        paper = jp.zeros(w["box_low"].shape[0], jp.float32)
        for name, values in fields.items():
            start, stop = t.paper_slices[name]
            paper = paper.at[start:stop].set(values)
        start = t.paper_slices["theta"][0]  # theta, p and phi side by side
        return paper.at[start:start + dynamic.shape[0]].set(dynamic)

    def _agent_obs(self, w: dict, paper: jax.Array, exercise: jax.Array, index: jax.Array,
                   setpoint: jax.Array, qvel: jax.Array, forces: jax.Array) -> jax.Array:
        t = self.tables
        count = w["count"][exercise]
        has_next = index + 1 < count
        targets = w["targets"]
        following = targets[exercise, jp.minimum(index + 1, targets.shape[1] - 1)]
        theta_star = paper[t.paper_slices["theta_star"][0]:t.paper_slices["theta_star"][1]]
        x = jp.concatenate([paper, jp.where(has_next, following, theta_star), setpoint,
                            jp.where(jp.isfinite(qvel), qvel, 0.0),
                            jp.where(jp.isfinite(forces), forces, NONFINITE_FORCE_N),
                            jp.ones(1, jp.float32)])
        v = w["matrix"] @ x
        bounded = slice(t.bounded_start, t.bounded_start + self._bounded_low.shape[0])
        v = v.at[:t.tanh_stop].set(jp.tanh(v[:t.tanh_stop]))
        v = v.at[bounded].set(jp.clip(v[bounded], self._bounded_low, self._bounded_high))
        v = v.at[t.exercise_start + exercise].set(1.0)
        progress = jp.where(count > 1, 2.0 * index / jp.maximum(count - 1, 1) - 1.0, 1.0)
        return v.at[t.progress_index].set(progress).astype(jp.float32)

    def _patient_begin(self, info: dict, exercise: jax.Array,
                       index: jax.Array) -> tuple[dict, jax.Array | None, jax.Array]:
        """The patient drive's state, goal and the world's next key at the start of a
        control step (no drive: nothing, and the key unchanged)."""
        if self.patient is None:
            return {}, None, info["rng"]
        rng, key = jax.random.split(info["rng"])
        state = {k: v for k, v in info.items() if k.startswith(("patient_", "tremor_"))}
        state, goal = self.patient.begin_step(state, info["patient"], exercise, index, key)
        return state, goal, rng

    # -- API ---------------------------------------------------------------------------------
    def _draw(self, rng: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """The episode's patient (drawn uniformly from a population, as the CPU population
        env draws it; 0 otherwise), exercise and weight level (the config's, or drawn
        uniformly, as the CPU env draws them), and the key for the next draw."""
        patient = jp.int32(0)
        if self.patients.count > 1:
            rng, patient_key = jax.random.split(rng)
            patient = jax.random.randint(patient_key, (), 0, self.patients.count, jp.int32)
        rng, exercise_key, level_key = jax.random.split(rng, 3)
        t = self.tables
        exercise = jp.int32(t.exercise) if t.exercise is not None else jax.random.randint(
            exercise_key, (), 0, self.patients.arrays["targets_rad"].shape[1], jp.int32)
        level = jp.int32(t.weight_level) if t.weight_level is not None else \
            jax.random.randint(level_key, (), 0, len(WEIGHT_LEVELS), jp.int32)
        return patient, exercise, level, rng

    def _start(self, data: Any, patient: jax.Array, exercise: jax.Array, level: jax.Array,
               rng: jax.Array) -> State:
        """The state of ``patient``'s episode of ``exercise`` at weight ``level`` starting at
        ``data`` (the home state, after ``mjx.forward``)."""
        t, w = self.tables, self._of(patient)
        theta, dynamic = self._dynamic(w, data)
        setpoint = w["home_ctrl"][level][self._servo]
        index = jp.int32(0)
        paper = self._paper(w, exercise, index, dynamic, level)
        forces = self.cuffs.forces(data)
        force = jp.max(forces)
        obs = self._agent_obs(w, paper, exercise, index, setpoint, data.qvel[self._dof], forces)
        zero = jp.zeros((), jp.float32)
        distances = self._arm_distances(theta, w["targets"][exercise, 0])
        leads = self._leads(setpoint, theta, data.qvel[self._dof])
        sync, gap = {}, None
        if self.has_sync:
            fractions, gap = self._in_segment(w, exercise, index, distances)
            sync = {"sync_gap": gap}
        hold_gap = self._hold_cost(w, exercise, index, t.max_episode_steps, leads, gap)
        info = {
            "setpoint": setpoint, "target_index": index, "exercise": exercise,
            "weight_level": level, "patient": jp.asarray(patient, jp.int32),
            "steps": jp.int32(0), "theta": theta, "healthy": dynamic,
            "path_left": laws.path_left_rad(distances, w["rests"][exercise, 0]),
            "hold_gap": hold_gap, **sync,
            "previous_action": jp.zeros(self._action_range.shape[0], jp.float32),
            "rng": rng, "truncation": zero, **self.cuffs.meter_start(data),
        }
        if self.patient is not None:
            info["rng"], key = jax.random.split(rng)
            info.update(self.patient.start(key))
        metrics = {"interaction_force_n": force, "cost": zero,
                   "safety_violation": jp.int32(0), "is_success": zero,
                   "target_index": index, "action_clipped": jp.int32(0),
                   **self._readings(data, patient, exercise, level),
                   **self._work_metrics(info), **dict.fromkeys(REWARD_TERMS, zero)}
        if t.arms > 1:
            metrics["cuff_forces_n"] = forces
        if self.has_sync:
            metrics.update(reward_sync=zero, segment_fraction=fractions, sync_gap=zero)
        return State(data, obs, zero, zero, metrics, info)

    def _readings(self, data: Any, patient: jax.Array, exercise: jax.Array, level: jax.Array
                  ) -> dict[str, jax.Array]:
        """The CPU env's ``info`` readings of the robot and the patient: the robot's actuator
        torques on its joints, the patient's joint angles, the exercise and weight level (and
        a population's patient)."""
        readings = {"robot_torque_nm": data.qfrc_actuator[self._dof],
                    "patient_qpos": data.qpos[self._patient_qpos],
                    "exercise": jp.asarray(exercise, jp.int32),
                    "weight_level": jp.asarray(level, jp.int32)}
        if self.is_population:
            readings["patient"] = jp.asarray(patient, jp.int32)
        return readings

    def reset(self, rng: jax.Array, exercise: jax.Array | int = -1,
              weight_level: jax.Array | int = -1, patient: jax.Array | int = -1) -> State:
        """A new episode at home: the patient (of a population), the exercise and the weight
        level are the config's, or drawn from ``rng``; an ``exercise``, ``weight_level`` or
        ``patient`` >= 0 overrides them for this episode (the CPU env's reset ``options``;
        checked by :meth:`check_reset_options`, since a jitted function cannot raise). All
        are drawn every reset, as on the CPU, so that the draws do not depend on the
        options."""
        drawn_patient, drawn_exercise, drawn_level, rng = self._draw(rng)

        def chosen(value: jax.Array | int, drawn: jax.Array) -> jax.Array:
            return jp.where(jp.asarray(value) >= 0, jp.asarray(value, jp.int32), drawn)

        patient = chosen(patient, drawn_patient)
        exercise, level = chosen(exercise, drawn_exercise), chosen(weight_level, drawn_level)
        w = self._of(patient)
        data = mjx.make_data(self.mj_model, impl="warp", naconmax=self.naconmax,
                             njmax=self.njmax)
        data = data.replace(qpos=w["home_qpos"], ctrl=w["home_ctrl"][level],
                            **{name: rows[patient, level]
                               for name, rows in self._data_rows.items()})
        return self._start(mjx.forward(self._model(patient, level), data), patient, exercise,
                           level, rng)

    def check_reset_options(self, options: dict | None) -> tuple[int, int, int]:
        """``(exercise, weight_level, patient)`` of the CPU env's reset ``options`` (-1: not
        given; ``patient`` only for a population id), or ``ValueError`` naming a bad one, as
        the CPU env does."""
        from rehabbot.common.checks import check_options
        from rehabbot.envs.env_base import RESET_OPTIONS
        from rehabbot.envs.population import POPULATION_RESET_OPTIONS
        from rehabbot.sim.scene import check_weight_level
        from rehabbot.tasks import feasibility

        names = POPULATION_RESET_OPTIONS if self.is_population else RESET_OPTIONS
        options = check_options(options, names)
        exercise = options.get("exercise", -1)
        count = int(self.patients.arrays["targets_rad"].shape[1])
        if "exercise" in options and (isinstance(exercise, bool)
                                      or exercise not in range(count)):
            raise ValueError(f"exercise={exercise!r} is not one of {list(range(count))}")
        patient = options.get("patient", -1)
        if "patient" in options:
            self.cpu_env.patient_env(patient)  # ValueError naming a bad index
        level = options.get("weight_level", -1)
        if "weight_level" in options:
            level = check_weight_level(level)
            envs = self.patient_envs if patient < 0 else [self.patient_envs[patient]]
            for env in envs:
                unusable = env.unusable_weight_levels
                if level in unusable:
                    feasibility.refuse(unusable, WEIGHT_LEVELS, level)
        return int(exercise), int(level), int(patient)

    def restart_done(self, state: State) -> State:
        """Auto-reset: a world whose episode ended (``state.done``) starts a new one (a new
        exercise and weight level drawn from its key); the state keeps the ending step's
        ``reward``, ``done`` and ``metrics``, and ``info["truncation"]``. Only the inputs of
        the physics are put back home (qpos, qvel, ctrl, the warm start, applied forces,
        time), then every world is forwarded at its level: MuJoCo Warp's shared contact array
        is never mixed between worlds, and a forward leaves a running world's next step
        unchanged (it only recomputes derived quantities; the warm start is written by a
        step)."""
        done = state.done > 0
        data = state.data
        patient, exercise, level, rng = self._draw(state.info["rng"])
        level = jp.where(done, level, state.info["weight_level"])
        patient = jp.where(done, patient, state.info["patient"])
        w = self._of(patient)

        def home(value: jax.Array, start: jax.Array | float) -> jax.Array:
            return jp.where(done, jp.broadcast_to(start, value.shape).astype(value.dtype), value)

        data = data.replace(qpos=home(data.qpos, w["home_qpos"]), qvel=home(data.qvel, 0.0),
                            ctrl=home(data.ctrl, w["home_ctrl"][level]),
                            qacc_warmstart=home(data.qacc_warmstart, 0.0),
                            qfrc_applied=home(data.qfrc_applied, 0.0),
                            time=home(data.time, 0.0),
                            **{name: home(getattr(data, name), rows[patient, level])
                               for name, rows in self._data_rows.items()})
        data = mjx.forward(self._model(patient, level), data)
        fresh = self._start(data, patient, exercise, level, rng)
        info = jax.tree.map(lambda new, old: jp.where(done, new, old), fresh.info, state.info)
        info["truncation"] = state.info["truncation"]
        return State(data, jp.where(done, fresh.obs, state.obs), state.reward, state.done,
                     state.metrics, info)

    def step_auto_reset(self, state: State, action: jax.Array) -> State:
        """:meth:`step`, then :meth:`restart_done`."""
        return self.restart_done(self.step(state, action))

    def step(self, state: State, action: jax.Array) -> State:
        """One decision (module docstring). Non-finite action entries act as 0 and, like
        entries outside [-1, 1], count in ``metrics["action_clipped"]``."""
        t, info = self.tables, state.info
        patient = info["patient"]
        w = self._of(patient)
        action = jp.asarray(action, jp.float32)
        unit, clipped = clip_to_box(action, -1.0, 1.0)  # a NaN or an inf counts as clipped
        unit = jp.where(jp.isfinite(action), unit, 0.0)  # ... and acts as 0
        clipped = clipped.astype(jp.int32)
        native = native_action(unit, self._center, self._half)
        setpoint = SETPOINT_LAWS[t.control_mode](info["setpoint"], native, w["low"], w["high"],
                                                 t.controller_dt_s)
        if t.control_mode == "torque":  # motor torques; the servos are off
            ctrl = state.data.ctrl.at[self._motor].set(
                motor_torque_nm(native, self._torque_limit))
        else:  # the servos follow the setpoints
            ctrl = state.data.ctrl.at[self._servo].set(setpoint)
        data = state.data.replace(ctrl=ctrl)

        level = info["weight_level"]
        model = self._model(patient, level)
        exercise, index = info["exercise"], info["target_index"]
        drive, goal, rng = self._patient_begin(info, exercise, index)

        def physics_step(carry: tuple, _: None) -> tuple[tuple, None]:
            d, meter, drive = carry
            if self.patient is not None:
                drive, d, q = self.patient.apply(drive, d, info["patient"], goal)
            d = mjx.step(model, d)
            if self.patient is not None:
                drive = self.patient.count_work(drive, d, q)
            return (d, self.cuffs.meter_after_step(meter, d), drive), None

        meter = {k: info[k] for k in METER_KEYS}
        (data, meter, drive), _ = jax.lax.scan(physics_step, (data, meter, drive), None,
                                               length=t.frame_skip)

        # Safety rules, in the CPU env's order.
        forces = self.cuffs.forces(data)
        force = jp.max(forces)
        theta, dynamic = self._dynamic(w, data)
        before = self._paper(w, exercise, index, dynamic, level)
        # MuJoCo Warp neither warns nor resets: a non-finite state is judged from the values.
        unstable = (~jp.all(jp.isfinite(data.qpos))
                    | blown_up(fastest_speed_rad_s(data.qvel), force, jp)
                    | outside_box(before, w["box_low"], w["box_high"]))
        patient_q = data.qpos[self._patient_qpos]
        violation = first_rule(
            unstable,
            beyond_range(list(patient_q), list(w["rom_low"]), list(w["rom_high"])),
            over_force_limit(list(forces), list(self._cuff_limits)),
            self.cuffs.touch(data)).astype(jp.int32)
        theta = jp.where(unstable, info["theta"], theta)
        dynamic = jp.where(unstable, info["healthy"], dynamic)
        force = jp.where(jp.isfinite(force), force, 0.0)

        # Reward (progress, "hold" penalty) and the target switch: the laws, as on the CPU.
        steps = info["steps"] + 1
        targets, rests = w["targets"], w["rests"]
        distances = self._arm_distances(theta, targets[exercise, index])
        stop = (violation > 0) & (t.terminate_on_safety | (violation == INSTABILITY))
        switch = switch_target(largest_error_rad(theta, targets[exercise, index]), index,
                               w["count"][exercise], stop, t.target_tolerance_rad)
        new_index = switch.index
        switching = new_index != index
        following = jp.minimum(index + 1, targets.shape[1] - 1)
        next_distances = jp.where(
            switching, self._arm_distances(theta, targets[exercise, following]), distances)
        after = laws.path_left_rad(next_distances, rests[exercise, new_index])
        progress = laws.progress_term(info["path_left"], after, t.progress_weight)
        gap = info["hold_gap"]
        smoothness, effort = self._optional_terms(native, info["previous_action"], data)
        safety = laws.progress_safety(
            stop, info["path_left"], after, gap, 0, progress, t.time_cost, smoothness, effort,
            progress_weight=t.progress_weight, smoothness_weight=t.smoothness_weight,
            effort_weight=t.effort_weight, margin=t.stop_margin)
        bonus = laws.target_bonus(switch.reached, switch.last, t.intermediate_bonus,
                                  t.final_bonus)
        time = jp.full((), -t.time_cost, jp.float32)
        leads = self._leads(setpoint, theta, data.qvel[self._dof])
        steps_left = laws.steps_left(t.max_episode_steps, steps)
        sync_info, sync_metrics, state_gap, sync_terms = {}, {}, None, []
        if self.has_sync:  # BilateralReward: the arms' sync term, in the stop and the hold
            fractions, step_gap = self._in_segment(w, exercise, index, distances)
            state_gap = jp.where(switching, self._in_segment(w, exercise, following,
                                                             next_distances)[1], step_gap)
            safety = jp.where(stop, safety - laws.sync_stop_charge(
                step_gap, info["sync_gap"], t.sync_weight), safety)
            reward_sync = laws.sync_term(step_gap, stop, t.sync_weight)
            sync_terms = [reward_sync]
            sync_info = {"sync_gap": state_gap}
            sync_metrics = {"reward_sync": reward_sync, "segment_fraction": fractions,
                            "sync_gap": step_gap}
        reward = laws.total([progress, bonus, time, safety, smoothness, effort, *sync_terms])
        hold = self._hold_cost(w, exercise, new_index, steps_left, leads, state_gap)
        gap = jp.where(stop, gap, laws.next_hold_gap(gap, reward, hold))
        terminated = stop | switch.success
        truncated = (steps >= t.max_episode_steps) & ~terminated

        paper = self._paper(w, exercise, new_index, dynamic, level)
        obs = self._agent_obs(w, paper, exercise, new_index, setpoint, data.qvel[self._dof],
                              forces)
        f32 = jp.float32
        new_info = {**info, **meter, **drive, "rng": rng, "setpoint": setpoint,
                    "target_index": new_index, "steps": steps,
                    "theta": theta, "healthy": dynamic, "path_left": after, "hold_gap": gap,
                    "previous_action": native, **sync_info,
                    "truncation": truncated.astype(f32)}
        metrics = {"interaction_force_n": force, "cost": (violation > 0).astype(f32),
                   "safety_violation": violation,
                   "is_success": switch.success.astype(f32),
                   "target_index": new_index, "action_clipped": clipped,
                   **self._readings(data, patient, exercise, level),
                   **self._work_metrics({**meter, **drive}),
                   "reward_progress": progress, "reward_bonus": bonus,
                   "reward_time": time, "reward_safety": safety,
                   "reward_smoothness": smoothness, "reward_effort": effort, **sync_metrics}
        if t.arms > 1:
            metrics["cuff_forces_n"] = jp.where(jp.isfinite(forces), forces, 0.0)
        return State(data, obs, reward.astype(f32), (terminated | truncated).astype(f32),
                     {k: jp.asarray(v) for k, v in metrics.items()}, new_info)
