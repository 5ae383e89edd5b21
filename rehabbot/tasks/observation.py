"""The observation as a named layout: which fields, in which order, with units and frames.

The paper's observation (Sec. 3.2) is 23 values for a 6-joint robot, in this order:

======  ==============  ===================================================  ======  =========
index   field           what                                                 unit    frame
======  ==============  ===================================================  ======  =========
0-5     ``theta_star``  target robot joint angles theta*                     rad     joint
6-8     ``p_star``      target tool (flange) position p* (x, y, z)           m       robot base
9-14    ``theta``       robot joint angles theta                             rad     joint
15-17   ``p``           tool (flange) position p                             m       robot base
18-20   ``phi``         the patient's exercised joints, flexion positive     rad     joint
21      ``e``           exercise index                                       -       -
22      ``l``           weight level                                         -       -
======  ==============  ===================================================  ======  =========

For a robot with ``n`` joints the joint fields have ``n`` values (``2 n + 11`` in all). A later
env version adds a field by appending an :class:`ObservationField` to its layout and giving
the env a source for it; the fields above and their order never change for the ``-v0`` ids.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ObservationField:
    """One named block of the observation vector."""

    name: str
    size: int
    unit: str
    frame: str
    description: str


@dataclass(frozen=True)
class ObservationLayout:
    """An ordered set of :class:`ObservationField` with their positions in the vector."""

    fields: tuple[ObservationField, ...]
    _starts: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        starts, offset = {}, 0
        for f in self.fields:
            if f.name in starts:
                raise ValueError(f"observation field {f.name!r} appears twice")
            if f.size < 1:
                raise ValueError(f"observation field {f.name!r} has size {f.size}")
            starts[f.name] = offset
            offset += f.size
        object.__setattr__(self, "_starts", starts)

    @property
    def size(self) -> int:
        """Length of the observation vector."""
        return sum(f.size for f in self.fields)

    @property
    def names(self) -> tuple[str, ...]:
        """Field names in order."""
        return tuple(f.name for f in self.fields)

    def __getitem__(self, name: str) -> ObservationField:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"no observation field {name!r}; fields: {list(self.names)}")

    def slice(self, name: str) -> slice:
        """Where field ``name`` sits in the vector."""
        size = self[name].size  # KeyError naming the fields for an unknown name
        start = self._starts[name]
        return slice(start, start + size)

    def index(self, name: str) -> int:
        """The position of a one-value field."""
        if self[name].size != 1:
            raise ValueError(f"observation field {name!r} has {self[name].size} values")
        return self._starts[name]

    def assemble(self, values: dict[str, np.ndarray | float]) -> np.ndarray:
        """A vector (float64) with every field taken from ``values`` (e.g. the bounds)."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise ValueError(f"no values for observation field(s) {missing}")
        out = np.zeros(self.size)
        for name in self.names:
            out[self.slice(name)] = values[name]
        return out

    def extended(self, *extra: ObservationField) -> ObservationLayout:
        """This layout with ``extra`` fields appended (a later env version's observation)."""
        return ObservationLayout((*self.fields, *extra))


def paper_layout(n_joints: int = 6, n_arms: int = 1) -> ObservationLayout:
    """The paper's observation for a robot with ``n_joints`` joints (23 values for 6).

    With ``n_arms=2`` (the bilateral env, one robot per arm) every per-arm field holds both
    arms, right first: ``theta_star`` is the right robot's ``n_joints`` targets then the left
    robot's, ``p_star`` the right then the left tool target, and so on (``2 n_joints + 9
    n_arms + 2`` values: 44 for two UR5e)."""
    if n_arms not in (1, 2):
        raise ValueError(f"n_arms={n_arms!r} must be 1 or 2")
    joints, xyz = n_joints * n_arms, 3 * n_arms
    arms = "" if n_arms == 1 else " (right arm, then left arm)"
    return ObservationLayout((
        ObservationField("theta_star", joints, "rad", "joint",
                         f"target robot joint angles theta* of the active target{arms}"),
        ObservationField("p_star", xyz, "m", "robot base",
                         f"target tool (flange) position p* of the active target{arms}"),
        ObservationField("theta", joints, "rad", "joint", f"robot joint angles theta{arms}"),
        ObservationField("p", xyz, "m", "robot base", f"tool (flange) position p{arms}"),
        ObservationField("phi", xyz, "rad", "joint",
                         "the patient's exercised joints (shoulder flexion, shoulder abduction, "
                         f"elbow flexion; or hip flexion, hip abduction, knee flexion){arms}"),
        ObservationField("e", 1, "-", "-", "exercise index"),
        ObservationField("l", 1, "-", "-", "weight level"),
    ))


def layout_for_size(size: int) -> ObservationLayout:
    """The paper layout of an observation of ``size`` values: ``2 n + 11`` (odd) is one robot
    of ``n`` joints, ``4 n + 20`` two robots of ``n`` joints (the bilateral env). A
    ``ValueError`` names any other size."""
    if size >= 13 and size % 2 == 1:
        return paper_layout((size - 11) // 2)
    if size >= 24 and (size - 20) % 4 == 0:
        return paper_layout((size - 20) // 4, n_arms=2)
    raise ValueError(f"an observation of {size} values is not a RehabBot layout (2 n + 11 "
                     "for one robot of n joints, 4 n + 20 for two)")


def tracking_slices(size: int) -> tuple[slice, slice, slice, slice]:
    """``(theta_star, p_star, theta, p)``: where the targets and the current joint angles and
    tool positions sit in an observation of ``size`` values (:func:`layout_for_size`)."""
    layout = layout_for_size(size)
    return tuple(layout.slice(name) for name in ("theta_star", "p_star", "theta", "p"))


PAPER_LAYOUT = paper_layout(6)
OBS_SIZE = PAPER_LAYOUT.size  # 23
THETA_STAR = PAPER_LAYOUT.slice("theta_star")
P_STAR = PAPER_LAYOUT.slice("p_star")
THETA = PAPER_LAYOUT.slice("theta")
P = PAPER_LAYOUT.slice("p")
PHI = PAPER_LAYOUT.slice("phi")
E = PAPER_LAYOUT.index("e")
L = PAPER_LAYOUT.index("l")

# Bounds that do not depend on the patient or the robot's placement.
POSITION_BOUND_M = 1.35  # > the UR5e's reach: no flange position in the base frame exceeds it
PHI_OBS_MARGIN_RAD = 0.5  # beyond the anatomical range (the range-of-motion rule fires first)
