"""rehabbot.laws.reward and rehabbot.laws.targets: the reward designs and the target switch
give known answers, in NumPy and jax.numpy alike, over batch axes, and equal (to the bit) the
one-world Python-float namespace the CPU env runs them in."""

from __future__ import annotations

import numpy as np
import pytest

from rehabbot.laws import reward as laws
from rehabbot.laws import scalar
from rehabbot.laws.targets import (
    TARGET_TOLERANCE_RAD,
    joint_distance_rad,
    largest_error_rad,
    remaining_path_rad,
    switch_target,
)


def approx(value, expected) -> None:
    np.testing.assert_allclose(np.asarray(value, float), expected, rtol=0, atol=1e-12)


def eq5_reward(xp, theta, target, last, *, tolerance=TARGET_TOLERANCE_RAD,
               intermediate=laws.INTERMEDIATE_BONUS, final=laws.FINAL_BONUS):
    """Eq. (5) of one step that did not stop: the distance term and the bonus."""
    theta, target = xp.asarray(theta), xp.asarray(target)
    switch = switch_target(largest_error_rad(theta, target), xp.asarray(0),
                           xp.asarray(1 if last else 3), xp.asarray(False), tolerance)
    return laws.total([-joint_distance_rad(theta, target),
                       laws.target_bonus(switch.reached, switch.last, intermediate, final)])


def check_eq5(xp, **settings) -> None:
    """Eq. (5) on hand-computed states: a 3-4-5 error of 0.5 rad pays -0.5 and no bonus; the
    bonus comes only strictly inside epsilon, 10 before the last target and 100 at it."""
    approx(eq5_reward(xp, [0.3, 0.4, 0.0], [0.0, 0.0, 0.0], True, **settings), -0.5)
    approx(eq5_reward(xp, [0.03, 0.04, 0.0], [0.0, 0.0, 0.05], False, **settings),
           -np.sqrt(0.005))  # 0.05 off in one joint: on epsilon, not inside
    approx(eq5_reward(xp, [0.0, 0.03, 0.0], [0.0, 0.0, -0.04], False, **settings), 10.0 - 0.05)
    approx(eq5_reward(xp, [0.0, 0.03, 0.0], [0.0, 0.0, -0.04], True, **settings), 100.0 - 0.05)


def check_progress(xp, **settings) -> None:
    """An arm from 1/4 to 1/2 of a 1 rad segment, with 2 rad after it: ``D`` goes from 2.75 to
    2.5 and the step pays 10 x 0.25 - 0.05."""
    weight = settings.get("progress_weight", laws.PROGRESS_WEIGHT_PER_RAD)
    time_cost = settings.get("time_cost", laws.TIME_COST_PER_STEP)
    length, rest = xp.asarray(1.0), xp.asarray(2.0)
    before = laws.path_left_rad(xp.asarray([0.75]), rest)
    after = laws.path_left_rad(xp.asarray([0.5]), rest)
    approx(laws.segment_fraction(xp.asarray(0.75), length), 0.25)
    approx(laws.segment_fraction(xp.asarray(0.5), length), 0.5)
    progress = laws.progress_term(before, after, weight)
    approx(laws.total([progress, -time_cost]), 2.45)


def test_eq5_known_answers(xp) -> None:
    check_eq5(xp)
    assert (laws.INTERMEDIATE_BONUS, laws.FINAL_BONUS, TARGET_TOLERANCE_RAD) == (10, 100, 0.05)


def test_progress_of_a_known_segment_fraction(xp) -> None:
    check_progress(xp)
    assert (laws.PROGRESS_WEIGHT_PER_RAD, laws.TIME_COST_PER_STEP) == (10.0, 0.05)


@pytest.mark.parametrize("settings", [
    {"tolerance": 0.0501}, {"tolerance": 0.03}, {"intermediate": 10.5}, {"final": 99.0}])
def test_a_changed_eq5_constant_fails_the_known_answers(xp, settings) -> None:
    with pytest.raises(AssertionError):
        check_eq5(xp, **settings)


@pytest.mark.parametrize("settings", [{"progress_weight": 10.01}, {"time_cost": 0.06}])
def test_a_changed_progress_constant_fails_the_known_answers(xp, settings) -> None:
    with pytest.raises(AssertionError):
        check_progress(xp, **settings)


def test_the_target_advances_only_when_every_joint_is_within_tolerance(xp) -> None:
    theta = xp.asarray([[0.01, 0.06], [0.01, 0.04], [0.01, 0.04], [0.01, 0.04],
                        [0.0, 0.0499]])
    largest = largest_error_rad(theta, xp.zeros(2))
    approx(largest, [0.06, 0.04, 0.04, 0.04, 0.0499])
    index, count = xp.asarray([1, 1, 1, 2, 2]), xp.asarray(3)
    stop = xp.asarray([False, False, True, False, False])
    switch = switch_target(largest, index, count, stop)
    assert np.asarray(switch.reached).tolist() == [False, True, False, True, True]
    assert np.asarray(switch.index).tolist() == [1, 2, 1, 2, 2]  # the last stays, and ends
    assert np.asarray(switch.success).tolist() == [False, False, False, True, True]
    assert not bool(switch_target(xp.asarray(0.05), xp.asarray(0), count,
                                  xp.asarray(False)).reached)  # on epsilon: not reached


def test_remaining_path(xp) -> None:
    approx(remaining_path_rad(xp.asarray([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])), [6.0, 1.0, 0.0])
    approx(remaining_path_rad(xp.asarray([[0.2, 0.1]])), [0.0])


def test_a_stop_never_pays_more_than_holding(xp) -> None:
    """Along random episodes (one per world), a stop at step k earns less than holding still
    from any state s < k would have cost at most, by one step's hold cost and the margin."""
    rng = np.random.default_rng(3)
    worlds, steps = 64, 12
    rewards = xp.asarray(rng.normal(0.0, 3.0, (steps, worlds)))
    bounds = xp.asarray(rng.uniform(0.0, 40.0, (steps + 1, worlds)))  # B(s) of each state
    others = xp.asarray(rng.normal(0.0, 3.0, worlds))  # the stopping step's other terms
    hold_step = xp.asarray(rng.uniform(0.0, 1.0, worlds))
    gap = bounds[0]
    for k in range(steps):
        gap = laws.next_hold_gap(gap, rewards[k], bounds[k + 1])
    stop_reward = others + laws.stop_penalty(gap, others, hold_step)
    for s in range(steps + 1):
        earned = sum((rewards[k] for k in range(s, steps)), xp.zeros(worlds)) + stop_reward
        assert bool(xp.all(earned <= -(bounds[s] + hold_step + laws.STOP_MARGIN) + 1e-9))
    # Holding is bounded by the progress design's hold cost: the stop charge exceeds it.
    hold = laws.progress_hold_cost(xp.asarray(100), xp.asarray([0.02, 0.03]), 0.05, 0.0, 0.0,
                                   10.0)
    approx(hold, 100 * 0.05 + 10.0 * 0.05)
    charge = laws.progress_safety(xp.asarray(True), xp.asarray(2.0), xp.asarray(2.0), hold,
                                  xp.asarray(101), xp.asarray(0.0), 0.05)
    approx(charge, -(hold - 0.05 + 0.05 + laws.STOP_MARGIN))
    assert float(charge) < -float(hold)
    approx(laws.stop_penalty(xp.asarray(5.0), xp.asarray(-0.5), xp.asarray(0.7)), -6.2)
    approx(laws.stop_penalty(xp.asarray(-5.0), xp.asarray(-0.5), xp.asarray(0.7)), -1.7)


def test_eq5_safety_modes(xp) -> None:
    stop, distance = xp.asarray(True), xp.asarray(-0.4)
    hold = laws.paper_hold_step(xp.asarray(0.4), xp.asarray(0.5), 0.1, 0.2)
    approx(hold, 0.8)
    steps = laws.steps_charged(1000, xp.asarray(990))
    approx(steps, 11)
    approx(laws.steps_charged(1000, xp.asarray(10), 100), 100)
    approx(laws.paper_safety(stop, distance, hold, xp.asarray(3.0), steps), -(2.6 + 0.8 + 1.0))
    approx(laws.paper_safety(stop, distance, hold, xp.asarray(3.0), steps, capped=True), -8.8)
    approx(laws.paper_safety(stop, distance, hold, xp.asarray(3.0), steps,
                             penalty="worst_case", worst_step_reward=-2.0), -22.0)
    approx(laws.paper_safety(xp.asarray(False), distance, hold, xp.asarray(3.0), steps), 0.0)
    approx(laws.paper_hold_cost(xp.asarray(10), xp.asarray(0.3), xp.asarray([0.1]), 0.1, 0.0),
           5.0)


def test_sync_of_two_known_fractions(xp) -> None:
    moving, still = xp.asarray(True), xp.asarray(False)
    right, left = xp.asarray(0.9), xp.asarray(0.5)
    gap = laws.sync_gap(right, left, moving, moving, 0.1)
    approx(gap, 0.3)
    approx(laws.sync_term(gap, still, 0.5), -0.15)
    approx(laws.sync_term(gap, moving, 0.5), 0.0)  # a stop pays its sync in the charge
    approx(laws.sync_gap(right, left, moving, still, 0.1), 0.0)  # one arm holds still
    in_step = laws.sync_term(laws.sync_gap(xp.asarray(0.55), left, moving, moving, 0.1), still)
    assert float(in_step) == 0.0 and not np.signbit(float(in_step))
    approx(laws.sync_stop_charge(gap, xp.asarray(0.4), 0.5), 0.2)
    approx(laws.sync_stop_charge(gap, xp.asarray(0.1), 0.5, xp.asarray(10)), 1.5)
    lengths = (xp.asarray(2.0), xp.asarray(1.0))
    approx(laws.sync_hold_gap(gap, xp.asarray(0.2), xp.asarray(0.1), *lengths, 0.05), 0.5)
    approx(laws.sync_hold_gap(gap, xp.asarray(2.0), xp.asarray(0.1), *lengths, 0.05), 1.0)
    approx(laws.sync_hold_gap(gap, xp.asarray(0.2), xp.asarray(0.1), lengths[0],
                              xp.asarray(0.04), 0.05), 0.0)
    approx(laws.segment_fraction(xp.asarray(2.0), xp.asarray(1.0)), 0.0)
    approx(laws.segment_fraction(xp.asarray(0.3), xp.asarray(0.0)), 1.0)


def test_optional_terms(xp) -> None:
    smooth = laws.smoothness_term(xp.asarray([0.5, 0.0]), xp.asarray([0.0, 0.5]),
                                  xp.asarray([1.0, 2.0]), 2.0)
    approx(smooth, -2.0 * (0.25 + 0.0625) / 2)
    effort = laws.effort_term(xp.asarray([[1.0, 2.0], [np.nan, 1.0]]), xp.asarray([2.0, 2.0]),
                              1.0)
    approx(effort, [-(0.25 + 1.0) / 2, 0.0])


def test_batched_laws_equal_the_one_world_laws_bit_for_bit(xp) -> None:
    """Each law over ``(worlds,)`` arrays gives, world by world, the very floats the Python
    float namespace gives (the CPU env's)."""
    rng = np.random.default_rng(7)
    n = 50
    values = {name: rng.uniform(low, high, n) for name, low, high in (
        ("gap", -5, 30), ("reward", -3, 3), ("bound", 0, 30), ("others", -3, 3),
        ("hold", 0, 1), ("distance", 0, 2), ("previous", 0, 2), ("length", -0.2, 2),
        ("fraction", 0, 1), ("lead", 0, 0.3), ("steps", 0, 1000), ("before", 0, 5),
        ("after", 0, 5))}
    values["length"][:5] = 0.0
    stop = rng.random(n) < 0.5
    moving = rng.random(n) < 0.7
    last = rng.random(n) < 0.3
    largest = rng.uniform(0.0, 0.1, n)
    index = rng.integers(0, 3, n)

    def laws_of(ns, v, i):
        """Every law at world ``i`` of ``v``, in namespace ``ns``."""
        def pick(name):
            return v[name] if i is None else float(v[name][i])
        s = stop if i is None else bool(stop[i])
        m = moving if i is None else bool(moving[i])
        lst = last if i is None else bool(last[i])
        lead = xp.stack([v["lead"], v["hold"]], axis=-1) if i is None else \
            [float(v["lead"][i]), float(v["hold"][i])]
        switch = switch_target(pick("largest"), index if i is None else int(index[i]), 3, s,
                               xp=ns)
        return [
            laws.stop_penalty(pick("gap"), pick("others"), pick("hold"), xp=ns),
            laws.next_hold_gap(pick("gap"), pick("reward"), pick("bound"), xp=ns),
            laws.target_bonus(switch.reached, lst, xp=ns), switch.index, switch.reached,
            laws.paper_hold_step(pick("distance"), pick("previous"), 0.1, 0.2, xp=ns),
            laws.paper_safety(s, pick("others"), pick("hold"), pick("gap"), pick("steps"),
                              xp=ns),
            laws.paper_hold_cost(pick("steps"), pick("distance"), lead, 0.1, 0.0, xp=ns),
            laws.progress_safety(s, pick("before"), pick("after"), pick("gap"), pick("steps"),
                                 pick("reward"), 0.05, xp=ns),
            laws.progress_safety(s, pick("before"), pick("after"), pick("gap"), pick("steps"),
                                 pick("reward"), 0.05, capped=True, xp=ns),
            laws.progress_hold_cost(pick("steps"), lead, 0.05, 0.0, 0.1, 10.0, xp=ns),
            laws.path_left_rad(lead, pick("after"), xp=ns),
            laws.segment_fraction(pick("distance"), pick("length"), xp=ns),
            laws.sync_gap(pick("fraction"), pick("previous"), m, s, xp=ns),
            laws.sync_term(pick("fraction"), s, xp=ns),
            laws.sync_stop_charge(pick("fraction"), pick("gap"), 0.5, xp=ns),
            laws.sync_hold_gap(pick("fraction"), pick("lead"), pick("hold"), pick("length"),
                               pick("distance"), 0.05, xp=ns),
        ]

    batched = {name: xp.asarray(array) for name, array in values.items()}
    batched["largest"] = xp.asarray(largest)
    values["largest"] = largest
    stop, moving, last = xp.asarray(stop), xp.asarray(moving), xp.asarray(last)
    index = xp.asarray(index)
    together = [np.asarray(out) for out in laws_of(None, batched, None)]
    stop, moving, last, index = (np.asarray(a) for a in (stop, moving, last, index))
    for i in range(n):
        one = laws_of(scalar, values, i)
        for law, (world, batch) in enumerate(zip(one, together, strict=True)):
            assert np.asarray(batch).shape == (n,), law
            assert float(world) == float(batch[i]), (law, i)
