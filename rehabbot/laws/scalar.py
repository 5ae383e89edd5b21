"""The scalar namespace: a law evaluated on one world's Python floats (or NumPy scalars).

The CPU env steps one world whose joints are a handful of numbers; NumPy's per-call cost on
2-6 element arrays would dominate its physics step. It therefore evaluates the same law
functions joint by joint on floats, passing this module as ``xp``: each operation a law uses is
here, built on :mod:`math` and the built-in ``min``/``max``, in the order of evaluation the law
writes.

Unlike ``numpy.where``, :func:`where` does not broadcast: both branches are evaluated, then
one is returned. A law may return early where a comparison of floats gives a Python ``bool``
that decides its answer (arrays give arrays and go on to the ``where``).
"""

from __future__ import annotations

import builtins
import math
from typing import Any

exp = math.exp
tanh = math.tanh
sin = math.sin
abs = builtins.abs
minimum = builtins.min
maximum = builtins.max


def where(condition: bool, if_true: Any, if_false: Any) -> Any:
    """``if_true`` where ``condition`` holds, else ``if_false``."""
    return if_true if condition else if_false


def mod(value: float, divisor: float) -> float:
    """The remainder of ``value / divisor`` with the divisor's sign (as ``numpy.mod``)."""
    return value % divisor

