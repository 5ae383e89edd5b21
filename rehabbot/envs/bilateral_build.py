"""Assembling a bilateral env from its config: the two-robot scene, each arm's setpoint bounds,
joint limits and controller, the targets of every (exercise, pattern), the spaces, the safety
monitor (both cuffs, robot-robot contact), the physics and the reward, each resolved once: the
parts of :class:`rehabbot.envs.build.EnvParts` that the env core steps.

Per arm everything is what a one-arm env of the same robot and patient would use, computed on
an arm view of the scene (:func:`rehabbot.tasks.bilateral.arm_view`); the spaces are the two
arms' side by side (right first), so that they depend only on the robot, the control mode and
the exercise table, never on the patient.
"""

from __future__ import annotations

import mujoco
import numpy as np
from gymnasium import spaces

from rehabbot.envs.bilateral_config import BilateralEnvConfig
from rehabbot.envs.build import (
    JOINT_LIMIT_MARGIN_RAD,
    THETA_OBS_MARGIN_RAD,
    EnvParts,
    limit_robot_joints,
    observation_bounds,
)
from rehabbot.envs.control import ControllerPair, make_controller
from rehabbot.sim.physics import LimbPhysics, SafetyMonitor
from rehabbot.sim.scene import WEIGHT_LEVELS, Scene
from rehabbot.sim.scene_build import build_scene
from rehabbot.tasks import feasibility
from rehabbot.tasks.bilateral import ARMS, arm_view, build_bilateral_targets, segment_lengths_rad
from rehabbot.tasks.observation import POSITION_BOUND_M, paper_layout
from rehabbot.tasks.reward import BilateralReward
from rehabbot.tasks.targets import TargetSequence
from rehabbot.tasks.workspace import (
    WORKSPACE_MARGIN_RAD,
    workspace_grid_deg,
    workspace_robot_angles,
)

# Collision bit that only the two robots of a bilateral scene share: the left robot's geoms
# get it in their contype, the right robot's in their conaffinity, so the robots collide with
# each other (and not with themselves); the safety monitor counts such a contact.
ROBOT_PAIR_BIT = 4


def let_robots_collide(scene: Scene) -> None:
    """Give the two robots of ``scene`` a collision bit of their own (:data:`ROBOT_PAIR_BIT`)."""
    model = scene.model
    right, left = scene.robots
    colliding = model.geom_contype != 0
    left_ids = left.geom_ids[colliding[left.geom_ids]]
    right_ids = right.geom_ids[colliding[right.geom_ids]]
    model.geom_contype[left_ids] |= ROBOT_PAIR_BIT
    model.geom_conaffinity[right_ids] |= ROBOT_PAIR_BIT


def arm_setpoint_bounds(view: Scene) -> tuple[np.ndarray, np.ndarray]:
    """One arm's setpoint bounds: as :func:`rehabbot.tasks.workspace.setpoint_bounds` for a
    one-arm scene (the robot angles holding the arm anywhere in its workspace box)."""
    robot = workspace_robot_angles(view, workspace_grid_deg(view, "arm"))
    return robot.min(axis=0) - WORKSPACE_MARGIN_RAD, robot.max(axis=0) + WORKSPACE_MARGIN_RAD


def _rest_per_arm(sequence: TargetSequence, n_joints: int) -> np.ndarray:
    """(N, 2): each robot's joint-space path from target ``i`` through the later targets."""
    rest = np.zeros((len(sequence), 2))
    for arm in range(2):
        rows = sequence.robot_rad[:, arm * n_joints:(arm + 1) * n_joints]
        steps = np.linalg.norm(np.diff(rows, axis=0), axis=1)
        rest[:-1, arm] = np.cumsum(steps[::-1])[::-1]
    return rest


def build_bilateral_parts(config: BilateralEnvConfig) -> EnvParts:
    """Build the two-robot scene and everything the bilateral env needs; refuse
    (``ValueError``) a patient who cannot do the exercises there."""
    scene = build_scene(config.preset, profile=config.profile,
                        weight_level=config.weight_level or 0, **config.scene_options())
    let_robots_collide(scene)
    n = scene.n_robot_joints
    views = tuple(arm_view(scene, k) for k in range(len(ARMS)))
    controllers, lows, highs, box_lows, box_highs, healthy_lows, healthy_highs = \
        [], [], [], [], [], [], []
    arm_layout = paper_layout(n)
    for k, view in enumerate(views):
        handle = scene.robots[k]
        low, high = arm_setpoint_bounds(view)
        limit_robot_joints(scene, handle, low - JOINT_LIMIT_MARGIN_RAD,
                           high + JOINT_LIMIT_MARGIN_RAD)
        controllers.append(make_controller(config.control_mode, handle, low, high,
                                           config.dt_s, config.max_speed_rad_s))
        box_low, box_high = observation_bounds(config, arm_layout, view, handle)
        healthy_low, healthy_high = box_low.copy(), box_high.copy()
        theta, theta_star = arm_layout.slice("theta"), arm_layout.slice("theta_star")
        healthy_low[theta_star], healthy_high[theta_star] = low, high
        healthy_low[theta] = low - JOINT_LIMIT_MARGIN_RAD - THETA_OBS_MARGIN_RAD
        healthy_high[theta] = high + JOINT_LIMIT_MARGIN_RAD + THETA_OBS_MARGIN_RAD
        if np.any(healthy_low < box_low) or np.any(healthy_high > box_high):
            raise ValueError(f"profile {config.profile}: the {ARMS[k]} robot needs angles "
                             "beyond its joint ranges (README, Failure modes)")
        for out, values in ((lows, low), (highs, high), (box_lows, box_low),
                            (box_highs, box_high), (healthy_lows, healthy_low),
                            (healthy_highs, healthy_high)):
            out.append(values)
    controller = ControllerPair(tuple(controllers))
    controller.configure(scene.model)

    layout = paper_layout(n, n_arms=2)
    n_entries = len(config.bilateral_table)

    def assemble(per_arm: list[np.ndarray], e_bound: float) -> np.ndarray:
        fields = {name: np.concatenate([arm[arm_layout.slice(name)] for arm in per_arm])
                  for name in ("theta_star", "p_star", "theta", "p", "phi")}
        fields["l"] = per_arm[0][arm_layout.slice("l")]
        fields["e"] = e_bound
        return layout.assemble(fields)

    low_obs = assemble(box_lows, 0.0)
    high_obs = assemble(box_highs, n_entries - 1)
    observation_space = spaces.Box(low_obs.astype(np.float32), high_obs.astype(np.float32),
                                   (layout.size,), np.float32)
    healthy_low = assemble(healthy_lows, 0.0).astype(np.float32)
    healthy_high = assemble(healthy_highs, n_entries - 1).astype(np.float32)

    targets = tuple(build_bilateral_targets(scene, exercise, pattern, config.task_type,
                                            segment_s=config.segment_s,
                                            waypoint_dt_s=config.waypoint_dt_s,
                                            min_spacing_rad=config.min_waypoint_spacing_rad)
                    for exercise, pattern in config.bilateral_table)
    setpoint_low, setpoint_high = np.concatenate(lows), np.concatenate(highs)
    feasibility.check_targets(targets, setpoint_low, setpoint_high, POSITION_BOUND_M,
                              config.profile)
    home = np.concatenate([scene.home_qpos[h.qpos_adr] for h in scene.robots])
    lengths = tuple(segment_lengths_rad(seq.robot_rad, home, n) for seq in targets)
    rests = tuple(_rest_per_arm(seq, n) for seq in targets)

    safety = SafetyMonitor(scene, config.safety_thresholds(), robots_collide=True)
    reward = BilateralReward(
        target_tolerance_rad=config.target_tolerance_rad,
        intermediate_bonus=config.intermediate_bonus, final_bonus=config.final_bonus,
        progress_weight=config.progress_weight, time_cost=config.time_cost,
        smoothness_weight=config.smoothness_weight, effort_weight=config.effort_weight,
        safety_penalty_steps=config.safety_penalty_steps,
        max_episode_steps=config.max_episode_steps,
        rests_rad=tuple(tuple(float(row.sum()) for row in rest) for rest in rests),
        path_cap_rad=float(max(rest[0].sum() for rest in rests)),
        action_range=controller.clip_high.astype(float) - controller.clip_low.astype(float),
        torque_limit_nm=np.concatenate([h.robot.torque_limits() for h in scene.robots]),
        sync_weight=config.sync_weight, sync_tolerance=config.sync_tolerance,
        segments_rad=tuple(tuple((float(a), float(b)) for a, b in length)
                           for length in lengths))

    data = mujoco.MjData(scene.model)
    unusable = {} if not config.terminate_on_safety else feasibility.unusable_levels(
        scene, data, safety, WEIGHT_LEVELS, config.profile)
    for level in config.weight_levels:
        if level in unusable:
            feasibility.refuse(unusable, WEIGHT_LEVELS, level)
    scene.set_weight_level(config.weight_level or 0)
    joint_low = np.concatenate([np.maximum(low - JOINT_LIMIT_MARGIN_RAD, h.robot.joint_low_rad())
                                for low, h in zip(lows, scene.robots, strict=True)])
    joint_high = np.concatenate([np.minimum(high + JOINT_LIMIT_MARGIN_RAD,
                                            h.robot.joint_high_rad())
                                 for high, h in zip(highs, scene.robots, strict=True)])
    return EnvParts(scene=scene, handles=tuple(scene.robots), setpoint_low_rad=setpoint_low,
                    setpoint_high_rad=setpoint_high, joint_low_rad=joint_low,
                    joint_high_rad=joint_high,
                    targets=targets, controller=controller, layout=layout,
                    observation_space=observation_space, healthy_low=healthy_low,
                    healthy_high=healthy_high, safety=safety,
                    physics=LimbPhysics(scene, config.condition, safety, None,
                                        config.frame_skip),
                    reward=reward, unusable_levels=unusable,
                    exercise_table=config.bilateral_exercises)
