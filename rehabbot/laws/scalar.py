"""The array namespace of one world held in Python floats: the functions the laws call, for
plain numbers (and, along an arm axis, short lists of them).

The CPU env steps one world, and there a law's inputs are a handful of Python floats. NumPy
would answer the same (both are IEEE doubles) but at about half a microsecond a call, more
than the arithmetic itself; this namespace lets the same law run at the cost of Python's
built-ins. A law receives it as its ``xp`` argument like NumPy or ``jax.numpy``, and its
functions give the same floats as NumPy's on the same numbers (``tests/laws`` checks it):

* ``maximum``, ``minimum``, ``abs``: Python's ``max``, ``min``, ``abs``; ``sqrt``, ``exp``,
  ``tanh``, ``sin``: those of Python's ``math`` module (IEEE results);
* ``where(condition, a, b)``: ``a if condition else b``. Unlike ``numpy.where`` it does not
  broadcast; both branches are already computed, as in NumPy, so a law keeps them finite for
  any input it accepts;
* ``mod``: the remainder with the divisor's sign (as ``numpy.mod``);
* ``sum(values, axis=-1)``: the values of one arm axis (a list) added from the left;
* ``logical_and``, ``logical_or``, ``logical_not``: of Python bools.
"""

from __future__ import annotations

import builtins
import math
from collections.abc import Iterable
from typing import TypeVar

T = TypeVar("T")

maximum = builtins.max
minimum = builtins.min
abs = builtins.abs
sqrt = math.sqrt
exp = math.exp
tanh = math.tanh
sin = math.sin


def where(condition: bool, a: T, b: T) -> T:
    """``a`` where ``condition`` holds, else ``b``."""
    return a if condition else b


def mod(value: float, divisor: float) -> float:
    """The remainder of ``value / divisor`` with the divisor's sign (as ``numpy.mod``)."""
    return value % divisor


def sum(values: Iterable[float], axis: int = -1) -> float:
    """The values along the one (arm) axis, added from the left."""
    del axis
    return builtins.sum(values)


def logical_and(a: bool, b: bool) -> bool:
    """``a and b``."""
    return a and b


def logical_or(a: bool, b: bool) -> bool:
    """``a or b``."""
    return a or b


def logical_not(a: bool) -> bool:
    """``not a``."""
    return not a


__all__ = ["abs", "exp", "logical_and", "logical_not", "logical_or", "maximum",
           "minimum", "mod", "sin", "sqrt", "sum", "tanh", "where"]
