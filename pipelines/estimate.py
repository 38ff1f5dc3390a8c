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

from .channels import ImuSeries
from .estimation.protocol import Estimate
from .estimation.registry import make_filter
from .estimation.setup import setup_from_metadata
from .mcap_log import METADATA_KEYS, McapLogWriter, Recording, read_mcap
from .mcap_records import LogError

__all__ = ["EstimateSummary", "estimate_log", "estimate_series", "check_samples"]


@dataclass(frozen=True)
class EstimateSummary:
    """What :func:`estimate_log` did, per device: ``(name, samples, filter name, 9D?)``."""

    path: Path
    devices: list


def check_samples(path, name: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> str | None:
    """Refuse samples a filter cannot run on, naming the file (:class:`LogError`): fewer than two,
    stamps that do not increase, or NaN everywhere. Some NaN samples are usable (the filters skip
    them): returns a note saying how many, None when there are none."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        raise LogError(f"device '{name}' has {len(t)} IMU sample(s): too few to run a filter", file=path)
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if len(bad):
        k = int(bad[0]) + 1
        raise LogError(
            f"IMU stamps of device '{name}' are not increasing: sample {k} at {t[k]:.9f} s follows "
            f"{t[k - 1]:.9f} s ({len(bad)} such steps)",
            file=path,
        )
    finite = np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)
    if not finite.any():
        raise LogError(f"every IMU sample of device '{name}' holds NaN", file=path)
    if finite.all():
        return None
    return (
        f"{int((~finite).sum())} of {len(t)} IMU samples of device '{name}' hold NaN; they are passed to the "
        "filters as they are (the built-in filters hold their estimate over them)"
    )


def rate_of(t: np.ndarray) -> float:
    """The nominal sample rate of stamps ``t``: the inverse of the median interval, Hz."""
    return 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def estimate_series(t, estimate: Estimate, gyro) -> ImuSeries:
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
        note = check_samples(path, name, samples.t, samples.gyro, samples.accel)
        if note:
            warnings.warn(f"{path}: {note}", UserWarning, stacklevel=2)
        nine = samples.has_mag if use_mag is None else (use_mag and samples.has_mag)
        setup = setup_from_metadata(dev.metadata, rate_of(samples.t), use_mag=nine)
        flt = make_filter(filter_name, setup)
        t_rel = samples.t - samples.t[0]  # relative times keep float64's resolution for the filter
        est = flt.process(t_rel, samples.gyro, samples.accel, samples.mag if nine else None)
        meta = dev.metadata or {}
        extra = {k: v for k, v in meta.items() if k not in METADATA_KEYS}
        extra["estimate_filter"] = getattr(flt, "name", filter_name)
        recordings.append(
            Recording(
                samples=samples,
                truth=dev.truth,
                estimate=estimate_series(samples.t, est, samples.gyro),
                device=meta.get("device") or None,
                seed=int(meta["seed"]) if meta.get("seed") else None,
                movement=dev.movement,
                metadata=extra,
                stamp_ns=dev.stamp_ns,
            )
        )
        done.append((name, len(samples), getattr(flt, "name", filter_name), nine))
    scenario_text = next((m.get("scenario") for m in log.metadata if m.get("scenario")), None)
    with McapLogWriter(out, scenario=scenario_text, prefix_topics=len(recordings) > 1) as writer:
        writer.write(*recordings)
    return EstimateSummary(path=Path(out), devices=done)
