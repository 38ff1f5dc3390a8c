"""Samples as a filter takes them, and its estimate as a series: shared by the offline jobs (estimate,
bench) and the live filter.

- :func:`check_samples`: refuse samples no filter can run on, naming the file (:class:`LogError`);
  :func:`check_counts` the same for samples counted as they went by;
- :func:`median_step_ns`, :func:`rate_of`: the median interval and the nominal rate of integer stamps;
- :func:`estimate_series`: the ``/estimate/imu`` content of an :class:`Estimate` (the body's, turned
  out of a mounted sensor's axes: :mod:`.mounting`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gyroemu.errors import LogError
from gyroemu.pipelines.formats.channels import ImuSeries

from .mounting import body_estimate, body_vectors
from .protocol import Estimate

__all__ = ["check_counts", "check_samples", "estimate_series", "median_step_ns", "not_increasing_error", "rate_of"]


def check_samples(path: str | Path | None, name: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> str | None:
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


def not_increasing_error(path: str | Path | None, name: str, first: tuple[int, float, float, int]) -> LogError:
    """The error for IMU stamps that do not increase: ``first`` is the first such sample's index, its stamp
    and the one before it (s), and how many such steps there are."""
    k, t, before, count = first
    return LogError(
        f"IMU stamps of device '{name}' are not increasing: sample {k} at {float(t)!r} s follows "
        f"{float(before)!r} s ({count} such steps)",
        file=path,
    )


def check_counts(path: str | Path | None, name: str, count: int, finite: int) -> str | None:
    """:func:`check_samples` for samples counted as they went by (their stamps increasing): ``count``
    samples, ``finite`` of them with finite gyro and accelerometer rows."""
    if count < 2:
        raise LogError(f"device '{name}' has {count} IMU sample(s): too few to run a filter", file=path)
    if not finite:
        raise LogError(f"every IMU sample of device '{name}' holds NaN", file=path)
    if finite == count:
        return None
    return (
        f"{count - finite} of {count} IMU samples of device '{name}' hold NaN or infinite values; they are "
        "passed to the filters as they are (the built-in filters hold their estimate over them)"
    )


def median_step_ns(stamp_ns: np.ndarray) -> float:
    """The median interval of integer stamps ``stamp_ns`` (N ≥ 2, ns), ns: NumPy's median of the integer
    steps (the mean of the two middle ones for an even count, an integer or a half, exact for steps below
    2**52 ns). From the nanoseconds, not float seconds since the epoch, which resolve 0.24 µs today and
    put a 1 kHz log's median step 72 ppm off. :class:`~gyroemu.pipelines.formats.device_stream.RateCounter`
    finds the same float a block at a time.

    Raises
    ------
    TypeError
        Stamps that are not integers (float seconds, say).
    ValueError
        Fewer than two stamps.
    """
    steps = np.diff(_integer_ns(stamp_ns))
    if not len(steps):
        raise ValueError("no intervals")
    lower, upper = (len(steps) - 1) // 2, len(steps) // 2
    middle = np.partition(steps, (lower, upper))
    return (int(middle[lower]) + int(middle[upper])) / 2


def rate_of(stamp_ns: np.ndarray) -> float:
    """The nominal sample rate of integer stamps ``stamp_ns`` (ns): ``1e9 / median_step_ns``, Hz (1000.0
    for steps of 1,000,000 ns); 1.0 for fewer than two stamps. TypeError for stamps that are not integers."""
    stamp_ns = _integer_ns(stamp_ns)
    return 1e9 / median_step_ns(stamp_ns) if len(stamp_ns) > 1 else 1.0


def _integer_ns(stamp_ns: np.ndarray) -> np.ndarray:
    """``stamp_ns`` as int64 ns; TypeError for stamps that are not integers (float seconds, say)."""
    stamp_ns = np.asarray(stamp_ns)
    if not np.issubdtype(stamp_ns.dtype, np.integer):
        raise TypeError(f"stamps must be integer nanoseconds, got {stamp_ns.dtype}")
    return stamp_ns.astype(np.int64, copy=False)


def estimate_series(t: np.ndarray, estimate: Estimate, gyro: np.ndarray, q_bs: np.ndarray | None = None) -> ImuSeries:
    """The ``/estimate/imu`` content of an estimate of samples ``gyro`` (N, 3) rad/s at ``t`` (N,) s:
    attitude (N, 4), world-axes covariance (N, 3, 3) rad², bias-corrected rate (N, 3) rad/s. With a
    mounting ``q_bs`` (4,) (:func:`~.mounting.mounting_turn`, None: none), the body's: ``q̂_ws ⊗ q_bs*``
    and ``R(q_bs) (ω_m − b̂)`` (:func:`~.mounting.body_estimate`)."""
    rate = gyro - estimate.gyro_bias if estimate.gyro_bias is not None else None
    if q_bs is not None:
        estimate = body_estimate(estimate, q_bs)
        rate = None if rate is None else body_vectors(rate, q_bs)  # ω̂_b = R(q_bs) (ω_m − b̂)_s
    return ImuSeries(t=t, q_wb=estimate.q_wb, omega_b=rate, q_wb_covariance=estimate.q_wb_covariance)
