"""The reward of the bilateral env: the ``-v1`` progress reward summed over both arms, plus a
synchronisation term.

The path still to travel ``D`` (:mod:`rehabbot.tasks.progress_reward`) is the sum of the two
robots' paths, each in its own joint space: ``D = sum_k ||theta_k - theta*_ik|| + rest_ik``.
``progress``, ``bonus`` (a target counts as reached when both arms are within
``target_tolerance_rad`` of it on every joint), ``time`` and ``safety`` are then the ``-v1``
terms.

**Synchronisation.** In symmetric bilateral training both limbs move together. Each arm's
progress through the current segment is ``f_k = clip(1 - ||theta_k - theta*_ik|| / L_ik, 0,
1)``, with ``L_ik`` the length of its segment (from the previous target, or from home); an arm
whose segment is shorter than ``target_tolerance_rad`` holds still in it and has no progress.
When both arms move in the segment, the step pays

    reward_sync = -sync_weight x max(|f_right - f_left| - sync_tolerance, 0)

so arms that move in step within ``sync_tolerance`` (10 % of the segment by default) pay
nothing, and an arm that lags a whole segment costs ``sync_weight x (1 - sync_tolerance)`` a
step. In the alternating pattern only one arm moves per segment, so the term is 0.

A stop never pays: the safety penalty of the ``-v1`` reward (the gap ``G`` to the best hold of
the episode, :mod:`rehabbot.tasks.progress_reward`) counts here also what holding still would
pay in synchronisation: each step of a hold at most ``sync_weight`` times the gap the arms can
reach while their joints travel to their setpoints (:meth:`BilateralReward.hold_cost`, bounded
by the env), and the stopping step one step more at the larger of the gaps before and after
it. So a stop pays less than holding still from any state the episode passed. An earlier
design charged ``sync_weight`` a step whatever the gap (the worst case): a stop then cost
about 550, twice what a whole successful episode earns, and SAC backed away from the
arms and learned nothing in 200 000 steps (README, "Both arms").
"""

from __future__ import annotations

from dataclasses import dataclass

from rehabbot.tasks.progress_reward import ProgressReward
from rehabbot.tasks.reward import StepOutcome

SYNC_WEIGHT = 0.5  # per step, at a whole segment's lag (beyond the tolerance)
SYNC_TOLERANCE = 0.1  # a lag of this share of the segment is free


def sync_gap(fraction_right: float, fraction_left: float, moving_right: bool,
             moving_left: bool, tolerance: float) -> float:
    """``max(|f_right - f_left| - tolerance, 0)`` when both arms move in the segment, else 0."""
    if not (moving_right and moving_left):
        return 0.0
    return max(abs(fraction_right - fraction_left) - tolerance, 0.0)


def segment_fraction(distance_rad: float, length_rad: float) -> float:
    """How far through its segment an arm is: ``clip(1 - distance / length, 0, 1)`` (1.0 for an
    arm that holds still, ``length`` 0)."""
    if length_rad <= 0.0:
        return 1.0
    return min(max(1.0 - distance_rad / length_rad, 0.0), 1.0)


@dataclass(frozen=True)
class BilateralReward:
    """The ``-v1`` terms of :class:`ProgressReward` plus ``reward_sync`` (module docstring).
    The env puts the step's synchronisation gap in ``outcome.sync_gap``."""

    progress: ProgressReward
    sync_weight: float = SYNC_WEIGHT
    sync_tolerance: float = SYNC_TOLERANCE

    @property
    def names(self) -> tuple[str, ...]:
        return (*self.progress.names, "sync")

    @property
    def target_tolerance_rad(self) -> float:
        return self.progress.target_tolerance_rad

    @property
    def uses_previous_action(self) -> bool:
        return self.progress.uses_previous_action

    def __call__(self, outcome: StepOutcome) -> dict[str, float]:
        """The terms of one step, ``{"reward_progress": ..., "reward_sync": ...}``."""
        terms = self.progress(outcome)
        if outcome.safety_stop:
            gap = max(outcome.sync_gap, outcome.sync_gap_before)
            if self.progress.safety_penalty_steps is not None:  # 0.2.0's capped count
                steps_left = min(max(self.progress.max_episode_steps - outcome.steps_done, 0)
                                 + 1, self.progress.safety_penalty_steps)
                terms["reward_safety"] -= steps_left * self.sync_weight * gap
            else:  # the hold gap G already holds the sync costs; one step's more
                terms["reward_safety"] -= self.sync_weight * gap
            terms["reward_sync"] = 0.0
        else:
            terms["reward_sync"] = -self.sync_weight * outcome.sync_gap if outcome.sync_gap \
                else 0.0
        return terms

    @property
    def uses_hold_gap(self) -> bool:
        """Whether the safety penalty needs :attr:`StepOutcome.hold_gap` (uncapped)."""
        return self.progress.uses_hold_gap

    def hold_cost(self, distance_rad: float, lead_rad: float, steps_left: int,
                  sync_gap: float = 0.0) -> float:
        """``B(s)`` of :class:`ProgressReward` plus the synchronisation term of every step at
        ``sync_gap`` (the most the gap can reach while the arms hold: the env's bound)."""
        return (self.progress.hold_cost(distance_rad, lead_rad, steps_left)
                + steps_left * self.sync_weight * sync_gap)

    def zero_terms(self) -> dict[str, float]:
        """Every term at 0 (the ``info`` of ``reset``)."""
        return {f"reward_{name}": 0.0 for name in self.names}
