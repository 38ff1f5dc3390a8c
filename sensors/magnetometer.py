"""The magnetometer triad: hard and soft iron, noise, range and quantisation.

Measurement model (the usual calibration model, e.g. Vasconcelos et al., IEEE TIM 2011)::

    m_meas = S m_s + h + n,      n ~ white, density N (tesla/√Hz; per sample σ = N/√T)

with ``S`` the soft-iron (and scale/misalignment) matrix and ``h`` the hard-iron offset, both in the
sensor's axes; the output is then clipped to the range and rounded to the quantum. With a
``latency_s`` ``L``, ``m_s`` of the sample stamped ``t_k`` is the field at the true instant ``τ_k − L``
(see :mod:`gyroemu.sensors.imu`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal, Section, Vec3

from .accelerometer import LatencySeconds

__all__ = ["MagnetometerSpec"]

_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


class MagnetometerSpec(Section):
    """``[magnetometer]`` of a device (absent: the device has none). Datasheet units as keys say."""

    noise_density_uT_per_sqrt_hz: NonNegativeReal = 0.0
    hard_iron_uT: Vec3 = (0.0, 0.0, 0.0)
    soft_iron: tuple[Vec3, Vec3, Vec3] = _IDENTITY
    range_uT: PositiveReal | None = None
    quantisation_uT: PositiveReal | None = None
    latency_s: LatencySeconds = 0.0
    """The sample stamped ``t_k`` measures the field at the true instant ``τ_k − latency_s``; positive:
    the sensor lags the truth (a real IMU's magnetometer: 9–16 ms)."""

    def measure(self, field_s: NDArray[np.float64], dt: float, rng: np.random.Generator) -> NDArray[np.float64]:
        """Measured field (N, 3), tesla, for the true sensor-axes field ``field_s`` (N, 3) sampled every ``dt``."""
        m: NDArray[np.float64] = (
            np.einsum("ij,nj->ni", np.array(self.soft_iron), field_s) + np.array(self.hard_iron_uT) * 1e-6
        )
        if self.noise_density_uT_per_sqrt_hz > 0:
            m += rng.standard_normal(m.shape) * (self.noise_density_uT_per_sqrt_hz * 1e-6 / np.sqrt(dt))
        if self.range_uT is not None:
            np.clip(m, -self.range_uT * 1e-6, self.range_uT * 1e-6, out=m)
        if self.quantisation_uT is not None:
            q = self.quantisation_uT * 1e-6
            m = np.round(m / q) * q
        return m
