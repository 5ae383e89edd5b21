"""rehabbot.laws.patient and rehabbot.laws.work: the patient's torques and the work meters give
known answers over NumPy and jax.numpy, row by row over a batch axis, and as the CPU env's
scalar path (rehabbot.laws.scalar) evaluates them joint by joint."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rehabbot.laws import patient as laws
from rehabbot.laws import scalar
from rehabbot.laws.work import (
    accumulate_work,
    assistance_ratio,
    cuff_work_j,
    joint_work_j,
)

# A joint of range [0, 1] rad, reflex gain 2 N·m s/rad, threshold 0.2 rad/s, catching at rest
# at 35 % of the range and not releasing.
REFLEX = {"low_rad": 0.0, "high_rad": 1.0, "gain_nms_per_rad": 2.0, "threshold_rad_s": 0.2,
          "catch_at_rest": 0.35, "release_to": 1.0}


def compiled(xp, law):
    """``law`` (a function of arrays) in ``xp``: compiled once per shape under JAX (its eager
    operations compile one by one), as the batched env runs the laws."""
    if xp is np:
        return law
    import jax

    return jax.jit(law)


def reflex(xp, velocity, position, **overrides) -> np.ndarray:
    p = {**REFLEX, **overrides}
    law = compiled(xp, lambda v, q, *params: laws.reflex_torque_nm(xp, v, q, *params))
    return np.asarray(law(xp.asarray(velocity, dtype=float), xp.asarray(position, dtype=float),
                          *(xp.asarray(p[k]) for k in REFLEX)))


def test_reflex_is_zero_below_the_threshold_and_linear_above(xp) -> None:
    # Below 0.2 rad/s nothing fires, wherever the joint is.
    assert np.all(reflex(xp, [0.0, 0.1, 0.19, -0.19], [0.9, 0.9, 0.9, 0.1]) == 0.0)
    # Far past the catch (built up, no release): -gain (|v| - threshold), against the motion.
    speeds = np.array([0.5, 1.0, 1.5])
    np.testing.assert_allclose(reflex(xp, speeds, [0.95] * 3), -2.0 * (speeds - 0.2))
    np.testing.assert_allclose(reflex(xp, -speeds, [0.05] * 3), 2.0 * (speeds - 0.2))
    # Before the catch (at 1 rad/s it is at 0.35 - 0.2 = 15 % of the range): nothing.
    assert reflex(xp, 1.0, 0.1) == 0.0
    # Within the ramp (3 % of the range) it builds up linearly: half-way, half the torque.
    np.testing.assert_allclose(reflex(xp, 1.0, 0.165), -0.5 * 2.0 * 0.8)


def test_reflex_releases_to_its_share_after_the_catch(xp) -> None:
    far = reflex(xp, 1.0, 0.95, release_to=0.25)  # 0.77 of the range past the ramp
    np.testing.assert_allclose(far, -0.25 * 1.6, rtol=1e-6)
    just_caught = reflex(xp, 1.0, 0.15 + 0.03, release_to=0.25)  # the end of the ramp
    np.testing.assert_allclose(just_caught, -1.6)


def test_active_effort_pulls_towards_the_goal_within_its_strength(xp) -> None:
    kp = float(laws.active_gain_nm_per_rad(xp, xp.asarray(3.0), xp.asarray(2.0)))
    assert kp == pytest.approx(3.0 / laws.ACTIVE_SATURATION_RAD)
    q = xp.asarray([0.0, 0.0, 0.0, 0.0])
    goal = xp.asarray([0.1, -0.1, 1.0, -1.0])
    torque = np.asarray(laws.active_pull_nm(xp, q, xp.zeros(4), goal, xp.zeros(4), kp, 3.0, 2.0))
    np.testing.assert_allclose(torque, [0.1 * kp, -0.1 * kp, 3.0, -2.0])
    # It carries the limb's weight (the bias) and damps its motion.
    held = laws.active_pull_nm(xp, xp.asarray(0.2), xp.asarray(0.1), xp.asarray(0.2),
                               xp.asarray(0.5), kp, 3.0, 2.0)
    np.testing.assert_allclose(held, 0.5 - laws.ACTIVE_DAMPING_S * kp * 0.1)


def test_resistive_effort_pushes_against_the_motion(xp) -> None:
    v = xp.asarray([1.0, -1.0, 0.1, 0.0])
    push = np.asarray(laws.resistive_push_nm(xp, v, 3.0, 2.0))
    np.testing.assert_allclose(push, [-2.0 * math.tanh(10.0), 3.0 * math.tanh(10.0),
                                      -2.0 * math.tanh(1.0), 0.0])


def test_tremor_amplitude_and_frequency_from_its_phase(xp) -> None:
    # A quarter period in: the modulated amplitude A (1 + 0.25 m).
    torque, _ = laws.tremor_torque_nm(xp, 2.0, xp.asarray([0.0, 1.0, -1.0]), 5.0, 0.0,
                                      math.pi / 2, 0.002)
    np.testing.assert_allclose(torque, [2.0, 2.5, 1.5])
    # 5 Hz, no drift, 2 ms steps from phases 0 and pi/2: A sin(2 pi 5 t), A cos(2 pi 5 t), a
    # period every 100 steps; then 6 Hz (5 Hz + 1 Hz of drift).
    phase, torques = xp.asarray([0.0, math.pi / 2]), []
    for _ in range(100):
        torque, phase = laws.tremor_torque_nm(xp, 2.0, 0.0, 5.0, 0.0, phase, 0.002)
        torques.append(np.asarray(torque))
    t = np.arange(100) * 0.002
    np.testing.assert_allclose(np.stack(torques)[:, 0], 2.0 * np.sin(2 * np.pi * 5.0 * t),
                               atol=1e-12)
    np.testing.assert_allclose(np.stack(torques)[:, 1], 2.0 * np.cos(2 * np.pi * 5.0 * t),
                               atol=1e-12)
    np.testing.assert_allclose(phase, [2 * np.pi, 2.5 * np.pi], rtol=1e-12)
    step = 2 * np.pi * 6.0 * 0.002
    _, wrapped = laws.tremor_torque_nm(xp, 2.0, 0.0, 5.0, 1.0, phase, 0.002, wrap=True)
    np.testing.assert_allclose(wrapped, [step, 0.5 * np.pi + step], atol=1e-12)


def test_tremor_processes_from_given_draws(xp) -> None:
    drift, modulation = laws.tremor_start(xp, xp.asarray(1.5), xp.asarray([-3.0, 0.5]))
    np.testing.assert_allclose(drift, 1.5 * laws.TREMOR_DRIFT_HZ)
    np.testing.assert_allclose(modulation, [-1.0, 0.5])
    decay, noise = laws.tremor_decay(0.02)
    assert decay == pytest.approx(math.exp(-0.01)) and decay**2 + noise**2 == pytest.approx(1)
    drift, modulation = laws.tremor_processes(xp, xp.asarray(0.1), xp.asarray(0.9),
                                              xp.asarray(1.0), xp.asarray(10.0), decay, noise)
    np.testing.assert_allclose(drift, decay * 0.1 + noise * laws.TREMOR_DRIFT_HZ)
    assert float(modulation) == 1.0  # clipped


def test_saturation_at_the_healthy_peak(xp) -> None:
    torque = xp.asarray([-9.0, -2.0, 0.5, 4.0, 9.0])
    np.testing.assert_allclose(laws.saturate_nm(xp, torque, 4.0, 2.0),
                               [-2.0, -2.0, 0.5, 4.0, 4.0])


def test_work_of_a_known_force_over_a_known_displacement(xp) -> None:
    # 2 N·m over +0.5 rad and -1 N·m over +0.25 rad: 1 - 0.25 J.
    work = joint_work_j(xp.asarray([2.0, -1.0]), xp.asarray([0.0, 1.0]),
                        xp.asarray([0.5, 1.25]))
    np.testing.assert_allclose(work, 0.75)
    # The cuff's constraint force (1, 2, 3) N; the limb is pushed the other way, moving
    # -0.1 m in x and +0.2 m in z: 0.1 - 0.6 J.
    work = cuff_work_j(xp.asarray([1.0, 2.0, 3.0]), xp.zeros(3), xp.asarray([-0.1, 0.0, 0.2]))
    np.testing.assert_allclose(work, 0.1 - 0.6)
    total, positive = xp.asarray(0.0), xp.asarray(0.0)
    for step in (1.0, -0.5, 0.25):
        total, positive = accumulate_work(xp, total, positive, xp.asarray(step))
    np.testing.assert_allclose([total, positive], [0.75, 1.25])
    # Each of several meters counts its own positive work.
    _, positive = accumulate_work(xp, 0.0, 0.0, xp.asarray([-1.0, 0.0, 2.0]))
    np.testing.assert_array_equal(positive, [0.0, 0.0, 2.0])


def test_assistance_ratio(xp) -> None:
    robot = xp.asarray([3.0, 3.0, 0.0, 0.0])
    patient = xp.asarray([1.0, 0.0, 0.0, 2.0])
    np.testing.assert_array_equal(assistance_ratio(xp, robot, patient), [0.75, 1.0, 1.0, 0.0])


def _rows(xp, rng: np.random.Generator) -> dict[str, np.ndarray]:
    worlds, m = 4, 3
    return {"v": rng.uniform(-2, 2, (worlds, m)), "q": rng.uniform(-0.5, 1.5, (worlds, m)),
            "low": rng.uniform(-0.6, -0.4, m), "high": rng.uniform(1.4, 1.6, m),
            "gain": rng.uniform(1, 3, m), "goal": rng.uniform(-1, 1, (worlds, m)),
            "bias": rng.uniform(-3, 3, (worlds, m)), "kp": rng.uniform(5, 9, m),
            "pos": rng.uniform(2, 4, m), "neg": rng.uniform(2, 4, m),
            "phase": rng.uniform(0, 6, (worlds, m)), "after": rng.uniform(-1, 1, (worlds, m))}


def _laws(xp, a: dict) -> list:
    """Every law once, on ``a``'s arrays (or floats)."""
    torque = laws.reflex_torque_nm(xp, a["v"], a["q"], a["low"], a["high"], a["gain"], 0.3, 0.5,
                                   0.25)
    torque = torque + laws.active_pull_nm(xp, a["q"], a["v"], a["goal"], a["bias"], a["kp"],
                                          a["pos"], a["neg"])
    torque = torque + laws.resistive_push_nm(xp, a["v"], a["pos"], a["neg"])
    tremor, phase = laws.tremor_torque_nm(xp, 1.5, 0.3, 5.0, 0.2, a["phase"], 0.002, wrap=True)
    return [laws.saturate_nm(xp, torque + tremor, a["pos"], a["neg"]), phase]


def test_a_batch_axis_gives_each_world_its_own_answer(xp) -> None:
    a = _rows(xp, np.random.default_rng(0))
    run = compiled(xp, lambda arrays: _laws(xp, arrays))
    batched = [np.asarray(r) for r in run({k: xp.asarray(v) for k, v in a.items()})]
    work = np.asarray(joint_work_j(xp.unstack(xp.asarray(batched[0]), axis=-1),
                                   xp.unstack(xp.asarray(a["q"]), axis=-1),
                                   xp.unstack(xp.asarray(a["after"]), axis=-1)))
    assert batched[0].shape == (4, 3) and work.shape == (4,)
    for w in range(4):
        row = {k: xp.asarray(v[w] if v.ndim == 2 else v) for k, v in a.items()}
        single = [np.asarray(r) for r in run(row)]
        for got, want in zip(batched, single, strict=True):
            np.testing.assert_allclose(got[w], want, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(work[w], joint_work_j(single[0], a["q"][w], a["after"][w]),
                                   rtol=1e-13)


def test_the_scalar_path_gives_numpys_answers_bit_for_bit() -> None:
    """The CPU env evaluates the laws joint by joint on floats: the same numbers as NumPy's."""
    a = _rows(np, np.random.default_rng(1))
    batched = _laws(np, a)
    for w in range(4):
        for j in range(3):
            one = {k: float(v[w, j] if v.ndim == 2 else v[j]) for k, v in a.items()}
            for got, want in zip(_laws(scalar, one), batched, strict=True):
                assert got == want[w, j]
        work = joint_work_j(batched[0][w].tolist(), a["q"][w].tolist(), a["after"][w].tolist())
        assert work == joint_work_j(np.unstack(batched[0][w:w + 1], axis=-1),
                                    np.unstack(a["q"][w:w + 1], axis=-1),
                                    np.unstack(a["after"][w:w + 1], axis=-1))[0]
    assert assistance_ratio(scalar, 3.0, 1.0) == 0.75 and assistance_ratio(scalar, 0.0, 0.0) == 1
    assert accumulate_work(scalar, 1.0, 1.0, -0.5) == (0.5, 1.0)
