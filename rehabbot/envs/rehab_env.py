"""``RehabEnv``: a UR5e strapped to a patient's hand or leg moves the limb through a therapy
exercise (Gymnasium API). The four registered ids of the paper are this class with different
keyword arguments (:mod:`rehabbot.envs.registration`).

## Description
A seated (arm, knee) or supine (hip) patient, sized from a :class:`PatientProfile`, has one
hand or shank strapped to the cuff of a UR5e. The agent moves the robot's joints; the
patient's relaxed limb follows the cuff. Each episode runs one exercise of the limb's table
(:data:`rehabbot.tasks.exercises.EXERCISES`, or the ``exercises`` kwarg), defined in the
patient's joint space; the robot's targets are the joint angles that hold the limb at each key
pose (reaching) or along a minimum-jerk path (trajectory following). The agent must reach the
targets in order, within ``target_tolerance_rad`` on every joint, without hurting the patient.

## Action space
``control_mode="joint_delta"`` (the paper's ids): ``Box(-pi/400, pi/400, (6,), float32)``.

| index | robot joint | unit |
|---|---|---|
| 0 | shoulder_pan | rad added to the joint's impedance setpoint |
| 1 | shoulder_lift | rad |
| 2 | elbow | rad |
| 3 | wrist_1 | rad |
| 4 | wrist_2 | rad |
| 5 | wrist_3 | rad |

A setpoint drives a gravity-compensated joint impedance controller whose torque is saturated
at the UR5e limits (150 / 28 N·m). With ``robot="fr3"`` the action has 7 values, one per joint
``fr3_joint1`` .. ``fr3_joint7`` (limits 87 / 12 N·m), and theta*, theta are 7 wide (25
observations; :mod:`rehabbot.sim.robots`). Setpoints are kept inside the setpoint bounds (the paper's
Table 3 ranges in robot joint space). Other modes (:mod:`rehabbot.envs.control`):
``"joint_position"`` (``Box(-r - 0.5, r + 0.5)`` with ``r`` the joints' hardware ranges, rad;
actions outside this patient's setpoint bounds are clipped to them), ``"joint_velocity"``
(``Box(-max_speed_rad_s, max_speed_rad_s)``, rad/s), ``"torque"`` (``Box(-1, 1)``, fraction
of each joint's torque limit, added to gravity compensation, servos off). Finite actions
outside the box are clipped (counted in ``info["action_clipped"]``); NaN/inf (the error names
the indices), a wrong shape, or a dtype that is not a real number (bool, complex, str, object)
raise ``ValueError``. float64, integer and list actions are accepted.

## Observation space
``Box(low, high, (23,), float32)`` in the paper's order (:mod:`rehabbot.tasks.observation`).
Positions are in the robot base frame (origin on the base's mounting face, z up the base
axis, x along the zero of shoulder_pan). The bounds are the same for every patient profile and
weight level of an id (``r``: each robot joint's hardware range, 2 pi or pi for the elbow).

| index | observation | unit | bounds |
|---|---|---|---|
| 0-5 | theta*: target robot joint angles (pan, lift, elbow, wrist 1-3) | rad | +-(r + 0.5) |
| 6-8 | p*: target tool (flange) position x, y, z, base frame | m | +-1.35 |
| 9-14 | theta: robot joint angles | rad | +-(r + 1.1) |
| 15-17 | p: tool (flange) position, base frame | m | +-1.35 |
| 18-20 | phi: the patient's exercised joints (shoulder flexion, shoulder abduction, elbow flexion; or hip flexion, hip abduction, knee flexion), flexion positive | rad | anatomical range +- 0.5 |
| 21 | e: exercise (0, 1, ...) | - | [0, number of exercises - 1] |
| 22 | l: weight level (0..4) | - | [0, 4] |

### The -v2 ids: ``observation="agent"``, ``action_scale="unit"``
The ``-v2`` ids are the ``-v1`` task and reward with an interface any learner can use: the
action is ``Box(-1, 1, (n,), float32)``, mapped linearly onto the control mode's box
(``joint_delta``: -1 .. +1 is -pi/400 .. +pi/400 rad; ``joint_position``: the patient's
setpoint bounds; :class:`rehabbot.envs.actions.UnitActions`), and the observation is
``Box(-2, 2, (50,), float32)`` (56 with the FR3), every entry scaled to about [-1, 1]
(:mod:`rehabbot.tasks.agent_observation`, where the formulas are):

| index | observation | scale |
|---|---|---|
| 0-5 | ``joint_error_fine``: theta* - theta, the active target's joint errors | tanh(./0.05 rad) |
| 6-11 | ``joint_error``: the same, coarse | tanh(./0.5 rad) |
| 12-14 | ``tool_error_fine``: p* - p, base frame | tanh(./0.05 m) |
| 15-17 | ``tool_error``: the same, coarse | tanh(./0.2 m) |
| 18-23 | ``next_target``: theta*_{i+1} - theta*_i (0 at the last target) | tanh(./0.5 rad) |
| 24-29 | ``setpoint_lead``: servo setpoint - theta (0 in torque mode) | tanh(./0.05 rad) |
| 30-35 | ``joint_velocity``: the robot joints' velocities | tanh(./0.5 rad/s) |
| 36-41 | ``theta_in_bounds``: theta, -1 / +1 at the setpoint bounds | clipped to +-2 |
| 42-44 | ``phi_in_range``: the patient's exercised joints, -1 / +1 at the ends of their range | clipped to +-2 |
| 45 | ``cuff_force``: cuff force / its limit (the cuff-force rule fires above 1) | clipped to [0, 2] |
| 46-47 | ``exercise``: one-hot | 0 or 1 |
| 48 | ``weight_level``: l / 2 - 1 | [-1, 1] |
| 49 | ``target_progress``: 2 i / (N - 1) - 1 for the active target i of N | [-1, 1] |

The paper's 23 fields stay available: ``info["paper_observation"]`` (every step) and
``env.unwrapped.paper_observation()``, in the layout above (``env.unwrapped.layout``;
``env.unwrapped.agent_layout`` names the agent observation's fields).

## Rewards
Named terms, each reported as ``info["reward_<name>"]``; the reward is their sum
(``docs/envs.md``, Reward). ``reward="paper"`` (the -v0 ids): eq. (5),
:mod:`rehabbot.tasks.reward`: ``reward_distance = -||theta - theta*_i||_2``, ``reward_bonus``
(``intermediate_bonus`` / ``final_bonus`` when ``||theta - theta*_i||_inf <
target_tolerance_rad``), optional ``reward_smoothness`` and ``reward_effort``, ``reward_safety``
on a stop (a stop never pays); stalling can be worth more than reaching a target
(``benchmarks/reward_trap.py``). ``reward="progress"`` (the -v1 ids),
:mod:`rehabbot.tasks.progress_reward`: ``reward_progress`` (``progress_weight`` x the decrease
of the joint-space path still to travel), ``reward_bonus``, ``reward_time = -time_cost``, the
optional terms and ``reward_safety``; reaching each target beats stalling for every gamma in
[0.95, 0.999]. ``info["cost"]`` is 1.0 in a step where a safety rule fired, else 0.0
(Safety-Gymnasium's convention).

A profile or condition that cannot do the exercises in its scene (the robot cannot reach the
cuff, a target outside the setpoint bounds, a home state that already breaks a safety rule, a
condition whose steady load exceeds the cuff's force limit) is refused with a ``ValueError``
when the env is built (:mod:`rehabbot.tasks.feasibility`, :mod:`rehabbot.envs.condition_setup`).

## The patient
``condition`` (:class:`rehabbot.sim.conditions.PatientCondition`, ``docs/conditions.md``) adds
spasticity, contracture, weakness, tremor and effort; the default is a healthy, passive limb.
Every id reports ``info["patient_torque_nm"]`` (the patient's muscle torques on the exercised
joints), ``info["patient_work_j"]`` and ``info["robot_work_j"]`` (work on the limb since reset,
counted every physics step) and ``info["assistance_ratio"]`` (the robot's share of the positive
work; 1.0 until the patient does positive work).

## Starting state
The home posture of the scene (cuff satisfied, static equilibrium), no noise. The exercise and
the weight level are drawn from ``np_random`` unless fixed by the constructor or by
``reset(options={"exercise": e, "weight_level": l})``.

## Episode end
* terminated, success: the last target is reached (``info["is_success"]``);
* terminated, safety: a rule of :mod:`rehabbot.tasks.safety` fires
  (``info["safety_violation"]``): ``"instability"``, ``"range_of_motion"``, ``"cuff_force"``
  or ``"unintended_contact"``;
* truncated: ``max_episode_steps`` (1000 = 20 s), applied by the registration's ``TimeLimit``.

``step()`` before the first ``reset()`` or after a termination raises
``gymnasium.error.ResetNeeded``; after ``close()`` it raises ``RuntimeError``; ``close()`` twice
is a no-op. An ``"instability"`` always ends the episode (even with
``terminate_on_safety=False``) and returns the last healthy observation; the next ``reset()``
starts from the healthy home state.

## Arguments
All are fields of :class:`rehabbot.envs.config.RehabEnvConfig`, validated before anything is
built (``ValueError`` naming the value and its valid choices or range). ``RehabEnv(config)``
takes a config instead.

| kwarg | default | meaning |
|---|---|---|
| ``limb`` | ``"arm"`` | ``"arm"`` (seated, shoulder + elbow), ``"hip"`` (supine), ``"knee"`` (seated) |
| ``side`` | ``"right"`` | ``"right"`` or ``"left"`` arm / leg |
| ``task_type`` | ``"reaching"`` | ``"reaching"`` (the key poses) or ``"trajectory"`` (dense min-jerk waypoints) |
| ``control_mode`` | ``"joint_delta"`` | see Action space |
| ``profile`` | ``None`` | :class:`PatientProfile` or a dict of its fields (default 1.75 m, 75 kg, male) |
| ``condition`` | ``None`` | :class:`PatientCondition` or a dict of its fields (``spasticity_mas``, ``stiffness_scale``, ``rom_scale``, ``strength_fraction``, ``tremor_hz``, ``tremor_amplitude_nm``, ``effort``, ``effort_fraction``, ``reaction_delay_s``); ``None`` = healthy, passive. A condition variant id (``rehab-reach-spastic-v1``, ...) refuses a ``condition=`` that would replace its own: use the base id |
| ``weight_level`` | ``None`` | fix the weight level 0..4 (limb mass x1.0 .. x2.0); ``None`` draws it |
| ``exercise`` | ``None`` | fix the exercise (an index into the table); ``None`` draws it |
| ``exercises`` | ``None`` | the exercise table: :class:`Exercise` objects or dicts of their fields; ``None`` = the limb's built-in two |
| ``robot`` | ``"ur5e"`` | the robot on the cuff: ``"ur5e"`` (the paper's) or ``"fr3"`` (Franka Research 3, 7 joints) |
| ``cuff`` | ``"connect"`` | ``"connect"`` (strap: position only) or ``"weld"`` |
| ``base_reorientation_deg`` | 0.0 | rotation of the robot base about its vertical axis, in [-180, 180] |
| ``frame_skip`` | 10 | physics steps per decision |
| ``timestep_s`` | 0.002 | physics step in [1e-4, 0.005] s; ``dt = frame_skip * timestep_s`` (0.02 s, 50 Hz) |
| ``target_tolerance_rad`` | 0.05 | epsilon of eq. (5) |
| ``reward`` | ``"paper"`` | ``"paper"`` (eq. (5), the -v0 ids) or ``"progress"`` (the -v1 ids); see Rewards |
| ``observation`` | ``"paper"`` | ``"paper"`` (the paper's 23 fields, -v0 and -v1) or ``"agent"`` (the -v2 ids; see Observation space) |
| ``action_scale`` | ``"native"`` | ``"native"`` (actions in the control mode's units, -v0 and -v1) or ``"unit"`` (``Box(-1, 1)``, the -v2 ids) |
| ``progress_weight`` | 10.0 | progress reward: paid per rad of path travelled |
| ``time_cost`` | 0.05 | progress reward: cost of every step |
| ``intermediate_bonus`` | 10.0 | B_i for i < N - 1 |
| ``final_bonus`` | 100.0 | B_{N-1} |
| ``smoothness_weight`` | 0.0 | weight of ``reward_smoothness`` |
| ``effort_weight`` | 0.0 | weight of ``reward_effort`` |
| ``terminate_on_safety`` | True | end the episode (with the penalty) when a safety rule fires; if False the rule is only reported |
| ``safety_penalty`` | ``"hold"`` | ``"hold"`` (every reward: the gap to the best hold of the episode, one step more and a margin of 1.0, so a stop never pays) or, paper reward only, ``"worst_case"`` (steps left x worst per-step loss); :mod:`rehabbot.tasks.reward` |
| ``safety_penalty_steps`` | None | charge at most this many steps at the current hold cost instead (0.2.0's default was 100; with a cap a stop can pay) |
| ``rom_tolerance_deg`` | 2.0 | range-of-motion rule: allowed excess beyond the anatomical range, in [0, 10] deg (10: the knee hyperextension a CPM device allows, domain-facts §4.2) |
| ``cuff_force_limit_n`` | None | cuff force rule: limit in N for every cuff, in [1, 880] N (880 = 4 x the largest ISO/TS 15066 quasi-static limit, thighs 220 N); None = the quasi-static limit of the region each cuff holds |
| ``contact_tolerance_m`` | 0.002 | contact rule: penetration that counts as contact, in [0, 0.01] m (2 x the deepest limb compression at an ISO/TS 15066 quasi-static limit, upper arm 150 N / 30 N/mm = 5 mm) |
| ``max_episode_steps`` | 1000 | horizon used by the safety penalty, in [1, 10**6] (the registration's TimeLimit uses the same). ``gym.make(id, max_episode_steps=m)`` sets both: the env takes its TimeLimit's ``m`` as its horizon; ``m <= 0`` (Gymnasium's ``-1`` = no time limit included) is refused (:mod:`rehabbot.envs.registration`). A ``RehabEnv`` built directly never truncates: wrap it as ``TimeLimit(RehabEnv(..., max_episode_steps=m), m)`` |
| ``segment_s`` | 3.0 | trajectory: duration of each min-jerk segment between key poses |
| ``waypoint_dt_s`` | 0.1 | trajectory: sampling period of the min-jerk path |
| ``min_waypoint_spacing_rad`` | 0.1 | trajectory: minimum distance (inf-norm, robot joints) between waypoints |
| ``max_speed_rad_s`` | 0.5 | ``joint_velocity`` mode: action bound |
| ``render_mode`` | None | ``"human"``, ``"rgb_array"`` or ``"depth_array"`` |
| ``width``, ``height`` | 640, 480 | image size in pixels |
| ``camera_name`` | ``"overview"`` | ``"overview"``, ``"front"``, ``"side"`` or None (free camera) |

``depth_array`` images hold the distance from the camera in metres; pixels that see no geometry
hold the camera's far-plane distance. ``env.dt`` is the seconds per step, as in Gymnasium's
MuJoCo envs.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import mujoco
import numpy as np

from rehabbot.common.arrays import as_index
from rehabbot.envs.actions import checked_action
from rehabbot.envs.build import build_parts
from rehabbot.envs.config import RehabEnvConfig, config_from
from rehabbot.envs.env_base import RehabEnvBase
from rehabbot.envs.env_rendering import EnvRendering
from rehabbot.sim.patient_drive import LimbPhysics
from rehabbot.tasks.exercises import Exercise
from rehabbot.tasks.reward import StepOutcome, joint_distance, next_hold_gap, total

# A value this far inside a bound of the healthy box is inside whatever float32 rounding does
# (the bounds are below 10 in magnitude; float32 rounds them by at most 5e-7).
BOUND_CLEARANCE = 1e-5


class RehabEnv(RehabEnvBase):
    """A UR5e moves a patient's limb through a therapy exercise (see the module docstring)."""

    config_class: ClassVar[type] = RehabEnvConfig

    def __init__(self, config: RehabEnvConfig | None = None, **kwargs: Any) -> None:
        self.config = config = config_from(RehabEnvConfig, "RehabEnv", config, kwargs)
        parts = build_parts(config)  # ValueError for a patient who cannot do the exercises
        self._adopt_parts(parts, config)
        self.handle = parts.handle
        self.robot = self.handle.robot
        self.joint_low_rad, self.joint_high_rad = parts.joint_low_rad, parts.joint_high_rad
        self.exercises: tuple[Exercise, ...] = parts.exercise_table
        self._remaining_paths = parts.remaining_paths
        self._uses_path = self.reward_function.uses_path
        self._rest: tuple[float, ...] = parts.remaining_paths[0]
        self._hold_distance = 0.0  # ||theta - theta*|| of the current state, active target
        self._path_left = 0.0  # the path still to travel from the current state [rad]
        self._uses_hold_gap = getattr(self.reward_function, "uses_hold_gap", False)
        # The physics with the patient's condition and the work on the limb.
        self._physics = LimbPhysics(self.scene, config.condition, self.safety.cuff_rows[0],
                                    parts.compliant_ranges_rad, self.frame_skip)
        self.compliant_ranges_rad = parts.compliant_ranges_rad  # (reduced by rom_scale)
        self._goals = parts.goals_rad
        self._goal = self._goals[0][0]
        self._hold_gap = 0.0  # G of StepOutcome.hold_gap

        # -- ids, slices and buffers (resolved once) -----------------------------------------
        layout = self.layout
        self._theta_star, self._p_star = layout.slice("theta_star"), layout.slice("p_star")
        self._theta_obs, self._p_obs = layout.slice("theta"), layout.slice("p")
        self._phi_obs, self._e_obs, self._l_obs = (layout.slice("phi"), layout.index("e"),
                                                   layout.index("l"))
        self._clip_low = self.controller.clip_low.astype(float)
        self._clip_high = self.controller.clip_high.astype(float)
        self._clip_bounds = tuple(zip(self.controller.clip_low.tolist(),
                                      self.controller.clip_high.tolist(), strict=True))
        base = self.handle.base_body_id
        mujoco.mj_kinematics(self.model, self.data)
        self._base_pos = self.data.xpos[base].copy()
        self._base_rot = self.data.xmat[base].reshape(3, 3).copy()
        self._qpos_adr = as_index(self.handle.qpos_adr)
        phi_adr = [int(a) for a in self.scene.exercised_qpos_adr]
        self._phi_block = slice(min(phi_adr), max(phi_adr) + 1)  # read as one slice
        self._phi_pick = tuple(a - min(phi_adr) for a in phi_adr)
        self._dof_adr = as_index(self.handle.dof_adr)
        self._tool_site = self.handle.tool_site_id
        self._exercised_qpos_adr = as_index(self.scene.exercised_qpos_adr)
        self._patient_qpos_adr = as_index(self.scene.patient_qpos_adr)
        n = self._n_joints = self.robot.n_joints
        self._obs = np.zeros(layout.size, np.float32)  # working vector
        # The per-step fields theta, p, phi sit side by side (indices 9-20 of the paper's
        # layout): one write, one bounds check.
        if not (self._theta_obs.stop == self._p_obs.start and self._p_obs.stop ==
                self._phi_obs.start):
            raise AssertionError("the layout must keep theta, p and phi side by side")
        self._dynamic = slice(self._theta_obs.start, self._phi_obs.stop)
        self.set_healthy_box(parts.healthy_low, parts.healthy_high)
        self._static_inside = True  # whether theta*, p*, e and l are in the healthy box
        self._healthy_values: list[float] = []  # theta, p, phi of the last healthy step
        self._base_pos_list = self._base_pos.tolist()
        self._base_rot_cols = self._base_rot.T.tolist()  # p = base_rot^T (x - base_pos)
        self._theta = [0.0] * n  # the last healthy joint angles (a list: six numbers)
        self._target = [0.0] * n  # theta* of the active target
        self._prev_action = np.zeros(n)
        self._keep_previous_action = self.reward_function.uses_previous_action
        self._outcome = StepOutcome(previous_action=self._prev_action)
        self._num_targets = 0
        self._tolerance = self.reward_function.target_tolerance_rad
        self._terminate_on_safety = config.terminate_on_safety
        self._steps = 0
        self._target_index = 0
        self._exercise = 0
        self._sequence = self.targets[0]
        self._needs_reset = True  # before the first reset, after a termination, after close
        self._closed = False
        self._rendering = EnvRendering(self.model, self.render_mode, config.width,
                                       config.height, config.camera_name,
                                       self.max_episode_steps, self.dt_s, self._base_pos,
                                       self._base_rot)
        self._record = self.render_mode is not None
        self._bind_views()
        self._adopt_agent_interface(n_arms=1)
        self.scene.reset_data(self.data)

    # ------------------------------------------------------------------------------------------
    # Gymnasium API
    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._start_episode(seed, options)
        data = self.data
        self.controller.reset(data, self.scene.home_setpoints[0])
        self.safety.reset(data)
        self._physics.reset(data, self.np_random)
        self._prev_action[:] = 0.0
        self._rendering.clear_trace()
        self._record_trace()
        obs = self._obs
        obs[self._e_obs] = self._exercise
        obs[self._l_obs] = self.scene.weight_level
        self._num_targets = len(self._sequence)
        self._write_target()
        self._theta = self._observe() or self._qpos[self._qpos_adr].tolist()
        self._rest = self._remaining_paths[self._exercise]
        self._hold_distance = joint_distance(self._theta, self._target)
        self._path_left = self._hold_distance + self._rest[0]
        if self._uses_hold_gap:
            self._hold_gap = self.reward_function.hold_cost(
                self._hold_distance, self._hold_travel(), self.max_episode_steps)
        info = self._info(None, False, self.safety.cuff_force_n(data),
                          self.reward_function.zero_terms(), 0)
        self._needs_reset = False
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info), info

    def step(self, action):
        if self._needs_reset:
            self._refuse_step()
        data, clipped = self.data, 0
        if self._unit_actions is not None:  # -v2: Box(-1, 1) onto the controller's box
            action, clipped = self._unit_actions.native(action)
        if not self.controller.apply_fast(action):  # a float32 array inside the box: checked
            action, native_clipped = checked_action(action, self.controller.action_space,
                                                    self._clip_low, self._clip_high,
                                                    self._clip_bounds)
            clipped += native_clipped
            self.controller.apply(action, data)
        self._physics.step(self.model, data, self._goal, self.np_random)
        self._steps += 1

        violation, force_n = self.safety.check_step(data)
        obs = self._obs
        if violation != "instability":
            healthy = self._healthy_values
            theta = self._observe()
            if theta is not None:
                self._theta = theta
                if self._record:
                    self._rendering.record(self._tool_xpos)
            else:
                violation = "instability"
                self._healthy_values = healthy
        if violation == "instability":  # keep the last healthy observation and joint angles
            obs[self._dynamic] = self._healthy_values
            force_n = 0.0 if not math.isfinite(force_n) else force_n

        # Distance to the target that was active during the step (six numbers: plain Python).
        squared = largest = 0.0
        for angle, goal in zip(self._theta, self._target, strict=True):
            error = angle - goal
            squared += error * error
            if abs(error) > largest:
                largest = abs(error)
        last = self._target_index == self._num_targets - 1
        safety_stop = violation is not None and (self._terminate_on_safety
                                                 or violation == "instability")
        reached = largest < self._tolerance and not safety_stop
        outcome = self._outcome
        distance = outcome.distance_rad = math.sqrt(squared)
        outcome.hold_distance_rad = self._hold_distance
        # After a switch, holding still costs the distance to the next target.
        switching = reached and not last
        hold = self._hold_distance = (
            joint_distance(self._theta, self._sequence.robot_rad[self._target_index + 1].tolist())
            if switching else distance)
        if self._uses_path:
            outcome.path_left_before_rad = self._path_left
            self._path_left = outcome.path_left_rad = hold + self._rest[
                self._target_index + 1 if switching else self._target_index]
        outcome.reached = reached
        outcome.last_target = last
        outcome.safety_stop = safety_stop
        outcome.steps_done = self._steps
        outcome.action = action
        outcome.hold_gap = self._hold_gap
        terms = self.reward_function(outcome)
        reward = total(terms)
        if self._uses_hold_gap and not safety_stop:
            self._hold_gap = next_hold_gap(self._hold_gap, reward, self.reward_function.hold_cost(
                hold, self._hold_travel(), max(self.max_episode_steps - self._steps, 0)))
        if self._keep_previous_action:
            self._prev_action[:] = action

        terminated, is_success = safety_stop, False
        if reached:
            if last:
                terminated = is_success = True
            else:
                self._target_index += 1
                self._write_target()  # the observation shows the next target
        self._needs_reset = terminated
        info = self._info(violation, is_success, force_n, terms, clipped)
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info), reward, terminated, False, info

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
    def worst_step_reward(self) -> float | None:
        """The per-step loss of the ``"worst_case"`` safety penalty (this patient's bounds);
        None for the progress reward, which has no such penalty."""
        return getattr(self.reward_function, "worst_step_reward", None)

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    def _hold_travel(self) -> float:
        """How far [rad] the joints may still travel if the agent holds still from here
        (:meth:`rehabbot.envs.control.Controller.hold_travel_rad`)."""
        speed = 0.0
        for velocity in self._qvel[self._dof_adr].tolist():
            speed += velocity * velocity
        return self.controller.hold_travel_rad(self._theta, math.sqrt(speed))

    def _write_target(self) -> None:
        """The active target's fields of the observation (theta*, p*)."""
        obs, i = self._obs, self._target_index
        target = self._sequence.robot_rad[i]
        obs[self._theta_star] = target
        obs[self._p_star] = self._sequence.tool_pos_base_m[i]
        self._target = target.tolist()
        self._goal = self._goals[self._exercise][i]
        self._static_inside = self._static_fields_inside()

    def _static_fields_inside(self) -> bool:
        """Whether the fields that change only at reset and target switches (theta*, p*, e,
        l) are in the healthy box; checked when they change, not every step."""
        obs, dynamic = self._obs, self._dynamic
        inside = (obs >= self._healthy_low) & (obs <= self._healthy_high)
        return bool(inside[:dynamic.start].all() and inside[dynamic.stop:].all())

    def _observe(self) -> list[float] | None:
        """Write the fields that change every step (theta, p, phi) into ``self._obs`` (and
        keep them, to restore the last healthy observation); return theta (the robot's joint
        angles, float64) as a list, or None if the observation left the healthy box."""
        qpos = self._qpos
        theta = qpos[self._qpos_adr].tolist()
        block = qpos[self._phi_block].tolist()
        (bx, by, bz), (c0, c1, c2) = self._base_pos_list, self._base_rot_cols
        x, y, z = self._tool_xpos.tolist()
        dx, dy, dz = x - bx, y - by, z - bz
        values = self._healthy_values = [
            *theta, dx * c0[0] + dy * c0[1] + dz * c0[2], dx * c1[0] + dy * c1[1] + dz * c1[2],
            dx * c2[0] + dy * c2[1] + dz * c2[2], *[block[k] for k in self._phi_pick]]
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

    def _info(self, safety_violation, is_success, force_n, terms, clipped) -> dict:
        return {
            "is_success": is_success,
            "target_index": self._target_index,
            "num_targets": self._num_targets,
            "safety_violation": safety_violation,
            **terms,  # reward_distance, reward_bonus, ...
            "interaction_force_n": force_n,
            "robot_torque_nm": self._qfrc_actuator[self._dof_adr].copy(),
            **self._physics.info(),  # patient_torque_nm, patient/robot_work_j, assistance
            "patient_qpos": self._qpos[self._patient_qpos_adr].copy(),
            "exercise": self._exercise,
            "weight_level": self.scene.weight_level,
            "action_clipped": clipped,
            # Safety-Gymnasium's convention: 1.0 in a step where a safety rule fired (also with
            # terminate_on_safety=False), else 0.0; for constrained RL.
            "cost": 0.0 if safety_violation is None else 1.0,
        }

    def _record_trace(self) -> None:
        if self._record:
            self._rendering.record(self._tool_xpos)

    def _bind_views(self) -> None:
        """Cache views of ``self.data``'s arrays (again after unpickling: views do not
        survive a pickle round trip)."""
        data = self.data
        self._qpos = data.qpos
        self._qvel = data.qvel
        self._tool_xpos = data.site_xpos[self._tool_site]  # a view
        self._qfrc_actuator = data.qfrc_actuator
        self.controller.bind(data)
        self.safety.bind(data)
        self._physics.bind(data)
        self._outcome.torque_nm = self._qfrc_actuator[self._dof_adr]  # a view

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()

