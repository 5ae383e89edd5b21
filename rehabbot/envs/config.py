"""The configuration of a :class:`rehabbot.envs.rehab_env.RehabEnv`: every keyword argument,
validated once, frozen, grouped by what it configures.

==============  =================  ===========================================================
group           class              keyword arguments (the env docstring's table)
==============  =================  ===========================================================
``scene``       SceneConfig        ``limb``, ``side``, ``robot``, ``cuff``,
                                   ``base_reorientation_deg``, ``timestep_s``,
                                   ``patient_model``, ``randomization``
``patient``     PatientConfig      ``profile``, ``condition``, ``weight_level``
``task``        TaskConfig         ``task_type``, ``exercises``, ``exercise``,
                                   ``target_tolerance_rad``, ``observation``,
                                   ``max_episode_steps``, ``segment_s``, ``waypoint_dt_s``,
                                   ``min_waypoint_spacing_rad``
``control``     ControlConfig      ``control_mode``, ``action_scale``, ``frame_skip``,
                                   ``max_speed_rad_s``
``safety``      SafetyConfig       ``terminate_on_safety``, ``rom_tolerance_deg``,
                                   ``cuff_force_limit_n``, ``contact_tolerance_m``
``reward``      RewardConfig       ``reward`` (the design: field ``design``),
                                   ``progress_weight``, ``time_cost``, ``intermediate_bonus``,
                                   ``final_bonus``, ``smoothness_weight``, ``effort_weight``,
                                   ``safety_penalty``, ``safety_penalty_steps``
``render``      RenderConfig       ``render_mode``, ``width``, ``height``, ``camera_name``
==============  =================  ===========================================================

A config is built from the flat keywords of the table (``RehabEnvConfig(limb="knee",
time_cost=0.1)``, what ``gym.make`` passes), from groups (``RehabEnvConfig(reward=
RewardConfig(design="progress", time_cost=0.1))``, a group may also be a dict of its fields),
or both: flat keywords apply on top of the groups. ``reward=`` is the one name of both kinds:
a string is the design (the flat keyword), a :class:`RewardConfig` or a dict the group.
Every flat keyword reads back as an attribute (``config.time_cost``, ``config.limb``);
``config.reward`` is the group (its design is ``config.reward.design``). ``to_kwargs()``
gives the flat keywords as plain data (run manifests store them).

Any bad value raises ``ValueError`` naming it and its valid choices or range (``TypeError``
for an unknown keyword) before anything is built. Profiles, conditions and exercises given as
dicts become :class:`PatientProfile`, :class:`PatientCondition` and :class:`Exercise` objects.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from rehabbot.common.checks import as_dataclass, check_choice, check_number
from rehabbot.sim.conditions import PatientCondition, as_condition
from rehabbot.sim.myo_patient import check_myo_profile
from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.physics import ISO_TS_15066_QUASI_STATIC_N, SafetyThresholds
from rehabbot.sim.randomization import check_preset
from rehabbot.sim.robots import ROBOT_NAMES, get_robot
from rehabbot.sim.scene import CAMERA_NAMES, SIDES, WEIGHT_LEVELS, SceneOptions, check_weight_level
from rehabbot.tasks.exercises import LIMBS, TASK_TYPES, Exercise, exercise_table
from rehabbot.tasks.reward import (
    PROGRESS_WEIGHT_PER_RAD,
    SAFETY_PENALTIES,
    SAFETY_PENALTY_STEPS,
    TIME_COST_PER_STEP,
)

CONTROL_MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")
RENDER_MODES = ("human", "rgb_array", "depth_array")
# "paper": eq. (5) (the -v0 ids); "progress": the learnable -v1 reward
# (rehabbot.tasks.reward.ProgressReward).
REWARDS = ("paper", "progress")
# What the agent sees and how its actions are scaled: "paper" / "native" (the -v0 and -v1 ids:
# the paper's 23 fields, actions in the control mode's units); "agent" / "unit" (the -v2 ids:
# rehabbot.tasks.agent_observation, actions in Box(-1, 1), rehabbot.envs.control.UnitActions).
OBSERVATIONS = ("paper", "agent")
ACTION_SCALES = ("native", "unit")

PRESET_OF: dict[tuple[str, str], str] = {
    ("arm", "right"): "upper_right", ("arm", "left"): "upper_left",
    ("hip", "right"): "hip", ("hip", "left"): "hip",
    ("knee", "right"): "knee", ("knee", "left"): "knee",
}

# Physical upper bounds of the safety thresholds: a larger value (1e9, True) would silently
# switch the rule off, so it is refused.
# Range-of-motion rule: the most a joint may go beyond its anatomical range. 10 deg is the
# hyperextension a continuous-passive-motion device allows the knee (Artromot K1 extends to
# -10 deg, its manual's range) and about the spread between the normal-range tables
# (AAOS vs Boone & Azen, section 3); beyond it the rule would accept joints past any range a
# clinician or a device accepts.
ROM_TOLERANCE_MAX_DEG = 10.0
# Unintended-contact rule: the deepest penetration that may go unreported. At the ISO/TS 15066
# quasi-static force limit the limb regions compress by at most F/k = 150 N / 30 N/mm = 5 mm
# (upper arm; hand 1.9, forearm 4.0, thigh 4.4, lower leg 2.2 mm: Tables A.2 and A.3,
# the body-region stiffnesses of its Annex A); twice that is the bound.
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


def _check_numbers(group: Any) -> None:
    """Check (and normalise) every field of ``group`` that :data:`NUMBER_RANGES` names."""
    for item in dataclasses.fields(group):
        if item.name in NUMBER_RANGES:
            low, high, integer = NUMBER_RANGES[item.name]
            object.__setattr__(group, item.name, check_number(
                item.name, getattr(group, item.name), low, high, integer))


# -- the groups ------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneConfig:
    """Where the therapy happens: the limb and side (the scene preset), the robot on the cuff,
    the cuff, the robot base's orientation, the physics step, and the randomisation preset
    drawn per episode (``randomization``, :mod:`rehabbot.sim.randomization`)."""

    limb: str = "arm"
    side: str = "right"
    robot: str = "ur5e"
    cuff: str = "connect"
    base_reorientation_deg: float = 0.0
    timestep_s: float = 0.002
    patient_model: str = "rigid"
    # Randomisation for transfer (rehabbot.sim.randomization): a preset's name drawn per
    # episode, or None (nothing drawn: every id but the -randomized- variants).
    randomization: str | None = None

    def __post_init__(self) -> None:
        check_preset(self.randomization)  # UsageError (a ValueError) naming a bad preset
        check_choice("limb", self.limb, LIMBS)
        check_choice("side", self.side, SIDES)
        check_choice("robot", self.robot, ROBOT_NAMES)
        SceneOptions(**self.scene_options())  # ValueError naming a bad scene option
        if self.patient_model == "myo" and self.limb == "arm" and self.side != "right":
            raise ValueError(f"patient_model='myo' on limb='arm' is built for side='right' "
                             f"only, not side={self.side!r}: MyoSuite's arm model is a right "
                             f"arm (myoarm_r)")

    @property
    def preset(self) -> str:
        """The scene preset of the limb and side."""
        return PRESET_OF[(self.limb, self.side)]

    def scene_options(self) -> dict[str, Any]:
        """Keyword arguments of :func:`rehabbot.sim.scene_build.build_scene`."""
        return {"robot": self.robot, "cuff": self.cuff,
                "side": None if self.limb == "arm" else self.side,
                "base_reorientation_deg": self.base_reorientation_deg,
                "timestep_s": self.timestep_s, "patient_model": self.patient_model}


@dataclass(frozen=True)
class PatientConfig:
    """Who is in the chair: the body (:class:`PatientProfile`), its condition
    (:class:`PatientCondition`) and the weight level of the exercised limb (``None``: drawn
    each episode)."""

    profile: PatientProfile | None = None
    condition: PatientCondition | None = None
    weight_level: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "profile", as_dataclass(PatientProfile, self.profile,
                                                         "profile"))
        object.__setattr__(self, "condition", as_condition(self.condition))
        if self.weight_level is not None:
            object.__setattr__(self, "weight_level", check_weight_level(self.weight_level))

    @property
    def weight_levels(self) -> tuple[int, ...]:
        """The weight levels episodes can use."""
        return WEIGHT_LEVELS if self.weight_level is None else (self.weight_level,)


@dataclass(frozen=True)
class TaskConfig:
    """What the patient does and the agent sees: the exercises, the targets' tolerance and
    sampling, the observation and the episode's horizon. (``exercise`` is checked against the
    exercise table, which depends on the scene's limb, by :class:`RehabEnvConfig`.)"""

    task_type: str = "reaching"
    exercises: tuple[Exercise, ...] | None = None
    exercise: int | None = None
    target_tolerance_rad: float = 0.05
    observation: str = "paper"
    max_episode_steps: int = 1000
    segment_s: float = 3.0
    waypoint_dt_s: float = 0.1
    min_waypoint_spacing_rad: float = 0.1

    def __post_init__(self) -> None:
        check_choice("task_type", self.task_type, TASK_TYPES)
        check_choice("observation", self.observation, OBSERVATIONS)
        _check_numbers(self)
        object.__setattr__(self, "waypoint_dt_s", check_number(
            "waypoint_dt_s", self.waypoint_dt_s, 0.01, min(1.0, self.segment_s)))


@dataclass(frozen=True)
class ControlConfig:
    """What an action means: the control mode (:mod:`rehabbot.envs.control`), its scaling,
    the physics steps per decision and the ``joint_velocity`` mode's bound. (The bound is
    checked against the scene's robot by :class:`RehabEnvConfig`.)"""

    control_mode: str = "joint_delta"
    action_scale: str = "native"
    frame_skip: int = 10
    max_speed_rad_s: float = 0.5

    def __post_init__(self) -> None:
        check_choice("control_mode", self.control_mode, CONTROL_MODES)
        check_choice("action_scale", self.action_scale, ACTION_SCALES)
        _check_numbers(self)


@dataclass(frozen=True)
class SafetyConfig:
    """The safety rules (:mod:`rehabbot.sim.physics`): whether a rule ends the episode, and
    their thresholds."""

    terminate_on_safety: bool = True
    rom_tolerance_deg: float = 2.0
    cuff_force_limit_n: float | None = None
    contact_tolerance_m: float = 0.002

    def __post_init__(self) -> None:
        if not isinstance(self.terminate_on_safety, bool):
            raise ValueError(f"terminate_on_safety={self.terminate_on_safety!r} must be a bool")
        _check_numbers(self)
        if self.cuff_force_limit_n is not None:
            object.__setattr__(self, "cuff_force_limit_n", check_number(
                "cuff_force_limit_n", self.cuff_force_limit_n, CUFF_FORCE_LIMIT_MIN_N,
                CUFF_FORCE_LIMIT_MAX_N))
        self.thresholds()  # ValueError naming a bad threshold

    def thresholds(self) -> SafetyThresholds:
        """The thresholds of the safety rules."""
        return SafetyThresholds(rom_tolerance_deg=self.rom_tolerance_deg,
                                cuff_force_limit_n=self.cuff_force_limit_n,
                                contact_tolerance_m=self.contact_tolerance_m)


@dataclass(frozen=True)
class RewardConfig:
    """What a step pays (:mod:`rehabbot.tasks.reward`): the design (the flat keyword
    ``reward``: ``"paper"``, eq. (5); ``"progress"``, the -v1 reward) and its weights."""

    design: str = "paper"
    progress_weight: float = PROGRESS_WEIGHT_PER_RAD
    time_cost: float = TIME_COST_PER_STEP
    intermediate_bonus: float = 10.0
    final_bonus: float = 100.0
    smoothness_weight: float = 0.0
    effort_weight: float = 0.0
    safety_penalty: str = "hold"
    safety_penalty_steps: int | None = SAFETY_PENALTY_STEPS

    def __post_init__(self) -> None:
        check_choice("reward", self.design, REWARDS)
        check_choice("safety_penalty", self.safety_penalty, SAFETY_PENALTIES)
        _check_numbers(self)
        if self.design == "progress" and self.safety_penalty != "hold":
            raise ValueError(f"safety_penalty={self.safety_penalty!r} applies to the paper's "
                             "reward only (reward='paper'); the progress reward has one penalty")
        if self.safety_penalty_steps is not None:
            object.__setattr__(self, "safety_penalty_steps", check_number(
                "safety_penalty_steps", self.safety_penalty_steps, 1,
                NUMBER_RANGES["max_episode_steps"][1], integer=True))


@dataclass(frozen=True)
class RenderConfig:
    """Rendering: the mode (``None``: none), the image size and the camera."""

    render_mode: str | None = None
    width: int = 640
    height: int = 480
    camera_name: str | None = "overview"

    def __post_init__(self) -> None:
        if self.render_mode is not None:
            check_choice("render_mode", self.render_mode, RENDER_MODES)
        _check_numbers(self)
        if self.camera_name is not None and self.camera_name not in CAMERA_NAMES:
            raise ValueError(f"camera_name={self.camera_name!r} is not one of "
                             f"{list(CAMERA_NAMES)} or None")


# The flat keyword of a group's field where it is not the field's own name.
FLAT_NAME_OF: dict[tuple[str, str], str] = {("reward", "design"): "reward"}
_FLAT_NAMES: dict[type, dict[str, tuple[str, str]]] = {}


@dataclass(frozen=True, init=False)
class RehabEnvConfig:
    """Every argument of a RehabEnv, in groups (module docstring; the table of the flat
    keywords is in :mod:`rehabbot.envs.rehab_env`)."""

    scene: SceneConfig
    patient: PatientConfig
    task: TaskConfig
    control: ControlConfig
    safety: SafetyConfig
    reward: RewardConfig
    render: RenderConfig
    # Derived: the exercise table actually used.
    exercise_table: tuple[Exercise, ...] = field(init=False, repr=False, compare=False)

    GROUPS: ClassVar[dict[str, type]] = {
        "scene": SceneConfig, "patient": PatientConfig, "task": TaskConfig,
        "control": ControlConfig, "safety": SafetyConfig, "reward": RewardConfig,
        "render": RenderConfig}

    def __init__(self, **kwargs: Any) -> None:
        for name, group in type(self)._groups({}, kwargs).items():
            object.__setattr__(self, name, group)
        self._check_across_groups()

    @classmethod
    def _groups(cls, base: dict[str, Any], kwargs: dict[str, Any]) -> dict[str, Any]:
        """The groups of a config: ``base`` (group name -> group; default groups where
        missing), the groups in ``kwargs`` replacing them and its flat keywords applied on
        top."""
        flat_names = cls.flat_names()
        groups = dict(base)
        changes: dict[str, dict[str, Any]] = {name: {} for name in cls.GROUPS}
        for name, value in kwargs.items():
            if name == "reward" and isinstance(value, str):  # the design (flat keyword)
                changes["reward"]["design"] = value
            elif name in cls.GROUPS:
                groups[name] = value
            elif name in flat_names:
                group, attribute = flat_names[name]
                changes[group][attribute] = value
            else:
                raise TypeError(f"{cls.__name__} got an unknown keyword argument {name!r}; "
                                f"valid: {sorted({*flat_names, *cls.GROUPS})}")
        for name, group_class in cls.GROUPS.items():
            group = groups.get(name)
            if not isinstance(group, group_class):
                group = as_dataclass(group_class, group, name)  # None: the defaults
            groups[name] = dataclasses.replace(group, **changes[name]) if changes[name] \
                else group
        return groups

    def _check_across_groups(self) -> None:
        """The checks that need two groups: the exercise table (the scene's limb and the
        task's exercises) and the joint_velocity bound (the scene's robot)."""
        table = exercise_table(self.scene.limb, self.task.exercises, self.scene.patient_model)
        object.__setattr__(self, "exercise_table", table)
        task = self.task
        if task.exercises is not None and task.exercises != table:
            task = dataclasses.replace(task, exercises=table)
        if task.exercise is not None:
            exercise = int(check_choice("exercise", task.exercise, range(len(table))))
            if exercise is not task.exercise:
                task = dataclasses.replace(task, exercise=exercise)
        object.__setattr__(self, "task", task)
        check_number("max_speed_rad_s", self.control.max_speed_rad_s, 1e-3,
                     get_robot(self.scene.robot).max_speed_rad_s)
        if self.scene.patient_model == "myo":
            check_myo_patient(self.patient)
        elif self.patient.condition.fatigue_scale > 0.0:
            raise ValueError(f"PatientCondition.fatigue_scale="
                             f"{self.patient.condition.fatigue_scale!r}: fatigue is modelled on "
                             "muscles only (the 3CC-r model of their motor units); give "
                             "patient_model='myo' (knee and hip ids), or leave it out")

    # -- flat keywords ---------------------------------------------------------------------
    @classmethod
    def flat_names(cls) -> dict[str, tuple[str, str]]:
        """Every flat keyword and where it lives: ``{"time_cost": ("reward", "time_cost"),
        ...}`` (computed once per class)."""
        names = _FLAT_NAMES.get(cls)
        if names is None:
            names = _FLAT_NAMES[cls] = {
                FLAT_NAME_OF.get((group, item.name), item.name): (group, item.name)
                for group, group_class in cls.GROUPS.items()
                for item in dataclasses.fields(group_class)}
        return names

    def __getattr__(self, name: str) -> Any:
        # A flat keyword read as an attribute (config.limb, config.time_cost, ...).
        where = type(self).flat_names().get(name)
        if where is None or where[0] not in self.__dict__:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(self.__dict__[where[0]], where[1])

    def flat(self, name: str) -> Any:
        """The value of the flat keyword ``name`` (``flat("reward")`` is the design)."""
        group, attribute = type(self).flat_names()[name]
        return getattr(getattr(self, group), attribute)

    def replace(self, **kwargs: Any) -> RehabEnvConfig:
        """A copy with flat keywords or groups replaced, validated again (``reward=`` a string
        replaces the design and keeps the reward group's weights)."""
        cls = type(self)
        return cls(**cls._groups({name: getattr(self, name) for name in cls.GROUPS}, kwargs))

    def to_kwargs(self) -> dict[str, Any]:
        """The flat keywords as plain data (profile, condition and exercises as dicts):
        JSON-able."""
        kwargs = {name: self.flat(name) for name in type(self).flat_names()}
        kwargs["profile"] = dataclasses.asdict(self.patient.profile)
        kwargs["condition"] = self.patient.condition.to_dict()
        if self.task.exercises is not None:
            kwargs["exercises"] = [exercise.to_dict() for exercise in self.task.exercises]
        return kwargs

    # -- derived ---------------------------------------------------------------------------
    @property
    def preset(self) -> str:
        """The scene preset of the limb and side."""
        return self.scene.preset

    @property
    def dt_s(self) -> float:
        """Seconds per decision: ``frame_skip x timestep_s``."""
        return self.control.frame_skip * self.scene.timestep_s

    @property
    def weight_levels(self) -> tuple[int, ...]:
        """The weight levels episodes can use."""
        return self.patient.weight_levels

    def scene_options(self) -> dict[str, Any]:
        """Keyword arguments of :func:`rehabbot.sim.scene_build.build_scene`."""
        return self.scene.scene_options()

    def safety_thresholds(self) -> SafetyThresholds:
        """The thresholds of the safety rules."""
        return self.safety.thresholds()


def check_myo_patient(patient: PatientConfig) -> None:
    """What MyoSuite's legs and arm support: the default profile (they are one adult size);
    every condition acts on their muscles (:mod:`rehabbot.sim.muscle_drive`). ``ValueError``
    naming the profile otherwise."""
    check_myo_profile(patient.profile)


def kwarg_names(config_class: type = RehabEnvConfig) -> tuple[str, ...]:
    """The flat keyword arguments an env whose config is ``config_class`` accepts (its groups'
    names are accepted too: :meth:`RehabEnvConfig.flat_names`)."""
    return tuple(config_class.flat_names())


def config_from(config_class: type, env_name: str, config: Any, kwargs: dict) -> Any:
    """An env's config: ``config`` (an instance of ``config_class``) or one built from the
    env's keyword arguments (flat or groups). ``TypeError`` for an unknown keyword (listing the
    valid ones), for both a config and keywords, or for a config of another class."""
    if config is None:
        valid = {*config_class.flat_names(), *config_class.GROUPS}
        unknown = sorted(set(kwargs) - valid)
        if unknown:
            raise TypeError(f"{env_name} got unknown keyword argument(s) {unknown}; valid: "
                            f"{sorted(valid)}")
        return config_class(**kwargs)
    if kwargs:
        raise TypeError(f"pass either a {config_class.__name__} or keyword arguments, not both")
    if not isinstance(config, config_class):
        raise TypeError(f"config must be a {config_class.__name__}, got {type(config).__name__}")
    return config
