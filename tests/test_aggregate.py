"""IQM and bootstrap intervals across seeds (benchmarks.common.aggregate)."""

import numpy as np
import pytest

from benchmarks.common.aggregate import iqm, iqm_interval


def test_iqm_drops_the_outer_quartiles():
    assert iqm([0.0, 1.0, 1.0, 100.0]) == pytest.approx(1.0)
    assert iqm(list(range(8))) == pytest.approx(np.mean([2, 3, 4, 5]))
    with pytest.raises(ValueError, match="finite"):
        iqm([1.0, float("nan")])


def test_interval_brackets_the_iqm_and_narrows_with_more_runs():
    rng = np.random.default_rng(0)
    few = iqm_interval(rng.normal(0.8, 0.1, 4), seed=1)
    many = iqm_interval(rng.normal(0.8, 0.1, 64), seed=1)
    for interval in (few, many):
        assert interval.low <= interval.iqm <= interval.high
    assert many.high - many.low < few.high - few.low
    assert iqm_interval([0.5], seed=1).low is None  # one run: no interval
    assert iqm_interval([1.0, 1.0, 1.0]).format(0, 100) == "100"
    assert iqm_interval([0.2, 0.4, 0.9], seed=3).format(0, 100) == "50 [20, 90]"  # 3 runs: mean
