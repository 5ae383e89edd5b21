"""The learnable -v1 reward (rehabbot.tasks.reward) and the safety audit of every id:
reaching a target is worth more than stalling short of it for gamma in [0.95, 0.999], and a
safety stop never pays better than holding still (benchmarks.common.reward_audit)."""

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.reward_audit import stall_cases, stop_cases
from rehabbot.envs.registration import (
    BILATERAL_IDS,
    CONDITION_VARIANTS,
    ENV_SPECS,
    POPULATION_VARIANTS,
)
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.tasks.reward import STOP_MARGIN, StepOutcome, remaining_path_rad

# The base -v1 ids (the condition and population variants pay the same reward; their own
# tests are in test_conditions.py and test_population.py).
# (The bilateral id pays the same terms summed over two arms: tests/test_bilateral.py checks
# its telescoping; the stall and stop audits below run on it too.)
V1_IDS = tuple(i for i in ENV_SPECS if i.endswith("-v1") and i not in CONDITION_VARIANTS
               and i not in POPULATION_VARIANTS and i not in BILATERAL_IDS)
# A population env draws another patient at every reset, so the stop audit (which replays a
# state after a reset) runs on its patients' own ids instead. The -v2 ids pay their -v1 id's
# reward step for step (tests/test_v2.py), so the audits run on the -v1 ids.
ALL_IDS = tuple(i for i in ENV_SPECS if i not in POPULATION_VARIANTS and not i.endswith("-v2"))
GAMMAS = (0.95, 0.99, 0.999)
V1_TERMS = ("reward_progress", "reward_bonus", "reward_time", "reward_safety",
            "reward_smoothness", "reward_effort")


def test_remaining_path_adds_the_lengths_after_each_target():
    targets = np.array([[0.0, 0, 0], [3.0, 4, 0], [3.0, 4, 1]])
    np.testing.assert_allclose(remaining_path_rad(targets), [6.0, 1.0, 0.0])


@pytest.mark.parametrize("env_id", [pytest.param(i, marks=() if i.endswith("reach-v1") else
                                                 pytest.mark.slow) for i in V1_IDS])
def test_v1_progress_telescopes_and_terms_sum_to_the_reward(env_id):
    """Over an expert episode the progress terms add up to progress_weight x (D_start - D_end);
    every step pays -time_cost; each reached target pays its bonus; spaces equal -v0's."""
    env = gym.make(env_id, exercise=1, weight_level=3)
    v0 = gym.make(env_id.replace("-v1", "-v0"))
    assert env.observation_space == v0.observation_space
    assert env.action_space == v0.action_space
    base = env.unwrapped
    obs, info = env.reset(seed=3)
    assert all(info[k] == 0.0 for k in V1_TERMS)
    sequence = base.target_sequence.robot_rad
    theta0 = base.data.qpos[base.handle.qpos_adr].copy()
    d_start = np.linalg.norm(theta0 - sequence[0]) + remaining_path_rad(sequence)[0]
    expert = ScriptedExpert(env)
    total_progress, bonuses, steps = 0.0, 0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(expert(obs))
        steps += 1
        assert reward == pytest.approx(sum(info[k] for k in V1_TERMS), abs=1e-12)
        assert info["reward_time"] == -base.config.reward.time_cost == -0.05
        assert info["cost"] == 0.0 and info["reward_safety"] == 0.0
        total_progress += info["reward_progress"]
        bonuses += info["reward_bonus"] > 0
        if terminated or truncated:
            break
    assert info["is_success"] and bonuses == len(sequence)
    theta = base.data.qpos[base.handle.qpos_adr]
    d_end = np.linalg.norm(theta - sequence[-1])
    weight = base.config.reward.progress_weight
    assert total_progress == pytest.approx(weight * (d_start - d_end), rel=1e-9)
    assert total_progress > 0.9 * weight * d_start


def test_v1_arguments_are_validated():
    with pytest.raises(ValueError, match=r"safety_penalty=.worst_case.*paper"):
        gym.make("rehabbot/rehab-reach-v1", safety_penalty="worst_case")
    with pytest.raises(ValueError, match="time_cost"):
        gym.make("rehabbot/rehab-reach-v1", time_cost=-1.0)
    with pytest.raises(ValueError, match="progress_weight"):
        gym.make("rehabbot/rehab-reach-v1", progress_weight=float("nan"))
    with pytest.raises(ValueError, match=r"reward=.shaped.*.paper.*.progress."):
        gym.make("rehabbot/rehab-reach-v0", reward="shaped")


@pytest.mark.slow
def test_the_paper_reward_traps_a_gamma_099_agent_and_v1_does_not():
    """Elbow exercise (1) of the reach id: under eq. (5), holding still 0.06 rad short of a
    target is worth more than reaching it for gamma = 0.99 (README: no agent reached the first
    elbow target); under the v1 reward reaching wins at every target and gamma."""
    v0 = stall_cases("rehabbot/rehab-reach-v0", 1, (0.99,))
    assert any(not case.reaching_pays for case in v0)
    v1 = stall_cases("rehabbot/rehab-reach-v1", 1, GAMMAS)
    assert len(v1) == 6 * len(GAMMAS)
    assert all(case.reaching_pays for case in v1), [c for c in v1 if not c.reaching_pays]
    assert all(case.short_rad >= 0.06 for case in v1)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", (*V1_IDS, *(i for i in BILATERAL_IDS if i.endswith("-v1"))))
@pytest.mark.parametrize("exercise", [0, 1])
def test_reaching_each_target_beats_stalling_for_every_gamma(env_id, exercise):
    n = len(gym.make(env_id).unwrapped.targets[exercise])
    targets = range(n) if n <= 6 else [*range(0, n, 5), n - 1]  # dense paths: a sample
    cases = stall_cases(env_id, exercise, GAMMAS, targets=targets)
    assert len(cases) >= len(GAMMAS) * 4
    bad = [c for c in cases if not c.reaching_pays]
    assert not bad, bad


def _assert_stops_never_pay(cases):
    for case in cases:
        if case.violation is None:
            continue
        # From the reset state: worse than the expert finishing the exercise, and than holding
        # still to the time limit (the penalty covers every earlier state).
        assert case.stop_return < case.expert_return, case
        assert case.stop_return < case.hold_return, case
        # From the state before the stop: the stopping step pays less than holding still
        # from there (when holding still there avoids a stop: else both are stops).
        if case.hold_from_there is not None and case.hold_from_there_stop is None:
            assert case.last_step_reward < case.hold_from_there, case


def test_a_safety_stop_never_pays_on_reach_v1():
    cases = stop_cases("rehabbot/rehab-reach-v1", "joint_delta", joints=(0, 1))
    assert [c.violation for c in cases] == ["cuff_force", "cuff_force"]
    _assert_stops_never_pay(cases)
    # The episode gives back every gain since the start and pays the time cost to the limit
    # and one step more, plus the margin: less than holding still from the start (B(0) =
    # 1000 x the time cost + the progress the joints' travel to their setpoints could undo).
    env = gym.make("rehabbot/rehab-reach-v1", exercise=0, weight_level=0)
    env.reset(seed=0)
    base = env.unwrapped
    start_bound = base.reward_function.hold_cost(StepOutcome(lead_rad=base._leads()), 1000)
    push = np.zeros(6, np.float32)
    push[0] = env.action_space.high[0]
    rewards = []
    while True:
        _obs, reward, terminated, _truncated, info = env.step(push)
        rewards.append(reward)
        if terminated:
            break
    assert 50.0 <= start_bound < 51.0  # the setpoints at reset carry the limb: a small lead
    assert sum(rewards) <= -(start_bound + 0.05 + STOP_MARGIN) + 1e-9
    assert info["reward_safety"] < -0.05 * (1000 - len(rewards))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["joint_delta", "torque"])
@pytest.mark.parametrize("env_id", ALL_IDS)
def test_a_safety_stop_never_pays_on_any_id(env_id, mode):
    # Shoulder pan, shoulder lift and wrist 1 drive every id into a rule in both modes
    # (benchmarks/probes/reward_trap.py pushes all six).
    cases = stop_cases(env_id, mode, joints=(0, 1, 3))
    assert sum(c.violation is not None for c in cases) >= 2, cases
    _assert_stops_never_pay(cases)


def test_cost_is_one_in_a_step_where_a_rule_fires_even_without_termination():
    env = gym.make("rehabbot/rehab-reach-v1", control_mode="torque", terminate_on_safety=False,
                   exercise=0, weight_level=0)
    env.reset(seed=0)
    push = np.zeros(6, np.float32)
    push[0] = 1.0
    costs, violations = [], []
    for _ in range(20):
        _obs, _r, terminated, _t, info = env.step(push)
        costs.append(info["cost"])
        violations.append(info["safety_violation"])
        assert not terminated or info["safety_violation"] == "instability"
        if terminated:
            break
    assert costs == [0.0 if v is None else 1.0 for v in violations]
    assert 1.0 in costs and 0.0 in costs
