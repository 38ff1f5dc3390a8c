"""A real recording as ``gyroemu twin`` holds it beside its twins: the samples, the truth at them, the
samples that count, and the rest phases its residuals are taken over.

Inputs: a BROAD trial (``.hdf5``: IMU, magnetometer in µT, optical attitude and position, ``movement``
mask) or a gyroemu MCAP log (one device with ``/imu``, ``/truth/imu`` and usually ``/truth/pose``; its
``/movement`` mask when it has one, otherwise every sample counts). Times are the motion's clock (BROAD:
``k / sampling_rate``; MCAP: the stamps less the first truth stamp), the recorded scenario's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "RECORDING_FORMATS",
    "Recording",
    "RecordingError",
    "load_recording",
    "longest_run",
    "measured_field",
    "rest_phases",
]

RECORDING_FORMATS = {".hdf5": "broad", ".h5": "broad", ".mcap": "mcap"}
"""File suffix → the ``recorded`` scenario's ``format``."""


class RecordingError(ValueError):
    """A recording a twin cannot be made of (the caller names the file)."""


@dataclass
class Recording:
    """A real recording, as the filters and the residuals need it (times in the motion's clock)."""

    name: str
    path: Path
    format: str
    t: np.ndarray  # (N,) s, recording clock (BROAD k/fs; MCAP stamps − first truth stamp)
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray | None  # tesla
    q_true: np.ndarray  # (N, 4), NaN rows without reference
    mask: np.ndarray  # (N,) bool: samples that count
    rate_hz: float
    metadata: dict[str, Any] | None
    counted: str
    omega_true: np.ndarray | None = None  # (N, 3) rad/s, a log's /truth/imu rate
    force_true: np.ndarray | None = None  # (N, 3) m/s², a log's /truth/imu specific force
    same_name_index: int = 0  # recordings of the same file name before it in the run (its twins' seeds)


def measured_field(mag_t: np.ndarray) -> np.ndarray | None:
    """The magnetometer ``mag_t`` (N, 3) T, or None when no row of it is finite (a recording without a
    magnetometer: its filters run 6D only)."""
    return mag_t if np.isfinite(mag_t).all(axis=1).any() else None


def load_recording(path: Path) -> Recording:
    """A recording (errors name the file)."""
    fmt = RECORDING_FORMATS[path.suffix.lower()]
    if fmt == "broad":
        from gyroemu.pipelines.formats.importers import read_broad

        trial = read_broad(path)
        t = np.arange(len(trial)) / trial.rate_hz
        mask = np.asarray(trial.movement, bool)
        return Recording(
            name=path.name,
            path=path,
            format=fmt,
            t=t,
            gyro=np.asarray(trial.gyro, float),
            accel=np.asarray(trial.accel, float),
            mag=measured_field(np.asarray(trial.mag_ut, float) * 1e-6),
            q_true=np.asarray(trial.opt_quat, float),
            mask=mask if mask.any() else np.ones(len(t), bool),
            rate_hz=float(trial.rate_hz),
            metadata=None,
            counted="movement mask" if mask.any() else "every sample",
        )
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    log = read_mcap(path)
    if len(log.devices) != 1:
        raise RecordingError(f"holds {len(log.devices)} devices; a twin needs exactly one")
    dev = log.device
    if dev.truth is None or dev.truth.q_wb is None:
        raise RecordingError("has no /truth/imu attitude")
    s = dev.samples
    tt = np.asarray(dev.truth.t, float)
    t = np.asarray(s.t, float)
    if len(t) < 2 or len(tt) < 2:  # no sample interval, hence no rate
        raise RecordingError(f"holds {len(t)} sample(s) and {len(tt)} truth sample(s): a twin needs many")
    from gyroemu.errors import LogError
    from gyroemu.pipelines.estimation.series import check_samples

    try:  # stamps that do not increase, or no sample without NaN (the twin interpolated nothing: a traceback)
        check_samples(path, dev.name, t, s.gyro, s.accel)
    except LogError as e:
        raise RecordingError(e.reason) from None
    # the motion file's clock (read_mcap_motion): from the first truth stamp, exactly where the truth is
    # at the samples' stamps (float seconds since the epoch resolve 0.24 µs: a 1 kHz log read 1000.07 Hz)
    clock = dev.seconds_from_first() if np.array_equal(tt, t) else t - tt[0]
    dt = float(np.median(np.diff(clock)))
    j = np.clip(np.searchsorted(tt, t), 1, len(tt) - 1)
    j = np.where(np.abs(tt[j - 1] - t) <= np.abs(tt[j] - t), j - 1, j)
    hit = np.abs(tt[j] - t) <= 0.25 * dt
    q_true = np.full((len(t), 4), np.nan)
    q_true[hit] = dev.truth.q_wb[j[hit]]

    def at_samples(attribute: str) -> np.ndarray | None:
        """The truth's (N, 3) ``attribute`` at the samples it meets (NaN elsewhere); None if it has none."""
        v = getattr(dev.truth, attribute, None)
        if v is None or not np.isfinite(v).any():
            return None
        column = np.full((len(t), 3), np.nan)
        column[hit] = np.asarray(v, float)[j[hit]]
        return column

    movement = getattr(dev, "movement", None)
    has_mask = movement is not None and np.asarray(movement, bool).any()
    return Recording(
        name=path.name,
        path=path,
        format=fmt,
        t=clock,
        gyro=np.asarray(s.gyro, float),
        accel=np.asarray(s.accel, float),
        mag=measured_field(np.asarray(s.mag, float)),
        q_true=q_true,
        mask=np.asarray(movement, bool) if has_mask else np.ones(len(t), bool),
        rate_hz=1.0 / dt,
        metadata=dev.metadata,
        counted="movement mask" if has_mask else "every sample",
        omega_true=at_samples("omega_b"),
        force_true=at_samples("specific_force_b"),
    )


def rest_phases(real: Recording) -> tuple[list[slice], dict[str, Any]]:
    """The rest phases of the real recording with a reference (each trimmed to it, at least 64 samples):
    (their samples, a description). The rest detector's threshold is relative to the recording's
    quietest stretch, so in a recording with a movement mask a phase is also trimmed to its longest run
    outside the mask (a recording that moves throughout has quiet motion, not rest). Without any, the
    samples before the first movement sample stand in for the residuals (``intervals_s``), but only
    phases found still are held still in the twins (``still_s``). A recording that moves from its first
    sample has none: its residuals are then taken over the whole recording if it has its own truth rate
    and specific force (a simulated log: the sensor's output less the truth, in motion as at rest, the
    real side at the stamp, so a latency L adds ω̇ L there), and not at all otherwise (rest's truth,
    ω = 0 and constant gravity, would be the motion itself)."""
    from gyroemu.pipelines.identification import find_rest_phases

    valid = np.isfinite(real.q_true).all(axis=1)
    if real.counted == "movement mask":
        valid &= ~real.mask
    rests = []
    for p in find_rest_phases(real.t, real.gyro, real.accel):
        run = longest_run(valid[p.start : p.stop])  # the phase's span with a reference (and still)
        if run is not None and run[1] - run[0] >= 64:
            rests.append(slice(p.start + run[0], p.start + run[1]))
    if rests:
        intervals = [(float(real.t[r.start]), float(real.t[r.stop - 1])) for r in rests]
        return rests, {"source": f"{len(rests)} rest phase(s)", "intervals_s": intervals, "still_s": intervals}
    first = np.flatnonzero(real.mask)
    stop = int(first[0]) if len(first) else len(real.t)
    source = "samples before the first movement sample"
    if stop == 0:
        if real.omega_true is None or real.force_true is None:
            return [], {"source": "none: the recording moves from its first sample", "intervals_s": [], "still_s": []}
        stop, source = len(real.t), "the whole recording, less its own truth (it moves from its first sample)"
    idx = np.flatnonzero(np.isfinite(real.q_true).all(axis=1)[:stop])
    if not len(idx):
        return [], {"source": "none: no reference before the first movement sample", "intervals_s": [], "still_s": []}
    start = int(idx[0])
    return [slice(start, stop)], {
        "source": source,
        "intervals_s": [(float(real.t[start]), float(real.t[stop - 1]))],
        "still_s": [],  # not found still: the twins' motion is not held there
    }


def longest_run(flags: np.ndarray) -> tuple[int, int] | None:
    """(start, stop) of the longest run of True in ``flags`` (the first of equal ones); None without any."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flags.astype(np.int8), [0]))))
    if not len(edges):
        return None
    starts, stops = edges[0::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])
