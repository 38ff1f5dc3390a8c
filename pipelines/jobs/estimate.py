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

from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.estimation.series import check_samples, estimate_series, rate_of
from gyroemu.pipelines.estimation.setup import setup_from_metadata
from gyroemu.pipelines.formats.mcap_log import METADATA_KEYS, McapLogWriter, Recording, read_mcap

__all__ = ["EstimateSummary", "estimate_log"]


@dataclass(frozen=True)
class EstimateSummary:
    """What :func:`estimate_log` did, per device: ``(name, samples, filter name, 9D?)``."""

    path: Path
    devices: list


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
