"""``gyroemu estimate``: run an attitude filter over a recorded log and write its estimate.

The output is the input log's devices (their samples, raw observables, truth, movement mask and
metadata) with an ``/estimate/imu`` channel added: one message per ``/imu`` message at exactly its
stamp, holding the estimated ``q_wb`` with its covariance (when the filter has one) and the
bias-corrected rate. An ``/estimate/imu`` already in the input is replaced.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .estimation.protocol import Estimate
from .estimation.registry import make_filter
from .estimation.setup import setup_from_metadata
from .mcap_io import ImuSeries, LogError, McapLogWriter, Recording, read_mcap

__all__ = ["EstimateSummary", "estimate_log", "estimate_series", "check_samples"]


@dataclass(frozen=True)
class EstimateSummary:
    """What :func:`estimate_log` did, per device: ``(name, samples, filter name, 9D?)``."""

    path: Path
    devices: list


def check_samples(path, name: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> None:
    """Refuse data a filter cannot run on, naming the file: stamps that do not increase. NaN samples
    are usable (a filter skips them) and only warned about."""
    dt = np.diff(t)
    if len(dt) and not np.all(dt > 0):
        k = int(np.argmax(~(dt > 0))) + 1
        raise LogError(f"device {name}: stamps do not increase at sample {k} ({t[k - 1]!r} s, then {t[k]!r} s)",
                       file=path)
    bad = ~np.isfinite(gyro).all(axis=1) | ~np.isfinite(accel).all(axis=1)
    if bad.any():
        warnings.warn(f"{path}: device {name}: {int(bad.sum())} of {len(t)} samples hold NaN; the filter "
                      "skips them (a NaN gyro sample holds the last rate)", UserWarning, stacklevel=3)


def rate_of(t: np.ndarray) -> float:
    """The nominal sample rate of stamps ``t``: the inverse of the median interval, Hz."""
    return 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def estimate_series(flt, t, estimate: Estimate, gyro) -> ImuSeries:
    """The ``/estimate/imu`` content of an estimate: attitude, covariance, bias-corrected rate."""
    rate = gyro - estimate.gyro_bias if estimate.gyro_bias is not None else None
    return ImuSeries(t=t, q_wb=estimate.q_wb, omega_b=rate, q_wb_covariance=estimate.q_wb_covariance)


def estimate_log(path, out, *, filter_name: str = "mekf", use_mag: bool | None = None) -> EstimateSummary:
    """Filter every device of the log ``path`` and write the log with ``/estimate/imu`` to ``out``.

    ``use_mag`` None: 9D where the device has a magnetometer. Raises :class:`LogError` for a log the
    filter cannot use (see :func:`check_samples`) and ``FilterError`` for an unknown filter.
    """
    log = read_mcap(path)
    recordings, done = [], []
    for name, dev in log.devices.items():
        samples = dev.samples
        check_samples(path, name, samples.t, samples.gyro, samples.accel)
        nine = samples.has_mag if use_mag is None else (use_mag and samples.has_mag)
        setup = setup_from_metadata(dev.metadata, rate_of(samples.t), use_mag=nine)
        flt = make_filter(filter_name, setup)
        t_rel = samples.t - samples.t[0]  # relative times keep float64's resolution for the filter
        est = flt.process(t_rel, samples.gyro, samples.accel, samples.mag if nine else None)
        meta = dev.metadata or {}
        extra = {k: v for k, v in meta.items()
                 if k not in ("version", "seed", "scenario", "device", "device_name", "topic_prefix")}
        extra["estimate_filter"] = getattr(flt, "name", filter_name)
        recordings.append(Recording(
            samples=samples, truth=dev.truth, estimate=estimate_series(flt, samples.t, est, samples.gyro),
            device=meta.get("device") or None, seed=int(meta["seed"]) if meta.get("seed") else None,
            movement=dev.movement, metadata=extra, stamp_ns=dev.stamp_ns))
        done.append((name, len(samples), getattr(flt, "name", filter_name), nine))
    scenario_text = next((m.get("scenario") for m in log.metadata if m.get("scenario")), None)
    with McapLogWriter(out, scenario=scenario_text, prefix_topics=len(recordings) > 1) as writer:
        writer.write(*recordings)
    return EstimateSummary(path=Path(out), devices=done)

