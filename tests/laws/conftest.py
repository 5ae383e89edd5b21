"""The laws' tests run once over NumPy and once over ``jax.numpy`` (skipped, with the reason,
where JAX is not installed). Each is milliseconds and builds no MuJoCo scene."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

XP_PARAMS = [pytest.param("numpy", id="numpy"),
             pytest.param("jax", id="jax", marks=pytest.mark.skipif(
                 importlib.util.find_spec("jax") is None,
                 reason="JAX is not installed (the [jax] or [gpu] extra)"))]


@pytest.fixture(params=XP_PARAMS)
def xp(request: pytest.FixtureRequest):
    """The array namespace a law is tested in: NumPy, then jax.numpy in float64."""
    if request.param == "numpy":
        yield np
        return
    import jax
    import jax.numpy as jnp

    with jax.enable_x64(True):  # for this test only: other tests keep JAX's float32 default
        yield jnp
