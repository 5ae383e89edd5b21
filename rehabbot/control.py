"""What an action means: one controller class per control mode.

Every mode drives the same UR5e actuators (:mod:`rehabbot.models.robot`): per joint an
impedance servo (``ctrl`` = setpoint [rad]) and a feed-forward motor (``ctrl`` = N·m), on top
of the gravity compensation of the robot's own links, with the joint's total torque saturated
at the UR5e limits (150 N·m base/shoulder/elbow, 28 N·m wrists).

================  =====================================  =====================================
mode              action                                 effect per decision (dt)
================  =====================================  =====================================
``joint_delta``   Box(-pi/400, pi/400, (6,)) [rad]       servo setpoints += action (paper)
``joint_position`` Box(setpoint bounds) [rad]            servo setpoints = action
``joint_velocity`` Box(-v_max, v_max, (6,)) [rad/s]      servo setpoints += action * dt
``torque``        Box(-1, 1, (6,)) (normalised)          motor torque = action * torque limit;
                                                         servos switched off
================  =====================================  =====================================

In the three setpoint modes the setpoint is kept inside the setpoint bounds (the paper's
Table 3 ranges in robot joint space, :func:`rehabbot.exercises.setpoint_bounds`).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from gymnasium import spaces

from rehabbot.models import robot as ur
from rehabbot.models.scene import RobotHandle

CONTROL_MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")
PAPER_DELTA_RAD = math.pi / 400


class Controller:
    """Base class: holds the setpoint state and writes ``data.ctrl``."""

    mode = ""

    def __init__(self, handle: RobotHandle, low_rad: np.ndarray, high_rad: np.ndarray,
                 dt_s: float) -> None:
        self.handle = handle
        self.low_rad = np.asarray(low_rad, dtype=float)
        self.high_rad = np.asarray(high_rad, dtype=float)
        self.dt_s = dt_s
        self.setpoint_rad = np.zeros(6)
        self.action_space = self._make_space()
        self._servo = as_index(handle.servo_ids)
        self._motor = as_index(handle.motor_ids)
        self._ctrl = np.zeros(0)

    def _make_space(self) -> spaces.Box:
        raise NotImplementedError

    def configure(self, model: mujoco.MjModel) -> None:
        """Switch the model's actuator groups for this mode (servos on, by default)."""
        model.opt.disableactuator = 0

    def reset(self, data: mujoco.MjData, home_setpoint_rad: np.ndarray) -> None:
        """Start an episode from the home setpoints (already written into ``data.ctrl``)."""
        self._ctrl = data.ctrl
        self.setpoint_rad[:] = np.clip(home_setpoint_rad, self.low_rad, self.high_rad)
        self._ctrl[self._servo] = self.setpoint_rad
        self._ctrl[self._motor] = 0.0

    def apply(self, action: np.ndarray, data: mujoco.MjData) -> None:
        """Write the controls for ``action`` (already checked and clipped to the space)."""
        raise NotImplementedError

    def _set(self, setpoint: np.ndarray, data: mujoco.MjData) -> None:
        np.clip(setpoint, self.low_rad, self.high_rad, out=self.setpoint_rad)
        self._ctrl[self._servo] = self.setpoint_rad


class JointDeltaController(Controller):
    """The paper's action: increments of the impedance setpoints, at most ``delta_max_rad``."""

    mode = "joint_delta"

    def __init__(self, handle, low_rad, high_rad, dt_s, delta_max_rad: float = PAPER_DELTA_RAD):
        self.delta_max_rad = delta_max_rad
        super().__init__(handle, low_rad, high_rad, dt_s)

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-self.delta_max_rad, self.delta_max_rad, (6,), np.float32)

    def apply(self, action, data):
        setpoint = self.setpoint_rad
        np.add(setpoint, action, out=setpoint)
        np.maximum(setpoint, self.low_rad, out=setpoint)
        np.minimum(setpoint, self.high_rad, out=setpoint)
        self._ctrl[self._servo] = setpoint


class JointPositionController(Controller):
    """Absolute impedance setpoints inside the setpoint bounds."""

    mode = "joint_position"

    def _make_space(self) -> spaces.Box:
        return spaces.Box(self.low_rad.astype(np.float32), self.high_rad.astype(np.float32),
                          (6,), np.float32)

    def apply(self, action, data):
        self._set(np.asarray(action, dtype=float), data)


class JointVelocityController(Controller):
    """Setpoint velocities [rad/s], at most ``max_speed_rad_s``."""

    mode = "joint_velocity"

    def __init__(self, handle, low_rad, high_rad, dt_s, max_speed_rad_s: float = 0.5):
        self.max_speed_rad_s = max_speed_rad_s
        super().__init__(handle, low_rad, high_rad, dt_s)

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-self.max_speed_rad_s, self.max_speed_rad_s, (6,), np.float32)

    def apply(self, action, data):
        self._set(self.setpoint_rad + self.dt_s * np.asarray(action, dtype=float), data)


class TorqueController(Controller):
    """Normalised joint torques added to the robot's gravity compensation; servos off."""

    mode = "torque"

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (6,), np.float32)

    def configure(self, model):
        model.opt.disableactuator = 1 << ur.SERVO_ACTUATOR_GROUP

    def apply(self, action, data):
        self._ctrl[self._motor] = ur.TORQUE_LIMIT_NM * np.asarray(action, dtype=float)


def as_index(indices: np.ndarray) -> slice | np.ndarray:
    """A slice equal to ``indices`` when they form an increasing arithmetic progression (reads
    are views, writes are faster), else the indices themselves."""
    idx = np.asarray(indices, dtype=int)
    if len(idx) == 1:
        return slice(int(idx[0]), int(idx[0]) + 1)
    if len(idx) > 1 and idx[1] > idx[0] and np.all(np.diff(idx) == idx[1] - idx[0]):
        return slice(int(idx[0]), int(idx[-1]) + 1, int(idx[1] - idx[0]))
    return idx


def make_controller(mode: str, handle: RobotHandle, low_rad: np.ndarray, high_rad: np.ndarray,
                    dt_s: float, max_speed_rad_s: float = 0.5) -> Controller:
    """The controller of ``mode`` (one of :data:`CONTROL_MODES`)."""
    if mode == "joint_delta":
        return JointDeltaController(handle, low_rad, high_rad, dt_s)
    if mode == "joint_position":
        return JointPositionController(handle, low_rad, high_rad, dt_s)
    if mode == "joint_velocity":
        return JointVelocityController(handle, low_rad, high_rad, dt_s, max_speed_rad_s)
    if mode == "torque":
        return TorqueController(handle, low_rad, high_rad, dt_s)
    raise ValueError(f"control_mode={mode!r} is not one of {list(CONTROL_MODES)}")
