"""Assembling a one-arm env from its config: scene, robot limits, targets, controller, spaces,
safety monitor, physics and reward function, each resolved once (:func:`build_parts`, the
parts :class:`rehabbot.envs.core.RehabEnvCore` steps; the two-arm builder,
:mod:`rehabbot.envs.bilateral_build`, resolves the same parts for two robots).

The observation and action spaces depend only on the id's limb, robot, control mode and
exercise table, never on the patient profile or the weight level, so that a policy trained on
one patient runs on another. The tighter, patient-specific box that a healthy observation
stays in (``healthy_low``/``healthy_high``: the setpoint bounds and joint limits of this
patient) is what the instability rule checks.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from gymnasium import spaces

from rehabbot.envs import condition_setup
from rehabbot.envs.config import RehabEnvConfig
from rehabbot.envs.control import (
    SETPOINT_SPACE_MARGIN_RAD,
    Controller,
    ControllerPair,
    make_controller,
)
from rehabbot.sim.handles import RobotHandle
from rehabbot.sim.physics import LimbPhysics, SafetyMonitor
from rehabbot.sim.scene import WEIGHT_LEVELS, Scene
from rehabbot.sim.scene_build import build_scene
from rehabbot.tasks import feasibility
from rehabbot.tasks.observation import (
    PHI_OBS_MARGIN_RAD,
    POSITION_BOUND_M,
    ObservationLayout,
    paper_layout,
)
from rehabbot.tasks.reward import PaperReward, ProgressReward, Reward, remaining_path_rad
from rehabbot.tasks.targets import TargetSequence, build_targets
from rehabbot.tasks.workspace import setpoint_bounds

JOINT_LIMIT_MARGIN_RAD = 0.3  # robot joint limits = setpoint bounds +- this
THETA_OBS_MARGIN_RAD = 0.3  # a healthy theta stays within the joint limits +- this
ROBOT_LIMIT_SOLREF = (0.004, 1.0)  # stiff joint limits (2 x the physics step)


@dataclass
class EnvParts:
    """What a builder resolved for one env (one arm: :func:`build_parts`; two:
    :func:`rehabbot.envs.bilateral_build.build_bilateral_parts`). Per-arm arrays hold every
    arm's values side by side, the right arm's first."""

    scene: Scene
    handles: tuple[RobotHandle, ...]  # one per arm
    setpoint_low_rad: np.ndarray
    setpoint_high_rad: np.ndarray
    joint_low_rad: np.ndarray  # the robots' joint limits in the model
    joint_high_rad: np.ndarray
    targets: tuple[TargetSequence, ...]
    controller: Controller | ControllerPair
    layout: ObservationLayout
    observation_space: spaces.Box
    healthy_low: np.ndarray  # float32
    healthy_high: np.ndarray  # float32
    safety: SafetyMonitor
    physics: LimbPhysics
    reward: Reward
    unusable_levels: dict[int, str]
    exercise_table: tuple  # the exercises as done (key poses scaled by the condition's rom_scale)
    # One arm: the compliant joints' ranges (n_compliant, 2), reduced by the condition's
    # rom_scale, and per exercise, per target, their angles [rad] (what an active patient aims
    # for); None for two arms (the bilateral patient is healthy and passive).
    compliant_ranges_rad: np.ndarray | None = None
    goals_rad: tuple | None = None


def limit_robot_joints(scene: Scene, handle: RobotHandle, low_rad: np.ndarray,
                       high_rad: np.ndarray) -> None:
    """Set the robot's joint limits in the model (a safety-configured range, stiff), never
    beyond the joints' hardware ranges."""
    model = scene.model
    jnt = model.dof_jntid[handle.dof_adr]
    model.jnt_range[jnt, 0] = np.maximum(low_rad, handle.robot.joint_low_rad())
    model.jnt_range[jnt, 1] = np.minimum(high_rad, handle.robot.joint_high_rad())
    model.jnt_solref[jnt] = ROBOT_LIMIT_SOLREF


def observation_bounds(config: RehabEnvConfig, layout: ObservationLayout, scene: Scene,
                       handle: RobotHandle) -> tuple[np.ndarray, np.ndarray]:
    """The observation space's bounds: the same for every patient of an id."""
    model = scene.model
    robot = handle.robot
    target_low = robot.joint_low_rad() - SETPOINT_SPACE_MARGIN_RAD
    target_high = robot.joint_high_rad() + SETPOINT_SPACE_MARGIN_RAD
    theta_low = target_low - JOINT_LIMIT_MARGIN_RAD - THETA_OBS_MARGIN_RAD
    theta_high = target_high + JOINT_LIMIT_MARGIN_RAD + THETA_OBS_MARGIN_RAD
    ex_jnt = [model.joint(n).id for n in scene.exercised_joints]
    phi_low = model.jnt_range[ex_jnt, 0] - PHI_OBS_MARGIN_RAD
    phi_high = model.jnt_range[ex_jnt, 1] + PHI_OBS_MARGIN_RAD
    n_exercises = len(config.exercise_table)
    low = layout.assemble({"theta_star": target_low, "p_star": -POSITION_BOUND_M,
                           "theta": theta_low, "p": -POSITION_BOUND_M, "phi": phi_low,
                           "e": 0, "l": 0})
    high = layout.assemble({"theta_star": target_high, "p_star": POSITION_BOUND_M,
                            "theta": theta_high, "p": POSITION_BOUND_M, "phi": phi_high,
                            "e": n_exercises - 1, "l": max(WEIGHT_LEVELS)})
    return low, high


def build_parts(config: RehabEnvConfig) -> EnvParts:
    """Build the scene and everything the env needs from it; refuse (``ValueError``) a
    patient who cannot do the exercises there."""
    scene = build_scene(config.preset, profile=config.profile,
                        weight_level=config.weight_level or 0, **config.scene_options())
    handle = scene.robots[0]
    model = scene.model
    setpoint_low, setpoint_high = setpoint_bounds(scene, config.limb)
    joint_low = np.maximum(setpoint_low - JOINT_LIMIT_MARGIN_RAD, handle.robot.joint_low_rad())
    joint_high = np.minimum(setpoint_high + JOINT_LIMIT_MARGIN_RAD,
                            handle.robot.joint_high_rad())
    limit_robot_joints(scene, handle, joint_low, joint_high)
    condition = config.condition
    condition_setup.scale_passive(scene, condition)
    condition_setup.scale_strength(scene, condition)
    exercises = condition_setup.scaled_exercises(scene, config.exercise_table, condition)

    targets = tuple(
        build_targets(scene, exercise, config.task_type, segment_s=config.segment_s,
                      waypoint_dt_s=config.waypoint_dt_s,
                      min_spacing_rad=config.min_waypoint_spacing_rad)
        for exercise in exercises)
    controller = make_controller(config.control_mode, handle, setpoint_low, setpoint_high,
                                 config.dt_s, config.max_speed_rad_s)
    controller.configure(model)

    layout = paper_layout(handle.n_joints)
    low, high = observation_bounds(config, layout, scene, handle)
    observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                   (layout.size,), np.float32)
    # The patient-specific box a healthy observation stays in (the instability rule).
    healthy_low, healthy_high = low.copy(), high.copy()
    theta, theta_star = layout.slice("theta"), layout.slice("theta_star")
    healthy_low[theta_star], healthy_high[theta_star] = setpoint_low, setpoint_high
    healthy_low[theta] = joint_low - THETA_OBS_MARGIN_RAD
    healthy_high[theta] = joint_high + THETA_OBS_MARGIN_RAD
    if np.any(healthy_low < low) or np.any(healthy_high > high):
        raise ValueError(f"profile {config.profile}: this scene needs robot angles beyond the "
                         "robot's joint ranges (README, Failure modes)")

    # The condition's reduced ranges (after the observation bounds, which every patient of
    # an id shares): joint limits and the range-of-motion rule follow them.
    ranges = condition_setup.reduced_ranges_rad(scene, condition)
    condition_setup.apply_ranges(scene, ranges)
    safety = SafetyMonitor(scene, config.safety_thresholds())
    # Worst reward one step can pay: the largest distance in the patient's box plus the
    # extra terms' maxima.
    worst_distance = np.maximum(healthy_high[theta] - healthy_low[theta_star],
                                healthy_high[theta_star] - healthy_low[theta])
    remaining = tuple(tuple(remaining_path_rad(seq.robot_rad).tolist()) for seq in targets)
    common = {
        "target_tolerance_rad": config.target_tolerance_rad,
        "intermediate_bonus": config.intermediate_bonus, "final_bonus": config.final_bonus,
        "smoothness_weight": config.smoothness_weight, "effort_weight": config.effort_weight,
        "safety_penalty_steps": config.safety_penalty_steps,
        "max_episode_steps": config.max_episode_steps,
        # The span of the box actions are clipped to (joint_position: the setpoint bounds).
        "action_range": controller.clip_high.astype(float) - controller.clip_low.astype(float),
        "torque_limit_nm": handle.robot.torque_limits(),
    }
    worst_norm = float(np.linalg.norm(worst_distance))
    reward: Reward
    if config.reward.design == "progress":
        # D_cap: no pose in the box is farther from a target, and no target has a longer path
        # after it than the first.
        reward = ProgressReward(progress_weight=config.progress_weight,
                                time_cost=config.time_cost, rests_rad=remaining,
                                path_cap_rad=worst_norm + max(rest[0] for rest in remaining),
                                **common)
    else:
        reward = PaperReward(safety_penalty=config.safety_penalty,
                             worst_step_reward=-(worst_norm + config.smoothness_weight
                                                 + config.effort_weight), **common)

    # Can this patient do these exercises here at all? (fails loudly, once)
    feasibility.check_targets(targets, setpoint_low, setpoint_high, POSITION_BOUND_M,
                              config.profile)
    data = mujoco.MjData(model)
    unusable = {} if not config.terminate_on_safety else feasibility.unusable_levels(
        scene, data, safety, WEIGHT_LEVELS, config.profile)
    for level in config.weight_levels:
        if level in unusable:
            feasibility.refuse(unusable, WEIGHT_LEVELS, level)
    if not condition.is_healthy:
        condition_setup.check_condition_forces(scene, targets, condition, safety.force_limit_n,
                                               config.weight_levels)
    scene.set_weight_level(config.weight_level or 0)
    return EnvParts(scene=scene, handles=(handle,), setpoint_low_rad=setpoint_low,
                    setpoint_high_rad=setpoint_high, joint_low_rad=joint_low,
                    joint_high_rad=joint_high,
                    targets=targets, controller=controller, layout=layout,
                    observation_space=observation_space,
                    healthy_low=healthy_low.astype(np.float32),
                    healthy_high=healthy_high.astype(np.float32), safety=safety,
                    physics=LimbPhysics(scene, condition, safety, ranges, config.frame_skip),
                    reward=reward, unusable_levels=unusable, exercise_table=exercises,
                    compliant_ranges_rad=ranges,
                    goals_rad=condition_setup.goals_rad(scene, targets))
