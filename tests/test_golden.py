"""The golden episodes (``tests/golden_episodes.py``) are reproduced: every registered id in
every control mode, for every exercise and weight level, gives the recorded observations,
rewards, terminations and ``info`` entries.

The comparison must pass on any CPU and still catch a change of behaviour; both are proved
here: rollouts perturbed by 1e-12 pass (the last-bit differences of another machine are
10,000 times smaller), and small real changes (a reward weight by 1e-4, one link's mass by
0.1 %, one safety threshold) fail. The file gives back every bit it was given, and a stored
rollout is compared in the rows it keeps (``tests/golden_storage.py``, ``stored_form``).
"""

import golden_storage
import gymnasium as gym
import numpy as np
import pytest
from golden_episodes import (
    GOLDEN_PATH,
    IDS,
    MODES,
    SAMPLE_EVERY,
    SAMPLED_ROWS,
    WEIGHT_LEVELS,
    Perturbation,
    compare_rollout,
    exercises_of,
    first_difference,
    load_golden,
    record_rollout,
    rollout_key,
    sampled_rows,
    write_golden,
)

import rehabbot  # noqa: F401  (registers the ids)


@pytest.fixture(scope="module")
def golden():
    return load_golden(GOLDEN_PATH)


def test_every_registered_id_has_golden_episodes(golden):
    """Every id but the -v2 ids: a -v2 id steps exactly as its -v1 id with actions scaled
    (its paper observation, reward and termination step for step) and its agent observation
    is a fixed function of the state, both checked in tests/test_v2.py."""
    registered = sorted(env_id for env_id in gym.registry if env_id.startswith("rehabbot/")
                        and not env_id.endswith("-v2"))
    assert registered == sorted(IDS), "record golden episodes of new ids: tests/golden_episodes.py"
    expected = {rollout_key(i, m, e, lv) for i in IDS for m in MODES for e in exercises_of(i)
                for lv in WEIGHT_LEVELS}
    assert set(golden) == expected


def _cells(env_id):
    return [(e, lv) for e in exercises_of(env_id) for lv in WEIGHT_LEVELS]


def _mode_params():
    return [pytest.param(m, marks=() if m == "joint_delta" else pytest.mark.slow) for m in MODES]


@pytest.mark.parametrize("mode", _mode_params())
@pytest.mark.parametrize("env_id", IDS)
def test_golden_episodes_are_reproduced(golden, env_id, mode):
    env = gym.make(env_id, control_mode=mode)
    try:
        for exercise, level in _cells(env_id):
            key = rollout_key(env_id, mode, exercise, level)
            difference = compare_rollout(env, env_id, mode, exercise, level, golden[key])
            assert difference is None, f"{key}: {difference}"
    finally:
        env.close()


# -- the comparison survives what another machine does ------------------------------------
# Every rollout again, its physics state nudged: 1e-12 rad on every joint position after the
# seeded reset and 1e-13 rad/s on every joint velocity before each step (another CPU differs
# by about 1e-16 relative, per operation). Seeds other than the shadow runs' own.
MACHINE_NOISE = Perturbation(initial=1e-12, per_step=1e-13, seed=101)


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("env_id", IDS)
def test_a_rollout_perturbed_by_1e_12_passes(golden, env_id, mode):
    env = gym.make(env_id, control_mode=mode)
    try:
        for exercise, level in _cells(env_id):
            key = rollout_key(env_id, mode, exercise, level)
            perturbed = record_rollout(env, env_id, mode, exercise, level, MACHINE_NOISE)
            difference = compare_rollout(env, env_id, mode, exercise, level, golden[key],
                                         actual=perturbed)
            assert difference is None, f"{key} perturbed by 1e-12: {difference}"
    finally:
        env.close()


@pytest.mark.slow
def test_the_perturbation_reaches_the_rollout_and_the_second_tier_absorbs_more(golden):
    """The nudge of the test above is real (it changes the rollout), and the second tier is
    needed and works: under the shadow runs' own noise level (1e-10 rad/s a step) some
    torque-mode rollout of reach-v1 leaves the 1e-6 tolerance, and the
    comparison still accepts every one of them."""
    env_id, mode = "rehabbot/rehab-reach-v1", "torque"
    env = gym.make(env_id, control_mode=mode)
    try:
        plain = record_rollout(env, env_id, mode, 1, 4)
        perturbed = record_rollout(env, env_id, mode, 1, 4, MACHINE_NOISE)
        assert not np.array_equal(plain["robot_torque_nm"], perturbed["robot_torque_nm"])
        needs_tier_two = 0
        for exercise, level in _cells(env_id):
            key = rollout_key(env_id, mode, exercise, level)
            noisy = record_rollout(env, env_id, mode, exercise, level,
                                   Perturbation(per_step=1e-10, seed=202))
            needs_tier_two += first_difference(noisy, golden[key]) is not None
            assert compare_rollout(env, env_id, mode, exercise, level, golden[key],
                                   actual=noisy) is None, key
        assert needs_tier_two >= 1
    finally:
        env.close()


# -- ... and still catches a real change ---------------------------------------------------
def _mutated_rollouts_fail(golden, env_id, mode, cells, make_kwargs=None, mutate=None):
    """How many of ``cells`` (exercise, level) fail the full comparison when the env is built
    with ``make_kwargs`` and ``mutate(env)`` is applied after ``gym.make``."""
    env = gym.make(env_id, control_mode=mode, **(make_kwargs or {}))
    if mutate is not None:
        mutate(env.unwrapped)
    failures = []
    try:
        for exercise, level in cells:
            key = rollout_key(env_id, mode, exercise, level)
            difference = compare_rollout(env, env_id, mode, exercise, level, golden[key])
            if difference is not None:
                failures.append(f"{key}: {difference}")
    finally:
        env.close()
    return failures


MUTATION_MODES = ("joint_delta", "torque")


@pytest.mark.slow
@pytest.mark.parametrize("mode", MUTATION_MODES)
def test_a_reward_weight_changed_by_1e_4_fails(golden, mode):
    env_id = "rehabbot/rehab-reach-v1"
    cells = _cells(env_id)
    failures = _mutated_rollouts_fail(golden, env_id, mode, cells,
                                      {"progress_weight": 10.0 * (1 + 1e-4)})
    assert len(failures) == len(cells), failures


@pytest.mark.slow
@pytest.mark.parametrize("mode", MUTATION_MODES)
def test_a_link_mass_changed_by_a_tenth_of_a_percent_fails(golden, mode):
    env_id = "rehabbot/rehab-reach-v1"
    cells = _cells(env_id)

    def heavier_forearm(base):  # the UR5e's forearm (link3): not a patient segment
        base.model.body_mass[base.model.body("link3").id] *= 1.001

    failures = _mutated_rollouts_fail(golden, env_id, mode, cells, mutate=heavier_forearm)
    assert len(failures) == len(cells), failures


def _default_cuff_limit_n(env_id):
    env = gym.make(env_id)
    try:
        return float(env.unwrapped.safety.force_limits_n[0])
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize(("env_id", "mode", "threshold"), [
    # Golden rollouts that stop on the cuff-force rule (the rule that fires in most of them;
    # none stops on the range of motion), the limit lowered by 1 %.
    ("rehabbot/rehab-hip-v1", "joint_delta", "cuff_force_limit_n"),
    ("rehabbot/rehab-knee-v1", "joint_velocity", "cuff_force_limit_n"),
])
def test_one_safety_threshold_changed_by_1_percent_fails(golden, env_id, mode, threshold):
    value = _default_cuff_limit_n(env_id)
    failures = _mutated_rollouts_fail(golden, env_id, mode, _cells(env_id),
                                      {threshold: value * 0.99})
    assert failures, f"{threshold}={value * 0.99} changed no rollout of {env_id} ({mode})"


# -- the file holds what was recorded --------------------------------------------------------
def _bits(values):
    return values.view(f"u{values.dtype.itemsize}")


def _assert_same_tables(got, want):
    assert list(got) == list(want)
    for key, fields in want.items():
        assert set(got[key]) == set(fields), key
        for name, values in fields.items():
            stored = got[key][name]
            assert stored.dtype == values.dtype and stored.shape == values.shape, (key, name)
            assert np.array_equal(_bits(stored), _bits(values)), (key, name)


def test_the_storage_gives_back_every_bit(tmp_path):
    """Any dtype and row shape, a name with other shapes or dtypes in other keys or missing
    from some, no rows, NaN payloads, -0.0, infinities, the extremes of every integer type and
    jumps between them (the differences wrap)."""
    rng = np.random.default_rng(7)
    special = np.array([np.nan, -np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, -1.7e308])
    payload_nan = np.array([0x7FF0_0000_0000_0ABC], dtype=np.uint64).view(np.float64)
    walk = np.cumsum(rng.normal(size=(50, 3)), axis=0)
    tables = {
        "a": {"walk": walk, "f32": walk.astype(np.float32), "special": special,
              "nan": payload_nan, "i8": np.array([-128, 127, -128, 0], dtype=np.int8),
              "i64": np.array([np.iinfo(np.int64).min, np.iinfo(np.int64).max, -1]),
              "u32": np.array([0, 2**32 - 1, 1], dtype=np.uint32),
              "grid": rng.normal(size=(4, 2, 3)).astype(np.float32)},
        "b": {"walk": rng.normal(size=(7, 5)), "f32": np.zeros((0, 3), dtype=np.float32),
              "i8": np.array([3], dtype=np.int32)},  # another width, no rows, another dtype
        "c": {},
    }
    golden_storage.write(tmp_path / "t.npz.xz", tables)
    _assert_same_tables(golden_storage.read(tmp_path / "t.npz.xz"), tables)


def test_the_storage_refuses_what_it_cannot_store(tmp_path):
    with pytest.raises(TypeError, match="dtype <U1"):
        golden_storage.write(tmp_path / "t.npz.xz", {"a": {"text": np.array(["x"])}})
    with pytest.raises(ValueError, match="'scalar' has no rows"):
        golden_storage.write(tmp_path / "t.npz.xz", {"a": {"scalar": np.float64(1.0)}})
    assert not list(tmp_path.iterdir())


def test_stored_rollouts_are_written_again_bit_for_bit(golden, tmp_path):
    """What ``--only`` and ``--stops`` do with the rollouts they keep."""
    kept = {key: golden[key] for key in list(golden)[::37]}
    write_golden(kept, tmp_path / "again.npz.xz")
    _assert_same_tables(load_golden(tmp_path / "again.npz.xz"), kept)


def test_the_file_holds_discrete_fields_in_every_row_and_floats_in_the_sampled_rows(golden):
    for key, fields in golden.items():
        rows = len(fields["kind"])
        sampled = fields[SAMPLED_ROWS]
        assert np.array_equal(sampled, sampled_rows(fields)), key
        assert sampled[0] == 0 and sampled[-1] == rows - 1
        assert set(range(0, rows, SAMPLE_EVERY)) <= set(sampled.tolist())
        for name, values in fields.items():
            if name != SAMPLED_ROWS:
                assert len(values) == (len(sampled) if values.dtype.kind == "f" else rows), \
                    (key, name)


def test_a_stored_rollout_is_compared_in_its_sampled_rows(golden):
    """Its floats in the sampled rows (every SAMPLE_EVERY-th, the last, and around every
    event), its discrete fields in every row."""
    env_id, mode, exercise, level = "rehabbot/rehab-hip-v1", "joint_delta", 0, 4
    expected = golden[rollout_key(env_id, mode, exercise, level)]
    assert (expected["safety_violation"] > 0).any()  # a rollout with events
    env = gym.make(env_id, control_mode=mode)
    try:
        actual = record_rollout(env, env_id, mode, exercise, level)
    finally:
        env.close()
    assert first_difference(actual, expected) is None
    sampled = expected[SAMPLED_ROWS]
    stop = int(np.flatnonzero(expected["safety_violation"])[0])
    skipped = sorted(set(range(len(expected["kind"]))) - set(sampled.tolist()))
    assert stop in sampled and stop + 1 in sampled and skipped

    def changed(name, row, delta):
        values = actual[name].copy()
        values[row] += delta
        return first_difference({**actual, name: values}, expected)

    assert changed("obs", stop, 1e-3).startswith(f"obs differs at row {stop}:")
    assert changed("reward", stop + 1, 1e-3).startswith(f"reward differs at row {stop + 1}:")
    assert changed("action_clipped", skipped[0], 1).startswith(
        f"action_clipped differs at row {skipped[0]}:")
    assert changed("reward", skipped[0], 1e-3) is None  # a row that is not stored
