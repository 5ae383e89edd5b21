"""The one env core of :class:`~rehabbot.envs.rehab_env.RehabEnv` (one robot) and
:class:`~rehabbot.envs.bilateral_env.BilateralEnv` (two): ``reset`` and ``step`` for any number
of arms, over the parts the env's builder resolved once
(:class:`rehabbot.envs.build.EnvParts`).

One ``step`` reads in four modules: this one, :mod:`rehabbot.envs.control` (what the action
does to the robots' controls), :mod:`rehabbot.sim.physics` (``frame_skip`` physics steps, the
work on the limb and the safety rules) and :mod:`rehabbot.tasks.reward` (what the step pays).
A patient condition that applies torques adds its torque laws
(:mod:`rehabbot.sim.patient_drive`). In order:

1. the action is checked and written into ``data.ctrl`` by the controller (on the ``-v2`` ids
   first mapped from ``Box(-1, 1)`` onto the controller's box);
2. the physics runs ``frame_skip`` steps and the safety rules judge the new state;
3. the paper's observation (theta, p, phi of every arm) is written, and a state that leaves
   the healthy box is an ``"instability"`` (the last healthy observation is kept);
4. each arm's distance to the active target decides whether it was reached (every joint of
   every arm within the tolerance) and the reward pays the step from a :class:`StepOutcome`;
5. a reached target switches to the next; ``info`` is assembled; on the ``-v2`` ids the agent
   observation is ``tanh`` or a clip of one affine map of the state
   (:mod:`rehabbot.tasks.agent_observation` builds the map).

The one-arm and the two-arm envs differ only in what their builders resolve (one robot or a
:class:`~rehabbot.envs.control.ControllerPair`, one cuff or two, the reward design) and in two
entries of ``info`` (``cuff_forces_n``, and the sync entries of the bilateral reward).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from rehabbot.common.arrays import as_index
from rehabbot.envs.build import EnvParts
from rehabbot.envs.control import UnitActions, checked_action
from rehabbot.envs.env_base import RehabEnvBase
from rehabbot.envs.env_rendering import EnvRendering
from rehabbot.laws import scalar
from rehabbot.laws.targets import switch_target
from rehabbot.sim.randomization import RandomizationDraw, Randomizer, check_preset
from rehabbot.tasks.agent_observation import AgentObservation
from rehabbot.tasks.reward import StepOutcome

# A value this far inside a bound of the healthy box is inside whatever float32 rounding does
# (the bounds are below 10 in magnitude; float32 rounds them by at most 5e-7).
BOUND_CLEARANCE = 1e-5


class RehabEnvCore(RehabEnvBase):
    """``reset`` and ``step`` of every RehabBot env (module docstring). A subclass builds its
    parts and calls :meth:`_adopt` from its constructor."""

    def _adopt(self, parts: EnvParts) -> None:
        """Take the built parts: resolve every id, slice and buffer a step uses, once."""
        config = self.config
        self._adopt_parts(parts, config)
        scene, data = self.scene, self.data
        self.handles = parts.handles
        self.robot = parts.handles[0].robot
        self.exercises = parts.exercise_table
        self._physics = parts.physics
        self._reward = parts.reward
        self._goals = parts.goals_rad
        self._goal: list[float] | None = None
        self._arms = len(parts.handles)
        n = self._n_joints = self.robot.n_joints  # per arm
        self._arm_of_joint = tuple(k for k in range(self._arms) for _ in range(n))

        layout = self.layout
        self._theta_star, self._p_star = layout.slice("theta_star"), layout.slice("p_star")
        self._e_obs, self._l_obs = layout.index("e"), layout.index("l")
        theta, p, phi = layout.slice("theta"), layout.slice("p"), layout.slice("phi")
        if not (theta.stop == p.start and p.stop == phi.start):
            raise AssertionError("the layout must keep theta, p and phi side by side")
        self._dynamic = slice(theta.start, phi.stop)  # written in one piece every step
        controller = self.controller
        self._clip_low = controller.clip_low.astype(np.float32)  # as the actions it clips
        self._clip_high = controller.clip_high.astype(np.float32)
        self._qpos_adr = as_index(np.concatenate([h.qpos_adr for h in self.handles]))
        self._dof_adr = as_index(np.concatenate([h.dof_adr for h in self.handles]))
        # Per arm: its controller, its dofs and its joints in theta.
        self._arm_parts = tuple(
            (arm_controller, as_index(handle.dof_adr), slice(k * n, (k + 1) * n))
            for k, (arm_controller, handle) in enumerate(zip(controller.controllers,
                                                             self.handles, strict=True)))
        mujoco.mj_kinematics(self.model, data)
        base_pos = [data.xpos[h.base_body_id].copy() for h in self.handles]
        base_rot = [data.xmat[h.base_body_id].reshape(3, 3).copy() for h in self.handles]
        # Per arm, the base frame as nine numbers and the origin: p = R^T (x - base).
        self._frames = [(*pos.tolist(), *rot.T.ravel().tolist())
                        for pos, rot in zip(base_pos, base_rot, strict=True)]
        self._tool_sites = [h.tool_site_id for h in self.handles]
        phi_adr = [int(a) for a in scene.exercised_qpos_adr]
        self._phi_block = slice(min(phi_adr), max(phi_adr) + 1)  # read as one slice
        self._phi_pick = tuple(a - min(phi_adr) for a in phi_adr)
        self._patient_qpos_adr = as_index(scene.patient_qpos_adr)
        self._obs = np.zeros(layout.size, np.float32)  # the paper's observation
        self.set_healthy_box(parts.healthy_low, parts.healthy_high)
        self._healthy_values: list[float] = []  # theta, p, phi of the last healthy step
        self._theta: list[float] = [0.0] * n * self._arms  # the last healthy joint angles
        self._target: list[float] = list(self._theta)  # theta* of the active target
        self._outcome = StepOutcome()
        self._num_targets = 0
        self._tolerance = config.target_tolerance_rad
        self._terminate_on_safety = config.terminate_on_safety
        self._uses_hold_gap = self._reward.uses_hold_gap
        self._reward_info = getattr(self._reward, "info", None)  # the bilateral entries
        self._steps = self._target_index = self._exercise = 0
        self._sequence = self.targets[0]
        self._needs_reset = True  # before the first reset, after a termination, after close
        self._closed = False
        self._rendering = EnvRendering(self.model, self.render_mode, config.width,
                                       config.height, config.camera_name,
                                       self.max_episode_steps, self.dt_s, base_pos[0],
                                       base_rot[0])
        self._record = self.render_mode is not None
        self._adopt_agent_interface()
        self._adopt_randomization()
        self._bind_views()
        scene.reset_data(data)

    def _adopt_agent_interface(self) -> None:
        """The ``-v2`` interface, when the config asks for it: actions in ``Box(-1, 1)``
        (``action_scale="unit"``) and the agent observation (``observation="agent"``)."""
        config = self.config
        self._unit_actions: UnitActions | None = None
        self._agent: AgentObservation | None = None
        if config.action_scale == "unit":
            self._unit_actions = UnitActions(self.controller.clip_low, self.controller.clip_high)
            self.action_space = self._unit_actions.space
        if config.observation == "agent":
            model, adr = self.model, np.asarray(self.scene.exercised_qpos_adr).tolist()
            joints = [int(np.flatnonzero(model.jnt_qposadr == a)[0]) for a in adr]
            phi_range = model.jnt_range[joints]
            agent = self._agent = AgentObservation(
                self._n_joints, self._arms, len(self.targets), self.setpoint_low_rad,
                self.setpoint_high_rad, phi_range[:, 0], phi_range[:, 1],
                self.safety.force_limits_n, has_setpoints=config.control_mode != "torque")
            self.agent_layout = agent.layout
            low, high = agent.space_bounds
            self.observation_space = gym.spaces.Box(low, high, (agent.layout.size,), np.float32)

    def _adopt_randomization(self) -> None:
        """Randomisation for transfer (:mod:`rehabbot.sim.randomization`), when the config
        names a preset: its randomizer over this scene; None (nothing drawn) otherwise."""
        preset = check_preset(getattr(self.config, "randomization", None))
        self._randomizer: Randomizer | None = None if preset is None else Randomizer(
            self.scene, preset, self.robot.torque_limit_nm)
        self.randomization_draw: RandomizationDraw | None = None  # the episode's draw

    # ------------------------------------------------------------------------------------------
    # Gymnasium API
    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._start_episode(seed, options)
        if self._randomizer is not None:  # draw the episode's model, then load its home state
            self.randomization_draw = self._randomizer.apply(self.np_random)
            self.scene.reset_data(self.data)
        data = self.data
        home = self.scene.home_setpoints  # per arm, at this weight level
        self.controller.reset(data, home if self._arms > 1 else home[0])
        self._physics.reset(data, self.np_random)
        self._rendering.clear_trace()
        self._record_trace()
        obs = self._obs
        obs[self._e_obs] = self._exercise
        obs[self._l_obs] = self.scene.weight_level
        self._num_targets = len(self._sequence)
        self._write_target()
        self._theta = self._observe() or self._qpos[self._qpos_adr].tolist()
        start = self._outcome
        start.next_distance_rad, start.next_arm_distances_rad = self._distances(self._target)
        start.lead_rad = self._leads() if self._uses_hold_gap else (0.0,)
        self._reward.reset(self._exercise, start)
        info = self._info(None, False, self.safety.cuff_force_n(data),
                          self._reward.zero_terms(), 0)
        self._needs_reset = False
        if self.randomization_draw is not None and self._randomizer is not None:
            info["randomization"] = self.randomization_draw.to_dict()
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info), info

    def step(self, action):
        applied = self.prepare_step(action)
        self.advance_physics()
        return self.finish_step(applied)

    # The three parts of ``step``, in this order; a vector env runs the physics of many worlds
    # at once between the other two (:mod:`rehabbot.envs.vector`).
    def prepare_step(self, action) -> tuple[Any, int]:
        """Check ``action`` and write it into the controls; return what ``finish_step`` needs
        (the applied action in the controller's units, and how many entries were clipped)."""
        if self._needs_reset:
            self._refuse_step()
        clipped = 0
        if self._randomizer is not None:  # randomisation: the action arrives k decisions late
            action, clipped = self._delayed_control(action)
        else:
            if self._unit_actions is not None:  # -v2: Box(-1, 1) onto the controller's box
                action, clipped = self._unit_actions.native(action)
            else:
                action, clipped = checked_action(action, self.controller.action_space,
                                                 self._clip_low, self._clip_high)
            self.controller.apply(action, self.data)
        return action, clipped

    def advance_physics(self) -> None:
        """The control step's ``frame_skip`` physics steps (with the patient's torques and the
        work meters): touches only this env's MuJoCo data and its own random stream."""
        self._physics.advance(self.model, self.data, self._goal, self.np_random)

    def finish_step(self, applied: tuple[Any, int]):
        """The rest of ``step`` after the physics: the safety rules, the observation, the
        reward and the target switch; returns ``step``'s five values."""
        action, clipped = applied
        violation, force_n = self.safety.check_step(self.data)
        self._steps += 1

        obs = self._obs
        if violation != "instability":
            healthy = self._healthy_values
            theta = self._observe()
            if theta is not None:
                self._theta = theta
                if self._record:
                    self._record_trace()
            else:
                violation = "instability"
                self._healthy_values = healthy
        if violation == "instability":  # keep the last healthy observation and joint angles
            obs[self._dynamic] = self._healthy_values
            force_n = 0.0 if not math.isfinite(force_n) else force_n

        # The distance to the target that was active during the step (a few numbers: plain
        # Python), and each arm's.
        squared = largest = 0.0
        for angle, goal in zip(self._theta, self._target, strict=True):
            error = angle - goal
            squared += error * error
            if abs(error) > largest:
                largest = abs(error)
        index = self._target_index
        safety_stop = violation is not None and (self._terminate_on_safety
                                                 or violation == "instability")
        switch = switch_target(largest, index, self._num_targets, safety_stop,
                               self._tolerance, xp=scalar)
        reached = switch.reached
        outcome = self._outcome
        distance = outcome.distance_rad = math.sqrt(squared)
        outcome.arm_distances_rad = [distance] if self._arms == 1 else \
            self._arm_distances(self._target)
        if switch.index != index:  # holding still now costs the distance to the next target
            outcome.next_distance_rad, outcome.next_arm_distances_rad = self._distances(
                self._sequence.robot_rad[switch.index].tolist())
        else:
            outcome.next_distance_rad = outcome.distance_rad
            outcome.next_arm_distances_rad = outcome.arm_distances_rad
        if self._uses_hold_gap and not safety_stop:
            outcome.lead_rad = self._leads()
        outcome.target_index = index
        outcome.reached = reached
        outcome.last_target = switch.last
        outcome.safety_stop = safety_stop
        outcome.steps_done = self._steps
        outcome.action = action
        if self._torque_view is None:
            outcome.torque_nm = self._qfrc_actuator[self._dof_adr]
        reward, terms = self._reward.step(outcome)

        is_success = switch.success
        terminated = safety_stop or is_success
        if switch.index != index:
            self._target_index = switch.index
            self._write_target()  # the observation shows the next target
        self._needs_reset = terminated
        forces_n = self.safety.step_forces_n
        info = self._info(violation, is_success, force_n, terms, clipped, forces_n)
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info, forces_n), reward, terminated, False, info

    def setpoints_for(self, action) -> np.ndarray:
        """The servo setpoints [rad] ``step(action)`` would command, the same floats, without
        stepping: what a robot is sent when this env's policy drives it
        (:mod:`rehabbot.deploy`). ``ValueError`` for an action ``step`` refuses, or a control
        mode without setpoints."""
        if self._unit_actions is not None:
            action, _ = self._unit_actions.native(action)
        action, _ = checked_action(action, self.controller.action_space, self._clip_low,
                                   self._clip_high)
        return self.controller.setpoint_for(action)

    # ------------------------------------------------------------------------------------------
    # Properties
    # ------------------------------------------------------------------------------------------
    def set_healthy_box(self, low: np.ndarray, high: np.ndarray) -> None:
        """Replace the box a healthy observation must stay in (float32, read-only copies)."""
        self._healthy_low = np.array(low, dtype=np.float32)
        self._healthy_high = np.array(high, dtype=np.float32)
        for bound in (self._healthy_low, self._healthy_high):
            bound.setflags(write=False)
        self._dynamic_bounds = tuple(zip(self._healthy_low[self._dynamic].tolist(),
                                         self._healthy_high[self._dynamic].tolist(),
                                         strict=True))
        self._dynamic_clear = tuple((low + BOUND_CLEARANCE, high - BOUND_CLEARANCE)
                                    for low, high in self._dynamic_bounds)
        self._static_inside = self._static_fields_inside()

    @property
    def physics(self) -> Any:
        """The physics of a control step (:mod:`rehabbot.sim.physics`): the patient's drive or
        muscles and the work meter."""
        return self._physics

    @property
    def goals_rad(self) -> Any:
        """Per exercise, the compliant exercised joints' angles at each target (the active
        patient's goals), or None."""
        return self._goals

    @property
    def robot_base_frames(self) -> tuple[tuple[float, ...], ...]:
        """Per arm, its base frame as 12 numbers: the origin [m], then R^T row by row (the
        paper observation's tool position is p = R^T (x - origin))."""
        return tuple(tuple(frame) for frame in self._frames)

    @property
    def unit_actions(self) -> UnitActions | None:
        """The ``-v2`` map of unit actions onto the controller's box (None: native actions)."""
        return self._unit_actions

    @property
    def agent_observation_map(self) -> AgentObservation | None:
        """The ``-v2`` agent observation's affine map (None: the paper observation)."""
        return self._agent

    @property
    def reward_function(self) -> Any:
        """The reward (:mod:`rehabbot.tasks.reward`): its settings and its episode's state."""
        return self._reward

    @property
    def worst_step_reward(self) -> float | None:
        """The per-step loss of the ``"worst_case"`` safety penalty (this patient's bounds);
        None for the progress reward, which has no such penalty."""
        return getattr(self._reward, "worst_step_reward", None)

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    def _distances(self, target: list[float]) -> tuple[float, list[float]]:
        """``||theta - target||`` over every joint, and per arm."""
        squared = 0.0
        for angle, goal in zip(self._theta, target, strict=True):
            squared += (angle - goal) * (angle - goal)
        distance = math.sqrt(squared)
        return distance, [distance] if self._arms == 1 else self._arm_distances(target)

    def _arm_distances(self, target: list[float]) -> list[float]:
        """Each arm's ``||theta_k - target_k||``."""
        squares = [0.0] * self._arms
        for arm, angle, goal in zip(self._arm_of_joint, self._theta, target, strict=True):
            squares[arm] += (angle - goal) * (angle - goal)
        return [math.sqrt(s) for s in squares]

    def _leads(self) -> list[float]:
        """Per arm, how far [rad] its joints may still travel if the agent holds still
        (:meth:`rehabbot.envs.control.Controller.hold_travel_rad`)."""
        leads, qvel, theta = [], self._qvel, self._theta
        for controller, dofs, joints in self._arm_parts:
            speed = 0.0
            for velocity in qvel[dofs].tolist():
                speed += velocity * velocity
            leads.append(controller.hold_travel_rad(theta[joints], math.sqrt(speed)))
        return leads

    def _write_target(self) -> None:
        """The active target's fields of the observation (theta*, p*) and what depends on it."""
        obs, i = self._obs, self._target_index
        target = self._sequence.robot_rad[i]
        obs[self._theta_star] = target
        obs[self._p_star] = self._sequence.tool_pos_base_m[i]
        self._target = target.tolist()
        if self._goals is not None:
            self._goal = self._goals[self._exercise][i]
        self._static_inside = self._static_fields_inside()
        agent = self._agent
        if agent is not None:  # the agent observation's fields fixed until the next switch
            # the next target, or theta* itself (as the observation rounds it): 0 at the last
            agent.input[agent.next] = self._sequence.robot_rad[i + 1] \
                if i + 1 < self._num_targets else obs[self._theta_star]
            self._agent_tail = (agent.exercise_start + self._exercise, 2.0 * i / (
                self._num_targets - 1) - 1.0 if self._num_targets > 1 else 1.0)

    def _static_fields_inside(self) -> bool:
        """Whether the fields that change only at reset and target switches (theta*, p*, e,
        l) are in the healthy box; checked when they change, not every step."""
        obs, dynamic = self._obs, self._dynamic
        inside = (obs >= self._healthy_low) & (obs <= self._healthy_high)
        return bool(inside[:dynamic.start].all() and inside[dynamic.stop:].all())

    def _observe(self) -> list[float] | None:
        """Write the fields that change every step (theta, p, phi of every arm) into the
        paper's observation (and keep them, to restore the last healthy observation); return
        theta (the robots' joint angles, float64) as a list, or None if the observation left
        the healthy box."""
        qpos = self._qpos
        theta = qpos[self._qpos_adr].tolist()
        values = self._healthy_values = theta.copy()
        for (bx, by, bz, r00, r01, r02, r10, r11, r12, r20, r21, r22), tool in zip(
                self._frames, self._tool_xpos, strict=True):
            x, y, z = tool.tolist()
            dx, dy, dz = x - bx, y - by, z - bz
            values += (dx * r00 + dy * r01 + dz * r02, dx * r10 + dy * r11 + dz * r12,
                       dx * r20 + dy * r21 + dz * r22)
        block = qpos[self._phi_block].tolist()
        values += [block[k] for k in self._phi_pick]
        self._obs[self._dynamic] = values
        if not self._static_inside:
            return None
        # Clear of the bounds (by far more than float32 rounding): inside. Near them, compare
        # the float32 observation with the float32 bounds, as the box is defined.
        for value, (low, high) in zip(values, self._dynamic_clear, strict=True):
            if not low < value < high:
                break
        else:
            return theta
        for value, (low, high) in zip(self._obs[self._dynamic].tolist(),
                                      self._dynamic_bounds, strict=True):
            if not low <= value <= high:  # NaN fails too
                return None
        return theta

    def _info(self, safety_violation, is_success, force_n, terms, clipped,
              forces_n: np.ndarray | None = None) -> dict:
        """The step's ``info`` (``forces_n``: each cuff's force when the safety rules have
        read them this step; read here otherwise)."""
        info = {
            "is_success": is_success,
            "target_index": self._target_index,
            "num_targets": self._num_targets,
            "safety_violation": safety_violation,
            **terms,  # reward_distance, reward_bonus, ...
            "interaction_force_n": force_n,  # the largest cuff force
            "robot_torque_nm": self._qfrc_actuator[self._dof_adr].copy(),
            **self._physics.info(self.data),  # patient torque and work, robot work, muscles
            "patient_qpos": self._qpos[self._patient_qpos_adr].copy(),
            "exercise": self._exercise,
            "weight_level": self.scene.weight_level,
            "action_clipped": clipped,
            # Safety-Gymnasium's convention: 1.0 in a step where a safety rule fired (also with
            # terminate_on_safety=False), else 0.0; for constrained RL.
            "cost": 0.0 if safety_violation is None else 1.0,
        }
        if self._arms > 1:
            info["cuff_forces_n"] = self.safety.cuff_forces_n(self.data) if forces_n is None \
                else forces_n.copy()
        if self._reward_info is not None:
            info.update(self._reward_info())
        return info

    def _observation_out(self, info: dict, forces_n: np.ndarray | None = None) -> np.ndarray:
        """What ``reset`` and ``step`` return: the paper's observation, or the agent
        observation (with the paper's in ``info["paper_observation"]``): ``tanh`` or a clip
        of one affine map of the paper's observation, the next target (written at each
        target switch), the setpoints, the joint velocities and the cuff forces."""
        agent = self._agent
        if agent is None:
            obs = self._obs.copy()
            if self._randomizer is not None:  # randomisation: the sensors' noise
                self._add_sensor_noise(obs, None)
            return obs
        info["paper_observation"] = self._obs.copy()
        x = agent.input
        x[agent.paper] = self._obs
        if agent.has_setpoints:
            x[agent.setpoint] = self.controller.setpoint_rad
        x[agent.velocity] = self._qvel[self._dof_adr]
        x[agent.forces] = self.safety.cuff_forces_n(self.data) if forces_n is None else forces_n
        if not math.isfinite(x.sum()):  # an unstable step: no NaN reaches the agent (and no
            velocity, forces = x[agent.velocity], x[agent.forces]  # NumPy warning the user)
            velocity[~np.isfinite(velocity)] = 0.0
            forces[~np.isfinite(forces)] = 1e9  # finite: 0 x inf would spread NaN
        if self._randomizer is not None:  # randomisation: the sensors' noise
            self._add_sensor_noise(x[agent.paper], x[agent.velocity])
        v = agent.matrix @ x
        head, bounded = v[:agent.tanh_stop], v[agent.bounded]
        np.tanh(head, out=head)
        np.minimum(bounded, agent.bounded_high, out=bounded)  # the ufuncs: np.clip's Python
        np.maximum(bounded, agent.bounded_low, out=bounded)  # wrapper costs more than both
        one_hot, progress = self._agent_tail
        v[one_hot] = 1.0
        v[agent.progress] = progress
        return v.astype(np.float32)

    # -- randomisation for transfer (rehabbot.sim.randomization) ---------------------------
    def _delayed_control(self, action) -> tuple[np.ndarray, int]:
        """Check the agent's action now (errors and clipping at the call that sent it), then
        apply the one sent ``latency_steps`` decisions ago; while none has arrived the robot
        holds its setpoint (no command). Returns the applied action in the controller's units
        (zeros while none arrived) and the clipped count."""
        clipped = 0
        if self._unit_actions is not None:
            action, clipped = self._unit_actions.native(action)
        action, native_clipped = checked_action(action, self.controller.action_space,
                                                self._clip_low, self._clip_high)
        assert self._randomizer is not None
        arrived = self._randomizer.delay.push(action)
        if arrived is None:
            return np.zeros(np.shape(action)), clipped + native_clipped
        self.controller.apply(arrived, self.data)
        return arrived, clipped + native_clipped

    def _add_sensor_noise(self, paper: np.ndarray, velocity: np.ndarray | None) -> None:
        """Add one decision's encoder noise, in place, to the robot joint angles and the
        patient's joint angles of a paper observation, and to the joint velocities."""
        assert self._randomizer is not None
        layout = self.layout
        theta, phi = layout.slice("theta"), layout.slice("phi")
        n_velocity = 0 if velocity is None else len(velocity)
        theta_noise, velocity_noise, phi_noise = self._randomizer.noise(
            self.np_random, theta.stop - theta.start, n_velocity, phi.stop - phi.start)
        paper[theta] += theta_noise
        paper[phi] += phi_noise
        if velocity is not None:
            velocity += velocity_noise

    def _record_trace(self) -> None:
        if self._record:
            self._rendering.record(self._tool_xpos[0])

    def _bind_views(self) -> None:
        """Cache views of ``self.data``'s arrays (again after unpickling: views do not
        survive a pickle round trip)."""
        data = self.data
        self._qpos = data.qpos
        self._qvel = data.qvel
        self._tool_xpos = [data.site_xpos[site] for site in self._tool_sites]  # views
        self._qfrc_actuator = data.qfrc_actuator
        self.controller.bind(data)
        self._physics.bind(data)
        # The robots' actuator torques for the effort term: a view when their dofs are one
        # slice, else read every step.
        self._torque_view = None
        if type(self._dof_adr) is slice:
            self._torque_view = self._outcome.torque_nm = data.qfrc_actuator[self._dof_adr]

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()
