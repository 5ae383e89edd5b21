"""What a step pays, for every reward design: the terms, the safety charge of a stop and the
bound ``B(s)`` on what holding still from a state costs.

Each function is one rule over arrays of any leading batch axes (one world's numbers, or
``(worlds,)`` arrays), in the namespace ``xp`` (NumPy, ``jax.numpy``, or
:mod:`rehabbot.laws.scalar` for one world's Python floats; by default the inputs' namespace).
Per-arm quantities (the arms' distances, the joints' leads) lie along the last axis. Settings
(weights, bonuses, the stop's mode) are plain numbers fixed for an env. Terms are summed in
their documented order (:func:`total`), and every rule keeps its order of floating-point
operations, so that each backend pays the same floats.

**Eq. (5) of the paper** (``reward="paper"``): ``distance = -||theta - theta*_i||_2`` [rad]
and the target ``bonus`` (:func:`target_bonus`: 10 at a reached target, 100 at the last; a
target is reached when every joint is within ``epsilon = 0.05`` rad, see
:mod:`rehabbot.laws.targets`). Holding still for a step from a state costs at most its
distance to the active target, plus the lead by which the setpoints pull the joints further
(:func:`paper_hold_cost`).

**Progress** (``reward="progress"``): ``D`` is the joint-space path still to travel (the arms'
distances to the active target plus the path after it, :func:`path_left_rad`); a step pays
``progress_weight x (D_before - D_after)``, the bonus and ``-time_cost``. Holding still costs the
time cost a step, and the lead may undo that much progress (:func:`progress_hold_cost`).

**Bilateral** (two arms): the progress terms plus ``sync = -sync_weight x max(|f_right -
f_left| - sync_tolerance, 0)`` while both arms move in the segment, with ``f_k`` each arm's
share of its segment done (:func:`segment_fraction`, :func:`sync_gap`).

**The stop charge**: ``G``, the hold gap, is the most that holding still from any state of
the episode so far could have cost beyond what the episode earned since
(:func:`next_hold_gap`); a stopping step pays ``-(max(G + r, 0) + c + STOP_MARGIN)``
(:func:`stop_penalty`), with ``r`` its other terms and ``c`` one step's hold cost, so that a
stop always earns less than holding still would have. Optional terms: ``smoothness`` (the
action's change over its range) and ``effort`` (the torques over their limits), 0 by default.
"""

from __future__ import annotations

from collections.abc import Iterable
from types import ModuleType
from typing import Any

from rehabbot.laws.namespace import namespace_of

Array = Any  # an array of the namespace, or a Python number

# What a stop costs beyond the best hold of its episode (reward units, on top of one step's
# hold cost): the margin by which a stop never pays (20 x the progress design's time cost).
STOP_MARGIN = 1.0
INTERMEDIATE_BONUS = 10.0  # eq. (5)'s B_i at a target before the last
FINAL_BONUS = 100.0  # at the last target
PROGRESS_WEIGHT_PER_RAD = 10.0
TIME_COST_PER_STEP = 0.05
SYNC_WEIGHT = 0.5  # per step, at a whole segment's lag (beyond the tolerance)
SYNC_TOLERANCE = 0.1  # a lag of this share of the segment is free


def total(terms: Iterable[Array]) -> Array:
    """The reward: the terms added in their order, from the left."""
    values = iter(terms)
    reward = next(values)
    for value in values:
        reward = reward + value
    return reward


# -- shared by every design ------------------------------------------------------------------
def target_bonus(reached: Array, last: Array, intermediate_bonus: float = INTERMEDIATE_BONUS,
                 final_bonus: float = FINAL_BONUS, *, xp: ModuleType | None = None) -> Array:
    """``B_i``: ``final_bonus`` when the last target was reached, ``intermediate_bonus`` when
    another was, else 0."""
    if xp is None:
        xp = namespace_of(reached, last)
    return xp.where(reached, xp.where(last, final_bonus, intermediate_bonus), 0.0)


def smoothness_term(action: Array, previous_action: Array, action_range: Array,
                    weight: float, *, xp: ModuleType | None = None) -> Array:
    """``-weight x mean(((a_t - a_{t-1}) / (high - low))^2)`` over the action's entries."""
    if xp is None:
        xp = namespace_of(action, previous_action)
    change = (action - previous_action) / action_range
    return -weight * xp.vecdot(change, change, axis=-1) / change.shape[-1]


def effort_term(torque_nm: Array, torque_limit_nm: Array, weight: float, *,
                xp: ModuleType | None = None) -> Array:
    """``-weight x mean((tau / tau_limit)^2)`` over the robot's joints; 0 when a torque is not
    finite (an unstable step pays no effort)."""
    if xp is None:
        xp = namespace_of(torque_nm)
    ratio = torque_nm / torque_limit_nm
    finite = xp.all(xp.isfinite(ratio), axis=-1)
    ratio = xp.where(finite[..., None], ratio, 0.0)
    return xp.where(finite, -weight * xp.vecdot(ratio, ratio, axis=-1) / ratio.shape[-1], 0.0)


def steps_charged(max_episode_steps: int, steps_done: Array, cap: int | None = None, *,
                  xp: ModuleType | None = None) -> Array:
    """The steps a stop is charged for: every step left to the time limit and the stopping
    one, at most ``cap`` (None: no cap)."""
    if xp is None:
        xp = namespace_of(steps_done)
    steps = xp.maximum(max_episode_steps - steps_done, 0) + 1
    return steps if cap is None else xp.minimum(steps, cap)


def stop_penalty(hold_gap: Array, other_terms: Array, hold_step: Array,
                 margin: float = STOP_MARGIN, *, xp: ModuleType | None = None) -> Array:
    """The safety term of a stopping step: the gap ``G`` to the best hold of the episode (with
    the step's ``other_terms`` added, never below 0), one step's hold cost ``hold_step`` more
    and ``margin``, negated."""
    if xp is None:
        xp = namespace_of(hold_gap, other_terms)
    return -(xp.maximum(hold_gap + other_terms, 0.0) + hold_step + margin)


def next_hold_gap(hold_gap: Array, reward: Array, hold_bound: Array, *,
                  xp: ModuleType | None = None) -> Array:
    """``G`` after a step that did not stop: the holds of the earlier states fell behind by the
    step's ``reward``; holding from the new state may cost ``hold_bound`` (its ``B(s)``)."""
    if xp is None:
        xp = namespace_of(hold_gap, reward, hold_bound)
    return xp.maximum(hold_gap + reward, hold_bound)


def steps_left(max_episode_steps: int, steps_done: Array, *,
               xp: ModuleType | None = None) -> Array:
    """The steps left to the time limit after ``steps_done`` (never below 0)."""
    if xp is None:
        xp = namespace_of(steps_done)
    return xp.maximum(max_episode_steps - steps_done, 0)


# -- eq. (5) ---------------------------------------------------------------------------------
def paper_hold_step(distance_rad: Array, hold_distance_rad: Array, smoothness_weight: float,
                    effort_weight: float, *, xp: ModuleType | None = None) -> Array:
    """One step's hold cost charged at a stop: the larger of the stopping step's distance and
    the previous state's, plus the optional terms' largest losses."""
    if xp is None:
        xp = namespace_of(distance_rad, hold_distance_rad)
    return xp.maximum(distance_rad, hold_distance_rad) + (smoothness_weight + effort_weight)


def paper_safety(stop: Array, distance_term: Array, hold_step: Array, hold_gap: Array,
                 steps: Array, smoothness: Array = 0.0, effort: Array = 0.0, *,
                 penalty: str = "hold", capped: bool = False,
                 worst_step_reward: float = 0.0, xp: ModuleType | None = None) -> Array:
    """Eq. (5)'s safety term (0 unless ``stop``): ``"worst_case"`` pays ``steps x
    worst_step_reward``; ``capped`` (a step cap on the charge) ``-steps x hold_step``; else
    :func:`stop_penalty` with the step's other terms (distance, smoothness, effort)."""
    if xp is None:
        xp = namespace_of(stop, distance_term)
    if penalty == "worst_case":
        charge = steps * worst_step_reward
    elif capped:
        charge = -steps * hold_step
    else:
        charge = stop_penalty(hold_gap, distance_term + smoothness + effort, hold_step, xp=xp)
    return xp.where(stop, charge, 0.0)


def paper_hold_cost(steps: Array, distance_rad: Array, lead_rad: Array,
                    smoothness_weight: float, effort_weight: float, *,
                    xp: ModuleType | None = None) -> Array:
    """``B(s)`` of eq. (5): each of ``steps`` steps of holding still costs at most the
    distance to the active target plus the arms' leads (holding the setpoints takes the
    joints there) plus the optional terms' largest losses."""
    if xp is None:
        xp = namespace_of(distance_rad, lead_rad)
    return steps * (distance_rad + xp.sum(lead_rad, axis=-1) + smoothness_weight
                    + effort_weight)


# -- progress --------------------------------------------------------------------------------
def path_left_rad(arm_distances_rad: Array, rest_rad: Array, *,
                  xp: ModuleType | None = None) -> Array:
    """``D``: the arms' distances to the active target plus the path after it."""
    if xp is None:
        xp = namespace_of(arm_distances_rad)
    return xp.sum(arm_distances_rad, axis=-1) + rest_rad


def progress_term(path_before_rad: Array, path_after_rad: Array, weight: float) -> Array:
    """``weight x (D_before - D_after)``."""
    return weight * (path_before_rad - path_after_rad)


def progress_hold_step(time_cost: float, smoothness_weight: float,
                       effort_weight: float) -> float:
    """What a step of holding still costs at most: the time cost and the optional terms'
    largest losses."""
    return time_cost + smoothness_weight + effort_weight


def progress_safety(stop: Array, path_before_rad: Array, path_after_rad: Array,
                    hold_gap: Array, steps: Array, progress: Array, time_cost: float,
                    smoothness: Array = 0.0, effort: Array = 0.0, *,
                    progress_weight: float = PROGRESS_WEIGHT_PER_RAD,
                    smoothness_weight: float = 0.0, effort_weight: float = 0.0,
                    capped: bool = False, margin: float = STOP_MARGIN,
                    xp: ModuleType | None = None) -> Array:
    """The progress design's safety term (0 unless ``stop``): :func:`stop_penalty` with the
    step's other terms and :func:`progress_hold_step`; ``capped`` (a step cap on the charge):
    the progress the step gained and ``steps`` hold steps, negated (a stop can then pay)."""
    if xp is None:
        xp = namespace_of(stop, progress)
    hold_step = progress_hold_step(time_cost, smoothness_weight, effort_weight)
    if capped:
        gained = xp.maximum(path_before_rad - path_after_rad, 0.0)
        charge = -(progress_weight * gained + steps * hold_step)
    else:
        charge = stop_penalty(hold_gap, progress - time_cost + smoothness + effort, hold_step,
                              margin, xp=xp)
    return xp.where(stop, charge, 0.0)


def progress_hold_cost(steps: Array, lead_rad: Array, time_cost: float,
                       smoothness_weight: float, effort_weight: float,
                       progress_weight: float, *, xp: ModuleType | None = None) -> Array:
    """``B(s)`` of the progress design: holding still makes no progress, so each of ``steps``
    steps costs :func:`progress_hold_step`, and the arms' leads can undo that much progress."""
    if xp is None:
        xp = namespace_of(lead_rad)
    return (steps * progress_hold_step(time_cost, smoothness_weight, effort_weight)
            + progress_weight * xp.sum(lead_rad, axis=-1))


# -- bilateral synchronisation ---------------------------------------------------------------
def segment_fraction(distance_rad: Array, length_rad: Array, *,
                     xp: ModuleType | None = None) -> Array:
    """How far through its segment an arm is: ``clip(1 - distance / length, 0, 1)``; 1 for an
    arm that holds still (a segment of length 0)."""
    if xp is None:
        xp = namespace_of(distance_rad, length_rad)
    moving = length_rad > 0.0
    share = 1.0 - distance_rad / xp.where(moving, length_rad, 1.0)
    return xp.where(moving, xp.minimum(xp.maximum(share, 0.0), 1.0), 1.0)


def moves_in_segment(length_rad: Array, tolerance_rad: float) -> Array:
    """Whether an arm moves in a segment: it is longer than the target tolerance."""
    return length_rad > tolerance_rad


def sync_gap(fraction_right: Array, fraction_left: Array, moving_right: Array,
             moving_left: Array, tolerance: float = SYNC_TOLERANCE, *,
             xp: ModuleType | None = None) -> Array:
    """``max(|f_right - f_left| - tolerance, 0)`` when both arms move in the segment, else 0."""
    if xp is None:
        xp = namespace_of(fraction_right, fraction_left)
    lag = xp.maximum(xp.abs(fraction_right - fraction_left) - tolerance, 0.0)
    return xp.where(moving_right & moving_left, lag, 0.0)


def sync_term(gap: Array, stop: Array, weight: float = SYNC_WEIGHT, *,
              xp: ModuleType | None = None) -> Array:
    """``-weight x gap``; 0 (never -0) for arms in step, and on a stopping step (whose sync
    cost is in the stop charge)."""
    if xp is None:
        xp = namespace_of(gap, stop)
    return xp.where(stop | (gap == 0.0), 0.0, -weight * gap)


def sync_stop_charge(step_gap: Array, gap_before: Array, weight: float = SYNC_WEIGHT,
                     steps: Array | None = None, *, xp: ModuleType | None = None) -> Array:
    """What a stop pays for synchronisation, taken off the safety term: one step at the
    larger of the gaps before and after the step (the hold gap ``G`` holds the rest); with a
    step cap on the charge, ``steps`` such steps."""
    if xp is None:
        xp = namespace_of(step_gap, gap_before)
    gap = xp.maximum(step_gap, gap_before)
    return weight * gap if steps is None else steps * weight * gap


def sync_hold_gap(gap: Array, lead_right_rad: Array, lead_left_rad: Array,
                  length_right_rad: Array, length_left_rad: Array, tolerance_rad: float, *,
                  xp: ModuleType | None = None) -> Array:
    """The largest sync gap the arms can reach while each travels its lead, from ``gap``
    (each lead moves its arm's fraction by lead / length; at most 1); 0 unless both arms move
    in the segment."""
    if xp is None:
        xp = namespace_of(gap, lead_right_rad)
    moving = moves_in_segment(length_right_rad, tolerance_rad) & moves_in_segment(
        length_left_rad, tolerance_rad)
    right = xp.where(moving, length_right_rad, 1.0)
    left = xp.where(moving, length_left_rad, 1.0)
    reach = xp.minimum(gap + (lead_right_rad / right + lead_left_rad / left), 1.0)
    return xp.where(moving, reach, 0.0)


def bilateral_hold_cost(progress_hold: Array, steps: Array, hold_sync_gap: Array,
                        sync_weight: float = SYNC_WEIGHT) -> Array:
    """``B(s)`` of the bilateral design: the progress design's bound plus every step's sync
    term at the largest gap the arms can reach (:func:`sync_hold_gap`)."""
    return progress_hold + steps * sync_weight * hold_sync_gap
