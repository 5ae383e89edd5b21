"""The read-only accessors other layers (rehabbot.batch) read the CPU env through, instead of
its private attributes: they hold what the env acts on, and hand out copies."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401


def test_unit_actions_and_frames():
    env = gym.make("rehabbot/rehab-reach-v2").unwrapped
    unit = env.unit_actions
    low, high = env.controller.clip_low, env.controller.clip_high
    np.testing.assert_allclose(unit.center, (high + low) / 2)
    np.testing.assert_allclose(unit.half_range, (high - low) / 2)
    native, clipped = unit.native(np.ones(env.action_space.shape, np.float32))
    np.testing.assert_allclose(native, high.astype(np.float32))
    assert clipped == 0
    unit.center[:] = 99.0  # a copy
    assert not np.any(unit.center == 99.0)
    (frame,) = env.robot_base_frames
    assert len(frame) == 12
    rot_t = np.asarray(frame[3:]).reshape(3, 3)
    np.testing.assert_allclose(rot_t @ rot_t.T, np.eye(3), atol=1e-12)
    assert env.agent_observation_map is not None
    assert gym.make("rehabbot/rehab-reach-v0").unwrapped.unit_actions is None


def test_safety_bounds_are_the_rules():
    env = gym.make("rehabbot/rehab-reach-v2").unwrapped
    low, high = env.safety.rom_bounds_rad
    tol = math.radians(env.safety.thresholds.rom_tolerance_deg)
    ranges = np.asarray([env.model.joint(n).range for n in env.scene.patient_joint_names])
    np.testing.assert_allclose(low, ranges[:, 0] - tol)
    np.testing.assert_allclose(high, ranges[:, 1] + tol)
    robot, other = env.safety.robot_geom_mask, env.safety.other_geom_mask
    assert robot.shape == other.shape == (env.model.ngeom,)
    assert robot.any() and other.any() and not (robot & other).any()
    low[:] = 0.0  # a copy
    assert not np.array_equal(env.safety.rom_bounds_rad[0], low)
    assert env.unusable_weight_levels == {}


@pytest.mark.parametrize(("condition", "mode", "has_reflex"), [
    ({"spasticity_mas": "3"}, "passive", True),
    ({"effort": "active_assisted", "strength_fraction": 0.5}, "active_assisted", False),
])
def test_patient_drive_parameters(condition, mode, has_reflex):
    env = gym.make("rehabbot/rehab-knee-v2", condition=condition).unwrapped
    drive = env.physics.drive
    assert drive.effort_mode == mode
    assert (drive.reflex is not None) == has_reflex
    assert len(drive.dof_ids) == len(drive.qpos_ids) == len(drive.stretch_ranges_rad) \
        == len(drive.reflex_gains_nms_per_rad) == len(drive.kp_nm_per_rad) > 0
    assert all(low < high for low, high in drive.stretch_ranges_rad)
    assert drive.reflex_lag_steps == round(0.030 / env.model.opt.timestep)
    assert drive.goal_lag_steps >= 0 and drive.tremor is None
    assert len(env.goals_rad) == len(env.targets)
