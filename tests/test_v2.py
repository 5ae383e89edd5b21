"""The ``-v2`` ids: the agent observation (rehabbot.tasks.agent_observation) and actions in
Box(-1, 1) (rehabbot.envs.control.UnitActions) over the -v1 task. The physics and the reward
are the -v1 id's, step for step; what the agent sees is computed from the paper's fields as
documented; bad settings are refused by name."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.registration import (
    BILATERAL_IDS,
    CONDITION_VARIANTS,
    ENV_SPECS,
    POPULATION_VARIANTS,
    V1_IDS,
    V2_IDS,
)
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.tasks.agent_observation import AgentObservation, agent_layout

BASE_V2 = tuple(i for i in V2_IDS if i not in CONDITION_VARIANTS and i not in POPULATION_VARIANTS)


def test_every_v1_id_has_a_v2_id_with_the_same_task() -> None:
    assert len(V2_IDS) == len(V1_IDS) == 14
    for v1, v2 in zip(V1_IDS, V2_IDS, strict=True):
        assert v2 == v1.replace("-v1", "-v2") and v2 in ENV_SPECS
        kwargs = dict(ENV_SPECS[v2][0])
        assert kwargs.pop("observation") == "agent" and kwargs.pop("action_scale") == "unit"
        assert kwargs == ENV_SPECS[v1][0]
    assert "rehabbot/rehab-bilateral-v2" in BILATERAL_IDS


@pytest.mark.parametrize("env_id", BASE_V2)
def test_v2_steps_as_v1_with_actions_scaled(env_id: str) -> None:
    """Every action u of -v2 is the -v1 action center + half * u: the same paper observation,
    reward and info, step for step (random actions, 60 steps)."""
    v1, v2 = gym.make(env_id.replace("-v2", "-v1")), gym.make(env_id)
    base = v2.unwrapped
    low, high = base.controller.clip_low.astype(float), base.controller.clip_high.astype(float)
    assert v2.action_space == gym.spaces.Box(-1.0, 1.0, v1.action_space.shape, np.float32)
    obs1, _ = v1.reset(seed=3)
    _, info2 = v2.reset(seed=3)
    np.testing.assert_array_equal(info2["paper_observation"], obs1)
    rng = np.random.default_rng(0)
    for _ in range(60):
        unit = rng.uniform(-1, 1, v2.action_space.shape).astype(np.float32)
        native = ((high + low) / 2 + (high - low) / 2 * unit).astype(np.float32)
        obs1, r1, t1, tr1, i1 = v1.step(native)
        obs2, r2, t2, tr2, i2 = v2.step(unit)
        np.testing.assert_array_equal(i2["paper_observation"], obs1)
        np.testing.assert_array_equal(base.paper_observation(), obs1)
        assert (r1, t1, tr1) == (r2, t2, tr2)
        assert i1["safety_violation"] == i2["safety_violation"]
        assert v2.observation_space.contains(obs2)
        if t1:
            break


def test_the_agent_observation_is_what_its_docstring_says() -> None:
    env = gym.make("rehabbot/rehab-knee-v2")
    base: RehabEnv = env.unwrapped
    layout = base.agent_layout
    assert layout.size == env.observation_space.shape[0] == 50
    expert = ScriptedExpert(env)
    obs, info = env.reset(seed=5, options={"exercise": 1, "weight_level": 4})
    seen_last = False
    for _ in range(1000):
        paper = info["paper_observation"].astype(float)
        p = base.layout
        error = paper[p.slice("theta_star")] - paper[p.slice("theta")]
        np.testing.assert_allclose(obs[layout.slice("joint_error_fine")],
                                   np.tanh(error / 0.05), atol=1e-6)
        np.testing.assert_allclose(obs[layout.slice("joint_error")], np.tanh(error / 0.5),
                                   atol=1e-6)
        tool = paper[p.slice("p_star")] - paper[p.slice("p")]
        np.testing.assert_allclose(obs[layout.slice("tool_error_fine")], np.tanh(tool / 0.05),
                                   atol=1e-6)
        i, n = info["target_index"], info["num_targets"]
        following = base.target_sequence.robot_rad
        expected_next = (np.zeros(6) if i == n - 1 else
                         np.tanh((following[i + 1] - following[i]) / 0.5))
        seen_last |= i == n - 1
        np.testing.assert_allclose(obs[layout.slice("next_target")], expected_next, atol=1e-6)
        lead = base.controller.setpoint_rad - paper[p.slice("theta")]
        np.testing.assert_allclose(obs[layout.slice("setpoint_lead")], np.tanh(lead / 0.05),
                                   atol=1e-5)
        force = obs[layout.index("cuff_force")]
        np.testing.assert_allclose(force, info["interaction_force_n"] / base.safety.force_limit_n,
                                   rtol=1e-5, atol=1e-7)
        np.testing.assert_array_equal(obs[layout.slice("exercise")], [0.0, 1.0])
        assert obs[layout.index("weight_level")] == 1.0  # level 4
        assert obs[layout.index("target_progress")] == pytest.approx(2 * i / (n - 1) - 1)
        assert np.all(np.abs(obs) <= 2.0)
        obs, _, terminated, truncated, info = env.step(expert(obs))
        if terminated or truncated:
            break
    assert info["is_success"] and seen_last


@pytest.mark.slow
def test_the_expert_finishes_every_v2_id_from_the_agent_observation() -> None:
    """The scripted expert reads the joint errors back from the agent observation (the tanh
    fields) and acts in Box(-1, 1): one episode of every -v2 id, as on -v1."""
    for env_id in V2_IDS:
        if env_id == "rehabbot/rehab-knee-resistive-v2":
            continue  # as on -v1 (tests/test_experts.py): the full-speed expert meets the limit
        env = gym.make(env_id)
        expert = ScriptedExpert(env)
        obs, info = env.reset(seed=11)
        done = False
        while not done:
            action = expert(obs)
            assert env.action_space.contains(action)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        assert info["is_success"], (env_id, info["safety_violation"])


def test_unit_actions_are_checked_and_clipped_by_the_unit_box() -> None:
    env = gym.make("rehabbot/rehab-reach-v2")
    env.reset(seed=0)
    *_, info = env.step(np.array([1.5, 0, 0, 0, 0, -3.0], np.float32))
    assert info["action_clipped"] == 2
    *_, info = env.step(np.ones(6, np.float32))
    assert info["action_clipped"] == 0
    with pytest.raises(ValueError, match=r"non-finite values at indices \[2\]"):
        env.step(np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(ValueError, match=r"shape \(5,\)"):
        env.step(np.zeros(5))


@pytest.mark.parametrize(("kwarg", "value"), [("observation", "learned"),
                                              ("action_scale", "normalised"),
                                              ("observation", True)])
def test_bad_interface_settings_are_refused_by_name(kwarg: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"{kwarg}={value!r} is not one of"):
        RehabEnv(**{kwarg: value})


def test_the_agent_observation_survives_an_unstable_state() -> None:
    """Non-finite joint velocities (an unstable step) read as 0; a non-finite cuff force as 2:
    the observation stays finite and inside its space."""
    env = gym.make("rehabbot/rehab-reach-v2")
    base = env.unwrapped
    env.reset(seed=0)
    base.data.qvel[base.handle.dof_adr[:2]] = [np.nan, np.inf]
    base.data.efc_force[:3] = np.nan  # the cuff's constraint force
    out = base._observation_out({})
    assert np.all(np.isfinite(out)) and env.observation_space.contains(out)
    assert out[base.agent_layout.index("cuff_force")] == 2.0
    with pytest.raises(ValueError, match="upper bound must exceed"):
        AgentObservation(6, 1, 2, np.ones(6), np.ones(6), -np.ones(3), np.ones(3), [1.0])
    with pytest.raises(ValueError, match="n_arms=3"):
        agent_layout(6, 3, 2)


def test_v2_observation_space_is_the_same_for_every_patient() -> None:
    """One policy serves a population: the agent space does not depend on the patient."""
    env = gym.make("rehabbot/rehab-knee-population-v2")
    space = env.observation_space
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        assert space.contains(obs)
        assert env.unwrapped.current_env.observation_space == space


def test_the_rollout_records_angles_not_agent_fields_on_v2() -> None:
    """The clinical evaluator's episode record (rehabbot.rl.rollout) reads the robot's and the
    patient's angles and the tool position from the paper's fields, which a -v2 observation
    does not hold: the same expert episode records the same kinematics on -v1 and -v2 (never the
    tracking errors read as angles)."""
    from rehabbot.rl.policies import load_policy
    from rehabbot.rl.rollout import run_episode

    episodes = {}
    for version in ("v1", "v2"):
        env = gym.make(f"rehabbot/rehab-knee-{version}", exercise=0, weight_level=2)
        episodes[version] = run_episode(env, load_policy("expert", env), seed=0)
        env.close()
    v1, v2 = episodes["v1"], episodes["v2"]
    assert v1.success and v2.success
    steps = min(v1.length, v2.length)
    # The expert reads its errors from a different observation on each id (rounding differs
    # in the last bits), so the paths agree to a milliradian, not bit for bit; reading the
    # agent fields instead would be off by radians.
    for field in ("robot_qpos_rad", "patient_qpos_rad", "tool_pos_m"):
        np.testing.assert_allclose(getattr(v2, field)[:steps], getattr(v1, field)[:steps],
                                   atol=1e-3, err_msg=field)
    speed = np.abs(np.diff(v2.robot_qpos_rad, axis=0)) / v2.dt_s
    assert speed.max() < np.pi  # the UR5e's fastest joint
