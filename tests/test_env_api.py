"""Gymnasium conformance: env checker, determinism (in and across processes), vector envs,
pickling."""

from __future__ import annotations

import hashlib
import os
import pickle
import shutil
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from rehabbot.envs.registration import ENV_SPECS, entry_point_of
from rehabbot.rl.experts import ScriptedExpert

PAPER_IDS = tuple(ENV_SPECS)

CHECK_ENV = """
import sys, traceback, warnings
import gymnasium as gym, rehabbot
from gymnasium.utils.env_checker import check_env
# One process checks every id given (starting Python, Xvfb and MuJoCo once, not per id).
# gym.make itself warns that a -v0 id is "out of date" (a -v1 exists): Gymnasium's notice,
# not the checker's; the checker must find nothing.
render_checked = set()
for env_id in sys.argv[1:]:
    env = gym.make(env_id)
    # The render modes are checked once per scene (entry point, limb, side): they draw the
    # same scene whatever the version, condition or population (software GL makes a render
    # check 12x the cost of the rest of the checker).
    spec = gym.spec(env_id)
    scene = (str(spec.entry_point), spec.kwargs.get("limb"), spec.kwargs.get("side"))
    skip_render = scene in render_checked
    render_checked.add(scene)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            check_env(env.unwrapped, skip_render_check=skip_render)
        except Exception:
            print("FAILED", env_id, traceback.format_exc().replace(chr(10), " | "))
            continue
        finally:
            env.close()
    for w in caught:
        print("WARNING", env_id, w.message)
    print("CHECKED", env_id, "render" if not skip_render else "")
"""


def _check_envs(env_ids: list[str], expect_render_checks: int = 1) -> None:
    """Gymnasium's env checker on each id, every render mode (``human`` included) opened once
    per scene: run where there is a display (``make test`` runs under xvfb), or under
    ``xvfb-run``."""
    cmd = [sys.executable, "-c", CHECK_ENV, *env_ids]
    if not os.environ.get("DISPLAY"):
        if shutil.which("xvfb-run") is None:
            pytest.skip("needs a display or xvfb-run for the human render mode")
        cmd = ["xvfb-run", "-a", *cmd]
    # A hang guard only (a loaded machine takes ten times as long as an idle one).
    result = subprocess.run(cmd, capture_output=True, text=True,
                            timeout=600 + 60 * len(env_ids))
    assert result.returncode == 0, result.stderr[-3000:]
    lines = result.stdout.splitlines()
    problems = [line for line in lines if line.startswith(("FAILED", "WARNING"))]
    assert not problems, "\n".join(problems)
    checked = [line.split() for line in lines if line.startswith("CHECKED")]
    assert [words[1] for words in checked] == env_ids
    assert sum(words[2:] == ["render"] for words in checked) == expect_render_checks


@pytest.mark.slow
def test_gymnasium_env_checker_passes_without_warnings():
    _check_envs(["rehabbot/rehab-reach-v1"])


@pytest.mark.slow
def test_gymnasium_env_checker_passes_without_warnings_on_every_id():
    # Newest first, so that each scene's render modes are checked on its current id.
    env_ids = [env_id for env_id in reversed(PAPER_IDS) if not env_id.endswith("reach-v1")]
    scenes = {(entry_point_of(i), ENV_SPECS[i][0].get("limb"), ENV_SPECS[i][0].get("side"))
              for i in env_ids}
    _check_envs(env_ids, expect_render_checks=len(scenes))


# One id per family: the paper's, the learnable reward, the agent interface, a condition
# variant, a population, both arms, the musculoskeletal patient; and the second robot.
FAMILIES = [("rehabbot/rehab-reach-v0", {}), ("rehabbot/rehab-knee-v1", {}),
            ("rehabbot/rehab-hip-v2", {}), ("rehabbot/rehab-reach-spastic-v2", {}),
            ("rehabbot/rehab-knee-population-v2", {}), ("rehabbot/rehab-bilateral-v2", {}),
            ("rehabbot/rehab-knee-myo-v2", {}), ("rehabbot/rehab-reach-v2", {"robot": "fr3"})]


@pytest.fixture
def headless(monkeypatch):
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)


@pytest.mark.slow
@pytest.mark.parametrize(("env_id", "kwargs"), FAMILIES,
                         ids=[f"{i.split('/')[1]}{'-' + k['robot'] if k else ''}"
                              for i, k in FAMILIES])
def test_env_checker_passes_headless_with_the_render_check_skipped(env_id, kwargs, headless):
    """What docs/envs.md tells a headless user to run, on one id of each family."""
    if "-myo-" in env_id:
        pytest.importorskip("myo_sim", reason='the -myo- ids need pip install "rehabbot[myo]"')
    env = gym.make(env_id, **kwargs)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()
    assert [str(w.message) for w in caught] == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display check is Linux's")
def test_env_checker_headless_names_the_skip(headless):
    """Without a display the checker's human render stops with an error that says what to do."""
    env = gym.make("rehabbot/rehab-hip-v2")
    try:
        with pytest.raises(RuntimeError, match=r"needs a display .*skip_render_check=True"), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore")
            check_env(env.unwrapped)
    finally:
        env.close()


# Keys that a third-party patch of Gymnasium's TimeLimit adds to the info of an episode's last
# step: importing RL Zoo (rl_zoo3.gym_patches) does so for every env made in the process after.
WRAPPER_INFO_KEYS = {"TimeLimit.truncated"}


def _episode_digest(env_id: str, seed: int, steps: int = 1000) -> tuple[str, list]:
    """Hash of observations, rewards and infos for ``steps`` steps of seeded random actions."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    digest = hashlib.sha256()
    obs, info = env.reset(seed=seed)
    draws = [(info["exercise"], info["weight_level"])]
    digest.update(obs.tobytes())
    for _ in range(steps):
        action = rng.uniform(low, high).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        digest.update(obs.tobytes())
        digest.update(np.float64(reward).tobytes())
        for key in sorted(info.keys() - WRAPPER_INFO_KEYS):
            value = info[key]
            digest.update(key.encode())
            digest.update(np.asarray(value if value is not None else -1).tobytes())
        if terminated or truncated:
            obs, info = env.reset()
            draws.append((info["exercise"], info["weight_level"]))
            digest.update(obs.tobytes())
    env.close()
    return digest.hexdigest(), draws


DIGEST = """
import importlib.util
import sys
sys.path.insert(0, sys.argv[3])
if sys.argv[4:] == ["zoo-patched"] and importlib.util.find_spec("rl_zoo3"):
    import rl_zoo3.gym_patches  # replaces Gymnasium's TimeLimit, as importing RL Zoo does
import rehabbot
from test_env_api import _episode_digest
print(_episode_digest(sys.argv[1], int(sys.argv[2]))[0])
"""


@pytest.mark.parametrize("env_id", ["rehabbot/rehab-reach-v0",
                                    pytest.param("rehabbot/rehab-knee-v0",
                                                 marks=pytest.mark.slow)])
@pytest.mark.slow
def test_same_seed_same_actions_give_bit_identical_episodes_in_and_across_processes(env_id):
    first, _draws = _episode_digest(env_id, seed=7)
    second, _ = _episode_digest(env_id, seed=7)
    assert first == second
    tests_dir = os.path.dirname(__file__)
    # the same in a fresh process, and in one where RL Zoo patched Gymnasium's TimeLimit (as
    # in a test process that ran RL Zoo before)
    other = [subprocess.run([sys.executable, "-c", DIGEST, env_id, "7", tests_dir, *patch],
                            capture_output=True, text=True, check=True).stdout.strip()
             for patch in ([], ["zoo-patched"])]
    assert other == [first, first]
    different, _ = _episode_digest(env_id, seed=8)
    assert different != first


def test_same_seed_after_other_episodes_gives_the_same_episode():
    env = gym.make("rehabbot/rehab-hip-v0")
    obs_a, _info_a = env.reset(seed=3)
    actions = [env.action_space.sample() for _ in range(50)]
    run_a = [env.step(a)[0] for a in actions]
    for seed in (11, 12, 13):  # other episodes change the weight level and the exercise
        env.reset(seed=seed)
        for a in actions[:10]:
            env.step(a)
    obs_b, _info_b = env.reset(seed=3)
    run_b = [env.step(a)[0] for a in actions]
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(np.array(run_a), np.array(run_b))


def test_observations_are_fresh_arrays_not_shared_between_steps():
    env = gym.make("rehabbot/rehab-reach-v0")
    obs0, _ = env.reset(seed=0)
    copy0 = obs0.copy()
    obs1, *_ = env.step(env.action_space.high)
    assert obs1 is not obs0
    np.testing.assert_array_equal(obs0, copy0)
    assert not np.array_equal(obs0, obs1), "observations change from step to step"


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_envs_match_single_envs(mode):
    n = 2
    vec = gym.make_vec("rehabbot/rehab-reach-v0", num_envs=n, vectorization_mode=mode)
    try:
        obs, _infos = vec.reset(seed=[5, 6])
        assert obs.shape == (n, 23) and obs.dtype == np.float32
        rng = np.random.default_rng(0)
        actions = rng.uniform(-np.pi / 400, np.pi / 400, (20, n, 6)).astype(np.float32)
        vec_obs = [obs]
        for a in actions:
            obs, reward, _terminated, _truncated, _infos = vec.step(a)
            assert reward.shape == (n,)
            vec_obs.append(obs)
    finally:
        vec.close()
    for k, seed in enumerate((5, 6)):
        env = gym.make("rehabbot/rehab-reach-v0")
        single = [env.reset(seed=seed)[0]]
        single += [env.step(a[k])[0] for a in actions]
        np.testing.assert_array_equal(np.array(single), np.array(vec_obs)[:, k])


def _vector_rollout(mode: str, steps: int = 60) -> dict[str, np.ndarray]:
    """Torque-mode random actions (episodes end every few steps on the cuff-force rule, so the
    vector env resets its sub-envs many times)."""
    vec = gym.make_vec("rehabbot/rehab-hip-v0", num_envs=2, vectorization_mode=mode,
                       control_mode="torque")
    try:
        obs, _ = vec.reset(seed=[21, 22])
        vec.action_space.seed(3)
        out: dict[str, list] = {"obs": [obs], "reward": [], "terminated": [], "truncated": [],
                                "force": [], "torque": [], "level": []}
        for _ in range(steps):
            obs, reward, terminated, truncated, infos = vec.step(vec.action_space.sample())
            out["obs"].append(obs)
            out["reward"].append(reward)
            out["terminated"].append(terminated)
            out["truncated"].append(truncated)
            out["force"].append(infos["interaction_force_n"])
            out["torque"].append(infos["robot_torque_nm"])
            out["level"].append(infos["weight_level"])
    finally:
        vec.close()
    return {k: np.array(v) for k, v in out.items()}


def test_vector_sync_and_async_are_bit_identical_across_autoresets():
    sync, async_ = _vector_rollout("sync"), _vector_rollout("async")
    assert sync["terminated"].sum() >= 6, "the rollout must cross several autoresets"
    assert len(np.unique(sync["level"])) > 1, "resets draw new weight levels"
    for key in sync:
        np.testing.assert_array_equal(sync[key], async_[key], err_msg=key)


def test_env_and_scripted_expert_pickle_mid_episode_and_continue_identically():
    env = gym.make("rehabbot/rehab-knee-v0")
    expert = ScriptedExpert(env)
    obs, _ = env.reset(seed=4)
    for _ in range(60):  # mid-episode: some targets reached, the limb moving
        obs, _, terminated, _, info = env.step(expert(obs))
        assert not terminated
    assert info["target_index"] > 0
    # Pickled together, the clone's expert drives the clone's env.
    clone_env, clone_expert = pickle.loads(pickle.dumps((env, expert)))
    assert clone_env.unwrapped.data is not env.unwrapped.data
    assert clone_expert._base is clone_env.unwrapped
    clone_obs = obs.copy()
    for _ in range(500):
        action = expert(obs)
        np.testing.assert_array_equal(action, clone_expert(clone_obs))
        obs, ra, ta, _, ia = env.step(action)
        clone_obs, rb, tb, _, ib = clone_env.step(action)
        np.testing.assert_array_equal(obs, clone_obs)
        assert ra == rb and ta == tb and ia["target_index"] == ib["target_index"]
        np.testing.assert_array_equal(ia["robot_torque_nm"], ib["robot_torque_nm"])
        if ta:
            break
    assert ia["is_success"] and ib["is_success"], "both finished the exercise"
    # A pickled expert alone brings its own copy of the env and predicts the same actions.
    lone = pickle.loads(pickle.dumps(expert))
    np.testing.assert_array_equal(lone(obs), expert(obs))
    assert lone._base is not env.unwrapped


def test_step_after_close_raises_and_double_close_is_a_noop():
    env = gym.make("rehabbot/rehab-reach-v0")
    env.reset(seed=0)
    env.close()
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.unwrapped.step(np.zeros(6, np.float32))


def test_step_before_reset_is_refused_by_gymnasium():
    env = gym.make("rehabbot/rehab-reach-v0")
    with pytest.raises(gym.error.ResetNeeded), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.step(np.zeros(6, np.float32))
