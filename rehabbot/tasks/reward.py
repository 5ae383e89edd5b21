"""What a step pays: named reward terms, and the per-episode state each reward design keeps.

A reward function turns what happened in a step (:class:`StepOutcome`, filled by the env)
into a dict of terms keyed ``"reward_<name>"``; the env pays their sum (:func:`total`) and puts
the dict into ``info``. Each reward owns what it remembers within an episode (the previous
action, the path left, the hold gap ``G``, the arms' sync gap): :meth:`Reward.reset` starts
it, :meth:`Reward.step` pays a step and moves it on. Three designs:

**PaperReward** (``reward="paper"``, the -v0 ids): eq. (5) of the paper.

==================  ===========================================================================
term                value
==================  ===========================================================================
``distance``        ``-||theta - theta*_i||_2`` [rad]
``bonus``           ``B_i`` when ``||theta - theta*_i||_inf < target_tolerance_rad``:
                    ``intermediate_bonus`` (10), or ``final_bonus`` (100) for the last target
``safety``          on a safety stop, ``safety_penalty="hold"`` (default): ``-(max(G + r, 0) +
                    c + STOP_MARGIN)``. ``G = max_s [B(s) + R(s)]`` over the episode's states
                    ``s`` so far: ``B(s)`` is the most that holding still from ``s`` to the
                    time limit can cost (:meth:`Reward.hold_cost`: for eq. (5) each of the
                    ``H - s`` steps at most the distance to the active target plus how far the
                    setpoint leads the joints, where holding the setpoint takes them, plus the
                    extra terms' maxima), ``R(s)`` the rewards earned after ``s``; ``r`` is
                    this step's other terms; ``c`` the larger of this step's and the previous
                    state's hold cost and ``STOP_MARGIN`` (1.0) a margin. The episode that
                    stops thus earns less than holding still from any state it passed through
                    would have, by ``c + STOP_MARGIN`` at least (tracked in O(1) a step:
                    :func:`next_hold_gap`). ``"worst_case"``: ``-(steps left + 1) x`` the
                    worst per-step loss the bounds allow. ``safety_penalty_steps=K`` instead
                    charges ``K`` steps at ``c`` at most (e.g. 100): smaller, and a
                    stop can then pay
``smoothness``      ``-smoothness_weight x mean(((a_t - a_{t-1}) / (high - low))^2)`` (0 by default)
``effort``          ``-effort_weight x mean((tau / tau_limit)^2)`` (0 by default)
==================  ===========================================================================

**ProgressReward** (``reward="progress"``, the -v1 and -v2 ids). Eq. (5) pays
``-||theta - theta*_i||`` every step; when a target is reached the distance switches to the next
target and the per-step reward drops (from about -0.07 to -0.72 on the shoulder exercise), so
for gamma = 0.99 holding still just short of a target is worth more than reaching it
(``benchmarks/probes/reward_trap.py``). This design pays for the same task without the trap. Let ``D
= sum_k (||theta_k - theta*_ik||_2 + sum_{j > i} ||theta*_jk - theta*_(j-1)k||_2)`` be the path
still to travel in robot joint space (rad), summed over the arms ``k``: the distance to the active
target plus the lengths between the targets after it. ``D`` never jumps up at a target switch
(triangle inequality), so ``-progress_weight x D`` is a potential in the sense of Ng, Harada and
Russell (1999) and an episode's progress terms add up to ``progress_weight x (D_start - D_end)``
whatever the route.

==================  ===========================================================================
term                value
==================  ===========================================================================
``progress``        ``progress_weight x (D_before - D_after)`` (10 per rad by default)
``bonus``           ``intermediate_bonus`` (10) or ``final_bonus`` (100), as in eq. (5)
``time``            ``-time_cost`` every step (0.05): holding still costs this, and only this
``safety``          on a safety stop: the ``"hold"`` penalty above with this design's hold
                    bound ``B(s) = (H - s) x (time_cost + extra maxima) + progress_weight x
                    lead``: holding still costs the time cost a step, and the joints may still
                    travel the ``lead`` [rad] by which the setpoints lead them, at most undoing
                    that much progress. The penalty stays small (about 50 plus the episode's
                    gains) because holding still costs little
``smoothness``,     as eq. (5)'s optional terms (0 by default)
``effort``
==================  ===========================================================================

Holding still pays ``-time_cost`` a step wherever the robot is, so stalling short of a target
is worth ``-time_cost x (1 - gamma^n) / (1 - gamma)`` (n steps left), while moving on earns the
progress, the bonus and an earlier end of the time cost: reaching beats stalling for every
gamma in [0.95, 0.999] (``tests/test_reward_v1.py``).

**BilateralReward** (the bilateral ids): the progress terms with ``D`` summed over both arms
(a target counts as reached when both arms are within the tolerance on every joint), plus a
synchronisation term. Each arm's progress through the current segment is ``f_k = clip(1 -
||theta_k - theta*_ik|| / L_ik, 0, 1)``, with ``L_ik`` the length of its segment (from the
previous target, or from home); an arm whose segment is shorter than the target tolerance
holds still in it. When both arms move in the segment, the step pays ``reward_sync =
-sync_weight x max(|f_right - f_left| - sync_tolerance, 0)``: arms in step within
``sync_tolerance`` (10 % of the segment) pay nothing; in the alternating pattern only one arm
moves per segment and the term is 0. A stop never pays: ``G`` also counts what holding still
would pay in synchronisation (each step of a hold at most ``sync_weight`` times the gap the arms
can reach while their joints travel to their setpoints), and the stopping step one step more at
the larger of the gaps before and after it. (An earlier design charged ``sync_weight`` a step
whatever the gap: a stop cost about 550, twice a whole successful episode, and SAC backed away
from the arms.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rehabbot.laws import reward as laws
from rehabbot.laws import scalar
from rehabbot.laws import targets as target_laws
from rehabbot.laws.reward import (  # noqa: F401  (the designs' settings, and laws users call)
    FINAL_BONUS,
    INTERMEDIATE_BONUS,
    PROGRESS_WEIGHT_PER_RAD,
    STOP_MARGIN,
    SYNC_TOLERANCE,
    SYNC_WEIGHT,
    TIME_COST_PER_STEP,
    next_hold_gap,
    segment_fraction,
    stop_penalty,
    sync_gap,
)
from rehabbot.laws.targets import TARGET_TOLERANCE_RAD

SAFETY_PENALTIES = ("hold", "worst_case")
# Steps the safety penalty counts by default: None = every step left to the time limit, the
# only count with which a stop never pays better than holding still.
SAFETY_PENALTY_STEPS: int | None = None


@dataclass
class StepOutcome:
    """What happened in one step, as a reward sees it; the env owns one and fills it in every
    step (no allocation). Distances are to the target that was active during the step;
    ``next_*`` to the target active after it (the next one after a switch, else the same)."""

    distance_rad: float = 0.0  # ||theta - theta*_i||_2 over every robot joint
    arm_distances_rad: Sequence[float] = (0.0,)  # the same per arm
    next_distance_rad: float = 0.0
    next_arm_distances_rad: Sequence[float] = (0.0,)
    target_index: int = 0  # the target active during the step
    reached: bool = False  # the target was reached (and no safety rule ended the episode)
    last_target: bool = False  # the target is the sequence's last
    safety_stop: bool = False  # a safety rule ended the episode
    steps_done: int = 0  # steps of the episode so far, this one included
    # Per arm: how far [rad] the joints may still travel if the agent holds still from the new
    # state (rehabbot.envs.control.Controller.hold_travel_rad); filled when the reward's
    # ``uses_hold_gap`` and no safety rule ended the episode.
    lead_rad: Sequence[float] = (0.0,)
    action: np.ndarray | None = None  # the action applied (inside the controller's box)
    torque_nm: np.ndarray | None = None  # the robot's actuator torques after the step


def total(terms: dict[str, float]) -> float:
    """The reward: the terms added in their order (:func:`rehabbot.laws.reward.total`)."""
    return laws.total(terms.values())


def info_keys(names: tuple[str, ...]) -> tuple[str, ...]:
    """The ``info`` keys of reward terms: ``"reward_<name>"``."""
    return tuple(f"reward_{name}" for name in names)


def remaining_path_rad(targets_rad: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """``rest[i]``: the joint-space length from target ``i`` through every later target
    (:func:`rehabbot.laws.targets.remaining_path_rad`); ``targets_rad`` is ``(N, n_joints)``."""
    return target_laws.remaining_path_rad(np.asarray(targets_rad, float))


@dataclass
class Reward:
    """What every design shares: the bonuses, the optional smoothness and effort terms (scaled
    by ``action_range`` and ``torque_limit_nm``), the safety penalty's settings and the hold
    gap ``G``. A subclass sets :attr:`names` and implements :meth:`terms`, :meth:`hold_cost`
    and, for state of its own, :meth:`reset`. The rules are :mod:`rehabbot.laws.reward`'s,
    run on this episode's Python floats (:mod:`rehabbot.laws.scalar`)."""

    target_tolerance_rad: float = TARGET_TOLERANCE_RAD
    intermediate_bonus: float = INTERMEDIATE_BONUS
    final_bonus: float = FINAL_BONUS
    smoothness_weight: float = 0.0
    effort_weight: float = 0.0
    safety_penalty_steps: int | None = SAFETY_PENALTY_STEPS
    max_episode_steps: int = 1000
    action_range: np.ndarray | None = None
    torque_limit_nm: np.ndarray | None = None
    # G (module docstring): the most that holding still from a state of the episode could
    # cost beyond what the episode earned since.
    hold_gap: float = field(default=0.0, init=False)
    _previous_action: np.ndarray | None = field(default=None, init=False, repr=False)

    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.action_range is not None:
            self._previous_action = np.zeros(len(self.action_range))

    @property
    def uses_hold_gap(self) -> bool:
        """Whether the safety penalty needs ``G`` (and so the outcome's ``lead_rad``)."""
        return self.safety_penalty_steps is None

    def reset(self, exercise: int, state: StepOutcome) -> None:
        """Start an episode of ``exercise`` from ``state`` (its ``next_*`` distances and
        ``lead_rad`` describe the start)."""
        del exercise
        if self._previous_action is not None:
            self._previous_action[:] = 0.0
        if self.uses_hold_gap:
            self.hold_gap = self.hold_cost(state, self.max_episode_steps)

    def step(self, outcome: StepOutcome) -> tuple[float, dict[str, float]]:
        """The reward of one step and its terms; moves the episode's state on."""
        terms = self.terms(outcome)
        reward = laws.total(terms.values())
        if self.uses_hold_gap and not outcome.safety_stop:
            self.hold_gap = laws.next_hold_gap(self.hold_gap, reward, self.hold_cost(
                outcome, laws.steps_left(self.max_episode_steps, outcome.steps_done,
                                         xp=scalar)), xp=scalar)
        if self.smoothness_weight:
            self._previous_action[:] = outcome.action
        return reward, terms

    def terms(self, outcome: StepOutcome) -> dict[str, float]:
        raise NotImplementedError

    def hold_cost(self, state: StepOutcome, steps_left: int) -> float:
        """``B(s)``: the most that holding still for ``steps_left`` steps from the state after
        ``state``'s step costs (module docstring)."""
        raise NotImplementedError

    def zero_terms(self) -> dict[str, float]:
        """Every term at 0 (the ``info`` of ``reset``)."""
        return dict.fromkeys(info_keys(self.names), 0.0)

    def bonus(self, outcome: StepOutcome) -> float:
        """The target bonus of a step that reached its target (0 otherwise)."""
        return laws.target_bonus(outcome.reached, outcome.last_target, self.intermediate_bonus,
                                 self.final_bonus, xp=scalar)

    def optional_terms(self, outcome: StepOutcome) -> tuple[float, float]:
        """The ``smoothness`` and ``effort`` terms (0.0 where the weight is 0)."""
        smoothness = effort = 0.0
        if self.smoothness_weight:
            smoothness = float(laws.smoothness_term(outcome.action, self._previous_action,
                                                    self.action_range, self.smoothness_weight,
                                                    xp=np))
        if self.effort_weight:
            effort = float(laws.effort_term(outcome.torque_nm, self.torque_limit_nm,
                                            self.effort_weight, xp=np))
        return smoothness, effort

    def steps_charged(self, outcome: StepOutcome) -> int:
        """The steps a stop is charged for: every step left and this one, at most
        ``safety_penalty_steps``."""
        return laws.steps_charged(self.max_episode_steps, outcome.steps_done,
                                  self.safety_penalty_steps, xp=scalar)


@dataclass
class PaperReward(Reward):
    """Eq. (5) of the paper, the optional terms and the safety penalty (module docstring).
    ``worst_step_reward`` is the ``"worst_case"`` penalty's per-step loss."""

    safety_penalty: str = "hold"
    worst_step_reward: float = 0.0
    names: tuple[str, ...] = ("distance", "bonus", "safety", "smoothness", "effort")
    # ||theta - theta*|| of the current state, to its active target: what one step of holding
    # still there costs.
    hold_distance_rad: float = field(default=0.0, init=False)

    @property
    def uses_hold_gap(self) -> bool:
        return self.safety_penalty == "hold" and self.safety_penalty_steps is None

    def reset(self, exercise: int, state: StepOutcome) -> None:
        self.hold_distance_rad = state.next_distance_rad
        super().reset(exercise, state)

    def terms(self, outcome: StepOutcome) -> dict[str, float]:
        distance = -outcome.distance_rad
        smoothness, effort = self.optional_terms(outcome)
        stop = outcome.safety_stop
        safety = 0.0
        if stop:
            hold = laws.paper_hold_step(outcome.distance_rad, self.hold_distance_rad,
                                        self.smoothness_weight, self.effort_weight, xp=scalar)
            safety = laws.paper_safety(
                stop, distance, hold, self.hold_gap, self.steps_charged(outcome), smoothness,
                effort, penalty=self.safety_penalty,
                capped=self.safety_penalty_steps is not None,
                worst_step_reward=self.worst_step_reward, xp=scalar)
        self.hold_distance_rad = outcome.next_distance_rad
        return {"reward_distance": distance, "reward_bonus": self.bonus(outcome),
                "reward_safety": safety, "reward_smoothness": smoothness,
                "reward_effort": effort}

    def hold_cost(self, state: StepOutcome, steps_left: int) -> float:
        """Each step of the hold at most the distance to the active target plus the lead
        (holding the setpoints takes the joints there) plus the extra terms' maxima."""
        return laws.paper_hold_cost(steps_left, state.next_distance_rad, state.lead_rad,
                                    self.smoothness_weight, self.effort_weight, xp=scalar)


@dataclass
class ProgressReward(Reward):
    """The ``-v1`` reward (module docstring). ``rests_rad[e][i]`` is the path after target
    ``i`` of exercise ``e``, summed over the arms; ``path_cap_rad`` the largest ``D`` the
    patient's box allows (reported, not used in the pay)."""

    progress_weight: float = PROGRESS_WEIGHT_PER_RAD
    time_cost: float = TIME_COST_PER_STEP
    rests_rad: tuple[tuple[float, ...], ...] = ((0.0,),)
    path_cap_rad: float = 0.0
    names: tuple[str, ...] = ("progress", "bonus", "time", "safety", "smoothness", "effort")
    _rest: tuple[float, ...] = field(default=(0.0,), init=False, repr=False)
    path_left_rad: float = field(default=0.0, init=False)  # D of the current state

    def reset(self, exercise: int, state: StepOutcome) -> None:
        self._rest = self.rests_rad[exercise]
        self.path_left_rad = laws.path_left_rad(state.next_arm_distances_rad, self._rest[0],
                                                xp=scalar)
        super().reset(exercise, state)

    def terms(self, outcome: StepOutcome) -> dict[str, float]:
        before = self.path_left_rad
        switching = outcome.reached and not outcome.last_target
        after = self.path_left_rad = laws.path_left_rad(
            outcome.next_arm_distances_rad,
            self._rest[outcome.target_index + 1 if switching else outcome.target_index],
            xp=scalar)
        progress = laws.progress_term(before, after, self.progress_weight)
        smoothness, effort = self.optional_terms(outcome)
        stop = outcome.safety_stop
        safety = 0.0
        if stop:
            safety = laws.progress_safety(
                stop, before, after, self.hold_gap, self.steps_charged(outcome), progress,
                self.time_cost, smoothness, effort, progress_weight=self.progress_weight,
                smoothness_weight=self.smoothness_weight, effort_weight=self.effort_weight,
                capped=self.safety_penalty_steps is not None, xp=scalar)
        return {"reward_progress": progress, "reward_bonus": self.bonus(outcome),
                "reward_time": -self.time_cost, "reward_safety": safety,
                "reward_smoothness": smoothness, "reward_effort": effort}

    def hold_cost(self, state: StepOutcome, steps_left: int) -> float:
        """Holding still makes no progress: the time cost a step, and the lead can undo that
        much progress."""
        return laws.progress_hold_cost(steps_left, state.lead_rad, self.time_cost,
                                       self.smoothness_weight, self.effort_weight,
                                       self.progress_weight, xp=scalar)


@dataclass
class BilateralReward(ProgressReward):
    """:class:`ProgressReward` summed over both arms plus ``reward_sync`` (module docstring).
    ``segments_rad[e][i]`` holds each arm's length of the segment that ends at target ``i`` of
    exercise ``e``."""

    sync_weight: float = SYNC_WEIGHT
    sync_tolerance: float = SYNC_TOLERANCE
    segments_rad: tuple[tuple[tuple[float, float], ...], ...] = (((0.0, 0.0),),)
    names: tuple[str, ...] = ("progress", "bonus", "time", "safety", "smoothness", "effort",
                              "sync")
    _segments: tuple[tuple[float, float], ...] = field(default=((0.0, 0.0),), init=False,
                                                       repr=False)
    _gap: float = field(default=0.0, init=False, repr=False)  # sync gap of the current state
    _step_gap: float = field(default=0.0, init=False, repr=False)  # of the last step
    _target: int = field(default=0, init=False, repr=False)  # the active target
    fractions: list[float] = field(default_factory=lambda: [1.0, 1.0], init=False)

    def reset(self, exercise: int, state: StepOutcome) -> None:
        self._segments = self.segments_rad[exercise]
        self._target = 0
        self.fractions, self._gap = self._in_segment(state.next_arm_distances_rad, 0)
        self._step_gap = 0.0
        super().reset(exercise, state)

    def _in_segment(self, distances: Sequence[float],
                    target: int) -> tuple[list[float], float]:
        """Each arm's share of target ``target``'s segment done, and the arms' sync gap."""
        (right, left), (length_right, length_left) = distances, self._segments[target]
        fractions = [laws.segment_fraction(right, length_right, xp=scalar),
                     laws.segment_fraction(left, length_left, xp=scalar)]
        tolerance = self.target_tolerance_rad
        return fractions, laws.sync_gap(
            fractions[0], fractions[1], laws.moves_in_segment(length_right, tolerance),
            laws.moves_in_segment(length_left, tolerance), self.sync_tolerance, xp=scalar)

    def terms(self, outcome: StepOutcome) -> dict[str, float]:
        index = outcome.target_index
        self.fractions, gap = self._in_segment(outcome.arm_distances_rad, index)
        gap_before, self._step_gap = self._gap, gap
        self._target = index
        self._gap = gap
        if outcome.reached and not outcome.last_target:
            self._target = index + 1
            self._gap = self._in_segment(outcome.next_arm_distances_rad, index + 1)[1]
        terms = super().terms(outcome)
        stop = outcome.safety_stop
        if stop:  # G holds the sync costs of a hold; the stop pays one step's more
            capped = self.safety_penalty_steps is not None
            terms["reward_safety"] -= laws.sync_stop_charge(
                gap, gap_before, self.sync_weight,
                self.steps_charged(outcome) if capped else None, xp=scalar)
        terms["reward_sync"] = laws.sync_term(gap, stop, self.sync_weight, xp=scalar)
        return terms

    def hold_cost(self, state: StepOutcome, steps_left: int) -> float:
        """:class:`ProgressReward`'s bound plus the sync term of every step at the largest gap
        the arms can reach while each travels its lead (when both move in the segment)."""
        (length_right, length_left), (lead_right, lead_left) = \
            self._segments[self._target], state.lead_rad
        gap = laws.sync_hold_gap(self._gap, lead_right, lead_left, length_right, length_left,
                                 self.target_tolerance_rad, xp=scalar)
        return laws.bilateral_hold_cost(super().hold_cost(state, steps_left), steps_left, gap,
                                        self.sync_weight)

    def info(self) -> dict[str, object]:
        """The bilateral entries of ``info``: each arm's progress through the last step's
        segment and the step's sync gap."""
        return {"segment_fraction": np.array(self.fractions), "sync_gap": self._step_gap}


def joint_distance(theta: Sequence[float], target: Sequence[float]) -> float:
    """``||theta - target||_2`` of two short lists (plain Python: no allocation)."""
    squared = 0.0
    for angle, goal in zip(theta, target, strict=True):
        squared += (angle - goal) * (angle - goal)
    return math.sqrt(squared)
