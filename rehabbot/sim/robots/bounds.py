"""The plausible range of every physical quantity a robot plug-in sets, and the checks that
refuse a value outside it (:func:`rehabbot.sim.robots.check_robot_model` runs them).

A robot here is an arm that can be strapped to a patient's wrist or ankle: a collaborative arm
of a few kilograms per link, reaching under two metres, with joint torques of tens to hundreds
of N·m (the UR5e: 150 / 28 N·m, links of 0.4–8.1 kg, 0.85 m reach; the FR3: 87 / 12 N·m,
links of 0.6–2.9 kg, 0.86 m reach). Each range is generous around that (about ten times the
largest value either shipped robot has) so that any real arm passes, and tight enough to
catch a NaN, an infinity, a placeholder such as 1e9 and the common unit slips (grams, or
millimetres, or N·mm, or degrees typed as kilograms, metres, N·m or radians).

=================== ================== ===========================================
quantity            range              why
=================== ================== ===========================================
mass                0 .. 100 kg        a link weighs kilograms (UR5e's heaviest
                                       8.06 kg); a 100 g link typed in grams is over
principal inertia   0 .. 100 kg·m²     100 kg at a 1 m radius of gyration (UR5e's
                                       largest 0.33)
length              -2 .. 2 m          a link, offset, geom or site of an arm that
                                       reaches under 2 m (UR5e's longest link
                                       0.425 m); also the stand's offset from its
                                       fitted placement (beyond it the arm cannot
                                       reach the limb); a 2 mm length typed in
                                       millimetres is over
joint limit         -4π .. 4π rad      two turns each way (multi-turn joints are
                                       rated ±2π)
joint speed         0 .. 4π rad/s      two turns a second (cobot joints are rated up
                                       to 2π rad/s); 180 deg/s typed as rad/s is over
torque limit        0 .. 2000 N·m      over ten times the UR5e's 150 N·m; 150 N·m
                                       typed in N·mm is over
stiffness           0 .. 1e5 N·m/rad   servo gain or joint spring: 60 times the
                                       UR5e's 1500 N·m/rad; beyond it a wrist's
                                       servo (about 0.05 kg·m²) rings faster than
                                       the 2 ms step resolves
damping             0 .. 1e4 N·m·s/rad 60 times the UR5e's servo damping of 150
armature            0 .. 10 kg·m²      reflected rotor inertia (the shipped robots:
                                       0.05–0.1)
friction loss       0 .. 2000 N·m      a dry friction below the torque limit's bound
gravity comp.       0 .. 1             a fraction of the body's weight
geom density        0 .. 1e5 kg/m³     over four times the densest metal (osmium,
                                       2.26e4 kg/m³)
geom friction       0 .. 10            sliding rubber on steel is about 1
actuator parameter  -1e5 .. 1e5        a gain, bias, gear, control or force range: a
                                       stiffness, damping, setpoint [rad] or torque
                                       [N·m], each bounded above
orientation         finite             quaternions and axes (MuJoCo normalises them)
=================== ================== ===========================================

Values are checked where the build writes them (the ``MjSpec`` elements, before compiling, so
that a NaN is named rather than failing in MuJoCo's compiler) and the masses and inertias again
in the compiled model (they may come from geoms); ``RobotModel``'s own numbers (torque limits,
joint ranges, speeds, gains, stand offsets) against the same ranges.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class Bound:
    """The range ``[low, high]`` (in ``unit``) of one kind of physical quantity, and why."""

    quantity: str
    unit: str
    low: float
    high: float
    reason: str

    def describe(self) -> str:
        """The rule as a sentence part: ``"finite, in [0, 100] kg (why)"``."""
        unit = f" {self.unit}" if self.unit else ""
        if math.isinf(self.low) and math.isinf(self.high):
            return f"finite ({self.reason})"
        return f"finite, in [{self.low:g}, {self.high:g}]{unit} ({self.reason})"

    def first_bad(self, values: object) -> float | None:
        """The first value outside the range (NaN and infinities included), or ``None``."""
        array = np.asarray(values, dtype=float).ravel()
        for value in array.tolist():
            if not (math.isfinite(value) and self.low <= value <= self.high):
                return value
        return None


MASS = Bound("mass", "kg", 0.0, 100.0, "a link of an arm weighs kilograms")
INERTIA = Bound("inertia", "kg·m²", 0.0, 100.0, "100 kg at a 1 m radius of gyration")
LENGTH = Bound("length", "m", -2.0, 2.0, "an arm reaching under 2 m")
JOINT_LIMIT = Bound("joint limit", "rad", -4 * math.pi, 4 * math.pi, "two turns each way")
JOINT_SPEED = Bound("joint speed", "rad/s", 0.0, 4 * math.pi, "two turns a second")
TORQUE = Bound("torque", "N·m", 0.0, 2000.0, "over ten times the UR5e's 150 N·m")
STIFFNESS = Bound("stiffness", "N·m/rad", 0.0, 1e5, "60 times the UR5e's servo stiffness")
DAMPING = Bound("damping", "N·m·s/rad", 0.0, 1e4, "60 times the UR5e's servo damping")
ARMATURE = Bound("armature", "kg·m²", 0.0, 10.0, "a reflected rotor inertia")
FRICTION_LOSS = Bound("friction loss", "N·m", 0.0, 2000.0, "below the torque limit's bound")
GRAVCOMP = Bound("gravity compensation", "", 0.0, 1.0, "a fraction of the body's weight")
DENSITY = Bound("density", "kg/m³", 0.0, 1e5, "over four times the densest metal")
FRICTION = Bound("friction coefficient", "", 0.0, 10.0, "rubber on steel is about 1")
ACTUATOR = Bound("actuator parameter", "", -1e5, 1e5,
                 "a stiffness, damping, setpoint or torque, each bounded above")
INERTIA_PRODUCT = Bound("product of inertia", "kg·m²", -100.0, 100.0,
                        "bounded as the moments are")
ORIENTATION = Bound("orientation", "", -math.inf, math.inf, "MuJoCo normalises it")

# What a build may set, per kind of MjSpec element: (attribute, bound, which entries). An
# attribute in UNSET_BY_NAN whose first entry is NaN is not given (MuJoCo's mark for "not
# given"), and skipped.
SPEC_FIELDS: dict[str, tuple[tuple[str, Bound, slice], ...]] = {
    "body": (("mass", MASS, slice(None)), ("inertia", INERTIA, slice(None)),
             ("fullinertia", INERTIA, slice(0, 3)),
             ("fullinertia", INERTIA_PRODUCT, slice(3, 6)), ("pos", LENGTH, slice(None)),
             ("ipos", LENGTH, slice(None)), ("quat", ORIENTATION, slice(None)),
             ("iquat", ORIENTATION, slice(None)), ("gravcomp", GRAVCOMP, slice(None))),
    "joint": (("pos", LENGTH, slice(None)), ("axis", ORIENTATION, slice(None)),
              ("range", JOINT_LIMIT, slice(None)), ("armature", ARMATURE, slice(None)),
              ("damping", DAMPING, slice(None)), ("frictionloss", FRICTION_LOSS, slice(None)),
              ("stiffness", STIFFNESS, slice(None)), ("springref", JOINT_LIMIT, slice(None)),
              ("actfrcrange", ACTUATOR, slice(None))),
    "geom": (("size", LENGTH, slice(None)), ("pos", LENGTH, slice(None)),
             ("fromto", LENGTH, slice(None)), ("quat", ORIENTATION, slice(None)),
             ("mass", MASS, slice(None)), ("density", DENSITY, slice(None)),
             ("friction", FRICTION, slice(None))),
    "site": (("size", LENGTH, slice(None)), ("pos", LENGTH, slice(None)),
             ("quat", ORIENTATION, slice(None))),
    "actuator": (("gear", ACTUATOR, slice(None)), ("gainprm", ACTUATOR, slice(0, 3)),
                 ("biasprm", ACTUATOR, slice(0, 3)), ("ctrlrange", ACTUATOR, slice(None)),
                 ("forcerange", ACTUATOR, slice(None))),
}
UNSET_BY_NAN = frozenset({("geom", "mass"), ("geom", "fromto"), ("body", "fullinertia"),
                          ("body", "ipos")})
_SPEC_LISTS = {"body": "bodies", "joint": "joints", "geom": "geoms", "site": "sites",
               "actuator": "actuators"}
# What compiling may derive from geoms (a body without explicit inertial): per body.
MODEL_FIELDS: tuple[tuple[str, str, Bound], ...] = (("mass", "body_mass", MASS),
                                                   ("inertia", "body_inertia", INERTIA))


def spec_problems(spec: mujoco.MjSpec, prefix: str) -> Iterable[str]:
    """Each value that a build wrote into the elements of ``spec`` (a spec holding only the
    robot: every element but the world body) outside its :data:`SPEC_FIELDS` range, as
    ``"body 'link2' mass = nan kg is out of range: ..."`` (names without ``prefix``)."""
    for kind, fields in SPEC_FIELDS.items():
        elements = getattr(spec, _SPEC_LISTS[kind])
        for index, element in enumerate(elements[1:] if kind == "body" else elements):
            name = _shown_name(element.name, prefix, index)
            for attribute, bound, entries in fields:
                values = np.array(getattr(element, attribute), dtype=float, ndmin=1)
                if (kind, attribute) in UNSET_BY_NAN and math.isnan(float(values[0])):
                    continue
                values = values[entries]
                bad = bound.first_bad(values)
                if bad is not None:
                    yield _problem(f"{kind} {name} {attribute}", values, bad, bound)


def model_problems(model: mujoco.MjModel, prefix: str) -> Iterable[str]:
    """Each compiled body mass or principal inertia of ``model`` (a model holding only the
    robot) outside its range (:data:`MODEL_FIELDS`; they may come from the geoms'
    densities)."""
    for body_id in range(1, model.nbody):
        name = _shown_name(model.body(body_id).name, prefix, body_id - 1)
        for quantity, array, bound in MODEL_FIELDS:
            values = np.array(getattr(model, array)[body_id], dtype=float, ndmin=1)
            bad = bound.first_bad(values)
            if bad is not None:
                yield _problem(f"body {name} compiled {quantity}", values, bad, bound)


def _shown_name(name: str, prefix: str, index: int) -> str:
    if not name:
        return f"#{index} (unnamed)"
    return repr(name[len(prefix):] if name.startswith(prefix) else name)


def value_problem(field: str, values: object, bound: Bound) -> str | None:
    """``"field = values is out of range: ..."`` if a value of ``values`` (a number or
    nested numbers) is outside ``bound``; ``None`` if all are inside."""
    array = np.asarray(values, dtype=float)
    bad = bound.first_bad(array)
    return None if bad is None else _problem(field, array, bad, bound)


def _problem(what: str, values: np.ndarray, bad: float, bound: Bound) -> str:
    unit = f" {bound.unit}" if bound.unit else ""
    shown = (f"{values.item()!r}{unit}" if values.size == 1
             else f"{values.tolist()!r}, whose {bad!r}{unit}")
    return f"{what} = {shown} is out of range: {bound.quantity} must be {bound.describe()}"
