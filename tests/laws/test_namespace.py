"""rehabbot.laws.namespace: a law finds its namespace from its arrays."""

from __future__ import annotations

import numpy as np

from rehabbot.laws.namespace import namespace_of


def test_namespace_of_tells_the_arrays_apart(xp) -> None:
    assert namespace_of(xp.zeros(3)) is xp
    assert namespace_of(1.0, np.zeros(2)) is np
    assert namespace_of(np.zeros(2), xp.ones(2)) is xp


def test_jax_arrays_are_float64_inside_a_law_test(xp) -> None:
    assert xp.asarray(0.1).dtype == np.float64
