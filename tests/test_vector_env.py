"""The CPU vector env (rehabbot.envs.vector): Gymnasium's door, the same results as
``SyncVectorEnv`` bit for bit (every autoreset mode, truncation, populations, two arms), and
the refusals."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from rehabbot.envs.vector import RehabVectorEnv, checked_actions, make_vec, merge_infos

KNEE_V2 = "rehabbot/rehab-knee-v2"
# What a third-party patch of Gymnasium's TimeLimit adds to the info of an episode's last
# step (importing RL Zoo, rl_zoo3.gym_patches, does so for every env made in the process
# after): SyncVectorEnv's envs have a TimeLimit, the vector env's worlds do not.
WRAPPER_INFO_KEYS = {"TimeLimit.truncated", "_TimeLimit.truncated"}


def _without_wrapper_keys(value):
    if isinstance(value, dict):
        return {k: _without_wrapper_keys(v) for k, v in value.items()
                if k not in WRAPPER_INFO_KEYS}
    if isinstance(value, tuple):
        return tuple(_without_wrapper_keys(v) for v in value)
    return value


def _same(a, b, where: str) -> None:
    """Bit-for-bit equality of two vector envs' outputs (arrays, nested dicts, objects)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), f"{where}: keys {set(a) ^ set(b)}"
        for key in a:
            _same(a[key], b[key], f"{where}[{key!r}]")
        return
    if isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{k}]")
        return
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, \
        f"{where}: {a.dtype}{a.shape} against {b.dtype}{b.shape}"
    if a.dtype == object:
        for k, (x, y) in enumerate(zip(a.ravel(), b.ravel(), strict=True)):
            if isinstance(x, dict | np.ndarray) or isinstance(y, dict | np.ndarray):
                _same(x, y, f"{where}[{k}]")
            else:
                assert x == y, f"{where}[{k}]: {x!r} != {y!r}"
    else:
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), where


def _rollout_both(env_id: str, n: int, steps: int, mode: AutoresetMode, seed: int,
                  perturb: float = 0.0, **kwargs) -> tuple[int, int]:
    """Step the vector env and SyncVectorEnv of the same id on the same random actions;
    returns (episodes ended, first step where they differ or -1)."""
    vector = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, **kwargs)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, **kwargs)
    ended, differs = 0, -1
    try:
        assert isinstance(vector.unwrapped, RehabVectorEnv)
        _same(vector.reset(seed=seed), _without_wrapper_keys(sync.reset(seed=seed)), "reset")
        rng = np.random.default_rng(seed)
        for t in range(steps):
            actions = rng.uniform(-1.0, 1.0, vector.action_space.shape).astype(np.float32)
            actions *= vector.single_action_space.high  # every mode's box
            out = vector.step(actions)
            shifted = actions.copy()
            shifted[-1, 0] += perturb
            expected = _without_wrapper_keys(sync.step(shifted))
            try:
                _same(out, expected, f"step {t}")
            except AssertionError:
                if perturb:
                    return ended, t
                raise
            ended += int(np.sum(out[2] | out[3]))
            if mode is AutoresetMode.DISABLED and (out[2] | out[3]).any():
                mask = out[2] | out[3]
                _same(vector.reset(options={"reset_mask": mask}),
                      _without_wrapper_keys(sync.reset(options={"reset_mask": mask.copy()})),
                      f"reset at {t}")
    finally:
        vector.close()
        sync.close()
    return ended, differs


@pytest.mark.parametrize("env_id, mode", [
    ("rehabbot/rehab-knee-v0", AutoresetMode.NEXT_STEP),
    ("rehabbot/rehab-reach-v2", AutoresetMode.SAME_STEP),
    ("rehabbot/rehab-knee-resistive-v2", AutoresetMode.DISABLED),
])
def test_equals_sync_vector_env_bit_for_bit(env_id, mode) -> None:
    ended, _ = _rollout_both(env_id, 3, 60, mode, seed=5, max_episode_steps=20)
    assert ended >= 6  # every world truncated at least twice: restarts are compared too


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["rehabbot/rehab-reach-population-v2",
                                    "rehabbot/rehab-bilateral-v2",
                                    "rehabbot/rehab-reach-tremor-v1"])
def test_equals_sync_vector_env_on_populations_two_arms_and_tremor(env_id) -> None:
    ended, _ = _rollout_both(env_id, 2, 40, AutoresetMode.NEXT_STEP, seed=2,
                             max_episode_steps=15)
    assert ended >= 4


def test_the_comparison_catches_a_tiny_change() -> None:
    """The comparison is exact because both run the same floating-point operations in the
    same order on the same machine (so it holds on any machine); it is not vacuous: one
    world's action moved by 1e-6 (a few float32 steps) shows in the first step."""
    _ended, differs = _rollout_both(KNEE_V2, 2, 5, AutoresetMode.NEXT_STEP, seed=1,
                                    perturb=1e-6)
    assert differs == 0


def test_threads_do_not_change_the_results() -> None:
    outputs = []
    for threads in (1, 2, 3):
        vector = make_vec(KNEE_V2, 3, threads=threads, max_episode_steps=10)
        rng = np.random.default_rng(0)
        run = [vector.reset(seed=11)]
        for _ in range(25):
            run.append(vector.step(rng.uniform(-1, 1, vector.action_space.shape)))
        vector.close()
        outputs.append(run)
    for run in outputs[1:]:
        for k, (a, b) in enumerate(zip(outputs[0], run, strict=True)):
            _same(a, b, f"call {k}")


def test_the_door_passes_kwargs_and_the_time_limit() -> None:
    vector = gym.make_vec("rehabbot/rehab-knee-v1", num_envs=2, max_episode_steps=7,
                          weight_level=3)
    try:
        base = vector.unwrapped
        assert isinstance(base, RehabVectorEnv) and base.max_episode_steps == 7
        assert all(env.max_episode_steps == 7 for env in base.envs)  # the envs' horizon too
        _obs, info = vector.reset(seed=0)
        assert info["weight_level"].tolist() == [3, 3]
        for _ in range(7):
            _obs, _r, terminated, truncated, _info = vector.step(
                np.zeros(vector.action_space.shape, np.float32))
        assert truncated.all() and not terminated.any()
        assert vector.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    finally:
        vector.close()


def test_bad_actions_are_refused_before_any_world_moves() -> None:
    vector = make_vec(KNEE_V2, 3)
    try:
        with pytest.raises(gym.error.ResetNeeded):
            vector.step(np.zeros(vector.action_space.shape, np.float32))
        vector.reset(seed=0)
        before = [env.controller.setpoint_rad.copy() for env in vector.envs]
        bad = np.zeros(vector.action_space.shape, np.float32)
        bad[2, 1] = np.nan
        with pytest.raises(ValueError, match=r"world 2 at indices \[1\]"):
            vector.step(bad)
        with pytest.raises(ValueError, match="shape"):
            vector.step(np.zeros((2, vector.single_action_space.shape[0])))
        with pytest.raises(ValueError, match="dtype bool"):
            vector.step(np.zeros(vector.action_space.shape, bool))
        for env, setpoint in zip(vector.envs, before, strict=True):
            assert np.array_equal(env.controller.setpoint_rad, setpoint)
    finally:
        vector.close()


@pytest.mark.parametrize("kwargs, message", [
    ({"num_envs": 0}, "num_envs=0"),
    ({"num_envs": 2, "threads": 0}, "threads=0"),
    ({"num_envs": 2, "autoreset_mode": "sometimes"}, "autoreset_mode='sometimes'"),
    ({"num_envs": 2, "max_episode_steps": -1}, "max_episode_steps=-1"),
])
def test_bad_settings_are_named(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        RehabVectorEnv(KNEE_V2, **kwargs)


def test_an_unknown_id_and_a_replaced_condition_are_refused() -> None:
    with pytest.raises(ValueError, match="not a RehabBot id"):
        RehabVectorEnv("rehabbot/rehab-elbow-v9", 2)
    with pytest.raises(ValueError, match="would replace the condition"):
        gym.make_vec("rehabbot/rehab-knee-weak-v2", num_envs=2, condition={"spasticity_mas": "2"})


def test_disabled_autoreset_needs_a_reset_of_ended_worlds() -> None:
    vector = make_vec(KNEE_V2, 2, autoreset_mode="disabled", max_episode_steps=2)
    try:
        vector.reset(seed=0)
        zeros = np.zeros(vector.action_space.shape, np.float32)
        vector.step(zeros)
        vector.step(zeros)
        with pytest.raises(gym.error.ResetNeeded, match=r"worlds \[0, 1\]"):
            vector.step(zeros)
        vector.reset(options={"reset_mask": np.array([True, True])})
        vector.step(zeros)
        with pytest.raises(ValueError, match="reset_mask"):
            vector.reset(options={"reset_mask": np.array([1, 0])})
    finally:
        vector.close()


def test_seeds_as_a_list_and_the_attribute_access() -> None:
    vector = make_vec(KNEE_V2, 2)
    try:
        obs, _info = vector.reset(seed=[3, 4])
        single = gym.make(KNEE_V2)
        assert np.array_equal(obs[1], single.reset(seed=4)[0])
        single.close()
        with pytest.raises(ValueError, match="2 worlds"):
            vector.reset(seed=[1, 2, 3])
        assert vector.get_attr("frame_skip") == (vector.envs[0].frame_skip,) * 2
        assert len(vector.call("setpoints_for", np.zeros(vector.single_action_space.shape,
                                                         np.float32))) == 2
    finally:
        vector.close()


def test_merge_infos_builds_what_add_info_builds() -> None:
    """Worlds with other keys, other types and nested dicts: the same arrays and masks as
    Gymnasium's ``_add_info`` world by world."""
    infos = [{"a": 1.0, "b": np.arange(2.0), "c": None, "d": {"x": 1}},
             {"a": 2, "e": "text", "d": {"y": True}},
             {"b": np.ones(2), "a": np.float32(3.5), "c": "stop"}]
    sync = SyncVectorEnv([lambda: gym.make("CartPole-v1")] * 3)
    expected: dict = {}
    for i, info in enumerate(infos):
        expected = sync._add_info(expected, info, i)
    sync.close()
    _same(merge_infos(infos), expected, "info")


def test_checked_actions_names_worlds() -> None:
    good = checked_actions([[0.0, 1.0], [1, 2]], (2, 2))
    assert good.shape == (2, 2)
    with pytest.raises(ValueError, match=r"2 of 3 worlds: world 0 .*; world 2"):
        checked_actions([[np.inf, 0.0], [0.0, 0.0], [0.0, np.nan]], (3, 2))
    with pytest.raises(ValueError, match="cannot be read"):
        checked_actions([[0.0], [0.0, 1.0]], (2, 2))
