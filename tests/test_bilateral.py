"""The bilateral env (rehabbot/envs/bilateral_env.py): both arms, a robot on each hand. Spaces,
patterns, the scripted expert on every exercise, both cuffs holding, the synchronisation term,
per-cuff safety, robot-robot contact, the reward's accounting and bad input."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.bilateral_build import ROBOT_PAIR_BIT
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.physics import SafetyMonitor, SafetyThresholds
from rehabbot.tasks.bilateral import pattern_rows, segment_lengths_rad
from rehabbot.tasks.reward import (
    STOP_MARGIN,
    BilateralReward,
    StepOutcome,
    segment_fraction,
    sync_gap,
)

ENV_ID = "rehabbot/rehab-bilateral-v1"
TERMS = ("reward_progress", "reward_bonus", "reward_time", "reward_safety",
         "reward_smoothness", "reward_effort", "reward_sync")


@pytest.fixture(scope="module")
def env():
    env = gym.make(ENV_ID)
    yield env
    env.close()


def _expert_episode(env, exercise, level, seed=0):
    """Run the expert; return the last info and per-step records."""
    expert = ScriptedExpert(env)
    obs, info = env.reset(seed=seed, options={"exercise": exercise, "weight_level": level})
    base = env.unwrapped
    records = []
    while True:
        obs, reward, terminated, truncated, info = env.step(expert(obs))
        records.append((reward, info, base.scene.cuff_errors_m(base.data).max()))
        if terminated or truncated:
            return info, records


def test_spaces_are_both_robots_side_by_side(env):
    base = env.unwrapped
    assert env.action_space.shape == (12,)
    np.testing.assert_allclose(env.action_space.high, np.pi / 400, rtol=1e-6)
    assert env.observation_space.shape == (44,)
    layout = base.layout
    assert [layout[name].size for name in layout.names] == [12, 6, 12, 6, 6, 1, 1]
    # The table: 2 arm exercises x 2 patterns, pattern-major.
    assert [e.name for e in base.exercises] == [
        "shoulder_flexion_symmetric", "elbow_flexion_symmetric",
        "shoulder_flexion_alternating", "elbow_flexion_alternating"]
    assert base.joint_names[0] == "right_shoulder_pan" and base.joint_names[6] == \
        "left_shoulder_pan"
    assert base.torque_limits_nm.shape == (12,)


def test_the_horizon_gives_alternating_exercises_the_one_arm_ids_slack(env):
    """An alternating exercise makes every move twice: the id registers 2000 steps (the
    safety penalty counts to the same limit), so the expert uses at most about 43 % of it, as
    on the one-arm ids (its longest one-arm exercise: 446 of 1000 steps)."""
    assert gym.spec(ENV_ID).max_episode_steps == 2000
    assert env.unwrapped.config.max_episode_steps == 2000
    expert = ScriptedExpert(env)
    for exercise in (2, 3):
        obs, _ = env.reset(seed=0, options={"exercise": exercise, "weight_level": 0})
        steps, done = 0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            steps, done = steps + 1, terminated or truncated
        assert info["is_success"] and steps < 0.45 * 2000


@pytest.mark.slow
def test_bounds_do_not_depend_on_the_patient(env):
    other = gym.make(ENV_ID, profile={"height_m": 1.6, "mass_kg": 60.0, "sex": "female"})
    assert other.observation_space == env.observation_space
    assert other.action_space == env.action_space


def test_pattern_rows_symmetric_and_alternating():
    keys = np.array([[45.0, 12, 70], [60.0, 12, 70]])
    home = np.array([30.0, 12, 70])
    right, left = pattern_rows(keys, home, "symmetric")
    np.testing.assert_array_equal(right, keys)
    np.testing.assert_array_equal(left, keys)
    right, left = pattern_rows(keys, home, "alternating")
    np.testing.assert_array_equal(right, [keys[0], keys[0], keys[1], keys[1]])
    np.testing.assert_array_equal(left, [home, keys[0], keys[0], keys[1]])
    with pytest.raises(ValueError, match="pattern='mirror'"):
        pattern_rows(keys, home, "mirror")


def test_targets_hold_one_arm_still_in_each_alternating_segment(env):
    base = env.unwrapped
    home = np.concatenate([base.scene.home_qpos[h.qpos_adr] for h in base.handles])
    symmetric, alternating = base.targets[0], base.targets[2]
    assert len(alternating) == 2 * len(symmetric)
    lengths = segment_lengths_rad(alternating.robot_rad, home, 6)
    np.testing.assert_array_less(lengths[0::2, 1], 1e-9)  # the left holds while the right moves
    np.testing.assert_array_less(lengths[1::2, 0], 1e-9)  # and the other way round
    assert np.all(lengths[0::2, 0] > 0.05) and np.all(lengths[1::2, 1] > 0.05)
    # Symmetric: both arms at the same patient pose at every target.
    np.testing.assert_allclose(symmetric.patient_deg[:, :3], symmetric.patient_deg[:, 3:])


@pytest.mark.parametrize("exercise", [0, 1, 2, 3])
def test_expert_solves_every_exercise_with_both_cuffs_holding(env, exercise):
    level = 4 if exercise % 2 else 0
    info, records = _expert_episode(env, exercise, level)
    assert info["is_success"], info["safety_violation"]
    assert info["target_index"] == info["num_targets"] - 1
    worst_cuff_error_m = max(r[2] for r in records)
    assert worst_cuff_error_m < 2e-3  # both straps stay on their hands
    forces = np.array([r[1]["cuff_forces_n"] for r in records])
    assert forces.shape == (len(records), 2)
    assert forces.max() < 140.0  # ISO/TS 15066, hands
    assert np.all(forces.min(axis=0) > 0.0)  # each cuff carries its own arm
    for reward, step_info, _ in records:
        assert reward == pytest.approx(sum(step_info[k] for k in TERMS), abs=1e-12)
    # The expert moves both arms in step: the synchronisation term never charges it.
    assert all(r[1]["reward_sync"] == 0.0 for r in records)
    assert all(r[1]["sync_gap"] == 0.0 for r in records)


def test_synchronisation_gap_of_the_expert_is_small_and_one_arm_first_pays():
    env = gym.make(ENV_ID, sync_tolerance=0.0, exercise=0, weight_level=2)
    info, records = _expert_episode(env, 0, 2)
    assert info["is_success"]
    assert max(r[1]["sync_gap"] for r in records) < 0.03  # in step without any tolerance
    # An agent that moves only the right arm is charged for the lag at once.
    expert = ScriptedExpert(env)
    obs, _ = env.reset(seed=0)
    sync = []
    for _ in range(100):
        action = expert(obs)
        action[6:] = 0.0
        obs, _r, terminated, _t, step_info = env.step(action)
        sync.append(step_info["reward_sync"])
        assert not terminated
    assert sum(sync) < -10.0
    assert min(sync) >= -env.unwrapped.config.reward.sync_weight


def test_progress_telescopes_over_both_arms():
    env = gym.make(ENV_ID, exercise=1, weight_level=3)
    base = env.unwrapped
    obs, info = env.reset(seed=3)
    assert all(info[k] == 0.0 for k in TERMS)
    seq = base.target_sequence.robot_rad
    theta0 = base.data.qpos[np.concatenate([h.qpos_adr for h in base.handles])].copy()

    def path(theta, i):
        rest = sum(np.linalg.norm(seq[j + 1, a * 6:(a + 1) * 6] - seq[j, a * 6:(a + 1) * 6])
                   for j in range(i, len(seq) - 1) for a in range(2))
        return sum(np.linalg.norm(theta[a * 6:(a + 1) * 6] - seq[i, a * 6:(a + 1) * 6])
                   for a in range(2)) + rest

    expert = ScriptedExpert(env)
    progress = 0.0
    while True:
        obs, _r, terminated, truncated, info = env.step(expert(obs))
        progress += info["reward_progress"]
        if terminated or truncated:
            break
    theta = base.data.qpos[np.concatenate([h.qpos_adr for h in base.handles])]
    assert info["is_success"]
    expected = base.config.reward.progress_weight * (path(theta0, 0) - path(theta, len(seq) - 1))
    assert progress == pytest.approx(expected, rel=1e-9)


def test_sync_helpers_and_a_stop_never_pays():
    assert sync_gap(0.9, 0.5, True, True, 0.1) == pytest.approx(0.3)
    assert sync_gap(0.9, 0.5, True, False, 0.1) == 0.0
    assert sync_gap(0.55, 0.5, True, True, 0.1) == 0.0
    assert segment_fraction(0.25, 1.0) == 0.75
    assert segment_fraction(2.0, 1.0) == 0.0 and segment_fraction(0.3, 0.0) == 1.0
    # One exercise of two targets, each arm's segments 1 rad long, 1 rad of path after the
    # first target: the fractions are 1 - distance, the path D = d_right + d_left + 1.
    reward = BilateralReward(max_episode_steps=1000, sync_weight=0.5, rests_rad=((1.0, 0.0),),
                             segments_rad=(((1.0, 1.0), (1.0, 1.0)),))

    def start(right, left):
        reward.reset(0, StepOutcome(next_arm_distances_rad=(right, left), lead_rad=(0.0, 0.0)))

    def step(right, left, **kwargs):
        return reward.step(StepOutcome(arm_distances_rad=(right, left),
                                       next_arm_distances_rad=(right, left), steps_done=10,
                                       **kwargs))[1]

    # G: holding still from the best earlier state would have cost 60 more than the episode
    # earned since. The stop pays G and this step's other terms (its progress 1.0, its time
    # cost 0.05), one step's hold at the larger sync gap (0.05 + 0.5 x 0.4: the gap was 0.4
    # before the step, 0.3 in it) and the margin.
    start(0.3, 0.8)  # fractions 0.7 and 0.2: a gap of 0.5 - 0.1
    reward.hold_gap = 60.0
    stop = step(0.3, 0.7, safety_stop=True)  # D from 2.1 to 2.0; a gap of 0.3
    assert stop["reward_safety"] == pytest.approx(
        -((60.0 + 1.0 - 0.05) + (0.05 + 0.5 * 0.4) + STOP_MARGIN))
    assert stop["reward_sync"] == 0.0 and stop["reward_bonus"] == 0.0
    # G below what the step earned: the stop still pays one step's hold and the margin.
    start(1.05, 1.05)
    reward.hold_gap = -5.0
    in_step = step(1.0, 1.0, safety_stop=True)
    assert in_step["reward_safety"] == pytest.approx(-(0.05 + STOP_MARGIN))
    # The hold bound: the time cost and the sync term at the gap the arms can reach while
    # each travels its lead (0.28 + 0.01 + 0.01) every step, and the progress the joints'
    # travel to their setpoints can undo.
    start(0.3, 0.68)
    assert reward.hold_cost(StepOutcome(lead_rad=(0.01, 0.01)), 100) == pytest.approx(
        100 * (0.05 + 0.5 * 0.3) + 10.0 * 0.02)
    # Out of step by 0.4 beyond the tolerance: 0.5 x 0.4 a step; the reward's G moves on by
    # the step's reward (and never below the new state's hold bound).
    start(1.0, 1.0)
    gap_before = reward.hold_gap
    lag = reward.step(StepOutcome(arm_distances_rad=(0.3, 0.8), next_arm_distances_rad=(0.3,
                                  0.8), steps_done=1, lead_rad=(0.0, 0.0)))
    assert lag[1]["reward_sync"] == pytest.approx(-0.2)
    assert reward.hold_gap == pytest.approx(max(gap_before + lag[0], 999 * (0.05 + 0.5 * 0.4)))


def test_each_cuff_is_checked_against_its_own_limit():
    """Pushing only the left robot down stops the episode on the left cuff's force."""
    env = gym.make(ENV_ID, exercise=0, weight_level=0, control_mode="torque")
    base = env.unwrapped
    env.reset(seed=0)
    push = np.zeros(12, np.float32)
    push[7] = 0.6  # left shoulder lift
    for _ in range(200):
        _obs, _r, terminated, _t, info = env.step(push)
        if terminated:
            break
    assert info["safety_violation"] == "cuff_force"
    left, right = info["cuff_forces_n"][1], info["cuff_forces_n"][0]
    assert left > base.safety.force_limits_n[1] and right < base.safety.force_limits_n[0]
    assert info["reward_safety"] < -(1000 - base.episode_steps) * 0.05


def test_contact_between_the_two_robots_is_unintended_contact(env):
    """Move the left robot's base onto the right robot: the two robots' geoms now collide (the
    bilateral scene gives them a collision bit of their own) and the monitor counts it."""
    base = env.unwrapped
    model = base.model
    right, left = base.handles
    assert np.all(model.geom_contype[left.geom_ids][model.geom_contype[left.geom_ids] > 0]
                  & ROBOT_PAIR_BIT)
    saved = (model.body_pos[left.base_body_id].copy(), model.geom_contype.copy(),
             model.geom_conaffinity.copy())
    try:
        model.body_pos[left.base_body_id] = model.body_pos[right.base_body_id].copy()
        robots = np.zeros(model.ngeom, bool)
        robots[base.scene.robot_geom_ids] = True
        model.geom_contype[~robots] = 0  # only the robots can touch anything
        model.geom_conaffinity[~robots] = 0
        data = mujoco.MjData(model)
        base.scene.reset_data(data)
        data.eq_active[:] = 0  # the moved robot has left its cuff
        mujoco.mj_forward(model, data)
        right_geoms, left_geoms = set(right.geom_ids.tolist()), set(left.geom_ids.tolist())
        between = [c for c in data.contact[:data.ncon]
                   if {int(c.geom[0]), int(c.geom[1])} & right_geoms
                   and {int(c.geom[0]), int(c.geom[1])} & left_geoms]
        assert between and len(between) == data.ncon  # robot-robot contacts only
        thresholds = SafetyThresholds()
        assert SafetyMonitor(base.scene, thresholds, robots_collide=True).check(data, 0.0) == \
            "unintended_contact"
        assert SafetyMonitor(base.scene, thresholds).check(data, 0.0) is None
    finally:
        model.body_pos[left.base_body_id], model.geom_contype[:], model.geom_conaffinity[:] = \
            saved
    assert base.safety._robots_collide


def test_bad_input_is_refused_with_the_value_named(env):
    env.reset(seed=0)
    action = np.zeros(12, np.float32)
    action[4] = np.nan
    with pytest.raises(ValueError, match="4"):
        env.step(action)
    with pytest.raises(ValueError, match=r"\(6,\)|shape"):
        env.step(np.zeros(6, np.float32))
    with pytest.raises(ValueError, match="patterns='mirror'"):
        gym.make(ENV_ID, patterns=("mirror",))
    with pytest.raises(ValueError, match="limb='knee'"):
        gym.make(ENV_ID, limb="knee")
    with pytest.raises(ValueError, match="reward='paper'"):
        gym.make(ENV_ID, reward="paper")
    with pytest.raises(ValueError, match="not supported by the bilateral env"):
        gym.make(ENV_ID, condition={"spasticity_mas": "2"})
    with pytest.raises(ValueError, match="exercise=4"):
        gym.make(ENV_ID, exercise=4)
    with pytest.raises(ValueError, match="sync_weight"):
        gym.make(ENV_ID, sync_weight=-1.0)
    with pytest.raises(TypeError, match="unknown keyword"):
        gym.make(ENV_ID, colour="red")


def test_one_pattern_table_and_reproducible_episodes():
    env = gym.make(ENV_ID, patterns=("alternating",))
    assert len(env.unwrapped.targets) == 2
    assert env.unwrapped.exercises[0].name == "shoulder_flexion_alternating"
    action = np.full(12, 0.004, np.float32)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=11)
        steps = [env.step(action) for _ in range(20)]
        runs.append((info["exercise"], info["weight_level"], obs,
                     np.array([s[0] for s in steps]), [s[1] for s in steps]))
    assert runs[0][:2] == runs[1][:2]
    np.testing.assert_array_equal(runs[0][2], runs[1][2])
    np.testing.assert_array_equal(runs[0][3], runs[1][3])
    assert runs[0][4] == runs[1][4]


def test_layouts_by_size_and_tracking_features_read_both_robots(env):
    from rehabbot.rl.zoo import tracking_error_features
    from rehabbot.tasks.observation import layout_for_size, paper_layout

    assert layout_for_size(23) == paper_layout(6)
    assert layout_for_size(25) == paper_layout(7)
    assert layout_for_size(44) == paper_layout(6, n_arms=2)
    with pytest.raises(ValueError, match="30 values"):
        layout_for_size(30)
    space = env.observation_space
    obs, _ = env.reset(seed=0)
    batch = obs[None].copy()
    batch[0, 18:30] += 0.01 * np.arange(12)  # theta of both robots
    center, half = (space.high + space.low) / 2, (space.high - space.low) / 2
    features = tracking_error_features(batch, center, half, 0.05)  # the -v1 agents' input
    assert features.shape == (1, 44 + 12 + 6 + 12)
    joint_error = (batch[0, 0:12] - batch[0, 18:30]) / 0.5
    np.testing.assert_allclose(features[0, 44:56], joint_error, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(features[0, 56:62], (batch[0, 12:18] - batch[0, 30:36]) / 0.1,
                               rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(features[0, 62:], np.tanh(joint_error / 0.1), rtol=1e-5,
                               atol=1e-6)


@pytest.mark.slow
def test_the_cli_trains_evaluates_renders_and_plots_the_bilateral_id(tmp_path, capsys):
    import json

    import imageio.v2 as imageio

    from rehabbot.cli import main

    runs = tmp_path / "runs"
    small = tmp_path / "sac.yml"  # the shipped settings have no -v1 entries; a small network
    small.write_text("learning_starts: 100\nbuffer_size: 5000\npolicy_kwargs: "
                     "'dict(net_arch=[32, 32])'\n")
    assert main(["train", "rehab-bilateral-v1", "--algo", "sac", "--backend", "sb3",
                 "--hyperparams", str(small),
                 "--timesteps", "300", "--demos", "1", "--eval-freq", "150",
                 "--eval-episodes", "1", "--checkpoint-freq", "150", "--out", str(runs),
                 "--no-progress"]) == 0
    run = runs / "rehab-bilateral-v1" / "sac" / "seed0"
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["env_id"] == ENV_ID and manifest["timesteps_done"] == 300
    evaluation = tmp_path / "eval"
    assert main(["evaluate", str(run / "model.zip"), "expert", "--episodes", "1",
                 "--seed", "7", "--out", str(evaluation)]) == 0
    expert = json.loads((evaluation / "expert" / "evaluation.json").read_text())
    assert expert["per_episode"][0]["success"]
    model = json.loads((evaluation / "sac-seed0" / "evaluation.json").read_text())
    assert model["per_episode"][0]["length"] > 0
    video = tmp_path / "expert.gif"
    assert main(["render", "expert", "--env", "rehab-bilateral-v1", "--out", str(video),
                 "--width", "96", "--height", "72", "--frame-every", "25"]) == 0
    frames = imageio.mimread(video)
    assert len(frames) > 2 and frames[0].shape[:2] == (72, 96)
    figures = tmp_path / "figures"
    assert main(["plot", str(run), "--out", str(figures), "--formats", "png",
                 "--source", "eval"]) == 0
    assert (figures / "fig4_learning_curves.png").stat().st_size > 10_000
    # Fig. 3 draws each robot's tool path in its own base frame: two panels side by side.
    path = imageio.imread(figures / "fig3_tool_path_sac-seed0_rehab-bilateral-v1.png")
    assert path.shape[1] > 1.8 * path.shape[0]
    for figure in ("fig5_kinematics", "fig6_torques"):
        assert (figures / f"{figure}_sac-seed0_rehab-bilateral-v1.png").stat().st_size > 10_000
    capsys.readouterr()
