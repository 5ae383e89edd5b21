"""The registered environment ids: one class (:class:`rehabbot.envs.rehab_env.RehabEnv`),
variants by keyword arguments. ``import rehabbot`` calls :func:`register_envs`.

Every id is registered with Gymnasium's ``TimeLimit`` (``max_episode_steps=1000``; 2000 for the
bilateral id, whose alternating exercises move each arm in turn) and without
its ``OrderEnforcing`` and ``PassiveEnvChecker`` wrappers: the env itself refuses ``step()``
before ``reset()`` (``gymnasium.error.ResetNeeded``) and checks its actions, and the test suite
runs Gymnasium's full ``check_env`` on every id. Gymnasium 1.4's passive checker also broke an
env whose first ``reset()`` raised (the next ``step()`` failed with ``TypeError: cannot unpack
non-iterable NoneType object``). ``gym.make(id, disable_env_checker=False)`` or
``order_enforce=True`` add them back.

The env knows its time limit. ``gym.make(id, max_episode_steps=m)`` gives ``m`` to the
``TimeLimit`` wrapper only (it never reaches the env's constructor), so the env reads it back
when ``gym.make`` hands it its spec (:func:`time_limit_from_make`) and uses ``m`` wherever
it uses ``max_episode_steps``: the safety penalties' steps left, ``config`` and the rendering's
trace. A non-positive ``m`` is refused (``ValueError`` naming it), and so is Gymnasium's
``m=-1`` ("no ``TimeLimit``"): the safety penalty needs a horizon. A spec without a time limit
(``gym.make(spec)`` of a spec whose ``max_episode_steps`` is None, as ``env.unwrapped.spec``
is: Gymnasium's env checker and vector envs make envs again from it) keeps the env's own
horizon (its ``max_episode_steps=`` keyword, 1000 by default), and nothing truncates the
episodes. Gymnasium offers no hook for this: the env's ``spec`` setter
reads ``max_episode_steps``, ``env_spec`` and ``kwargs`` from the frame of
``gymnasium.make`` that sets it (Gymnasium 1.x; ``tests/test_knobs.py`` fails if a new
version moves them).

A condition variant (:data:`CONDITION_VARIANTS`) is its base id with a condition: ``gym.make``
of a variant id refuses a ``condition=`` that would replace it (``condition=None`` would
silently give a healthy patient); use the base id with ``condition=`` instead.
"""

from __future__ import annotations

import types
from typing import Any

import gymnasium as gym
import gymnasium.envs.registration as gym_registration

from rehabbot.common.errors import UsageError

NAMESPACE = "rehabbot"
ENTRY_POINT = "rehabbot.envs.rehab_env:RehabEnv"
MAX_EPISODE_STEPS = 1000

# id -> (kwargs, one-line description). The -v0 ids are the paper's Table 2 with eq. (5); the
# -v1 ids are the same tasks and spaces with the learnable progress reward
# (rehabbot.tasks.reward).
ENV_SPECS: dict[str, tuple[dict, str]] = {
    "rehabbot/rehab-reach-v0": (
        {"limb": "arm", "side": "right", "task_type": "reaching"},
        "right arm, seated: reach 6 shoulder or elbow key poses in order",
    ),
    "rehabbot/rehab-reach-l-v0": (
        {"limb": "arm", "side": "left", "task_type": "trajectory"},
        "left arm, seated: follow dense waypoints of a minimum-jerk shoulder or elbow path",
    ),
    "rehabbot/rehab-hip-v0": (
        {"limb": "hip", "side": "right", "task_type": "reaching"},
        "right leg, supine: reach 6 hip flexion/extension key poses in order",
    ),
    "rehabbot/rehab-knee-v0": (
        {"limb": "knee", "side": "right", "task_type": "trajectory"},
        "right leg, seated: follow dense waypoints of a minimum-jerk knee flexion/extension path",
    ),
}
V1_KWARGS = {"reward": "progress"}
for _v0_id, (_kwargs, _description) in list(ENV_SPECS.items()):
    ENV_SPECS[_v0_id.replace("-v0", "-v1")] = (
        {**_kwargs, **V1_KWARGS}, f"{_description}; learnable progress reward")

# Patients with clinical conditions (rehabbot.sim.conditions; docs/conditions.md): the -v1
# task of the base id with a PatientCondition. Same spaces and reward as the base id.
CONDITION_VARIANTS: dict[str, tuple[str, dict, str]] = {
    "rehabbot/rehab-reach-spastic-v1": (
        "rehabbot/rehab-reach-v1", {"spasticity_mas": "2"},
        "spastic arm (Modified Ashworth 2): the stretch reflex resists fast motion"),
    "rehabbot/rehab-reach-tremor-v1": (
        "rehabbot/rehab-reach-v1", {"tremor_hz": 5.0, "tremor_amplitude_nm": 1.0},
        "5 Hz rest tremor (parkinsonian band), 1 N·m on each exercised joint"),
    "rehabbot/rehab-reach-active-v1": (
        "rehabbot/rehab-reach-v1", {"effort": "active_assisted", "strength_fraction": 0.3},
        "hemiparetic arm at 30 % strength that tries to follow the exercise"),
    "rehabbot/rehab-hip-spastic-v1": (
        "rehabbot/rehab-hip-v1", {"spasticity_mas": "2"},
        "spastic leg (Modified Ashworth 2) in the supine straight-leg raise"),
    "rehabbot/rehab-knee-weak-v1": (
        "rehabbot/rehab-knee-v1", {"effort": "active_assisted", "strength_fraction": 0.1},
        "weak knee (10 % strength) that tries to follow the exercise"),
    "rehabbot/rehab-knee-stiff-v1": (
        "rehabbot/rehab-knee-v1", {"stiffness_scale": 3.0, "rom_scale": 0.7},
        "contracted knee: passive stiffness x3, 70 % of the range of motion"),
    "rehabbot/rehab-knee-resistive-v1": (
        "rehabbot/rehab-knee-v1", {"effort": "resistive", "effort_fraction": 0.1},
        "resistive exercise: the patient pushes against the motion with 10 % of its strength"),
}
for _id, (_base_id, _condition, _description) in CONDITION_VARIANTS.items():
    ENV_SPECS[_id] = ({**ENV_SPECS[_base_id][0], "condition": dict(_condition)}, _description)

# A new patient every episode (rehabbot.envs.population, rehabbot.sim.populations): the base
# -v1 task with patients drawn from the "train" population; patients="test" gives the
# held-out one.
POPULATION_ENTRY_POINT = "rehabbot.envs.population:PopulationEnv"
POPULATION_VARIANTS: dict[str, str] = {
    "rehabbot/rehab-reach-population-v1": "rehabbot/rehab-reach-v1",
    "rehabbot/rehab-knee-population-v1": "rehabbot/rehab-knee-v1",
}
for _id, _base_id in POPULATION_VARIANTS.items():
    ENV_SPECS[_id] = ({**ENV_SPECS[_base_id][0], "patients": "train"},
                      f"{ENV_SPECS[_base_id][1]}; a patient of a population each episode")

# Both arms, one robot per hand (rehabbot.envs.bilateral_env): the -v1 reward summed over the
# arms with a synchronisation term; symmetric and alternating patterns.
BILATERAL_ENTRY_POINT = "rehabbot.envs.bilateral_env:BilateralEnv"
BILATERAL_IDS: tuple[str, ...] = ("rehabbot/rehab-bilateral-v1", "rehabbot/rehab-bilateral-v2")
# 40 s: an alternating exercise makes every move twice, one arm at a time (the scripted expert
# needs up to 847 steps of the UR5e; one-arm exercises up to 446 of 1000).
BILATERAL_MAX_EPISODE_STEPS = 2000
ENV_SPECS["rehabbot/rehab-bilateral-v1"] = (
    {"limb": "arm", "task_type": "reaching", "max_episode_steps": BILATERAL_MAX_EPISODE_STEPS},
    "both arms, seated, a robot on each hand: reach shoulder or elbow key poses with both arms "
    "together (symmetric) or in turns (alternating); learnable progress reward with a "
    "synchronisation term")


# The -v2 ids: every -v1 id (the same task and reward) with the agent observation
# (rehabbot.tasks.agent_observation: tracking errors, next target, cuff force margin, ... every
# entry in [-2, 2]) and actions in Box(-1, 1); what a plain network of any framework learns.
V2_KWARGS = {"observation": "agent", "action_scale": "unit"}
V1_IDS: tuple[str, ...] = tuple(i for i in ENV_SPECS if i.endswith("-v1"))
for _v1_id in V1_IDS:
    _v2_id = _v1_id.replace("-v1", "-v2")
    _kwargs, _description = ENV_SPECS[_v1_id]
    ENV_SPECS[_v2_id] = ({**_kwargs, **V2_KWARGS},
                         f"{_description}; agent observation, actions in [-1, 1]")
    if _v1_id in CONDITION_VARIANTS:
        _base, _condition, _text = CONDITION_VARIANTS[_v1_id]
        CONDITION_VARIANTS[_v2_id] = (_base.replace("-v1", "-v2"), _condition, _text)
    if _v1_id in POPULATION_VARIANTS:
        POPULATION_VARIANTS[_v2_id] = POPULATION_VARIANTS[_v1_id].replace("-v1", "-v2")

# Every one-arm and leg -v2 task with a patient of a population each episode: the reach and
# knee ids above, and the left arm's trajectory and the hip. Their default population is
# "train"; patients="envelope-train" draws across the adult envelope (rehabbot.sim.envelope).
for _base_id in ("rehabbot/rehab-reach-l-v2", "rehabbot/rehab-hip-v2"):
    _id = _base_id.replace("-v2", "-population-v2")
    POPULATION_VARIANTS[_id] = _base_id
    ENV_SPECS[_id] = ({**ENV_SPECS[_base_id][0], "patients": "train"},
                      f"{ENV_SPECS[_base_id][1]}; a patient of a population each episode")

# Randomisation for transfer (rehabbot.sim.randomization; docs/deployment/randomisation.md):
# each one-arm and leg population -v2 id with the adult envelope's training cohort (a body of
# another size each episode: the segment lengths) and the "transfer" preset (masses, passive
# stiffness and damping, cuff compliance, joint friction, encoder noise, 0-2 decisions of
# action latency, drawn every episode). Same spaces as the base id; what the agent sees
# changes (noise, latency), hence new ids.
RANDOMIZED_VARIANTS: dict[str, str] = {
    _id.replace("-population-v2", "-randomized-v2"): _id
    for _id in ("rehabbot/rehab-reach-population-v2", "rehabbot/rehab-knee-population-v2",
                "rehabbot/rehab-reach-l-population-v2", "rehabbot/rehab-hip-population-v2")}
RANDOMIZED_KWARGS = {"patients": "envelope-train", "randomization": "transfer"}
for _id, _base_id in RANDOMIZED_VARIANTS.items():
    ENV_SPECS[_id] = ({**ENV_SPECS[_base_id][0], **RANDOMIZED_KWARGS},
                      f"{ENV_SPECS[_base_id][1]} (the envelope's training cohort); "
                      "masses, passive joints, cuff, friction, sensor noise and action latency "
                      "randomised every episode")

# MyoSuite's musculoskeletal legs (rehabbot.sim.myo_patient) and right arm
# (rehabbot.sim.myo_arm; pip install "rehabbot[myo]"): the -v2 task of the base id on
# patient_model="myo", the same observation and actions.
MYO_VARIANTS: dict[str, str] = {
    "rehabbot/rehab-knee-myo-v2": "rehabbot/rehab-knee-v2",
    "rehabbot/rehab-hip-myo-v2": "rehabbot/rehab-hip-v2",
    "rehabbot/rehab-reach-myo-v2": "rehabbot/rehab-reach-v2",
}
_MYO_MODEL_TEXT = {"arm": "MyoSuite's musculoskeletal right arm (63 passive muscles)"}
for _id, _base_id in MYO_VARIANTS.items():
    _limb = ENV_SPECS[_base_id][0].get("limb")
    ENV_SPECS[_id] = ({**ENV_SPECS[_base_id][0], "patient_model": "myo"},
                      f"{ENV_SPECS[_base_id][1]}; "
                      + _MYO_MODEL_TEXT.get(_limb, "MyoSuite's musculoskeletal legs (80 passive "
                                                   "muscles)"))
V2_IDS: tuple[str, ...] = tuple(i.replace("-v1", "-v2") for i in V1_IDS)


# What an id's kwargs need beyond the core install: (kwarg, value) -> the extra of
# ``pip install "rehabbot[EXTRA]"`` that brings it (read by ``rehabbot list``; a test builds
# every id on a core install to check it).
KWARG_EXTRAS: dict[tuple[str, str], str] = {("patient_model", "myo"): "myo"}


def required_extra(env_id: str) -> str | None:
    """The extra that building ``env_id`` needs beyond the core install (``"myo"`` for
    MyoSuite's models), or None; read from the id's registered kwargs, nothing is built."""
    kwargs = ENV_SPECS[env_id][0]
    for (key, value), extra in KWARG_EXTRAS.items():
        if kwargs.get(key) == value:
            return extra
    return None


def entry_point_of(env_id: str) -> str:
    """The class an id builds: RehabEnv, PopulationEnv or BilateralEnv."""
    if env_id in BILATERAL_IDS:
        return BILATERAL_ENTRY_POINT
    return POPULATION_ENTRY_POINT if "patients" in ENV_SPECS[env_id][0] else ENTRY_POINT


def _made_by_gym(caller: types.FrameType | None) -> bool:
    return caller is not None and caller.f_code is gym_registration.make.__code__


def check_variant_condition(spec: Any, caller: types.FrameType | None) -> None:
    """Refuse (``ValueError``) a ``condition=`` given to ``gym.make`` of a condition variant id
    that differs from the variant's own condition (``caller``: as in
    :func:`time_limit_from_make`)."""
    env_id = getattr(spec, "id", None)
    if env_id not in CONDITION_VARIANTS or not _made_by_gym(caller):
        return
    refuse_condition_override(env_id, caller.f_locals.get("kwargs") or {})


def refuse_condition_override(env_id: str, given: dict) -> None:
    """Refuse (``ValueError``) keyword arguments ``given`` for ``env_id`` whose
    ``condition=`` differs from the condition variant's own (nothing to check for another
    id, or without ``condition=``)."""
    if env_id not in CONDITION_VARIANTS or "condition" not in given:
        return
    from rehabbot.sim.conditions import as_condition  # the env module imports this one

    base_id, own, _description = CONDITION_VARIANTS[env_id]
    if as_condition(given["condition"]) != as_condition(own):
        raise ValueError(
            f"condition={given['condition']!r} would replace the condition of {env_id} "
            f"({own}); make the base id with a condition instead: "
            f"gym.make({base_id!r}, condition=...)")


def time_limit_from_make(spec: Any, caller: types.FrameType | None) -> int | None:
    """The time limit of an env whose ``spec`` is being set by ``caller`` (the frame that sets
    ``env.unwrapped.spec``): ``None`` to keep the env's own.

    When ``caller`` is ``gymnasium.make`` (which sets a spec without the time limit, then
    wraps the env in ``TimeLimit``), the limit is the ``max_episode_steps`` given to ``make``,
    else the registered one; otherwise the spec's ``max_episode_steps`` when it has one.

    Raises:
        ValueError: a ``max_episode_steps`` that is not a positive integer (``-1``, Gymnasium's
            "no time limit", included).
    """
    if _made_by_gym(caller):
        given = caller.f_locals.get("max_episode_steps")
        registered = getattr(caller.f_locals.get("env_spec"), "max_episode_steps", None)
        if given is not None:
            if isinstance(given, bool) or not isinstance(given, int) or given <= 0:
                raise ValueError(
                    f"max_episode_steps={given!r} must be a positive integer (the episode's "
                    "time limit; -1, Gymnasium's 'no time limit', is refused: the safety "
                    "penalty counts the steps left to the limit)")
            return given
        return registered  # None: no TimeLimit; the env keeps its own horizon
    limit = getattr(spec, "max_episode_steps", None)
    if isinstance(limit, int) and not isinstance(limit, bool) and limit > 0:
        return limit
    return None


def check_make(spec: Any, caller: types.FrameType | None) -> int | None:
    """What an env checks when ``caller`` sets its ``spec``: :func:`check_variant_condition`,
    then the time limit it takes (:func:`time_limit_from_make`)."""
    check_variant_condition(spec, caller)
    return time_limit_from_make(spec, caller)


def register_envs() -> None:
    """Register every id of :data:`ENV_SPECS` with Gymnasium (idempotent)."""
    for env_id, (kwargs, _description) in ENV_SPECS.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry_point_of(env_id), kwargs=dict(kwargs),
                     max_episode_steps=kwargs.get("max_episode_steps", MAX_EPISODE_STEPS),
                     order_enforce=False, disable_env_checker=True,
                     vector_entry_point=f"rehabbot.envs.vector:{vector_creator_name(env_id)}")


def vector_creator_name(env_id: str) -> str:
    """The name, in :mod:`rehabbot.envs.vector`, of ``env_id``'s vector entry point (Gymnasium
    passes it the number of worlds and the keyword arguments, not the id; it loads the
    module when ``make_vec`` first needs it)."""
    return "vector_" + env_short_name(env_id).replace("-", "_")


def resolve_env_id(name: str) -> str:
    """The full registered id for ``name`` (full, or without the ``rehabbot/`` prefix).

    Raises:
        UsageError: ``name`` is not a RehabBot id (the message lists the valid ones).
    """
    for candidate in (name, f"{NAMESPACE}/{name}"):
        if candidate in ENV_SPECS:
            return candidate
    raise UsageError(f"unknown env id {name!r}; valid ids: {', '.join(ENV_SPECS)} "
                     f"(the '{NAMESPACE}/' prefix may be left out)")


def env_short_name(env_id: str) -> str:
    """``rehabbot/rehab-reach-v0`` -> ``rehab-reach-v0``."""
    return env_id.split("/", 1)[-1]
