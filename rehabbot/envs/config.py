"""The configuration of a :class:`rehabbot.envs.rehab_env.RehabEnv`: every keyword argument,
validated once, frozen.

``RehabEnvConfig(**kwargs)`` raises ``ValueError`` naming the bad value and its valid choices
or range (and ``TypeError`` for an unknown keyword) before anything is built. Profiles,
conditions and exercises given as dicts become :class:`PatientProfile`,
:class:`PatientCondition` and :class:`Exercise` objects.
The table of the arguments is in the docstring of :mod:`rehabbot.envs.rehab_env`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from rehabbot.common.checks import as_dataclass, check_choice, check_number
from rehabbot.sim.conditions import PatientCondition, as_condition
from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.robots import ROBOT_NAMES, get_robot
from rehabbot.sim.scene import CAMERA_NAMES, SIDES, WEIGHT_LEVELS, SceneOptions, check_weight_level
from rehabbot.tasks.exercises import LIMBS, TASK_TYPES, Exercise, exercise_table
from rehabbot.tasks.progress_reward import PROGRESS_WEIGHT_PER_RAD, TIME_COST_PER_STEP
from rehabbot.tasks.reward import SAFETY_PENALTIES, SAFETY_PENALTY_STEPS
from rehabbot.tasks.safety import ISO_TS_15066_QUASI_STATIC_N, SafetyThresholds

CONTROL_MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")
RENDER_MODES = ("human", "rgb_array", "depth_array")
# "paper": eq. (5) (the -v0 ids); "progress": the learnable -v1 reward
# (rehabbot.tasks.progress_reward).
REWARDS = ("paper", "progress")
# What the agent sees and how its actions are scaled: "paper" / "native" (the -v0 and -v1 ids:
# the paper's 23 fields, actions in the control mode's units); "agent" / "unit" (the -v2 ids:
# rehabbot.tasks.agent_observation, actions in Box(-1, 1), rehabbot.envs.actions.UnitActions).
OBSERVATIONS = ("paper", "agent")
ACTION_SCALES = ("native", "unit")

PRESET_OF: dict[tuple[str, str], str] = {
    ("arm", "right"): "upper_right", ("arm", "left"): "upper_left",
    ("hip", "right"): "hip", ("hip", "left"): "hip",
    ("knee", "right"): "knee", ("knee", "left"): "knee",
}

# Physical upper bounds of the safety thresholds: a larger value would silently switch the
# rule off (1e9 or True did, before these bounds).
# Range-of-motion rule: the most a joint may go beyond its anatomical range. 10 deg is the
# hyperextension a continuous-passive-motion device allows the knee (Artromot K1 extends to
# -10 deg, domain-facts.md section 4.2) and about the spread between the normal-range tables
# (AAOS vs Boone & Azen, section 3); beyond it the rule would accept joints past any range a
# clinician or a device accepts.
ROM_TOLERANCE_MAX_DEG = 10.0
# Unintended-contact rule: the deepest penetration that may go unreported. At the ISO/TS 15066
# quasi-static force limit the limb regions compress by at most F/k = 150 N / 30 N/mm = 5 mm
# (upper arm; hand 1.9, forearm 4.0, thigh 4.4, lower leg 2.2 mm: Tables A.2 and A.3,
# domain-facts.md section 4.1); twice that is the bound.
CONTACT_TOLERANCE_MAX_M = 0.01
# Cuff force rule: a limit given in N. Four times the largest ISO/TS 15066 quasi-static limit
# of the limb regions (thighs and knees, 220 N), i.e. twice its transient limit (440 N); above
# the largest spasm-protection setting of a knee CPM device (60 kg = 589 N, section 4.2).
CUFF_FORCE_LIMIT_MIN_N = 1.0
CUFF_FORCE_LIMIT_MAX_N = 4.0 * max(ISO_TS_15066_QUASI_STATIC_N.values())

# name -> (low, high, integer): the numeric arguments and their valid ranges (bools, NaN and
# infinities are refused too: rehabbot.common.checks.check_number).
NUMBER_RANGES: dict[str, tuple[float, float, bool]] = {
    "frame_skip": (1, 1000, True),
    # 10**6 steps: 5.6 h at the default 50 Hz, longer than any therapy session (the
    # rendering keeps one trace row per step).
    "max_episode_steps": (1, 10**6, True),
    "target_tolerance_rad": (1e-6, 1.0, False),
    "intermediate_bonus": (0.0, 1e6, False),
    "final_bonus": (0.0, 1e6, False),
    "smoothness_weight": (0.0, 1e6, False),
    "effort_weight": (0.0, 1e6, False),
    "progress_weight": (0.0, 1e6, False),
    "time_cost": (0.0, 1e6, False),
    "segment_s": (0.1, 60.0, False),
    "min_waypoint_spacing_rad": (0.0, 1.0, False),
    "rom_tolerance_deg": (0.0, ROM_TOLERANCE_MAX_DEG, False),
    "contact_tolerance_m": (0.0, CONTACT_TOLERANCE_MAX_M, False),
    "width": (1, 8192, True),
    "height": (1, 8192, True),
}


@dataclass(frozen=True)
class RehabEnvConfig:
    """Every argument of a RehabEnv (see the table in :mod:`rehabbot.envs.rehab_env`)."""

    limb: str = "arm"
    side: str = "right"
    task_type: str = "reaching"
    control_mode: str = "joint_delta"
    profile: PatientProfile | None = None
    condition: PatientCondition | None = None
    weight_level: int | None = None
    exercise: int | None = None
    exercises: tuple[Exercise, ...] | None = None
    robot: str = "ur5e"
    cuff: str = "connect"
    base_reorientation_deg: float = 0.0
    frame_skip: int = 10
    timestep_s: float = 0.002
    target_tolerance_rad: float = 0.05
    reward: str = "paper"
    observation: str = "paper"
    action_scale: str = "native"
    progress_weight: float = PROGRESS_WEIGHT_PER_RAD
    time_cost: float = TIME_COST_PER_STEP
    intermediate_bonus: float = 10.0
    final_bonus: float = 100.0
    smoothness_weight: float = 0.0
    effort_weight: float = 0.0
    terminate_on_safety: bool = True
    safety_penalty: str = "hold"
    safety_penalty_steps: int | None = SAFETY_PENALTY_STEPS
    rom_tolerance_deg: float = 2.0
    cuff_force_limit_n: float | None = None
    contact_tolerance_m: float = 0.002
    max_episode_steps: int = 1000
    segment_s: float = 3.0
    waypoint_dt_s: float = 0.1
    min_waypoint_spacing_rad: float = 0.1
    max_speed_rad_s: float = 0.5
    render_mode: str | None = None
    width: int = 640
    height: int = 480
    camera_name: str | None = "overview"
    # Derived in __post_init__: the exercise table actually used.
    exercise_table: tuple[Exercise, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        check_choice("limb", self.limb, LIMBS)
        check_choice("side", self.side, SIDES)
        check_choice("task_type", self.task_type, TASK_TYPES)
        check_choice("control_mode", self.control_mode, CONTROL_MODES)
        if self.render_mode is not None:
            check_choice("render_mode", self.render_mode, RENDER_MODES)
        set_(self, "profile", _as_profile(self.profile))
        set_(self, "condition", as_condition(self.condition))
        if self.weight_level is not None:
            set_(self, "weight_level", check_weight_level(self.weight_level))
        table = exercise_table(self.limb, self.exercises)
        set_(self, "exercise_table", table)
        if self.exercises is not None:
            set_(self, "exercises", table)
        if self.exercise is not None:
            set_(self, "exercise", check_choice("exercise", self.exercise, range(len(table))))
            set_(self, "exercise", int(self.exercise))
        for name, (low, high, integer) in NUMBER_RANGES.items():
            set_(self, name, check_number(name, getattr(self, name), low, high, integer))
        check_choice("robot", self.robot, ROBOT_NAMES)
        # The joint_velocity bound: at most what the robot's slowest joint is rated for.
        set_(self, "max_speed_rad_s", check_number("max_speed_rad_s", self.max_speed_rad_s,
                                                   1e-3, get_robot(self.robot).max_speed_rad_s))
        set_(self, "waypoint_dt_s", check_number("waypoint_dt_s", self.waypoint_dt_s, 0.01,
                                                 min(1.0, self.segment_s)))
        if not isinstance(self.terminate_on_safety, bool):
            raise ValueError(f"terminate_on_safety={self.terminate_on_safety!r} must be a bool")
        check_choice("safety_penalty", self.safety_penalty, SAFETY_PENALTIES)
        check_choice("reward", self.reward, REWARDS)
        check_choice("observation", self.observation, OBSERVATIONS)
        check_choice("action_scale", self.action_scale, ACTION_SCALES)
        if self.reward == "progress" and self.safety_penalty != "hold":
            raise ValueError(f"safety_penalty={self.safety_penalty!r} applies to the paper's "
                             "reward only (reward='paper'); the progress reward has one penalty")
        if self.cuff_force_limit_n is not None:
            set_(self, "cuff_force_limit_n", check_number(
                "cuff_force_limit_n", self.cuff_force_limit_n, CUFF_FORCE_LIMIT_MIN_N,
                CUFF_FORCE_LIMIT_MAX_N))
        if self.safety_penalty_steps is not None:
            set_(self, "safety_penalty_steps", check_number(
                "safety_penalty_steps", self.safety_penalty_steps, 1,
                NUMBER_RANGES["max_episode_steps"][1], integer=True))
        if self.camera_name is not None and self.camera_name not in CAMERA_NAMES:
            raise ValueError(f"camera_name={self.camera_name!r} is not one of "
                             f"{list(CAMERA_NAMES)} or None")
        self.safety_thresholds()  # ValueError naming a bad threshold
        SceneOptions(**self.scene_options())  # ValueError naming a bad scene option

    # -- derived -------------------------------------------------------------------------
    @property
    def preset(self) -> str:
        """The scene preset of the limb and side."""
        return PRESET_OF[(self.limb, self.side)]

    @property
    def dt_s(self) -> float:
        """Seconds per decision: ``frame_skip x timestep_s``."""
        return self.frame_skip * self.timestep_s

    @property
    def weight_levels(self) -> tuple[int, ...]:
        """The weight levels episodes can use."""
        return WEIGHT_LEVELS if self.weight_level is None else (self.weight_level,)

    def scene_options(self) -> dict[str, Any]:
        """Keyword arguments of :func:`rehabbot.sim.scene_build.build_scene`."""
        return {"robot": self.robot, "cuff": self.cuff,
                "side": None if self.limb == "arm" else self.side,
                "base_reorientation_deg": self.base_reorientation_deg,
                "timestep_s": self.timestep_s}

    def safety_thresholds(self) -> SafetyThresholds:
        """The thresholds of the safety rules."""
        return SafetyThresholds(rom_tolerance_deg=self.rom_tolerance_deg,
                                cuff_force_limit_n=self.cuff_force_limit_n,
                                contact_tolerance_m=self.contact_tolerance_m)

    def to_kwargs(self) -> dict[str, Any]:
        """The arguments as plain data (profile and exercises as dicts): JSON-able."""
        kwargs = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}
        kwargs["profile"] = dataclasses.asdict(self.profile)
        kwargs["condition"] = self.condition.to_dict()
        if self.exercises is not None:
            kwargs["exercises"] = [exercise.to_dict() for exercise in self.exercises]
        return kwargs


def kwarg_names(config_class: type = RehabEnvConfig) -> tuple[str, ...]:
    """The keyword arguments an env whose config is ``config_class`` accepts."""
    return tuple(f.name for f in dataclasses.fields(config_class) if f.init)


def config_from(config_class: type, env_name: str, config: Any, kwargs: dict) -> Any:
    """An env's config: ``config`` (an instance of ``config_class``) or one built from the
    env's keyword arguments. ``TypeError`` for an unknown keyword (listing the valid ones), for
    both a config and keywords, or for a config of another class."""
    if config is None:
        unknown = sorted(set(kwargs) - set(kwarg_names(config_class)))
        if unknown:
            raise TypeError(f"{env_name} got unknown keyword argument(s) {unknown}; valid: "
                            f"{list(kwarg_names(config_class))}")
        return config_class(**kwargs)
    if kwargs:
        raise TypeError(f"pass either a {config_class.__name__} or keyword arguments, not both")
    if not isinstance(config, config_class):
        raise TypeError(f"config must be a {config_class.__name__}, got {type(config).__name__}")
    return config


def _as_profile(profile: Any) -> PatientProfile:
    return as_dataclass(PatientProfile, profile, "profile")
