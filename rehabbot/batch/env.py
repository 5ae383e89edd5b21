"""The batched ``-v2`` env: one CPU env's step as pure JAX functions on MJX with
``impl="warp"`` (MuJoCo Warp), in MuJoCo Playground's interface: ``reset(rng) -> State`` and
``step(state, action) -> State``, both ``jax.jit``- and ``jax.vmap``-able.

Every number comes from the CPU env (:mod:`rehabbot.batch.tables`,
:mod:`rehabbot.batch.patient_tables`); one step does what
:meth:`rehabbot.envs.core.RehabEnvCore.step` does:

1. the unit action is clipped to [-1, 1], mapped onto the controller's box and added to the
   servo setpoints (``joint_delta``), made the setpoints (``joint_position``) or their speeds
   (``joint_velocity``), which are clipped to the setpoint bounds; or motor torques
   (``torque``);
2. ``frame_skip`` MuJoCo Warp steps (``jax.lax.scan``), each after the patient's torques of
   its condition (:mod:`rehabbot.batch.patient`; none for a healthy patient);
3. the safety rules in the CPU order: instability (judged from the values, since MuJoCo
   Warp neither warns nor resets on a bad acceleration: a non-finite state, a joint faster
   than the blow-up speed, a non-finite or blow-up cuff force, or a paper observation
   outside the healthy box), range of motion, cuff force, unintended contact;
4. the progress reward with the ``"hold"`` safety penalty (its hold gap in the state), and
   the target switch;
5. the agent observation: ``tanh`` or a clip of the CPU env's affine map.

MuJoCo Warp keeps one contact array for all worlds. The contact rule therefore reads the
contacts through the world's own constraint rows (``efc_type`` a contact, ``efc_id`` the
contact), which belong to this world only, whatever ``vmap`` does.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import mjx

from rehabbot.batch.patient import BatchedPatientDrive
from rehabbot.batch.patient_tables import read_patient_tables
from rehabbot.batch.state import State
from rehabbot.batch.tables import RULE_CODES, EnvTables, check_id, read_tables
from rehabbot.sim.scene import WEIGHT_LEVELS

CONTACT_CONSTRAINTS = (int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS),
                       int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
                       int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC))
# A non-finite cuff force reads as this in the agent observation (as the CPU env does).
NONFINITE_FORCE_N = 1e9
INSTABILITY = RULE_CODES["instability"]
METER_KEYS = ("meter_pos", "meter_force", "meter_has_force", "robot_work_j",
              "robot_positive_work_j")
REWARD_TERMS = ("reward_progress", "reward_bonus", "reward_time", "reward_safety")


def physics_model(model: mujoco.MjModel, tables: EnvTables) -> mujoco.MjModel:
    """The model MuJoCo Warp steps: the CPU env's, except in ``torque`` mode, where the servos
    are switched off by zero gains (MuJoCo Warp ignores ``opt.disableactuator``, with which the
    CPU env switches them off). The robot's gravity compensation and torque clamp are joint
    properties (``actgravcomp``, ``actfrcrange``), so nothing else changes."""
    if tables.control_mode != "torque":
        return model
    if not model.opt.disableactuator:
        raise AssertionError("the CPU env's torque mode no longer disables the servos")
    servo = tables.servo_ids
    if np.any(model.actuator_biasprm[servo, 0] != 0):
        raise AssertionError("a servo has a constant bias: zero gains would not switch it off")
    copy = mujoco.MjModel.__copy__(model)
    copy.actuator_gainprm[servo, 0] = 0.0
    copy.actuator_biasprm[servo, 1:3] = 0.0
    copy.opt.disableactuator = 0
    return copy


def _f32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.float32))


def _i32(array: Any) -> jax.Array:
    return jp.asarray(np.asarray(array, dtype=np.int32))


class BatchedRehabEnv:
    """A ``-v2`` id as a functional env (module docstring); make it with
    :func:`rehabbot.batch.make`.

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
        model_fields = {field.name for field in dataclasses.fields(mjx.Model)}
        self.tables: EnvTables = read_tables(env_id, cpu, model_fields)
        patient = read_patient_tables(cpu)
        # The condition's torques on the patient's joints (None: it applies none).
        self.patient = BatchedPatientDrive(patient) if patient is not None else None
        self.cpu_env = cpu
        self.mj_model: mujoco.MjModel = physics_model(cpu.model, self.tables)
        self.mjx_model = mjx.put_model(self.mj_model, impl="warp")
        self.naconmax, self.njmax = naconmax, njmax
        self.action_size = int(cpu.action_space.shape[0])
        self.observation_size = int(cpu.observation_space.shape[0])
        self.dt_s = float(cpu.dt_s)
        self._build_arrays(self.tables)

    def _build_arrays(self, t: EnvTables) -> None:
        self._servo, self._dof, self._qpos = _i32(t.servo_ids), _i32(t.dof_adr), _i32(t.qpos_adr)
        self._motor, self._torque_limit = _i32(t.motor_ids), _f32(t.torque_limit_nm)
        self._center, self._half = _f32(t.action_center), _f32(t.action_half)
        self._low, self._high = _f32(t.setpoint_low_rad), _f32(t.setpoint_high_rad)
        self._home_qpos = _f32(t.home_qpos)
        home_ctrl = np.zeros((len(WEIGHT_LEVELS), self.mj_model.nu))
        home_ctrl[:, t.servo_ids] = t.home_setpoints_rad
        self._home_ctrl = _f32(home_ctrl)  # per weight level
        self._level_fields = {
            name: jp.asarray(rows, dtype=getattr(self.mjx_model, name).dtype)
            for name, rows in t.level_fields.items()}
        self._base, self._rot_t = _f32(t.base_pos_m), _f32(t.base_rot_t)
        self._phi = _i32(t.phi_adr)
        self._box_low, self._box_high = jp.asarray(t.healthy_low), jp.asarray(t.healthy_high)
        self._targets, self._tools = _f32(t.targets_rad), _f32(t.tool_targets_m)
        self._count, self._rests = _i32(t.num_targets), _f32(t.rests_rad)
        self._patient = _i32(t.patient_qpos_adr)
        self._rom_low, self._rom_high = _f32(t.rom_low_rad), _f32(t.rom_high_rad)
        self._is_robot, self._is_other = jp.asarray(t.is_robot_geom), jp.asarray(t.is_other_geom)
        self._matrix = _f32(t.agent_matrix)
        self._bounded_low, self._bounded_high = _f32(t.bounded_low), _f32(t.bounded_high)
        self._contact_types = _i32(CONTACT_CONSTRAINTS)

    # -- pieces ------------------------------------------------------------------------------
    def _model(self, level: jax.Array) -> Any:
        """The MJX model at weight ``level``; under ``jax.vmap`` its level fields are per world
        (MuJoCo Warp's batched model fields)."""
        return self.mjx_model.replace(**{name: rows[level]
                                         for name, rows in self._level_fields.items()})

    def _dynamic(self, data: Any) -> tuple[jax.Array, jax.Array]:
        """theta (the robot's joint angles) and the paper observation's theta, p, phi."""
        theta = data.qpos[self._qpos]
        p = self._rot_t @ (data.site_xpos[self.tables.tool_site] - self._base)
        return theta, jp.concatenate([theta, p, data.qpos[self._phi]])

    def _cuff_rows_force(self, data: Any) -> tuple[jax.Array, jax.Array]:
        """The cuff's constraint force (3,) and whether its rows exist (the work meter's)."""
        row, impl = self.tables.cuff_row, data._impl
        return impl.efc__force[row:row + 3], jp.reshape(impl.nefc, ()) >= row + 3

    def _meter_start(self, data: Any) -> dict[str, jax.Array]:
        """The work meter at the start of an episode (``WorkMeter.reset``)."""
        zero = jp.zeros((), jp.float32)
        return {"meter_pos": data.site_xpos[self.tables.patient_cuff_site],
                "meter_force": jp.zeros(3, jp.float32), "meter_has_force": jp.bool_(False),
                "robot_work_j": zero, "robot_positive_work_j": zero}

    def _meter_after_step(self, meter: dict, data: Any) -> dict[str, jax.Array]:
        """``WorkMeter.after_step``: the force of the physics step before times the cuff
        site's displacement since (the force on the limb is minus the constraint force)."""
        pos = data.site_xpos[self.tables.patient_cuff_site]
        work = jp.where(meter["meter_has_force"],
                        jp.dot(meter["meter_force"], meter["meter_pos"] - pos), 0.0)
        force, has_force = self._cuff_rows_force(data)
        return {"meter_pos": pos, "meter_force": force, "meter_has_force": has_force,
                "robot_work_j": meter["robot_work_j"] + work,
                "robot_positive_work_j": meter["robot_positive_work_j"]
                + jp.maximum(work, 0.0)}

    def _work_metrics(self, meter: dict) -> dict[str, jax.Array]:
        """The work entries of the CPU env's ``info``: a patient without a drive does no work
        (so the robot's share of the positive work, the assistance ratio, is 1); with one,
        also the last physics step's ``patient_torque_nm``."""
        if self.patient is None:
            return {"robot_work_j": meter["robot_work_j"],
                    "patient_work_j": jp.zeros((), jp.float32),
                    "assistance_ratio": jp.ones((), jp.float32)}
        robot, patient = meter["robot_positive_work_j"], meter["patient_positive_work_j"]
        ratio = jp.where(patient > 0.0, robot / jp.maximum(robot + patient, 1e-30), 1.0)
        return {"robot_work_j": meter["robot_work_j"], "patient_work_j": meter["patient_work_j"],
                "assistance_ratio": ratio,
                "patient_torque_nm": self.patient.exercised_torque(meter)}

    def _hold_travel(self, setpoint: jax.Array, theta: jax.Array,
                     speed: jax.Array) -> jax.Array:
        """How far [rad] the joints may still travel if the agent holds still
        (``Controller.hold_travel_rad``): to the setpoints, or in ``torque`` mode the sag and
        braking allowance."""
        t = self.tables
        if t.control_mode == "torque":
            return t.hold_sag_rad + t.hold_brake_s * speed
        return jp.linalg.norm(setpoint - theta)

    def _paper(self, exercise: jax.Array, index: jax.Array, dynamic: jax.Array,
               level: jax.Array) -> jax.Array:
        """The paper observation (float32), in the CPU layout's order."""
        t = self.tables
        fields = {"theta_star": self._targets[exercise, index],
                  "p_star": self._tools[exercise, index],
                  "e": exercise.astype(jp.float32)[None],
                  "l": level.astype(jp.float32)[None]}
        paper = jp.zeros(self._box_low.shape[0], jp.float32)
        for name, values in fields.items():
            start, stop = t.paper_slices[name]
            paper = paper.at[start:stop].set(values)
        start = t.paper_slices["theta"][0]  # theta, p and phi side by side
        return paper.at[start:start + dynamic.shape[0]].set(dynamic)

    def _cuff_force(self, data: Any) -> jax.Array:
        """The cuff's force [N] (0 while its constraint is not active), as the CPU reads it."""
        row, impl = self.tables.cuff_row, data._impl
        force = jp.linalg.norm(impl.efc__force[row:row + 3])
        return jp.where(jp.reshape(impl.ne, ()) >= row + 3, force, 0.0)

    def _touch(self, data: Any) -> jax.Array:
        """Whether a robot geom touches the patient or the furniture deeper than the
        tolerance: the contacts of this world's contact constraint rows."""
        impl = data._impl
        rows = jp.arange(impl.efc__type.shape[-1]) < jp.reshape(impl.nefc, ())
        contact_row = rows & jp.isin(impl.efc__type, self._contact_types)
        cid = jp.clip(impl.efc__id, 0, impl.contact__geom.shape[0] - 1)
        geom = impl.contact__geom[cid]
        robot, other = self._is_robot[geom], self._is_other[geom]
        hit = (robot[:, 0] & other[:, 1]) | (robot[:, 1] & other[:, 0])
        deep = impl.contact__dist[cid] < -self.tables.contact_tolerance_m
        return jp.any(contact_row & hit & deep)

    def _agent_obs(self, paper: jax.Array, exercise: jax.Array, index: jax.Array,
                   setpoint: jax.Array, qvel: jax.Array, force: jax.Array) -> jax.Array:
        t = self.tables
        count = self._count[exercise]
        has_next = index + 1 < count
        following = self._targets[exercise, jp.minimum(index + 1, self._targets.shape[1] - 1)]
        theta_star = paper[t.paper_slices["theta_star"][0]:t.paper_slices["theta_star"][1]]
        x = jp.concatenate([paper, jp.where(has_next, following, theta_star), setpoint,
                            jp.where(jp.isfinite(qvel), qvel, 0.0),
                            jp.where(jp.isfinite(force), force, NONFINITE_FORCE_N)[None],
                            jp.ones(1, jp.float32)])
        v = self._matrix @ x
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
        state, goal = self.patient.begin_step(state, exercise, index, key)
        return state, goal, rng

    # -- API ---------------------------------------------------------------------------------
    def _draw(self, rng: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        """The episode's exercise and weight level (the config's, or drawn uniformly, as the
        CPU env draws them) and the key for the next draw."""
        rng, exercise_key, level_key = jax.random.split(rng, 3)
        t = self.tables
        exercise = jp.int32(t.exercise) if t.exercise is not None else jax.random.randint(
            exercise_key, (), 0, self._targets.shape[0], jp.int32)
        level = jp.int32(t.weight_level) if t.weight_level is not None else \
            jax.random.randint(level_key, (), 0, len(WEIGHT_LEVELS), jp.int32)
        return exercise, level, rng

    def _start(self, data: Any, exercise: jax.Array, level: jax.Array,
               rng: jax.Array) -> State:
        """The state of an episode of ``exercise`` at weight ``level`` starting at ``data``
        (the home state, after ``mjx.forward``)."""
        t = self.tables
        theta, dynamic = self._dynamic(data)
        setpoint = self._home_ctrl[level][self._servo]
        index = jp.int32(0)
        paper = self._paper(exercise, index, dynamic, level)
        speed = jp.linalg.norm(data.qvel[self._dof])
        force = self._cuff_force(data)
        obs = self._agent_obs(paper, exercise, index, setpoint, data.qvel[self._dof], force)
        zero = jp.zeros((), jp.float32)
        info = {
            "setpoint": setpoint, "target_index": index, "exercise": exercise,
            "weight_level": level, "steps": jp.int32(0), "theta": theta, "healthy": dynamic,
            "path_left": jp.linalg.norm(theta - self._targets[exercise, 0])
            + self._rests[exercise, 0],
            "hold_gap": jp.float32(t.max_episode_steps * t.time_cost)
            + t.progress_weight * self._hold_travel(setpoint, theta, speed),
            "rng": rng, "truncation": zero, **self._meter_start(data),
        }
        if self.patient is not None:
            info["rng"], key = jax.random.split(rng)
            info.update(self.patient.start(key))
        metrics = {"interaction_force_n": force, "cost": zero,
                   "safety_violation": jp.int32(0), "is_success": zero,
                   "target_index": index, "action_clipped": jp.int32(0),
                   **self._readings(data, exercise, level),
                   **self._work_metrics(info), **dict.fromkeys(REWARD_TERMS, zero)}
        return State(data, obs, zero, zero, metrics, info)

    def _readings(self, data: Any, exercise: jax.Array, level: jax.Array
                  ) -> dict[str, jax.Array]:
        """The CPU env's ``info`` readings of the robot and the patient: the robot's actuator
        torques on its joints, the patient's joint angles, the exercise and weight level."""
        return {"robot_torque_nm": data.qfrc_actuator[self._dof],
                "patient_qpos": data.qpos[self._patient],
                "exercise": jp.asarray(exercise, jp.int32),
                "weight_level": jp.asarray(level, jp.int32)}

    def reset(self, rng: jax.Array, exercise: jax.Array | int = -1,
              weight_level: jax.Array | int = -1) -> State:
        """A new episode at home: the exercise and the weight level are the config's, or drawn
        from ``rng``; an ``exercise`` or ``weight_level`` >= 0 overrides them for this episode
        (the CPU env's reset ``options``; checked by :meth:`check_reset_options`, since a
        jitted function cannot raise). Both are drawn every reset, as on the CPU, so that the
        draws do not depend on the options."""
        drawn_exercise, drawn_level, rng = self._draw(rng)
        exercise = jp.where(jp.asarray(exercise) >= 0, jp.asarray(exercise, jp.int32),
                            drawn_exercise)
        level = jp.where(jp.asarray(weight_level) >= 0, jp.asarray(weight_level, jp.int32),
                         drawn_level)
        data = mjx.make_data(self.mj_model, impl="warp", naconmax=self.naconmax,
                             njmax=self.njmax)
        data = data.replace(qpos=self._home_qpos, ctrl=self._home_ctrl[level])
        return self._start(mjx.forward(self._model(level), data), exercise, level, rng)

    def check_reset_options(self, options: dict | None) -> tuple[int, int]:
        """``(exercise, weight_level)`` of the CPU env's reset ``options`` (-1: not given), or
        ``ValueError`` naming a bad one, as the CPU env does."""
        from rehabbot.common.checks import check_options
        from rehabbot.envs.env_base import RESET_OPTIONS
        from rehabbot.sim.scene import check_weight_level
        from rehabbot.tasks import feasibility

        options = check_options(options, RESET_OPTIONS)
        exercise = options.get("exercise", -1)
        count = int(self._targets.shape[0])
        if "exercise" in options and (isinstance(exercise, bool)
                                      or exercise not in range(count)):
            raise ValueError(f"exercise={exercise!r} is not one of {list(range(count))}")
        level = options.get("weight_level", -1)
        if "weight_level" in options:
            level = check_weight_level(level)
            unusable = getattr(self.cpu_env, "_unusable_levels", {})
            if level in unusable:
                feasibility.refuse(unusable, WEIGHT_LEVELS, level)
        return int(exercise), int(level)

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
        exercise, level, rng = self._draw(state.info["rng"])
        level = jp.where(done, level, state.info["weight_level"])

        def home(value: jax.Array, start: jax.Array | float) -> jax.Array:
            return jp.where(done, jp.broadcast_to(start, value.shape).astype(value.dtype), value)

        data = data.replace(qpos=home(data.qpos, self._home_qpos), qvel=home(data.qvel, 0.0),
                            ctrl=home(data.ctrl, self._home_ctrl[level]),
                            qacc_warmstart=home(data.qacc_warmstart, 0.0),
                            qfrc_applied=home(data.qfrc_applied, 0.0),
                            time=home(data.time, 0.0))
        data = mjx.forward(self._model(level), data)
        fresh = self._start(data, exercise, level, rng)
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
        action = jp.asarray(action, jp.float32)
        finite = jp.isfinite(action)
        clipped = jp.sum(~finite | (jp.abs(action) > 1.0)).astype(jp.int32)
        unit = jp.clip(jp.where(finite, action, 0.0), -1.0, 1.0)
        native = self._center + self._half * unit
        if t.control_mode == "torque":  # motor torques; the servos are off
            setpoint = info["setpoint"]
            ctrl = state.data.ctrl.at[self._motor].set(self._torque_limit * native)
        else:  # the servos follow setpoints, clipped to the setpoint bounds
            if t.control_mode == "joint_position":  # the action is the setpoint
                wanted = native
            elif t.control_mode == "joint_velocity":  # setpoint speeds over one control step
                wanted = info["setpoint"] + t.controller_dt_s * native
            else:  # joint_delta: setpoint increments
                wanted = info["setpoint"] + native
            setpoint = jp.clip(wanted, self._low, self._high)
            ctrl = state.data.ctrl.at[self._servo].set(setpoint)
        data = state.data.replace(ctrl=ctrl)

        level = info["weight_level"]
        model = self._model(level)
        exercise, index = info["exercise"], info["target_index"]
        patient, goal, rng = self._patient_begin(info, exercise, index)

        def physics_step(carry: tuple, _: None) -> tuple[tuple, None]:
            d, meter, patient = carry
            if self.patient is not None:
                patient, d, q = self.patient.apply(patient, d, goal)
            d = mjx.step(model, d)
            if self.patient is not None:
                patient = self.patient.count_work(patient, d, q)
            return (d, self._meter_after_step(meter, d), patient), None

        meter = {k: info[k] for k in METER_KEYS}
        (data, meter, patient), _ = jax.lax.scan(physics_step, (data, meter, patient), None,
                                                 length=t.frame_skip)

        # Safety rules, in the CPU env's order.
        force = self._cuff_force(data)
        speed = jp.max(jp.abs(data.qvel))
        unstable = (~jp.all(jp.isfinite(data.qpos)) | ~(force <= t.blowup_force_n)
                    | ~(speed <= t.blowup_speed_rad_s))
        theta, dynamic = self._dynamic(data)
        before = self._paper(exercise, index, dynamic, level)
        outside = ~jp.all((before >= self._box_low) & (before <= self._box_high))
        unstable = unstable | outside
        q = data.qpos[self._patient]
        rom = jp.any((q < self._rom_low) | (q > self._rom_high))
        cuff = force > t.cuff_force_limit_n
        touch = self._touch(data)
        violation = jp.select([unstable, rom, cuff, touch],
                              [RULE_CODES["instability"], RULE_CODES["range_of_motion"],
                               RULE_CODES["cuff_force"], RULE_CODES["unintended_contact"]],
                              0).astype(jp.int32)
        theta = jp.where(unstable, info["theta"], theta)
        dynamic = jp.where(unstable, info["healthy"], dynamic)
        force = jp.where(jp.isfinite(force), force, 0.0)

        # Reward (progress, "hold" penalty) and the target switch.
        steps = info["steps"] + 1
        error = theta - self._targets[exercise, index]
        distance, largest = jp.linalg.norm(error), jp.max(jp.abs(error))
        count = self._count[exercise]
        last = index == count - 1
        stop = (violation > 0) & (t.terminate_on_safety | (violation == INSTABILITY))
        reached = (largest < t.target_tolerance_rad) & ~stop
        switching = reached & ~last
        following = jp.minimum(index + 1, self._targets.shape[1] - 1)
        next_distance = jp.where(
            switching, jp.linalg.norm(theta - self._targets[exercise, following]), distance)
        new_index = jp.where(switching, index + 1, index)
        after = next_distance + self._rests[exercise, new_index]
        progress = t.progress_weight * (info["path_left"] - after)
        gap = info["hold_gap"]
        safety = jp.where(stop, -(jp.maximum(gap + progress - t.time_cost, 0.0) + t.time_cost
                                  + t.stop_margin), 0.0)
        bonus = jp.where(reached, jp.where(last, t.final_bonus, t.intermediate_bonus), 0.0)
        reward = progress + bonus - t.time_cost + safety
        lead = self._hold_travel(setpoint, theta, jp.linalg.norm(data.qvel[self._dof]))
        hold = jp.maximum(t.max_episode_steps - steps, 0) * t.time_cost \
            + t.progress_weight * lead
        gap = jp.where(stop, gap, jp.maximum(gap + reward, hold))
        terminated = stop | (reached & last)
        truncated = (steps >= t.max_episode_steps) & ~terminated

        paper = self._paper(exercise, new_index, dynamic, level)
        obs = self._agent_obs(paper, exercise, new_index, setpoint, data.qvel[self._dof],
                              self._cuff_force(data))
        f32 = jp.float32
        new_info = {**info, **meter, **patient, "rng": rng, "setpoint": setpoint,
                    "target_index": new_index, "steps": steps,
                    "theta": theta, "healthy": dynamic, "path_left": after, "hold_gap": gap,
                    "truncation": truncated.astype(f32)}
        metrics = {"interaction_force_n": force, "cost": (violation > 0).astype(f32),
                   "safety_violation": violation,
                   "is_success": (reached & last).astype(f32),
                   "target_index": new_index, "action_clipped": clipped,
                   **self._readings(data, exercise, level),
                   **self._work_metrics({**meter, **patient}),
                   "reward_progress": progress, "reward_bonus": bonus,
                   "reward_time": jp.full((), -t.time_cost, f32), "reward_safety": safety}
        return State(data, obs, reward.astype(f32), (terminated | truncated).astype(f32),
                     {k: jp.asarray(v) for k, v in metrics.items()}, new_info)
