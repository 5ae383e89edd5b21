"""What the batched env reads from the CPU env, once: every table its step needs, as NumPy
arrays taken from ``gym.make(env_id, **kwargs).unwrapped`` (its config, model, targets,
controller, safety rules, reward and agent observation), so that the two cannot drift.

This module needs only NumPy; :mod:`rehabbot.batch.env` turns the tables into JAX arrays.
What the batched env does not model yet is refused here, with a ``ValueError`` naming the
value (:func:`check_supported`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rehabbot.batch.padding import stack_padded
from rehabbot.envs.control import TORQUE_HOLD_BRAKE_S, TORQUE_HOLD_SAG_RAD
from rehabbot.envs.registration import (
    BILATERAL_IDS,
    CONDITION_VARIANTS,
    POPULATION_VARIANTS,
    V2_IDS,
)
from rehabbot.laws.safety import RULE_CODES  # noqa: F401 (the codes in the batched state)
from rehabbot.sim.patient_drive import PatientDrive
from rehabbot.sim.physics import BLOWUP_FORCE_N, BLOWUP_SPEED_RAD_S
from rehabbot.sim.scene import WEIGHT_LEVELS
from rehabbot.tasks.reward import STOP_MARGIN

# The ids the batched env builds: the single-arm -v2 base ids (a healthy patient, or any
# rigid patient's condition=), and their condition variants (CONDITION_IDS).
SUPPORTED_IDS: tuple[str, ...] = (
    "rehabbot/rehab-reach-v2",
    "rehabbot/rehab-reach-l-v2",
    "rehabbot/rehab-hip-v2",
    "rehabbot/rehab-knee-v2",
)
# The condition variants of those ids (rigid patient: rehabbot.batch.patient_drive): spastic,
# tremor, active, weak, stiff and resistive limbs.
CONDITION_IDS: tuple[str, ...] = tuple(
    env_id for env_id, (base_id, _condition, _text) in CONDITION_VARIANTS.items()
    if env_id.endswith("-v2") and base_id in SUPPORTED_IDS)
# The population ids batched and parity-tested (a patient of a population per world and
# episode: rehabbot.batch.patient_stack): the reach's and the knee's; the left arm's and the hip's
# population ids run on the CPU env only.
POPULATION_IDS: tuple[str, ...] = tuple(
    env_id for env_id, base_id in POPULATION_VARIANTS.items()
    if env_id.endswith("-v2") and base_id in ("rehabbot/rehab-reach-v2",
                                              "rehabbot/rehab-knee-v2"))
# The two-arm id: two robots, one on each hand (the bilateral exercise table).
BILATERAL_ID = "rehabbot/rehab-bilateral-v2"
# Every id the batched env builds.
BATCHED_IDS: tuple[str, ...] = SUPPORTED_IDS + CONDITION_IDS + POPULATION_IDS + (BILATERAL_ID,)
# The control modes the batched env builds.
CONTROL_MODES: tuple[str, ...] = ("joint_delta", "joint_position", "joint_velocity", "torque")
# The control modes the two-arm env is batched in (parity-tested).
TWO_ARM_CONTROL_MODES: tuple[str, ...] = ("joint_delta", "joint_position", "joint_velocity",
                                          "torque")


@dataclass(frozen=True)
class EnvTables:
    """The CPU env's tables for one batched env (float64 NumPy arrays, int index arrays).

    Shapes: ``n`` robot joints, ``E`` exercises, ``T`` targets of the longest exercise (the
    shorter ones are padded with their last target).
    """

    env_id: str
    frame_skip: int
    max_episode_steps: int
    weight_level: int | None  # fixed by the config, or None: drawn at every reset
    exercise: int | None  # fixed by the config, or None: drawn at every reset
    # the controller (every control mode) and the -v2 unit actions
    control_mode: str
    controller_dt_s: float  # joint_velocity: setpoint += this x the native action
    torque_limit_nm: np.ndarray  # (n,) torque mode: motor torque = limit x native action
    hold_sag_rad: float  # torque mode: what a hold may still travel, at rest ...
    hold_brake_s: float  # ... plus the joints' speed times this
    servo_ids: np.ndarray  # (n,) actuator ids of the servos
    motor_ids: np.ndarray  # (n,) actuator ids of the feed-forward motors
    action_center: np.ndarray  # (n,) native action = center + half * unit action
    action_half: np.ndarray
    setpoint_low_rad: np.ndarray  # (n,) the controller's setpoint bounds
    setpoint_high_rad: np.ndarray
    # the home state at this weight level
    home_qpos: np.ndarray  # (nq,)
    home_setpoints_rad: np.ndarray  # (levels, n) clipped to the bounds, as the controller does
    # the paper observation
    arms: int  # robots (1, or 2 for the bilateral id); n counts every arm's joints
    qpos_adr: np.ndarray  # (n,) robot joints in qpos
    dof_adr: np.ndarray  # (n,) robot joints in qvel
    tool_sites: np.ndarray  # (arms,)
    base_pos_m: np.ndarray  # (arms, 3) each robot's base in the world
    base_rot_t: np.ndarray  # (arms, 3, 3) R^T: p = R^T (x - base)
    phi_adr: np.ndarray  # (3,) the exercised patient joints in qpos
    healthy_low: np.ndarray  # (23,) float32 box of a healthy paper observation
    healthy_high: np.ndarray
    paper_slices: dict[str, tuple[int, int]]  # the paper observation's fields
    # targets
    targets_rad: np.ndarray  # (E, T, n)
    tool_targets_m: np.ndarray  # (E, T, 3 arms) p* in each robot's base frame
    num_targets: np.ndarray  # (E,)
    rests_rad: np.ndarray  # (E, T) path after target i (the progress reward's rest)
    target_tolerance_rad: float
    # reward (ProgressReward, the "hold" safety penalty over every step left)
    progress_weight: float
    time_cost: float
    intermediate_bonus: float
    final_bonus: float
    stop_margin: float
    # the two-arm reward's sync term: each arm's length of the segment ending at each target
    # (E, T, arms; zeros for one arm), its weight and tolerance (0 weight: no term)
    segments_rad: np.ndarray
    sync_weight: float
    sync_tolerance: float
    # the optional terms: smoothness (the native action's change over its range) and effort
    # (the robot's actuator torques over their limits), 0: off
    smoothness_weight: float
    effort_weight: float
    reward_action_range: np.ndarray  # (n,)
    reward_torque_limit_nm: np.ndarray  # (n,)
    # safety
    terminate_on_safety: bool
    patient_qpos_adr: np.ndarray
    rom_low_rad: np.ndarray
    rom_high_rad: np.ndarray
    cuff_rows: np.ndarray  # (arms,) each cuff's first constraint row
    patient_cuff_sites: np.ndarray  # (arms,) the patient's side of each cuff (work meters)
    cuff_force_limits_n: np.ndarray  # (arms,)
    contact_tolerance_m: float
    is_robot_geom: np.ndarray  # (ngeom,) bool
    is_other_geom: np.ndarray  # (ngeom,) bool: patient or furniture
    robot_of_geom: np.ndarray  # (ngeom,) the robot a geom belongs to, -1: none
    robots_collide: bool  # a contact between two robots' geoms is unintended contact
    blowup_speed_rad_s: float
    blowup_force_n: float
    # the -v2 agent observation: v = matrix @ [paper | next | setpoint | qvel | force | 1]
    agent_matrix: np.ndarray
    tanh_stop: int
    bounded_start: int
    bounded_low: np.ndarray
    bounded_high: np.ndarray
    exercise_start: int
    progress_index: int


def check_id(env_id: str) -> None:
    """``ValueError`` (naming it) for an id the batched env does not build yet: checked before
    the CPU env is made (a ``-myo-`` id would need MyoSuite's models first)."""
    if env_id in BILATERAL_IDS and env_id != BILATERAL_ID:
        raise ValueError(f"env_id={env_id!r}: of the bilateral ids only {BILATERAL_ID!r} is "
                         "batched")
    if env_id not in BATCHED_IDS:
        kind = "a -v2 id that" if env_id in V2_IDS else "an id that"
        raise ValueError(f"env_id={env_id!r} is {kind} the batched env does not build yet; "
                         f"it builds {list(BATCHED_IDS)}")


def check_supported(env_id: str, env: Any) -> None:
    """``ValueError`` (naming the value) for what the batched env does not build yet."""
    check_id(env_id)
    config = env.config
    checks = (
        ("observation", config.observation, "agent"),
        ("action_scale", config.action_scale, "unit"),
        ("reward", config.reward.design, "progress"),
        ("safety_penalty", config.reward.safety_penalty, "hold"),
        ("safety_penalty_steps", config.reward.safety_penalty_steps, None),
        ("patients", getattr(config, "patients", None), None),
        ("randomization", getattr(config, "randomization", None), None),
        ("patient_model", env.scene.patient_model, "rigid"),
    )
    for name, value, wanted in checks:
        if value != wanted:
            raise ValueError(f"{name}={value!r} is not batched yet (only {wanted!r})")
    if config.control_mode not in CONTROL_MODES:
        raise ValueError(f"control_mode={config.control_mode!r} is not batched yet (only "
                         f"{list(CONTROL_MODES)})")
    physics = env.physics
    if physics.muscles is not None or not isinstance(physics.drive, PatientDrive | None):
        raise ValueError(f"condition={config.condition!r}: only the rigid patient's "
                         "conditions are batched (not muscles' excitations)")
    if len(env.handles) != 1 and config.control_mode not in TWO_ARM_CONTROL_MODES:
        raise ValueError(f"control_mode={config.control_mode!r}: the two-arm env is batched in "
                         f"{list(TWO_ARM_CONTROL_MODES)} only yet")
    # The contact rule reads the contacts through their constraint rows, which MuJoCo Warp
    # makes for contacts closer than margin - gap: every contact deeper than the tolerance
    # has rows when no geom has a gap.
    gaps = np.flatnonzero(env.model.geom_gap > 0)
    if gaps.size:
        raise ValueError(f"geoms {gaps.tolist()} have a contact gap (geom_gap > 0), which the "
                         "batched contact rule does not read yet")


def _home_setpoints(env: Any) -> np.ndarray:
    """The home setpoints at every weight level ``(levels, n)``, clipped to the controller's
    bounds. The CPU env's scene is put back at its level afterwards."""
    scene = env.scene
    start = scene.weight_level
    homes = []
    for level in WEIGHT_LEVELS:
        scene.set_weight_level(level)
        homes.append(np.concatenate([
            np.clip(scene.home_setpoints[k], arm.low_rad, arm.high_rad)
            for k, arm in enumerate(arm_controllers(env.controller))]))
    scene.set_weight_level(start)
    return np.stack(homes)


def arm_controllers(controller: Any) -> tuple[Any, ...]:
    """Each arm's controller (a :class:`~rehabbot.envs.control.ControllerPair`'s two, or the
    one)."""
    return tuple(getattr(controller, "controllers", (controller,)))


def _rotation_t(frame: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The CPU env's base frame (origin, then R^T row by row) as arrays."""
    values = np.asarray(frame, dtype=float)
    return values[:3], values[3:].reshape(3, 3)


def read_tables(env_id: str, env: Any) -> EnvTables:
    """Every table of the batched env, from the CPU env ``env`` (``gym.make(...).unwrapped``,
    freshly made: its scene at the config's weight level), but the model, which
    :mod:`rehabbot.batch.patient_stack` reads per patient and weight level. Refuses what is not
    built yet."""
    check_supported(env_id, env)
    if env.config.weight_level is None and env.unusable_weight_levels:
        raise ValueError(f"weight levels {sorted(env.unusable_weight_levels)} are unusable "
                         "for this patient and weight_level=None would draw them; fix "
                         "weight_level")
    homes = _home_setpoints(env)
    config, scene, safety, agent = env.config, env.scene, env.safety, env.agent_observation_map
    controller, handles, reward = env.controller, env.handles, env.reward_function
    arms = len(handles)
    per_arm = arm_controllers(controller)
    sequences = env.targets
    count = max(len(s.robot_rad) for s in sequences)
    targets = stack_padded([s.robot_rad for s in sequences], count)
    tools = stack_padded([s.tool_pos_base_m[:, :3 * arms] for s in sequences], count)
    lengths = [len(s.robot_rad) for s in sequences]
    rests = stack_padded([reward.rests_rad[e][:k] for e, k in enumerate(lengths)], count, 0.0)
    segments = (stack_padded([reward.segments_rad[e][:k] for e, k in enumerate(lengths)],
                             count, 0.0) if arms > 1
                else np.zeros((len(sequences), count, arms)))
    frames = [_rotation_t(frame) for frame in env.robot_base_frames]
    unit = env.unit_actions
    rom_low, rom_high = safety.rom_bounds_rad
    low = np.concatenate([arm.low_rad for arm in per_arm])
    high = np.concatenate([arm.high_rad for arm in per_arm])
    return EnvTables(
        env_id=env_id, frame_skip=int(config.frame_skip),
        max_episode_steps=int(env.max_episode_steps), weight_level=config.weight_level,
        exercise=config.exercise,
        control_mode=config.control_mode, controller_dt_s=float(per_arm[0].dt_s),
        torque_limit_nm=np.concatenate([np.asarray(h.robot.torque_limits(), dtype=float)
                                        for h in handles]),
        hold_sag_rad=float(TORQUE_HOLD_SAG_RAD), hold_brake_s=float(TORQUE_HOLD_BRAKE_S),
        servo_ids=np.concatenate([np.asarray(h.servo_ids, dtype=int) for h in handles]),
        motor_ids=np.concatenate([np.asarray(h.motor_ids, dtype=int) for h in handles]),
        action_center=np.asarray(unit.center, dtype=float),
        action_half=np.asarray(unit.half_range, dtype=float),
        setpoint_low_rad=np.asarray(low, dtype=float),
        setpoint_high_rad=np.asarray(high, dtype=float),
        home_qpos=np.asarray(scene.home_qpos, dtype=float),
        home_setpoints_rad=homes,
        arms=arms,
        qpos_adr=np.concatenate([np.asarray(h.qpos_adr, dtype=int) for h in handles]),
        dof_adr=np.concatenate([np.asarray(h.dof_adr, dtype=int) for h in handles]),
        tool_sites=np.asarray([h.tool_site_id for h in handles], dtype=int),
        base_pos_m=np.stack([pos for pos, _rot in frames]),
        base_rot_t=np.stack([rot for _pos, rot in frames]),
        phi_adr=np.asarray(scene.exercised_qpos_adr, dtype=int),
        healthy_low=np.asarray(env.healthy_obs_low, dtype=np.float32),
        healthy_high=np.asarray(env.healthy_obs_high, dtype=np.float32),
        paper_slices={name: (env.layout.slice(name).start, env.layout.slice(name).stop)
                      for name in ("theta_star", "p_star", "theta", "p", "phi", "e", "l")},
        targets_rad=targets, tool_targets_m=tools,
        num_targets=np.asarray([len(s.robot_rad) for s in sequences], dtype=int),
        rests_rad=rests, target_tolerance_rad=float(config.target_tolerance_rad),
        progress_weight=float(reward.progress_weight), time_cost=float(reward.time_cost),
        intermediate_bonus=float(reward.intermediate_bonus),
        final_bonus=float(reward.final_bonus), stop_margin=float(STOP_MARGIN),
        segments_rad=segments, sync_weight=float(getattr(reward, "sync_weight", 0.0)),
        sync_tolerance=float(getattr(reward, "sync_tolerance", 0.0)),
        smoothness_weight=float(reward.smoothness_weight),
        effort_weight=float(reward.effort_weight),
        reward_action_range=np.asarray(reward.action_range, dtype=float),
        reward_torque_limit_nm=np.asarray(reward.torque_limit_nm, dtype=float),
        terminate_on_safety=bool(config.terminate_on_safety),
        patient_qpos_adr=np.asarray(scene.patient_qpos_adr, dtype=int),
        rom_low_rad=np.asarray(rom_low, dtype=float),
        rom_high_rad=np.asarray(rom_high, dtype=float),
        cuff_rows=np.asarray(safety.cuff_rows, dtype=int),
        patient_cuff_sites=np.asarray([h.patient_cuff_site_id for h in handles], dtype=int),
        cuff_force_limits_n=np.asarray(safety.force_limits_n, dtype=float),
        contact_tolerance_m=float(safety.thresholds.contact_tolerance_m),
        is_robot_geom=np.asarray(safety.robot_geom_mask, dtype=bool),
        is_other_geom=np.asarray(safety.other_geom_mask, dtype=bool),
        robot_of_geom=safety.robot_of_geom, robots_collide=safety.robots_collide,
        blowup_speed_rad_s=float(BLOWUP_SPEED_RAD_S), blowup_force_n=float(BLOWUP_FORCE_N),
        agent_matrix=np.asarray(agent.matrix, dtype=float), tanh_stop=int(agent.tanh_stop),
        bounded_start=int(agent.bounded.start),
        bounded_low=np.asarray(agent.bounded_low, dtype=float),
        bounded_high=np.asarray(agent.bounded_high, dtype=float),
        exercise_start=int(agent.exercise_start), progress_index=int(agent.progress),
    )
