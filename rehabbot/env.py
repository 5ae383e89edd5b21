"""``RehabEnv``: a UR5e strapped to a patient's hand or leg moves the limb through a therapy
exercise (Gymnasium API). The four registered ids of the paper are this class with different
keyword arguments (:mod:`rehabbot.registration`).

## Description
A seated (arm, knee) or supine (hip) patient, sized from a :class:`PatientProfile`, has one
hand or shank strapped to the cuff of a UR5e. The agent moves the robot's six joints; the
patient's relaxed limb follows the cuff. Each episode runs one of two exercises of the limb
(:data:`rehabbot.exercises.EXERCISES`), defined in the patient's joint space; the robot's
targets are the joint angles that hold the limb at each key pose (reaching) or along a
minimum-jerk path (trajectory following). The agent must reach the targets in order, within
``target_tolerance_rad`` on every joint, without hurting the patient.

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
at the UR5e limits (150 / 28 N·m); setpoints are kept inside the setpoint bounds (the paper's
Table 3 ranges in robot joint space). Other modes (:mod:`rehabbot.control`):
``"joint_position"`` (Box = setpoint bounds, rad), ``"joint_velocity"``
(``Box(-max_speed_rad_s, max_speed_rad_s)``, rad/s), ``"torque"`` (``Box(-1, 1)``, fraction
of each joint's torque limit, added to gravity compensation, servos off). Finite actions
outside the box are clipped (counted in ``info["action_clipped"]``); NaN/inf (the error names
the indices), a wrong shape, or a dtype that is not a real number (bool, complex, str, object)
raise ``ValueError``. float64, integer and list actions are accepted.

## Observation space
``Box(low, high, (23,), float32)``, in the paper's order. Positions are in the robot base
frame (origin on the base's mounting face, z up the base axis, x along the zero of
shoulder_pan).

| index | observation | unit | bounds |
|---|---|---|---|
| 0-5 | theta*: target robot joint angles (pan, lift, elbow, wrist 1-3) | rad | setpoint bounds |
| 6-8 | p*: target tool (flange) position x, y, z, base frame | m | +-1.35 |
| 9-14 | theta: robot joint angles | rad | joint limits +- 0.3 |
| 15-17 | p: tool (flange) position, base frame | m | +-1.35 |
| 18-20 | phi: the patient's exercised joints (shoulder flexion, shoulder abduction, elbow flexion; or hip flexion, hip abduction, knee flexion), flexion positive | rad | anatomical range +- 0.5 |
| 21 | e: exercise (0 or 1) | - | [0, 1] |
| 22 | l: weight level (0..4) | - | [0, 4] |

## Rewards
Eq. (5) of the paper: ``reward_distance = -||theta - theta*_i||_2`` and ``reward_bonus =
B_i`` when ``||theta - theta*_i||_inf < target_tolerance_rad`` (``B_i = intermediate_bonus``,
or ``final_bonus`` for the last target). Optional terms, 0 by default:
``reward_smoothness = -smoothness_weight * mean(((a_t - a_{t-1}) / (high - low))^2)``,
``reward_effort = -effort_weight * mean((tau / tau_limit)^2)``. On a safety termination
(``safety_penalty="hold"``, the default) ``reward_safety = -min(steps left + 1, H) * (this
step's distance + the extra terms' maxima)`` with ``H = safety_penalty_steps`` (default 100 =
1 / (1 - gamma) for the usual gamma = 0.99): what holding still at the current error would
cost an agent that discounts with gamma, so stopping never pays better than holding still.
``safety_penalty_steps=None`` counts every step left until the time limit (a penalty of up to
-1000 x the distance, which dwarfs the discounted values and stops SAC and TD3 from learning;
README, Results). ``safety_penalty="worst_case"`` uses the worst per-step reward that the
observation bounds allow instead of the current distance (up to about -7600 uncapped).
``reward`` is the sum of the ``reward_*`` terms in ``info``.

A profile that cannot do the exercises in its scene (the robot cannot reach the cuff, a target
outside the setpoint bounds, or a home state that already breaks a safety rule at a weight
level the env may use) is refused with a ``ValueError`` when the env is built
(:mod:`rehabbot.feasibility`).

## Starting state
The home posture of the scene (cuff satisfied, static equilibrium), no noise. The exercise and
the weight level are drawn from ``np_random`` unless fixed by the constructor or by
``reset(options={"exercise": e, "weight_level": l})``.

## Episode end
* terminated, success: the last target is reached (``info["is_success"]``);
* terminated, safety: a rule of :mod:`rehabbot.safety` fires (``info["safety_violation"]``):
  ``"instability"``, ``"range_of_motion"``, ``"cuff_force"`` or ``"unintended_contact"``;
* truncated: ``max_episode_steps`` (1000 = 20 s), applied by the registration's ``TimeLimit``.

``step()`` before the first ``reset()`` or after a termination raises
``gymnasium.error.ResetNeeded``; after ``close()`` it raises ``RuntimeError``; ``close()`` twice
is a no-op. An ``"instability"`` always ends the episode (even with
``terminate_on_safety=False``) and returns the last healthy observation; the next ``reset()``
starts from the healthy home state.

## Arguments
| kwarg | default | meaning |
|---|---|---|
| ``limb`` | ``"arm"`` | ``"arm"`` (seated, shoulder + elbow), ``"hip"`` (supine), ``"knee"`` (seated) |
| ``side`` | ``"right"`` | ``"right"`` or ``"left"`` arm / leg |
| ``task_type`` | ``"reaching"`` | ``"reaching"`` (6 key poses) or ``"trajectory"`` (dense min-jerk waypoints) |
| ``control_mode`` | ``"joint_delta"`` | see Action space |
| ``profile`` | ``None`` | :class:`PatientProfile` or a dict of its fields (default 1.75 m, 75 kg, male) |
| ``weight_level`` | ``None`` | fix the weight level 0..4 (limb mass x1.0 .. x2.0); ``None`` draws it |
| ``exercise`` | ``None`` | fix the exercise 0 or 1; ``None`` draws it |
| ``cuff`` | ``"connect"`` | ``"connect"`` (strap: position only) or ``"weld"`` |
| ``base_reorientation_deg`` | 0.0 | rotation of the robot base about its vertical axis |
| ``frame_skip`` | 10 | physics steps per decision |
| ``timestep_s`` | 0.002 | physics step; ``dt = frame_skip * timestep_s`` (0.02 s, 50 Hz) |
| ``target_tolerance_rad`` | 0.05 | epsilon of eq. (5) |
| ``intermediate_bonus`` | 10.0 | B_i for i < N - 1 |
| ``final_bonus`` | 100.0 | B_{N-1} |
| ``smoothness_weight`` | 0.0 | weight of ``reward_smoothness`` |
| ``effort_weight`` | 0.0 | weight of ``reward_effort`` |
| ``terminate_on_safety`` | True | end the episode (with the penalty) when a safety rule fires; if False the rule is only reported |
| ``safety_penalty`` | ``"hold"`` | ``"hold"`` (steps left x current per-step loss) or ``"worst_case"`` (steps left x worst per-step loss); see Rewards |
| ``safety_penalty_steps`` | 100 | count at most this many steps in the safety penalty (None: all steps left until the time limit); see Rewards |
| ``rom_tolerance_deg`` | 2.0 | range-of-motion rule: allowed excess beyond the anatomical range |
| ``cuff_force_limit_n`` | None | cuff force rule: limit in N (None = ISO/TS 15066 quasi-static limit of the strapped region) |
| ``contact_tolerance_m`` | 0.002 | contact rule: penetration that counts as contact |
| ``max_episode_steps`` | 1000 | horizon used by the safety penalty (the registration's TimeLimit uses the same). ``gym.make(id, max_episode_steps=m)`` takes the name for its TimeLimit and never passes it to the env, which keeps 1000: with the default ``safety_penalty_steps=100`` this only over-counts the penalty in the last 100 steps before m. Build ``TimeLimit(RehabEnv(..., max_episode_steps=m), m)`` to change both |
| ``segment_s`` | 3.0 | trajectory: duration of each min-jerk segment between key poses |
| ``waypoint_dt_s`` | 0.1 | trajectory: sampling period of the min-jerk path |
| ``min_waypoint_spacing_rad`` | 0.1 | trajectory: minimum distance (inf-norm, robot joints) between waypoints |
| ``max_speed_rad_s`` | 0.5 | ``joint_velocity`` mode: action bound |
| ``render_mode`` | None | ``"human"``, ``"rgb_array"`` or ``"depth_array"`` |
| ``width``, ``height`` | 640, 480 | image size in pixels |
| ``camera_name`` | ``"overview"`` | ``"overview"``, ``"front"``, ``"side"`` or None (free camera) |

``depth_array`` images hold the distance from the camera in metres; pixels that see no geometry
hold the camera's far-plane distance.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import threading
import time
from typing import ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from rehabbot import exercises as ex
from rehabbot import feasibility, overlay
from rehabbot.control import CONTROL_MODES, as_index, make_controller
from rehabbot.models import robot as ur
from rehabbot.models.patient import PatientProfile
from rehabbot.models.scene import (
    CAMERA_NAMES,
    SIDES,
    WEIGHT_LEVELS,
    SceneOptions,
    build_scene,
    check_weight_level,
)
from rehabbot.safety import SafetyMonitor, SafetyThresholds

OBS_SIZE = 23
THETA_STAR, P_STAR, THETA, P, PHI, E, L = (slice(0, 6), slice(6, 9), slice(9, 15),
                                           slice(15, 18), slice(18, 21), 21, 22)
POSITION_BOUND_M = 1.35  # > the sum of the UR5e's link lengths: no flange position exceeds it
JOINT_LIMIT_MARGIN_RAD = 0.3  # robot joint limits = setpoint bounds +- this
THETA_OBS_MARGIN_RAD = 0.3  # theta bounds = joint limits +- this (soft-limit penetration)
PHI_OBS_MARGIN_RAD = 0.5
SAFETY_PENALTIES = ("hold", "worst_case")
SAFETY_PENALTY_STEPS = 100  # 1 / (1 - gamma) for gamma = 0.99: the horizon of the agent's values
ROBOT_LIMIT_SOLREF = (0.004, 1.0)  # stiff joint limits (2 x the physics step)

_PRESET = {("arm", "right"): "upper_right", ("arm", "left"): "upper_left",
           ("hip", "right"): "hip", ("hip", "left"): "hip",
           ("knee", "right"): "knee", ("knee", "left"): "knee"}


def _check_number(name: str, value, low: float, high: float, integer: bool = False):
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if ok:
        ok = math.isfinite(float(value)) and low <= float(value) <= high
        if integer:
            ok = ok and float(value).is_integer()
    if not ok:
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{name}={value!r} must be {kind} in [{low}, {high}]")
    return int(value) if integer else float(value)


class RehabEnv(gym.Env):
    """A UR5e moves a patient's limb through a therapy exercise (see the module docstring)."""

    metadata: ClassVar[dict] = {"render_modes": ["human", "rgb_array", "depth_array"],
                                "render_fps": 50}

    def __init__(
        self,
        limb: str = "arm",
        side: str = "right",
        task_type: str = "reaching",
        control_mode: str = "joint_delta",
        profile: PatientProfile | dict | None = None,
        weight_level: int | None = None,
        exercise: int | None = None,
        cuff: str = "connect",
        base_reorientation_deg: float = 0.0,
        frame_skip: int = 10,
        timestep_s: float = 0.002,
        target_tolerance_rad: float = 0.05,
        intermediate_bonus: float = 10.0,
        final_bonus: float = 100.0,
        smoothness_weight: float = 0.0,
        effort_weight: float = 0.0,
        terminate_on_safety: bool = True,
        safety_penalty: str = "hold",
        safety_penalty_steps: int | None = SAFETY_PENALTY_STEPS,
        rom_tolerance_deg: float = 2.0,
        cuff_force_limit_n: float | None = None,
        contact_tolerance_m: float = 0.002,
        max_episode_steps: int = 1000,
        segment_s: float = 3.0,
        waypoint_dt_s: float = 0.1,
        min_waypoint_spacing_rad: float = 0.1,
        max_speed_rad_s: float = 0.5,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        camera_name: str | None = "overview",
    ) -> None:
        # -- validate everything before building anything ---------------------------------
        ex.check_choice("limb", limb, ex.LIMBS)
        ex.check_choice("side", side, SIDES)
        ex.check_choice("task_type", task_type, ex.TASK_TYPES)
        ex.check_choice("control_mode", control_mode, CONTROL_MODES)
        if render_mode is not None:
            ex.check_choice("render_mode", render_mode, self.metadata["render_modes"])
        if isinstance(profile, dict):
            fields = [f.name for f in dataclasses.fields(PatientProfile)]
            unknown = sorted(set(profile) - set(fields))
            if unknown:
                raise ValueError(f"profile has unknown field(s) {unknown}; valid: {fields}")
            profile = PatientProfile(**profile)
        elif profile is None:
            profile = PatientProfile()
        elif not isinstance(profile, PatientProfile):
            raise ValueError(f"profile={profile!r} must be a PatientProfile, a dict of its "
                             "fields (height_m, mass_kg, sex) or None")
        if weight_level is not None:
            weight_level = check_weight_level(weight_level)
        if exercise is not None:
            ex.check_choice("exercise", exercise, ex.EXERCISE_IDS)
        self.frame_skip = _check_number("frame_skip", frame_skip, 1, 1000, integer=True)
        self.max_episode_steps = _check_number("max_episode_steps", max_episode_steps, 1, 10**9,
                                               integer=True)
        self.target_tolerance_rad = _check_number("target_tolerance_rad",
                                                  target_tolerance_rad, 1e-6, 1.0)
        self.intermediate_bonus = _check_number("intermediate_bonus", intermediate_bonus,
                                                0.0, 1e6)
        self.final_bonus = _check_number("final_bonus", final_bonus, 0.0, 1e6)
        self.smoothness_weight = _check_number("smoothness_weight", smoothness_weight, 0.0, 1e6)
        self.effort_weight = _check_number("effort_weight", effort_weight, 0.0, 1e6)
        if not isinstance(terminate_on_safety, bool):
            raise ValueError(f"terminate_on_safety={terminate_on_safety!r} must be a bool")
        self.terminate_on_safety = terminate_on_safety
        ex.check_choice("safety_penalty", safety_penalty, SAFETY_PENALTIES)
        self.safety_penalty = safety_penalty
        if safety_penalty_steps is not None:
            safety_penalty_steps = _check_number("safety_penalty_steps", safety_penalty_steps,
                                                 1, 10**9, integer=True)
        self.safety_penalty_steps = safety_penalty_steps
        _check_number("segment_s", segment_s, 0.1, 60.0)
        _check_number("waypoint_dt_s", waypoint_dt_s, 0.01, min(1.0, float(segment_s)))
        _check_number("min_waypoint_spacing_rad", min_waypoint_spacing_rad, 0.0, 1.0)
        _check_number("max_speed_rad_s", max_speed_rad_s, 1e-3, ur.MAX_JOINT_SPEED_RAD_S)
        if camera_name is not None and camera_name not in CAMERA_NAMES:
            raise ValueError(f"camera_name={camera_name!r} is not one of "
                             f"{list(CAMERA_NAMES)} or None")
        thresholds = SafetyThresholds(rom_tolerance_deg=rom_tolerance_deg,
                                      cuff_force_limit_n=cuff_force_limit_n,
                                      contact_tolerance_m=contact_tolerance_m)
        self.width = _check_number("width", width, 1, 8192, integer=True)
        self.height = _check_number("height", height, 1, 8192, integer=True)
        self.render_mode = render_mode

        self.limb, self.side, self.task_type = limb, side, task_type
        self.control_mode = control_mode
        self.profile = profile
        self._fixed_weight_level = weight_level
        self._fixed_exercise = exercise

        scene_options = {"cuff": cuff, "side": None if limb == "arm" else side,
                         "base_reorientation_deg": base_reorientation_deg,
                         "timestep_s": timestep_s}
        SceneOptions(**scene_options)  # raises ValueError naming a bad option

        # -- build -----------------------------------------------------------------------
        self.scene = build_scene(_PRESET[(limb, side)], profile=profile,
                                 weight_level=weight_level or 0, **scene_options)
        self.model = self.scene.model
        self.data = mujoco.MjData(self.model)
        self.handle = self.scene.robots[0]
        model = self.model
        self.camera_name = camera_name
        if render_mode in ("rgb_array", "depth_array"):
            from rehabbot.rendering import check_offscreen_size

            check_offscreen_size(model, self.width, self.height)

        self.setpoint_low_rad, self.setpoint_high_rad = ex.setpoint_bounds(self.scene, limb)
        jnt = model.dof_jntid[self.handle.dof_adr]
        self.joint_low_rad = self.setpoint_low_rad - JOINT_LIMIT_MARGIN_RAD
        self.joint_high_rad = self.setpoint_high_rad + JOINT_LIMIT_MARGIN_RAD
        model.jnt_range[jnt, 0] = self.joint_low_rad
        model.jnt_range[jnt, 1] = self.joint_high_rad
        model.jnt_solref[jnt] = ROBOT_LIMIT_SOLREF

        self.targets = tuple(
            ex.build_targets(self.scene, exercise_def, task_type, segment_s=segment_s,
                             waypoint_dt_s=waypoint_dt_s, min_spacing_rad=min_waypoint_spacing_rad)
            for exercise_def in ex.EXERCISES[limb]
        )
        self.dt_s = self.frame_skip * model.opt.timestep
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.dt_s)}
        self.controller = make_controller(control_mode, self.handle, self.setpoint_low_rad,
                                          self.setpoint_high_rad, self.dt_s, max_speed_rad_s)
        self.controller.configure(model)
        self.action_space = self.controller.action_space
        self._action_low = self.action_space.low.astype(float)
        self._action_high = self.action_space.high.astype(float)
        self._action_range = self._action_high - self._action_low
        self._action_shape = self.action_space.shape
        self._action_low32 = self.action_space.low
        self._action_high32 = self.action_space.high

        # -- observation space -------------------------------------------------------------
        ex_jnt = [model.joint(n).id for n in self.scene.exercised_joints]
        low = np.zeros(OBS_SIZE)
        high = np.zeros(OBS_SIZE)
        low[THETA_STAR], high[THETA_STAR] = self.setpoint_low_rad, self.setpoint_high_rad
        low[P_STAR], high[P_STAR] = -POSITION_BOUND_M, POSITION_BOUND_M
        low[THETA] = self.joint_low_rad - THETA_OBS_MARGIN_RAD
        high[THETA] = self.joint_high_rad + THETA_OBS_MARGIN_RAD
        low[P], high[P] = -POSITION_BOUND_M, POSITION_BOUND_M
        low[PHI] = model.jnt_range[ex_jnt, 0] - PHI_OBS_MARGIN_RAD
        high[PHI] = model.jnt_range[ex_jnt, 1] + PHI_OBS_MARGIN_RAD
        low[E], high[E] = 0, 1
        low[L], high[L] = 0, max(WEIGHT_LEVELS)
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                            (OBS_SIZE,), np.float32)
        self._obs_low32 = self.observation_space.low
        self._obs_high32 = self.observation_space.high

        self.safety = SafetyMonitor(self.scene, thresholds)
        # Worst reward one step can pay: the largest possible distance plus the extra terms.
        worst_distance = np.maximum(high[THETA] - low[THETA_STAR],
                                    high[THETA_STAR] - low[THETA])
        self.worst_step_reward = -(float(np.linalg.norm(worst_distance))
                                   + self.smoothness_weight + self.effort_weight)

        # -- ids and buffers (resolved once) ------------------------------------------------
        base = self.handle.base_body_id
        mujoco.mj_kinematics(model, self.data)
        self._base_pos = self.data.xpos[base].copy()
        self._base_rot = self.data.xmat[base].reshape(3, 3).copy()
        self._qpos_adr = as_index(self.handle.qpos_adr)
        self._dof_adr = as_index(self.handle.dof_adr)
        self._tool_site = self.handle.tool_site_id
        self._exercised_qpos_adr = as_index(self.scene.exercised_qpos_adr)
        self._patient_qpos_adr = as_index(self.scene.patient_qpos_adr)
        self._bind_views()

        # -- can this patient do these exercises here at all? (fails loudly, once) ---------
        feasibility.check_targets(self.targets, self.setpoint_low_rad, self.setpoint_high_rad,
                                  POSITION_BOUND_M, profile)
        self._unusable_levels = {} if not terminate_on_safety else feasibility.unusable_levels(
            self.scene, self.data, self.safety, WEIGHT_LEVELS, profile)
        used = WEIGHT_LEVELS if weight_level is None else (weight_level,)
        for level in used:
            if level in self._unusable_levels:
                feasibility.refuse(self._unusable_levels, WEIGHT_LEVELS, level)
        self.scene.set_weight_level(weight_level or 0)
        self.scene.reset_data(self.data)

        self._obs = np.zeros(OBS_SIZE)
        self._healthy_obs = np.zeros(OBS_SIZE, np.float32)  # the last observation in bounds
        self._theta = np.zeros(6)
        self._prev_action = np.zeros(6)
        self._trace = np.zeros((self.max_episode_steps + 1, 3))
        self._trace_len = 0
        self._steps = 0
        self._target_index = 0
        self._exercise = 0
        self._sequence = self.targets[0]
        self._needs_reset = True  # before the first reset, after a termination, after close
        self._renderer: mujoco.Renderer | None = None
        self._viewer = None
        self._viewer_threads: set[threading.Thread] = set()
        self._last_frame_s = 0.0
        self._closed = False

    # ------------------------------------------------------------------------------------------
    # Gymnasium API
    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"exercise", "weight_level"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; valid: "
                             "['exercise', 'weight_level']")
        drawn_exercise = int(self.np_random.integers(len(ex.EXERCISE_IDS)))
        drawn_level = int(self.np_random.integers(len(WEIGHT_LEVELS)))
        exercise = options.get("exercise", self._fixed_exercise)
        if exercise is None:
            exercise = drawn_exercise
        ex.check_choice("exercise", exercise, ex.EXERCISE_IDS)
        level = options.get("weight_level", self._fixed_weight_level)
        level = drawn_level if level is None else check_weight_level(level)
        if level in self._unusable_levels:
            feasibility.refuse(self._unusable_levels, WEIGHT_LEVELS, level)

        if level != self.scene.weight_level:
            self.scene.set_weight_level(level)
        self._exercise = int(exercise)
        self._sequence = self.targets[self._exercise]
        self._target_index = 0
        self._steps = 0
        data = self.data
        self.scene.reset_data(data)
        self.controller.reset(data, self.scene.home_setpoints[0])
        self.safety.reset(data)
        self._prev_action[:] = 0.0
        self._trace_len = 0
        self._record_trace()
        obs = self._healthy_obs = self._observation()
        self._theta[:] = self._qpos[self._qpos_adr]
        info = self._info(safety_violation=None, is_success=False, force_n=self.safety
                          .cuff_force_n(data), terms=(0.0, 0.0, 0.0, 0.0, 0.0), clipped=0)
        self._needs_reset = False
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        if self._needs_reset:
            self._refuse_step()
        action, clipped = self._check_action(action)
        data = self.data
        self.controller.apply(action, data)
        mujoco.mj_step(self.model, data, nstep=self.frame_skip)
        self._steps += 1

        force_n = self.safety.cuff_force_n(data)
        violation = self.safety.check(data, force_n)
        obs = self._observation() if violation != "instability" else None
        if obs is not None and not self._inside(obs):
            violation = "instability"
            obs = None
        if obs is None:  # keep the last healthy observation and joint angles
            obs = self._healthy_obs.copy()
            force_n = 0.0 if not math.isfinite(force_n) else force_n
        else:
            self._healthy_obs = obs
            self._theta[:] = self._qpos[self._qpos_adr]
            self._record_trace()

        i = self._target_index
        error = self._theta - self._sequence.robot_rad[i]
        reward_distance = -math.sqrt(float(error @ error))
        reached = float(np.maximum.reduce(np.abs(error))) < self.target_tolerance_rad
        reward_smoothness = reward_effort = reward_safety = reward_bonus = 0.0
        if self.smoothness_weight:
            change = (action - self._prev_action) / self._action_range
            reward_smoothness = -self.smoothness_weight * float(change @ change) / 6.0
        if self.effort_weight:
            torque = self._qfrc_actuator[self._dof_adr] / ur.TORQUE_LIMIT_NM
            if np.all(np.isfinite(torque)):
                reward_effort = -self.effort_weight * float(torque @ torque) / 6.0
        self._prev_action[:] = action

        terminated = False
        is_success = False
        if violation is not None and (self.terminate_on_safety or violation == "instability"):
            terminated = True
            steps_left = max(self.max_episode_steps - self._steps, 0) + 1
            if self.safety_penalty_steps is not None:
                steps_left = min(steps_left, self.safety_penalty_steps)
            per_step = (self.worst_step_reward if self.safety_penalty == "worst_case"
                        else reward_distance - self.smoothness_weight - self.effort_weight)
            reward_safety = steps_left * per_step
        elif reached:
            last = i == len(self._sequence) - 1
            reward_bonus = self.final_bonus if last else self.intermediate_bonus
            if last:
                terminated = is_success = True
            else:
                self._target_index += 1
                obs = self._healthy_obs = self._observation()  # the next target
        reward = (reward_distance + reward_bonus + reward_safety + reward_smoothness
                  + reward_effort)
        self._needs_reset = terminated
        info = self._info(violation, is_success, force_n,
                          (reward_distance, reward_bonus, reward_safety, reward_smoothness,
                           reward_effort), clipped)
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, False, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode="
                            "'human', 'rgb_array' or 'depth_array' to the constructor")
            return None
        if self._closed:
            raise RuntimeError("render() called after close()")
        if self.render_mode == "human":
            self._render_human()
            return None
        return self._render_offscreen(depth=self.render_mode == "depth_array")

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
            for thread in self._viewer_threads:
                if thread is not threading.current_thread():
                    thread.join(10.0)
            self._viewer_threads = set()
        self._closed = True
        self._needs_reset = True

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    @property
    def target_index(self) -> int:
        """Index of the active target in the episode's sequence."""
        return self._target_index

    @property
    def exercise(self) -> int:
        """The episode's exercise (0 or 1)."""
        return self._exercise

    @property
    def target_sequence(self) -> ex.TargetSequence:
        """The episode's targets (patient and robot joint space)."""
        return self._sequence

    def _refuse_step(self) -> None:
        if self._closed:
            raise RuntimeError("step() called after close(); make a new env")
        if self._steps == 0:
            raise gym.error.ResetNeeded("step() called before reset(); call env.reset() first")
        raise gym.error.ResetNeeded("step() called after the episode terminated; call "
                                    "env.reset() to start the next one")

    def _check_action(self, action) -> tuple[np.ndarray, int]:
        if type(action) is np.ndarray and action.shape == self._action_shape \
                and action.dtype == np.float32 and np.logical_and.reduce(
                    (action >= self._action_low32) & (action <= self._action_high32)):
            return action.astype(float), 0  # the common case (NaN fails the comparisons)
        try:
            a = np.asarray(action)
        except (TypeError, ValueError) as err:
            raise ValueError(f"action {action!r} cannot be read as {self.action_space.shape} "
                             f"floats: {err}") from None
        if a.dtype.kind not in "iuf":  # no silent casts of bool, complex, str or objects
            raise ValueError(f"action {action!r} has dtype {a.dtype}; expected "
                             f"{self.action_space.shape} real numbers (float32 preferred)")
        a = a.astype(float)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action has shape {a.shape}; expected {self.action_space.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            raise ValueError(f"action has non-finite values at indices "
                             f"{np.flatnonzero(bad).tolist()}: {a.tolist()}")
        clipped_mask = (a < self._action_low) | (a > self._action_high)
        clipped = int(np.count_nonzero(clipped_mask))
        if clipped:
            a = np.clip(a, self._action_low, self._action_high)
        return a, clipped

    def _observation(self) -> np.ndarray:
        obs = self._obs
        qpos = self._qpos
        i = self._target_index
        obs[THETA_STAR] = self._sequence.robot_rad[i]
        obs[P_STAR] = self._sequence.tool_pos_base_m[i]
        obs[THETA] = qpos[self._qpos_adr]
        obs[P] = (self._site_xpos[self._tool_site] - self._base_pos) @ self._base_rot
        obs[PHI] = qpos[self._exercised_qpos_adr]
        obs[E] = self._exercise
        obs[L] = self.scene.weight_level
        return obs.astype(np.float32)

    def _inside(self, obs: np.ndarray) -> bool:
        # NaN fails both comparisons, so this also rejects non-finite values.
        return bool(np.logical_and.reduce((obs >= self._obs_low32) & (obs <= self._obs_high32)))

    def _info(self, safety_violation, is_success, force_n, terms, clipped) -> dict:
        distance, bonus, safety, smoothness, effort = terms
        return {
            "is_success": is_success,
            "target_index": self._target_index,
            "num_targets": len(self._sequence),
            "safety_violation": safety_violation,
            "reward_distance": distance,
            "reward_bonus": bonus,
            "reward_safety": safety,
            "reward_smoothness": smoothness,
            "reward_effort": effort,
            "interaction_force_n": float(force_n),
            "robot_torque_nm": self._qfrc_actuator[self._dof_adr].copy(),
            "patient_qpos": self._qpos[self._patient_qpos_adr].copy(),
            "exercise": self._exercise,
            "weight_level": self.scene.weight_level,
            "action_clipped": clipped,
        }

    def _record_trace(self) -> None:
        if self._trace_len >= len(self._trace):
            self._trace[:-1] = self._trace[1:]
            self._trace_len = len(self._trace) - 1
        self._trace[self._trace_len] = self._site_xpos[self._tool_site]
        self._trace_len += 1

    def _target_world(self, index: int) -> np.ndarray:
        return self._base_pos + self._base_rot @ self._sequence.tool_pos_base_m[index]

    def _decorate(self, scene: mujoco.MjvScene) -> None:
        upcoming = [self._target_world(k) for k in
                    range(self._target_index + 1, len(self._sequence))]
        overlay.draw_task(scene, self._trace[:self._trace_len],
                          self._target_world(self._target_index),
                          np.array(upcoming) if upcoming else None)

    def _render_offscreen(self, depth: bool) -> np.ndarray:
        if self._renderer is None:
            from rehabbot.rendering import check_gl_backend

            check_gl_backend()  # a clear error on a headless machine without MUJOCO_GL=egl
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        renderer = self._renderer
        camera = -1 if self.camera_name is None else self.camera_name
        renderer.update_scene(self.data, camera)
        if depth:
            renderer.enable_depth_rendering()
            image = renderer.render()
            renderer.disable_depth_rendering()
            return image
        self._decorate(renderer.scene)
        return renderer.render()

    def _render_human(self) -> None:
        if self._viewer is None:
            import mujoco.viewer

            if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                         or os.environ.get("WAYLAND_DISPLAY")):
                raise RuntimeError("render_mode='human' opens MuJoCo's viewer, which needs a "
                                   "display (DISPLAY is not set); use render_mode='rgb_array' "
                                   "on a headless machine, or run under xvfb-run")

            before = set(threading.enumerate())
            self._viewer = mujoco.viewer.launch_passive(self.model, self.data,
                                                        show_left_ui=False,
                                                        show_right_ui=False)
            self._viewer_threads = set(threading.enumerate()) - before
            if self.camera_name is not None:
                self._viewer.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
                self._viewer.cam.fixedcamid = self.model.camera(self.camera_name).id
            self._last_frame_s = time.perf_counter()
        viewer = self._viewer
        if not viewer.is_running():
            return
        with viewer.lock():
            viewer.user_scn.ngeom = 0
            self._decorate(viewer.user_scn)
        viewer.sync()
        # Keep to real time: one decision per dt.
        idle_s = self.dt_s - (time.perf_counter() - self._last_frame_s)
        if idle_s > 0:
            time.sleep(idle_s)
        self._last_frame_s = time.perf_counter()

    def _bind_views(self) -> None:
        """Cache views of ``self.data``'s arrays (again after unpickling: views do not
        survive a pickle round trip)."""
        data = self.data
        self._qpos = data.qpos
        self._site_xpos = data.site_xpos
        self._qfrc_actuator = data.qfrc_actuator
        self.controller._ctrl = data.ctrl
        self.safety.bind(data)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_viewer"] = None
        state["_viewer_threads"] = set()
        return state

