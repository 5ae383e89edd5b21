"""Bilateral exercises: both arms of the seated patient, one robot per hand, moved through the
same exercise either together or in turns.

A bilateral exercise is an arm exercise (:data:`rehabbot.tasks.exercises.EXERCISES`) done with
a *pattern*:

================  ============================================================================
pattern           targets (``K_1 .. K_m`` the exercise's key poses, ``K_0`` the home posture)
================  ============================================================================
``symmetric``     ``m`` targets: both arms at ``K_i`` at the same time (in-phase bilateral
                  training: the arms move together, in step)
``alternating``   ``2 m`` targets: the right arm moves to ``K_i`` while the left holds
                  ``K_{i-1}``, then the left arm follows to ``K_i`` while the right holds (the
                  arms take turns)
================  ============================================================================

A target is a pose of both arms: its robot joint angles are the right robot's ``n`` then the
left robot's ``n`` (a :class:`rehabbot.tasks.targets.TargetSequence` whose rows are ``2 n``
wide, tool positions ``6`` wide: right then left, each in its own robot's base frame).

Everything per arm is computed on an *arm view* of the two-robot scene (:func:`arm_view`): the
same compiled model, with one robot and that arm's exercised joints, so that the one-arm tools
(IK paths, statics, workspace bounds) apply unchanged.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from rehabbot.common.checks import check_choice
from rehabbot.sim import patient as pt
from rehabbot.sim.paths import coupled_path
from rehabbot.sim.scene import Scene
from rehabbot.tasks.exercises import TASK_TYPES, Exercise
from rehabbot.tasks.targets import (
    TargetSequence,
    key_poses_deg,
    thin_waypoints,
    tool_positions_base,
    trajectory_samples,
)

PATTERNS = ("symmetric", "alternating")
ARMS = ("arm_r", "arm_l")  # the order of the arms in every two-arm vector


def arm_view(scene: Scene, arm: int) -> Scene:
    """The two-robot ``scene`` seen as a one-arm scene: robot ``arm`` (0 right, 1 left) and its
    arm's exercised joints. It shares the model; build-time use only (targets, bounds)."""
    handle = scene.robots[arm]
    joints = pt.LIMB_EXERCISE_JOINTS[handle.limb]
    model = scene.model
    own = set(joints)
    compliant = np.array([d for d in scene.compliant_dof_adr
                          if model.joint(int(model.dof_jntid[d])).name in own], dtype=int)
    return dataclasses.replace(
        scene, robots=(handle,), exercised_joints=joints,
        exercised_qpos_adr=np.array([model.joint(n).qposadr[0] for n in joints]),
        exercised_dof_adr=np.array([model.joint(n).dofadr[0] for n in joints]),
        compliant_dof_adr=compliant,
        home_setpoints=scene.home_setpoints[arm:arm + 1].copy(), _scratch=None)


def pattern_rows(keys_deg: np.ndarray, home_deg: np.ndarray,
                 pattern: str) -> tuple[np.ndarray, np.ndarray]:
    """The right and the left arm's exercised-joint angles [deg] at each target of ``pattern``
    (module docstring); ``keys_deg`` is ``(m, 3)``, the same key poses for both arms."""
    check_choice("pattern", pattern, PATTERNS)
    keys = np.asarray(keys_deg, dtype=float)
    if pattern == "symmetric":
        return keys.copy(), keys.copy()
    previous = np.vstack([np.asarray(home_deg, dtype=float)[None], keys[:-1]])
    right = np.repeat(keys, 2, axis=0)
    left = np.empty_like(right)
    left[0::2], left[1::2] = previous, keys
    return right, left


def bilateral_exercise(exercise: Exercise, pattern: str) -> Exercise:
    """The arm exercise done with ``pattern``, named ``<exercise>_<pattern>``."""
    check_choice("pattern", pattern, PATTERNS)
    how = ("both arms together" if pattern == "symmetric" else
           "the arms in turns, right first")
    return Exercise(f"{exercise.name}_{pattern}", f"{exercise.description}; {how}",
                    exercise.key_poses_deg)


def build_bilateral_targets(scene: Scene, exercise: Exercise, pattern: str, task_type: str,
                            segment_s: float = 3.0, waypoint_dt_s: float = 0.1,
                            min_spacing_rad: float = 0.1) -> TargetSequence:
    """The targets of ``exercise`` done with ``pattern`` in the two-robot ``scene``.

    ``"reaching"``: the pattern's poses. ``"trajectory"``: a minimum-jerk path between them for
    each arm (segments of ``segment_s``, sampled every ``waypoint_dt_s``; an arm that holds in
    a segment stays put), thinned so that consecutive targets differ by at least
    ``min_spacing_rad`` on some joint of either robot. Both arms' rows are solved on one IK
    branch each, warm-started along the path.
    """
    check_choice("task_type", task_type, TASK_TYPES)
    views = tuple(arm_view(scene, k) for k in range(len(ARMS)))
    home = [np.degrees(v.home_qpos[v.exercised_qpos_adr]) for v in views]
    right_rows, _ = pattern_rows(key_poses_deg(views[0], exercise), home[0], pattern)
    _, left_rows = pattern_rows(key_poses_deg(views[1], exercise), home[1], pattern)
    rows = (right_rows, left_rows)
    if task_type == "reaching":
        paths = [coupled_path(v, r, dt_s=waypoint_dt_s) for v, r in zip(views, rows, strict=True)]
        keep = np.arange(len(rows[0]))
    else:
        dense = [trajectory_samples(h, r, segment_s, waypoint_dt_s)
                 for h, r in zip(home, rows, strict=True)]
        paths = [coupled_path(v, samples, dt_s=waypoint_dt_s)
                 for v, (samples, _) in zip(views, dense, strict=True)]
        start = np.concatenate([v.home_qpos[v.robots[0].qpos_adr] for v in views])
        both = np.concatenate([p.robot_rad[:, 0] for p in paths], axis=1)
        keep = thin_waypoints(start, both, dense[0][1], min_spacing_rad)
    robot = [p.robot_rad[keep, 0] for p in paths]
    return TargetSequence(
        exercise=bilateral_exercise(exercise, pattern),
        task_type=task_type,
        patient_deg=np.concatenate([p.patient_deg[keep] for p in paths], axis=1),
        robot_rad=np.concatenate(robot, axis=1),
        tool_pos_base_m=np.concatenate([tool_positions_base(v, q)
                                        for v, q in zip(views, robot, strict=True)], axis=1),
        servo_setpoint_rad=np.concatenate([p.servo_setpoint_rad[keep, 0] for p in paths],
                                          axis=1),
        ik_error_m=np.maximum(paths[0].ik_error_m[keep], paths[1].ik_error_m[keep]),
    )


def segment_lengths_rad(targets_rad: np.ndarray, home_rad: np.ndarray,
                        n_joints: int) -> np.ndarray:
    """``(N, 2)``: how far each robot's joints travel (2-norm, rad) from the previous target
    (the home angles before the first) to each target; rows are right then left robot."""
    rows = np.vstack([np.asarray(home_rad, dtype=float)[None], targets_rad])
    steps = np.diff(rows, axis=0)
    return np.stack([np.linalg.norm(steps[:, :n_joints], axis=1),
                     np.linalg.norm(steps[:, n_joints:], axis=1)], axis=1)
