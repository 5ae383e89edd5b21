"""The array namespace of one world held in Python floats: the few functions the laws call,
for plain numbers (and, along an arm axis, short lists of them).

The CPU env steps one world, and there a law's inputs are a handful of Python floats. NumPy
would answer the same (both are IEEE doubles) but at about half a microsecond a call, more than
the arithmetic itself; this namespace lets the same law run at the cost of Python's built-ins.
A law receives it as its ``xp`` argument like NumPy or ``jax.numpy``; its functions give the
same floats as NumPy's on the same numbers:

* ``maximum``, ``minimum``, ``abs``, ``sqrt``: Python's ``max``, ``min``, ``abs`` and
  :func:`math.sqrt` (both sides compute IEEE results, the last correctly rounded);
* ``where(condition, a, b)``: ``a if condition else b`` (both already computed, as in NumPy:
  a law never divides by a value the condition rules out);
* ``sum(values, axis=-1)``: the values of one arm axis (a list) added from the left;
* ``logical_not``: of a Python bool (whose ``~`` is an integer's); laws join bools with
  ``&`` and ``|``, which Python bools, NumPy and JAX read alike.
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


def where(condition: bool, a: T, b: T) -> T:
    """``a`` where ``condition`` holds, else ``b``."""
    return a if condition else b


def sum(values: Iterable[float], axis: int = -1) -> float:
    """The values along the one (arm) axis, added from the left."""
    del axis
    return builtins.sum(values)


def logical_not(a: bool) -> bool:
    """``not a``."""
    return not a
