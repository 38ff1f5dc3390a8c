"""The :class:`ImuSamples` type: what a device outputs (and what a recorded log decodes to)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ImuSamples"]


@dataclass(frozen=True, eq=False)
class ImuSamples:
    """A device's output samples (N of them), SI units, sensor axes.

    Attributes
    ----------
    t : ndarray (N,)
        Sample stamps, s, as the device's clock reports them.
    gyro : ndarray (N, 3)
        Angular rate, rad/s: the indicated angle increment over ``[t_{k−1}, t_k]`` divided by the
        nominal sample interval (the strapdown convention, see :mod:`gyroemu.sensors.mechanism`).
    accel : ndarray (N, 3)
        Specific force, m/s², the mean over the same interval.
    mag : ndarray (N, 3)
        Magnetic flux density, tesla, sampled at ``t_k``; NaN where the device has no magnetometer.
    raw : dict of str to dict of str to ndarray
        Each gyro kind's physical observables at the sample instants: ``raw[kind][name]``, first axis N.
    delta_angle, delta_velocity : ndarray (N, 3) or None
        Increments (rad, m/s) over each interval, for devices that output increments.
    t_true : ndarray (N,) or None
        The true instants (the trajectory's time axis) at which each sample was taken; differs from
        ``t`` by the clock's rate error, offset and jitter.
    temperature_degC : ndarray (N,) or None
    device : str
        The device's name.
    """

    t: NDArray[np.float64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    mag: NDArray[np.float64]
    raw: dict[str, dict[str, NDArray[Any]]] = field(default_factory=dict)
    delta_angle: NDArray[np.float64] | None = None
    delta_velocity: NDArray[np.float64] | None = None
    t_true: NDArray[np.float64] | None = None
    temperature_degC: NDArray[np.float64] | None = None
    device: str = "imu0"

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("gyro", "accel", "mag"):
            if np.shape(getattr(self, name)) != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {np.shape(getattr(self, name))}")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def has_mag(self) -> bool:
        """Whether the device has a magnetometer (its samples are not all NaN)."""
        return bool(len(self.mag)) and not np.all(np.isnan(self.mag))
