"""What an action means: one controller class per control mode.

Every mode drives the same robot actuators (:mod:`rehabbot.sim.robots`): per joint an
impedance servo (``ctrl`` = setpoint [rad]) and a feed-forward motor (``ctrl`` = N·m), on top
of the gravity compensation of the robot's own links, with the joint's total torque saturated
at the robot's limits (UR5e: 150 N·m base/shoulder/elbow, 28 N·m wrists). ``n`` is the
robot's number of joints (6 for the UR5e).

==================  ===================================  =====================================
mode                action                               effect per decision (dt)
==================  ===================================  =====================================
``joint_delta``     Box(-pi/400, pi/400, (n,)) [rad]     servo setpoints += action (paper)
``joint_position``  Box(-r - 0.5, r + 0.5, (n,)) [rad]   servo setpoints = action
``joint_velocity``  Box(-v_max, v_max, (n,)) [rad/s]     servo setpoints += action * dt
``torque``          Box(-1, 1, (n,)) (normalised)        motor torque = action * torque limit;
                                                         servos switched off
==================  ===================================  =====================================

``r`` is each joint's hardware range, so every space is the same for every patient. In the
three setpoint modes the setpoint is kept inside the setpoint bounds of the patient's
workspace (the paper's Table 3 ranges in robot joint space,
:func:`rehabbot.tasks.workspace.setpoint_bounds`); in ``joint_position`` mode an action
outside them is clipped to them and counted in ``info["action_clipped"]``
(:attr:`Controller.clip_low` / :attr:`Controller.clip_high`).

What each mode does with an action is its law in :mod:`rehabbot.laws.control` (the same
functions the batched env calls); a controller holds the setpoint state and writes
``data.ctrl``. An action reaches the controller checked by :func:`checked_action` (clipped and
counted, or refused with a ``ValueError`` that names the problem). On the ``-v2`` ids
(``action_scale="unit"``) the action is ``Box(-1, 1)``, mapped linearly onto the controller's
box first (:class:`UnitActions`). Two robots (:class:`ControllerPair`) act as one controller
on both halves of the action.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from gymnasium import spaces

from rehabbot.common.arrays import as_index
from rehabbot.envs.config import CONTROL_MODES
from rehabbot.laws.control import (
    SETPOINT_LAWS,
    clip_setpoint,
    clip_to_box,
    motor_torque_nm,
    native_action,
    unit_box,
)
from rehabbot.sim.handles import RobotHandle

PAPER_DELTA_RAD = math.pi / 400
FLOAT32 = np.dtype(np.float32)
# joint_position actions and setpoints: the joints' hardware ranges plus this margin (the
# setpoint bounds add 0.1 rad around the workspace, and the load-carrying setpoints of a
# joint near its range can lie a little beyond it).
SETPOINT_SPACE_MARGIN_RAD = 0.5
# How far [rad] the joints may still travel when the agent holds still in ``torque`` mode,
# where no servo holds them (the safety penalty counts it: rehabbot.tasks.reward): the sag of
# a hold under the limb's weight plus a braking distance of the joints' speed times
# TORQUE_HOLD_BRAKE_S. Measured with a PD at 0.3 x the robot's gains (the audit's torque-mode
# hold, benchmarks.common.reward_audit) after pushes of every joint at 0.3 and 1.0 of the
# torque bound on the four -v0 ids: at most 0.148 rad at rest and 0.1 + 0.04 s x speed moving
# (benchmarks/probes/stop_audit.py --drift).
TORQUE_HOLD_SAG_RAD = 0.15
TORQUE_HOLD_BRAKE_S = 0.05


class Controller:
    """Base class: holds the setpoint state, moves it by the mode's law
    (:data:`rehabbot.laws.control.SETPOINT_LAWS`) and writes ``data.ctrl``."""

    mode = ""

    def __init__(self, handle: RobotHandle, low_rad: np.ndarray, high_rad: np.ndarray,
                 dt_s: float) -> None:
        self.handle = handle
        self.robot = handle.robot
        self.n_joints = handle.robot.n_joints
        self.low_rad = np.asarray(low_rad, dtype=float)
        self.high_rad = np.asarray(high_rad, dtype=float)
        self.dt_s = dt_s
        # The servo setpoints: a view of the servos' entries of data.ctrl once bound.
        self.setpoint_rad = np.zeros(self.n_joints)
        self.action_space = self._make_space()
        # The box an action is clipped to and counted against: the space, or tighter.
        self.clip_low: np.ndarray = self.action_space.low
        self.clip_high: np.ndarray = self.action_space.high
        self._servo = as_index(handle.servo_ids)
        self._motor = as_index(handle.motor_ids)
        self._ctrl = np.zeros(0)
        self._law = SETPOINT_LAWS[self.mode]

    def _make_space(self) -> spaces.Box:
        raise NotImplementedError

    @property
    def controllers(self) -> tuple[Controller, ...]:
        """The controllers of each arm: this one (a :class:`ControllerPair` has two)."""
        return (self,)

    def configure(self, model: mujoco.MjModel) -> None:
        """Switch the model's actuator groups for this mode (servos on, by default)."""
        model.opt.disableactuator = 0

    def bind(self, data: mujoco.MjData) -> None:
        """Write into ``data.ctrl`` from now on (again after a pickle round trip)."""
        self._ctrl = data.ctrl
        self.setpoint_rad = data.ctrl[self._servo]  # a view when the servo ids are a slice

    def reset(self, data: mujoco.MjData, home_setpoint_rad: np.ndarray) -> None:
        """Start an episode from the home setpoints (already written into ``data.ctrl``)."""
        self.bind(data)
        self._set(clip_setpoint(np.asarray(home_setpoint_rad, dtype=float), self.low_rad,
                                self.high_rad))
        self._ctrl[self._motor] = 0.0

    def apply(self, action: np.ndarray, data: mujoco.MjData) -> None:
        """Write the controls for ``action`` (already checked and clipped to the space): the
        setpoints of the mode's law."""
        self._set(self.setpoint_for(action))

    def setpoint_for(self, action: np.ndarray) -> np.ndarray:
        """The servo setpoints :meth:`apply` would set for ``action`` (checked and clipped to
        the space), the same floats, without setting them. A mode without setpoints raises
        ``ValueError``."""
        return self._law(self.setpoint_rad, action, self.low_rad, self.high_rad, self.dt_s)

    def command_setpoint(self, setpoint_rad: np.ndarray) -> None:
        """Make ``setpoint_rad`` (clipped to the setpoint bounds) the servo setpoints, as if an
        action had moved them there (a robot commanded joint positions directly)."""
        self._set(clip_setpoint(np.asarray(setpoint_rad, dtype=float), self.low_rad,
                                self.high_rad))

    def hold_travel_rad(self, theta_rad: list[float], speed_rad_s: float) -> float:
        """How far [rad] the joints at ``theta_rad`` (moving at ``speed_rad_s``, the norm of
        their velocities) may still travel if the agent holds still: to the setpoints,
        which a hold keeps (:class:`TorqueController`: a sag and braking allowance)."""
        del speed_rad_s  # the servo brakes toward its setpoint
        travel = 0.0
        for angle, setpoint in zip(theta_rad, self.setpoint_rad.tolist(), strict=True):
            travel += (setpoint - angle) * (setpoint - angle)
        return math.sqrt(travel)

    def _set(self, setpoint_rad: np.ndarray) -> None:
        """Make ``setpoint_rad`` (inside the bounds) the servo setpoints."""
        self.setpoint_rad[:] = setpoint_rad
        if type(self._servo) is not slice:  # setpoint_rad is a copy, not a view
            self._ctrl[self._servo] = setpoint_rad


class JointDeltaController(Controller):
    """The paper's action: increments of the impedance setpoints, at most ``delta_max_rad``."""

    mode = "joint_delta"

    def __init__(self, handle, low_rad, high_rad, dt_s, delta_max_rad: float = PAPER_DELTA_RAD):
        self.delta_max_rad = delta_max_rad
        super().__init__(handle, low_rad, high_rad, dt_s)

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-self.delta_max_rad, self.delta_max_rad, (self.n_joints,), np.float32)


class JointPositionController(Controller):
    """Absolute impedance setpoints; actions outside the setpoint bounds are clipped to them
    (and counted as clipped)."""

    mode = "joint_position"

    def __init__(self, handle, low_rad, high_rad, dt_s):
        super().__init__(handle, low_rad, high_rad, dt_s)
        self.clip_low = self.low_rad.astype(np.float32)
        self.clip_high = self.high_rad.astype(np.float32)

    def _make_space(self) -> spaces.Box:
        low = self.robot.joint_low_rad() - SETPOINT_SPACE_MARGIN_RAD
        high = self.robot.joint_high_rad() + SETPOINT_SPACE_MARGIN_RAD
        return spaces.Box(low.astype(np.float32), high.astype(np.float32), (self.n_joints,),
                          np.float32)


class JointVelocityController(Controller):
    """Setpoint velocities [rad/s], at most ``max_speed_rad_s``."""

    mode = "joint_velocity"

    def __init__(self, handle, low_rad, high_rad, dt_s, max_speed_rad_s: float = 0.5):
        self.max_speed_rad_s = max_speed_rad_s
        super().__init__(handle, low_rad, high_rad, dt_s)

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-self.max_speed_rad_s, self.max_speed_rad_s, (self.n_joints,),
                          np.float32)


class TorqueController(Controller):
    """Normalised joint torques added to the robot's gravity compensation; servos off."""

    mode = "torque"

    def __init__(self, handle, low_rad, high_rad, dt_s):
        super().__init__(handle, low_rad, high_rad, dt_s)
        self._torque_limit_nm = self.robot.torque_limits()

    def _make_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (self.n_joints,), np.float32)

    def configure(self, model):
        model.opt.disableactuator = 1 << self.robot.servo_group

    def apply(self, action, data):
        self._ctrl[self._motor] = motor_torque_nm(action, self._torque_limit_nm)

    def setpoint_for(self, action):
        raise ValueError(f"control mode {self.mode!r} commands no joint setpoints")

    def hold_travel_rad(self, theta_rad, speed_rad_s):
        """No setpoint holds the joints: :data:`TORQUE_HOLD_SAG_RAD` plus the speed times
        :data:`TORQUE_HOLD_BRAKE_S`."""
        del theta_rad
        return TORQUE_HOLD_SAG_RAD + TORQUE_HOLD_BRAKE_S * speed_rad_s


def checked_action(action, space: spaces.Box, clip_low: np.ndarray,
                   clip_high: np.ndarray) -> tuple[np.ndarray, int]:
    """``action`` as an array inside ``[clip_low, clip_high]`` and how many values were
    clipped (:func:`rehabbot.laws.control.clip_to_box`); a float32 array of the space's shape
    inside the box is returned as it is. ``ValueError`` names the problem for anything that
    cannot be an action: NaN/inf (with their indices), a wrong shape, a dtype that is not a
    real number (bool, complex, str, object)."""
    if type(action) is np.ndarray and action.dtype is FLOAT32 and action.shape == space.shape:
        a = action
    else:
        try:
            a = np.asarray(action)
        except (TypeError, ValueError) as err:
            raise ValueError(f"action {action!r} cannot be read as {space.shape} floats: "
                             f"{err}") from None
        if a.dtype.kind not in "iuf":  # no silent casts of bool, complex, str or objects
            raise ValueError(f"action {action!r} has dtype {a.dtype}; expected {space.shape} "
                             "real numbers (float32 preferred)")
        a = a.astype(float)
        if a.shape != space.shape:
            raise ValueError(f"action has shape {a.shape}; expected {space.shape}")
    inside, clipped = clip_to_box(a, clip_low, clip_high)
    if not clipped:
        return a, 0
    bad = ~np.isfinite(a)  # NaN and inf count as clipped: refuse them
    if bad.any():
        raise ValueError(f"action has non-finite values at indices "
                         f"{np.flatnonzero(bad).tolist()}: {a.astype(float).tolist()}")
    return inside, int(clipped)


class UnitActions:
    """Actions in ``Box(-1, 1)`` (the ``-v2`` ids, ``action_scale="unit"``), mapped linearly
    onto the controller's box ``[clip_low, clip_high]``
    (:func:`rehabbot.laws.control.native_action`): -1 is the lower and +1 the upper bound of
    each joint's action (``-pi/400 .. pi/400`` rad in ``joint_delta`` mode; the patient's
    setpoint bounds in ``joint_position`` mode). The checks and the clipping count of
    :func:`checked_action` apply to the unit action."""

    def __init__(self, clip_low: np.ndarray, clip_high: np.ndarray) -> None:
        low = np.asarray(clip_low, dtype=np.float64)
        high = np.asarray(clip_high, dtype=np.float64)
        if low.shape != high.shape or not np.all(high > low):
            raise ValueError(f"a unit action needs a bounded box, got {low} .. {high}")
        self.space = spaces.Box(-1.0, 1.0, low.shape, np.float32)
        self._center, self._half = unit_box(low, high)
        # float32 like the actions they clip (no cast in the clip; the same floats)
        self._ones = np.ones(low.shape, np.float32)
        self._minus_ones = -self._ones

    @property
    def center(self) -> np.ndarray:
        """The native action of a zero unit action (a copy)."""
        return self._center.copy()

    @property
    def half_range(self) -> np.ndarray:
        """The native action's change per unit of the unit action (a copy)."""
        return self._half.copy()

    def native(self, action) -> tuple[np.ndarray, int]:
        """``(the controller's action (float32, inside its box), how many values were
        clipped to [-1, 1])``; ``ValueError`` as :func:`checked_action`."""
        unit, clipped = checked_action(action, self.space, self._minus_ones, self._ones)
        # +-1 maps onto the bounds up to float64 rounding, far below float32's step, and the
        # map is monotone: the cast lands inside the float32 bounds, so the native action
        # needs no second check.
        return native_action(unit, self._center, self._half).astype(np.float32), clipped


class ControllerPair:
    """The two arms' controllers of one control mode as one: actions, setpoints and bounds
    are the right robot's then the left robot's."""

    def __init__(self, controllers: tuple[Controller, Controller]) -> None:
        self.controllers = controllers
        self.mode = controllers[0].mode
        self.n_joints = controllers[0].n_joints
        self.split = self.n_joints
        self.action_space = spaces.Box(
            np.concatenate([c.action_space.low for c in controllers]),
            np.concatenate([c.action_space.high for c in controllers]),
            (2 * self.n_joints,), np.float32)
        self.clip_low = np.concatenate([c.clip_low for c in controllers]).astype(np.float32)
        self.clip_high = np.concatenate([c.clip_high for c in controllers]).astype(np.float32)

    @property
    def setpoint_rad(self) -> np.ndarray:
        """Both robots' servo setpoints (a new array)."""
        return np.concatenate([c.setpoint_rad for c in self.controllers])

    def configure(self, model: mujoco.MjModel) -> None:
        self.controllers[0].configure(model)

    def bind(self, data: mujoco.MjData) -> None:
        for controller in self.controllers:
            controller.bind(data)

    def reset(self, data: mujoco.MjData, home_setpoints_rad: np.ndarray) -> None:
        for controller, home in zip(self.controllers, home_setpoints_rad, strict=True):
            controller.reset(data, home)

    def apply(self, action: np.ndarray, data: mujoco.MjData) -> None:
        """Write both robots' controls for a checked action (right half, then left)."""
        self.controllers[0].apply(action[:self.split], data)
        self.controllers[1].apply(action[self.split:], data)


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
