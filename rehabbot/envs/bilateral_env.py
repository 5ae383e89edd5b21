"""``BilateralEnv``: two robots, one strapped to each hand of the seated patient, move both arms
through a therapy exercise together or in turns (Gymnasium API). Registered as
``rehabbot/rehab-bilateral-v1`` and, with the agent observation and actions in [-1, 1],
``rehabbot/rehab-bilateral-v2`` (:mod:`rehabbot.envs.registration`).

## Description
The paper's two-arm scene (its Figs. 2-3): the ``upper_bilateral`` preset, a robot on a stand
beside each shoulder, each cuff on its hand. Each episode runs one entry of the bilateral
exercise table: an arm exercise (shoulder or elbow flexion, :data:`rehabbot.tasks.exercises.
EXERCISES`) done with a pattern (:mod:`rehabbot.tasks.bilateral`): ``"symmetric"`` (both arms
through the same key poses at the same time) or ``"alternating"`` (the right arm moves to a
key pose while the left holds, then the left follows). A target is reached when both robots
are within ``target_tolerance_rad`` of it on every joint.

## Action space
Both robots' actions side by side, right robot first: ``control_mode="joint_delta"`` gives
``Box(-pi/400, pi/400, (2 n,), float32)`` (12 values for two UR5e, 14 for two FR3), each half
meaning what a one-arm env's action means (:mod:`rehabbot.envs.rehab_env`), with each robot's
own setpoint bounds. The other control modes likewise. Finite actions outside the box are
clipped (``info["action_clipped"]``); NaN/inf or a wrong shape raise ``ValueError``.

## Observation space
:func:`rehabbot.tasks.observation.paper_layout` with ``n_arms=2``: the paper's per-arm fields
for both arms, right first, then ``e`` and ``l`` (44 values for two UR5e):

| field | values | unit |
|---|---|---|
| theta* | 2 n: the right robot's target joint angles, then the left's | rad |
| p* | 6: each robot's target tool position, in its own base frame | m |
| theta | 2 n: robot joint angles | rad |
| p | 6: tool positions, each in its own base frame | m |
| phi | 6: shoulder flexion, abduction, elbow flexion of the right arm, then the left | rad |
| e | 1: the entry of the bilateral exercise table (:mod:`rehabbot.envs.bilateral_config`) | - |
| l | 1: weight level 0..4 (both arms' masses x1.0 .. x2.0) | - |

The bounds are each arm's one-arm bounds; they do not depend on the patient.

``rehab-bilateral-v2`` (``observation="agent"``, ``action_scale="unit"``): the action is
``Box(-1, 1, (2 n,))``, each half mapped onto its robot's box; the observation is
``Box(-2, 2, (98,))`` for two UR5e (110 for two FR3): the fields of
:mod:`rehabbot.tasks.agent_observation`, each per-arm field right arm first
(``joint_error_fine`` 12, ``joint_error`` 12, ``tool_error_fine`` 6, ``tool_error`` 6,
``next_target`` 12, ``setpoint_lead`` 12, ``joint_velocity`` 12, ``theta_in_bounds`` 12,
``phi_in_range`` 6, ``cuff_force`` 2), then ``exercise`` (one-hot over the 4 entries of the
bilateral table), ``weight_level`` and ``target_progress``. The paper's fields are in
``info["paper_observation"]``.

## Rewards
:mod:`rehabbot.tasks.bilateral_reward`: the ``-v1`` terms with the path summed over both arms
(``reward_progress``, ``reward_bonus``, ``reward_time``, ``reward_safety``, optional
``reward_smoothness``, ``reward_effort``) plus ``reward_sync``, which charges the arms for
moving out of step when both move (``sync_weight``, ``sync_tolerance``). A stop never pays.

## Episode end
Success when both arms reach the last target; a safety stop when a rule of
:mod:`rehabbot.tasks.safety` fires: each cuff against its own ISO/TS 15066 limit (hand, 140 N),
the range of motion of every patient joint, and unintended contact, which includes contact
between the two robots; truncation at ``max_episode_steps`` (the id registers 2000 = 40 s: an
alternating exercise makes every move twice).

## Info
As :class:`rehabbot.envs.rehab_env.RehabEnv`'s (``interaction_force_n`` is the larger cuff
force, ``robot_torque_nm`` both robots', ``robot_work_j`` the two cuffs' work on the arms),
plus ``cuff_forces_n`` (right, left), ``segment_fraction`` (each arm's progress through the
current segment) and ``sync_gap``.

## Arguments
Every argument of :class:`rehabbot.envs.rehab_env.RehabEnv` (the table there) except that
``limb`` must be ``"arm"``, ``side`` is unused, ``reward`` is ``"progress"`` and ``condition``
must be healthy (conditions on both arms are not supported yet); ``exercise`` indexes the
bilateral table. Bilateral arguments:

| kwarg | default | meaning |
|---|---|---|
| ``patterns`` | ``("symmetric", "alternating")`` | the patterns of the table (pattern-major) |
| ``sync_weight`` | 0.5 | cost per step of a whole segment's lag between the arms |
| ``sync_tolerance`` | 0.1 | lag (share of the segment) that costs nothing |

Rendering draws the right robot's tool path and targets.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import mujoco
import numpy as np

from rehabbot.envs.actions import checked_action
from rehabbot.envs.bilateral_build import build_bilateral_parts
from rehabbot.envs.bilateral_config import BilateralEnvConfig
from rehabbot.envs.config import config_from
from rehabbot.envs.env_base import RehabEnvBase
from rehabbot.envs.env_rendering import EnvRendering
from rehabbot.sim.patient_drive import WorkMeter
from rehabbot.tasks.bilateral import arm_view
from rehabbot.tasks.bilateral_reward import segment_fraction, sync_gap
from rehabbot.tasks.reward import StepOutcome, next_hold_gap, total


class BilateralEnv(RehabEnvBase):
    """Two robots move both of a patient's arms through an exercise (module docstring)."""

    config_class: ClassVar[type] = BilateralEnvConfig

    def __init__(self, config: BilateralEnvConfig | None = None, **kwargs: Any) -> None:
        self.config = config = config_from(BilateralEnvConfig, "BilateralEnv", config, kwargs)
        parts = build_bilateral_parts(config)
        self._adopt_parts(parts, config)
        scene = self.scene
        self.handles = scene.robots
        self.robot = scene.robots[0].robot
        self.n_joints_per_robot = n = scene.n_robot_joints
        self.joint_names = tuple(f"{h.prefix}{j}" for h in scene.robots
                                 for j in h.robot.joint_names)
        self.exercises = config.bilateral_exercises
        self._segments = parts.segment_lengths_rad
        self._rests = parts.remaining_paths
        self._healthy_low, self._healthy_high = parts.healthy_low, parts.healthy_high
        self._meters = tuple(WorkMeter(arm_view(scene, k), self.safety.cuff_rows[k])
                             for k in range(2))
        layout = self.layout
        self._theta_star, self._p_star = layout.slice("theta_star"), layout.slice("p_star")
        self._dynamic = slice(layout.slice("theta").start, layout.slice("phi").stop)
        self._e_obs, self._l_obs = layout.index("e"), layout.index("l")
        self._qpos_adr = np.concatenate([h.qpos_adr for h in self.handles])
        self._dof_adr = np.concatenate([h.dof_adr for h in self.handles])
        self._tool_sites = [h.tool_site_id for h in self.handles]
        self._phi_adr = scene.exercised_qpos_adr
        self._patient_qpos_adr = scene.patient_qpos_adr
        mujoco.mj_kinematics(self.model, self.data)
        self._base_pos = np.array([self.data.xpos[h.base_body_id] for h in self.handles])
        self._base_rot = np.array([self.data.xmat[h.base_body_id].reshape(3, 3)
                                   for h in self.handles])
        self._obs = np.zeros(layout.size, np.float32)
        self._dynamic_values = np.zeros(self._dynamic.stop - self._dynamic.start)
        self._prev_action = np.zeros(2 * n)
        self._outcome = StepOutcome(previous_action=self._prev_action)
        self._clip_low = self.controller.clip_low.astype(float)
        self._clip_high = self.controller.clip_high.astype(float)
        self._clip_bounds = tuple(zip(self.controller.clip_low.tolist(),
                                      self.controller.clip_high.tolist(), strict=True))
        self._tolerance = config.target_tolerance_rad
        self._steps = self._target_index = self._exercise = 0
        self._sequence = self.targets[0]
        self._path_left = 0.0
        self._fractions = np.ones(2)
        self._gap = 0.0  # the arms' sync gap in the active target's segment, at this state
        # G of StepOutcome.hold_gap: the most that holding still from a state of the episode
        # could cost beyond what the episode earned since (rehabbot.tasks.reward).
        self._hold_gap = 0.0
        self._uses_hold_gap = self.reward_function.uses_hold_gap
        self._needs_reset = True
        self._closed = False
        self._rendering = EnvRendering(self.model, self.render_mode, config.width,
                                       config.height, config.camera_name,
                                       self.max_episode_steps, self.dt_s, self._base_pos[0],
                                       self._base_rot[0])
        self._record = self.render_mode is not None
        self._bind_views()
        self._adopt_agent_interface(n_arms=2)
        scene.reset_data(self.data)

    # ------------------------------------------------------------------------------------------
    # Gymnasium API
    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._start_episode(seed, options)
        data = self.data
        self.controller.reset(data, self.scene.home_setpoints)
        self.safety.reset(data)
        for meter in self._meters:
            meter.reset(data)
        self._prev_action[:] = 0.0
        self._rendering.clear_trace()
        obs = self._obs
        obs[self._e_obs] = self._exercise
        obs[self._l_obs] = self.scene.weight_level
        self._write_target()
        self._observe()
        self._record_trace()
        distances = self._arm_distances()
        self._path_left = self._path(distances, self._target_index)
        self._fractions[:], self._gap = self._progress_in_segment(distances)
        self._hold_gap = self._hold_cost(distances)
        info = self._info(None, False, self.reward_function.zero_terms(), 0, 0.0)
        self._needs_reset = False
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info), info

    def step(self, action):
        if self._needs_reset:
            self._refuse_step()
        unit_clipped = 0
        if self._unit_actions is not None:  # -v2: Box(-1, 1) onto the controllers' box
            action, unit_clipped = self._unit_actions.native(action)
        action, clipped = checked_action(action, self.controller.action_space, self._clip_low,
                                         self._clip_high, self._clip_bounds)
        clipped += unit_clipped
        data, model = self.data, self.model
        self.controller.apply(action, data)
        for _ in range(self.frame_skip):
            mujoco.mj_step(model, data)
            for meter in self._meters:
                meter.after_step(data)
        self._steps += 1
        violation, _ = self.safety.check_step(data)
        if violation != "instability" and not self._observe():
            violation = "instability"
        elif violation != "instability":
            self._record_trace()
        if violation == "instability":  # keep the last healthy observation
            self._obs[self._dynamic] = self._dynamic_values

        distances = self._arm_distances()
        index, last = self._target_index, self._target_index == len(self._sequence) - 1
        safety_stop = violation is not None and (self.config.terminate_on_safety
                                                 or violation == "instability")
        theta = self._dynamic_values[:2 * self.n_joints_per_robot]
        largest = float(np.max(np.abs(theta - self._sequence.robot_rad[index])))
        reached = largest < self._tolerance and not safety_stop
        switching = reached and not last
        fractions, gap = self._progress_in_segment(distances)
        outcome = self._outcome
        outcome.sync_gap, outcome.sync_gap_before = gap, self._gap
        outcome.path_left_before_rad = self._path_left
        self._gap = gap
        if switching:
            self._target_index += 1
            distances = self._arm_distances()
            self._gap = self._progress_in_segment(distances)[1]
        self._path_left = outcome.path_left_rad = self._path(distances, self._target_index)
        outcome.distance_rad = float(np.linalg.norm(theta - self._sequence.robot_rad[index]))
        outcome.reached, outcome.last_target = reached, last
        outcome.safety_stop, outcome.steps_done = safety_stop, self._steps
        outcome.action, outcome.torque_nm = action, data.qfrc_actuator[self._dof_adr]
        outcome.hold_gap = self._hold_gap
        terms = self.reward_function(outcome)
        reward = total(terms)
        if self._uses_hold_gap and not safety_stop:
            self._hold_gap = next_hold_gap(self._hold_gap, reward, self._hold_cost(distances))
        if self.reward_function.uses_previous_action:
            self._prev_action[:] = action
        self._fractions[:] = fractions
        if switching:
            self._write_target()
        terminated = safety_stop or (reached and last)
        self._needs_reset = terminated
        info = self._info(violation, reached and last, terms, clipped, outcome.sync_gap)
        if self.render_mode == "human":
            self.render()
        return self._observation_out(info), reward, terminated, False, info

    # ------------------------------------------------------------------------------------------
    # Properties
    # ------------------------------------------------------------------------------------------
    @property
    def torque_limits_nm(self) -> np.ndarray:
        """Both robots' joint torque limits [N·m], right first (a new array)."""
        return np.concatenate([h.robot.torque_limits() for h in self.handles])

    @property
    def segment_fractions(self) -> np.ndarray:
        """Each arm's progress through the current segment (a copy)."""
        return self._fractions.copy()

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    def _render_targets(self) -> np.ndarray:
        """The right robot's target tool positions (the rendering draws its path)."""
        return self._sequence.tool_pos_base_m[:, :3]

    def _write_target(self) -> None:
        i = self._target_index
        self._obs[self._theta_star] = self._sequence.robot_rad[i]
        self._obs[self._p_star] = self._sequence.tool_pos_base_m[i]

    def _observe(self) -> bool:
        """Write theta, p and phi of both arms into the observation; False (the observation
        not written) when they are not finite or leave the healthy box."""
        qpos = self._qpos
        tools = [
            self._base_rot[k].T @ (self._site_xpos[site] - self._base_pos[k])
            for k, site in enumerate(self._tool_sites)]
        values = np.concatenate([qpos[self._qpos_adr], *tools, qpos[self._phi_adr]])
        candidate = values.astype(np.float32)
        dynamic = self._dynamic
        inside = (candidate >= self._healthy_low[dynamic]) & \
            (candidate <= self._healthy_high[dynamic])
        if not inside.all():
            return False
        self._dynamic_values[:] = values
        self._obs[dynamic] = candidate
        return True

    def _arm_distances(self) -> np.ndarray:
        """Each robot's joint-space distance [rad] to the active target."""
        n = self.n_joints_per_robot
        theta = self._dynamic_values[:2 * n]
        error = theta - self._sequence.robot_rad[self._target_index]
        return np.array([math.sqrt(float(error[:n] @ error[:n])),
                         math.sqrt(float(error[n:] @ error[n:]))])

    def _hold_cost(self, distances: np.ndarray) -> float:
        """``B(s)`` of the current state (:meth:`BilateralReward.hold_cost`): each arm's joints
        may still travel ``lead`` [rad] while it holds still
        (:meth:`rehabbot.envs.control.Controller.hold_travel_rad`), and the sync gap may grow
        by the share of its segment that each arm's travel covers."""
        if not self._uses_hold_gap:
            return 0.0
        n = self.n_joints_per_robot
        theta = self._dynamic_values[:2 * n].tolist()
        velocity = self.data.qvel[self._dof_adr].reshape(2, n)
        lead = np.array([controller.hold_travel_rad(theta[k * n:(k + 1) * n],
                                                    float(np.linalg.norm(velocity[k])))
                         for k, controller in enumerate(self.controller.controllers)])
        lengths = self._segments[self._exercise][self._target_index]
        moving = lengths > self._tolerance
        gap = 0.0
        if moving.all():
            gap = min(self._gap + float((lead / lengths).sum()), 1.0)
        return self.reward_function.hold_cost(float(distances.sum()), float(lead.sum()),
                                              max(self.max_episode_steps - self._steps, 0), gap)

    def _path(self, distances: np.ndarray, index: int) -> float:
        """The path both arms still have to travel [rad] (the reward's D)."""
        return float(distances.sum() + self._rests[self._exercise][index].sum())

    def _progress_in_segment(self, distances: np.ndarray) -> tuple[np.ndarray, float]:
        """Each arm's share of the active target's segment done and the arms' sync gap."""
        lengths = self._segments[self._exercise][self._target_index]
        fractions = np.array([segment_fraction(float(d), float(length))
                              for d, length in zip(distances, lengths, strict=True)])
        moving = lengths > self._tolerance
        return fractions, sync_gap(fractions[0], fractions[1], bool(moving[0]),
                                   bool(moving[1]), self.reward_function.sync_tolerance)

    def _info(self, violation, is_success, terms, clipped, gap) -> dict:
        forces = self.safety.cuff_forces_n(self.data).copy()
        return {
            "is_success": bool(is_success),
            "target_index": self._target_index,
            "num_targets": len(self._sequence),
            "safety_violation": violation,
            **terms,
            "interaction_force_n": float(forces.max()),
            "cuff_forces_n": forces,
            "robot_torque_nm": self._qfrc_actuator[self._dof_adr].copy(),
            "patient_torque_nm": np.zeros(len(self._phi_adr)),
            "patient_work_j": 0.0,
            "robot_work_j": float(sum(m.robot_j for m in self._meters)),
            "assistance_ratio": 1.0,
            "patient_qpos": self._qpos[self._patient_qpos_adr].copy(),
            "exercise": self._exercise,
            "weight_level": self.scene.weight_level,
            "action_clipped": clipped,
            "segment_fraction": self._fractions.copy(),
            "sync_gap": gap,
            "cost": 0.0 if violation is None else 1.0,
        }

    def _record_trace(self) -> None:
        if self._record:
            self._rendering.record(self._site_xpos[self._tool_sites[0]])

    def _bind_views(self) -> None:
        data = self.data
        self._qpos = data.qpos
        self._site_xpos = data.site_xpos
        self._qfrc_actuator = data.qfrc_actuator
        self.controller.bind(data)
        self.safety.bind(data)
        for meter in self._meters:
            meter.bind(data)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()
