"""Robots of one's own: ``register_robot`` checks a RobotModel against the plug-in contract
and makes ``robot=<name>`` work in every env, without editing the package."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the env ids)
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim import scene as scene_module
from rehabbot.sim.robots import (
    ROBOT_NAMES,
    ROBOTS,
    RobotBuildOptions,
    check_robot_model,
    get_robot,
    register_robot,
    ur5e,
)

LIGHT_LIMITS_NM = (120.0, 120.0, 100.0, 20.0, 20.0, 20.0)


def build_light(parent, spec, opts=None, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
    """The UR5e, its torque clamps lowered to LIGHT_LIMITS_NM."""
    base = ur5e.add_ur5e(parent, spec, opts, pos=pos, quat=quat)
    p = opts.prefix if opts is not None else ""
    for name, limit in zip(ur5e.JOINT_NAMES, LIGHT_LIMITS_NM, strict=True):
        spec.joint(f"{p}{name}").actfrcrange = [-limit, limit]
        spec.actuator(f"{p}{name}_servo").forcerange = [-limit, limit]
        spec.actuator(f"{p}{name}_motor").ctrlrange = [-limit, limit]
    return base


LIGHT = dataclasses.replace(ur5e.UR5E, name="ur5e_light", torque_limit_nm=LIGHT_LIMITS_NM,
                            build=build_light)


@pytest.fixture(autouse=True)
def restore_robots() -> Iterator[None]:
    """Every test leaves the registry as it found it."""
    before = dict(ROBOTS)
    yield
    ROBOTS.clear()
    ROBOTS.update(before)


def test_a_registered_robot_runs_in_an_env_with_its_own_limits():
    assert register_robot(LIGHT) is LIGHT
    assert get_robot("ur5e_light") is LIGHT
    # The names are live wherever they were imported (the scene checks robot= against them).
    assert "ur5e_light" in ROBOT_NAMES and "ur5e_light" in scene_module.ROBOT_NAMES
    assert tuple(ROBOT_NAMES) == ("ur5e", "fr3", "ur5e_light")
    env = gym.make("rehabbot/rehab-knee-v2", robot="ur5e_light")
    try:
        model = env.unwrapped.scene.model
        for name, limit in zip(ur5e.JOINT_NAMES, LIGHT_LIMITS_NM, strict=True):
            np.testing.assert_allclose(model.jnt_actfrcrange[model.joint(name).id],
                                       [-limit, limit])
        obs, info = env.reset(seed=0)
        expert = ScriptedExpert(env)
        peak = np.zeros(6)
        for _ in range(1000):
            obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
            peak = np.maximum(peak, np.abs(info["robot_torque_nm"]))
            if terminated or truncated:
                break
        assert info["is_success"] and info["safety_violation"] is None
        assert np.all(peak <= np.array(LIGHT_LIMITS_NM) + 1e-6)
    finally:
        env.close()


def test_a_name_clash_is_refused_unless_replace():
    with pytest.raises(ValueError, match=r"robot 'ur5e' is already registered .*replace=True"):
        register_robot(ur5e.UR5E)
    register_robot(LIGHT)
    with pytest.raises(ValueError, match="'ur5e_light' is already registered"):
        register_robot(LIGHT)
    assert register_robot(LIGHT, replace=True) is LIGHT
    with pytest.raises(ValueError, match="replace=1 must be True or False"):
        register_robot(LIGHT, replace=1)  # type: ignore[arg-type]


def _ignore_prefix(parent, spec, opts=None, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
    return ur5e.add_ur5e(parent, spec, RobotBuildOptions(), pos=pos, quat=quat)


def _fails(parent, spec, opts=None, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
    raise RuntimeError("no meshes here")


BROKEN = {
    # the build keeps the UR5e's 150/28 N·m clamps: the model would lie about its limits
    "joint 'shoulder_pan' clamps its actuator torque at \\[-150.0, 150.0\\] N·m .* "
    "torque_limit_nm says \\+-120.0":
        dict(torque_limit_nm=LIGHT_LIMITS_NM),
    "joint 'elbow' has range .* joint_range_rad says": dict(joint_range_rad=(
        *ur5e.UR5E.joint_range_rad[:2], (-1.0, 1.0), *ur5e.UR5E.joint_range_rad[3:])),
    "build adds no body 'chk_base'": dict(build=_ignore_prefix),
    "build adds no joint 'chk_knuckle'": dict(joint_names=(*ur5e.JOINT_NAMES[:5], "knuckle")),
    "build\\(parent, spec, options, pos, quat\\) failed: RuntimeError: no meshes here":
        dict(build=_fails),
    "actuator shoulder_pan_servo is in group 1, not servo_group=3": dict(servo_group=3),
    "servo_group=2 and motor_group=2 must be two different": dict(servo_group=2),
    "ik_seed must return 6 finite joint angles .* shape \\(5,\\)":
        dict(ik_seed=lambda cuff: np.zeros(5)),
    "ik_seed\\(cuff_in_base_m\\) failed: ZeroDivisionError": dict(ik_seed=lambda cuff: 1 / 0),
    "max_joint_speed_rad_s=.* must be finite values > 0":
        dict(max_joint_speed_rad_s=(3.0, 3.0, 3.0, 3.0, 3.0, float("nan"))),
    "cuffed_links=0 must be an integer in \\[1, 6\\]": dict(cuffed_links=0),
    "base_offset_m entry .*'table'": dict(base_offset_m=(("table", (0.0, 0.0, 0.0)),)),
    "default_gains: gains for ur5e_light need 6 values per joint, got 7":
        dict(default_gains=get_robot("fr3").default_gains),
}


@pytest.mark.parametrize("pattern", list(BROKEN), ids=range(len(BROKEN)))
def test_a_model_that_breaks_the_contract_is_refused_and_not_registered(pattern):
    model = dataclasses.replace(ur5e.UR5E, name="ur5e_light", **BROKEN[pattern])
    with pytest.raises(ValueError, match="robot 'ur5e_light' breaks the plug-in contract: "
                                         + pattern):
        register_robot(model)
    assert "ur5e_light" not in ROBOTS and "ur5e_light" not in ROBOT_NAMES


@pytest.mark.parametrize("name", ["", "UR5e", "my robot", "../ur5e", "_x"])
def test_a_bad_name_is_refused(name):
    with pytest.raises(ValueError, match=f"robot name {name!r} must be lower-case"):
        register_robot(dataclasses.replace(LIGHT, name=name))


def test_only_a_robot_model_is_registered():
    with pytest.raises(ValueError, match="register_robot needs a RobotModel, got dict"):
        register_robot({"name": "x"})  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["ur5e", "fr3"])
def test_the_shipped_robots_keep_the_contract(name):
    check_robot_model(get_robot(name))


def test_an_unknown_robot_still_names_the_valid_ones():
    register_robot(LIGHT)
    with pytest.raises(ValueError, match=r"robot='kuka' is not one of "
                                         r"\['ur5e', 'fr3', 'ur5e_light'\]"):
        gym.make("rehabbot/rehab-knee-v2", robot="kuka")
