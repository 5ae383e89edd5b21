"""Argument checks that name the bad value and what would have been valid."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
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
        # bool is an int subclass: say why True is refused where 1 would pass.
        why = " (a bool is not a number)" if isinstance(value, (bool, np.bool_)) else ""
        raise ValueError(f"{name}={value!r} must be {kind} in [{low}, {high}]{why}")
    return int(value) if integer else float(value)


def as_dataclass(cls: type, value: Any, name: str) -> Any:
    """``value`` as a ``cls`` (a dataclass): itself, one built from a dict of its fields, or
    ``cls()`` for None; ``ValueError`` naming ``name`` and the valid fields otherwise."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    fields = [f.name for f in dataclasses.fields(cls)]
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - set(fields))
        if unknown:
            raise ValueError(f"{name} has unknown field(s) {unknown}; valid: {fields}")
        return cls(**value)
    raise ValueError(f"{name}={value!r} must be a {cls.__name__}, a dict of its fields "
                     f"({', '.join(fields)}) or None")


def check_options(options: Mapping | None, valid: Iterable[str]) -> dict:
    """``options`` (e.g. of ``reset``) as a new dict; ``ValueError`` naming unknown keys."""
    options = dict(options or {})
    valid = list(valid)
    unknown = set(options) - set(valid)
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; valid: {valid}")
    return options
