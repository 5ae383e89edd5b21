"""The range of motion an episode achieved against the one its exercise prescribed (pure NumPy).

Per exercised joint, the *achieved* excursion is the largest minus the smallest angle the joint
took in the episode; the *prescribed* excursion runs from the start pose through every target
of the exercise. Joints the exercise moves less than :data:`PRESCRIBED_MIN_DEG` are left out of
the ratio (their prescribed excursion is rounding noise). The ratio achieved / prescribed is
1 when the limb went exactly as far as prescribed; below 1 it fell short; **above 1 the limb
went beyond what was prescribed** (an overshoot, or a joint pushed past the path), which a
therapist must see: tables and figures flag it (:func:`beyond_prescribed`).
"""

from __future__ import annotations

import numpy as np

PRESCRIBED_MIN_DEG = 1.0  # joints the exercise moves less than this are left out of the ratio
BEYOND_PRESCRIBED = "beyond the prescribed range"  # the flag's words in tables and figures


def range_of_motion_deg(patient_rad: np.ndarray,
                        targets_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per exercised joint: the excursion achieved in an episode (max - min of the joint's
    angle, ``patient_rad`` (T + 1, 3) from the reset on) and the excursion prescribed (from the
    start pose through every target of ``targets_deg`` (N, 3)), both in degrees."""
    angles = np.degrees(np.asarray(patient_rad, dtype=float))
    achieved = angles.max(axis=0) - angles.min(axis=0)
    path = np.vstack([angles[:1], np.asarray(targets_deg, dtype=float)])
    return achieved, path.max(axis=0) - path.min(axis=0)


def achieved_fraction(achieved_deg: np.ndarray, prescribed_deg: np.ndarray) -> float | None:
    """Achieved over prescribed excursion, summed over the joints the exercise moves
    (prescribed >= :data:`PRESCRIBED_MIN_DEG`); None when it moves none."""
    achieved = np.asarray(achieved_deg, dtype=float)
    prescribed = np.asarray(prescribed_deg, dtype=float)
    moved = prescribed >= PRESCRIBED_MIN_DEG
    if not moved.any():
        return None
    return float(achieved[moved].sum() / prescribed[moved].sum())


def beyond_prescribed(fraction: float | None) -> bool:
    """Whether an achieved / prescribed ratio says the limb went beyond the prescription
    (above 1, at the two decimals tables show)."""
    return fraction is not None and round(float(fraction), 2) > 1.0
