"""The work meters: the mechanical work done on the limb by the robot, through each cuff, and by
the patient, through its joint torques, each also as positive work only, and the assistance
ratio (the robot's share of the positive work).

Work is counted per physics step. A vector (a cuff's force and position, a world's joint
torques and angles) is passed as the sequence of its components, each a float or an array of
any batch shape: one world's tuple or list of floats, or ``xp.unstack(array, axis=-1)`` of an
array whose last axis holds them. Its products are summed in the components' order.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType
from typing import Any

Array = Any  # a float, a NumPy array or a JAX array


def joint_work_j(torque_nm: Sequence[Array], before_rad: Sequence[Array],
                 after_rad: Sequence[Array]) -> Array:
    """The work [J] of joint torques held over a physics step while the joints move from
    ``before_rad`` to ``after_rad``: ``sum_j torque_j (after_j - before_j)``."""
    work = 0.0
    for torque, before, after in zip(torque_nm, before_rad, after_rad, strict=True):
        work = work + torque * (after - before)
    return work


def cuff_work_j(constraint_force_n: Sequence[Array], before_m: Sequence[Array],
                after_m: Sequence[Array]) -> Array:
    """The robot's work [J] on the limb through a cuff over a physics step: the force on the
    limb is minus the cuff's constraint force ``constraint_force_n`` (that of the step before),
    the displacement that of the patient's cuff site from ``before_m`` to ``after_m``:
    ``f_x (before_x - after_x) + f_y (...) + f_z (...)``."""
    fx, fy, fz = constraint_force_n
    bx, by, bz = before_m
    ax, ay, az = after_m
    return fx * (bx - ax) + fy * (by - ay) + fz * (bz - az)


def accumulate_work(xp: ModuleType, total_j: Array, positive_j: Array,
                    work_j: Array) -> tuple[Array, Array]:
    """A meter's total and positive work after one physics step's ``work_j``: the positive
    work grows by ``work_j`` where it is positive (a NaN adds nothing)."""
    return total_j + work_j, positive_j + xp.where(work_j > 0.0, work_j, 0.0)


def assistance_ratio(xp: ModuleType, robot_positive_j: Array, patient_positive_j: Array) -> Array:
    """The robot's share of all positive work on the limb, ``robot / (robot + patient)``; 1.0
    until the patient has done positive work (the robot carries the limb)."""
    patient_works = patient_positive_j > 0.0
    total = xp.where(patient_works, robot_positive_j + patient_positive_j, 1.0)
    return xp.where(patient_works, robot_positive_j / total, 1.0)
