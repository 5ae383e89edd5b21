"""Patient populations (rehabbot.sim.populations, rehabbot.envs.population): a patient drawn
per episode from the env's seed, the shipped train/test split, and bad populations refused."""

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.population import PopulationEnv
from rehabbot.envs.registration import POPULATION_VARIANTS
from rehabbot.rl.assist_as_needed import AssistAsNeeded
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.conditions import PatientCondition
from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.populations import POPULATIONS, PatientPopulation, as_population

SMALL = PatientPopulation("small", profiles=(PatientProfile(), {"height_m": 1.6,
                                                                 "mass_kg": 55.0,
                                                                 "sex": "female"}),
                          conditions=(PatientCondition(), {"spasticity_mas": "2"}))


def test_train_and_test_populations_share_no_profile_and_no_condition():
    train, test = POPULATIONS["train"], POPULATIONS["test"]
    assert not set(train.profiles) & set(test.profiles)
    assert not set(train.conditions) & set(test.conditions)
    assert len(train.patients) == 27 and len(test.patients) == 12
    assert PatientCondition() in train.conditions  # the healthy patient trains too
    assert all(not c.is_healthy for c in test.conditions)  # every test patient is impaired


def test_each_episode_draws_a_patient_from_the_seed():
    env = PopulationEnv(SMALL, weight_level=0)

    def patients(seed):
        drawn = []
        obs, info = env.reset(seed=seed)
        drawn.append((info["patient"], obs.tobytes()))
        for _ in range(11):
            obs, info = env.reset()
            drawn.append((info["patient"], obs.tobytes()))
        return drawn

    first = patients(4)
    assert first == patients(4)
    assert {k for k, _ in first} == set(range(4))  # all four patients in 12 episodes
    assert first != patients(5)
    env.close()


def test_the_episode_runs_in_the_drawn_patients_env():
    env = PopulationEnv(SMALL, weight_level=0, exercise=0)
    for k, (profile, condition) in enumerate(SMALL.patients):
        obs, info = env.reset(seed=0, options={"patient": k})
        assert info["patient"] == env.current_patient == k
        assert env.current_env.config.profile == profile
        assert env.current_env.config.condition == condition
        assert env.observation_space.contains(obs)
        obs, _, _, _, info = env.step(np.zeros(6, np.float32))
        assert info["patient"] == k
        # attributes pass through to the episode's env
        assert env.target_sequence is env.current_env.target_sequence
    env.close()


def test_bad_populations_and_options_are_refused_by_name():
    with pytest.raises(ValueError, match="'adults'"):
        as_population("adults")
    with pytest.raises(ValueError, match="unknown field"):
        as_population({"name": "x", "profiles": [{}], "conditions": [{}], "ages": [3]})
    with pytest.raises(ValueError, match="profiles must be a non-empty"):
        PatientPopulation("x", profiles=(), conditions=(PatientCondition(),))
    with pytest.raises(ValueError, match="sets 'condition'"):
        PopulationEnv(SMALL, condition={"spasticity_mas": "2"})
    env = PopulationEnv(SMALL, weight_level=0)
    with pytest.raises(ValueError, match="patient=7"):
        env.reset(seed=0, options={"patient": 7})
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(seed=0, options={"patients": 1})
    env.close()


def test_a_patient_who_cannot_do_the_exercises_is_named():
    hopeless = PatientPopulation("hopeless", profiles=(PatientProfile(),),
                                 conditions=({"effort": "resistive", "effort_fraction": 0.6},))
    with pytest.raises(ValueError, match=r"patient 0 of population 'hopeless'.*resistive"):
        PopulationEnv(hopeless)


def test_population_ids_keep_their_base_ids_spaces_and_take_the_test_split():
    for env_id, base_id in POPULATION_VARIANTS.items():
        assert gym.spec(env_id).kwargs == {**gym.spec(base_id).kwargs, "patients": "train"}
    env = gym.make("rehabbot/rehab-reach-population-v1", patients="test")
    base = gym.make("rehabbot/rehab-reach-v1")
    assert env.observation_space == base.observation_space
    assert env.action_space == base.action_space
    assert env.unwrapped.population is POPULATIONS["test"]
    env.close()
    base.close()


@pytest.mark.parametrize("controller", [ScriptedExpert, AssistAsNeeded])
def test_controllers_finish_population_episodes(controller):
    env = gym.make("rehabbot/rehab-reach-population-v1", patients="test")
    policy = controller(env)
    for seed in range(2):
        obs, info = env.reset(seed=seed)
        for _ in range(1000):
            obs, _, terminated, truncated, info = env.step(policy.predict(obs)[0])
            if terminated or truncated:
                break
        assert info["is_success"], (seed, info["patient"], info["safety_violation"])
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", list(POPULATION_VARIANTS))
@pytest.mark.parametrize("split", ["train", "test"])
def test_every_shipped_patient_can_do_the_exercises(env_id, split):
    env = gym.make(env_id, patients=split)
    env.unwrapped.build_all()  # ValueError for a patient the env refuses
    assert len(env.unwrapped._envs) == len(POPULATIONS[split].patients)
    env.close()


def test_conditions_restrict_a_population_to_one_condition():
    """Over many episodes only the chosen condition appears, with every profile of the
    population; patient indices count in the subset."""
    train = POPULATIONS["train"]
    env = gym.make("rehabbot/rehab-reach-population-v2", conditions=3)
    base = env.unwrapped
    assert base.population.name == "train[conditions 3]"
    assert base.population.conditions == (train.conditions[3],)
    assert base.population.profiles == train.profiles
    seen_conditions, seen_profiles = set(), set()
    env.reset(seed=0)
    for _ in range(40):
        _, info = env.reset()
        patient = base.current_env.config.patient
        seen_conditions.add(patient.condition)
        seen_profiles.add(patient.profile)
        assert info["patient"] in range(3)
    env.close()
    assert seen_conditions == {PatientCondition(spasticity_mas="2")}
    assert seen_profiles == set(train.profiles)
    explicit = gym.make("rehabbot/rehab-reach-population-v2", conditions=None)
    assert explicit.unwrapped.population is train  # None: every condition, as by default
    explicit.close()


def test_conditions_may_be_named_by_value_and_several():
    env = gym.make("rehabbot/rehab-knee-population-v2", patients="test",
                   conditions=[{"spasticity_mas": "3"}, 3])
    population = env.unwrapped.population
    assert population.name == "test[conditions 0, 3]"
    assert population.conditions == (POPULATIONS["test"].conditions[0],
                                     POPULATIONS["test"].conditions[3])
    assert len(population.patients) == 4
    env.close()
    assert POPULATIONS["train"].with_conditions(PatientCondition()).conditions == (
        PatientCondition(),)


@pytest.mark.parametrize(("conditions", "named"), [
    (9, r"condition 9 is not an index into the conditions of population 'train'; valid: "
        r"0 \(healthy, passive\); 1 \(spasticity_mas='1'\);.* 8 \(stiffness_scale=2.0"),
    (-1, "condition -1 is not an index"),
    (True, "condition True must be an index"),
    (2.0, "condition 2.0 must be an index"),
    ("MAS 2", "condition 'MAS 2' must be an index"),
    ([], r"conditions=\[\] must name at least one condition"),
    ([3, 3], r"names condition 3 \(spasticity_mas='2'\) twice"),
    ({"spasticity_mas": "3"}, "condition \"spasticity_mas='3'\" is not one of the conditions of "
                              "population 'train' .*make a PatientPopulation"),
    ({"bogus": 1}, r"condition \{'bogus': 1\}: .*unknown field.*; valid: 0 \(healthy"),
])
def test_a_bad_condition_is_named_with_the_valid_ones(conditions, named):
    with pytest.raises(ValueError, match=named):
        gym.make("rehabbot/rehab-reach-population-v2", conditions=conditions)


def test_the_default_draws_every_patient_as_before():
    """Without conditions= the population is the whole split and each reset's patient is the
    first draw of the env's np_random, as it always was."""
    env = gym.make("rehabbot/rehab-reach-population-v2")
    base = env.unwrapped
    assert base.population is POPULATIONS["train"]
    drawn = []
    for seed in range(12):
        _, info = env.reset(seed=seed)
        rng, _ = gym.utils.seeding.np_random(seed)
        assert info["patient"] == int(rng.integers(27))
        drawn.append(info["patient"])
    env.close()
    assert len(set(drawn)) > 3
