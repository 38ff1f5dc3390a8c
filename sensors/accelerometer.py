"""The accelerometer triad: mean specific force over each output interval, then the error terms.

An accelerometer (or its integrating ADC) reports the specific force averaged over the sample
interval, ``Δv_k / T = (1/T) ∫ f_s dt`` over ``[τ_{k−1}, τ_k]`` in sensor axes. The integral is taken
by composite Simpson's rule on a grid two or more points per trajectory sample (error ``O(h⁴)``),
then :func:`gyroemu.sensors.errors.apply_errors` adds bias, scale factor, misalignment, noise and the rest.
"""

from __future__ import annotations

import numpy as np

from gyroemu.dynamics.config import Section

from .errors import AccelErrors
from .sampling import SensorTruth

__all__ = ["AccelerometerSpec", "mean_specific_force"]


class AccelerometerSpec(Section):
    """``[accelerometer]`` of a device: the error terms in datasheet units (see :class:`AccelErrors`)."""

    errors: AccelErrors = AccelErrors()


def mean_specific_force(truth: SensorTruth, instants: np.ndarray, substeps: int) -> np.ndarray:
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
    k = len(instants) - 1
    grid = instants[0] + (instants[-1] - instants[0]) * np.arange(k * substeps + 1) / (k * substeps)
    f = truth.specific_force(grid)
    # Each interval's points: k*substeps + 0 … substeps, overlapping the next interval's first point.
    idx = np.arange(k)[:, None] * substeps + np.arange(substeps + 1)[None, :]
    from scipy.integrate import simpson  # scipy where it is used: the CLI's listings skip it

    return simpson(f[idx], dx=1.0 / substeps, axis=1)
