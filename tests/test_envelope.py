"""Patients across the adult envelope (rehabbot.sim.envelope): disjoint cohorts drawn the same
everywhere, their distances to the training bodies, and a population env that leaves out the
patients a scene refuses instead of failing an episode."""

import math

import gymnasium as gym
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.population import PopulationEnv
from rehabbot.sim.conditions import PatientCondition
from rehabbot.sim.envelope import (
    ENVELOPE_SPLITS,
    ENVELOPES,
    TEST_CONDITIONS,
    TRAIN_CONDITIONS,
    VALIDATION_CONDITIONS,
    Envelope,
    body_distance,
    corner_bodies,
    draw_bodies,
    envelope_bodies,
    envelope_conditions,
    envelope_of,
    nearest_training_body,
)
from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.populations import PatientPopulation, as_population, envelope_population

SCENES = sorted(ENVELOPES)
TRAINING_PATIENT = PatientProfile()  # the 1.75 m, 75 kg man every fixed-patient id trains on


@pytest.mark.parametrize("scene", SCENES)
def test_cohorts_are_disjoint_inside_the_envelope_and_spread_over_it(scene):
    envelope = envelope_of(*scene)
    cohorts = {split: envelope_bodies(split, *scene) for split in ENVELOPE_SPLITS}
    train, validation, test = (set(cohorts[s]) for s in ("train", "validation", "test"))
    assert not train & validation and not train & test and not validation & test
    assert set(cohorts["test-conditions"]) <= test
    assert TRAINING_PATIENT not in validation | test
    assert set(corner_bodies(envelope)) <= train  # test bodies lie between training bodies
    for split, bodies in cohorts.items():
        assert len(set(bodies)) == len(bodies), split
        assert {b.sex for b in bodies} == {"male", "female"}, split
        for body in bodies:
            assert envelope.contains(body), (split, body)
            assert body.height_m == round(body.height_m, 2)
            assert body.mass_kg * 2 == round(body.mass_kg * 2)
    heights = sorted(b.height_m for b in cohorts["test"])
    span = envelope.height_m[1] - envelope.height_m[0]
    assert heights[-1] - heights[0] > 0.6 * span  # drawn across the envelope, not bunched


def test_cohorts_are_the_same_on_every_machine():
    # Latin-hypercube draws from fixed seeds, rounded to 1 cm and 0.5 kg.
    assert envelope_bodies("train", "knee")[:4] == (
        PatientProfile(1.5, 45.0, "female"), PatientProfile(1.5, 85.5, "female"),
        PatientProfile(2.0, 68.0, "male"), PatientProfile(2.0, 140.0, "male"))
    assert envelope_bodies("test", "knee") == envelope_bodies("test", "knee")
    assert draw_bodies(ENVELOPES[("knee", "ur5e")], 8, 5) == \
        draw_bodies(ENVELOPES[("knee", "ur5e")], 8, 5)
    assert draw_bodies(ENVELOPES[("knee", "ur5e")], 8, 5) != \
        draw_bodies(ENVELOPES[("knee", "ur5e")], 8, 6)


def test_latin_hypercube_puts_one_body_in_each_height_stratum():
    envelope = Envelope(height_m=(1.5, 2.0), mass_kg=(40.0, 150.0))
    bodies = draw_bodies(envelope, 10, 3)
    strata = sorted(min(int((b.height_m - 1.5) / 0.05), 9) for b in bodies)
    assert strata == list(range(10)) or len(set(strata)) >= 9  # rounding may move an edge body


def test_condition_cohorts_differ_and_test_holds_the_hard_cases():
    assert not set(VALIDATION_CONDITIONS[1:]) & set(TRAIN_CONDITIONS)
    assert not set(TEST_CONDITIONS) & (set(TRAIN_CONDITIONS) | set(VALIDATION_CONDITIONS))
    assert PatientCondition(effort="resistive", effort_fraction=0.1) in TEST_CONDITIONS
    efforts = {c.effort for c in TRAIN_CONDITIONS}
    assert efforts == {"passive", "active_assisted", "resistive"}
    assert any(c.has_tremor for c in TRAIN_CONDITIONS) and any(c.reflex for c in TRAIN_CONDITIONS)
    assert envelope_conditions("test") == (PatientCondition(),)
    with pytest.raises(ValueError, match="split='nope'"):
        envelope_conditions("nope")


def test_distance_to_the_nearest_training_body():
    envelope = Envelope(height_m=(1.5, 2.0), mass_kg=(50.0, 150.0))
    training = (PatientProfile(1.6, 60.0, "male"), PatientProfile(1.9, 120.0, "female"))
    near = nearest_training_body(PatientProfile(1.85, 110.0, "male"), training, envelope)
    assert near.nearest == training[1]
    assert near.distance == pytest.approx(math.hypot(0.05 / 0.5, 10 / 100))
    assert near.height_diff_m == pytest.approx(-0.05) and near.mass_diff_kg == pytest.approx(-10)
    assert near.same_sex is False
    assert body_distance(training[0], training[0], envelope) == 0.0
    assert near.to_dict()["nearest_training_body"]["height_m"] == 1.9


def test_bad_envelopes_and_scenes_are_refused_by_name():
    with pytest.raises(ValueError, match="height_m"):
        Envelope(height_m=(2.0, 1.5), mass_kg=(40.0, 100.0))
    with pytest.raises(ValueError, match="limb='tail'"):
        envelope_of("tail")
    with pytest.raises(ValueError, match="split='holdout'"):
        envelope_bodies("holdout", "knee")
    with pytest.raises(ValueError, match="count=0"):
        draw_bodies(ENVELOPES[("knee", "ur5e")], 0, 1)
    with pytest.raises(ValueError, match=r"envelope cohort.*limb"):
        as_population("envelope-train")


def test_an_envelope_population_is_drawn_for_the_envs_scene():
    env = gym.make("rehabbot/rehab-hip-population-v2", patients="envelope-test", robot="fr3")
    population = env.unwrapped.population
    assert population.name == "envelope-test:hip-fr3"
    assert population.profiles == envelope_bodies("test", "hip", "fr3")
    assert population.skip_infeasible
    assert envelope_population("envelope-test", "hip", "fr3") == population
    env.close()


HOPELESS = PatientCondition(effort="resistive", effort_fraction=0.6)


def test_a_skipping_population_leaves_out_the_patients_the_scene_refuses():
    mixed = PatientPopulation("mixed", profiles=(PatientProfile(),),
                              conditions=(PatientCondition(), HOPELESS, {"spasticity_mas": "2"}),
                              skip_infeasible=True)
    env = PopulationEnv(mixed, weight_level=0)
    drawn = {env.reset(seed=seed)[1]["patient"] for seed in range(12)}
    assert drawn == {0, 2}  # every patient the scene takes, never the refused one
    assert list(env.refused_patients) == [1]
    assert "resistive" in env.refused_patients[1]
    assert env.feasible_patients == (0, 2)
    with pytest.raises(ValueError, match=r"patient 1 of population 'mixed'.*resistive"):
        env.reset(options={"patient": 1})
    sequence = [env.reset(seed=5)[1]["patient"]] + [env.reset()[1]["patient"] for _ in range(5)]
    again = [env.reset(seed=5)[1]["patient"]] + [env.reset()[1]["patient"] for _ in range(5)]
    assert sequence == again
    env.close()


def test_a_population_the_scene_refuses_entirely_is_an_error():
    hopeless = PatientPopulation("hopeless", profiles=(PatientProfile(),), conditions=(HOPELESS,),
                                 skip_infeasible=True)
    with pytest.raises(ValueError, match="no patient of population 'hopeless'"):
        PopulationEnv(hopeless)
    with pytest.raises(ValueError, match="skip_infeasible='yes'"):
        PatientPopulation("bad", profiles=(PatientProfile(),), conditions=(PatientCondition(),),
                          skip_infeasible="yes")


def test_an_agent_trained_on_a_population_is_filed_under_its_base_id():
    from rehabbot.rl.zoo_export import serve_base_id

    meta = {"env_id": "rehabbot/rehab-knee-population-v2",
            "env_kwargs": {"patients": "envelope-train", "robot": "fr3"}}
    serve_base_id(meta)
    assert meta == {"env_id": "rehabbot/rehab-knee-v2", "env_kwargs": {"robot": "fr3"},
                    "training_env_id": "rehabbot/rehab-knee-population-v2",
                    "training_patients": "envelope-train"}
    default = {"env_id": "rehabbot/rehab-hip-population-v2", "env_kwargs": {}}
    serve_base_id(default)
    assert default["env_id"] == "rehabbot/rehab-hip-v2"
    assert default["training_patients"] == "train"  # the id's own default population
    plain = {"env_id": "rehabbot/rehab-knee-v2", "env_kwargs": {}}
    serve_base_id(plain)
    assert plain == {"env_id": "rehabbot/rehab-knee-v2", "env_kwargs": {}}
