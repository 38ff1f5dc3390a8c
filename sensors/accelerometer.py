"""The accelerometer triad: mean specific force over each output interval, then the error terms.

An accelerometer (or its integrating ADC) reports the specific force averaged over the sample
interval, ``Δv_k / T = (1/T) ∫ f_s dt`` over ``[τ_{k−1}, τ_k]`` in sensor axes. The integral is taken
by composite Simpson's rule on a grid two or more points per trajectory sample (error ``O(h⁴)``),
then :func:`gyroemu.sensors.errors.apply_errors` adds bias, scale factor, misalignment, noise and the rest.
With a ``latency_s`` ``L`` the interval is ``[τ_{k−1} − L, τ_k − L]`` (see :mod:`gyroemu.sensors.imu`).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from gyroemu.dynamics.config import Real, Section
from gyroemu.dynamics.jit import njit

from .errors import AccelErrors
from .sampling import SensorTruth

__all__ = ["AccelerometerSpec", "LatencySeconds", "mean_specific_force"]


def _is_zero(value: float) -> bool:
    return value == 0.0


LatencySeconds = Annotated[Real, Field(gt=-1.0, lt=1.0, exclude_if=_is_zero)]
"""A sensor's ``latency_s`` key (``[gyro]``, ``[accelerometer]``, ``[magnetometer]``), s, ``|L| < 1``:
the sample stamped ``t_k`` measures the motion at the true instant ``τ_k − L``; positive, the sensor
lags the truth. Left out of a dumped config when 0, so configs without it resolve to the same text."""


class AccelerometerSpec(Section):
    """``[accelerometer]`` of a device: the error terms in datasheet units (see :class:`AccelErrors`)
    and the latency."""

    errors: AccelErrors = AccelErrors()
    latency_s: LatencySeconds = 0.0
    """The sample stamped ``t_k`` is the mean specific force over ``[τ_{k−1} − L, τ_k − L]``, the motion
    ``latency_s`` earlier than the true instants; positive: the sensor lags the truth."""


def mean_specific_force(truth: SensorTruth, instants: NDArray[np.float64], substeps: int) -> NDArray[np.float64]:
    """Mean specific force (sensor axes, m/s²) over each interval between consecutive ``instants``.

    Parameters
    ----------
    truth : SensorTruth
    instants : ndarray (K+1,)
        Interval boundaries, s, uniform.
    substeps : int
        Even number of Simpson sub-intervals per interval.

    Returns
    -------
    ndarray (K, 3)
    """
    if substeps < 2 or substeps % 2:
        raise ValueError(f"Simpson's rule needs an even number of sub-intervals, got {substeps}")
    k = len(instants) - 1
    grid = instants[0] + (instants[-1] - instants[0]) * np.arange(k * substeps + 1) / (k * substeps)
    f = np.ascontiguousarray(truth.specific_force(grid))
    out = np.empty((k, f.shape[1]))
    _simpson_means(f, substeps, out)
    return out


@njit
def _simpson_means(f: NDArray[np.float64], substeps: int, out: NDArray[np.float64]) -> None:
    """Interval ``i``'s composite Simpson rule over the points ``i·substeps … (i + 1)·substeps`` of ``f``
    (K·substeps + 1, A), in units of the interval: scipy's ``simpson(f[idx], dx=1/substeps, axis=1)``
    for each interval's points ``idx``, bit for bit (its panels ``f₀ + 4.0 f₁ + f₂`` summed in order,
    times ``dx/3.0``), without gathering the points."""
    third = (1.0 / substeps) / 3.0
    for i in range(out.shape[0]):
        base = i * substeps
        for a in range(out.shape[1]):
            total = f[base, a] + 4.0 * f[base + 1, a] + f[base + 2, a]
            for j in range(base + 2, base + substeps, 2):
                total = total + (f[j, a] + 4.0 * f[j + 1, a] + f[j + 2, a])
            out[i, a] = total * third
