"""rehabbot.batch.padding: ragged per-exercise tables padded to the longest, targets with their
last row and rests with zeros, and refusals of what cannot be padded."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("warp")

from rehabbot.batch.padding import pad_to, stack_padded


def test_targets_repeat_their_last_row_and_rests_take_the_constant():
    short = np.array([[1.0, 2.0], [3.0, 4.0]])
    long = np.arange(8.0).reshape(4, 2)
    targets = stack_padded([short, long])
    assert targets.shape == (2, 4, 2)
    assert np.array_equal(targets[0], [[1, 2], [3, 4], [3, 4], [3, 4]])
    assert np.array_equal(targets[1], long)
    rests = stack_padded([np.array([0.5]), np.array([0.1, 0.2, 0.3])], fill=0.0)
    assert np.array_equal(rests, [[0.5, 0, 0], [0.1, 0.2, 0.3]])
    assert np.array_equal(stack_padded([short], count=3)[0], [[1, 2], [3, 4], [3, 4]])
    assert np.array_equal(pad_to(long, 4), long)


def test_what_cannot_be_padded_is_refused():
    with pytest.raises(ValueError, match="4 rows do not fit in 3"):
        pad_to(np.zeros((4, 2)), 3)
    with pytest.raises(ValueError, match="no last row"):
        pad_to(np.zeros((0, 2)), 2)
    assert np.array_equal(pad_to(np.zeros((0, 2)), 2, fill=0.0), np.zeros((2, 2)))
