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
