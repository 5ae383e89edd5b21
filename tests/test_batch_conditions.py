"""The rigid patient's conditions in the batched env (rehabbot.batch.patient_drive) against the CPU
env's PatientDrive, on MuJoCo Warp's CPU device: the scripted expert's episode with a spastic,
a weak and active, and a contracted and resistive limb replayed with the same target
switches, termination step, return and patient's work; tremor by its statistics; what stays
refused.

Tolerances are those of ``tests/test_batch_parity.py`` (see its docstring): every observation
entry within ``OBS_TOL = 1e-3`` (5e-5 rad of joint angle, 0.13 N of cuff force), the return
within ``RETURN_RTOL = 1e-4`` relative, work within ``WORK_RTOL = 1e-3`` relative, and the
discrete outcomes exact. The patient's torques enter the physics every 2 ms step, so a
broken law, a wrong delay or a missing torque moves the limb by far more than those bounds:
the CPU replays of these conditions differ from a healthy patient's by 0.1 to 1 in some
observation entry and by joules in the patient's work.

Tremor draws its random numbers from the world's JAX key, not the CPU env's ``np_random``, so
it is compared by statistics (:func:`test_tremor_statistics_match_the_cpu_env`).
"""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("warp")
pytest.importorskip("mujoco.mjx")

import rehabbot.batch as batch  # noqa: E402
from benchmarks.common.batch_parity import (  # noqa: E402
    band_rms,
    cpu_episode,
    hold_still,
    replay_expert,
    tremor_spectrum,
)
from rehabbot.batch.env_tables import CONDITION_IDS  # noqa: E402
from rehabbot.sim.conditions import PatientCondition  # noqa: E402
from rehabbot.sim.tremor import TREMOR_DRIFT_HZ, TREMOR_MODULATION  # noqa: E402

OBS_TOL = 1e-3
RETURN_RTOL = 1e-4
WORK_RTOL = 1e-3

# A batched step costs about 0.15 s on a CPU: each replay covers the first steps of its
# episode, enough for two or more target switches and over 1 J of the patient's work.
PREFIX_STEPS = {"reach-mas4": 200, "knee-weak-v2": 120, "hip-stiff-resistive": 120}
MAS4 = {"spasticity_mas": "4"}
STIFF_RESISTIVE = {"stiffness_scale": 3.0, "rom_scale": 0.7, "effort": "resistive",
                   "effort_fraction": 0.1}


@pytest.mark.slow
@pytest.mark.parametrize(("case", "env_id", "kwargs"), [
    # the strongest stretch reflex, on the arm (condition=)
    ("reach-mas4", "rehabbot/rehab-reach-v2", {"condition": MAS4}),
    # a weak knee (10 % strength) that tries to follow the exercise (a condition id)
    ("knee-weak-v2", "rehabbot/rehab-knee-weak-v2", {}),
    # a contracted hip (stiffness x3, 70 % of the range) that pushes against the motion
    ("hip-stiff-resistive", "rehabbot/rehab-hip-v2", {"condition": STIFF_RESISTIVE}),
], ids=["reach-mas4", "knee-weak-v2", "hip-stiff-resistive"])
def test_condition_expert_episode_replays_on_warp(case, env_id, kwargs):
    # The first PREFIX_STEPS[case] steps: the drive's laws act from the first step.
    steps = PREFIX_STEPS[case]
    replay = replay_expert(env_id, max_steps=steps, **kwargs)
    assert len(replay["switches_cpu"]) >= 2, replay["switches_cpu"]
    assert replay["reset_obs_error"] < OBS_TOL
    assert replay["obs_error"] < OBS_TOL, replay["obs_error"]
    assert replay["switches_batched"] == replay["switches_cpu"]
    assert replay["end_batched"] == replay["end_cpu"], replay
    assert replay["stop_cpu"] is None and replay["stop_batched"] == 0
    batched_return, cpu_return = replay["return_batched"], replay["return_cpu"]
    assert abs(batched_return - cpu_return) <= RETURN_RTOL * abs(cpu_return), \
        (batched_return, cpu_return)
    for who in ("robot", "patient"):
        work, cpu_work = replay[f"{who}_work_batched_j"], replay[f"{who}_work_cpu_j"]
        assert abs(work - cpu_work) <= WORK_RTOL * abs(cpu_work), (who, work, cpu_work)
    # The patient's torques did work on the limb (joules; none for a healthy patient), so the
    # replay exercised the drive.
    assert abs(replay["patient_work_cpu_j"]) > 1.0, replay["patient_work_cpu_j"]
    if kwargs.get("condition") == MAS4:
        # The reflex changes the episode by far more than the tolerances.
        healthy = cpu_episode(env_id, max_steps=steps)
        mas4 = cpu_episode(env_id, max_steps=steps, **kwargs)
        steps = min(len(healthy["obs"]), len(mas4["obs"]))
        assert np.abs(healthy["obs"][:steps] - mas4["obs"][:steps]).max() > 100 * OBS_TOL
        assert abs(healthy["robot_work_j"] - replay["robot_work_cpu_j"]) > \
            100 * WORK_RTOL * abs(replay["robot_work_cpu_j"])


@pytest.mark.slow
def test_tremor_statistics_match_the_cpu_env():
    """``rehab-reach-tremor-v2`` (5 Hz, 1 N·m): the robot holds still for 2 s in eight worlds
    and in eight CPU episodes (seeds 0-7). Batched world k starts its tremor where CPU seed k
    drew it; the drift and modulation then take their own random steps (JAX keys against
    ``np_random``).

    * The spectral peak of the patient's joint angles (detrended, summed over runs and
      joints) is at ``tremor_hz``: within 0.5 Hz, one frequency bin of the 2 s hold (the
      drift's 0.2 Hz standard deviation, averaged over eight runs, is 0.07 Hz).
    * The tremor band (``tremor_hz`` +- 1 Hz, five drift deviations) holds most of the motion
      (the held limb has no other drive).
    * Each run's RMS in that band is within the modulation's bounds of the CPU run with the
      same start: the limb's small motion is linear in the torque, whose amplitude is
      ``A (1 + 0.25 m)`` with ``m`` in [-1, 1], so two runs with the same phases differ at
      most by a factor 1.25 / 0.75 either way.
    * The worlds' own start phases (drawn from their keys) are all different.
    """
    condition = PatientCondition(tremor_hz=5.0, tremor_amplitude_nm=1.0)
    hold = hold_still("rehabbot/rehab-reach-tremor-v2", steps=100, seeds=range(8))
    dt_s, hz = hold["dt_s"], condition.tremor_hz
    bound = (1.0 + TREMOR_MODULATION) / (1.0 - TREMOR_MODULATION)
    band = (hz - 5 * TREMOR_DRIFT_HZ, hz + 5 * TREMOR_DRIFT_HZ)
    for name in ("batched", "cpu"):
        freqs, power = tremor_spectrum(hold[name], dt_s)
        peak = freqs[np.argmax(np.where(freqs > 1.0, power, 0.0))]
        assert abs(peak - hz) <= 0.5, (name, peak)
        assert band_rms(hold[name], dt_s, *band) > 0.9 * band_rms(hold[name], dt_s, 0.5, 25.0)
    for k in range(hold["batched"].shape[1]):
        batched = band_rms(hold["batched"][:, k:k + 1], dt_s, *band)
        cpu = band_rms(hold["cpu"][:, k:k + 1], dt_s, *band)
        assert cpu > 1e-4, cpu  # rad: the CPU tremor is there
        assert 1.0 / bound <= batched / cpu <= bound, (k, batched, cpu)
    drawn = hold["drawn"]
    assert len({tuple(row) for row in drawn.round(6).tolist()}) == len(drawn)
    assert ((drawn >= 0.0) & (drawn < 2 * np.pi)).all()


def test_condition_ids_are_built():
    assert set(CONDITION_IDS) == {
        "rehabbot/rehab-reach-spastic-v2", "rehabbot/rehab-reach-tremor-v2",
        "rehabbot/rehab-reach-active-v2", "rehabbot/rehab-hip-spastic-v2",
        "rehabbot/rehab-knee-weak-v2", "rehabbot/rehab-knee-stiff-v2",
        "rehabbot/rehab-knee-resistive-v2"}


@pytest.mark.parametrize(("kwargs", "drive"), [
    ({}, False),
    ({"condition": PatientCondition()}, False),
    # contracture acts through the CPU model's stiffness, damping and ranges: no torques
    ({"condition": {"stiffness_scale": 3.0, "rom_scale": 0.7}}, False),
    ({"condition": {"spasticity_mas": "2"}}, True),
])
def test_only_conditions_that_apply_torques_get_a_drive(kwargs, drive):
    env = batch.make("rehabbot/rehab-knee-v2", naconmax=16, **kwargs)
    assert (env.patient is not None) == drive
    cpu = env.cpu_env
    assert np.array_equal(env.mj_model.jnt_stiffness, cpu.model.jnt_stiffness)
    assert np.array_equal(env.mj_model.jnt_range, cpu.model.jnt_range)


@pytest.mark.parametrize(("env_id", "kwargs", "named"), [
    ("rehabbot/rehab-reach-myo-v2", {}, "rehab-reach-myo-v2"),
    ("rehabbot/rehab-knee-myo-v2", {}, "rehab-knee-myo-v2"),
    ("rehabbot/rehab-knee-population-v1", {}, "rehab-knee-population-v1"),
    ("rehabbot/rehab-bilateral-v1", {}, "rehab-bilateral-v1"),
    ("rehabbot/rehab-reach-spastic-v1", {}, "rehab-reach-spastic-v1"),
])
def test_refuses_conditions_that_are_not_batched(env_id, kwargs, named):
    with pytest.raises(ValueError, match=named):
        batch.make(env_id, **kwargs)


@pytest.mark.slow
def test_auto_reset_starts_the_patient_drive_afresh():
    """A world that is done starts its drive's delay lines, work and tremor afresh; a running
    world keeps them."""
    env = batch.make("rehabbot/rehab-reach-tremor-v2", naconmax=32)
    start = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), 2))
    info = dict(start.info)
    for key in ("patient_velocities", "patient_work_j", "patient_positive_work_j"):
        info[key] = info[key] + 1.0
    info["patient_substep"] = info["patient_substep"] + 7
    info["patient_goal_index"] = info["patient_goal_index"] + 2
    used = start.replace(info=info, done=jax.numpy.asarray([1.0, 0.0]))
    restarted = jax.jit(jax.vmap(env.restart_done))(used)
    for key in ("patient_velocities", "patient_work_j", "patient_substep",
                "patient_goal_index"):
        fresh, kept = np.asarray(restarted.info[key]), np.asarray(info[key])
        assert (fresh[0] == 0).all(), key
        assert np.array_equal(fresh[1], kept[1]), key
    phases = np.asarray(restarted.info["tremor_phase"])
    assert not np.array_equal(phases[0], np.asarray(start.info["tremor_phase"])[0])
    assert np.array_equal(phases[1], np.asarray(start.info["tremor_phase"])[1])
