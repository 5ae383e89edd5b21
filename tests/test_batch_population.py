"""Populations in the batched env (rehabbot.batch.patient_stack): every world draws a patient of the
population at each reset, with its own profile (the robot's base, the targets, the limb's
geometry and masses as per-world MuJoCo Warp model fields) and its own condition (the drive's
parameters indexed by the world's patient).

The replays put several patients side by side in one batch, each world replaying its own
patient's CPU expert episode, with the bounds of ``tests/test_batch_parity.py``: every
observation entry within ``OBS_TOL = 1e-3``, the return within ``RETURN_RTOL = 1e-4``
relative, the patient's work within ``WORK_RTOL = 1e-3`` relative, the target switches and
the termination step exact. The patients' own CPU episodes differ from one another by far
more than those bounds (asserted), so a world that got another patient's model or tables
fails them.
"""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("warp")
pytest.importorskip("mujoco.mjx")

import gymnasium as gym  # noqa: E402

import rehabbot.batch as batch  # noqa: E402
from benchmarks.common.batch_parity import cpu_episode, replay_population  # noqa: E402
from rehabbot.batch.env_tables import POPULATION_IDS  # noqa: E402

OBS_TOL = 1e-3
RETURN_RTOL = 1e-4
WORK_RTOL = 1e-3

REACH = "rehabbot/rehab-reach-population-v2"
KNEE = "rehabbot/rehab-knee-population-v2"
# The "train" population: patient k is profile k // 9 (1.60, 1.75, 1.85 m) with condition
# k % 9 (rehabbot.sim.populations). Tremor draws from JAX's stream: tested by statistics in
# tests/test_batch_conditions.py, not replayed here.
REACH_PATIENTS = (21, 16, 26, 9)  # 1.85 m MAS 2; 1.75 m active 50 %; 1.85 m contracture; 1.75 m
# The "test" population: profile k // 6 (1.68, 1.80 m), condition k % 6.
KNEE_PATIENTS = (3, 11, 8, 0)  # resistive; MAS 2 with contracture; active 35 %; MAS 3


def _assert_replays(rows: list[dict]) -> None:
    for row in rows:
        where = f"patient {row['patient']}"
        assert row["stop_cpu"] is None, where
        assert row["switches_batched"] == row["switches_cpu"], where
        assert row["end_batched"] == row["end_cpu"], where
        assert row["stop_batched"] == 0, where
        assert row["reset_obs_error"] < OBS_TOL, where
        assert row["obs_error"] < OBS_TOL, where
        assert row["return_batched"] == pytest.approx(row["return_cpu"], rel=RETURN_RTOL), where
        assert row["patient_work_batched_j"] == pytest.approx(
            row["patient_work_cpu_j"], rel=WORK_RTOL, abs=1e-6), where


def _assert_patients_differ(env_id: str, world_patients: tuple[int, ...], **kwargs) -> None:
    """Each patient's CPU episode differs from the others' by far more than the bounds (over
    the steps both episodes have)."""
    episodes = [cpu_episode(env_id, start={"exercise": 0, "weight_level": 0, "patient": k},
                            **kwargs)["obs"] for k in world_patients]
    for i, a in enumerate(episodes):
        for b in episodes[i + 1:]:
            n = min(len(a), len(b))
            assert np.abs(a[:n] - b[:n]).max() > 100 * OBS_TOL


def test_population_ids_are_batched():
    assert set(POPULATION_IDS) == {REACH, KNEE}


@pytest.mark.slow  # builds the cohort's 100 patients to find the refused ones
def test_a_cohort_that_leaves_out_patients_is_refused_by_name():
    with pytest.raises(ValueError, match=r"envelope-train:knee-ur5e.*leaves out patients"):
        batch.make(KNEE, patients="envelope-train")


@pytest.mark.slow
def test_reach_population_patients_replay_side_by_side():
    rows = replay_population(REACH, REACH_PATIENTS, max_steps=200)  # four switches each
    _assert_replays(rows)
    by_patient = {row["patient"]: row for row in rows}
    assert by_patient[16]["patient_work_cpu_j"] > 0.1  # the active patient pulls
    # the profiles take different paths: their targets switch on other steps
    assert len({tuple(row["switches_cpu"]) for row in rows}) > 1
    _assert_patients_differ(REACH, REACH_PATIENTS)


@pytest.mark.slow
def test_knee_population_patients_with_different_target_counts_replay():
    env = gym.make(KNEE, patients="test").unwrapped
    counts = {k: len(env.patient_env(k).targets[0].robot_rad) for k in KNEE_PATIENTS}
    env.close()
    assert len(set(counts.values())) > 1, counts  # the padding of the target tables is used
    # the first 200 steps (eleven or more switches each; the whole episodes, 333 to 418
    # steps, are on the parity page)
    rows = replay_population(KNEE, KNEE_PATIENTS, patients="test", max_steps=200)
    assert min(len(row["switches_cpu"]) for row in rows) >= 11
    _assert_replays(rows)
    by_patient = {row["patient"]: row for row in rows}
    assert by_patient[3]["patient_work_cpu_j"] < -1.0  # the resistive patient pushes back
    _assert_patients_differ(KNEE, KNEE_PATIENTS, patients="test")


@pytest.fixture(scope="module")
def reach_population():
    return batch.make(REACH, naconmax=16 * 64)


@pytest.mark.slow
def test_worlds_draw_patients_and_auto_reset_draws_again(reach_population):
    env = reach_population
    worlds = 64
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), worlds))
    drawn = np.asarray(state.info["patient"])
    assert np.array_equal(np.asarray(state.metrics["patient"]), drawn)
    assert len(set(drawn.tolist())) > 15  # of 27 patients, uniformly
    assert set(drawn.tolist()) <= set(range(27))
    # each world's first observation is its own patient's (the profile moves the robot's
    # base and the targets): equal to the CPU population env's for the same start
    for world in [*np.flatnonzero(drawn != drawn[0])[:2].tolist(), 0]:
        cpu = gym.make(REACH).unwrapped
        start = {"patient": int(drawn[world]),
                 "exercise": int(state.info["exercise"][world]),
                 "weight_level": int(state.info["weight_level"][world])}
        obs, info = cpu.reset(seed=0, options=start)
        assert info["patient"] == start["patient"]
        assert np.abs(np.asarray(state.obs[world]) - obs).max() < OBS_TOL
    # a world that ends draws its next patient from its key, and starts at that patient's
    # home: its first observation is the CPU env's (the chair, a world geom whose place
    # MuJoCo Warp sets only in a fresh MjData, moves with the profile; the cuff force at
    # home shows it)
    ended = state.replace(done=jax.numpy.ones(worlds))
    restarted = jax.jit(jax.vmap(env.restart_done))(ended)
    again = np.asarray(restarted.info["patient"])
    assert not np.array_equal(again, drawn)
    for world in np.flatnonzero(again != drawn)[:3].tolist():
        start = {"patient": int(again[world]),
                 "exercise": int(restarted.info["exercise"][world]),
                 "weight_level": int(restarted.info["weight_level"][world])}
        obs, _info = gym.make(REACH).unwrapped.reset(seed=0, options=start)
        assert np.abs(np.asarray(restarted.obs[world]) - obs).max() < OBS_TOL, start
    kept = jax.jit(jax.vmap(env.restart_done))(state)
    assert np.array_equal(np.asarray(kept.info["patient"]), drawn)


@pytest.mark.slow
def test_patient_option_and_its_refusals(reach_population):
    env = reach_population
    assert env.check_reset_options({"patient": 5, "exercise": 1}) == (1, -1, 5)
    with pytest.raises(ValueError, match="patient=27"):
        env.check_reset_options({"patient": 27})
    with pytest.raises(ValueError, match="patient"):
        batch.make("rehabbot/rehab-reach-v2").check_reset_options({"patient": 0})
    state = jax.jit(jax.vmap(env.reset, in_axes=(0, None, None, None)))(
        jax.random.split(jax.random.key(1), 3), -1, -1, 5)
    assert np.asarray(state.info["patient"]).tolist() == [5, 5, 5]


@pytest.mark.slow
def test_vector_door_of_a_population_id():
    batch.register_vector_entry_points()
    vec = gym.make_vec(KNEE, num_envs=3, vectorization_mode="vector_entry_point",
                       patients="test")
    obs, info = vec.reset(seed=0, options={"patient": 4})
    assert obs.shape == (3, *vec.single_observation_space.shape)
    assert info["patient"].tolist() == [4, 4, 4]
    obs, _reward, _terminated, _truncated, info = vec.step(np.zeros(vec.action_space.shape))
    assert np.isfinite(obs).all() and info["patient"].tolist() == [4, 4, 4]
    with pytest.raises(ValueError, match="patient=12"):
        vec.reset(options={"patient": 12})
