"""Reward terms, named: a reward function turns what happened in a step
(:class:`StepOutcome`) into a dict of terms keyed ``"reward_<name>"``; the env pays their sum
(:func:`total`) and puts the dict into ``info``. A later env version adds or replaces terms
by giving the env another reward function, without touching ``step``.

:class:`PaperReward` is eq. (5) of the paper with two optional terms and the safety penalty:

==================  ===========================================================================
term                value
==================  ===========================================================================
``distance``        ``-||theta - theta*_i||_2`` [rad]
``bonus``           ``B_i`` when ``||theta - theta*_i||_inf < target_tolerance_rad``:
                    ``intermediate_bonus`` (10), or ``final_bonus`` (100) for the last target
``safety``          on a safety stop, ``safety_penalty="hold"`` (default): ``-(max(G + r, 0) +
                    c + STOP_MARGIN)``. ``G = max_s [B(s) + R(s)]`` over the episode's states
                    ``s`` so far: ``B(s)`` is the most that holding still from ``s`` to the
                    time limit can cost (:meth:`PaperReward.hold_cost`: each of the ``H - s``
                    steps at most the distance to the active target plus how far the setpoint
                    leads the joints, where holding the setpoint takes them, plus the extra
                    terms' maxima), ``R(s)`` the rewards earned after ``s``; ``r`` is this
                    step's other terms; ``c`` the larger of this step's and the previous
                    state's hold cost and ``STOP_MARGIN`` (1.0) a margin. The episode that
                    stops thus earns less than holding still from any state it passed through
                    would have, by ``c + STOP_MARGIN`` at least (tracked in O(1) a step:
                    :func:`next_hold_gap`). ``"worst_case"``: ``-(steps left + 1) x`` the
                    worst per-step loss the bounds allow. ``safety_penalty_steps=K`` instead
                    charges ``K`` steps at ``c`` at most (0.2.0's default, 100): smaller, and a
                    stop can then pay
``smoothness``      ``-smoothness_weight x mean(((a_t - a_{t-1}) / (high - low))^2)`` (0 by default)
``effort``          ``-effort_weight x mean((tau / tau_limit)^2)`` (0 by default)
==================  ===========================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SAFETY_PENALTIES = ("hold", "worst_case")
# Steps the safety penalty counts by default: None = every step left to the time limit, the
# only count with which a stop never pays better than holding still (0.2.0 capped it at 100).
SAFETY_PENALTY_STEPS: int | None = None
# What a stop costs beyond the best hold of its episode (reward units, on top of one step's
# hold cost): the margin by which a stop never pays (issue 25; 20 x the -v1 time cost).
STOP_MARGIN = 1.0


@dataclass
class StepOutcome:
    """What happened in one step, as the reward terms see it; the env owns one and fills it
    in every step (no allocation)."""

    distance_rad: float = 0.0  # ||theta - theta*_i||_2 for the target active during the step
    # ||theta - theta*|| of the state before the step, to the target active in that state:
    # what one step of holding still there costs in eq. (5)
    hold_distance_rad: float = 0.0
    # The path still to travel [rad]: the distance to the active target plus the joint-space
    # lengths between the remaining targets, before and after the step (after a target switch:
    # from the next target). Filled only for reward functions with ``uses_path``.
    path_left_before_rad: float = 0.0
    path_left_rad: float = 0.0
    # G: the most that holding still from some earlier state of the episode could have cost
    # beyond what the episode earned since (``max_s [B(s) + R(s, t-1)]``, B(s) the reward
    # function's ``hold_cost`` bound at s, R the rewards since s). Filled for
    # ``uses_hold_gap``.
    hold_gap: float = 0.0
    reached: bool = False  # the target was reached (and no safety rule ended the episode)
    last_target: bool = False  # the target is the sequence's last
    safety_stop: bool = False  # a safety rule ended the episode
    steps_done: int = 0  # steps of the episode so far, this one included
    action: np.ndarray | None = None  # the action applied (inside the action space)
    previous_action: np.ndarray | None = None
    torque_nm: np.ndarray | None = None  # the robot's actuator torques after the step
    # The arms' synchronisation gap after and before the step, in the step's segment (bilateral
    # env: rehabbot.tasks.bilateral_reward).
    sync_gap: float = 0.0
    sync_gap_before: float = 0.0


@dataclass(frozen=True)
class PaperReward:
    """Eq. (5) of the paper plus the optional smoothness and effort terms and the safety
    penalty (module docstring). ``action_range`` and ``torque_limit_nm`` scale the optional
    terms; ``worst_step_reward`` is the ``"worst_case"`` penalty's per-step loss."""

    target_tolerance_rad: float = 0.05
    intermediate_bonus: float = 10.0
    final_bonus: float = 100.0
    smoothness_weight: float = 0.0
    effort_weight: float = 0.0
    safety_penalty: str = "hold"
    safety_penalty_steps: int | None = SAFETY_PENALTY_STEPS
    max_episode_steps: int = 1000
    action_range: np.ndarray | None = None
    torque_limit_nm: np.ndarray | None = None
    worst_step_reward: float = 0.0

    names: tuple[str, ...] = ("distance", "bonus", "safety", "smoothness", "effort")

    def __call__(self, outcome: StepOutcome) -> dict[str, float]:
        """The terms of one step, ``{"reward_distance": ..., "reward_bonus": ..., ...}``."""
        distance = -outcome.distance_rad
        safety = bonus = 0.0
        smoothness, effort = optional_terms(self, outcome)
        if outcome.safety_stop:
            steps_left = max(self.max_episode_steps - outcome.steps_done, 0) + 1
            if self.safety_penalty_steps is not None:
                steps_left = min(steps_left, self.safety_penalty_steps)
            extras = self.smoothness_weight + self.effort_weight
            hold = max(outcome.distance_rad, outcome.hold_distance_rad) + extras
            if self.safety_penalty == "worst_case":
                safety = steps_left * self.worst_step_reward
            elif self.safety_penalty_steps is not None:
                safety = -steps_left * hold
            else:  # the gap to the best hold of the episode, one step more and the margin
                safety = stop_penalty(outcome.hold_gap, distance + smoothness + effort, hold)
        elif outcome.reached:
            bonus = self.final_bonus if outcome.last_target else self.intermediate_bonus
        return {"reward_distance": distance, "reward_bonus": bonus, "reward_safety": safety,
                "reward_smoothness": smoothness, "reward_effort": effort}

    @property
    def uses_previous_action(self) -> bool:
        """Whether a term needs the previous action (the smoothness term)."""
        return bool(self.smoothness_weight)

    @property
    def uses_path(self) -> bool:
        """Whether a term needs the path still to travel (not eq. (5))."""
        return False

    @property
    def uses_hold_gap(self) -> bool:
        """Whether the safety penalty needs :attr:`StepOutcome.hold_gap` (the default
        uncapped ``"hold"`` penalty)."""
        return self.safety_penalty == "hold" and self.safety_penalty_steps is None

    def hold_cost(self, distance_rad: float, lead_rad: float, steps_left: int,
                  sync_gap: float = 0.0) -> float:
        """``B(s)``: the most that holding still for ``steps_left`` steps costs from a state at
        ``distance_rad`` from its active target whose setpoints lead its joints by
        ``lead_rad`` (holding the setpoints takes the joints there, so no step of the hold is
        farther than the sum): each step the distance plus the extra terms' maxima."""
        del sync_gap  # one arm: no synchronisation term
        return steps_left * (distance_rad + lead_rad + self.smoothness_weight
                             + self.effort_weight)

    def zero_terms(self) -> dict[str, float]:
        """Every term at 0 (the ``info`` of ``reset``)."""
        return dict.fromkeys(info_keys(self.names), 0.0)


def stop_penalty(hold_gap: float, other_terms: float, hold_step: float) -> float:
    """The ``"hold"`` safety penalty of a stopping step: the gap ``G`` to the best hold of the
    episode (with this step's ``other_terms`` added, never below 0), one step's hold cost
    ``hold_step`` more and :data:`STOP_MARGIN`, negated."""
    return -(max(hold_gap + other_terms, 0.0) + hold_step + STOP_MARGIN)


def next_hold_gap(hold_gap: float, reward: float, hold_bound: float) -> float:
    """``G`` after a step that did not stop: the holds of the earlier states fell behind by
    the step's ``reward``; holding from the new state may cost ``hold_bound`` (its
    ``hold_cost``)."""
    return max(hold_gap + reward, hold_bound)


def info_keys(names: tuple[str, ...]) -> tuple[str, ...]:
    """The ``info`` keys of reward terms: ``"reward_<name>"``."""
    return tuple(f"reward_{name}" for name in names)


def joint_distance(theta: list[float], target: list[float]) -> float:
    """``||theta - target||_2`` of two short lists (plain Python: no allocation)."""
    squared = 0.0
    for angle, goal in zip(theta, target, strict=True):
        squared += (angle - goal) * (angle - goal)
    return math.sqrt(squared)


def total(terms: dict[str, float]) -> float:
    """The reward: the terms added in their order."""
    values = iter(terms.values())
    reward = next(values)
    for value in values:
        reward += value
    return reward


def optional_terms(reward, outcome: StepOutcome) -> tuple[float, float]:
    """The optional ``smoothness`` and ``effort`` terms of a reward function with
    ``smoothness_weight``, ``effort_weight``, ``action_range`` and ``torque_limit_nm`` (0.0
    where the weight is 0): shared by every reward design."""
    smoothness = effort = 0.0
    if reward.smoothness_weight:
        change = (outcome.action - outcome.previous_action) / reward.action_range
        smoothness = -reward.smoothness_weight * float(change @ change) / len(change)
    if reward.effort_weight:
        torque = outcome.torque_nm / reward.torque_limit_nm
        if np.all(np.isfinite(torque)):
            effort = -reward.effort_weight * float(torque @ torque) / len(torque)
    return smoothness, effort
