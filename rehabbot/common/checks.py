"""Argument checks that name the bad value and what would have been valid."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (int or float, NumPy's too), not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """Return ``value``; ``ValueError`` naming it and the valid ``choices`` unless it is one."""
    choices = tuple(choices)
    if isinstance(value, (bool, np.bool_)) or value not in choices:
        raise ValueError(f"{name}={value!r} is not one of {list(choices)}")
    return value


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
                 integer: bool = False) -> float | int:
    """``value`` as a float (or int with ``integer``) in ``[low, high]``; ``ValueError``
    naming it and the range otherwise (NaN, inf, bools and non-numbers included)."""
    ok = is_real(value) and math.isfinite(float(value)) and low <= float(value) <= high
    if ok and integer:
        ok = float(value).is_integer()
    if not ok:
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{name}={value!r} must be {kind} in [{low}, {high}]")
    return int(value) if integer else float(value)
