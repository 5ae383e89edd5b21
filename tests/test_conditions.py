"""Patients with conditions (rehabbot.sim.conditions, rehabbot.sim.patient_drive): physical
facts measured in the simulation, validation, feasibility and the registered variants."""

import itertools
import math

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.condition_probes import stretch_test, tremor_spectrum
from rehabbot.envs.registration import CONDITION_VARIANTS
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.conditions import (
    MAS_GRADES,
    PatientCondition,
    as_condition,
    healthy_strength_nm,
)
from rehabbot.sim.patient import PatientProfile


def expert_episode(condition, limb="arm", exercise=0, level=0, seed=0, speed_fraction=1.0,
                   mean_force=False, **kwargs):
    """One episode of the scripted expert; returns the last info and the peak (or mean) cuff
    force."""
    env = RehabEnv(limb=limb, condition=condition, exercise=exercise, weight_level=level,
                   reward="progress", **kwargs)
    expert = ScriptedExpert(env, speed_fraction=speed_fraction)
    obs, info = env.reset(seed=seed)
    forces = []
    for _ in range(1000):
        obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
        forces.append(info["interaction_force_n"])
        if terminated or truncated:
            break
    env.close()
    return info, float(np.mean(forces) if mean_force else np.max(forces))


# ------------------------------------------------------------------------------ validation
@pytest.mark.parametrize(("field", "value", "needle"), [
    ("spasticity_mas", "5", "Modified Ashworth"),
    ("spasticity_mas", 1.5, "Modified Ashworth"),
    ("spasticity_mas", True, "Modified Ashworth"),
    ("stiffness_scale", 0.0, "[0.25, 20.0]"),
    ("stiffness_scale", math.nan, "stiffness_scale"),
    ("rom_scale", 1.2, "[0.2, 1.0]"),
    ("strength_fraction", -0.1, "[0.0, 1.0]"),
    ("tremor_hz", 1.0, "2.0, 12.0"),
    ("tremor_hz", 15.0, "tremor_hz"),
    ("tremor_amplitude_nm", math.inf, "tremor_amplitude_nm"),
    ("effort", "helpful", "passive"),
    ("reaction_delay_s", 1.0, "[0.0, 0.5]"),
])
def test_bad_condition_values_are_refused_by_name(field, value, needle):
    with pytest.raises(ValueError) as err:
        PatientCondition(**{field: value})
    assert field in str(err.value) and needle in str(err.value)


def test_tremor_amplitude_needs_a_frequency():
    with pytest.raises(ValueError, match="needs a tremor_hz"):
        PatientCondition(tremor_amplitude_nm=1.0)


@pytest.mark.parametrize(("fields", "field", "remedy"), [
    ({"strength_fraction": 0.2}, "strength_fraction", "effort='active_assisted'"),
    ({"effort_fraction": 0.5}, "effort_fraction", "effort='active_assisted'"),
    ({"reaction_delay_s": 0.3}, "reaction_delay_s", "effort='active_assisted'"),
    ({"effort": "resistive", "reaction_delay_s": 0.3}, "reaction_delay_s",
     "effort='active_assisted'"),
    ({"effort": "active_assisted", "strength_fraction": 0.0}, "strength_fraction",
     "strength_fraction > 0"),
    ({"effort": "resistive", "effort_fraction": 0.0}, "effort_fraction", "effort_fraction > 0"),
    ({"tremor_hz": 6.0}, "tremor_hz", "tremor_amplitude_nm > 0"),
])
def test_a_field_that_cannot_act_is_refused_naming_it(fields, field, remedy):
    with pytest.raises(ValueError) as err:
        PatientCondition(**fields)
    message = str(err.value)
    assert f"PatientCondition.{field}={fields[field]!r}" in message
    assert remedy in message


def test_a_field_refused_as_inert_acts_once_its_remedy_is_given():
    # strength_fraction on a passive patient was bit-identical to a healthy one; with an
    # effort it changes the patient's torques
    assert PatientCondition(effort="active_assisted", strength_fraction=0.2).acts
    assert PatientCondition(tremor_hz=6.0, tremor_amplitude_nm=0.5).acts


def test_every_shipped_condition_passes_the_inert_field_check():
    from rehabbot.sim.populations import POPULATIONS

    for _base, condition, _text in CONDITION_VARIANTS.values():
        assert as_condition(condition).acts or as_condition(condition).rom_scale < 1 \
            or as_condition(condition).stiffness_scale != 1
    for population in POPULATIONS.values():
        for condition in population.conditions:
            as_condition(condition.to_dict())  # rebuilt from its fields: no ValueError


def test_conditions_come_from_dicts_and_integer_grades():
    assert as_condition({"spasticity_mas": 2}).spasticity_mas == "2"
    assert as_condition(None) == PatientCondition()
    with pytest.raises(ValueError, match="unknown field"):
        as_condition({"spasticity": "2"})
    with pytest.raises(ValueError, match="condition="):
        as_condition("spastic")
    env = RehabEnv(condition={"spasticity_mas": "1+"}, weight_level=0)
    assert env.config.condition == PatientCondition(spasticity_mas="1+")
    assert env.config.to_kwargs()["condition"]["spasticity_mas"] == "1+"
    env.close()


def test_gym_make_refuses_a_bad_condition_naming_it():
    with pytest.raises(ValueError, match="rom_scale"):
        gym.make("rehabbot/rehab-reach-v1", condition={"rom_scale": 0.0})


def test_healthy_strength_is_sized_from_the_profile():
    man = healthy_strength_nm("knee_flexion", 75.0, "male")
    heavy = healthy_strength_nm("knee_flexion", 100.0, "male")
    woman = healthy_strength_nm("knee_flexion", 75.0, "female")
    assert heavy[1] == pytest.approx(man[1] * 100 / 75)
    assert woman[1] < man[1]
    assert 150 < man[1] < 260  # knee extension of a 75 kg man [N·m]
    assert 40 < healthy_strength_nm("elbow_flexion", 75.0, "male")[0] < 90


# ------------------------------------------------------------------- the default is today's
def test_default_condition_applies_no_torque_and_pays_the_robot_all_the_work():
    info, _ = expert_episode(PatientCondition(), exercise=0)
    assert info["is_success"]
    assert info["patient_work_j"] == 0.0
    assert np.all(info["patient_torque_nm"] == 0.0)
    assert info["robot_work_j"] > 0.5  # the robot lifts the arm to 90 deg
    assert info["assistance_ratio"] == 1.0


def test_default_condition_episode_is_bit_identical_to_no_condition():
    def rollout(**kwargs):
        env = gym.make("rehabbot/rehab-knee-v1", **kwargs)
        rng = np.random.default_rng(3)
        obs, _ = env.reset(seed=3)
        rows = [obs]
        for _ in range(60):
            obs, reward, *_ = env.step(rng.uniform(-1, 1, 6).astype(np.float32)
                                       * env.action_space.high)
            rows.append(np.append(obs, reward))
        env.close()
        return rows

    plain, explicit = rollout(), rollout(condition=PatientCondition())
    assert all(np.array_equal(a, b) for a, b in zip(plain, explicit, strict=True))


# ------------------------------------------------------------------------------ spasticity
@pytest.fixture(scope="module")
def stretches():
    """Isokinetic elbow stretches at 100 deg/s for every grade, and at 5 deg/s over the
    second half of the range (where the fast catches are) for grades 0 and 4."""
    fast = {g: stretch_test({"spasticity_mas": g}, speed_deg_s=100.0) for g in MAS_GRADES}
    slow = {g: stretch_test({"spasticity_mas": g}, speed_deg_s=5.0, sweep=(0.5, 0.75))
            for g in ("0", "4")}
    return fast, slow


def test_resistance_at_100_deg_s_rises_with_the_mas_grade(stretches):
    fast, _ = stretches
    peaks = [fast[g].resistance_nm.max() for g in MAS_GRADES]
    means = [fast[g].resistance_nm.mean() for g in MAS_GRADES]
    assert peaks[0] == 0.0 and means[0] == 0.0
    assert all(b > a for a, b in itertools.pairwise(peaks)), peaks
    assert all(b > a for a, b in itertools.pairwise(means)), means
    # the dynamometer, not just the model, feels it: it pushes harder for every grade
    dyn = [fast[g].dynamometer_nm.mean() for g in MAS_GRADES]
    assert all(b > a for a, b in itertools.pairwise(dyn)), dyn
    assert all(abs(r.velocity_deg_s.mean() - 100.0) < 5.0 for r in fast.values())


def test_catch_and_extent_follow_the_ashworth_definitions(stretches):
    fast, _ = stretches
    assert fast["1"].resisted_fraction() < 0.1  # a catch at the end of the range
    assert 0.1 < fast["1+"].resisted_fraction() < 0.5  # less than half of the rest
    for grade in ("2", "3", "4"):
        assert fast[grade].resisted_fraction() > 0.75  # through most of the range
    # grade 1 catches and releases: the resistance falls after its peak, within the sweep
    one = fast["1"].resistance_nm
    assert one.max() > 0.2 and one[-1] < 0.8 * one.max()
    assert fast["2"].resistance_nm[-1] > 0.95 * fast["2"].resistance_nm.max()  # no release


def test_slow_stretch_stays_passive_for_every_grade(stretches):
    _, slow = stretches
    rigid, healthy = slow["4"], slow["0"]
    assert np.all(rigid.reflex_nm == 0.0)
    # after the first 0.5 s (the start jolts the held shoulder past grade 4's threshold for
    # a moment), the dynamometer pushes exactly as hard as for a healthy elbow
    settled = slice(250, min(len(rigid.dynamometer_nm), len(healthy.dynamometer_nm)))
    assert np.allclose(rigid.dynamometer_nm[settled], healthy.dynamometer_nm[settled],
                       atol=1e-6)


# ----------------------------------------------------------------------------------- tremor
@pytest.mark.parametrize("tremor_hz", [4.0, pytest.param(9.5, marks=pytest.mark.slow)])
def test_tremor_shows_a_spectral_peak_at_its_frequency(tremor_hz):
    spectrum = tremor_spectrum({"tremor_hz": tremor_hz, "tremor_amplitude_nm": 1.0},
                               seconds=8.0, seed=1)
    assert abs(spectrum.peak_hz - tremor_hz) <= 0.5
    quiet = tremor_spectrum(None, seconds=8.0, seed=1)
    assert spectrum.rms_deg > 20 * quiet.rms_deg


def test_tremor_phase_comes_from_the_env_seed():
    def angles(seed):
        env = RehabEnv(condition={"tremor_hz": 6.0, "tremor_amplitude_nm": 1.0},
                       weight_level=0, exercise=0)
        env.reset(seed=seed)
        zero = np.zeros(6, np.float32)
        rows = [env.step(zero)[4]["patient_torque_nm"] for _ in range(20)]
        env.close()
        return np.array(rows)

    assert np.array_equal(angles(5), angles(5))
    assert not np.allclose(angles(5), angles(6))


# ------------------------------------------------------------------- effort and weakness
def test_active_patient_lowers_the_robots_work_and_a_weaker_one_raises_it():
    passive, _ = expert_episode(PatientCondition(), exercise=0)
    weak, _ = expert_episode(PatientCondition(effort="active_assisted",
                                              strength_fraction=0.1), exercise=0)
    strong, _ = expert_episode(PatientCondition(effort="active_assisted",
                                                strength_fraction=0.4), exercise=0)
    for info in (passive, weak, strong):
        assert info["is_success"]
    assert passive["robot_work_j"] > weak["robot_work_j"] > strong["robot_work_j"]
    assert 1.0 == passive["assistance_ratio"] > weak["assistance_ratio"] \
        > strong["assistance_ratio"]
    assert strong["patient_work_j"] > weak["patient_work_j"] > 0.0


def test_voluntary_torque_stays_within_the_available_strength():
    condition = PatientCondition(effort="active_assisted", strength_fraction=0.5,
                                 effort_fraction=0.4)
    env = RehabEnv(limb="knee", condition=condition, weight_level=0, exercise=0)
    expert = ScriptedExpert(env)
    obs, _ = env.reset(seed=0)
    strength = healthy_strength_nm("knee_flexion", 75.0, "male")
    peak = 0.0
    for _ in range(200):
        obs, *_, info = env.step(expert.predict(obs)[0])
        peak = max(peak, abs(info["patient_torque_nm"][2]))
    env.close()
    assert 0.0 < peak <= 0.5 * 0.4 * max(strength) + 1e-9
    assert np.all(info["patient_torque_nm"][:2] == 0.0)  # the hip is held, not driven


def test_resistive_patient_raises_the_cuff_force():
    passive_info, passive = expert_episode(PatientCondition(), limb="knee", exercise=0,
                                           task_type="trajectory", mean_force=True)
    info, resisting = expert_episode(PatientCondition(effort="resistive",
                                                      effort_fraction=0.05),
                                     limb="knee", exercise=0, task_type="trajectory",
                                     mean_force=True)
    assert info["is_success"]
    assert resisting > 1.2 * passive  # the mean cuff force over the episode
    assert info["robot_work_j"] > 2 * passive_info["robot_work_j"]
    assert info["patient_work_j"] < 0.0  # the patient only brakes


# ---------------------------------------------------------------------------- contracture
def test_contracture_scales_stiffness_and_shrinks_range_targets_and_rule():
    healthy = RehabEnv(limb="knee", weight_level=0)
    stiff = RehabEnv(limb="knee", weight_level=0,
                     condition={"stiffness_scale": 3.0, "rom_scale": 0.6})
    knee = healthy.model.joint("knee_flexion_r")
    home = healthy.scene.home_qpos[knee.qposadr[0]]
    assert stiff.model.jnt_stiffness[knee.id] == pytest.approx(3 * healthy.model.jnt_stiffness[
        knee.id])
    low, high = stiff.model.jnt_range[knee.id]
    assert low == pytest.approx(home + 0.6 * (healthy.model.jnt_range[knee.id][0] - home))
    assert high == pytest.approx(home + 0.6 * (healthy.model.jnt_range[knee.id][1] - home))
    for sequence in stiff.targets:
        angles = np.radians(sequence.patient_deg[:, 2])
        assert np.all((angles >= low) & (angles <= high))
    # the observation space is every patient's of the id
    assert stiff.observation_space == healthy.observation_space
    # the range-of-motion rule fires beyond the reduced range (plus the 2 deg tolerance)
    stiff.reset(seed=0)
    stiff.data.qpos[knee.qposadr[0]] = high + math.radians(3)
    import mujoco
    mujoco.mj_forward(stiff.model, stiff.data)
    assert stiff.safety.check(stiff.data, 0.0) == "range_of_motion"
    healthy.close()
    stiff.close()


def test_contracted_patient_still_does_the_scaled_exercise():
    info, peak = expert_episode({"stiffness_scale": 3.0, "rom_scale": 0.7}, limb="knee")
    assert info["is_success"] and peak < 130.0


# ----------------------------------------------------------------------------- feasibility
def test_infeasible_conditions_are_refused_with_the_reason():
    with pytest.raises(ValueError) as err:
        RehabEnv(limb="arm", condition={"effort": "resistive", "effort_fraction": 0.5})
    text = str(err.value)
    assert "effort='resistive'" in text and "N at the cuff" in text and "140 N" in text
    with pytest.raises(ValueError, match=r"stiffness_scale=20\.0"):
        RehabEnv(limb="knee", condition={"stiffness_scale": 20.0})


def test_a_rigid_elbow_stops_a_fast_robot_and_lets_a_slow_one_finish():
    fast, _ = expert_episode({"spasticity_mas": "4"}, exercise=1)
    assert fast["safety_violation"] == "cuff_force"  # the reflex resists a fast stretch
    slow, peak = expert_episode({"spasticity_mas": "4"}, exercise=1, speed_fraction=0.5)
    assert slow["is_success"] and peak < 0.5 * 140.0


# -------------------------------------------------------------------------- determinism
@pytest.mark.parametrize("condition", [
    {"spasticity_mas": "3"}, {"tremor_hz": 6.0, "tremor_amplitude_nm": 0.8},
    {"effort": "active_assisted", "strength_fraction": 0.3},
    {"effort": "resistive", "effort_fraction": 0.05, "stiffness_scale": 2.0}])
def test_every_condition_is_deterministic_per_seed(condition):
    def rollout():
        env = gym.make("rehabbot/rehab-reach-v1", condition=condition)
        rng = np.random.default_rng(0)
        obs, _ = env.reset(seed=11)
        rows = [np.append(obs, [0.0, 0.0])]
        for _ in range(40):
            obs, reward, _, _, info = env.step(
                rng.uniform(-1, 1, 6).astype(np.float32) * env.action_space.high)
            rows.append(np.concatenate([obs, [reward, info["robot_work_j"]]]))
        env.close()
        return np.array(rows)

    assert np.array_equal(rollout(), rollout())


# -------------------------------------------------------------------- registered variants
def test_condition_variants_keep_their_base_ids_spaces():
    for env_id, (base_id, condition, _description) in CONDITION_VARIANTS.items():
        spec = gym.spec(env_id)
        assert spec.kwargs["condition"] == condition
        assert {k: v for k, v in spec.kwargs.items() if k != "condition"} == \
            gym.spec(base_id).kwargs


@pytest.mark.slow
@pytest.mark.parametrize("env_id", list(CONDITION_VARIANTS))
def test_the_expert_finishes_every_condition_variant(env_id):
    env = gym.make(env_id, weight_level=0)
    base = gym.make(CONDITION_VARIANTS[env_id][0], weight_level=0)
    assert env.observation_space == base.observation_space
    assert env.action_space == base.action_space
    expert = ScriptedExpert(env)
    for exercise in range(2):
        obs, _ = env.reset(seed=exercise, options={"exercise": exercise})
        for _ in range(1000):
            obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
            if terminated or truncated:
                break
        assert info["is_success"], (env_id, exercise, info["safety_violation"])
    env.close()
    base.close()


def test_conditions_work_for_other_profiles():
    info, _ = expert_episode({"effort": "active_assisted", "strength_fraction": 0.3},
                             profile=PatientProfile(1.6, 55.0, "female"))
    assert info["is_success"] and 0.0 < info["assistance_ratio"] < 1.0


# ------------------------------------------------------------------------------- evaluate
def test_range_of_motion_counts_the_excursion_achieved_and_prescribed():
    from rehabbot.analysis.evaluation import range_of_motion_deg

    patient = np.radians([[30, 12, 70], [50, 12, 70], [80, 13, 70], [60, 12, 70]])
    targets = np.array([[45, 12, 70], [90, 12, 70], [40, 12, 70]])
    achieved, prescribed = range_of_motion_deg(patient, targets)
    assert np.allclose(achieved, [50, 1, 0])
    assert np.allclose(prescribed, [60, 0, 0])  # from the start (30) through 90 and back


def test_evaluate_reports_the_patients_side():
    from rehabbot.analysis.evaluation import evaluate_policies, format_table

    reports = [r for r, _ in evaluate_policies(["expert", "aan"], "rehabbot/rehab-knee-weak-v1",
                                               episodes=1, seed=0)]
    for report in reports:
        summary, episode = report["summary"], report["per_episode"][0]
        assert episode["success"]
        assert 0.0 < summary["assistance_ratio"]["mean"] < 1.0  # the active patient helps
        assert summary["patient_work_j"]["mean"] > 0.0
        assert 0.9 < summary["rom_achieved_fraction"]["mean"] < 1.1
        assert episode["rom_prescribed_deg"][2] > 30.0  # the knee moves, the hip is held
        assert episode["rom_prescribed_deg"][0] < 0.1  # (IK residuals only)
    table = format_table(reports)
    assert "assistance ratio" in table and "ROM achieved / prescribed" in table
