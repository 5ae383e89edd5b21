"""The patient's tremor: a torque on each compliant exercised joint,
``A (1 + 0.25 m(t)) sin(phase_j(t))``, the phase advancing at ``tremor_hz + df(t)``.

``df`` (0.2 Hz standard deviation) and ``m`` (clipped to +-1) are Ornstein-Uhlenbeck processes
with a 2 s time constant, drawn from the env's ``np_random`` at each control step; each joint
starts at a random phase. :class:`Tremor` holds that state; the rigid patient applies its
torques directly (:class:`~rehabbot.sim.patient_drive.PatientDrive`), MyoSuite's muscles as
excitations of the muscles that pull each way (:class:`~rehabbot.sim.muscle_drive.MuscleDrive`).
"""

from __future__ import annotations

import math

import numpy as np

TREMOR_DRIFT_HZ = 0.2  # standard deviation of the tremor frequency's drift
TREMOR_MODULATION = 0.25  # amplitude modulation depth
TREMOR_CORRELATION_S = 2.0  # time constant of the drift and modulation


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
        self.phase = rng.uniform(0.0, 2.0 * math.pi, len(self.phase)).tolist()
        self.drift_hz = float(rng.normal(0.0, TREMOR_DRIFT_HZ))
        self.modulation = float(np.clip(rng.normal(0.0, 1.0), -1.0, 1.0))

    def advance(self, rng: np.random.Generator, control_dt_s: float) -> None:
        """One control step of the drift and modulation (exact Ornstein-Uhlenbeck update)."""
        decay = math.exp(-control_dt_s / TREMOR_CORRELATION_S)
        noise = math.sqrt(1.0 - decay * decay)
        z_drift, z_mod = rng.normal(0.0, 1.0, 2).tolist()
        self.drift_hz = decay * self.drift_hz + noise * TREMOR_DRIFT_HZ * z_drift
        self.modulation = min(max(decay * self.modulation + noise * z_mod, -1.0), 1.0)

    def add_torques(self, torque: list[float]) -> None:
        """Add this physics step's tremor torque to each joint's ``torque`` [N m] and advance
        the phases."""
        amplitude = self.amplitude_nm * (1.0 + TREMOR_MODULATION * self.modulation)
        step = 2.0 * math.pi * (self.frequency_hz + self.drift_hz) * self.dt_s
        phase = self.phase
        for j in range(len(torque)):
            torque[j] += amplitude * math.sin(phase[j])
            phase[j] += step
