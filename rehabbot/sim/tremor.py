"""The patient's tremor: a torque on each compliant exercised joint,
``A (1 + 0.25 m(t)) sin(phase_j(t))``, the phase advancing at ``tremor_hz + df(t)``
(the laws: :mod:`rehabbot.laws.patient`).

``df`` (0.2 Hz standard deviation) and ``m`` (clipped to +-1) are Ornstein-Uhlenbeck processes
with a 2 s time constant, drawn from the env's ``np_random`` at each control step; each joint
starts at a random phase. :class:`Tremor` holds that state; the rigid patient applies its
torques directly (:class:`~rehabbot.sim.patient_drive.PatientDrive`), MyoSuite's muscles as
excitations of the muscles that pull each way (:class:`~rehabbot.sim.muscle_drive.MuscleDrive`).
"""

from __future__ import annotations

import numpy as np

from rehabbot.laws import patient as laws
from rehabbot.laws import scalar
from rehabbot.laws.patient import (  # noqa: F401  (re-exported)
    TREMOR_CORRELATION_S,
    TREMOR_DRIFT_HZ,
    TREMOR_MODULATION,
    TWO_PI,
)


class Tremor:
    """The tremor of ``n_joints`` joints at ``frequency_hz`` with ``amplitude_nm``, advanced
    every physics step of ``dt_s`` (:meth:`add_torques`) and every control step
    (:meth:`advance`)."""

    def __init__(self, frequency_hz: float, amplitude_nm: float, n_joints: int,
                 dt_s: float) -> None:
        self.frequency_hz = frequency_hz
        self.amplitude_nm = amplitude_nm
        self.dt_s = dt_s
        self.phase = [0.0] * n_joints
        self.drift_hz = 0.0
        self.modulation = 0.0

    def reset(self, rng: np.random.Generator) -> None:
        """Draw each joint's phase and the processes' start from ``rng``."""
        self.phase = rng.uniform(0.0, TWO_PI, len(self.phase)).tolist()
        z_drift = float(rng.normal(0.0, 1.0))
        z_modulation = float(rng.normal(0.0, 1.0))
        self.drift_hz, self.modulation = laws.tremor_start(scalar, z_drift, z_modulation)

    def advance(self, rng: np.random.Generator, control_dt_s: float) -> None:
        """One control step of the drift and modulation (exact Ornstein-Uhlenbeck update)."""
        decay, noise = laws.tremor_decay(control_dt_s)
        z_drift, z_mod = rng.normal(0.0, 1.0, 2).tolist()
        self.drift_hz, self.modulation = laws.tremor_processes(
            scalar, self.drift_hz, self.modulation, z_drift, z_mod, decay, noise)

    def torques_nm(self) -> list[float]:
        """This physics step's tremor torque on each joint [N m]; the phases advance."""
        amplitude, modulation = self.amplitude_nm, self.modulation
        frequency, drift, dt, law = self.frequency_hz, self.drift_hz, self.dt_s, \
            laws.tremor_torque_nm
        phase = self.phase
        torque = [0.0] * len(phase)
        for j, p in enumerate(phase):
            torque[j], phase[j] = law(scalar, amplitude, modulation, frequency, drift, p, dt)
        return torque

    def add_torques(self, torque: list[float]) -> None:
        """Add this physics step's tremor torque to each joint's ``torque`` [N m] and advance
        the phases."""
        for j, t in enumerate(self.torques_nm()):
            torque[j] += t
