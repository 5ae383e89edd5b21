"""The simulator backend: a closed loop policy -> policy_target -> command reproduces
``env.step`` bit for bit; commands, stops and bad input."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rehabbot.zoo
from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotBackend, RobotState
from rehabbot.deploy.simulator import SimulatorBackend

STEPS = 60


def _env_rollout(env_id, agent, seed, **kwargs):
    env = gym.make(f"rehabbot/{env_id}", **kwargs)
    obs, _ = env.reset(seed=seed)
    out = []
    for _ in range(STEPS):
        obs, reward, terminated, truncated, info = env.step(agent.predict(obs)[0])
        out.append((obs, reward, info["target_index"]))
        if terminated or truncated:
            break
    return out


def _backend_rollout(env_id, agent, seed, perturb=0.0, **kwargs):
    backend = SimulatorBackend(env_id, **kwargs)
    obs, _ = backend.reset(seed=seed)
    out = []
    for _ in range(STEPS):
        target = backend.policy_target(agent.predict(obs)[0])
        backend.command(target + perturb)
        obs, reward, terminated, truncated, info = backend.last_step
        out.append((obs, reward, info["target_index"]))
        if terminated or truncated:
            break
    return out


def _same(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x[0], y[0]) and x[1] == y[1] and x[2] == y[2]
        for x, y in zip(a, b, strict=False))


@pytest.mark.parametrize(("env_id", "algo", "kwargs"), [
    ("rehab-knee-v2", "sac", {}),
    ("rehab-hip-v2", "ppo-fr3", {"robot": "fr3"}),
])
def test_closed_loop_reproduces_env_step(env_id, algo, kwargs):
    agent = rehabbot.zoo.load(env_id, algo)
    expected = _env_rollout(env_id, agent, 4, **kwargs)
    assert _same(_backend_rollout(env_id, agent, 4, **kwargs), expected)
    # The comparison catches a change of the command far below a servo's resolution, yet
    # well above round-off.
    assert not _same(_backend_rollout(env_id, agent, 4, perturb=1e-9, **kwargs), expected)


def test_state_reports_the_scene():
    backend = SimulatorBackend("rehab-knee-v2")
    assert isinstance(backend, RobotBackend)
    backend.reset(seed=0)
    state = backend.state()
    assert isinstance(state, RobotState)
    env = backend.env
    assert state.q_rad.shape == (len(backend.joint_names),) == (6,)
    np.testing.assert_array_equal(state.q_rad, env.data.qpos[env.handle.qpos_adr])
    assert state.patient_q_rad.shape == (3,)
    assert state.cuff_force_n == env.safety.cuff_force_n(env.data)
    assert backend.control_dt_s == env.dt
    assert np.linalg.norm(backend.cuff_force_vector_n()) == pytest.approx(state.cuff_force_n)
    low, high = backend.rom_bounds_rad()
    assert np.all(low < high)
    assert backend.cuff_force_limit_n() == 130.0  # ISO/TS 15066, lower leg


def test_command_moves_the_setpoints_and_stop_holds():
    backend = SimulatorBackend("rehab-knee-v2")
    backend.reset(seed=0)
    start = backend.state().q_rad
    target = start + 0.005
    backend.command(target)
    np.testing.assert_array_equal(backend.env.controller.setpoint_rad, target)
    backend.stop()
    assert not backend.healthy()
    np.testing.assert_array_equal(backend.env.controller.setpoint_rad, backend.state().q_rad)
    with pytest.raises(UsageError, match="stopped"):
        backend.command(target)
    backend.reset(seed=0)
    assert backend.healthy()


@pytest.mark.parametrize(("command", "match"), [
    (np.zeros(5), "6 joint positions"),
    (np.full(6, np.nan), "non-finite"),
])
def test_bad_commands_are_named(command, match):
    backend = SimulatorBackend("rehab-knee-v2")
    backend.reset(seed=0)
    with pytest.raises(UsageError, match=match):
        backend.command(command)


def test_refused_envs_are_named():
    with pytest.raises(UsageError, match="torque"):
        SimulatorBackend("rehab-knee-v2", control_mode="torque")
    with pytest.raises(UsageError, match="two robots"):
        SimulatorBackend("rehab-bilateral-v1")
    with pytest.raises(UsageError, match="cannot make"):
        SimulatorBackend("rehab-nothing-v2")
    backend = SimulatorBackend("rehab-knee-v2")
    backend.reset(seed=0)
    with pytest.raises(UsageError, match="non-finite"):
        backend.policy_target(np.full(6, np.inf, dtype=np.float32))
