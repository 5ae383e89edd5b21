"""The interface every robot backend implements: state, command, stop, healthy.

A backend is a robot (simulated or real) that accepts joint-position targets at the policy's
control rate and reports its state. The deployment loop (:mod:`rehabbot.deploy.session`) and
the calibration protocol (:mod:`rehabbot.deploy.calibration`) talk to a backend only through
:class:`RobotBackend`, so that the same loop drives the simulator, a Franka or a UR.

=================  ==========================================================================
member             meaning
=================  ==========================================================================
``joint_names``    the robot's joints, in the order of every array below
``control_dt_s``   seconds between two ``command`` calls (the policy's decision period)
``state()``        the latest :class:`RobotState` (a copy)
``command(q)``     move toward the joint positions ``q`` [rad] during the next period
``stop()``         stop the robot now (hold position, brakes where the robot has them); every
                   later ``command`` is refused until the backend is made again
``healthy()``      False once the robot stopped, faulted or its connection was lost
=================  ==========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

#: The backends ``rehabbot deploy`` drives: the simulator, a Franka (pylibfranka), a UR
#: (ur_rtde).
BACKENDS = ("sim", "franka", "ur")


@dataclass(frozen=True)
class RobotState:
    """What a backend reports at one instant. Arrays are float64 copies.

    ``patient_q_rad`` and ``patient_dq_rad_s`` are the exercised patient joints (the env's
    ``theta`` order) where the backend can measure or estimate them; ``cuff_force_n`` the
    magnitude of the force in the cuff [N] (NaN where the robot has no force estimate).
    """

    time_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    cuff_force_n: float = float("nan")
    patient_q_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    patient_dq_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(0))


@runtime_checkable
class RobotBackend(Protocol):
    """A robot the deployment loop can drive (module docstring)."""

    joint_names: tuple[str, ...]
    control_dt_s: float

    def state(self) -> RobotState: ...

    def command(self, q_target_rad: np.ndarray) -> None: ...

    def stop(self) -> None: ...

    def healthy(self) -> bool: ...
