"""The description every robot module provides: :class:`RobotModel`, its build options
and its impedance gains (see :mod:`rehabbot.sim.robots`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np


@dataclass(frozen=True)
class ImpedanceGains:
    """Joint impedance of the servo actuators, one value per joint (SI units)."""

    kp_nm_per_rad: tuple[float, ...]
    kv_nms_per_rad: tuple[float, ...]

    def __post_init__(self) -> None:
        for name in ("kp_nm_per_rad", "kv_nms_per_rad"):
            values = np.asarray(getattr(self, name), dtype=float)
            if values.ndim != 1 or not np.all(np.isfinite(values)) or np.any(values < 0):
                raise ValueError(f"ImpedanceGains.{name} must be finite values >= 0, got "
                                 f"{getattr(self, name)!r}")
        if len(self.kp_nm_per_rad) != len(self.kv_nms_per_rad):
            raise ValueError(f"ImpedanceGains: {len(self.kp_nm_per_rad)} stiffnesses but "
                             f"{len(self.kv_nms_per_rad)} dampings")


@dataclass(frozen=True)
class RobotBuildOptions:
    """How to build one robot in a scene.

    ``cuff_offset_m`` is the distance along the flange's z axis from the flange to the centre
    of the cuff that holds the patient's wrist or ankle; ``gains=None`` takes the robot's own.
    """

    prefix: str = ""
    gains: ImpedanceGains | None = None
    cuff_offset_m: float = 0.09
    cuff_radius_m: float = 0.05


@dataclass(frozen=True)
class RobotModel:
    """What the rest of RehabBot needs to know about a robot (joint order = action order)."""

    name: str
    joint_names: tuple[str, ...]
    torque_limit_nm: tuple[float, ...]
    joint_range_rad: tuple[float, ...]  # symmetric hardware range: [-r, r] per joint
    default_gains: ImpedanceGains
    build: Callable[..., mujoco.MjsBody] = field(compare=False, repr=False)
    ik_seed: Callable[[np.ndarray], np.ndarray] = field(compare=False, repr=False)
    servo_group: int = 1
    motor_group: int = 2

    @property
    def n_joints(self) -> int:
        """Number of actuated joints (the length of an action)."""
        return len(self.joint_names)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Bodies of the arm, base first (without prefix)."""
        return ("base", *(f"link{i}" for i in range(1, self.n_joints + 1)))

    def torque_limits(self) -> np.ndarray:
        """Per-joint torque limits [N·m] as a new array."""
        return np.array(self.torque_limit_nm, dtype=float)

    def check_gains(self, gains: ImpedanceGains) -> None:
        """``ValueError`` unless ``gains`` has one value per joint."""
        if len(gains.kp_nm_per_rad) != self.n_joints:
            raise ValueError(f"gains for {self.name} need {self.n_joints} values per joint, "
                             f"got {len(gains.kp_nm_per_rad)}")

