"""The batched env (rehabbot.batch, MuJoCo Warp's CPU device) against the CPU env: the scripted
expert's episode replayed with the same target switches, termination step and return, every
observation within a float32 bound, and safety stops on the same step with the same rule.

Slow (``pytest --full``): Warp compiles its kernels once (about 40-80 s, cached in
``~/.cache/warp``), then steps one world in about 15 ms on the CPU.

Tolerances, and why they do not depend on the machine:

* Observation: every entry of the ``-v2`` observation lies in [-2, 2]; the most sensitive
  entries are ``tanh`` of a joint error over 0.05 rad (20 per rad), of a velocity over
  0.5 rad/s (2 per rad/s) and the cuff force over its limit (1/130 per N). A bound of
  ``OBS_TOL = 1e-3`` is 5e-5 rad of joint angle (1/1000 of the 0.05 rad target tolerance),
  5e-4 rad/s of joint speed and 0.13 N of cuff force: far below anything the task can see,
  and far above float32's rounding of the physics (the study measured 3.5e-6 rad of qpos after
  1000 steps; the replays here stay below 1e-4 in every entry).
* Return: the progress terms add up to ``10 / rad x`` the path travelled, so a relative
  ``RETURN_RTOL = 1e-4`` of a return of about 175 (0.018) is 1.8e-3 rad of path in a whole
  episode, again far below the 0.05 rad tolerance; float32 rewards differ by about 1e-5 a
  step.
* In ``torque`` mode no servo damps the joints, and float32 rounding in the constraint solve
  shows in the transient joint velocities and cuff force (measured: up to 0.018 in a
  velocity entry and 0.0025 in the force entry). Those entries get ``TORQUE_TRANSIENT_TOL =
  0.05``, which is 0.025 rad/s or 7 N, 5 % of the 140 N limit. Every other entry keeps
  ``OBS_TOL``.
* The robot's work on the limb over an episode (a sum of about 3000 float32 products of
  force and displacement): ``WORK_RTOL = 1e-3`` relative.
* Target switches, the termination step and the safety rule must match exactly: they are
  the task's discrete outcomes.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("warp")
pytest.importorskip("mujoco.mjx")

import jax.numpy as jp  # noqa: E402

import rehabbot.batch as batch  # noqa: E402
from benchmarks.common.batch_parity import (  # noqa: E402
    START,
    batched_rollout,
    cpu_episode,
    replay_expert,
    replay_stops,
)
from rehabbot.rl.experts import ScriptedExpert  # noqa: E402

pytestmark = pytest.mark.slow

OBS_TOL = 1e-3
TORQUE_TRANSIENT_TOL = 0.05
WORK_RTOL = 1e-3
RETURN_RTOL = 1e-4


# The base ids' replays: two whole episodes (to success), and the first PREFIX_STEPS steps of
# the two long ones (their whole episodes, 337 and 412 steps, are on the parity page,
# benchmarks/results/batch_parity.py): a batched step costs about 0.15 s on a CPU.
PREFIX_STEPS = 200
# The reward terms' test needs fewer: two target switches.
REWARD_TERMS_STEPS = 120
WHOLE_EPISODES = ("rehabbot/rehab-reach-v2", "rehabbot/rehab-hip-v2")


@pytest.mark.parametrize("env_id", batch.SUPPORTED_IDS)
def test_expert_episode_replays_on_warp(env_id):
    replay = replay_expert(env_id, max_steps=None if env_id in WHOLE_EPISODES else PREFIX_STEPS)
    if env_id in WHOLE_EPISODES:
        assert replay["end_cpu"] is not None  # a whole episode, to its end
    else:
        assert replay["end_cpu"] is None and len(replay["switches_cpu"]) >= 5
    assert replay["reset_obs_error"] < OBS_TOL
    assert replay["obs_error"] < OBS_TOL, replay["obs_error"]
    assert replay["switches_batched"] == replay["switches_cpu"]
    assert replay["end_batched"] == replay["end_cpu"], replay
    assert replay["stop_batched"] == 0
    work, cpu_work = replay["robot_work_batched_j"], replay["robot_work_cpu_j"]
    assert abs(work - cpu_work) <= WORK_RTOL * abs(cpu_work), (work, cpu_work)
    batched_return, cpu_return = replay["return_batched"], replay["return_cpu"]
    assert abs(batched_return - cpu_return) <= RETURN_RTOL * abs(cpu_return), \
        (batched_return, cpu_return)


# The optional reward terms switched on: the native action's change and the robot's effort.
SMOOTH_EFFORT = {"design": "progress", "smoothness_weight": 2.0, "effort_weight": 1.0}


def test_smoothness_and_effort_terms_follow_the_cpu():
    """With ``smoothness_weight`` and ``effort_weight`` on, the expert's episode (its first
    REWARD_TERMS_STEPS steps) pays the same on both envs; the terms cost more than 100x the
    return's bound, so a term left out or mis-scaled fails it."""
    env_id = "rehabbot/rehab-reach-v2"
    replay = replay_expert(env_id, reward=SMOOTH_EFFORT, max_steps=REWARD_TERMS_STEPS)
    assert len(replay["switches_cpu"]) >= 2
    assert replay["switches_batched"] == replay["switches_cpu"]
    assert replay["end_batched"] == replay["end_cpu"]
    assert replay["obs_error"] < OBS_TOL
    batched_return, cpu_return = replay["return_batched"], replay["return_cpu"]
    assert abs(batched_return - cpu_return) <= RETURN_RTOL * abs(cpu_return), \
        (batched_return, cpu_return)
    plain = cpu_episode(env_id, max_steps=REWARD_TERMS_STEPS)["rewards"].sum()
    assert abs(plain - cpu_return) > 100 * RETURN_RTOL * abs(cpu_return)


def first_stop(done: np.ndarray) -> int:
    stops = np.flatnonzero(done)
    assert stops.size, "the batched world never stopped"
    return int(stops[0])


@pytest.mark.parametrize(("kwargs", "unit_actions"), [
    # the cuff-force rule, pulling on the shoulder joint both ways
    ({}, ([1, 0, 0, 0, 0, 0], [-1, 0, 0, 0, 0, 0])),
    # with the highest cuff limit (880 N): unintended contact in world 0, range of motion in
    # world 1 (which stops first and keeps moving: its contacts share MuJoCo Warp's array)
    ({"cuff_force_limit_n": 880.0}, ([1, 0, 0, -1, -1, -1], [1, 0, -1, 1, 1, -1])),
    # the cuff-force stop's penalty with the optional terms in the hold cost
    ({"reward": SMOOTH_EFFORT}, ([1, 0, 0, 0, 0, 0],)),
])
def test_safety_stops_match(kwargs, unit_actions):
    for row in replay_stops("rehabbot/rehab-reach-v2", unit_actions, **kwargs):
        assert row["rule_cpu"] is not None, f"{row['unit_action']}: the CPU episode did not stop"
        assert row["stop_batched"] == row["stop_cpu"], row
        assert row["rule_batched"] == row["rule_cpu"], row
        assert abs(row["last_reward_batched"] - row["last_reward_cpu"]) <= \
            RETURN_RTOL * abs(row["last_reward_cpu"])
        assert abs(row["return_batched"] - row["return_cpu"]) <= \
            RETURN_RTOL * abs(row["return_cpu"])


def test_auto_reset_starts_the_next_episode_and_leaves_running_worlds_alone():
    """World 0 stops on the cuff force, restarts at home and stops again on the same step of
    its second episode; world 1 holds still throughout, as on the CPU (the forward of the
    auto-reset does not disturb a running world)."""
    env_id = "rehabbot/rehab-reach-v2"
    pull = np.asarray([-1, 0, 0, 0, 0, 0], np.float32)
    cpu_pull = cpu_episode(env_id, pull)
    length = len(cpu_pull["actions"])
    cpu_hold = cpu_episode(env_id, np.zeros(6, np.float32))
    steps = 2 * length + 3
    actions = np.zeros((steps, 2, 6), np.float32)
    actions[:, 0] = pull
    env = batch.make(env_id, naconmax=32, **START)

    def run(state, action_seq):
        def body(state, action):
            state = jax.vmap(env.step_auto_reset)(state, action)
            return state, (state.obs, state.reward, state.done,
                           state.metrics["safety_violation"])
        return jax.lax.scan(body, state, action_seq)

    start = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), 2))
    _, (obs, rewards, done, violation) = jax.jit(run)(start, jp.asarray(actions))
    obs, rewards, done, violation = map(np.asarray, (obs, rewards, done, violation))
    assert np.flatnonzero(done[:, 0]).tolist() == [length - 1, 2 * length - 1]
    assert (violation[[length - 1, 2 * length - 1], 0] == batch.RULE_CODES["cuff_force"]).all()
    # the step that stopped shows the next episode's first observation
    assert np.abs(obs[length - 1, 0] - np.asarray(start.obs[0])).max() < OBS_TOL
    first, second = rewards[:length, 0], rewards[length:2 * length, 0]
    assert np.abs(first - cpu_pull["rewards"]).max() <= RETURN_RTOL * abs(cpu_pull["rewards"]).max()
    assert abs(second.sum() - first.sum()) <= RETURN_RTOL * abs(first.sum())
    assert not done[:, 1].any()
    assert np.abs(obs[:, 1] - cpu_hold["obs"][1:steps + 1]).max() < OBS_TOL


def test_instability_is_judged_from_the_values():
    """MuJoCo Warp neither warns nor resets on a diverging state: a wrist spun to 1e4 rad/s
    (beyond the blow-up speed) stops both envs on the first step with the instability rule,
    the same penalty and the last healthy observation."""
    env_id = "rehabbot/rehab-reach-v2"
    speed_rad_s = 1.0e4
    cpu = gym.make(env_id).unwrapped
    cpu.reset(seed=0, options=START)
    wrist = cpu.handles[0].dof_adr[-1]
    cpu.data.qvel[wrist] = speed_rad_s
    cpu_obs, cpu_reward, terminated, _, info = cpu.step(np.zeros(6, np.float32))
    assert terminated and info["safety_violation"] == "instability"

    env = batch.make(env_id, naconmax=16, **START)
    state = jax.jit(env.reset)(jax.random.key(0))
    data = state.data
    state = state.replace(data=data.replace(qvel=data.qvel.at[wrist].set(speed_rad_s)))
    state = jax.jit(env.step)(state, jp.zeros(6))
    assert float(state.done) == 1.0
    assert int(state.metrics["safety_violation"]) == batch.RULE_CODES["instability"]
    assert abs(float(state.reward) - cpu_reward) <= RETURN_RTOL * abs(cpu_reward)
    # the fields of the last healthy state (tracking errors, next target, setpoint lead); the
    # velocities and forces are the diverged ones
    healthy = slice(0, cpu.agent_layout.slice("setpoint_lead").stop)
    assert np.abs(np.asarray(state.obs)[healthy] - cpu_obs[healthy]).max() < OBS_TOL


def test_weight_levels_drawn_per_world():
    """With the weight level left to be drawn, each world draws its own at reset and steps
    with that level's masses, inertias and home setpoints (MuJoCo Warp's per-world model
    fields): every world follows the CPU env's expert at its level."""
    env_id, steps, worlds = "rehabbot/rehab-reach-v2", 25, 3
    env = batch.make(env_id, naconmax=16 * worlds, exercise=0)
    start = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), worlds))
    levels = np.asarray(start.info["weight_level"]).tolist()
    assert len(set(levels)) > 1, levels
    episodes = []
    for level in levels:
        cpu = gym.make(env_id).unwrapped
        obs, _ = cpu.reset(seed=0, options={"exercise": 0, "weight_level": level})
        expert, actions, observations = ScriptedExpert(cpu), [], [obs]
        for _ in range(steps):
            action = np.asarray(expert.predict(obs)[0], np.float32)
            obs, *_ = cpu.step(action)
            actions.append(action)
            observations.append(obs)
        episodes.append((np.asarray(actions), np.asarray(observations)))
    actions = np.stack([a for a, _ in episodes], axis=1)

    def run(state, action_seq):
        def body(state, action):
            state = jax.vmap(env.step)(state, action)
            return state, state.obs
        return jax.lax.scan(body, state, action_seq)

    _, obs = jax.jit(run)(start, jp.asarray(actions))
    obs = np.asarray(obs)
    for world, (_, cpu_obs) in enumerate(episodes):
        assert np.abs(np.asarray(start.obs[world]) - cpu_obs[0]).max() < OBS_TOL
        error = np.abs(obs[:, world] - cpu_obs[1:]).max()
        assert error < OBS_TOL, (world, levels[world], error)


@pytest.mark.parametrize("condition", [None,
                                       {"effort": "active_assisted", "strength_fraction": 0.5}],
                         ids=["healthy", "active"])
def test_torque_mode_zeroes_the_servo_gains(condition):
    """``control_mode="torque"``: MuJoCo Warp ignores ``opt.disableactuator``, so the batched
    model has zero servo gains instead. World 0 holds zero torque (a healthy arm sags into the
    cuff-force stop); world 1 pushes the shoulder and elbow: both as on the CPU, for a healthy
    arm and with a condition whose drive acts on the limb in the same physics steps."""
    env_id, steps = "rehabbot/rehab-reach-v2", 60
    kwargs = {"control_mode": "torque", **({"condition": condition} if condition else {})}
    unit_actions = ([0, 0, 0, 0, 0, 0], [0, -0.1, 0.1, 0, 0, 0])
    cpus = [cpu_episode(env_id, np.asarray(a, np.float32), max_steps=steps, **kwargs)
            for a in unit_actions]
    if condition is None:
        assert cpus[0]["violation"] == "cuff_force" and cpus[1]["violation"] is None
    actions = np.repeat(np.asarray(unit_actions, np.float32)[None], steps, axis=0)
    out = batched_rollout(env_id, actions, **kwargs)
    for world, cpu in enumerate(cpus):
        if cpu["violation"] is None:
            assert not out["done"][:, world].any()
        else:
            stop = len(cpu["actions"]) - 1
            assert first_stop(out["done"][:, world]) == stop
            assert out["violation"][stop, world] == batch.RULE_CODES[cpu["violation"]]
    layout = gym.make(env_id, **kwargs).unwrapped.agent_layout
    transient = np.zeros(layout.size, bool)
    for name in ("joint_velocity", "cuff_force"):
        transient[layout.slice(name)] = True
    for world, cpu in enumerate(cpus):
        n = len(cpu["actions"])
        error = np.abs(out["obs"][:n, world] - cpu["obs"][1:])
        assert error[:, ~transient].max() < OBS_TOL
        assert error[:, transient].max() < TORQUE_TRANSIENT_TOL
        assert abs(out["rewards"][:n, world].sum() - cpu["rewards"].sum()) <= \
            RETURN_RTOL * abs(cpu["rewards"].sum())
        assert out["patient_work_j"][n - 1, world] == pytest.approx(
            cpu["patient_work_j"], rel=WORK_RTOL, abs=1e-6)
    if condition is not None:  # the drive does work in the pushed world
        assert abs(cpus[1]["patient_work_j"]) > 1e-3


@pytest.mark.parametrize("mode", ["joint_position", "joint_velocity"])
def test_setpoint_control_modes_follow_the_cpu(mode):
    """``joint_position`` (the unit action is the setpoint, within the setpoint bounds) and
    ``joint_velocity`` (setpoint speeds over one control step): the scripted expert's first
    80 steps in world 0 of two follow the CPU env's; the same actions read as ``joint_delta``
    increments do not."""
    env_id, steps = "rehabbot/rehab-reach-v2", 80
    cpu = cpu_episode(env_id, max_steps=steps, control_mode=mode)
    actions = np.repeat(cpu["actions"][:, None], 2, axis=1)
    actions[:, 1] = np.clip(actions[:, 1] + 0.3, -1, 1)
    out = batched_rollout(env_id, actions, control_mode=mode)
    assert np.abs(out["obs"][:, 0] - cpu["obs"][1:]).max() < OBS_TOL
    assert abs(out["rewards"][:, 0].sum() - cpu["rewards"].sum()) \
        < RETURN_RTOL * max(1.0, abs(cpu["rewards"].sum()))
    assert not out["done"][:, 0].any()
    if mode == "joint_position":  # as increments, the same actions move the arm elsewhere
        wrong = batched_rollout(env_id, actions[:, :1], control_mode="joint_delta")
        assert np.abs(wrong["obs"][:, 0] - cpu["obs"][1:]).max() > 100 * OBS_TOL


def test_readings_match_the_cpu_info():
    """``metrics`` carry the CPU env's ``info`` readings: the robot's actuator torques on its
    joints, the patient's joint angles, the exercise and the weight level, step by step."""
    env_id, steps, start = "rehabbot/rehab-hip-v2", 30, {"exercise": 1, "weight_level": 2}
    cpu = gym.make(env_id).unwrapped
    obs, info = cpu.reset(seed=0, options=start)
    expert = ScriptedExpert(cpu)
    actions, infos = [], []
    for _ in range(steps):
        actions.append(np.asarray(expert.predict(obs)[0], np.float32))
        obs, _r, _term, _trunc, info = cpu.step(actions[-1])
        infos.append(info)
    env = batch.make(env_id, naconmax=32, **start)
    step = jax.jit(jax.vmap(env.step))
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), 2))
    limit = np.asarray(cpu.controller.robot.torque_limits())
    moved = 0.0
    for k in range(steps):
        state = step(state, jp.asarray(np.stack([actions[k], np.zeros_like(actions[k])])))
        m = {name: np.asarray(value)[0] for name, value in state.metrics.items()}
        assert m["exercise"] == 1 and m["weight_level"] == 2
        assert np.abs(m["patient_qpos"] - infos[k]["patient_qpos"]).max() < 5e-5
        # 1e-3 of each joint's torque limit (the servo torque is float32 there).
        assert (np.abs(m["robot_torque_nm"] - infos[k]["robot_torque_nm"]) < 1e-3 * limit).all()
        moved = max(moved, float(np.abs(infos[k]["patient_qpos"]
                                        - infos[0]["patient_qpos"]).max()))
    assert moved > 0.01  # the comparison follows a moving patient
