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

A robot of your own joins them without editing the package: :func:`register_robot` checks its
:class:`RobotModel` against the contract above (it builds and compiles the arm once) and adds
it to :data:`ROBOTS`, after which ``gym.make(..., robot="<name>")`` builds scenes with it in
this process (a ``--vec subproc`` worker or any other new process must register it again).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from typing import overload

import mujoco
import numpy as np

from rehabbot.sim.robots import bounds, fr3, ur5e
from rehabbot.sim.robots.base import ImpedanceGains, RobotBuildOptions, RobotModel

ROBOTS: dict[str, RobotModel] = {ur5e.UR5E.name: ur5e.UR5E, fr3.FR3.name: fr3.FR3}

ROBOT_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_]*$")
PLACEMENTS = ("arm", "leg_seated", "leg_supine")
# MuJoCo switches actuator groups off with a bit mask of an int (``opt.disableactuator``).
MAX_ACTUATOR_GROUP = 30
_CHECK_PREFIX = "chk_"  # the contract check builds the arm with this prefix
_CHECK_CUFF_M = np.array([0.3, -0.3, 0.2])  # a cuff position in the base frame for ik_seed


class _RobotNames(Sequence[str]):
    """The names in :data:`ROBOTS`, in order, as a live read-only sequence: a robot that
    :func:`register_robot` adds is in it at once, wherever it was imported."""

    @overload
    def __getitem__(self, index: int) -> str: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[str, ...]: ...

    def __getitem__(self, index: int | slice) -> str | tuple[str, ...]:
        return tuple(ROBOTS)[index]

    def __len__(self) -> int:
        return len(ROBOTS)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(ROBOTS))

    def __contains__(self, name: object) -> bool:
        return name in ROBOTS

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and tuple(self) == tuple(other)

    __hash__ = None  # type: ignore[assignment]  # it changes when a robot is registered

    def __repr__(self) -> str:
        return repr(tuple(ROBOTS))


ROBOT_NAMES: Sequence[str] = _RobotNames()


def get_robot(name: str) -> RobotModel:
    """The :class:`RobotModel` called ``name``; ``ValueError`` naming the valid robots."""
    if not isinstance(name, str) or name not in ROBOTS:
        raise ValueError(f"robot={name!r} is not one of {list(ROBOTS)}")
    return ROBOTS[name]


def register_robot(model: RobotModel, *, replace: bool = False) -> RobotModel:
    """Add ``model`` to :data:`ROBOTS` (and :data:`ROBOT_NAMES`) so that envs and scenes take
    ``robot=model.name``; returns it.

    The model is checked first (:func:`check_robot_model`: its fields, then its ``build``
    run once and compiled, then its ``ik_seed``; every physical quantity they set in its
    plausible range, :mod:`rehabbot.sim.robots.bounds`); a model that breaks the plug-in
    contract, or
    whose name is already registered (unless ``replace=True``), raises ``ValueError`` naming
    the problem and nothing is registered. Replacing a robot changes the scenes built after
    the call, never an env already built.
    """
    if not isinstance(model, RobotModel):
        raise ValueError(f"register_robot needs a RobotModel, got {type(model).__name__}")
    if not isinstance(replace, bool):
        raise ValueError(f"replace={replace!r} must be True or False")
    if model.name in ROBOTS and not replace:
        raise ValueError(f"robot {model.name!r} is already registered (registered: "
                         f"{list(ROBOTS)}); pick another name, or pass replace=True")
    check_robot_model(model)
    ROBOTS[model.name] = model
    return model


def check_robot_model(model: RobotModel) -> None:
    """``ValueError`` naming the first way ``model`` breaks the plug-in contract of the module
    docstring: its name and fields, then what its ``build`` adds to a spec (bodies, hinge
    joints with the model's ranges and torque clamps, the tool and cuff sites, the servo and
    motor of every joint in their groups), then what its ``ik_seed`` returns.

    Every physical quantity the model holds (torque limits, joint ranges and speeds, gains,
    stand offsets) or its build sets (masses, inertias, positions, sizes, joint limits,
    armature, damping, friction, actuator parameters; checked in the spec before compiling,
    the masses and inertias again after) must be finite and inside the range
    :mod:`rehabbot.sim.robots.bounds` gives with its reason; the build must leave the
    scene's physics options and compiler settings (timestep, gravity, angle unit, inertia
    rules) as it found them. The error names the
    robot, the element, the field and the value. Checking at registration runs the build
    once, when the user's own line registers the robot, and never lets a bad robot into
    :data:`ROBOTS`."""
    if not isinstance(model, RobotModel):
        raise ValueError(f"a robot must be a RobotModel, got {type(model).__name__}")
    name = model.name
    if not isinstance(name, str) or not ROBOT_NAME_RE.match(name):
        raise ValueError(f"robot name {name!r} must be lower-case letters, digits and '_', "
                         "starting with a letter or digit (it names files and zoo agents)")
    _check_fields(model)
    _check_build(model)
    _check_ik_seed(model)


def _fail(model: RobotModel, message: str) -> ValueError:
    return ValueError(f"robot {model.name!r} breaks the plug-in contract: {message}")


def _check_fields(model: RobotModel) -> None:
    n = model.n_joints
    if n < 1 or not all(isinstance(j, str) and j for j in model.joint_names):
        raise _fail(model, f"joint_names={model.joint_names!r} must be non-empty strings")
    if len(set(model.joint_names)) != n:
        raise _fail(model, f"joint_names={model.joint_names!r} must be unique")
    values = {"torque_limit_nm": model.torque_limit_nm,
              "max_joint_speed_rad_s": model.max_joint_speed_rad_s}
    for field_name, field_values in values.items():
        if not all(_positive(v) for v in field_values):
            raise _fail(model, f"{field_name}={field_values!r} must be finite values > 0")
    if not all(math.isfinite(float(v)) for pair in model.joint_range_rad for v in pair):
        raise _fail(model, f"joint_range_rad={model.joint_range_rad!r} must be finite")
    if not isinstance(model.default_gains, ImpedanceGains):
        raise _fail(model, f"default_gains={model.default_gains!r} must be ImpedanceGains")
    try:
        model.check_gains(model.default_gains)
    except ValueError as error:
        raise _fail(model, f"default_gains: {error}") from None
    gains = model.default_gains
    ranged = (("torque_limit_nm", model.torque_limit_nm, bounds.TORQUE),
              ("max_joint_speed_rad_s", model.max_joint_speed_rad_s, bounds.JOINT_SPEED),
              ("joint_range_rad", model.joint_range_rad, bounds.JOINT_LIMIT),
              ("default_gains.kp_nm_per_rad", gains.kp_nm_per_rad, bounds.STIFFNESS),
              ("default_gains.kv_nms_per_rad", gains.kv_nms_per_rad, bounds.DAMPING))
    for field_name, field_values, bound in ranged:
        problem = bounds.value_problem(field_name, field_values, bound)
        if problem is not None:
            raise _fail(model, problem)
    for field_name in ("build", "ik_seed"):
        if not callable(getattr(model, field_name)):
            raise _fail(model, f"{field_name}={getattr(model, field_name)!r} is not callable")
    groups = (model.servo_group, model.motor_group)
    if any(isinstance(g, bool) or not isinstance(g, int) or not 0 <= g <= MAX_ACTUATOR_GROUP
           for g in groups) or groups[0] == groups[1]:
        raise _fail(model, f"servo_group={model.servo_group!r} and motor_group="
                           f"{model.motor_group!r} must be two different integers in "
                           f"[0, {MAX_ACTUATOR_GROUP}]")
    cuffed = model.cuffed_links
    if isinstance(cuffed, bool) or not isinstance(cuffed, int) or not 1 <= cuffed <= n:
        raise _fail(model, f"cuffed_links={cuffed!r} must be an integer in [1, {n}]")
    for entry in model.base_offset_m:
        ok = (isinstance(entry, tuple) and len(entry) == 2 and entry[0] in PLACEMENTS
              and isinstance(entry[1], Sequence) and len(entry[1]) == 3
              and all(_real(v) for v in entry[1]))
        if not ok:
            raise _fail(model, f"base_offset_m entry {entry!r} must be (placement, (x, y, z)) "
                               f"with a placement in {list(PLACEMENTS)}")
        problem = bounds.value_problem(f"base_offset_m[{entry[0]!r}]", entry[1], bounds.LENGTH)
        if problem is not None:
            raise _fail(model, problem)


def _real(value: object) -> bool:
    return isinstance(value, (int, float, np.number)) and not isinstance(value, bool)


def _positive(value: object) -> bool:
    return (isinstance(value, (int, float, np.number)) and not isinstance(value, bool)
            and math.isfinite(float(value)) and float(value) > 0)


def _check_build(model: RobotModel) -> None:
    p = _CHECK_PREFIX
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = 0.002
    settings = _scene_settings(spec)
    try:
        model.build(spec.worldbody, spec, RobotBuildOptions(prefix=p),
                    pos=np.array([0.1, 0.2, 0.5]), quat=np.array([1.0, 0.0, 0.0, 0.0]))
    except Exception as error:  # any failure of foreign code: named, with its cause
        raise _fail(model, f"build(parent, spec, options, pos, quat) failed: "
                           f"{type(error).__name__}: {error}") from error
    for problem in bounds.spec_problems(spec, p):
        raise _fail(model, f"build sets {problem}")
    changed = {name: value for name, value in _scene_settings(spec).items()
               if value != settings[name]}
    if changed:
        raise _fail(model, f"build changes the scene's settings {changed} (spec.option and "
                           "spec.compiler belong to the scene, not to a robot)")
    try:
        compiled = spec.compile()
    except Exception as error:  # any failure of foreign code: named, with its cause
        raise _fail(model, f"build(parent, spec, options, pos, quat) gives a spec that does "
                           f"not compile: {type(error).__name__}: {error}") from error
    for problem in bounds.model_problems(compiled, p):
        raise _fail(model, f"build gives {problem}")

    def find(kind: str, name: str):
        try:
            return getattr(compiled, kind)(name)
        except KeyError:
            raise _fail(model, f"build adds no {kind} {name!r} (with the prefix "
                               f"{p!r} of RobotBuildOptions)") from None

    for link in model.link_names:
        find("body", f"{p}{link}")
    for site in ("tool", "cuff"):
        find("site", f"{p}{site}")
    for j, joint_name in enumerate(model.joint_names):
        joint = find("joint", f"{p}{joint_name}")
        jid = joint.id
        if compiled.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise _fail(model, f"joint {joint_name!r} must be a hinge")
        low, high = model.joint_range_rad[j]
        if not compiled.jnt_limited[jid] or not np.allclose(compiled.jnt_range[jid],
                                                            [low, high], atol=1e-9):
            raise _fail(model, f"joint {joint_name!r} has range "
                               f"{compiled.jnt_range[jid].tolist()} rad in the built arm, but "
                               f"joint_range_rad says {[low, high]}")
        limit = model.torque_limit_nm[j]
        if not compiled.jnt_actfrclimited[jid] or not np.allclose(
                compiled.jnt_actfrcrange[jid], [-limit, limit], rtol=1e-9):
            raise _fail(model, f"joint {joint_name!r} clamps its actuator torque at "
                               f"{compiled.jnt_actfrcrange[jid].tolist()} N·m in the built arm "
                               f"(jnt_actfrcrange), but torque_limit_nm says +-{limit}; build "
                               "must clamp each joint at the model's limit")
        for role, group in (("servo", model.servo_group), ("motor", model.motor_group)):
            actuator = find("actuator", f"{p}{joint_name}_{role}")
            aid = actuator.id
            if (compiled.actuator_trntype[aid] != mujoco.mjtTrn.mjTRN_JOINT
                    or compiled.actuator_trnid[aid, 0] != jid):
                raise _fail(model, f"actuator {joint_name}_{role} must act on joint "
                                   f"{joint_name!r}")
            if compiled.actuator_group[aid] != group:
                raise _fail(model, f"actuator {joint_name}_{role} is in group "
                                   f"{compiled.actuator_group[aid]}, not {role}_group={group}")


# The scene's settings a robot's build must leave alone: its physics options and how its
# compiler reads angles and inertias (they hold for the patient's bodies too).
_SCENE_SETTINGS = (("option", ("timestep", "gravity", "wind", "magnetic", "density",
                               "viscosity", "integrator", "impratio", "o_margin")),
                   ("compiler", ("degree", "autolimits", "inertiafromgeom",
                                 "inertiagrouprange", "boundmass", "boundinertia",
                                 "settotalmass", "balanceinertia", "alignfree")))


def _scene_settings(spec: mujoco.MjSpec) -> dict[str, object]:
    return {f"spec.{part}.{name}": np.array(getattr(getattr(spec, part), name),
                                            dtype=float).tolist()
            for part, names in _SCENE_SETTINGS for name in names}


def _check_ik_seed(model: RobotModel) -> None:
    try:
        seed = np.asarray(model.ik_seed(_CHECK_CUFF_M.copy()), dtype=float)
    except Exception as error:  # any failure of foreign code: named, with its cause
        raise _fail(model, f"ik_seed(cuff_in_base_m) failed: {type(error).__name__}: "
                           f"{error}") from error
    n = model.n_joints
    if seed.shape[-1:] != (n,) or seed.ndim not in (1, 2) or seed.size == 0 \
            or not np.all(np.isfinite(seed)):
        raise _fail(model, f"ik_seed must return {n} finite joint angles (or rows of {n}), "
                           f"got an array of shape {seed.shape}")


__all__ = ["ROBOTS", "ROBOT_NAMES", "ImpedanceGains", "RobotBuildOptions", "RobotModel",
           "check_robot_model", "get_robot", "register_robot"]
