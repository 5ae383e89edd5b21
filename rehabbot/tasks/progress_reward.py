"""The learnable reward of the ``-v1`` ids: progress along the exercise's remaining path, the
target bonuses, a time cost, and a safety penalty with which a stop never pays.

Eq. (5) of the paper pays ``-||theta - theta*_i||`` every step. When a target is reached the
distance switches to the next target and the per-step reward drops (from about -0.07 to -0.72
on the shoulder exercise, -0.95 on the elbow): for an agent with gamma = 0.99 holding still
just short of a target is worth more than reaching it (``benchmarks/reward_trap.py``). This
reward pays for the same task without that trap.

Let ``D = ||theta - theta*_i||_2 + sum_{j > i} ||theta*_j - theta*_{j-1}||_2`` be the path still
to travel in robot joint space (rad): the distance to the active target plus the lengths
between the targets after it. ``D`` never jumps up at a target switch (triangle inequality), so
``-progress_weight x D`` is a potential in the sense of Ng, Harada and Russell (1999) over the
state (theta, active target), and its differences telescope: an episode's progress terms add up
to ``progress_weight x (D_start - D_end)`` whatever the route.

==================  ===========================================================================
term                value
==================  ===========================================================================
``progress``        ``progress_weight x (D_before - D_after)`` (10 per rad by default)
``bonus``           ``intermediate_bonus`` (10) or ``final_bonus`` (100) when a target is
                    reached, as in eq. (5)
``time``            ``-time_cost`` every step (0.05): holding still costs this, and only this
``safety``          on a safety stop: ``-(max(G + r, 0) + time_cost + extra maxima +
                    STOP_MARGIN)`` as eq. (5)'s ``"hold"`` penalty
                    (:mod:`rehabbot.tasks.reward`), with this reward's hold bound ``B(s) =
                    (H - s) x (time_cost + extra maxima) + progress_weight x lead``: holding
                    still costs the time cost a step, and the joints may still travel the
                    ``lead`` [rad] by which the setpoints lead them, at most undoing that much
                    progress. So every gain of the episode since the best state to hold is
                    taken back (before issue 25 only the stopping step's was, and a stop after a
                    gain could pay: issue 25). The penalty stays small (about 50 plus the
                    episode's gains) because holding still costs little
``smoothness``      as eq. (5)'s optional term (0 by default)
``effort``          as eq. (5)'s optional term (0 by default)
==================  ===========================================================================

Why it is learnable for every gamma in [0.95, 0.999]: holding still pays ``-time_cost`` a step
wherever the robot is, so stalling short of a target is worth ``-time_cost x (1 - gamma^n) /
(1 - gamma)`` (n steps left), while moving on earns the progress (positive at once, not
discounted away), the bonus, and an earlier end of the time cost. Tested on expert episodes in
``tests/test_reward_v1.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rehabbot.tasks.reward import StepOutcome, optional_terms, stop_penalty

PROGRESS_WEIGHT_PER_RAD = 10.0
TIME_COST_PER_STEP = 0.05


def remaining_path_rad(targets_rad: np.ndarray) -> np.ndarray:
    """``rest[i]``: the joint-space length from target ``i`` through every later target
    (``rest[-1] = 0``); ``targets_rad`` is ``(N, n_joints)``."""
    steps = np.linalg.norm(np.diff(np.asarray(targets_rad, float), axis=0), axis=1)
    rest = np.zeros(len(targets_rad))
    rest[:-1] = np.cumsum(steps[::-1])[::-1]
    return rest


@dataclass(frozen=True)
class ProgressReward:
    """The ``-v1`` reward (module docstring). ``path_cap_rad`` is the largest ``D`` the
    patient's box allows (reported, not used in the pay); ``action_range``
    and ``torque_limit_nm`` scale the optional terms as in
    :class:`rehabbot.tasks.reward.PaperReward`."""

    target_tolerance_rad: float = 0.05
    intermediate_bonus: float = 10.0
    final_bonus: float = 100.0
    progress_weight: float = PROGRESS_WEIGHT_PER_RAD
    time_cost: float = TIME_COST_PER_STEP
    smoothness_weight: float = 0.0
    effort_weight: float = 0.0
    safety_penalty_steps: int | None = None
    max_episode_steps: int = 1000
    path_cap_rad: float = 0.0
    action_range: np.ndarray | None = None
    torque_limit_nm: np.ndarray | None = None

    names: tuple[str, ...] = ("progress", "bonus", "time", "safety", "smoothness", "effort")

    def __call__(self, outcome: StepOutcome) -> dict[str, float]:
        """The terms of one step, ``{"reward_progress": ..., ...}``."""
        progress = self.progress_weight * (outcome.path_left_before_rad - outcome.path_left_rad)
        safety = bonus = 0.0
        smoothness, effort = optional_terms(self, outcome)
        if outcome.safety_stop:
            steps_left = max(self.max_episode_steps - outcome.steps_done, 0) + 1
            if self.safety_penalty_steps is not None:
                steps_left = min(steps_left, self.safety_penalty_steps)
            per_step = self.time_cost + self.smoothness_weight + self.effort_weight
            if self.safety_penalty_steps is not None:  # 0.2.0's capped count: a stop can pay
                gained = max(outcome.path_left_before_rad - outcome.path_left_rad, 0.0)
                safety = -(self.progress_weight * gained + steps_left * per_step)
            else:
                safety = stop_penalty(outcome.hold_gap,
                                      progress - self.time_cost + smoothness + effort, per_step)
        elif outcome.reached:
            bonus = self.final_bonus if outcome.last_target else self.intermediate_bonus
        return {"reward_progress": progress, "reward_bonus": bonus,
                "reward_time": -self.time_cost, "reward_safety": safety,
                "reward_smoothness": smoothness, "reward_effort": effort}

    @property
    def uses_previous_action(self) -> bool:
        """Whether a term needs the previous action (the smoothness term)."""
        return bool(self.smoothness_weight)

    @property
    def uses_path(self) -> bool:
        """The progress term needs the path still to travel."""
        return True

    @property
    def uses_hold_gap(self) -> bool:
        """Whether the safety penalty needs :attr:`StepOutcome.hold_gap` (uncapped)."""
        return self.safety_penalty_steps is None

    def hold_cost(self, distance_rad: float, lead_rad: float, steps_left: int,
                  sync_gap: float = 0.0) -> float:
        """``B(s)``: the most that holding still for ``steps_left`` steps costs (module
        docstring); ``distance_rad`` does not enter (holding still makes no progress)."""
        del distance_rad, sync_gap
        return (steps_left * (self.time_cost + self.smoothness_weight + self.effort_weight)
                + self.progress_weight * lead_rad)

    def zero_terms(self) -> dict[str, float]:
        """Every term at 0 (the ``info`` of ``reset``)."""
        return {f"reward_{name}": 0.0 for name in self.names}
