"""Ids of one robot and its cuff in a compiled scene, resolved once when the scene is built."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rehabbot.sim.robots.base import RobotModel


@dataclass(frozen=True)
class RobotHandle:
    """One robot of a scene: its model and every id the layers above need."""

    robot: RobotModel
    prefix: str
    limb: str  # the cuffed limb: "arm_r", "arm_l", "leg_r" or "leg_l"
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    servo_ids: np.ndarray
    motor_ids: np.ndarray
    tool_site_id: int
    cuff_site_id: int
    patient_cuff_site_id: int
    base_body_id: int
    equality_id: int
    geom_ids: np.ndarray

    @property
    def n_joints(self) -> int:
        """Number of actuated joints of the robot."""
        return self.robot.n_joints
