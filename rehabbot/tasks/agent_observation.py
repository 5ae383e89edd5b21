"""The agent's observation of the ``-v2`` ids: what a plain network needs in order to learn.

The paper's observation (:mod:`rehabbot.tasks.observation`) holds the targets and the current
joint angles side by side, in radians and metres with ranges of several units. A plain MLP has
to learn to subtract them before it can see that it is 0.04 rad from a target with a tolerance
of 0.05 rad, and it never does (0 % on the ``-v1`` ids). As dm_control's reacher observes
``to_target`` and MyoSuite's reach tasks observe ``reach_err``, the agent observation gives the
differences themselves, each scaled so that every entry lies in [-1, 1] (a few in [-2, 2]):

=====================  ================  ===================================================
field                  values            what
=====================  ================  ===================================================
``joint_error_fine``   n per arm         ``tanh((theta* - theta) / 0.05 rad)``: the tolerance
                                         is visible (0.76 at the tolerance)
``joint_error``        n per arm         ``tanh((theta* - theta) / 0.5 rad)``: direction and
                                         size of large errors
``tool_error_fine``    3 per arm         ``tanh((p* - p) / 0.05 m)``, robot base frame
``tool_error``         3 per arm         ``tanh((p* - p) / 0.2 m)``
``next_target``        n per arm         ``tanh((theta*_{i+1} - theta*_i) / 0.5 rad)``: where
                                         the target after the active one lies (0 at the last)
``setpoint_lead``      n per arm         ``tanh((setpoint - theta) / 0.05 rad)``: how far the
                                         servo setpoint leads the joint (the controller's
                                         state; 0 in ``torque`` mode, which has no setpoint)
``joint_velocity``     n per arm         ``tanh(dtheta/dt / 0.5 rad/s)``
``theta_in_bounds``    n per arm         theta relative to the setpoint bounds: -1 at the
                                         lower, +1 at the upper bound (clipped to [-2, 2])
``phi_in_range``       3 per arm         the patient's exercised joints relative to their
                                         range of motion: -1 / +1 at its ends (clipped to
                                         [-2, 2])
``cuff_force``         1 per arm         cuff force / its limit (the cuff-force rule fires
                                         above 1; clipped to [0, 2])
``exercise``           E                 the exercise, one-hot
``weight_level``       1                 ``l / 2 - 1``: -1 for level 0, +1 for level 4
``target_progress``    1                 ``2 i / (N - 1) - 1`` for the active target ``i`` of
                                         ``N``: +1 at the last target
=====================  ================  ===================================================

With two arms (the bilateral env) every per-arm field holds the right arm's values, then the
left arm's. ``n`` is the robot's number of joints (6 for the UR5e, 7 for the FR3), ``E`` the
number of exercises of the id. For one UR5e and two exercises the observation has 50 values.
"""

from __future__ import annotations

import numpy as np

from rehabbot.tasks.observation import ObservationField, ObservationLayout, paper_layout

JOINT_FINE_SCALE_RAD = 0.05  # the reaching tolerance: the feature reads 0.76 at it
JOINT_SCALE_RAD = 0.5  # a few key-pose spacings
TOOL_FINE_SCALE_M = 0.05
TOOL_SCALE_M = 0.2
NEXT_TARGET_SCALE_RAD = 0.5
SETPOINT_LEAD_SCALE_RAD = 0.05
JOINT_SPEED_SCALE_RAD_S = 0.5  # the joint_delta mode's setpoint moves at most pi/400 per 20 ms
RELATIVE_CLIP = 2.0  # the fields relative to a range are clipped to +-2 (twice the range)
FORCE_CLIP = 2.0
OBSERVATION_BOUND = 2.0  # every entry lies in [-2, 2]


def agent_layout(n_joints: int, n_arms: int, n_exercises: int) -> ObservationLayout:
    """The agent observation's fields (see the module docstring) for ``n_arms`` robots of
    ``n_joints`` joints and ``n_exercises`` exercises."""
    if n_arms not in (1, 2):
        raise ValueError(f"n_arms={n_arms!r} must be 1 or 2")
    if n_exercises < 1:
        raise ValueError(f"n_exercises={n_exercises!r} must be at least 1")
    joints, xyz, k = n_joints * n_arms, 3 * n_arms, n_arms
    return ObservationLayout((
        ObservationField("joint_error_fine", joints, "-", "joint",
                         f"tanh((theta* - theta) / {JOINT_FINE_SCALE_RAD} rad)"),
        ObservationField("joint_error", joints, "-", "joint",
                         f"tanh((theta* - theta) / {JOINT_SCALE_RAD} rad)"),
        ObservationField("tool_error_fine", xyz, "-", "robot base",
                         f"tanh((p* - p) / {TOOL_FINE_SCALE_M} m)"),
        ObservationField("tool_error", xyz, "-", "robot base",
                         f"tanh((p* - p) / {TOOL_SCALE_M} m)"),
        ObservationField("next_target", joints, "-", "joint",
                         f"tanh((theta*_next - theta*) / {NEXT_TARGET_SCALE_RAD} rad), 0 at "
                         "the last target"),
        ObservationField("setpoint_lead", joints, "-", "joint",
                         f"tanh((setpoint - theta) / {SETPOINT_LEAD_SCALE_RAD} rad), 0 in "
                         "torque mode"),
        ObservationField("joint_velocity", joints, "-", "joint",
                         f"tanh(joint velocity / {JOINT_SPEED_SCALE_RAD_S} rad/s)"),
        ObservationField("theta_in_bounds", joints, "-", "joint",
                         "robot joint angles: -1 / +1 at the setpoint bounds"),
        ObservationField("phi_in_range", xyz, "-", "joint",
                         "the patient's exercised joints: -1 / +1 at the ends of their range"),
        ObservationField("cuff_force", k, "-", "-", "cuff force / its limit"),
        ObservationField("exercise", n_exercises, "-", "-", "the exercise, one-hot"),
        ObservationField("weight_level", 1, "-", "-", "l / 2 - 1"),
        ObservationField("target_progress", 1, "-", "-", "2 i / (N - 1) - 1"),
    ))


def _scaled_range(low: np.ndarray, high: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    if low.shape != high.shape or not np.all(high > low):
        raise ValueError(f"{name}: every upper bound must exceed its lower bound, got "
                         f"{low.tolist()} and {high.tolist()}")
    return (high + low) / 2, (high - low) / 2


class AgentObservation:
    """The agent observation as one affine map: the matrix and the input layout with which the
    env computes it every step (:meth:`rehabbot.envs.core.RehabEnvCore._observation_out`):
    ``v = matrix @ [paper observation | next target | setpoints | joint velocities | cuff
    forces | 1]``, then ``tanh`` on ``v[:tanh_stop]`` and a clip of ``v[bounded]`` to
    ``[bounded_low, bounded_high]``; the one-hot exercise (``exercise_start + e``) and the
    ``target_progress`` entry (index ``progress``) are set from the episode's state. Every
    field but those two is such a map of the readings followed by ``tanh`` or a clip, so one
    matrix-vector product computes them all (a few microseconds a step).

    Args:
        n_joints, n_arms, n_exercises: the layout (:func:`agent_layout`).
        setpoint_low_rad, setpoint_high_rad: the setpoint bounds, ``n_joints * n_arms`` each.
        phi_low_rad, phi_high_rad: the exercised joints' range of motion, ``3 * n_arms`` each.
        force_limits_n: each cuff's force limit (``n_arms`` values).
        has_setpoints: False in ``torque`` mode (``setpoint_lead`` stays 0).
    """

    def __init__(self, n_joints: int, n_arms: int, n_exercises: int,
                 setpoint_low_rad: np.ndarray, setpoint_high_rad: np.ndarray,
                 phi_low_rad: np.ndarray, phi_high_rad: np.ndarray,
                 force_limits_n: np.ndarray, has_setpoints: bool = True) -> None:
        self.layout = agent_layout(n_joints, n_arms, n_exercises)
        self.paper_layout = paper_layout(n_joints, n_arms)
        self.n_exercises = n_exercises
        self.has_setpoints = has_setpoints
        joints = n_joints * n_arms
        self._theta_center, self._theta_half = _scaled_range(
            setpoint_low_rad, setpoint_high_rad, "setpoint bounds")
        # The input vector: [paper observation | next target | setpoints | joint velocities |
        # cuff forces | 1].
        size = self.paper_layout.size
        self.paper = slice(0, size)
        self.next = slice(size, size + joints)
        self.setpoint = slice(self.next.stop, self.next.stop + joints)
        self.velocity = slice(self.setpoint.stop, self.setpoint.stop + joints)
        self.forces = slice(self.velocity.stop, self.velocity.stop + n_arms)
        self.input = np.zeros(self.forces.stop + 1)
        self.input[-1] = 1.0
        out = self.layout
        self.tanh_stop = out.slice("joint_velocity").stop
        relative = slice(out.slice("theta_in_bounds").start, out.slice("phi_in_range").stop)
        # theta_in_bounds, phi_in_range and cuff_force lie side by side: one clip.
        self.bounded = slice(relative.start, out.slice("cuff_force").stop)
        n_relative = relative.stop - relative.start
        self.bounded_low = np.r_[np.full(n_relative, -RELATIVE_CLIP), np.zeros(n_arms)]
        self.bounded_high = np.r_[np.full(n_relative, RELATIVE_CLIP), np.full(n_arms,
                                                                              FORCE_CLIP)]
        self.exercise_start = out.slice("exercise").start
        self.progress = out.index("target_progress")
        self.matrix = np.zeros((out.size, self.input.size))
        self._fill_fixed_rows()
        self.set_patient(phi_low_rad, phi_high_rad, force_limits_n)

    def _rows(self, name: str) -> np.ndarray:
        return np.arange(self.layout.slice(name).start, self.layout.slice(name).stop)

    def _cols(self, name: str) -> np.ndarray:
        if name in ("next", "setpoint", "velocity", "forces"):
            part = getattr(self, name)
            return np.arange(part.start, part.stop)
        return np.arange(self.paper_layout.slice(name).start, self.paper_layout.slice(name).stop)

    def _difference(self, out: str, plus: str, minus: str, scale: float) -> None:
        rows, m = self._rows(out), self.matrix
        m[rows, self._cols(plus)] = 1.0 / scale
        m[rows, self._cols(minus)] = -1.0 / scale

    def _fill_fixed_rows(self) -> None:
        m, one = self.matrix, self.input.size - 1
        self._difference("joint_error_fine", "theta_star", "theta", JOINT_FINE_SCALE_RAD)
        self._difference("joint_error", "theta_star", "theta", JOINT_SCALE_RAD)
        self._difference("tool_error_fine", "p_star", "p", TOOL_FINE_SCALE_M)
        self._difference("tool_error", "p_star", "p", TOOL_SCALE_M)
        self._difference("next_target", "next", "theta_star", NEXT_TARGET_SCALE_RAD)
        if self.has_setpoints:
            self._difference("setpoint_lead", "setpoint", "theta", SETPOINT_LEAD_SCALE_RAD)
        m[self._rows("joint_velocity"), self._cols("velocity")] = 1.0 / JOINT_SPEED_SCALE_RAD_S
        rows = self._rows("theta_in_bounds")
        m[rows, self._cols("theta")] = 1.0 / self._theta_half
        m[rows, one] = -self._theta_center / self._theta_half
        level = self.layout.index("weight_level")
        m[level, self.paper_layout.index("l")] = 0.5
        m[level, one] = -1.0

    def set_patient(self, phi_low_rad: np.ndarray, phi_high_rad: np.ndarray,
                    force_limits_n: np.ndarray) -> None:
        """The patient-specific scales: the exercised joints' range and the cuff limits."""
        center, half = _scaled_range(phi_low_rad, phi_high_rad, "range of motion")
        limits = np.asarray(force_limits_n, dtype=float)
        if limits.shape != (self.forces.stop - self.forces.start,) or not np.all(limits > 0):
            raise ValueError(f"force_limits_n={limits.tolist()} must be one positive limit "
                             "per cuff")
        m, one, rows = self.matrix, self.input.size - 1, self._rows("phi_in_range")
        m[rows, self._cols("phi")] = 1.0 / half
        m[rows, one] = -center / half
        m[self._rows("cuff_force"), self._cols("forces")] = 1.0 / limits

    @property
    def space_bounds(self) -> tuple[float, float]:
        """The observation space's bounds: every entry lies in [-2, 2]."""
        return -OBSERVATION_BOUND, OBSERVATION_BOUND
