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

from rehabbot.envs.control import TORQUE_HOLD_BRAKE_S, TORQUE_HOLD_SAG_RAD
from rehabbot.envs.registration import (
    BILATERAL_IDS,
    CONDITION_VARIANTS,
    POPULATION_VARIANTS,
    V2_IDS,
)
from rehabbot.sim.patient_drive import PatientDrive
from rehabbot.sim.physics import BLOWUP_FORCE_N, BLOWUP_SPEED_RAD_S, RULES
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
# The condition variants of those ids (rigid patient: rehabbot.batch.patient): spastic,
# tremor, active, weak, stiff and resistive limbs.
CONDITION_IDS: tuple[str, ...] = tuple(
    env_id for env_id, (base_id, _condition, _text) in CONDITION_VARIANTS.items()
    if env_id.endswith("-v2") and base_id in SUPPORTED_IDS)
# The population ids of those ids (a patient of a population per world and episode:
# rehabbot.batch.patients).
POPULATION_IDS: tuple[str, ...] = tuple(
    env_id for env_id, base_id in POPULATION_VARIANTS.items()
    if env_id.endswith("-v2") and base_id in SUPPORTED_IDS)
# Every id the batched env builds.
BATCHED_IDS: tuple[str, ...] = SUPPORTED_IDS + CONDITION_IDS + POPULATION_IDS
# The control modes the batched env builds.
CONTROL_MODES: tuple[str, ...] = ("joint_delta", "joint_position", "joint_velocity", "torque")
# The safety rules' codes in the batched state: 0 for none, then RULES in order (1-based).
RULE_CODES: dict[str, int] = {rule: k + 1 for k, rule in enumerate(RULES)}


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
    qpos_adr: np.ndarray  # (n,) robot joints in qpos
    dof_adr: np.ndarray  # (n,) robot joints in qvel
    tool_site: int
    base_pos_m: np.ndarray  # (3,) robot base in the world
    base_rot_t: np.ndarray  # (3, 3) R^T: p = R^T (x - base)
    phi_adr: np.ndarray  # (3,) the exercised patient joints in qpos
    healthy_low: np.ndarray  # (23,) float32 box of a healthy paper observation
    healthy_high: np.ndarray
    paper_slices: dict[str, tuple[int, int]]  # the paper observation's fields
    # targets
    targets_rad: np.ndarray  # (E, T, n)
    tool_targets_m: np.ndarray  # (E, T, 3) p* in the robot base frame
    num_targets: np.ndarray  # (E,)
    rests_rad: np.ndarray  # (E, T) path after target i (the progress reward's rest)
    target_tolerance_rad: float
    # reward (ProgressReward, the "hold" safety penalty over every step left)
    progress_weight: float
    time_cost: float
    intermediate_bonus: float
    final_bonus: float
    stop_margin: float
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
    cuff_row: int  # the cuff's first constraint row
    patient_cuff_site: int  # the patient's side of the cuff (the work meter's point)
    cuff_force_limit_n: float
    contact_tolerance_m: float
    is_robot_geom: np.ndarray  # (ngeom,) bool
    is_other_geom: np.ndarray  # (ngeom,) bool: patient or furniture
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
    if env_id in BILATERAL_IDS:
        raise ValueError(f"env_id={env_id!r}: the bilateral env is not batched yet")
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
    if len(env.handles) != 1:
        raise ValueError(f"{len(env.handles)} robots: only one-arm scenes are batched yet")
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
    scene, controller = env.scene, env.controller
    start = scene.weight_level
    homes = []
    for level in WEIGHT_LEVELS:
        scene.set_weight_level(level)
        homes.append(np.clip(scene.home_setpoints[0], controller.low_rad, controller.high_rad))
    scene.set_weight_level(start)
    return np.stack(homes)


def _rotation_t(frame: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The CPU env's base frame (origin, then R^T row by row) as arrays."""
    values = np.asarray(frame, dtype=float)
    return values[:3], values[3:].reshape(3, 3)


def read_tables(env_id: str, env: Any) -> EnvTables:
    """Every table of the batched env, from the CPU env ``env`` (``gym.make(...).unwrapped``,
    freshly made: its scene at the config's weight level), but the model, which
    :mod:`rehabbot.batch.patients` reads per patient and weight level. Refuses what is not
    built yet."""
    check_supported(env_id, env)
    if env.config.weight_level is None and env.unusable_weight_levels:
        raise ValueError(f"weight levels {sorted(env.unusable_weight_levels)} are unusable "
                         "for this patient and weight_level=None would draw them; fix "
                         "weight_level")
    homes = _home_setpoints(env)
    config, scene, safety, agent = env.config, env.scene, env.safety, env.agent_observation_map
    controller, handle, reward = env.controller, env.handles[0], env.reward_function
    n = controller.n_joints
    sequences = env.targets
    count = max(len(s.robot_rad) for s in sequences)
    targets = np.zeros((len(sequences), count, n))
    tools = np.zeros((len(sequences), count, 3))
    rests = np.zeros((len(sequences), count))
    for e, sequence in enumerate(sequences):
        k = len(sequence.robot_rad)
        targets[e, :k] = sequence.robot_rad
        targets[e, k:] = sequence.robot_rad[-1]
        tools[e, :k] = sequence.tool_pos_base_m[:, :3]
        tools[e, k:] = sequence.tool_pos_base_m[-1, :3]
        rests[e, :k] = reward.rests_rad[e][:k]
    base_pos, base_rot_t = _rotation_t(env.robot_base_frames[0])
    unit = env.unit_actions
    rom_low, rom_high = safety.rom_bounds_rad
    low, high = controller.low_rad, controller.high_rad
    return EnvTables(
        env_id=env_id, frame_skip=int(config.frame_skip),
        max_episode_steps=int(env.max_episode_steps), weight_level=config.weight_level,
        exercise=config.exercise,
        control_mode=config.control_mode, controller_dt_s=float(controller.dt_s),
        torque_limit_nm=np.asarray(controller.robot.torque_limits(), dtype=float),
        hold_sag_rad=float(TORQUE_HOLD_SAG_RAD), hold_brake_s=float(TORQUE_HOLD_BRAKE_S),
        servo_ids=np.asarray(handle.servo_ids, dtype=int),
        motor_ids=np.asarray(handle.motor_ids, dtype=int),
        action_center=np.asarray(unit.center, dtype=float),
        action_half=np.asarray(unit.half_range, dtype=float),
        setpoint_low_rad=np.asarray(low, dtype=float),
        setpoint_high_rad=np.asarray(high, dtype=float),
        home_qpos=np.asarray(scene.home_qpos, dtype=float),
        home_setpoints_rad=homes,
        qpos_adr=np.asarray(handle.qpos_adr, dtype=int),
        dof_adr=np.asarray(handle.dof_adr, dtype=int),
        tool_site=int(handle.tool_site_id), base_pos_m=base_pos, base_rot_t=base_rot_t,
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
        smoothness_weight=float(reward.smoothness_weight),
        effort_weight=float(reward.effort_weight),
        reward_action_range=np.asarray(reward.action_range, dtype=float),
        reward_torque_limit_nm=np.asarray(reward.torque_limit_nm, dtype=float),
        terminate_on_safety=bool(config.terminate_on_safety),
        patient_qpos_adr=np.asarray(scene.patient_qpos_adr, dtype=int),
        rom_low_rad=np.asarray(rom_low, dtype=float),
        rom_high_rad=np.asarray(rom_high, dtype=float),
        cuff_row=int(safety.cuff_rows[0]), patient_cuff_site=int(handle.patient_cuff_site_id),
        cuff_force_limit_n=float(safety.force_limits_n[0]),
        contact_tolerance_m=float(safety.thresholds.contact_tolerance_m),
        is_robot_geom=np.asarray(safety.robot_geom_mask, dtype=bool),
        is_other_geom=np.asarray(safety.other_geom_mask, dtype=bool),
        blowup_speed_rad_s=float(BLOWUP_SPEED_RAD_S), blowup_force_n=float(BLOWUP_FORCE_N),
        agent_matrix=np.asarray(agent.matrix, dtype=float), tanh_stop=int(agent.tanh_stop),
        bounded_start=int(agent.bounded.start),
        bounded_low=np.asarray(agent.bounded_low, dtype=float),
        bounded_high=np.asarray(agent.bounded_high, dtype=float),
        exercise_start=int(agent.exercise_start), progress_index=int(agent.progress),
    )
