"""Robots of one's own: ``register_robot`` checks a RobotModel against the plug-in contract
and makes ``robot=<name>`` work in every env, without editing the package."""

from __future__ import annotations

import dataclasses
import math
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


def _ur5e_then(change):
    """A build: the UR5e, then ``change(spec, prefix)``."""

    def build(parent, spec, opts=None, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
        base = ur5e.add_ur5e(parent, spec, opts, pos=pos, quat=quat)
        change(spec, opts.prefix if opts is not None else "")
        return base

    return build


def _set(kind, name, attribute, value):
    def change(spec, p):
        setattr(getattr(spec, kind)(f"{p}{name}"), attribute, value)

    return change


def _set_entry(kind, name, attribute, index, value):
    def change(spec, p):
        getattr(getattr(spec, kind)(f"{p}{name}"), attribute)[index] = value

    return change


NAN, INF = float("nan"), float("inf")
# (what the build changes, the field as the error names it, the value it names), for a
# non-finite and an absurd value of every physical quantity a build sets.
BAD_BUILDS = [
    (_set("body", "link2", "mass", NAN), "body 'link2' mass = nan kg", "mass"),
    (_set("body", "base", "mass", NAN), "body 'base' mass = nan kg", "mass"),
    (_set("body", "link2", "mass", 1e9), "body 'link2' mass = 1000000000.0 kg", "mass"),
    (_set("body", "link2", "mass", -1.0), "body 'link2' mass = -1.0 kg", "mass"),
    (_set("body", "link3", "inertia", [INF, 0.1, 0.1]), "body 'link3' inertia = .*inf kg·m²",
     "inertia"),
    (_set("body", "link3", "inertia", [1e6, 1e6, 1e6]), "body 'link3' inertia = .*1000000.0",
     "inertia"),
    (_set("body", "link2", "pos", [1e9, 0.0, 0.0]), "body 'link2' pos = .*1000000000.0 m",
     "length"),
    (_set("body", "link2", "pos", [NAN, 0.0, 0.0]), "body 'link2' pos = .*nan m", "length"),
    (_set("body", "link4", "ipos", [0.0, 5.0, 0.0]), "body 'link4' ipos = .*5.0 m", "length"),
    (_set("body", "link1", "quat", [NAN, 0.0, 0.0, 1.0]), "body 'link1' quat = .*nan",
     "orientation"),
    (_set("body", "link1", "gravcomp", 7.0), "body 'link1' gravcomp = 7.0", "gravity"),
    (_set("joint", "elbow", "range", [-1e9, 1e9]), "joint 'elbow' range = .*-1000000000.0 rad",
     "joint limit"),
    (_set("joint", "elbow", "pos", [0.0, INF, 0.0]), "joint 'elbow' pos = .*inf m", "length"),
    (_set("joint", "elbow", "armature", NAN), "joint 'elbow' armature = nan kg·m²",
     "armature"),
    (_set("joint", "elbow", "armature", 1e4), "joint 'elbow' armature = 10000.0", "armature"),
    (_set_entry("joint", "elbow", "damping", 0, 1e7), "joint 'elbow' damping = .*10000000.0",
     "damping"),
    (_set("joint", "elbow", "frictionloss", NAN), "joint 'elbow' frictionloss = nan N·m",
     "friction loss"),
    (_set_entry("joint", "elbow", "stiffness", 0, -5.0), "joint 'elbow' stiffness = .*-5.0",
     "stiffness"),
    (_set("geom", "forearm_tube", "size", [0.05, 1e9, 0.0]),
     "geom 'forearm_tube' size = .*1000000000.0 m", "length"),
    (_set("geom", "forearm_tube", "density", NAN), "geom 'forearm_tube' density = nan kg/m³",
     "density"),
    (_set("geom", "forearm_tube", "mass", 5e3), "geom 'forearm_tube' mass = 5000.0 kg", "mass"),
    (_set("geom", "cuff", "friction", [NAN, 0.0, 0.0]), "geom 'cuff' friction = .*nan",
     "friction coefficient"),
    (_set("site", "cuff", "pos", [0.0, 0.0, 1e3]), "site 'cuff' pos = .*1000.0 m", "length"),
    (_set_entry("actuator", "elbow_servo", "gainprm", 0, NAN),
     "actuator 'elbow_servo' gainprm = .*nan", "actuator parameter"),
    (_set_entry("actuator", "elbow_servo", "biasprm", 2, -1e12),
     "actuator 'elbow_servo' biasprm = .*-1000000000000.0", "actuator parameter"),
    (_set("actuator", "elbow_motor", "ctrlrange", [-INF, INF]),
     "actuator 'elbow_motor' ctrlrange = .*-inf", "actuator parameter"),
    (_set_entry("actuator", "elbow_motor", "gear", 0, 1e9),
     "actuator 'elbow_motor' gear = .*1000000000.0", "actuator parameter"),
]


@pytest.mark.parametrize(("change", "named", "quantity"), BAD_BUILDS,
                         ids=[named.split(" =")[0] + f"-{k}"
                              for k, (_, named, _) in enumerate(BAD_BUILDS)])
def test_a_build_that_sets_an_implausible_physical_value_is_refused(change, named, quantity):
    """The error names the robot, the element, the field, the value and the allowed range."""
    model = dataclasses.replace(ur5e.UR5E, name="ur5e_bad", build=_ur5e_then(change))
    with pytest.raises(ValueError, match=f"robot 'ur5e_bad' breaks the plug-in contract: "
                                         f"build sets {named}.* is out of range: {quantity}"
                                         r".* must be finite"):
        register_robot(model)
    assert "ur5e_bad" not in ROBOTS


@pytest.mark.parametrize(("setting", "value"), [("option.timestep", 0.01),
                                                ("option.gravity", [0.0, 0.0, NAN]),
                                                ("compiler.degree", True),
                                                ("compiler.boundmass", 1.0)])
def test_a_build_that_changes_the_scenes_settings_is_refused(setting, value):
    part, name = setting.split(".")

    def change(spec, p):
        setattr(getattr(spec, part), name, value)

    model = dataclasses.replace(ur5e.UR5E, name="ur5e_bad", build=_ur5e_then(change))
    with pytest.raises(ValueError, match=f"build changes the scene's settings .*'spec.{setting}'"):
        register_robot(model)


BAD_FIELDS = [
    (dict(base_offset_m=(("arm", (1e9, 0.0, 0.0)),)), r"base_offset_m\['arm'\] = "
     r"\[1000000000.0, 0.0, 0.0\], whose 1000000000.0 m is out of range: length"),
    (dict(base_offset_m=(("leg_seated", (0.0, NAN, 0.0)),)), r"base_offset_m\['leg_seated'\] "
     r"= \[0.0, nan, 0.0\], whose nan m"),
    (dict(torque_limit_nm=(150e3,) * 6), r"torque_limit_nm = .*150000.0 N·m is out of range"),
    (dict(max_joint_speed_rad_s=(180.0,) * 6), r"max_joint_speed_rad_s = .*180.0 rad/s"),
    (dict(joint_range_rad=((-1e9, 1e9),) * 6), r"joint_range_rad = .*-1000000000.0 rad"),
    (dict(default_gains=ur5e.ImpedanceGains((1e9,) * 6, (1.0,) * 6)),
     r"default_gains.kp_nm_per_rad = .*1000000000.0 N·m/rad"),
    (dict(default_gains=ur5e.ImpedanceGains((1.0,) * 6, (1e9,) * 6)),
     r"default_gains.kv_nms_per_rad = .*1000000000.0 N·m·s/rad"),
]


@pytest.mark.parametrize(("fields", "named"), BAD_FIELDS, ids=range(len(BAD_FIELDS)))
def test_a_model_with_an_implausible_physical_value_is_refused(fields, named):
    model = dataclasses.replace(ur5e.UR5E, name="ur5e_bad", **fields)
    with pytest.raises(ValueError, match="robot 'ur5e_bad' breaks the plug-in contract: "
                                         + named):
        register_robot(model)
    assert "ur5e_bad" not in ROBOTS


def test_masses_derived_from_geoms_are_checked_after_compiling():
    """A body without explicit inertial takes its mass from its geoms' densities: a heavy
    one is named from the compiled model."""
    import mujoco

    from rehabbot.sim.robots import bounds

    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="chk_link1")
    body.add_joint(name="chk_j", type=mujoco.mjtJoint.mjJNT_HINGE)
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.1, 0.0, 0.0], density=9e4)
    assert list(bounds.spec_problems(spec, "chk_")) == []  # every value the build set is fine
    problems = list(bounds.model_problems(spec.compile(), "chk_"))
    assert len(problems) == 1 and problems[0].startswith(
        "body 'link1' compiled mass = 376.99") and "in [0, 100] kg" in problems[0]


def test_every_range_states_its_reason():
    from rehabbot.sim.robots import bounds

    ranges = [value for value in vars(bounds).values() if isinstance(value, bounds.Bound)]
    assert len(ranges) >= 15
    for bound in ranges:
        assert bound.low < bound.high and bound.reason and bound.quantity
        ends = [max(bound.low, -1e300), min(bound.high, 1e300)]
        assert bound.first_bad(ends) is None
        if math.isfinite(bound.high):
            assert bound.first_bad([np.nextafter(bound.high, np.inf)]) is not None
        assert math.isnan(bound.first_bad([NAN]))
