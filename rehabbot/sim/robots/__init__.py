"""Robots as plug-ins: each robot is a module that builds its arm in an ``MjSpec`` from
published parameters and describes itself with a :class:`RobotModel`.

Everything above the scene (controllers, observations, experts, metrics) reads the number of
joints, their names and their limits from the :class:`RobotModel` of the scene's robot, never
from a literal. A robot module provides:

* ``build(parent, spec, options, pos, quat)``: bodies ``{prefix}base``, ``{prefix}link1`` ...
  ``{prefix}link<n>``; hinge joints ``{prefix}<joint name>``; sites ``{prefix}tool`` (flange)
  and ``{prefix}cuff`` (cuff centre); per joint an impedance servo ``{prefix}<joint>_servo``
  (actuator group ``servo_group``) and a feed-forward motor ``{prefix}<joint>_motor`` (group
  ``motor_group``), the joint's total actuator torque clamped at its limit;
* an IK seed for a cuff position given in the robot's base frame.

=========== ====================== ===========================================================
name        module                 robot
=========== ====================== ===========================================================
``"ur5e"``  :mod:`.ur5e`            Universal Robots UR5e (6 joints), the paper's robot
``"fr3"``   :mod:`.fr3`             Franka Research 3 (7 joints)
=========== ====================== ===========================================================
"""

from __future__ import annotations

from rehabbot.sim.robots import fr3, ur5e
from rehabbot.sim.robots.base import ImpedanceGains, RobotBuildOptions, RobotModel

ROBOTS: dict[str, RobotModel] = {ur5e.UR5E.name: ur5e.UR5E, fr3.FR3.name: fr3.FR3}
ROBOT_NAMES: tuple[str, ...] = tuple(ROBOTS)


def get_robot(name: str) -> RobotModel:
    """The :class:`RobotModel` called ``name``; ``ValueError`` naming the valid robots."""
    if name not in ROBOTS:
        raise ValueError(f"robot={name!r} is not one of {list(ROBOTS)}")
    return ROBOTS[name]


__all__ = ["ROBOTS", "ROBOT_NAMES", "ImpedanceGains", "RobotBuildOptions", "RobotModel",
           "get_robot"]
