"""Muscle fatigue: the three-compartment controller model with rest recovery (3CC-r).

Each muscle's motor units are split into three fractions that always sum to one: active
``MA`` (producing force), resting ``MR`` (available) and fatigued ``MF`` (Xia & Frey Law,
J Biomech 2008;41:3046; the rest-recovery multiplier ``r`` of Looft, Herkert & Frey-Law,
J Biomech 2018;77:16). The muscle's commanded excitation is the *target load* ``TL``; a
controller recruits resting units towards it and releases active ones above it:

* ``C = LD (TL - MA)`` while ``MA < TL`` and enough units rest, ``C = LD MR`` while too few rest,
  ``C = LR (TL - MA)`` once ``MA >= TL``;
* ``dMA/dt = C - F MA``, ``dMR/dt = -C + R_eff MF``, ``dMF/dt = F MA - R_eff MF``, with
  ``R_eff = r R`` while the muscle is not asked for more than it gives (resting) and ``R``
  otherwise.

The muscle then receives ``MA`` as its excitation instead of ``TL`` (MyoSuite's use of the
model for muscles): a fatigued muscle falls short of what it is asked for. ``F`` and ``R``
[1/s] are published per joint (Rakshit et al., J Biomech 2021;122:110695: knee ``F = 0.00825``,
``R = 0.00076``, ``r = 14.85``; the general values of Looft et al. 2018: ``F = 0.00970``,
``R = 0.00091``, ``r = 15``); :class:`ThreeCompartmentFatigue` takes them per muscle.
"""

from __future__ import annotations

import numpy as np

# (F [1/s], R [1/s], r) per joint group (see the module docstring for the sources).
KNEE_3CCR = (0.00825, 0.00076, 14.85)
GENERAL_3CCR = (0.00970, 0.00091, 15.0)
# Recruitment (LD) and release (LR) rates of the controller [1/s] (Xia & Frey Law 2008).
RECRUIT_RATE_PER_S = 10.0
RELEASE_RATE_PER_S = 10.0


class ThreeCompartmentFatigue:
    """The 3CC-r state of ``n`` muscles, advanced by :meth:`step` every physics step.

    ``fatigue_per_s``, ``recovery_per_s`` and ``rest_multiplier`` are ``F``, ``R`` and ``r``
    (scalars or one per muscle); ``dt_s`` is the step. The compartments start fresh (all
    units resting) at :meth:`reset`.
    """

    def __init__(self, n: int, fatigue_per_s: np.ndarray | float,
                 recovery_per_s: np.ndarray | float, rest_multiplier: np.ndarray | float,
                 dt_s: float) -> None:
        if not dt_s > 0.0:
            raise ValueError(f"dt_s={dt_s!r} must be > 0")
        self.fatigue_per_s = np.broadcast_to(np.asarray(fatigue_per_s, float), (n,)).copy()
        self.recovery_per_s = np.broadcast_to(np.asarray(recovery_per_s, float), (n,)).copy()
        self.rest_multiplier = np.broadcast_to(np.asarray(rest_multiplier, float), (n,)).copy()
        for name in ("fatigue_per_s", "recovery_per_s", "rest_multiplier"):
            values = getattr(self, name)
            if not np.all(np.isfinite(values)) or (values < 0.0).any():
                raise ValueError(f"{name}={values!r} must be finite and >= 0")
        self.dt_s = float(dt_s)
        self.active = np.zeros(n)
        self.resting = np.ones(n)
        self.fatigued = np.zeros(n)
        self._control = np.zeros(n)
        self._recovery = np.zeros(n)

    def reset(self) -> None:
        """Every unit resting."""
        self.active[:] = 0.0
        self.resting[:] = 1.0
        self.fatigued[:] = 0.0

    def step(self, target: np.ndarray) -> np.ndarray:
        """Advance one step towards the target loads ``target`` (excitations in [0, 1]) and
        return the active fractions ``MA`` (a view, valid until the next step)."""
        ma, mr, mf, dt = self.active, self.resting, self.fatigued, self.dt_s
        f = self.fatigue_per_s
        gap = target - ma
        below = gap > 0.0
        control = self._control
        np.multiply(RELEASE_RATE_PER_S, gap, out=control)
        np.copyto(control, RECRUIT_RATE_PER_S * np.minimum(gap, mr), where=below)
        recovery = self._recovery
        np.copyto(recovery, self.recovery_per_s)
        np.multiply(recovery, self.rest_multiplier, out=recovery, where=~below)
        # Keep each compartment within [0, 1] over the step (explicit Euler).
        low = np.maximum(-ma / dt + f * ma, (mr - 1.0) / dt + recovery * mf)
        high = np.minimum((1.0 - ma) / dt + f * ma, mr / dt + recovery * mf)
        np.clip(control, low, high, out=control)
        to_fatigue = f * ma
        to_rest = recovery * mf
        ma += (control - to_fatigue) * dt
        mr += (to_rest - control) * dt
        mf += (to_fatigue - to_rest) * dt
        return ma
