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
    """Builds the agent observation from the paper's observation and a few more readings of
    the state (one preallocated vector; :meth:`__call__` allocates only its returned copy).

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
        self.paper = paper_layout(n_joints, n_arms)
        self.n_exercises = n_exercises
        self.has_setpoints = has_setpoints
        self._theta_center, self._theta_half = _scaled_range(
            setpoint_low_rad, setpoint_high_rad, "setpoint bounds")
        self.set_patient(phi_low_rad, phi_high_rad, force_limits_n)
        p, a = self.paper, self.layout
        self._in = {name: p.slice(name) for name in p.names}
        self._e, self._l = p.index("e"), p.index("l")
        self._out = {name: a.slice(name) for name in a.names}
        self._vector = np.zeros(a.size, np.float64)
        self._zeros = np.zeros(n_joints * n_arms)

    def set_patient(self, phi_low_rad: np.ndarray, phi_high_rad: np.ndarray,
                    force_limits_n: np.ndarray) -> None:
        """The patient-specific scales: the exercised joints' range and the cuff limits."""
        self._phi_center, self._phi_half = _scaled_range(phi_low_rad, phi_high_rad,
                                                         "range of motion")
        limits = np.asarray(force_limits_n, dtype=float)
        if not np.all(limits > 0):
            raise ValueError(f"force_limits_n={limits.tolist()} must be positive")
        self._inverse_limits = 1.0 / limits

    @property
    def space_bounds(self) -> tuple[float, float]:
        """The observation space's bounds: every entry lies in [-2, 2]."""
        return -OBSERVATION_BOUND, OBSERVATION_BOUND

    def __call__(self, paper_obs: np.ndarray, next_target_rad: np.ndarray | None,
                 setpoint_rad: np.ndarray, joint_velocity_rad_s: np.ndarray,
                 cuff_forces_n: np.ndarray, target_index: int, num_targets: int) -> np.ndarray:
        """The agent observation (float32, a new array).

        Args:
            paper_obs: the paper's observation of the state (:mod:`rehabbot.tasks.observation`).
            next_target_rad: the robot joint target after the active one, or None at the last.
            setpoint_rad: the servo setpoints (ignored without setpoints).
            joint_velocity_rad_s: the robot joints' velocities (non-finite values read as 0:
                an unstable step keeps a finite observation).
            cuff_forces_n: each cuff's force.
            target_index, num_targets: the active target and how many the exercise has.
        """
        src, out, v = self._in, self._out, self._vector
        obs = paper_obs.astype(np.float64)
        theta_star, theta = obs[src["theta_star"]], obs[src["theta"]]
        joint_error = theta_star - theta
        tool_error = obs[src["p_star"]] - obs[src["p"]]
        v[out["joint_error_fine"]] = joint_error / JOINT_FINE_SCALE_RAD
        v[out["joint_error"]] = joint_error / JOINT_SCALE_RAD
        v[out["tool_error_fine"]] = tool_error / TOOL_FINE_SCALE_M
        v[out["tool_error"]] = tool_error / TOOL_SCALE_M
        v[out["next_target"]] = (self._zeros if next_target_rad is None else
                                 (next_target_rad - theta_star) / NEXT_TARGET_SCALE_RAD)
        v[out["setpoint_lead"]] = ((setpoint_rad - theta) / SETPOINT_LEAD_SCALE_RAD
                                   if self.has_setpoints else self._zeros)
        velocity = np.asarray(joint_velocity_rad_s, dtype=float)
        if not np.isfinite(velocity).all():
            velocity = np.where(np.isfinite(velocity), velocity, 0.0)
        v[out["joint_velocity"]] = velocity / JOINT_SPEED_SCALE_RAD_S
        np.tanh(v[:out["joint_velocity"].stop], out=v[:out["joint_velocity"].stop])
        v[out["theta_in_bounds"]] = (theta - self._theta_center) / self._theta_half
        v[out["phi_in_range"]] = (obs[src["phi"]] - self._phi_center) / self._phi_half
        relative = slice(out["theta_in_bounds"].start, out["phi_in_range"].stop)
        np.clip(v[relative], -RELATIVE_CLIP, RELATIVE_CLIP, out=v[relative])
        forces = np.asarray(cuff_forces_n, dtype=float) * self._inverse_limits
        v[out["cuff_force"]] = np.clip(np.nan_to_num(forces, nan=FORCE_CLIP), 0.0, FORCE_CLIP)
        one_hot = v[out["exercise"]]
        one_hot[:] = 0.0
        one_hot[int(paper_obs[self._e])] = 1.0
        v[out["weight_level"]] = float(paper_obs[self._l]) / 2.0 - 1.0
        v[out["target_progress"]] = (2.0 * target_index / (num_targets - 1) - 1.0
                                     if num_targets > 1 else 1.0)
        return v.astype(np.float32)
