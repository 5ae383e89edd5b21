"""rehabbot.laws.safety: each rule's test and the order of the rules, over NumPy and
jax.numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rehabbot.laws import safety, scalar
from rehabbot.laws.safety import NO_STOP, RULE_CODES, first_rule, rule_name


def test_codes_and_names() -> None:
    assert safety.RULES == ("instability", "range_of_motion", "cuff_force",
                            "unintended_contact")
    assert [RULE_CODES[r] for r in safety.RULES] == [1, 2, 3, 4] and NO_STOP == 0
    assert [rule_name(c) for c in range(5)] == [None, *safety.RULES]


def test_none_firing_is_no_stop(xp) -> None:
    no = xp.asarray(False)
    assert int(first_rule(no, no, no, no)) == NO_STOP
    assert first_rule(False, False, False, False) == NO_STOP


@pytest.mark.parametrize("fired", [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
def test_the_first_rule_in_order_wins(xp, fired) -> None:
    flags = [xp.asarray(k in fired) for k in range(4)]
    assert int(first_rule(*flags)) == RULE_CODES[safety.RULES[fired[0]]]


def test_each_rule_alone(xp) -> None:
    for k, rule in enumerate(safety.RULES):
        flags = [xp.asarray(j == k) for j in range(4)]
        assert rule_name(first_rule(*flags)) == rule


def test_first_rule_over_a_batch_axis(xp) -> None:
    instability = xp.asarray([False, True, False, False])
    rom = xp.asarray([False, True, True, False])
    cuff = xp.asarray([False, False, True, False])
    contact = xp.asarray([False, False, False, True])
    codes = first_rule(instability, rom, cuff, contact)
    assert np.asarray(codes).tolist() == [0, 1, 2, 4]


def _columns(xp, rows):
    """A reading given per entry: each entry's column over a batch of worlds."""
    array = xp.asarray(rows)
    return [array[:, k] for k in range(array.shape[1])]


def test_range_of_motion(xp) -> None:
    low, high = [-1.0, 0.0], [1.0, 2.0]
    assert not bool(safety.beyond_range([1.0, 0.0], low, high))  # on the bounds
    assert bool(safety.beyond_range([1.001, 0.0], low, high))
    assert bool(safety.beyond_range([0.0, -0.001], low, high))
    assert not bool(safety.beyond_range([math.nan, 0.0], low, high))
    batch = safety.beyond_range(_columns(xp, [[0.0, 1.0], [0.0, 2.5], [-1.5, 0.0]]),
                                xp.asarray(low), xp.asarray(high))
    assert np.asarray(batch).tolist() == [False, True, True]


def test_cuff_force_over_its_limit(xp) -> None:
    limits = [140.0, 130.0]
    assert not bool(safety.over_force_limit([140.0, 130.0], limits))
    assert bool(safety.over_force_limit([10.0, 130.5], limits))
    assert not bool(safety.over_force_limit([math.nan, 0.0], limits))
    batch = safety.over_force_limit(_columns(xp, [[140.0, 130.0], [141.0, 0.0]]),
                                    xp.asarray(limits))
    assert np.asarray(batch).tolist() == [False, True]


def test_force_magnitude(xp) -> None:
    assert safety.force_magnitude_n((3.0, 4.0, 0.0), scalar) == 5.0
    forces = safety.force_magnitude_n(_columns(xp, [[3.0, 4.0, 0.0], [0.0, 0.0, -2.0]]), xp)
    np.testing.assert_allclose(np.asarray(forces), [5.0, 2.0])


def test_the_scalar_force_is_numpys_to_the_bit() -> None:
    rng = np.random.default_rng(3)
    xyz = rng.normal(scale=50.0, size=(200, 3))
    in_floats = [safety.force_magnitude_n(row.tolist(), scalar) for row in xyz]
    assert in_floats == safety.force_magnitude_n(_columns(np, xyz), np).tolist()


def test_blow_up(xp) -> None:
    calm = safety.fastest_speed_rad_s(xp.asarray([0.0, -999.0, 10.0]))
    assert float(calm) == 999.0
    assert not bool(safety.blown_up(calm, 10.0, xp))
    assert not safety.blown_up(float(calm), 10.0, scalar)
    fast = safety.fastest_speed_rad_s(xp.asarray([0.0, -1000.5, 0.0]))
    assert bool(safety.blown_up(fast, 10.0, xp))
    assert safety.blown_up(float(fast), 10.0, scalar)
    nan = safety.fastest_speed_rad_s(xp.asarray([0.0, math.nan, 0.0]))
    assert bool(safety.blown_up(nan, 10.0, xp)) and safety.blown_up(float(nan), 10.0, scalar)
    assert bool(safety.blown_up(calm, 2.0 * safety.BLOWUP_FORCE_N, xp))
    assert bool(safety.blown_up(calm, math.nan, xp))
    assert safety.blown_up(999.0, math.nan, scalar)
    batch = safety.blown_up(safety.fastest_speed_rad_s(xp.asarray([[0.0, 0.0], [2000.0, 0.0]])),
                            xp.asarray([1.0, 1.0]), xp)
    assert np.asarray(batch).tolist() == [False, True]


def test_outside_box(xp) -> None:
    low, high = xp.asarray([0.0, 0.0]), xp.asarray([1.0, 1.0])
    assert not bool(safety.outside_box(xp.asarray([0.0, 1.0]), low, high))
    assert bool(safety.outside_box(xp.asarray([0.0, 1.5]), low, high))
    assert bool(safety.outside_box(xp.asarray([math.nan, 0.5]), low, high))


def test_unintended_contact(xp) -> None:
    # three contacts: robot-patient shallow, patient-robot deep, robot-robot (two robots) deep
    is_robot = xp.asarray([[True, False], [False, True], [True, True]])
    is_other = xp.asarray([[False, True], [True, False], [False, False]])
    owner = xp.asarray([[0, -1], [-1, 0], [0, 1]])
    shallow = xp.asarray([-0.001, -0.001, -0.01])
    assert not bool(safety.unintended_contact(is_robot, is_other, shallow, 0.002))
    assert bool(safety.unintended_contact(is_robot, is_other, shallow, 0.002, owner))
    deep = xp.asarray([-0.001, -0.003, 0.0])
    assert bool(safety.unintended_contact(is_robot, is_other, deep, 0.002))
    assert not bool(safety.unintended_contact(is_robot, is_other, deep, 0.002,
                                              counted=xp.asarray([True, False, True])))


def test_a_changed_bound_fails_a_test(xp) -> None:
    """The blow-up bound is the documented one: a law with another would fail above."""
    assert safety.BLOWUP_SPEED_RAD_S == 1000.0 and safety.BLOWUP_FORCE_N == 1.0e5
    at_bound = safety.fastest_speed_rad_s(xp.asarray([1000.0]))
    assert not bool(safety.blown_up(at_bound, 0.0, xp))
    assert bool(safety.blown_up(at_bound, 0.0, xp, speed_limit_rad_s=999.0))
