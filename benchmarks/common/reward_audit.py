"""Audits of a reward design, measured in the sim: is reaching a target worth more than
stalling short of it, and does a safety stop ever pay? (``benchmarks/probes/reward_trap.py`` prints
them; ``tests/test_reward_v1.py`` asserts them.)

Both replay seeded episodes: the same seed, options and actions reproduce a state exactly
(the envs are deterministic), so "what if the agent had held still from here" is measured by
replaying the actions up to that step and then sending zero actions to the time limit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from rehabbot.envs.control import PAPER_DELTA_RAD
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.tasks.observation import tracking_slices
from rehabbot.tasks.reward import STOP_MARGIN


def _joint_slices(env: gym.Env) -> tuple[slice, slice]:
    """Where theta* and theta sit in ``env``'s observations (any robot, one or two arms)."""
    theta_star, _, theta, _ = tracking_slices(env.observation_space.shape[0])
    return theta_star, theta


@dataclass(frozen=True)
class StallCase:
    """One target of one expert episode: the discounted value of going on (the expert) and
    of holding still, from the last state short of the target."""

    env_id: str
    exercise: int
    target: int
    step: int  # the decision at which the two choices part
    short_rad: float  # how far short of the target (inf-norm) the robot is there
    gamma: float
    reach_value: float
    stall_value: float

    @property
    def reaching_pays(self) -> bool:
        return self.reach_value > self.stall_value


def _expert_episode(env: gym.Env, seed: int, options: dict) -> tuple[list, list, list]:
    """Actions, rewards and per-step (target index, inf-norm error before the step)."""
    expert = ScriptedExpert(env)
    theta_star, theta = _joint_slices(env)
    obs, _ = env.reset(seed=seed, options=options)
    actions, rewards, states = [], [], []
    base = env.unwrapped
    while True:
        error = float(np.max(np.abs(obs[theta].astype(float) - obs[theta_star].astype(float))))
        states.append((base.target_index, error))
        action, _ = expert.predict(obs, deterministic=True)
        actions.append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        rewards.append(reward)
        if terminated or truncated:
            if not info["is_success"]:
                raise RuntimeError(f"the expert failed: {info['safety_violation']}")
            return actions, rewards, states


def _hold_rewards(env: gym.Env, seed: int, options: dict, actions: Sequence,
                  servo: bool = False, stops: list | None = None) -> list[float]:
    """Rewards of replaying ``actions`` and then holding still to the end: zero actions, or
    (``servo``, joint_delta mode) moving the setpoints so that the robot stays at the joint
    angles it had when the replay ended (its setpoints may lead them). A safety stop while
    holding is appended to ``stops``."""
    _, theta = _joint_slices(env)
    obs, _ = env.reset(seed=seed, options=options)
    for action in actions:
        obs, *_ = env.step(action)
    space = env.action_space
    zero = np.zeros(space.shape, space.dtype)
    hold_at = obs[theta].astype(float)
    rewards = []
    while True:
        action = zero
        if servo:
            action = np.clip(0.5 * (hold_at - obs[theta].astype(float)), space.low,
                             space.high).astype(space.dtype)
        obs, reward, terminated, truncated, info = env.step(action)
        rewards.append(reward)
        if terminated or truncated:
            if stops is not None and info["safety_violation"] is not None:
                stops.append(info["safety_violation"])
            return rewards


def _discounted(rewards: Sequence[float], gamma: float) -> float:
    value = 0.0
    for reward in reversed(rewards):
        value = reward + gamma * value
    return value


def stall_cases(env_id: str, exercise: int, gammas: Sequence[float], seed: int = 0,
                weight_level: int = 2, targets: Sequence[int] | None = None,
                short_rad: float = 0.06, **env_kwargs) -> list[StallCase]:
    """For each target (all, or ``targets``) of one expert episode, the last step before the
    target is reached at which the robot is still ``short_rad`` or more short of it (inf-norm;
    the tolerance is 0.05 rad): the discounted return of the expert's remaining episode
    versus that of holding still there (servoing the setpoints to hold those angles)."""
    env = gym.make(env_id, **env_kwargs)
    options = {"exercise": exercise, "weight_level": weight_level}
    try:
        actions, rewards, states = _expert_episode(env, seed, options)
        cases = []
        n_targets = len(env.unwrapped.target_sequence)
        for target in (range(n_targets) if targets is None else targets):
            steps = [t for t, (index, error) in enumerate(states)
                     if index == target and error >= short_rad]
            if not steps:  # reached in the step it became active
                continue
            t = steps[-1]
            held = _hold_rewards(env, seed, options, actions[:t], servo=True)
            for gamma in gammas:
                cases.append(StallCase(env_id, exercise, target, t, states[t][1], gamma,
                                       _discounted(rewards[t:], gamma),
                                       _discounted(held, gamma)))
        return cases
    finally:
        env.close()


@dataclass(frozen=True)
class StopCase:
    """Undiscounted returns from the reset state: driving one joint at the action bound until a
    safety rule stops the episode, holding still (zero actions) to the time limit, and the
    expert's episode."""

    env_id: str
    control_mode: str
    joint: int
    violation: str | None
    stop_step: int
    stop_return: float
    hold_return: float
    expert_return: float
    # From the state before the stop: the stopping step's reward and the return of holding
    # still from that state instead (setpoint modes only: with torques off nothing holds),
    # and the rule that ended that hold, if holding could not avoid a stop either.
    last_step_reward: float
    hold_from_there: float | None
    hold_from_there_stop: str | None


def stop_cases(env_id: str, control_mode: str = "joint_delta", seed: int = 0,
               exercise: int = 0, weight_level: int = 0,
               joints: Sequence[int] = range(6)) -> list[StopCase]:
    """The safety audit of one id (see :class:`StopCase`); a joint that its push never drives
    into a rule within the episode is reported with ``violation=None``."""
    options = {"exercise": exercise, "weight_level": weight_level}
    env = gym.make(env_id, control_mode=control_mode)
    expert_env = gym.make(env_id)
    try:
        # Holding still: the robot servoed at its reset angles (joint_delta mode; with torques
        # alone nothing holds the limb up).
        hold = sum(_hold_rewards(expert_env, seed, options, [], servo=True))
        _actions, expert_rewards, _states = _expert_episode(expert_env, seed, options)
        cases = []
        for joint in joints:
            push = np.zeros(env.action_space.shape, np.float32)
            push[joint] = env.action_space.high[joint]
            env.reset(seed=seed, options=options)
            rewards = []
            while True:
                _obs, reward, terminated, truncated, info = env.step(push)
                rewards.append(reward)
                if terminated or truncated:
                    break
            violation = info["safety_violation"] if terminated else None
            there, stops = None, []
            if control_mode != "torque":
                there = float(sum(_hold_rewards(env, seed, options, [push] * (len(rewards) - 1),
                                                servo=True, stops=stops)))
            cases.append(StopCase(env_id, control_mode, joint, violation, len(rewards),
                                  float(sum(rewards)), float(hold),
                                  float(sum(expert_rewards)), float(rewards[-1]), there,
                                  stops[0] if stops else None))
        return cases
    finally:
        env.close()
        expert_env.close()


# -- a stop never pays: push a joint into a stop, then hold from earlier states --------------
AUDIT_GAMMAS: tuple[float | None, ...] = (None, 0.95, 0.99, 0.999)  # None: undiscounted
# Holding still in torque mode: a PD at this fraction of the robot's impedance gains, the
# largest of 1, 0.3, 0.2, 0.1 with which every id holds its limb at rest for 1000 steps.
TORQUE_HOLD_GAIN_FRACTION = 0.3


@dataclass(frozen=True)
class HoldComparison:
    """From state ``state`` (the number of steps taken) of an episode that a safety rule
    stopped: its return from there against holding still from there, for one ``gamma``
    (``None``: undiscounted). ``hold_stop`` names the rule if holding still could not avoid a
    stop either (the comparison then sets one stop against another). ``headway``: some step
    of the episode between ``state`` and the stop paid more than holding still paid in that
    step (it made progress that holding does not; discounted, that progress can outweigh the
    later stop, whatever the penalty)."""

    state: int
    gamma: float | None
    stop_value: float
    hold_value: float
    hold_stop: str | None
    headway: bool


@dataclass(frozen=True)
class PushAudit:
    """One push of ``joint`` at ``fraction`` of its action bound in direction ``sign`` (see
    :func:`push_audit`): the rule that stopped it (None: none within ``max_steps``), at which
    step, and the comparisons with holding still."""

    env_id: str
    control_mode: str
    joint: int
    sign: int
    fraction: float
    violation: str | None
    stop_step: int
    comparisons: tuple[HoldComparison, ...]

    def margin(self, comparison: HoldComparison) -> float:
        """The margin a stop must lose by: half of ``STOP_MARGIN``, discounted from the stop
        back to the compared state (the penalty pays the whole margin at the stop)."""
        gamma = 1.0 if comparison.gamma is None else comparison.gamma
        return 0.5 * STOP_MARGIN * gamma ** (self.stop_step - comparison.state - 1)

    def stop_pays(self, comparison: HoldComparison) -> bool:
        """Whether the stop earns more than holding still less :meth:`margin` (whatever
        ``hold_stop`` and ``headway`` say: the caller decides which comparisons count)."""
        return not comparison.stop_value < comparison.hold_value - self.margin(comparison)


def push_action(env: gym.Env, joint: int, sign: int, fraction: float) -> np.ndarray:
    """The action that drives ``joint`` at ``fraction`` of its bound in every mode: an
    increment (joint_delta), a velocity (joint_velocity), a torque (torque); in
    joint_position mode, the current setpoints with that joint moved by the delta bound."""
    base = env.unwrapped
    space = env.action_space
    if base.config.control.control_mode == "joint_position":
        action = np.asarray(base.controller.setpoint_rad, float).copy()
        action[joint] += sign * fraction * PAPER_DELTA_RAD
        return np.clip(action, space.low, space.high).astype(space.dtype)
    action = np.zeros(space.shape, space.dtype)
    action[joint] = sign * fraction * space.high[joint]
    return action


def hold_action(env: gym.Env, held_rad: np.ndarray, servo: bool) -> np.ndarray:
    """Holding still: the setpoints kept (zero increments or velocities, the same positions);
    with ``servo``, moved to the angles ``held_rad`` instead. In torque mode (no servo) a
    joint PD at :data:`TORQUE_HOLD_GAIN_FRACTION` of the robot's own impedance gains toward
    ``held_rad`` (at 50 Hz decisions the full gains are unstable)."""
    base = env.unwrapped
    space = env.action_space
    mode = base.config.control.control_mode
    theta = base.data.qpos[base._qpos_adr]
    if mode == "torque":
        handles = getattr(base, "handles", None) or (base.handle,)
        kp, kv = (TORQUE_HOLD_GAIN_FRACTION * np.concatenate(
            [getattr(h.robot.default_gains, name) for h in handles])
            for name in ("kp_nm_per_rad", "kv_nms_per_rad"))
        dof = np.concatenate([h.dof_adr for h in handles])
        limit = np.concatenate([h.robot.torque_limits() for h in handles])
        torque = kp * (held_rad - theta) - kv * base.data.qvel[dof]
        return np.clip(torque / limit, -1, 1).astype(space.dtype)
    setpoint = np.asarray(base.controller.setpoint_rad, float)
    target = held_rad if servo else setpoint
    if mode == "joint_position":
        return np.clip(target, space.low, space.high).astype(space.dtype)
    change = target - setpoint
    if mode == "joint_velocity":
        change = change / base.dt_s
    return np.clip(change, space.low, space.high).astype(space.dtype)


def _returns_holding_from(env: gym.Env, seed: int, options: dict, actions: Sequence,
                          servo: bool) -> tuple[list[float], str | None]:
    """Replay ``actions`` from the seeded reset, then hold still to the end of the episode:
    the rewards after the replay and the rule that stopped the hold (None: none)."""
    env.reset(seed=seed, options=options)
    for action in actions:
        env.step(action)
    base = env.unwrapped
    held = np.array(base.data.qpos[base._qpos_adr])
    rewards = []
    while True:
        _obs, reward, terminated, truncated, info = env.step(hold_action(env, held, servo))
        rewards.append(reward)
        if terminated or truncated:
            return rewards, info["safety_violation"] if terminated else None


def push_audit(env_id: str, control_mode: str, joint: int, sign: int, fraction: float = 1.0,
               seed: int = 0, exercise: int = 0, weight_level: int = 0,
               states: Sequence[int] | None = None, max_steps: int = 400,
               gammas: Sequence[float | None] = AUDIT_GAMMAS, **env_kwargs) -> PushAudit:
    """Drive one joint into a safety stop, then compare the episode's return from some of its
    states (``states``: step counts; default the start, the middle and the step just before
    the stop) with holding still from there: keeping the setpoints (zero actions), or, where
    that cannot avoid a stop either, servoing the setpoints to the angles of that state."""
    options = {"exercise": exercise, "weight_level": weight_level}
    env = gym.make(env_id, control_mode=control_mode, **env_kwargs)
    try:
        env.reset(seed=seed, options=options)
        actions, rewards = [], []
        for _ in range(max_steps):
            action = push_action(env, joint, sign, fraction)
            actions.append(action)
            _obs, reward, terminated, truncated, info = env.step(action)
            rewards.append(reward)
            if terminated or truncated:
                break
        violation = info["safety_violation"] if terminated else None
        stop = len(rewards)
        comparisons: list[HoldComparison] = []
        if violation is not None:
            chosen = sorted({0, stop // 2, stop - 1} if states is None
                            else {s for s in states if 0 <= s < stop})
            for state in chosen:
                held, hold_stop = _returns_holding_from(env, seed, options, actions[:state],
                                                        servo=False)
                if hold_stop is not None:
                    held, hold_stop = _returns_holding_from(env, seed, options,
                                                            actions[:state], servo=True)
                before_stop = rewards[state:stop - 1]
                headway = any(r > h for r, h in zip(before_stop, held, strict=False))
                for gamma in gammas:
                    comparisons.append(HoldComparison(
                        state, gamma, _value(rewards[state:], gamma), _value(held, gamma),
                        hold_stop, headway))
        return PushAudit(env_id, control_mode, joint, sign, fraction, violation, stop,
                         tuple(comparisons))
    finally:
        env.close()


def _value(rewards: Sequence[float], gamma: float | None) -> float:
    return float(sum(rewards)) if gamma is None else _discounted(rewards, gamma)
