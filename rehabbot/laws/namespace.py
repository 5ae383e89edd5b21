"""Which array namespace a law runs in."""

from __future__ import annotations

import sys
from types import ModuleType
from typing import Any

import numpy as np


def namespace_of(*arrays: Any) -> ModuleType:
    """``jax.numpy`` if any of ``arrays`` is a JAX array (or tracer), else NumPy. A JAX array
    exists only once JAX is loaded, so this module never imports it."""
    for array in arrays:
        kind = type(array)
        if kind is np.ndarray or kind is float:  # the CPU env's readings: a quick look
            continue
        if kind.__module__.startswith(("jax", "jaxlib")):
            return sys.modules["jax.numpy"]
    return np
