"""The configuration of a :class:`rehabbot.envs.bilateral_env.BilateralEnv`: the arguments of a
:class:`~rehabbot.envs.config.RehabEnvConfig` (validated the same way) plus the bilateral ones.

The exercise table of a bilateral env is every arm exercise done with every pattern
(:mod:`rehabbot.tasks.bilateral`), pattern-major: with the built-in arm exercises and both
patterns, ``e = 0, 1`` are shoulder and elbow flexion done symmetrically and ``e = 2, 3`` the
same done alternating. ``exercise=`` indexes this table.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rehabbot.common.checks import check_choice, check_number
from rehabbot.envs.config import RehabEnvConfig
from rehabbot.tasks.bilateral import PATTERNS, bilateral_exercise
from rehabbot.tasks.bilateral_reward import SYNC_TOLERANCE, SYNC_WEIGHT
from rehabbot.tasks.exercises import Exercise

BILATERAL_PRESET = "upper_bilateral"


@dataclass(frozen=True)
class BilateralEnvConfig(RehabEnvConfig):
    """Every argument of a BilateralEnv (the table in :mod:`rehabbot.envs.bilateral_env`)."""

    reward: str = "progress"
    patterns: tuple[str, ...] = PATTERNS
    sync_weight: float = SYNC_WEIGHT
    sync_tolerance: float = SYNC_TOLERANCE
    # Derived: (arm exercise, pattern) of each entry of the bilateral exercise table.
    bilateral_table: tuple[tuple[Exercise, str], ...] = field(init=False, repr=False,
                                                               compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        exercise = self.exercise
        set_(self, "exercise", None)  # indexes the bilateral table, checked below
        super().__post_init__()
        if self.limb != "arm":
            raise ValueError(f"limb={self.limb!r}: the bilateral env moves both arms; "
                             "only limb='arm' is supported")
        if self.side != "right":
            raise ValueError(f"side={self.side!r}: the bilateral env moves both arms (leave "
                             "side at its default)")
        if self.reward != "progress":
            raise ValueError(f"reward={self.reward!r}: the bilateral env pays the -v1 "
                             "progress reward only (reward='progress')")
        if not self.condition.is_healthy:
            raise ValueError(f"condition={self.condition.to_dict()}: patient conditions are "
                             "not supported by the bilateral env yet (the patient is healthy "
                             "and passive)")
        patterns = self.patterns
        if isinstance(patterns, str) or not isinstance(patterns, (tuple, list)) or not patterns:
            raise ValueError(f"patterns={patterns!r} must be a non-empty sequence of "
                             f"{list(PATTERNS)}")
        for pattern in patterns:
            check_choice("patterns", pattern, PATTERNS)
        if len(set(patterns)) != len(patterns):
            raise ValueError(f"patterns={patterns!r} names a pattern twice")
        set_(self, "patterns", tuple(patterns))
        set_(self, "sync_weight", check_number("sync_weight", self.sync_weight, 0.0, 1e6))
        set_(self, "sync_tolerance", check_number("sync_tolerance", self.sync_tolerance,
                                                  0.0, 1.0))
        table = tuple((exercise_, pattern) for pattern in self.patterns
                      for exercise_ in self.exercise_table)
        set_(self, "bilateral_table", table)
        if exercise is not None:
            exercise = check_choice("exercise", exercise, range(len(table)))
            set_(self, "exercise", int(exercise))

    @property
    def preset(self) -> str:
        """Both arms: the two-robot scene."""
        return BILATERAL_PRESET

    @property
    def bilateral_exercises(self) -> tuple[Exercise, ...]:
        """The bilateral exercise table, named ``<exercise>_<pattern>``."""
        return tuple(bilateral_exercise(ex, pattern) for ex, pattern in self.bilateral_table)

    def to_kwargs(self) -> dict:
        kwargs = super().to_kwargs()
        kwargs["patterns"] = list(self.patterns)
        return kwargs

