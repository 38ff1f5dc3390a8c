"""``gyroemu allan``: fit the IEEE 952 noise terms to a static gyro log and draw the Allan plot.

:func:`allan_of_log` reads the log (an .mcap, or an .npz of ``gyroemu simulate``) and fits it;
:func:`write_allan_plot` draws the plot.

The fit is :func:`gyroemu.sensors.allan.fit_allan` over the overlapping Allan deviation, axis by axis.
:func:`allan_of_log` computes that deviation with
:class:`gyroemu.sensors.allan_stream.OverlappingAllanAccumulator`, fed the log a batch of samples at a
time, so the memory it needs does not grow with the log's length (a 12-hour run at hundreds of Hz);
:func:`allan_report` takes a record already in memory and uses ``allantools`` (``allan_deviation``).
The two agree to round-off for τ up to the accumulator's exact range (2^15 samples); beyond it the
streamed one is the overlapping estimator with a coarser overlap step (see that module).

The plot shows each axis's measured curve with its confidence band, the fitted model, and, when the
log carries its device's config, the specification's lines (quantisation, ARW, bias instability
floor, RRW) beside them.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from gyroemu.sensors.allan import AllanDeviation, AllanFit, allan_deviation, fit_allan
from gyroemu.sensors.allan_stream import OverlappingAllanAccumulator
from gyroemu.sensors.errors import ErrorModel

__all__ = [
    "AllanLogError",
    "AllanReport",
    "allan_report",
    "allan_of_log",
    "BATCH",
    "plot_allan",
    "write_allan_plot",
    "SPEC_UNITS",
]

_DEG = 180.0 / np.pi
SPEC_UNITS = {  # term: (SI to datasheet factor, datasheet unit)
    "quantisation": (1.0, "rad"),
    "arw": (_DEG * 60.0, "deg/sqrt(h)"),
    "bias_instability": (_DEG * 3600.0, "deg/h"),
    "rrw": (_DEG * 3600.0 * 60.0, "deg/h/sqrt(h)"),
    "rate_ramp": (_DEG * 3600.0 * 3600.0, "deg/h/h"),
}


@dataclass(frozen=True)
class AllanReport:
    """Fits of the three axes of a gyro log, and the specification they are compared with."""

    fits: tuple[AllanFit, AllanFit, AllanFit]
    spec: ErrorModel | None
    intrinsic_noise_density: float = 0.0

    def table(self) -> str:
        """A plain-text table: each term's fitted value per axis (datasheet units) and the spec."""
        lines = [f"{'term':<17}{'unit':<15}{'x':>12}{'y':>12}{'z':>12}{'spec':>12}"]
        specified = _spec_terms(self.spec) if self.spec is not None else {}
        for term, (factor, unit) in SPEC_UNITS.items():
            values = [getattr(f, term).value * factor for f in self.fits]
            spec = specified.get(term)
            spec_text = f"{spec * factor:12.4g}" if spec is not None else f"{'-':>12}"
            lines.append(f"{term:<17}{unit:<15}" + "".join(f"{v:12.4g}" for v in values) + spec_text)
        return "\n".join(lines)


def _spec_terms(spec: ErrorModel) -> dict:
    """The specification's Allan coefficients in SI (axis x; presets give the same for all axes)."""
    q = spec.integral_lsb / np.sqrt(12) if spec.integral_lsb else None
    return {
        "quantisation": q,
        "arw": float(spec.noise_density[0]),
        "bias_instability": float(spec.bias_instability[0]),
        "rrw": float(spec.random_walk[0]),
        "rate_ramp": float(spec.ramp[0]) or None,
    }


def allan_report(gyro: np.ndarray, dt: float, spec: ErrorModel | None = None) -> AllanReport:
    """Fit each axis of a static gyro record ``gyro`` (N, 3), rad/s, sampled every ``dt`` s."""
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < 64:
        raise ValueError(f"an Allan analysis needs a (N, 3) gyro record with N >= 64, got shape {gyro.shape}")
    if not np.all(np.isfinite(gyro)):
        raise ValueError("the gyro record has NaN or infinite samples")
    fits = cast(  # one per axis: three
        tuple[AllanFit, AllanFit, AllanFit],
        tuple(fit_allan(allan_deviation(gyro[:, i] - gyro[:, i].mean(), dt)) for i in range(3)),
    )
    return AllanReport(fits=fits, spec=spec)


class AllanLogError(ValueError):
    """A log :func:`allan_of_log` cannot analyse: missing, not a gyroemu log, no or too few gyro samples.
    The message starts with the file's name."""


BATCH = 1 << 16
"""Samples handed to the Allan accumulator at a time (at least: an .mcap's IMU messages are decoded a
file chunk at a time, and gathered until they reach it)."""

_MIN_SAMPLES = 64
_MAX_STEP_BINS = 1 << 16


def _shape_error(shape: tuple) -> str:
    return f"an Allan analysis needs a (N, 3) gyro record with N >= {_MIN_SAMPLES}, got shape {shape}"


class _StepMedian:
    """The median step between integer stamps, from a histogram of the steps fed in batches.

    Exact (as ``np.median(np.diff(stamps))``) while the steps take at most 65 536 distinct values (a
    gyroemu log's steps differ only by rounding to the nanosecond); past that the bins are merged two
    by two (as often as needed) and the median is the middle of its bin, within half a bin width. The
    histogram is bounded by the number of distinct steps, not by the number of samples.
    """

    def __init__(self) -> None:
        self.values = np.empty(0, dtype=np.int64)
        self.counts = np.empty(0, dtype=np.int64)
        self.shift = 0  # bins are [v·2^shift, (v + 1)·2^shift)

    def add(self, steps: np.ndarray) -> None:
        if not len(steps):
            return
        values, counts = np.unique(np.asarray(steps, dtype=np.int64) >> self.shift, return_counts=True)
        self._merge(np.concatenate([self.values, values]), np.concatenate([self.counts, counts]))
        while len(self.values) > _MAX_STEP_BINS:
            self.shift += 1
            self._merge(self.values >> 1, self.counts)

    def _merge(self, values: np.ndarray, counts: np.ndarray) -> None:
        self.values, index = np.unique(values, return_inverse=True)
        self.counts = np.bincount(index, weights=counts).astype(np.int64)

    def median(self) -> float:
        """The median step (NaN without steps), in the stamps' unit."""
        total = int(self.counts.sum())
        if total == 0:
            return float("nan")
        cumulative = np.cumsum(self.counts)
        middle = ((total - 1) // 2, total // 2)  # the two middle steps (the same one for an odd count)
        lower, upper = (self.values[np.searchsorted(cumulative, i, side="right")] for i in middle)
        width = 1 << self.shift
        centre = (width - 1) / 2 if self.shift else 0.0
        return (float(lower) + float(upper)) / 2 * width + centre


class _GyroSeries:
    """One gyro channel fed in batches: the Allan accumulator, the steps' median, the sample count."""

    def __init__(self) -> None:
        self.allan = OverlappingAllanAccumulator(dt=1.0, n_axes=3)  # dt is given with the result
        self.steps = _StepMedian()
        self.n = 0
        self.finite = True
        self.last_stamp: int | None = None
        self.last_log_time: int | None = None
        self._pending: list[np.ndarray] = []
        self._pending_n = 0

    def add(self, gyro: np.ndarray, stamps: np.ndarray | None = None) -> None:
        """Append samples ``gyro`` (n, 3), rad/s, with their integer stamps (n,) when known."""
        if not len(gyro):
            return
        if stamps is not None:
            stamps = np.asarray(stamps, dtype=np.int64)
            if self.last_stamp is None:
                self.steps.add(np.diff(stamps))
            else:
                self.steps.add(np.diff(stamps, prepend=self.last_stamp))
            self.last_stamp = int(stamps[-1])
        self.n += len(gyro)
        if not self.finite:
            return
        if not np.all(np.isfinite(gyro)):
            self.finite = False  # reported after the length check, as allan_report orders them
            self._pending, self._pending_n = [], 0
            return
        self._pending.append(gyro)
        self._pending_n += len(gyro)
        if self._pending_n >= BATCH:
            self.flush()

    def flush(self) -> None:
        if self._pending:
            self.allan.update(np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0])
            self._pending, self._pending_n = [], 0

    def deviations(self, dt: float) -> tuple[AllanDeviation, ...]:
        """The three axes' Allan deviations; ``ValueError`` (allan_report's words) for a record it cannot use."""
        self.flush()
        if self.n < _MIN_SAMPLES:
            raise ValueError(_shape_error((self.n, 3)))
        if not self.finite:
            raise ValueError("the gyro record has NaN or infinite samples")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"the stamps do not increase (median step {dt:g} s)")
        return self.allan.deviations(dt)


def _npz_series(log: Path) -> tuple[_GyroSeries, float, str | None]:
    """An .npz log's gyro series, its median step (s) and device TOML.

    .npz is the in-memory format (``np.load``'s ``mmap_mode`` cannot map an array inside a zip): its
    ``imu/gyro`` and ``imu/t`` are read whole, then fed to the accumulator in batches like an .mcap's.
    """
    try:
        with np.load(log, allow_pickle=False) as data:
            if "imu/gyro" not in data or "imu/t" not in data:
                gyro = None
            else:
                gyro, t = data["imu/gyro"], data["imu/t"]
                device_toml = str(data["device_toml"]) if "device_toml" in data else None
    except (OSError, ValueError) as e:
        raise AllanLogError(f"{log}: not a gyroemu log (.mcap or .npz): {e}") from None
    if gyro is None:
        raise AllanLogError(f"{log}: holds no gyro samples (write one with 'gyroemu simulate --device ...')")
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < _MIN_SAMPLES:
        raise AllanLogError(f"{log}: {_shape_error(gyro.shape)}")
    dt = float(np.median(np.diff(t)))
    series = _GyroSeries()
    for start in range(0, len(gyro), BATCH):
        series.add(gyro[start : start + BATCH])
    return series, dt, device_toml


def _mcap_series(log: Path) -> tuple[_GyroSeries, float, str | None]:
    """An .mcap log's gyro series (its one device's IMU channel), median step (s) and device TOML.

    The file is walked a record at a time (one decompressed chunk in memory), the device's IMU messages
    decoded as they come and handed on in batches of :data:`BATCH`, so memory does not grow with the
    log. The device is the one :func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` finds (``/imu``,
    ``/<device>/imu``, any other Imu topic, or a lone ``/truth/imu``, ``/estimate/imu``), with the same
    errors and warnings; unlike ``read_mcap`` it keeps every sample of the channel (``read_mcap`` drops
    samples that lack a ``/raw/<kind>`` message at their stamp, which gyroemu's logs never do). Each
    chunk's messages are put in log-time order; a channel whose chunks overlap in time (so that only
    a whole-file sort would order it) is refused.
    """
    from gyroemu.pipelines.formats.channels import ESTIMATE_ROLE, IMU_ROLE, TRUTH_ROLE, role_accepts, split_topic
    from gyroemu.pipelines.formats.mcap_log import LogWarning
    from gyroemu.pipelines.formats.mcap_records import LogError, McapScan
    from gyroemu.pipelines.formats.messages import IMU

    scan = McapScan(log)
    series: dict[int, _GyroSeries] = {}  # channel id -> its samples, for every channel that may be the device's
    keys: dict[int, tuple[str, str, str]] = {}  # channel id -> place()

    def place(channel_id: int) -> tuple[str, str, str]:
        """``(device key, prefix, role)`` of an Imu channel, as read_mcap groups it."""
        if channel_id not in keys:
            topic = scan.data[channel_id].channel.topic
            prefix, role = split_topic(topic)
            if role and not role_accepts(role, IMU):
                role = ""  # e.g. an Imu message on a /mag topic: a plain topic, a device of its own
            keys[channel_id] = (topic if role in ("", TRUTH_ROLE, ESTIMATE_ROLE) else prefix, prefix, role)
        return keys[channel_id]

    def candidate(channel_id: int) -> bool:
        """Whether an Imu channel is (so far) a device: a truth or estimate one only while its device's
        measured /imu has no messages."""
        _, prefix, role = place(channel_id)
        if role not in (TRUTH_ROLE, ESTIMATE_ROLE):
            return True
        return not any(place(c)[2] == IMU_ROLE and place(c)[1] == prefix and s.n for c, s in series.items())

    def gather(channel_id: int) -> None:
        data = scan.data[channel_id]
        blocks = list(zip(data.order, data.header, data.payload))
        blocks += [
            (np.array([ordinal]), fields, np.frombuffer(payload, np.uint8)[None, :])
            for ordinal, fields, payload in data.loose
        ]
        for gathered in (data.order, data.header, data.payload, data.loose):
            gathered.clear()  # what the scan gathered for this channel is handed on or dropped: memory stays flat
        if not blocks or data.mtype is not IMU:
            return
        if not candidate(channel_id):
            series.pop(channel_id, None)  # a truth or estimate channel beside a measured /imu
            return
        try:
            batches = [IMU.decode(rows) for _, _, rows in blocks]
        except ValueError as e:
            raise LogError(f"topic {data.channel.topic}: corrupt {IMU.name} message: {e}", file=log) from None
        order = np.concatenate([b[0] for b in blocks])
        log_time = np.concatenate([b[1]["log_time"] for b in blocks]).astype(np.int64)
        stamps = np.concatenate([b.stamp_ns for b in batches])
        gyro = np.concatenate([b["angular_velocity"] for b in batches])
        index = np.lexsort((order, log_time))  # log-time order, file order for equal times
        stamps, gyro, log_time = stamps[index], gyro[index], log_time[index]
        target = series.setdefault(channel_id, _GyroSeries())
        if target.last_log_time is not None and log_time[0] < target.last_log_time:
            raise AllanLogError(
                f"{log}: the chunks of {data.channel.topic} overlap in time; "
                "rewrite the log in time order (e.g. 'mcap sort') to analyse it"
            )
        target.last_log_time = int(log_time[-1])
        target.add(gyro, stamps)

    for _ in scan.walk():
        for channel_id, data in scan.data.items():
            if data.payload or data.loose:
                gather(channel_id)

    if scan.truncated_at is not None:
        warnings.warn(
            f"{log}: truncated at byte {scan.truncated_at} (no MCAP footer): recovered "
            f"{scan.message_count} messages from {scan.chunks} complete chunks",
            LogWarning,
            stacklevel=3,
        )
    for topic, reason in scan.skipped.items():
        warnings.warn(f"{log}: skipping topic {topic}: {reason}", LogWarning, stacklevel=3)
    devices = {c: s for c, s in series.items() if s.n and candidate(c)}
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    records = {m.get("topic_prefix", ""): m for m in metadata}

    def meta(channel_id: int) -> dict | None:
        key = place(channel_id)[0]
        return records.get(key) or (metadata[0] if key == "" and len(metadata) == 1 else None)

    if not devices:
        state = (
            f"; truncated at byte {scan.truncated_at}, {scan.message_count} messages recovered"
            if scan.truncated_at is not None
            else ""
        )
        raise LogError(
            f"holds no sensor_msgs/msg/Imu messages ({len(scan.channels)} channels, "
            f"{scan.message_count} messages{state})",
            file=log,
        )
    if len(devices) != 1:
        names = [(meta(c) or {}).get("device_name") or (keys[c][0].strip("/") or "imu0") for c in devices]
        raise ValueError(f"{log}: {len(devices)} devices ({', '.join(names)}); choose one from .devices")
    channel_id, chosen = next(iter(devices.items()))
    device_toml = (meta(channel_id) or {}).get("device") or None
    return chosen, chosen.steps.median() * 1e-9, device_toml


def allan_of_log(path: str | os.PathLike) -> AllanReport:
    """Fit a static gyro log: an .mcap (its device, with the device's config when the log carries it),
    or an .npz of ``gyroemu simulate --device`` (``imu/gyro``, ``imu/t``, ``device_toml``). The sample
    interval is the median step of the stamps. Raises :class:`AllanLogError` for a log it cannot use,
    :class:`gyroemu.errors.LogError` for an .mcap it cannot read.

    The log is read and analysed in batches of :data:`BATCH` samples: memory is bounded by the batch
    (and, for an .npz, by the gyro array, which that format holds in memory), not by the log's length.
    """
    log = Path(path)
    if not log.is_file():
        raise AllanLogError(f"{log}: no such file")
    series, dt, device_toml = _mcap_series(log) if log.suffix == ".mcap" else _npz_series(log)
    spec = None
    if device_toml is not None:
        import dataclasses
        import tomllib

        from gyroemu.sensors import device_from_dict

        device = device_from_dict(tomllib.loads(device_toml), name=log.name)
        spec = dataclasses.replace(device.gyro_errors, noise_density=device.gyro_noise_density)
    try:
        deviations = series.deviations(dt)
        fits = cast(tuple[AllanFit, AllanFit, AllanFit], tuple(fit_allan(d) for d in deviations))
    except ValueError as e:
        raise AllanLogError(f"{log}: {e}") from None
    return AllanReport(fits=fits, spec=spec)


def write_allan_plot(report: AllanReport, out: str | os.PathLike, title: str = "") -> Path:
    """:func:`plot_allan` to ``out`` (a PNG whatever its suffix) through a temporary file beside it, so
    that no partial plot is left; returns ``out``."""
    out = Path(out)
    tmp = out.with_name(f".{out.name}.tmp.png")
    try:
        plot_allan(report, tmp, title=title)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


def plot_allan(report: AllanReport, out: str | Path, title: str = "") -> Path:
    """Draw the Allan plot (PNG): measured curves with 68 % bands, fitted models, specification lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5), dpi=110)
    to_deg_h = _DEG * 3600.0
    for axis, (fit, colour) in enumerate(zip(report.fits, ("tab:red", "tab:green", "tab:blue"))):
        a = fit.allan
        ax.fill_between(a.tau, a.low * to_deg_h, a.high * to_deg_h, color=colour, alpha=0.15, lw=0)
        ax.loglog(a.tau, a.adev * to_deg_h, "o", ms=3, color=colour, label=f"measured {'xyz'[axis]}")
        ax.loglog(a.tau, fit.model(a.tau) * to_deg_h, "-", lw=1, color=colour, alpha=0.8)
    tau = report.fits[0].allan.tau
    if report.spec is not None:
        s = _spec_terms(report.spec)
        lines = {
            "spec quantisation": None if s["quantisation"] is None else np.sqrt(3) * s["quantisation"] / tau,
            "spec ARW": s["arw"] / np.sqrt(tau) if s["arw"] else None,
            "spec bias instability": np.full_like(tau, 0.664 * s["bias_instability"])
            if s["bias_instability"]
            else None,
            "spec RRW": s["rrw"] * np.sqrt(tau / 3) if s["rrw"] else None,
        }
        for (label, values), style in zip(lines.items(), ((0, (1, 3)), "--", "-.", ":")):
            if values is not None:
                ax.loglog(tau, values * to_deg_h, color="0.3", ls=style, lw=1.2, label=label)
    lowest = min(float(f.allan.adev.min()) for f in report.fits) * to_deg_h
    ax.set_ylim(bottom=lowest / 5)  # spec lines below the data would only squash the curves
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel("Allan deviation (deg/h)")
    ax.set_title(title or "Allan deviation")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out)
    plt.close(fig)
    return out
