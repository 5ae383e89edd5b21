"""``BilateralEnv``: two robots, one strapped to each hand of the seated patient, move both arms
through a therapy exercise together or in turns (Gymnasium API). Registered as
``rehabbot/rehab-bilateral-v1`` and, with the agent observation and actions in [-1, 1],
``rehabbot/rehab-bilateral-v2`` (:mod:`rehabbot.envs.registration`).

## Description
The paper's two-arm scene (its Figs. 2-3): the ``upper_bilateral`` preset, a robot on a stand
beside each shoulder, each cuff on its hand. Each episode runs one entry of the bilateral
exercise table: an arm exercise (shoulder or elbow flexion,
:data:`rehabbot.tasks.exercises.EXERCISES`) done with a pattern (:mod:`rehabbot.tasks.bilateral`): ``"symmetric"`` (both arms
through the same key poses at the same time) or ``"alternating"`` (the right arm moves to a
key pose while the left holds, then the left follows). A target is reached when both robots
are within ``target_tolerance_rad`` of it on every joint.

## Action space
Both robots' actions side by side, right robot first: ``control_mode="joint_delta"`` gives
``Box(-pi/400, pi/400, (2 n,), float32)`` (12 values for two UR5e, 14 for two FR3), each half
meaning what a one-arm env's action means (:mod:`rehabbot.envs.rehab_env`), with each robot's
own setpoint bounds. The other control modes likewise. Finite actions outside the box are
clipped (``info["action_clipped"]``); NaN/inf or a wrong shape raise ``ValueError``.

## Observation space
:func:`rehabbot.tasks.observation.paper_layout` with ``n_arms=2``: the paper's per-arm fields
for both arms, right first, then ``e`` and ``l`` (44 values for two UR5e):

| field | values | unit |
|---|---|---|
| theta* | 2 n: the right robot's target joint angles, then the left's | rad |
| p* | 6: each robot's target tool position, in its own base frame | m |
| theta | 2 n: robot joint angles | rad |
| p | 6: tool positions, each in its own base frame | m |
| phi | 6: shoulder flexion, abduction, elbow flexion of the right arm, then the left | rad |
| e | 1: the entry of the bilateral exercise table (:mod:`rehabbot.envs.bilateral_config`) | - |
| l | 1: weight level 0..4 (both arms' masses x1.0 .. x2.0) | - |

The bounds are each arm's one-arm bounds; they do not depend on the patient.

``rehab-bilateral-v2`` (``observation="agent"``, ``action_scale="unit"``): the action is
``Box(-1, 1, (2 n,))``, each half mapped onto its robot's box; the observation is
``Box(-2, 2, (98,))`` for two UR5e (110 for two FR3): the fields of
:mod:`rehabbot.tasks.agent_observation`, each per-arm field right arm first
(``joint_error_fine`` 12, ``joint_error`` 12, ``tool_error_fine`` 6, ``tool_error`` 6,
``next_target`` 12, ``setpoint_lead`` 12, ``joint_velocity`` 12, ``theta_in_bounds`` 12,
``phi_in_range`` 6, ``cuff_force`` 2), then ``exercise`` (one-hot over the 4 entries of the
bilateral table), ``weight_level`` and ``target_progress``. The paper's fields are in
``info["paper_observation"]``.

## Rewards
:class:`rehabbot.tasks.reward.BilateralReward`: the ``-v1`` terms with the path summed over both arms
(``reward_progress``, ``reward_bonus``, ``reward_time``, ``reward_safety``, optional
``reward_smoothness``, ``reward_effort``) plus ``reward_sync``, which charges the arms for
moving out of step when both move (``sync_weight``, ``sync_tolerance``). A stop never pays.

## Episode end
Success when both arms reach the last target; a safety stop when a rule of
:mod:`rehabbot.sim.physics` fires: each cuff against its own ISO/TS 15066 limit (hand, 140 N),
the range of motion of every patient joint, and unintended contact, which includes contact
between the two robots; truncation at ``max_episode_steps`` (the id registers 2000 = 40 s: an
alternating exercise makes every move twice).

## Info
As :class:`rehabbot.envs.rehab_env.RehabEnv`'s (``interaction_force_n`` is the larger cuff
force, ``robot_torque_nm`` both robots', ``robot_work_j`` the two cuffs' work on the arms),
plus ``cuff_forces_n`` (right, left), ``segment_fraction`` (each arm's progress through the
current segment) and ``sync_gap``.

## Arguments
Every argument of :class:`rehabbot.envs.rehab_env.RehabEnv` (the table there) except that
``limb`` must be ``"arm"``, ``side`` is unused, ``reward`` is ``"progress"`` and ``condition``
must be healthy (conditions on both arms are not supported yet); ``exercise`` indexes the
bilateral table. Bilateral arguments:

| kwarg | group | default | meaning |
|---|---|---|---|
| ``patterns`` | task | ``("symmetric", "alternating")`` | the patterns of the table (pattern-major) |
| ``sync_weight`` | reward | 0.5 | cost per step of a whole segment's lag between the arms |
| ``sync_tolerance`` | reward | 0.1 | lag (share of the segment) that costs nothing |

Rendering draws the right robot's tool path and targets.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from rehabbot.envs.bilateral_build import build_bilateral_parts
from rehabbot.envs.bilateral_config import BilateralEnvConfig
from rehabbot.envs.config import config_from
from rehabbot.envs.core import RehabEnvCore


class BilateralEnv(RehabEnvCore):
    """Two robots move both of a patient's arms through an exercise (module docstring).
    ``reset`` and ``step`` are the env core's (:mod:`rehabbot.envs.core`), for two arms."""

    config_class: ClassVar[type] = BilateralEnvConfig

    def __init__(self, config: BilateralEnvConfig | None = None, **kwargs: Any) -> None:
        self.config = config = config_from(BilateralEnvConfig, "BilateralEnv", config, kwargs)
        parts = build_bilateral_parts(config)
        self.n_joints_per_robot = parts.handles[0].robot.n_joints
        self.joint_names = tuple(f"{h.prefix}{j}" for h in parts.handles
                                 for j in h.robot.joint_names)
        self.joint_low_rad, self.joint_high_rad = parts.joint_low_rad, parts.joint_high_rad
        self._adopt(parts)

    @property
    def torque_limits_nm(self) -> np.ndarray:
        """Both robots' joint torque limits [N·m], right first (a new array)."""
        return np.concatenate([h.robot.torque_limits() for h in self.handles])

    @property
    def segment_fractions(self) -> np.ndarray:
        """Each arm's progress through the current segment (a copy)."""
        return np.array(self._reward.fractions)
