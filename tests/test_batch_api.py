"""rehabbot.batch's interface: what it refuses (by name), that ``import rehabbot`` does not
load it, and a jitted, vmapped reset and step with exercises drawn per world."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("warp")
pytest.importorskip("mujoco.mjx")

import rehabbot.batch as batch  # noqa: E402


def test_import_rehabbot_loads_neither_batch_nor_jax():
    code = ("import sys, gymnasium as gym, rehabbot; gym.make('rehabbot/rehab-reach-v2'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'warp', 'flax') "
            "or m.startswith('rehabbot.batch') or m.startswith('mujoco.mjx')))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=True)
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize(("env_id", "kwargs", "named"), [
    ("rehabbot/rehab-bilateral-v1", {}, "rehab-bilateral-v1"),
    ("rehabbot/rehab-reach-v1", {}, "rehab-reach-v1"),
    ("rehabbot/rehab-reach-myo-v2", {}, "rehab-reach-myo-v2"),
    ("rehabbot/rehab-reach-population-v1", {}, "rehab-reach-population-v1"),
    ("rehabbot/rehab-reach-v2", {"action_scale": "native"}, "action_scale='native'"),
    ("rehabbot/rehab-reach-v2", {"reward": {"design": "progress", "safety_penalty_steps": 100}},
     "safety_penalty_steps=100"),
    ("rehabbot/rehab-reach-v2", {"naconmax": 0}, "naconmax=0"),
])
def test_refuses_what_is_not_built_yet(env_id, kwargs, named):
    with pytest.raises(ValueError, match=named.replace("(", r"\(").replace(")", r"\)")):
        batch.make(env_id, **kwargs)


@pytest.mark.slow
def test_jit_vmap_reset_and_step_draw_exercises_per_world():
    env = batch.make("rehabbot/rehab-knee-v2", naconmax=64)
    worlds = 4
    reset, step = jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))
    state = reset(jax.random.split(jax.random.key(3), worlds))
    exercises = np.asarray(state.info["exercise"])
    assert exercises.shape == (worlds,)
    assert set(exercises.tolist()) <= set(range(len(env.cpu_env.targets)))
    assert state.obs.shape == (worlds, env.observation_size)
    one_hot = np.asarray(state.obs)[:, env.tables.exercise_start:][:, :len(env.cpu_env.targets)]
    assert (one_hot.argmax(axis=1) == exercises).all()
    state = step(state, np.zeros((worlds, env.action_size), np.float32))
    assert np.isfinite(np.asarray(state.obs)).all()
    assert (np.asarray(state.done) == 0).all()
    assert np.allclose(np.asarray(state.reward), -env.tables.time_cost, atol=0.05)


@pytest.mark.slow
def test_gymnasium_vector_door():
    import gymnasium as gym

    env_id, condition_id = "rehabbot/rehab-hip-v2", "rehabbot/rehab-knee-weak-v2"
    before = {name: gym.registry[name].vector_entry_point for name in gym.registry}
    batch.register_vector_entry_points()
    try:
        vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                           exercise=0, weight_level=0)
        # A condition id gets its registered condition, and its patient drive.
        weak = gym.make_vec(condition_id, num_envs=2, vectorization_mode="vector_entry_point")
    finally:
        for name, entry_point in before.items():
            gym.registry[name].vector_entry_point = entry_point
    assert isinstance(weak, batch.BatchedVectorEnv) and weak.env.patient is not None
    assert weak.env.cpu_env.config.condition == gym.make(condition_id).unwrapped.config.condition
    assert isinstance(vec, batch.BatchedVectorEnv)
    obs, info = vec.reset(seed=0)
    assert obs in vec.observation_space
    cpu_obs, _ = gym.make(env_id).reset(seed=0, options={"exercise": 0, "weight_level": 0})
    assert np.abs(obs - cpu_obs).max() < 1e-3
    for _ in range(2):
        obs, reward, terminated, truncated, info = vec.step(np.zeros((2, 6), np.float32))
    assert obs.shape == (2, vec.single_observation_space.shape[0])
    assert reward.shape == terminated.shape == truncated.shape == (2,)
    assert not terminated.any() and not truncated.any()
    assert info["safety_violation"].tolist() == [0, 0]
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        vec.step(np.zeros(6, np.float32))
    nan = np.zeros((2, 6), np.float32)
    nan[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"world 1 at indices \[0\]"):
        vec.step(nan)  # after reset too: no world steps
    assert np.isfinite(vec.step(np.zeros((2, 6), np.float32))[0]).all()
    # Reset options, as the CPU env's: every world's first episode.
    obs, _ = vec.reset(seed=1, options={"exercise": 1, "weight_level": 3})
    cpu_obs, _ = gym.make(env_id).reset(seed=0, options={"exercise": 1, "weight_level": 3})
    assert np.abs(obs - cpu_obs).max() < 1e-3
    assert np.abs(obs - vec.reset(seed=1)[0]).max() > 1e-2  # the options took effect
    for options, named in (({"exercise": 9}, "exercise=9"), ({"weight_level": 7}, "7"),
                           ({"speed": 1}, "speed")):
        with pytest.raises(ValueError, match=named):
            vec.reset(options=options)


def test_vector_door_refuses_non_finite_actions_as_the_cpu_env_does():
    """NaN/inf actions are refused with the CPU env's error type, naming the world and the
    value, before anything is compiled or stepped (the jitted step would read them as 0)."""
    import gymnasium as gym

    env_id = "rehabbot/rehab-reach-v2"
    cpu = gym.make(env_id)
    cpu.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        cpu.step(np.full(6, np.nan, np.float32))
    before = gym.registry[env_id].vector_entry_point
    batch.register_vector_entry_points()
    try:
        door = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    finally:
        gym.registry[env_id].vector_entry_point = before
    for vec in (door, batch.make_vec(env_id, 3)):
        for bad, named in ((np.nan, "nan"), (np.inf, "inf"), (-np.inf, "-inf")):
            actions = np.zeros((3, 6), np.float32)
            actions[1, 4] = bad
            with pytest.raises(ValueError, match=rf"world 1 at indices \[4\]: .*{named}"):
                vec.step(actions)
        actions = np.zeros((3, 6))
        actions[0, 0] = actions[2, 5] = np.nan
        with pytest.raises(ValueError, match=r"2 of 3 worlds: world 0 .*; world 2 "):
            vec.step(actions)
        with pytest.raises(ValueError, match="dtype bool"):
            vec.step(np.zeros((3, 6), bool))
        with pytest.raises(ValueError, match=r"shape \(6,\)"):
            vec.step(np.zeros(6))
        with pytest.raises(gym.error.ResetNeeded):  # good actions pass the check
            vec.step(np.zeros((3, 6), np.float32))


def test_checked_actions_keeps_finite_values_finite():
    from rehabbot.batch.vector import checked_actions

    actions = checked_actions([[1e300, -1e300, 0.5]], (1, 3))
    assert actions.dtype == np.float32 and np.isfinite(actions).all()
    assert actions[0, 2] == np.float32(0.5) and actions[0, 0] > 1 and actions[0, 1] < -1


@pytest.mark.slow
def test_vector_env_resets_in_the_same_step():
    """A world stopped by the cuff-force rule returns the next episode's first observation,
    with the ended episode's last one in info["final_obs"] (Gymnasium's SAME_STEP mode)."""
    vec = batch.make_vec("rehabbot/rehab-reach-v2", 2, exercise=0, weight_level=0)
    first, _ = vec.reset(seed=1)
    actions = np.zeros((2, 6), np.float32)
    actions[0, 0] = -1.0  # pulls the shoulder until the cuff force stops world 0
    for _ in range(200):
        obs, _reward, terminated, truncated, info = vec.step(actions)
        if terminated.any():
            break
    assert terminated.tolist() == [True, False] and not truncated.any()
    assert info["safety_violation"][0] == batch.RULE_CODES["cuff_force"]
    assert info["_final_obs"].tolist() == [True, False]
    assert info["final_obs"][1] is None
    assert np.abs(obs[0] - first[0]).max() < 1e-3
    assert np.abs(info["final_obs"][0] - first[0]).max() > 0.1


def test_tables_follow_the_cpu_env_kwargs():
    """Changing a CPU keyword changes the batched env's table: nothing is copied by hand."""
    kwargs = {"target_tolerance_rad": 0.08, "cuff_force_limit_n": 100.0,
              "reward": {"design": "progress", "time_cost": 0.1, "progress_weight": 5.0},
              "exercise": 1, "weight_level": 3, "frame_skip": 5}
    env = batch.make("rehabbot/rehab-knee-v2", naconmax=16, **kwargs)
    t, cpu = env.tables, env.cpu_env
    assert (t.target_tolerance_rad, t.cuff_force_limits_n.tolist()) == (0.08, [100.0])
    assert (t.time_cost, t.progress_weight) == (0.1, 5.0)
    assert (t.exercise, t.weight_level, t.frame_skip) == (1, 3, 5)
    cpu.reset(seed=0)
    np.testing.assert_array_equal(t.home_setpoints_rad[3], cpu.controller.setpoint_rad)
    np.testing.assert_array_equal(t.targets_rad[1, :len(cpu.target_sequence.robot_rad)],
                                  cpu.target_sequence.robot_rad)
    np.testing.assert_array_equal(t.agent_matrix, cpu.agent_observation_map.matrix)


def test_a_population_restricted_to_conditions_stacks_only_their_patients():
    env = batch.make("rehabbot/rehab-knee-population-v2", patients="test", conditions=[0, 3],
                     naconmax=16)
    assert env.patients.count == 4 == len(env.patient_envs)
    test = env.cpu_env.population
    assert test.name == "test[conditions 0, 3]"
    assert [e.config.patient.condition for e in env.patient_envs] == [
        test.conditions[0], test.conditions[1]] * 2
    with pytest.raises(ValueError, match=r"names condition 3 .* twice"):
        batch.make("rehabbot/rehab-knee-population-v2", conditions=[3, 3], naconmax=16)


@pytest.mark.slow
def test_the_batched_env_prints_nothing():
    """Building, compiling and stepping a batched env prints nothing (Warp announces every
    kernel module it loads unless told to be quiet), in a fresh process."""
    code = ("import jax, rehabbot.batch as b; env = b.make('rehabbot/rehab-reach-v2', "
            "naconmax=16, exercise=0, weight_level=0); "
            "s = jax.jit(env.reset)(jax.random.key(0)); "
            "s = jax.jit(env.step)(s, jax.numpy.zeros(env.action_size)); "
            "s.obs.block_until_ready()")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=600, check=True)
    assert result.stdout == "" and result.stderr == "", (result.stdout[-500:],
                                                         result.stderr[-500:])
