"""The golden episodes (``tests/golden_episodes.py``) are reproduced: every registered id in
every control mode, for every exercise and weight level, gives the recorded observations,
rewards, terminations and ``info`` entries."""

import gymnasium as gym
import numpy as np
import pytest
from golden_episodes import (
    ATOL,
    GOLDEN_PATH,
    IDS,
    MODES,
    RTOL,
    WEIGHT_LEVELS,
    exercises_of,
    load_golden,
    record_rollout,
    rollout_key,
)

import rehabbot  # noqa: F401  (registers the ids)


@pytest.fixture(scope="module")
def golden():
    return load_golden(GOLDEN_PATH)


def test_every_registered_id_has_golden_episodes(golden):
    registered = sorted(env_id for env_id in gym.registry if env_id.startswith("rehabbot/"))
    assert registered == sorted(IDS), "record golden episodes of new ids: tests/golden_episodes.py"
    expected = {rollout_key(i, m, e, lv) for i in IDS for m in MODES for e in exercises_of(i)
                for lv in WEIGHT_LEVELS}
    assert set(golden) == expected


def _first_difference(actual: np.ndarray, expected: np.ndarray) -> str:
    if actual.dtype.kind == "f" or expected.dtype.kind == "f":
        bad = ~np.isclose(actual, expected, rtol=RTOL, atol=ATOL, equal_nan=True)
    else:
        bad = actual != expected
    row = int(np.argwhere(bad.reshape(len(bad), -1).any(axis=1))[0, 0])
    return f"row {row}: {actual[row]!r} != {expected[row]!r}"


@pytest.mark.parametrize("mode", [
    pytest.param(m, marks=() if m == "joint_delta" else pytest.mark.slow) for m in MODES])
@pytest.mark.parametrize("env_id", IDS)
def test_golden_episodes_are_reproduced(golden, env_id, mode):
    env = gym.make(env_id, control_mode=mode)
    try:
        for exercise in exercises_of(env_id):
            for level in WEIGHT_LEVELS:
                key = rollout_key(env_id, mode, exercise, level)
                actual = record_rollout(env, env_id, mode, exercise, level)
                expected = golden[key]
                assert len(actual["kind"]) == len(expected["kind"]), (
                    f"{key}: {len(actual['kind'])} rows (resets + steps), recorded "
                    f"{len(expected['kind'])}: an episode ended at another step")
                for name, want in expected.items():
                    assert name in actual, f"{key}: info lost the entry {name!r}"
                    got = actual[name]
                    if want.dtype.kind == "f":
                        ok = np.allclose(got, want, rtol=RTOL, atol=ATOL, equal_nan=True)
                    else:
                        ok = np.array_equal(got, want)
                    assert ok, f"{key}: {name} differs at {_first_difference(got, want)}"
    finally:
        env.close()
