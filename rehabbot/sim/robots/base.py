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
    """What the rest of RehabBot needs to know about a robot (joint order = action order).

    ``joint_range_rad`` is each joint's hardware range as ``(low, high)`` (asymmetric for some
    robots); ``max_joint_speed_rad_s`` each joint's rated speed. ``base_offset_m`` moves the
    robot's stand from the scene's default placement (the one the UR5e was fitted to), per
    placement (``"arm"``, ``"leg_seated"``, ``"leg_supine"``), in the patient's mirror-symmetric
    frame: (along the room's x axis, which is forward for a seated patient and towards the feet
    for a supine one; outwards, away from the patient's midline; up) [m], so that one offset
    serves the right and the left side. ``cuffed_links`` is how many of the last links carry
    the wrist around the cuff (they never collide with the strapped segment).
    """

    name: str
    joint_names: tuple[str, ...]
    torque_limit_nm: tuple[float, ...]
    joint_range_rad: tuple[tuple[float, float], ...]
    max_joint_speed_rad_s: tuple[float, ...]
    default_gains: ImpedanceGains
    build: Callable[..., mujoco.MjsBody] = field(compare=False, repr=False)
    ik_seed: Callable[[np.ndarray], np.ndarray] = field(compare=False, repr=False)
    servo_group: int = 1
    motor_group: int = 2
    base_offset_m: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    cuffed_links: int = 3

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        for name in ("torque_limit_nm", "joint_range_rad", "max_joint_speed_rad_s"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"RobotModel {self.name!r}: {name} needs {n} values")
        if any(not low < high for low, high in self.joint_range_rad):
            raise ValueError(f"RobotModel {self.name!r}: joint_range_rad needs low < high")

    @property
    def n_joints(self) -> int:
        """Number of actuated joints (the length of an action)."""
        return len(self.joint_names)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Bodies of the arm, base first (without prefix)."""
        return ("base", *(f"link{i}" for i in range(1, self.n_joints + 1)))

    @property
    def max_speed_rad_s(self) -> float:
        """The speed every joint can reach [rad/s]: the slowest joint's rated speed."""
        return float(min(self.max_joint_speed_rad_s))

    def torque_limits(self) -> np.ndarray:
        """Per-joint torque limits [N·m] as a new array."""
        return np.array(self.torque_limit_nm, dtype=float)

    def joint_low_rad(self) -> np.ndarray:
        """Lower ends of the joints' hardware ranges [rad] as a new array."""
        return np.array([low for low, _ in self.joint_range_rad], dtype=float)

    def joint_high_rad(self) -> np.ndarray:
        """Upper ends of the joints' hardware ranges [rad] as a new array."""
        return np.array([high for _, high in self.joint_range_rad], dtype=float)

    def base_offset(self, placement: str) -> np.ndarray:
        """The stand's offset for ``placement`` (zero if the robot names none) [m]."""
        return np.array(dict(self.base_offset_m).get(placement, (0.0, 0.0, 0.0)), dtype=float)

    def check_gains(self, gains: ImpedanceGains) -> None:
        """``ValueError`` unless ``gains`` has one value per joint."""
        if len(gains.kp_nm_per_rad) != self.n_joints:
            raise ValueError(f"gains for {self.name} need {self.n_joints} values per joint, "
                             f"got {len(gains.kp_nm_per_rad)}")
