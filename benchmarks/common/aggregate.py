"""Aggregate scores across training seeds the way rliable recommends (Agarwal et al., 2021,
"Deep RL at the edge of the statistical precipice"): the interquartile mean (IQM, the mean of
the middle 50 % of the runs) with a 95 % percentile-bootstrap confidence interval.

rliable itself (1.2.0) cannot be imported next to pandas 3 (its dependency ``arch`` 7.2 fails
with ``TypeError: deprecate_kwarg()``), so this module follows its protocol with SciPy:
``scipy.stats.trim_mean(x, 0.25)`` is the IQM and ``scipy.stats.bootstrap`` resamples the runs.
With fewer than two runs there is no interval (``None``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

BOOTSTRAP_RESAMPLES = 2000
CONFIDENCE = 0.95


@dataclass(frozen=True)
class Interval:
    """An IQM over runs and its bootstrap confidence interval (``low``/``high`` None with
    fewer than two runs or when every run scored the same)."""

    iqm: float
    low: float | None
    high: float | None
    runs: int

    def format(self, digits: int = 0, scale: float = 1.0) -> str:
        value = f"{self.iqm * scale:.{digits}f}"
        if self.low is None or self.high is None:
            return value
        return f"{value} [{self.low * scale:.{digits}f}, {self.high * scale:.{digits}f}]"


def iqm(scores: Sequence[float]) -> float:
    """The interquartile mean of ``scores`` (the plain mean for fewer than four)."""
    from scipy.stats import trim_mean

    values = np.asarray(scores, dtype=float)
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise ValueError(f"scores must be finite and non-empty, got {list(values)}")
    return float(trim_mean(values, 0.25))


def iqm_interval(scores: Sequence[float], seed: int = 0,
                 resamples: int = BOOTSTRAP_RESAMPLES) -> Interval:
    """The IQM of one score per run and its 95 % percentile-bootstrap interval over runs."""
    from scipy.stats import bootstrap, trim_mean

    values = np.asarray(scores, dtype=float)
    centre = iqm(values)
    if values.size < 2 or np.ptp(values) == 0.0:
        return Interval(centre, None, None, int(values.size))
    result = bootstrap((values,), lambda x, axis: trim_mean(x, 0.25, axis=axis),
                       n_resamples=resamples, confidence_level=CONFIDENCE,
                       method="percentile", random_state=np.random.default_rng(seed))
    low, high = result.confidence_interval
    return Interval(centre, float(low), float(high), int(values.size))
