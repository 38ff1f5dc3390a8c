"""Pictures of logs: ``gyroemu estimate --plot`` and ``gyroemu info --plot``.

Both read the log they draw, so a picture shows what the file holds, and write one PNG beside it
(matplotlib, Agg backend, imported when drawing). They read it a chunk at a time, in memory that does
not grow with the log: each series goes into a :class:`~gyroemu.pipelines.jobs.plot_envelope.Envelope`,
every sample of a short log, the min–max envelope of columns of time of a long one (``buckets``
columns); the error's RMS is summed as it goes. A log whose devices one pass cannot find
(:class:`~gyroemu.pipelines.formats.device_stream.NotStreamable`) is read whole
(:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap`) into the same envelopes.

- :func:`plot_estimate`: per device with an ``/estimate/imu``, the estimated roll, pitch and yaw against
  the truth's (``/truth/imu``; Tait–Bryan z-y'-x'' angles of ``q_wb``, REP 103), the attitude error over
  time (the angle of ``q_true⁻¹ ⊗ q_est``, the same for every Euler convention), and the gyro bias the
  filter estimated where it gives one (``/imu`` rate less ``/estimate/imu``'s bias-corrected rate, in
  body axes: a gyroemu device's ``/imu`` turned by its mounting, as its estimate is).
- :func:`plot_info`: per device, each IMU topic's series: ``/imu`` rate and specific force, and
  ``/mag`` where there is one.

The estimate's error and bias are drawn where the estimate has a truth, or a measurement, at the same
stamp (matched by stamp as the log goes by).

Time axes are seconds from the device's first stamp.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from gyroemu.pipelines.formats.atomic import write_figure_atomic
from gyroemu.pipelines.formats.messages import DecodedBatch
from gyroemu.pipelines.jobs.plot_envelope import Envelope

if TYPE_CHECKING:
    from gyroemu.pipelines.formats.device_stream import StreamDevice

_T = TypeVar("_T")

__all__ = ["BUCKETS", "EstimateCurves", "InfoCurves", "StampMatch", "attitude_error_deg", "estimate_curves"]
__all__ += ["estimate_plot_path", "euler_zyx_deg", "info_curves", "info_plot_path", "plot_estimate", "plot_info"]

BUCKETS = 2000
"""Columns of time of a long log's curves (a figure 7 inches wide at 110 dpi has 770 pixels)."""


def estimate_plot_path(path: str | os.PathLike[str]) -> Path:
    """Where :func:`plot_estimate` draws the log ``path`` by default: beside it, ``.estimate.png``."""
    return Path(path).with_suffix(".estimate.png")


def info_plot_path(path: str | os.PathLike[str]) -> Path:
    """Where :func:`plot_info` draws the log ``path`` by default: beside it, ``.info.png``."""
    return Path(path).with_suffix(".info.png")


def euler_zyx_deg(q_wb: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (N, 3), degrees, of unit quaternions ``q_wb`` (N, 4) (w, x, y, z): the intrinsic
    z-y'-x'' angles, ``R = R_z(yaw) R_y(pitch) R_x(roll)``."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_wb, dtype=float)
    out = np.full((len(q), 3), np.nan)
    ok = np.all(np.isfinite(q), axis=1)
    if ok.any():
        yaw_pitch_roll = Rotation.from_quat(q[ok][:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)
        out[ok] = yaw_pitch_roll[:, ::-1]
    return out


def attitude_error_deg(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Angle (N,) of the rotation between two attitudes, degrees: ``2 atan2(|v|, |w|)`` of
    ``q_true⁻¹ ⊗ q_est`` (sign-free; exact at small angles)."""
    a = np.asarray(q_true, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])
    b = np.asarray(q_est, dtype=float)
    w = a[:, 0] * b[:, 0] - np.sum(a[:, 1:] * b[:, 1:], axis=1)
    v = a[:, :1] * b[:, 1:] + b[:, :1] * a[:, 1:] + np.cross(a[:, 1:], b[:, 1:])
    angle: np.ndarray = np.degrees(2 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w)))
    return angle


def _pyplot() -> ModuleType:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


class StampMatch:
    """Rows of two topics with equal stamps, as a log goes by (each topic's stamps increasing): a row
    waits while the other topic has not yet gone past its stamp, and is dropped once it has, or once
    the other topic has ended (:meth:`end`). A side may be told only its stamps (``values`` None:
    messages without the quantity), which moves it on. Of rows with the same stamp, the first matches."""

    _NONE = np.iinfo(np.int64).min
    _ENDED = np.iinfo(np.int64).max

    def __init__(self) -> None:
        self.waiting: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]
        self.last = [self._NONE, self._NONE]  # the last stamp each side has shown, ns

    def add(self, side: int, stamp_ns: np.ndarray, values: np.ndarray | None) -> None:
        """Side ``side`` (0 or 1)'s next rows: ``stamp_ns`` (n,) int64, increasing; ``values`` (n, ...)."""
        if len(stamp_ns):
            self.last[side] = max(self.last[side], int(stamp_ns[-1]))
        if values is None:
            return
        held = self.waiting[side]
        if held is not None:
            stamp_ns, values = np.concatenate((held[0], stamp_ns)), np.concatenate((held[1], values))
        self.waiting[side] = (stamp_ns, values)

    def end(self, side: int) -> None:
        """Side ``side`` has shown every row: nothing of the other side waits for it any more."""
        self.last[side] = self._ENDED

    def take(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(stamps, values of side 0, of side 1)`` matched since the last call; the rows the other side
        has gone past without a match are dropped."""
        a, b = self.waiting
        common, ia, ib = np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0, np.int64)
        if a is not None and b is not None:  # a stamp twice on a side: its first row (intersect1d's indices)
            common, ia, ib = np.intersect1d(a[0], b[0], return_indices=True)
        matched = (a[1][ia] if a is not None else np.empty(0), b[1][ib] if b is not None else np.empty(0))
        for side, (rows, used) in enumerate(((a, ia), (b, ib))):
            if rows is not None:
                keep = rows[0] > self.last[1 - side]  # a row the other side has gone past never matches
                keep[used] = False
                self.waiting[side] = (rows[0][keep], rows[1][keep])
        return common, matched[0], matched[1]


class EstimateCurves:
    """What :func:`plot_estimate` draws of a device (times in s, absolute; ``t0`` the first sample's),
    fed a block of one of its topics at a time by :meth:`add`.

    ``angles`` and ``true_angles``: roll, pitch, yaw, °; ``error``: the attitude error, °, where the
    truth has the estimate's stamp, with its ``rms`` and ``final`` (None: no such stamp); ``bias``: the
    gyro bias the estimate implies, °/h (``/imu`` rate less ``/estimate/imu``'s bias-corrected rate at
    the same stamp; empty where the estimate has no rate), in body axes: with the device's mounting
    ``q_bs`` (4,) (a gyroemu log's, :func:`~gyroemu.pipelines.estimation.mounting.mounting_from_metadata`;
    None: none) the ``/imu`` rate is turned by ``R(q_bs)`` as ``gyroemu estimate`` turned the estimate's.
    ``has_truth``, ``has_imu``: whether the log has those topics (without one, nothing waits for it)."""

    def __init__(
        self,
        name: str,
        buckets: int = BUCKETS,
        *,
        has_truth: bool = True,
        has_imu: bool = True,
        q_bs: np.ndarray | None = None,
    ):
        self.name = name
        self.q_bs = q_bs
        self.t0: float | None = None
        self.angles, self.true_angles = Envelope(3, buckets), Envelope(3, buckets)
        self.error, self.bias = Envelope(1, buckets), Envelope(3, buckets)
        self.sum_squares, self.finite = 0.0, 0
        self.final: float | None = None
        self._errors = StampMatch() if has_truth else None  # estimate (0) against truth (1)
        self._biases = StampMatch() if has_imu else None  # estimate (0) against /imu (1)

    @property
    def rms(self) -> float | None:
        """The error's RMS over its finite values, ° (None: no error)."""
        return float(np.sqrt(self.sum_squares / self.finite)) if self.finite else None

    def add(self, role: str, stamp_ns: np.ndarray, q_wb: np.ndarray | None, omega_b: np.ndarray | None) -> None:
        """The next block of the device's topic ``role`` (``imu``, ``truth/imu``, ``estimate/imu``):
        stamps (n,) int64 ns, increasing; attitudes (n, 4) and rates (n, 3), rad/s, or None."""
        from gyroemu.pipelines.formats.channels import ESTIMATE_ROLE, IMU_ROLE, TRUTH_ROLE
        from gyroemu.pipelines.formats.messages import ns_to_stamps

        n, t = len(stamp_ns), ns_to_stamps(stamp_ns)
        if role == IMU_ROLE:
            self.t0 = float(t[0]) if self.t0 is None and n else self.t0
            if self.q_bs is not None and omega_b is not None:
                from gyroemu.pipelines.estimation.mounting import body_vectors

                omega_b = body_vectors(omega_b, self.q_bs)  # ω_b = R(q_bs) ω_s: the estimate's axes
            if self._biases is not None:
                _add_finite(self._biases, 1, stamp_ns, omega_b)
        elif role == TRUTH_ROLE:
            if q_wb is not None:
                self.true_angles.add(t, euler_zyx_deg(q_wb))
            if self._errors is not None:
                _add_finite(self._errors, 1, stamp_ns, q_wb)
        elif role == ESTIMATE_ROLE:
            self.angles.add(t, euler_zyx_deg(_nan_if_none(q_wb, n, 4)))
            if self._errors is not None:
                _add_finite(self._errors, 0, stamp_ns, q_wb)
            if self._biases is not None:
                _add_finite(self._biases, 0, stamp_ns, omega_b)
        self._take()

    def end(self, role: str) -> None:
        """The device's topic ``role`` has given every message: nothing waits for it any more."""
        from gyroemu.pipelines.formats.channels import ESTIMATE_ROLE, IMU_ROLE, TRUTH_ROLE

        ends: dict[str, list[tuple[StampMatch | None, int]]] = {
            TRUTH_ROLE: [(self._errors, 1)],
            IMU_ROLE: [(self._biases, 1)],
            ESTIMATE_ROLE: [(self._errors, 0), (self._biases, 0)],
        }
        for match, side in ends.get(role, []):
            if match is not None:
                match.end(side)
        self._take()

    def _take(self) -> None:
        from gyroemu.pipelines.formats.messages import ns_to_stamps

        if self._errors is not None:
            stamps, q_est, q_true = self._errors.take()
            if len(stamps):
                self._add_error(ns_to_stamps(stamps), attitude_error_deg(q_true, q_est))
        if self._biases is not None:
            stamps, omega, gyro = self._biases.take()
            if len(stamps):
                self.bias.add(ns_to_stamps(stamps), np.degrees(gyro - omega) * 3600.0)

    def _add_error(self, t: np.ndarray, error: np.ndarray) -> None:
        self.error.add(t, error[:, None])
        ok = np.isfinite(error)
        self.sum_squares += float(np.sum(error[ok] ** 2))
        self.finite += int(ok.sum())
        if len(error):
            self.final = float(error[-1])


class InfoCurves:
    """What :func:`plot_info` draws of a device: its ``/imu`` rate (°/s) and specific force (m/s²), its
    ``/mag`` field (µT; empty without one), times in s, absolute; ``t0`` the first sample's."""

    def __init__(self, name: str, topics: dict[str, str], buckets: int = BUCKETS):
        self.name, self.topics = name, topics
        self.t0: float | None = None
        self.rate, self.force, self.field = Envelope(3, buckets), Envelope(3, buckets), Envelope(3, buckets)

    def add_imu(self, t: np.ndarray, gyro: np.ndarray | None, accel: np.ndarray | None) -> None:
        """The next ``/imu`` samples: stamps (n,) s, rates (n, 3) rad/s and forces (n, 3) m/s² (None: NaN)."""
        n = len(t)
        self.t0 = float(t[0]) if self.t0 is None and n else self.t0
        self.rate.add(t, np.degrees(_nan_if_none(gyro, n, 3)))
        self.force.add(t, _nan_if_none(accel, n, 3))

    def add_field(self, t: np.ndarray, magnetic_field: np.ndarray) -> None:
        """The field at the next samples, as the filters see it (``/mag`` at the ``/imu`` stamps, NaN where
        it has no message there): stamps (n,) s, field (n, 3) T; the rows with a field are drawn."""
        ok = np.isfinite(magnetic_field).all(axis=1)
        self.field.add(t[ok], np.asarray(magnetic_field)[ok] * 1e6)


def _nan_if_none(values: ArrayLike | None, n: int, width: int) -> np.ndarray:
    return np.full((n, width), np.nan) if values is None else np.asarray(values, dtype=float)


def _add_finite(match: StampMatch, side: int, stamp_ns: np.ndarray, values: np.ndarray | None) -> None:
    """A side's stamps, and its rows whose values are finite: a row without the quantity matches nothing,
    whether its message says so for the whole topic, for a chunk or for itself."""
    match.add(side, stamp_ns, None)
    if values is not None:
        ok = np.isfinite(values).all(axis=1)
        match.add(side, stamp_ns[ok], np.asarray(values, dtype=float)[ok])


def _quietly(function: Callable[..., _T], *args: object) -> _T:
    import warnings

    from gyroemu.pipelines.formats.mcap_log import LogWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)
        return function(*args)


def _stream_devices(path: Path, read_whole: bool) -> dict[str, StreamDevice] | None:
    """The log's devices for reading it a chunk at a time (:func:`scan_devices`), or None: asked to
    read it whole, or a log one pass cannot pair (:class:`NotStreamable`)."""
    from gyroemu.pipelines.formats.device_stream import NotStreamable, scan_devices

    if read_whole:
        return None
    try:
        return _quietly(scan_devices, path)[0]
    except NotStreamable:
        return None


def _float_ns(stamp_ns: np.ndarray) -> np.ndarray:
    """Stamps as the log read whole has them: through float seconds (two stamps closer than a float's
    resolution, 0.24 µs at today's epoch, become one), so that both reads match the same rows."""
    from gyroemu.pipelines.formats.messages import ns_to_stamps, stamps_to_ns

    return stamps_to_ns(ns_to_stamps(stamp_ns))


class _Topic:
    """A topic of a device read a chunk at a time in :func:`read_mcap`'s order, its stamps increasing
    (:class:`NotStreamable` otherwise: the whole read pairs it), its end known from the scan's count."""

    def __init__(self, channel: tuple[int, Any], count: int) -> None:
        self.channel_id, self.mtype = channel
        self.count, self.read = count, 0
        self.log_time, self.stamp = -1, -(1 << 62)  # below any stamp, and no overflow in a difference

    def rows(self, batch: Any) -> DecodedBatch | None:
        from gyroemu.pipelines.formats.device_stream import read_topic

        got = read_topic(batch, self.channel_id, self.mtype, self.log_time, self.stamp)
        if got is None:
            return None
        decoded, self.log_time = got
        self.stamp = int(decoded.stamp_ns[-1])
        self.read += len(decoded.stamp_ns)
        return decoded

    @property
    def ended(self) -> bool:
        return self.read == self.count


def _walk_devices(
    path: Path, devices: dict[str, StreamDevice], roles: tuple[str, ...]
) -> Iterator[tuple[str, str, Any]]:
    """Per device name, its samples a block at a time as :func:`read_mcap` pairs them (``"samples"``: the
    raw topics' drops, the field at each sample's stamp) and its topics of ``roles`` a chunk at a time
    (a ``DecodedBatch``), each followed by None once it has ended."""
    from gyroemu.pipelines.formats.device_stream import DeviceStream
    from gyroemu.pipelines.formats.mcap_records import McapRecordWalk

    streams = {name: DeviceStream(d.channels, messages=d.messages) for name, d in devices.items()}
    topics = {
        (name, role): _Topic(d.channels[role], d.messages.get(role, 0))
        for name, d in devices.items()
        for role in roles
        if role in d.channels
    }
    for batch in McapRecordWalk(path).batches():
        for (name, role), topic in topics.items():
            decoded = topic.rows(batch)
            if decoded is not None:
                yield name, role, decoded
                if topic.ended:
                    yield name, role, None
        for name, stream in streams.items():
            stream.feed(batch)
            yield name, "samples", stream.take()
    for name, stream in streams.items():
        yield name, "samples", stream.take(final=True)
        yield name, "samples", None


def estimate_curves(
    path: str | os.PathLike[str], buckets: int = BUCKETS, *, read_whole: bool = False
) -> list[EstimateCurves]:
    """The curves :func:`plot_estimate` draws, per device with an ``/estimate/imu`` that holds an
    attitude, from one pass over the log after the one that finds its devices (module's notes);
    ``read_whole``: from the log read whole (the same curves)."""
    from gyroemu.pipelines.estimation.mounting import mounting_from_metadata
    from gyroemu.pipelines.formats.channels import ESTIMATE_ROLE, IMU_ROLE, TRUTH_ROLE, series_from_batch
    from gyroemu.pipelines.formats.device_stream import NotStreamable

    path = Path(path)
    devices = _stream_devices(path, read_whole)
    if devices is None:
        return _estimate_curves_whole(path, buckets)
    devices = {name: d for name, d in devices.items() if ESTIMATE_ROLE in d.channels}
    curves = {
        name: EstimateCurves(name, buckets, has_truth=TRUTH_ROLE in d.channels, q_bs=mounting_from_metadata(d.metadata))
        for name, d in devices.items()
    }
    try:
        for name, role, rows in _walk_devices(path, devices, (TRUTH_ROLE, ESTIMATE_ROLE)):
            c = curves[name]
            if rows is None:
                c.end(IMU_ROLE if role == "samples" else role)
            elif role == "samples":
                if len(rows):
                    c.add(IMU_ROLE, _float_ns(rows.stamp_ns), None, rows.gyro)
            else:
                series = series_from_batch(rows)
                c.add(role, _float_ns(rows.stamp_ns), series.q_wb, series.omega_b)
    except NotStreamable:
        return _estimate_curves_whole(path, buckets)
    return [c for c in curves.values() if np.isfinite(c.angles.columns()[1]).any()]


def _estimate_curves_whole(path: Path, buckets: int) -> list[EstimateCurves]:
    """:func:`estimate_curves` of a log read whole (:func:`read_mcap`): each series as one block."""
    from gyroemu.pipelines.estimation.mounting import mounting_from_metadata
    from gyroemu.pipelines.formats.channels import ESTIMATE_ROLE, IMU_ROLE, TRUTH_ROLE
    from gyroemu.pipelines.formats.mcap_log import read_mcap
    from gyroemu.pipelines.formats.messages import stamps_to_ns

    log = _quietly(read_mcap, path)
    out = []
    for dev in log.devices.values():
        est, truth, s = dev.estimate, dev.truth, dev.samples
        if est is None or est.q_wb is None:
            continue
        c = EstimateCurves(dev.name, buckets, has_truth=truth is not None, q_bs=mounting_from_metadata(dev.metadata))
        c.add(IMU_ROLE, stamps_to_ns(s.t), None, s.gyro)
        c.add(ESTIMATE_ROLE, stamps_to_ns(est.t), est.q_wb, est.omega_b)
        if truth is not None:
            c.add(TRUTH_ROLE, stamps_to_ns(truth.t), truth.q_wb, None)
        out.append(c)
    return out


def plot_estimate(
    path: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    buckets: int = BUCKETS,
    read_whole: bool = False,
) -> Path:
    """Draw the estimate of the log ``path`` against its truth into ``out`` (default: ``path`` with
    ``.estimate.png``); returns the file written. ``ValueError`` when no device of the log has an
    ``/estimate/imu``. ``buckets``, ``read_whole``: :func:`estimate_curves`'."""
    path = Path(path)
    out = Path(out) if out is not None else estimate_plot_path(path)
    devices = estimate_curves(path, buckets, read_whole=read_whole)
    if not devices:
        raise ValueError(f"{path}: no /estimate/imu to draw")
    plt = _pyplot()
    rows = 5
    fig, axes = plt.subplots(rows, len(devices), figsize=(7 * len(devices), 12), sharex="col", squeeze=False)
    for column, c in enumerate(devices):
        t0 = c.t0 if c.t0 is not None else (c.angles.t0 or 0.0)
        for k, name in enumerate(("roll", "pitch", "yaw")):
            ax = axes[k, column]
            if len(c.true_angles):
                c.true_angles.draw(ax, channels=[k], labels=["truth"], colors=["0.3"], t_offset=t0, lw=1.2)
            c.angles.draw(ax, channels=[k], labels=["estimate"], colors=["C0"], t_offset=t0, lw=0.9)
            ax.set_ylabel(f"{name}, °")
            ax.grid(alpha=0.3)
        axes[0, column].set_title(f"{c.name}: estimate against the truth")
        axes[0, column].legend(loc="upper right", fontsize=8)
        ax = axes[3, column]
        if len(c.error):
            c.error.draw(ax, colors=["C3"], t_offset=t0, lw=0.9)
            final = c.final if c.final is not None else float("nan")
            rms = c.rms if c.rms is not None else float("nan")
            ax.set_title(f"attitude error: RMS {rms:.3g}°, final {final:.3g}°", fontsize=9)
        else:
            ax.text(0.5, 0.5, "no truth at the estimate's stamps", ha="center", va="center", transform=ax.transAxes)
        ax.set_ylabel("error, °")
        ax.grid(alpha=0.3)
        ax = axes[4, column]
        if len(c.bias):
            c.bias.draw(ax, labels=["bx", "by", "bz"], t_offset=t0, lw=0.9)
            ax.legend(loc="upper right", fontsize=8)
        else:
            ax.text(0.5, 0.5, "the filter gives no bias", ha="center", va="center", transform=ax.transAxes)
        ax.set_ylabel("gyro bias, °/h")
        ax.set_xlabel("time, s")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return write_figure_atomic(fig, out, dpi=110)  # whole or not at all; closes the figure


def info_curves(path: str | os.PathLike[str], buckets: int = BUCKETS, *, read_whole: bool = False) -> list[InfoCurves]:
    """The curves :func:`plot_info` draws, per device, from one pass over the log after the one that
    finds its devices (module's notes): its samples as :func:`read_mcap` pairs them; ``read_whole``: from
    the log read whole (the same curves)."""
    from gyroemu.pipelines.formats.device_stream import NotStreamable
    from gyroemu.pipelines.formats.messages import ns_to_stamps

    path = Path(path)
    devices = _stream_devices(path, read_whole)
    if devices is None:
        return _info_curves_whole(path, buckets)
    curves = {name: InfoCurves(name, dict(d.topics), buckets) for name, d in devices.items()}
    try:
        for name, _, block in _walk_devices(path, devices, ()):
            if block is not None and len(block):
                t = ns_to_stamps(block.stamp_ns)
                curves[name].add_imu(t, block.gyro, block.accel)
                curves[name].add_field(t, block.mag)
    except NotStreamable:
        return _info_curves_whole(path, buckets)
    return list(curves.values())


def _info_curves_whole(path: Path, buckets: int) -> list[InfoCurves]:
    """:func:`info_curves` of a log read whole (:func:`read_mcap`): each series as one block."""
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    log = _quietly(read_mcap, path)
    out = []
    for dev in log.devices.values():
        s = dev.samples
        c = InfoCurves(dev.name, dict(dev.topics), buckets)
        c.add_imu(s.t, s.gyro, s.accel)
        c.add_field(s.t, s.mag)
        out.append(c)
    return out


def plot_info(
    path: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    buckets: int = BUCKETS,
    read_whole: bool = False,
) -> Path:
    """Draw each IMU topic's series of the log ``path`` (per device: rate, specific force, field) into
    ``out`` (default: ``path`` with ``.info.png``); returns the file written. ``buckets``,
    ``read_whole``: :func:`info_curves`'."""
    path = Path(path)
    out = Path(out) if out is not None else info_plot_path(path)
    devices = info_curves(path, buckets, read_whole=read_whole)
    plt = _pyplot()
    fig, axes = plt.subplots(3, len(devices), figsize=(7 * len(devices), 9), sharex="col", squeeze=False)
    for column, c in enumerate(devices):
        t0 = c.t0 if c.t0 is not None else 0.0
        panels = (
            (c.rate, "rate, °/s", c.topics.get("imu", "/imu")),
            (c.force, "specific force, m/s²", c.topics.get("imu", "/imu")),
            (c.field if len(c.field) else None, "field, µT", c.topics.get("mag", "/mag")),
        )
        for row, (values, label, topic) in enumerate(panels):
            ax = axes[row, column]
            if values is None:
                ax.text(0.5, 0.5, "no magnetometer", ha="center", va="center", transform=ax.transAxes)
            else:
                values.draw(ax, labels=list("xyz"), t_offset=t0, lw=0.7)
                ax.legend(loc="upper right", fontsize=8)
            ax.set_ylabel(label)
            ax.set_title(f"{c.name}: {topic}", fontsize=9)
            ax.grid(alpha=0.3)
        axes[-1, column].set_xlabel("time, s")
    fig.tight_layout()
    return write_figure_atomic(fig, out, dpi=110)  # whole or not at all; closes the figure
