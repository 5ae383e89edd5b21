"""The nested env config (rehabbot/envs/config.py): seven groups, today's flat keywords still
accepted and read back, groups as objects or dicts with flat keywords on top, and the same env
whichever way it is given."""

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.bilateral_config import BilateralEnvConfig, BilateralRewardConfig
from rehabbot.envs.config import (
    ControlConfig,
    RehabEnvConfig,
    RewardConfig,
    SceneConfig,
    TaskConfig,
    kwarg_names,
)
from rehabbot.envs.rehab_env import RehabEnv


def test_every_flat_keyword_lives_in_exactly_one_group():
    names = RehabEnvConfig.flat_names()
    assert set(RehabEnvConfig.GROUPS) == {"scene", "patient", "task", "control", "safety",
                                          "reward", "render"}
    assert len(names) == 41 and set(kwarg_names()) == set(names)
    assert names["patient_model"] == ("scene", "patient_model")
    assert names["reward"] == ("reward", "design")
    assert names["time_cost"] == ("reward", "time_cost")
    assert names["frame_skip"] == ("control", "frame_skip")
    assert names["max_episode_steps"] == ("task", "max_episode_steps")
    bilateral = BilateralEnvConfig.flat_names()
    assert bilateral["patterns"] == ("task", "patterns")
    assert bilateral["sync_weight"] == ("reward", "sync_weight")


def test_flat_keywords_groups_and_dicts_give_the_same_config():
    flat = RehabEnvConfig(limb="knee", reward="progress", time_cost=0.1, frame_skip=5)
    grouped = RehabEnvConfig(scene=SceneConfig(limb="knee"), control=ControlConfig(frame_skip=5),
                             reward=RewardConfig(design="progress", time_cost=0.1))
    as_dicts = RehabEnvConfig(scene={"limb": "knee"}, control={"frame_skip": 5},
                              reward={"design": "progress", "time_cost": 0.1})
    assert flat == grouped == as_dicts
    assert flat != RehabEnvConfig(limb="knee", reward="progress")
    # Read back flat (the design under its keyword) and as groups.
    assert (flat.limb, flat.time_cost, flat.frame_skip) == ("knee", 0.1, 5)
    assert flat.reward.design == "progress" == flat.flat("reward")
    assert flat.dt_s == pytest.approx(0.01)
    # The flat keywords round-trip through plain data (what run manifests store).
    assert RehabEnvConfig(**flat.to_kwargs()) == flat


def test_flat_keywords_apply_on_top_of_a_group_and_replace_keeps_the_rest():
    config = RehabEnvConfig(reward=RewardConfig(design="progress", time_cost=0.2),
                            progress_weight=5.0)
    assert (config.reward.design, config.time_cost, config.progress_weight) == \
        ("progress", 0.2, 5.0)
    # A design given as a string replaces only the design.
    paper = config.replace(reward="paper")
    assert (paper.reward.design, paper.time_cost, paper.progress_weight) == ("paper", 0.2, 5.0)
    longer = config.replace(max_episode_steps=50, task=TaskConfig(task_type="trajectory"))
    assert (longer.max_episode_steps, longer.task_type, longer.time_cost) == \
        (50, "trajectory", 0.2)
    assert config.max_episode_steps == 1000  # frozen: the original is unchanged


def test_bad_values_and_keywords_are_named():
    with pytest.raises(TypeError, match="unknown keyword argument 'speed'"):
        RehabEnvConfig(speed=3)
    with pytest.raises(ValueError, match=r"reward='\w+'|reward=RewardConfig"):
        RehabEnvConfig(reward="money")
    with pytest.raises(ValueError, match="scene=3 must be a SceneConfig"):
        RehabEnvConfig(scene=3)
    with pytest.raises(ValueError, match="reward has unknown field"):
        RehabEnvConfig(reward={"desing": "progress"})
    with pytest.raises(ValueError, match="frame_skip=0 must be an integer"):
        RehabEnvConfig(control={"frame_skip": 0})
    # Checks across groups: the exercise against the limb's table, the speed bound against
    # the robot.
    with pytest.raises(ValueError, match="exercise=2 is not one of"):
        RehabEnvConfig(task={"exercise": 2})
    with pytest.raises(ValueError, match="max_speed_rad_s=9"):
        RehabEnvConfig(max_speed_rad_s=9, robot="fr3")
    with pytest.raises(ValueError, match="reward='paper': the bilateral env pays"):
        BilateralEnvConfig(reward="paper")


def test_an_env_made_from_groups_steps_as_one_made_from_flat_keywords():
    flat = gym.make("rehabbot/rehab-knee-v1", time_cost=0.1, exercise=1, weight_level=2)
    grouped = gym.make("rehabbot/rehab-knee-v1", reward={"design": "progress",
                                                         "time_cost": 0.1},
                       task={"exercise": 1}, patient={"weight_level": 2})
    assert flat.unwrapped.config == grouped.unwrapped.config
    reward = grouped.unwrapped.config.reward
    assert reward.time_cost == 0.1 and reward.design == "progress"
    obs_a, _ = flat.reset(seed=3)
    obs_b, _ = grouped.reset(seed=3)
    action = np.full(6, 0.5 * np.pi / 400, np.float32)
    np.testing.assert_array_equal(obs_a, obs_b)
    for _ in range(20):
        a = flat.step(action)
        b = grouped.step(action)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4]
        if a[2]:
            break
    with pytest.raises(TypeError, match="got unknown keyword argument"):
        RehabEnv(rewrad="progress")


def test_bilateral_groups():
    config = BilateralEnvConfig(patterns=["symmetric"], sync_weight=1.0, exercise=1)
    assert isinstance(config.reward, BilateralRewardConfig)
    assert config.reward.design == "progress" and config.task.patterns == ("symmetric",)
    assert len(config.bilateral_table) == 2 and config.exercise == 1
    assert BilateralEnvConfig(**config.to_kwargs()) == config
