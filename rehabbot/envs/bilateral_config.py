"""The configuration of a :class:`rehabbot.envs.bilateral_env.BilateralEnv`: the groups of a
:class:`~rehabbot.envs.config.RehabEnvConfig` (validated the same way), with the bilateral
arguments in two of them: ``patterns`` in the task (:class:`BilateralTaskConfig`),
``sync_weight`` and ``sync_tolerance`` in the reward (:class:`BilateralRewardConfig`, whose
design is ``"progress"``).

The exercise table of a bilateral env is every arm exercise done with every pattern
(:mod:`rehabbot.tasks.bilateral`), pattern-major: with the built-in arm exercises and both
patterns, ``e = 0, 1`` are shoulder and elbow flexion done symmetrically and ``e = 2, 3`` the
same done alternating. ``exercise=`` indexes this table.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

from rehabbot.common.checks import check_choice, check_number
from rehabbot.envs.config import RehabEnvConfig, RewardConfig, TaskConfig
from rehabbot.tasks.bilateral import PATTERNS, bilateral_exercise
from rehabbot.tasks.exercises import Exercise, exercise_table
from rehabbot.tasks.reward import SYNC_TOLERANCE, SYNC_WEIGHT

BILATERAL_PRESET = "upper_bilateral"


@dataclass(frozen=True)
class BilateralTaskConfig(TaskConfig):
    """:class:`TaskConfig` plus the patterns of the bilateral table."""

    patterns: tuple[str, ...] = PATTERNS

    def __post_init__(self) -> None:
        super().__post_init__()
        patterns = self.patterns
        if isinstance(patterns, str) or not isinstance(patterns, (tuple, list)) or not patterns:
            raise ValueError(f"patterns={patterns!r} must be a non-empty sequence of "
                             f"{list(PATTERNS)}")
        for pattern in patterns:
            check_choice("patterns", pattern, PATTERNS)
        if len(set(patterns)) != len(patterns):
            raise ValueError(f"patterns={patterns!r} names a pattern twice")
        object.__setattr__(self, "patterns", tuple(patterns))


@dataclass(frozen=True)
class BilateralRewardConfig(RewardConfig):
    """:class:`RewardConfig` with the ``-v1`` design and the synchronisation term's weights
    (:class:`rehabbot.tasks.reward.BilateralReward`)."""

    design: str = "progress"
    sync_weight: float = SYNC_WEIGHT
    sync_tolerance: float = SYNC_TOLERANCE

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.design != "progress":
            raise ValueError(f"reward={self.design!r}: the bilateral env pays the -v1 "
                             "progress reward only (reward='progress')")
        object.__setattr__(self, "sync_weight", check_number("sync_weight", self.sync_weight,
                                                             0.0, 1e6))
        object.__setattr__(self, "sync_tolerance", check_number(
            "sync_tolerance", self.sync_tolerance, 0.0, 1.0))


@dataclass(frozen=True, init=False)
class BilateralEnvConfig(RehabEnvConfig):
    """Every argument of a BilateralEnv (the table in :mod:`rehabbot.envs.bilateral_env`)."""

    # Derived: (arm exercise, pattern) of each entry of the bilateral exercise table.
    bilateral_table: tuple[tuple[Exercise, str], ...] = field(init=False, repr=False,
                                                               compare=False)

    GROUPS: ClassVar[dict[str, type]] = {**RehabEnvConfig.GROUPS, "task": BilateralTaskConfig,
                                         "reward": BilateralRewardConfig}

    def _check_across_groups(self) -> None:
        if self.scene.limb != "arm":
            raise ValueError(f"limb={self.scene.limb!r}: the bilateral env moves both arms; "
                             "only limb='arm' is supported")
        if self.scene.side != "right":
            raise ValueError(f"side={self.scene.side!r}: the bilateral env moves both arms "
                             "(leave side at its default)")
        if not self.patient.condition.is_healthy:
            raise ValueError(f"condition={self.patient.condition.to_dict()}: patient "
                             "conditions are not supported by the bilateral env yet (the "
                             "patient is healthy and passive)")
        # ``exercise`` indexes the bilateral table, not the arm exercises'.
        task = self.task
        arm_table = exercise_table("arm", task.exercises)
        object.__setattr__(self, "task", dataclasses.replace(task, exercise=None))
        super()._check_across_groups()
        table = tuple((exercise, pattern) for pattern in task.patterns
                      for exercise in arm_table)
        object.__setattr__(self, "bilateral_table", table)
        if task.exercise is not None:
            exercise = int(check_choice("exercise", task.exercise, range(len(table))))
            object.__setattr__(self, "task", dataclasses.replace(self.task, exercise=exercise))

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
        kwargs["patterns"] = list(self.task.patterns)
        return kwargs
