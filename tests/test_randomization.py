"""Randomisation for transfer (rehabbot.sim.randomization): every quantity of the preset is
drawn per episode into the MjModel within its stated range, recorded, reproducible per seed;
the action latency delays by exactly k decisions; the noise reaches only what the agent sees;
without a preset nothing changes (the golden episodes, tests/test_golden.py, check the ids
bit for bit)."""

import dataclasses
import itertools
import re

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.common.errors import UsageError
from rehabbot.envs.config import RehabEnvConfig
from rehabbot.envs.registration import (
    ENV_SPECS,
    RANDOMIZED_KWARGS,
    RANDOMIZED_VARIANTS,
)
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.sim.randomization import PRESETS, ActionDelay, check_preset
from rehabbot.sim.scene import weight_factors

PRESET = PRESETS["transfer"]
# A draw's ratio to the built value is computed in floating point: inside its range up to a
# relative rounding far below any change of a range (1e-6 of a range of 0.3 or more).
SLACK = 1e-9
KNEE = {"limb": "knee", "task_type": "trajectory", "observation": "agent",
        "action_scale": "unit"}


def _inside(values, low, high):
    values = np.asarray(values, float)
    span = high - low
    return bool(np.all(values >= low - SLACK * span) and np.all(values <= high + SLACK * span))


@pytest.fixture(scope="module")
def pair():
    """A nominal knee env and the same env with the preset (each built once)."""
    nominal = RehabEnv(**KNEE)
    randomized = RehabEnv(**KNEE, randomization="transfer")
    yield nominal, randomized
    nominal.close()
    randomized.close()


def test_without_a_preset_nothing_is_drawn_and_the_model_is_the_built_one():
    env, default = RehabEnv(**KNEE, randomization=None), RehabEnv(**KNEE)
    built = (env.model.body_mass.copy(), env.model.jnt_stiffness.copy(),
             env.model.dof_damping.copy(), env.model.dof_frictionloss.copy(),
             env.model.eq_solref.copy(), env.model.eq_solimp.copy())
    rng = np.random.default_rng(0)
    for seed in range(2):
        obs_a, info_a = env.reset(seed=seed, options={"weight_level": 0})
        obs_b, _info = default.reset(seed=seed, options={"weight_level": 0})
        assert "randomization" not in info_a and env.unwrapped.randomization_draw is None
        assert np.array_equal(obs_a, obs_b)
        for _ in range(20):
            action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            obs_a, reward_a, *_ = env.step(action)
            obs_b, reward_b, *_ = default.step(action)
            assert np.array_equal(obs_a, obs_b) and reward_a == reward_b
    model = env.model
    for before, after in zip(built, (model.body_mass, model.jnt_stiffness, model.dof_damping,
                                     model.dof_frictionloss, model.eq_solref, model.eq_solimp),
                             strict=True):
        assert np.array_equal(before, after)
    env.close()
    default.close()


def test_every_quantity_changes_between_episodes_within_its_range(pair):
    nominal, env = pair
    model, scene, built = env.model, env.scene, nominal.model
    bodies = scene.limb_body_ids
    dofs = scene.compliant_dof_adr
    joints = model.dof_jntid[dofs]
    robot_dofs = env.handle.dof_adr
    cuff = env.handle.equality_id
    limits = env.robot.torque_limit_nm
    seen = []
    for seed in range(6):
        _obs, info = env.reset(seed=seed)
        draw = env.randomization_draw
        assert info["randomization"] == draw.to_dict()
        factor = weight_factors(scene.preset)[scene.weight_level]
        mass = model.body_mass[bodies] / (scene.nominal_body_mass[bodies] * factor)
        inertia = model.body_inertia[bodies] / (scene.nominal_body_inertia[bodies] * factor)
        stiffness = model.jnt_stiffness[joints] / built.jnt_stiffness[joints]
        damping = model.dof_damping[dofs] / built.dof_damping[dofs]
        quantities = {
            "mass": (mass, *PRESET.segment_mass_scale),
            "inertia": (inertia.ravel(), *PRESET.segment_mass_scale),
            "stiffness": (stiffness, *PRESET.passive_stiffness_scale),
            "damping": (damping, *PRESET.passive_damping_scale),
            "timeconst": (model.eq_solref[cuff, :1], *PRESET.cuff_timeconst_s),
            "dampratio": (model.eq_solref[cuff, 1:], *PRESET.cuff_dampratio),
            "impedance": (model.eq_solimp[cuff, :1], *PRESET.cuff_impedance_min),
            "patient_friction": (model.dof_frictionloss[dofs], *PRESET.patient_frictionloss_nm),
            "robot_friction": (model.dof_frictionloss[robot_dofs] / limits,
                               *PRESET.robot_frictionloss_fraction),
        }
        for name, (values, low, high) in quantities.items():
            assert _inside(values, low, high), (name, values)
        # The model holds exactly what the draw records.
        assert np.allclose(mass, draw.segment_mass_scale, rtol=SLACK, atol=0)
        assert np.allclose(stiffness, draw.stiffness_scale, rtol=SLACK, atol=0)
        assert np.allclose(model.dof_frictionloss[robot_dofs], draw.robot_frictionloss_nm,
                           rtol=SLACK, atol=0)
        assert tuple(model.eq_solref[cuff]) == draw.cuff_solref[0]
        assert model.eq_solimp[cuff, 1] == built.eq_solimp[cuff, 1]  # solimp[1] stays
        assert draw.latency_steps in (0, 1, 2)
        # Nothing else of the model moves: the posture joints and the other bodies.
        others = np.setdiff1d(np.arange(model.nbody), bodies)
        assert np.array_equal(model.body_mass[others], built.body_mass[others])
        posture = model.dof_jntid[scene.posture_dof_adr]
        assert np.array_equal(model.jnt_stiffness[posture] > 0, built.jnt_stiffness[posture] > 0)
        seen.append({name: np.array(values, float) for name, (values, _l, _h) in
                     quantities.items()})
    for name in seen[0]:  # each quantity differs between consecutive episodes
        for before, after in itertools.pairwise(seen):
            assert not np.array_equal(before[name], after[name]), name
    assert len({d for d in (env.reset(seed=s)[1]["randomization"]["latency_steps"]
                            for s in range(30))}) == 3  # 0, 1 and 2 all occur


def test_the_draws_are_reproducible_per_seed_and_differ_between_seeds(pair):
    _nominal, env = pair
    other = RehabEnv(**KNEE, randomization="transfer")
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1, 1, (15, *env.action_space.shape)).astype(np.float32)
    runs = []
    for e, seed in ((env, 7), (other, 7), (other, 8)):
        obs, info = e.reset(seed=seed, options={"exercise": 0, "weight_level": 2})
        trace = [obs]
        for action in actions:
            trace.append(e.step(action)[0])
        runs.append((info["randomization"], np.array(trace)))
    assert runs[0][0] == runs[1][0] and np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][0]["segment_mass_scale"] != runs[2][0]["segment_mass_scale"]
    assert not np.array_equal(runs[0][1], runs[2][1])
    other.close()


def test_the_action_delay_hands_each_action_back_exactly_k_pushes_later():
    for k in (0, 1, 2):
        delay = ActionDelay(k)
        out = [delay.push(np.array([float(i)])) for i in range(6)]
        assert out[:k] == [None] * k
        assert [float(a[0]) for a in out[k:]] == [float(i) for i in range(6 - k)]
    buffered = np.array([1.0])
    delay = ActionDelay(1)
    delay.push(buffered)
    buffered[0] = 5.0  # the caller's array changes after the push: the queued copy does not
    assert delay.push(np.array([2.0]))[0] == 1.0
    with pytest.raises(UsageError, match="-1"):
        ActionDelay(-1)


def _first_move(env, seed: int) -> tuple[int, int]:
    """The episode's latency, and the decision at which the servo setpoint first moves after
    one full-scale action at decision 1 (zeros after it)."""
    env.reset(seed=seed, options={"exercise": 0, "weight_level": 0})
    latency = env.randomization_draw.latency_steps
    home = env.controller.setpoint_rad.copy()
    push = np.ones(env.action_space.shape, np.float32)
    for step in range(1, 6):
        env.step(push if step == 1 else np.zeros_like(push))
        if not np.array_equal(env.controller.setpoint_rad, home):
            return latency, step
    return latency, -1


def test_the_robot_receives_each_action_exactly_latency_decisions_late(pair):
    _nominal, env = pair
    found = {}
    for seed in range(40):
        latency, step = _first_move(env, seed)
        found.setdefault(latency, step)
        assert step == latency + 1, (seed, latency, step)
        if len(found) == 3:
            break
    assert sorted(found) == [0, 1, 2]


def test_the_noise_reaches_what_the_agent_sees_not_the_state(pair):
    _nominal, env = pair
    paper = RehabEnv(limb="knee", task_type="trajectory", randomization="transfer")
    obs, info = paper.reset(seed=1)
    layout = paper.layout
    truth = paper.paper_observation()  # the state's own
    theta, phi, p = layout.slice("theta"), layout.slice("phi"), layout.slice("p")
    theta_error = (obs[theta] - truth[theta]).astype(float)
    phi_error = (obs[phi] - truth[phi]).astype(float)
    assert np.all(theta_error != 0) and np.all(phi_error != 0)
    assert np.all(np.abs(theta_error) < 6 * PRESET.encoder_noise_rad)
    assert np.all(np.abs(phi_error) < 6 * PRESET.patient_angle_noise_rad)
    assert np.array_equal(obs[p], truth[p])  # the tool position: the true forward kinematics
    # The agent observation: the same env without noise (the same draws: a zero deviation
    # still draws) sees other values, while the state, the reward and info's paper
    # observation stay the noisy env's, step for step.
    quiet = RehabEnv(**KNEE, randomization="transfer")
    quiet._randomizer.preset = dataclasses.replace(
        PRESET, encoder_noise_rad=0.0, velocity_noise_rad_s=0.0, patient_angle_noise_rad=0.0)
    seen, told = [], []
    for e in (env, quiet):
        obs, info = e.reset(seed=1, options={"exercise": 0, "weight_level": 0})
        trace, truth = [obs], [info["paper_observation"]]
        for _ in range(10):
            obs, reward, _t, _tr, info = e.step(np.full(e.action_space.shape, 0.5, np.float32))
            trace.append(obs)
            truth.append(np.append(info["paper_observation"], reward))
        seen.append(np.array(trace))
        told.append(np.array(truth[1:]))
    assert np.array_equal(told[0], told[1])
    assert np.all(np.any(seen[0] != seen[1], axis=1))
    quiet.close()
    paper.close()


def test_a_bad_preset_is_refused_with_its_name():
    assert check_preset(None) is None and check_preset("transfer") is PRESET
    for bad in ("bogus", "Transfer", 1, True):
        with pytest.raises(UsageError, match=re.escape(f"randomization={bad!r} ")):
            RehabEnvConfig(limb="knee", randomization=bad)
    with pytest.raises(ValueError, match=r"'bogus'.*transfer"):
        gym.make("rehabbot/rehab-knee-population-v2", randomization="bogus")


def test_the_randomized_ids_are_their_population_id_on_the_envelope_cohort_with_the_preset():
    assert set(RANDOMIZED_VARIANTS) == {
        "rehabbot/rehab-reach-randomized-v2", "rehabbot/rehab-knee-randomized-v2",
        "rehabbot/rehab-reach-l-randomized-v2", "rehabbot/rehab-hip-randomized-v2"}
    for env_id, base_id in RANDOMIZED_VARIANTS.items():
        assert ENV_SPECS[env_id][0] == {**ENV_SPECS[base_id][0], **RANDOMIZED_KWARGS}
        assert gym.spec(env_id).kwargs == ENV_SPECS[env_id][0]
    env, base = gym.make("rehabbot/rehab-knee-randomized-v2"), gym.make(
        "rehabbot/rehab-knee-population-v2")
    assert env.observation_space == base.observation_space
    assert env.action_space == base.action_space
    _obs, info = env.reset(seed=0)
    assert info["randomization"] == env.unwrapped.randomization_draw.to_dict()
    assert env.unwrapped.population.name.startswith("envelope-train")
    env.close()
    base.close()


# -- the transfer experiment (benchmarks/results/transfer_results.py) ----------------------
def test_the_transfer_floor_needs_both_agents_and_both_conditions():
    from benchmarks.results import transfer_results as transfer

    def rows(with_drop, without_drop):
        return [{"trained_with": "with", "drop_points": with_drop},
                {"trained_with": "without", "drop_points": without_drop},
                {"trained_with": "-", "drop_points": 50.0}]  # the expert is not judged

    assert transfer.floor_verdict(rows(10.0, 10.5)).startswith("met")
    assert transfer.floor_verdict(rows(10.5, 30.0)).startswith("NOT met")  # beyond the floor
    assert transfer.floor_verdict(rows(2.0, 2.0)).startswith("NOT met")  # without: not more
    assert transfer.floor_verdict(rows(2.0, 1.0)).startswith("NOT met")
    assert transfer.floor_verdict(rows(2.0, 30.0)[:1]).startswith("not judged")
    for bad in ("with", "both=zoo:rehab-knee-v2/sac", "without="):
        with pytest.raises(ValueError, match=re.escape(repr(bad))):
            transfer.parse_agent(bad)
    assert transfer.parse_agent("with=runs/x") == ("with", "runs/x")


def test_the_randomised_test_episodes_repeat_the_nominal_cells_on_seeds_of_their_own():
    import argparse

    from benchmarks.results import transfer_results as transfer

    args = argparse.Namespace(seed=60_000, randomized_seed=70_000, draws=3, max_bodies=2,
                              part="bodies")
    targets = transfer.targets_of("rehabbot/rehab-knee-v2", "transfer")
    assert targets["randomised"].env_kwargs == {"randomization": "transfer"}
    assert targets["nominal"].env_kwargs == {}
    plans = transfer.plans_of(targets["nominal"], args)
    nominal, randomised = plans["nominal"], plans["randomised"]
    assert len(nominal) == 2 * 2 * 5 and len(randomised) == 3 * len(nominal)
    assert {p.patient.part for p in nominal} == {"bodies"}
    cells = [(p.patient, p.exercise, p.weight_level) for p in nominal]
    assert [(p.patient, p.exercise, p.weight_level) for p in randomised] == \
        [cell for cell in cells for _ in range(3)]
    seeds = [p.seed for p in randomised]
    assert len(set(seeds)) == len(seeds) and min(seeds) == 70_000
    assert not set(seeds) & {p.seed for p in nominal}
    assert not set(seeds) & set(range(20_001, 20_021))  # the run's expert demonstrations


@pytest.mark.slow
def test_the_recorded_latencies_are_the_episodes_own_and_a_refused_patient_is_skipped():
    from benchmarks.results import heldout_results as heldout
    from benchmarks.results import transfer_results as transfer
    from rehabbot.sim.conditions import PatientCondition
    from rehabbot.sim.patient import PatientProfile

    target = transfer.targets_of("rehabbot/rehab-knee-v2", "transfer")["randomised"]
    able = heldout.Patient("bodies", PatientProfile(), PatientCondition())
    refused = heldout.Patient("conditions", PatientProfile(1.85, 102.0, "male"),
                              PatientCondition(effort="resistive", effort_fraction=0.1))
    plan = [heldout.Planned(able, 0, level, 70_000 + level) for level in (0, 3)] + \
        [heldout.Planned(refused, 0, 0, 70_010)]
    draws = transfer.draws_of(target, plan)
    assert [d["seed"] for d in draws] == [70_000, 70_003]
    env = RehabEnv(**KNEE, randomization="transfer")
    for d in draws:
        _obs, info = env.reset(seed=d["seed"], options={"exercise": 0,
                                                        "weight_level": d["seed"] - 70_000})
        assert d["latency_steps"] == info["randomization"]["latency_steps"]
    env.close()
