"""The two-arm id (``rehab-bilateral-v2``) in the batched env, against the CPU
``BilateralEnv`` on MuJoCo Warp's CPU device: two robots, two cuffs, the path summed over the
arms, the arms' synchronisation term, and the cuff-force rule per cuff.

Bounds as in ``tests/test_batch_parity.py``: every observation entry within
``OBS_TOL = 1e-3``, the return within ``RETURN_RTOL = 1e-4`` relative, the robots' work within
``WORK_RTOL = 1e-3`` relative, target switches, termination and rules exact. The
out-of-step replay compares each step's reward within ``STEP_REWARD_TOL = 1e-4`` (1e-5 rad of
path at 10 per rad): its sync term costs more than 1 over the replay, so a sync term left out
or mis-scaled fails it.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("warp")
pytest.importorskip("mujoco.mjx")

import rehabbot.batch as batch  # noqa: E402
from benchmarks.common.batch_parity import (  # noqa: E402
    batched_rollout,
    cpu_episode,
    replay_expert,
    replay_stops,
)
from rehabbot.rl.experts import ScriptedExpert  # noqa: E402

pytestmark = pytest.mark.slow

ENV = "rehabbot/rehab-bilateral-v2"
OBS_TOL = 1e-3
RETURN_RTOL = 1e-4
WORK_RTOL = 1e-3
STEP_REWARD_TOL = 1e-4
TORQUE_TRANSIENT_TOL = 0.05


def test_expert_episode_replays_on_warp():
    """The symmetric exercise (entry 0), its first 200 steps (four target switches); its whole
    episode and the alternating one (entry 2, 644 steps) are on the parity page
    (benchmarks/results/batch_parity.py), outside the suite's time budget."""
    replay = replay_expert(ENV, start={"exercise": 0, "weight_level": 0}, max_steps=200)
    assert len(replay["switches_cpu"]) >= 4
    assert replay["stop_cpu"] is None
    assert replay["reset_obs_error"] < OBS_TOL  # the cuff forces at home (dense Jacobian)
    assert replay["obs_error"] < OBS_TOL, replay["obs_error"]
    assert replay["switches_batched"] == replay["switches_cpu"]
    assert replay["end_batched"] == replay["end_cpu"]
    assert replay["stop_batched"] == 0
    assert replay["return_batched"] == pytest.approx(replay["return_cpu"], rel=RETURN_RTOL)
    assert replay["robot_work_batched_j"] == pytest.approx(replay["robot_work_cpu_j"],
                                                           rel=WORK_RTOL)


def test_arms_out_of_step_pay_the_same_sync_term():
    """The expert's actions with the left arm's slowed to 40 %: the arms fall out of step and
    the sync term charges them; every step's reward matches the CPU's."""
    env = gym.make(ENV).unwrapped
    obs, _info = env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    expert = ScriptedExpert(env)
    actions, rewards, sync = [], [], 0.0
    for _ in range(150):
        action = np.asarray(expert.predict(obs)[0], np.float32).copy()
        action[6:] *= 0.4
        obs, reward, terminated, _truncated, info = env.step(action)
        actions.append(action)
        rewards.append(reward)
        sync += info["reward_sync"]
        assert not terminated
    env.close()
    assert sync < -1.0
    out = batched_rollout(ENV, np.asarray(actions)[:, None])
    assert np.abs(out["rewards"][:, 0] - np.asarray(rewards)).max() < STEP_REWARD_TOL


def test_each_cuff_stops_on_its_own_force():
    """One robot pulls away from its hand (world 0 the right, world 1 the left): the
    cuff-force rule stops both envs on the same step, with the same penalty."""
    right, left = [1.0] + [0.0] * 11, [0.0] * 6 + [-1.0] + [0.0] * 5
    for row in replay_stops(ENV, (right, left)):
        assert row["rule_cpu"] == "cuff_force"
        assert row["stop_batched"] == row["stop_cpu"]
        assert row["rule_batched"] == row["rule_cpu"]
        assert row["last_reward_batched"] == pytest.approx(row["last_reward_cpu"],
                                                           rel=RETURN_RTOL)


def test_the_two_arm_model_steps_with_a_dense_jacobian():
    """MuJoCo Warp's sparse Jacobian (its choice above 32 dofs) regularises the cuffs by the
    welded ancestors' weights, unlike MuJoCo: the batched model asks for a dense one."""
    env = batch.make(ENV)
    assert env.mj_model.nv > 32
    assert env.cpu_env.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_AUTO
    assert env.mj_model.opt.jacobian == mujoco.mjtJacobian.mjJAC_DENSE
    one_arm = batch.make("rehabbot/rehab-reach-v2")
    assert one_arm.mj_model is one_arm.cpu_env.model  # unchanged below 33 dofs


@pytest.mark.parametrize("mode", ["joint_position"])
def test_setpoint_control_modes_follow_the_cpu(mode):
    """The two-arm expert's first 80 steps in a setpoint mode, every observation entry within
    the bound (``joint_velocity`` shares the per-arm setpoint path and is checked on one arm
    in tests/test_batch_parity.py; on two arms it stays within 6.3e-5, measured)."""
    cpu = cpu_episode(ENV, max_steps=80, control_mode=mode)
    out = batched_rollout(ENV, cpu["actions"][:, None], control_mode=mode)
    assert np.abs(out["obs"][:, 0] - cpu["obs"][1:]).max() < OBS_TOL
    assert out["rewards"][:, 0].sum() == pytest.approx(cpu["rewards"].sum(), rel=RETURN_RTOL)
    assert not out["done"].any()


def test_torque_mode_sags_into_the_same_stop():
    """``control_mode="torque"`` on both robots (their servos off by zero gains): zero
    torque, and a push on both shoulders and elbows, stop both envs on the same step by the
    cuff-force rule. Without servos float32 rounding shows in the transient joint velocities
    and cuff forces (``TORQUE_TRANSIENT_TOL``, as in tests/test_batch_parity.py)."""
    unit_actions = ([0.0] * 12, [0, -0.1, 0.1, 0, 0, 0] * 2)
    kwargs = {"control_mode": "torque"}
    cpus = [cpu_episode(ENV, np.asarray(a, np.float32), max_steps=60, **kwargs)
            for a in unit_actions]
    out = batched_rollout(ENV, np.repeat(np.asarray(unit_actions, np.float32)[None], 60,
                                         axis=0), **kwargs)
    layout = gym.make(ENV, **kwargs).unwrapped.agent_layout
    transient = np.zeros(layout.size, bool)
    for name in ("joint_velocity", "cuff_force"):
        transient[layout.slice(name)] = True
    for world, cpu in enumerate(cpus):
        assert cpu["violation"] == "cuff_force"
        stop = len(cpu["actions"]) - 1
        assert int(np.flatnonzero(out["done"][:, world])[0]) == stop
        assert out["violation"][stop, world] == batch.RULE_CODES["cuff_force"]
        error = np.abs(out["obs"][:stop + 1, world] - cpu["obs"][1:])
        assert error[:, ~transient].max() < OBS_TOL
        assert error[:, transient].max() < TORQUE_TRANSIENT_TOL
        assert out["rewards"][:stop + 1, world].sum() == pytest.approx(cpu["rewards"].sum(),
                                                                      rel=RETURN_RTOL)
