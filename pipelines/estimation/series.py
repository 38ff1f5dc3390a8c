"""Samples as a filter takes them, and its estimate as a series: shared by the offline jobs (estimate,
bench) and the live filter.

- :func:`check_samples`: refuse samples no filter can run on, naming the file (:class:`LogError`);
  :func:`check_counts` the same for samples counted as they went by;
- :func:`rate_of`: the nominal rate of stamps;
- :func:`estimate_series`: the ``/estimate/imu`` content of an :class:`Estimate`.
"""

from __future__ import annotations

import numpy as np

from gyroemu.errors import LogError
from gyroemu.pipelines.formats.channels import ImuSeries

from .protocol import Estimate

__all__ = ["check_counts", "check_samples", "estimate_series", "not_increasing_error", "rate_of"]


def check_samples(path, name: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> str | None:
    """Refuse samples a filter cannot run on, naming the file (:class:`LogError`): fewer than two,
    stamps that do not increase, or NaN everywhere. Some NaN samples are usable (the filters skip
    them): returns a note saying how many, None when there are none."""
    t = np.asarray(t, dtype=float)
    bad = np.flatnonzero(~(np.diff(t) > 0)) if len(t) > 1 else np.empty(0, np.int64)
    if len(bad):
        k = int(bad[0]) + 1
        raise not_increasing_error(path, name, (k, float(t[k]), float(t[k - 1]), len(bad)))
    finite = np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)
    return check_counts(path, name, len(t), int(finite.sum()))


def not_increasing_error(path, name: str, first: tuple[int, float, float, int]) -> LogError:
    """The error for IMU stamps that do not increase: ``first`` is the first such sample's index, its stamp
    and the one before it (s), and how many such steps there are."""
    k, t, before, count = first
    return LogError(
        f"IMU stamps of device '{name}' are not increasing: sample {k} at {t:.9f} s follows "
        f"{before:.9f} s ({count} such steps)",
        file=path,
    )


def check_counts(path, name: str, count: int, finite: int) -> str | None:
    """:func:`check_samples` for samples counted as they went by (their stamps increasing): ``count``
    samples, ``finite`` of them with finite gyro and accelerometer rows."""
    if count < 2:
        raise LogError(f"device '{name}' has {count} IMU sample(s): too few to run a filter", file=path)
    if not finite:
        raise LogError(f"every IMU sample of device '{name}' holds NaN", file=path)
    if finite == count:
        return None
    return (
        f"{count - finite} of {count} IMU samples of device '{name}' hold NaN; they are passed to the "
        "filters as they are (the built-in filters hold their estimate over them)"
    )


def rate_of(t: np.ndarray) -> float:
    """The nominal sample rate of stamps ``t``: the inverse of the median interval, Hz."""
    return 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def estimate_series(t, estimate: Estimate, gyro) -> ImuSeries:
    """The ``/estimate/imu`` content of an estimate: attitude, covariance, bias-corrected rate."""
    rate = gyro - estimate.gyro_bias if estimate.gyro_bias is not None else None
    return ImuSeries(t=t, q_wb=estimate.q_wb, omega_b=rate, q_wb_covariance=estimate.q_wb_covariance)
