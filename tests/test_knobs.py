"""Every knob validated: no value switches a protection off or lies.

* the env's numeric kwargs (safety thresholds included) have physical bounds and refuse
  booleans, NaN and infinities, naming the kwarg and the value;
* hyperparameters are checked before training;
* the env knows its time limit (``gym.make(id, max_episode_steps=m)``) and refuses a
  non-positive one;
* a condition variant id refuses a ``condition=`` that would replace its condition;
* the patient's torques are bounded by the patient's physiology.
"""

from __future__ import annotations

import math
import re

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.bilateral_config import BilateralEnvConfig
from rehabbot.envs.config import (
    CONTACT_TOLERANCE_MAX_M,
    CUFF_FORCE_LIMIT_MAX_N,
    NUMBER_RANGES,
    ROM_TOLERANCE_MAX_DEG,
    RehabEnvConfig,
)
from rehabbot.envs.registration import CONDITION_VARIANTS
from rehabbot.rl.hyperparam_checks import VALUE_RANGES
from rehabbot.rl.hyperparams import (
    HyperparameterError,
    hyperparameters_from_mapping,
    load_hyperparameters,
    settings_names,
)
from rehabbot.sim.conditions import healthy_strength_nm
from rehabbot.sim.physics import ISO_TS_15066_QUASI_STATIC_N
from rehabbot.sim.scene import SceneOptions

REACH = "rehabbot/rehab-reach-v1"
BAD_NUMBERS = [True, False, float("nan"), float("inf"), -float("inf"), 1e9, 1e300, -1e300]


def _named(name: str, value: object) -> str:
    """A regex matching ``name=value`` as the error messages write it."""
    return re.escape(f"{name}={value!r}")


# ----------------------------------------------------------------------------- env kwargs
# Every float kwarg of the config and where its range is checked (the config's table, the
# cuff force limit, the scene options, the joint_velocity bound, the waypoint period).
FLOAT_KWARGS = ["rom_tolerance_deg", "contact_tolerance_m", "cuff_force_limit_n",
                "base_reorientation_deg", "timestep_s", "target_tolerance_rad",
                "intermediate_bonus", "final_bonus", "smoothness_weight", "effort_weight",
                "progress_weight", "time_cost", "segment_s", "waypoint_dt_s",
                "min_waypoint_spacing_rad", "max_speed_rad_s"]
INT_KWARGS = ["frame_skip", "max_episode_steps", "safety_penalty_steps", "width", "height"]


def test_the_safety_thresholds_have_physical_upper_bounds():
    # 4 x the largest ISO/TS 15066 quasi-static limit (thighs, 220 N) = 2 x its transient.
    assert CUFF_FORCE_LIMIT_MAX_N == 4 * max(ISO_TS_15066_QUASI_STATIC_N.values()) == 880.0
    assert ROM_TOLERANCE_MAX_DEG == 10.0
    assert CONTACT_TOLERANCE_MAX_M == 0.01
    assert NUMBER_RANGES["rom_tolerance_deg"][:2] == (0.0, ROM_TOLERANCE_MAX_DEG)
    assert NUMBER_RANGES["contact_tolerance_m"][:2] == (0.0, CONTACT_TOLERANCE_MAX_M)
    # At the bounds the config is valid; just beyond, refused with the value named.
    config = RehabEnvConfig(rom_tolerance_deg=ROM_TOLERANCE_MAX_DEG,
                            contact_tolerance_m=CONTACT_TOLERANCE_MAX_M,
                            cuff_force_limit_n=CUFF_FORCE_LIMIT_MAX_N)
    assert config.safety_thresholds().cuff_force_limit_n == CUFF_FORCE_LIMIT_MAX_N
    for name, bound in (("rom_tolerance_deg", ROM_TOLERANCE_MAX_DEG),
                        ("contact_tolerance_m", CONTACT_TOLERANCE_MAX_M),
                        ("cuff_force_limit_n", CUFF_FORCE_LIMIT_MAX_N)):
        value = bound * 1.001
        with pytest.raises(ValueError, match=_named(name, value)):
            RehabEnvConfig(**{name: value})


@pytest.mark.parametrize("name", FLOAT_KWARGS + INT_KWARGS)
@pytest.mark.parametrize("value", BAD_NUMBERS, ids=repr)
def test_every_numeric_kwarg_refuses_bools_non_finite_and_huge_values(name, value):
    with pytest.raises(ValueError, match=_named(name, value)):
        RehabEnvConfig(**{name: value})


@pytest.mark.parametrize("value", [True, 1e9, 1e300, float("nan")], ids=repr)
def test_gym_make_refuses_a_threshold_that_would_switch_a_stop_off(value):
    # 1e300 used to overflow into an OverflowError traceback; True and 1e9 silently switched
    # the stops off.
    for name in ("rom_tolerance_deg", "cuff_force_limit_n", "contact_tolerance_m"):
        with pytest.raises(ValueError, match=_named(name, value)):
            gym.make(REACH, **{name: value})


def test_a_bool_is_refused_as_a_bool():
    with pytest.raises(ValueError, match=r"rom_tolerance_deg=True .*a bool is not a number"):
        RehabEnvConfig(rom_tolerance_deg=True)


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(NUMBER_RANGES)), data=st.data())
def test_a_value_outside_its_range_is_refused_and_one_inside_is_kept(name, data):
    low, high, integer = NUMBER_RANGES[name]
    outside = data.draw(st.one_of(
        st.floats(max_value=low, exclude_max=True, allow_nan=False),
        st.floats(min_value=high, exclude_min=True, allow_nan=False),
        st.booleans(), st.just(float("nan"))))
    with pytest.raises(ValueError, match=_named(name, outside)):
        RehabEnvConfig(**{name: outside})
    inside = data.draw(st.integers(int(low), int(min(high, 10**6))) if integer
                       else st.floats(low, high))
    if name == "segment_s":  # the waypoint period must fit a segment
        inside = max(inside, RehabEnvConfig().waypoint_dt_s)
    assert getattr(RehabEnvConfig(**{name: inside}), name) == inside


@pytest.mark.parametrize("kwargs", [{"sync_weight": True}, {"sync_weight": 1e9},
                                    {"sync_tolerance": float("nan")},
                                    {"rom_tolerance_deg": 1e300},
                                    {"cuff_force_limit_n": True}], ids=repr)
def test_the_bilateral_config_refuses_the_same_values(kwargs):
    (name, value), = kwargs.items()
    with pytest.raises(ValueError, match=_named(name, value)):
        BilateralEnvConfig(**kwargs)


@pytest.mark.parametrize("name", ["base_reorientation_deg", "timestep_s", "posture_hold_hz",
                                  "furniture_gap_m"])
@pytest.mark.parametrize("value", [True, float("nan"), 1e9], ids=repr)
def test_the_scene_options_refuse_bools_non_finite_and_huge_values(name, value):
    with pytest.raises(ValueError, match=_named(name, value)):
        SceneOptions(**{name: value})


def test_the_default_configs_are_valid():
    assert RehabEnvConfig().to_kwargs()["rom_tolerance_deg"] == 2.0
    assert BilateralEnvConfig().max_episode_steps == 1000
    assert SceneOptions().timestep_s == 0.002


# ----------------------------------------------------------------------------- hyperparameters
BAD_HYPERPARAMETERS = [
    ("sac", "learning_rate", -1), ("sac", "learning_rate", 0), ("sac", "learning_rate", True),
    ("sac", "learning_rate", float("nan")), ("sac", "learning_rate", "nan"),
    ("sac", "learning_rate", "lin_-0.001"), ("sac", "learning_rate", "lin_inf"),
    ("sac", "gamma", 2.0), ("sac", "gamma", 0.0), ("sac", "gamma", float("nan")),
    ("sac", "ent_coef", float("inf")), ("sac", "ent_coef", -0.1), ("sac", "ent_coef", "auto_0"),
    ("sac", "ent_coef", "auto_nan"), ("sac", "ent_coef", "often"),
    ("sac", "tau", 0.0), ("sac", "tau", 1.5), ("sac", "batch_size", 0),
    ("sac", "batch_size", True), ("sac", "buffer_size", 2.5), ("sac", "learning_starts", -1),
    ("sac", "gradient_steps", 0), ("sac", "train_freq", 0), ("sac", "train_freq", [1, "day"]),
    ("sac", "target_entropy", float("-inf")), ("sac", "use_sde", 1),
    ("td3", "policy_delay", 0), ("td3", "target_policy_noise", -0.2),
    ("ppo", "n_steps", 0), ("ppo", "n_epochs", -3), ("ppo", "gae_lambda", 1.5),
    ("ppo", "clip_range", 0), ("ppo", "clip_range", "lin_0"), ("ppo", "vf_coef", float("inf")),
    ("ppo", "max_grad_norm", 0.0), ("ppo", "target_kl", -1.0),
]


@pytest.mark.parametrize(("algo", "key", "value"), BAD_HYPERPARAMETERS, ids=repr)
def test_bad_hyperparameters_are_refused_before_training(algo, key, value):
    with pytest.raises(HyperparameterError, match=_named(key, value)):
        hyperparameters_from_mapping({key: value}, algo)


@pytest.mark.parametrize(("algo", "mapping"), [
    ("sac", {"learning_rate": 3e-4, "gamma": 1.0, "tau": 1.0, "ent_coef": "auto"}),
    ("sac", {"learning_rate": "lin_7.3e-4", "ent_coef": "auto_0.1", "gradient_steps": -1,
             "train_freq": [1, "episode"], "target_entropy": "auto", "use_sde": True}),
    ("sac", {"ent_coef": 0.0, "learning_starts": 0, "batch_size": "256", "gamma": "0.99"}),
    ("ppo", {"clip_range": "lin_0.2", "clip_range_vf": None, "target_kl": None,
             "gae_lambda": 0.0, "n_steps": 2048, "vf_coef": 0.5}),
], ids=repr)
def test_valid_hyperparameters_pass(algo, mapping):
    hyperparameters_from_mapping(mapping, algo)


@pytest.mark.parametrize("name", settings_names())
def test_every_shipped_settings_file_passes_the_checks(name):
    algo = name.split("/")[-1].split("-")[0]
    load_hyperparameters(name, "rehabbot/rehab-reach-v2", algo)  # every file has an entry


@settings(max_examples=50, deadline=None)
@given(gamma=st.one_of(st.floats(allow_nan=True), st.booleans()))
def test_gamma_is_accepted_exactly_in_the_unit_interval(gamma):
    if not isinstance(gamma, bool) and math.isfinite(gamma) and 0.0 < gamma <= 1.0:
        assert hyperparameters_from_mapping({"gamma": gamma}, "sac").kwargs["gamma"] == gamma
    else:
        with pytest.raises(HyperparameterError, match=_named("gamma", gamma)):
            hyperparameters_from_mapping({"gamma": gamma}, "sac")


def test_every_ranged_key_is_an_argument_of_some_algorithm():
    import inspect

    from rehabbot.rl.algorithms import ALGO_NAMES, algo_class

    params: set[str] = set()
    for algo in ALGO_NAMES:
        try:
            params |= set(inspect.signature(algo_class(algo, "sb3").__init__).parameters)
        except Exception:  # an optional backend that is not installed
            continue
    assert set(VALUE_RANGES) <= params, set(VALUE_RANGES) - params


# ----------------------------------------------------------------------------- time limit
def _horizons(env: gym.Env) -> tuple[int, ...]:
    base = env.unwrapped
    return (base.max_episode_steps, base.config.max_episode_steps,
            base.reward_function.max_episode_steps, env.spec.max_episode_steps)


@pytest.mark.parametrize("env_id", [REACH, "rehabbot/rehab-knee-v0",
                                    "rehabbot/rehab-reach-population-v1"])
def test_gym_make_max_episode_steps_reaches_the_env(env_id):
    env = gym.make(env_id, max_episode_steps=37)
    assert _horizons(env) == (37, 37, 37, 37)
    env.reset(seed=0)
    truncated = False
    for _ in range(37):
        *_, terminated, truncated, _info = env.step(np.zeros(env.action_space.shape, np.float32))
        if terminated:
            break
    assert truncated or terminated
    env.close()


def test_the_default_ids_keep_their_horizon():
    env = gym.make(REACH)
    assert _horizons(env) == (1000, 1000, 1000, 1000)
    assert env.unwrapped.config == RehabEnvConfig(**gym.spec(REACH).kwargs)
    env.close()


@pytest.mark.slow
def test_the_bilateral_id_takes_the_limit_too():
    env = gym.make("rehabbot/rehab-bilateral-v1", max_episode_steps=55)
    assert _horizons(env) == (55, 55, 55, 55)
    env.close()


@pytest.mark.parametrize("limit", [-1, 0, -5, True, 2.5, 10**6 + 1], ids=repr)
def test_a_non_positive_time_limit_is_refused(limit):
    # Gymnasium's -1 would silently remove the TimeLimit: refused, the stop penalty needs a
    # horizon.
    with pytest.raises(ValueError, match=_named("max_episode_steps", limit)):
        gym.make(REACH, max_episode_steps=limit)


def test_a_spec_without_a_time_limit_keeps_the_envs_own_horizon():
    made = gym.make(REACH, max_episode_steps=40)
    spec = made.unwrapped.spec  # gym.make leaves max_episode_steps=None in it
    assert spec.max_episode_steps is None
    again = gym.make(spec)  # as Gymnasium's env checker and vector envs do
    assert again.unwrapped.max_episode_steps == 1000
    again.close()
    own = gym.make(gym.envs.registration.EnvSpec(
        id="rehabbot-own-horizon", entry_point=spec.entry_point,
        kwargs={**spec.kwargs, "max_episode_steps": 40}, max_episode_steps=None))
    assert own.unwrapped.max_episode_steps == 40
    made.close()
    own.close()


def test_the_time_limit_cannot_change_during_an_episode():
    env = gym.make(REACH)
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, np.float32))
    with pytest.raises(RuntimeError, match="during an episode"):
        env.unwrapped.set_time_limit(50)
    with pytest.raises(ValueError, match=_named("max_episode_steps", 0)):
        env.unwrapped.set_time_limit(0)
    env.close()


# ----------------------------------------------------------------------------- variants
@pytest.mark.parametrize("condition", [None, {}, {"spasticity_mas": "3"}], ids=repr)
def test_a_condition_variant_refuses_a_condition_that_replaces_its_own(condition):
    base_id = CONDITION_VARIANTS["rehabbot/rehab-reach-spastic-v1"][0]
    with pytest.raises(ValueError, match=_named("condition", condition)) as err:
        gym.make("rehabbot/rehab-reach-spastic-v1", condition=condition)
    assert base_id in str(err.value)


def test_a_condition_variant_accepts_its_own_condition():
    for kwargs in ({}, {"condition": {"spasticity_mas": "2"}}):
        env = gym.make("rehabbot/rehab-reach-spastic-v1", **kwargs)
        assert env.unwrapped.config.condition.spasticity_mas == "2"
        env.close()


# ----------------------------------------------------------------------------- patient torques
@pytest.fixture(scope="module")
def rigid_arm():
    """A grade-4 spastic arm with the safety stops off (where the reflex was unbounded)."""
    env = gym.make(REACH, condition={"spasticity_mas": "4", "tremor_hz": 5.0,
                                     "tremor_amplitude_nm": 10.0},
                   terminate_on_safety=False, control_mode="torque")
    yield env
    env.close()


def test_the_patient_torque_bound_is_the_healthy_peak_torque(rigid_arm):
    base = rigid_arm.unwrapped
    drive = base._physics.drive
    profile = base.scene.profile
    joints = [base.model.joint(int(base.model.dof_jntid[d])).name.rsplit("_", 1)[0]
              for d in drive._dofs]
    assert drive.peak_nm == [healthy_strength_nm(j, profile.mass_kg, profile.sex)
                             for j in joints]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(speed=st.floats(-500.0, 500.0), where=st.floats(0.0, 1.0))
def test_the_reflex_never_exceeds_the_patients_strength(rigid_arm, speed, where):
    drive = rigid_arm.unwrapped._physics.drive
    n = len(drive._dofs)
    drive._velocity_history = [[speed] * n for _ in drive._velocity_history]
    q = [low + where * (high - low) for low, high in zip(drive._low, drive._high, strict=True)]
    torque = drive._torques(q, [speed] * n, q, [0.0] * n)
    for t, (pos, neg) in zip(torque, drive.peak_nm, strict=True):
        assert -neg - 1e-12 <= t <= pos + 1e-12
    if abs(speed) >= 400.0 and 0.2 < where < 0.8:  # a fast stretch saturates the muscles
        assert any(math.isclose(abs(t), bound) for t, bound in
                   zip(torque, [p if s else m for (p, m), s in
                                zip(drive.peak_nm, [t > 0 for t in torque], strict=True)],
                       strict=True))


def test_patient_torques_stay_bounded_when_the_robot_forces_the_limb(rigid_arm):
    base = rigid_arm.unwrapped
    peak = np.array(base._physics.drive.peak_nm)
    exercised = base._physics.drive.exercised_index
    rigid_arm.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    action = np.zeros(rigid_arm.action_space.shape, np.float32)
    for k in range(150):
        action[1] = 1.0 if (k // 25) % 2 else -1.0  # full torque back and forth
        *_, terminated, _truncated, info = rigid_arm.step(action)
        torque = info["patient_torque_nm"][exercised]
        assert np.all(torque <= peak[:, 0] + 1e-9) and np.all(torque >= -peak[:, 1] - 1e-9)
        if terminated:  # only an instability ends it with the stops off
            break
