"""``gyroemu bench --log``: a log's devices benched a block at a time, in memory that does not grow with it.

A log case used to be read whole (:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap`: 2.6 kB a sample,
every channel decoded) and each filter given the whole run in one call. Here the log is read with
:class:`~gyroemu.pipelines.formats.device_stream.DeviceStream` in passes of bounded memory, each a walk
over the file's chunks:

1. :func:`~gyroemu.pipelines.formats.device_stream.scan_devices`: every message decoded and checked (the
   errors and warnings of ``read_mcap``), the devices found;
2. the census: per device, how many samples, their stamps (increasing), their rate, whether any has a
   whole field and any a movement flag, whether the truth has attitudes and rates; the first samples
   (every sample's gyro, accelerometer and field where a filter or ``latency_s={"mag": "auto"}`` needs
   them at once);
3. the reference: each sample's nearest ``/truth/imu`` message within a quarter of the sample interval
   (the interval is the census's median), to count the samples that count before any filter runs;
4. (the smoother only) its forward pass, a block at a time (``learn``);
5. every filter of the device on each block in turn, and each run's :class:`~.bench_metrics.RunMetrics`
   (a gyroemu device's estimates turned out of its mounted sensor's axes into the body's, whose truth
   they are compared with: :func:`~.bench_filters.in_body_axes`).

The filters see the samples a log read whole would give them, in blocks (the filter protocol's blocks
in time order; every built-in gives the same bytes whole or in blocks, ``tests/pipelines/
test_filter_blocks.py``), and the metrics do not depend on the cut, so the report is the whole read's
but for the wall times (``tests/pipelines/test_bench_log.py``). A log one pass cannot pair
(:class:`~gyroemu.pipelines.formats.device_stream.NotStreamable`: topics out of time order, the truth's
stamps not increasing, ...) is read whole instead, with the same results.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar

import numpy as np

from gyroemu.pipelines.estimation import registry
from gyroemu.pipelines.estimation.mounting import mounting_from_metadata
from gyroemu.pipelines.estimation.protocol import FilterSetup, learns_in_blocks
from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.estimation.series import check_counts, not_increasing_error
from gyroemu.pipelines.formats.channels import MOVEMENT_ROLE
from gyroemu.pipelines.formats.device_stream import (
    FIRST_BLOCK_S,
    DeviceBlock,
    DeviceStream,
    NotStreamable,
    StreamDevice,
    count_samples,
    scan_devices,
)
from gyroemu.pipelines.formats.mcap_log import LogWarning
from gyroemu.pipelines.formats.mcap_records import McapRecordWalk
from gyroemu.pipelines.formats.messages import seconds_since
from gyroemu.pipelines.jobs.bench_cases import PLOT_POINTS, BenchError, BenchWarning, LogCase
from gyroemu.pipelines.jobs.bench_filters import check_estimate, in_body_axes, warm_up
from gyroemu.pipelines.jobs.bench_metrics import BIAS_WINDOW_S, RunMetrics, RunResult

__all__ = [
    "TRUTH_MATCH",
    "FilterRun",
    "LogDevice",
    "bench_log_device",
    "check_log_case",
    "choose_devices",
    "log_label",
    "log_setup",
    "mask_notes",
    "no_reference_error",
    "stream_log_devices",
]

TRUTH_MATCH = 0.25
"""How far, in sample intervals, a truth message may lie from a sample's stamp to be its reference."""


class _Named(Protocol):
    @property
    def topics(self) -> Mapping[str, str]: ...


DeviceT = TypeVar("DeviceT", bound=_Named)


def check_log_case(case: LogCase) -> Path:
    """The log's path, once the case's latencies name known sensors and the file exists (:class:`BenchError`)."""
    from gyroemu.pipelines.estimation.setup import check_latency_sensors

    path = Path(case.path)
    try:
        check_latency_sensors(case.latency_s or {})
    except ValueError as e:
        raise BenchError(f"latency: {e}", file=path, key="latency_s") from None
    if not path.is_file():
        raise BenchError("no such file", file=path, key=None)
    return path


def choose_devices(
    path: Path, devices: Mapping[str, DeviceT], case: LogCase, has_truth: Callable[[str, DeviceT], bool]
) -> dict[str, DeviceT]:
    """The devices of a log to bench: those with an IMU topic (not a lone truth or estimate), the one
    ``case.device`` names, with an attitude in their truth (``has_truth``); :class:`BenchError` naming
    the file when none is left."""
    lone = ("truth/imu", "estimate/imu")
    imu = {n: d for n, d in devices.items() if not str(d.topics.get("imu", "")).rstrip("/").endswith(lone)}
    if not imu:
        raise BenchError(
            "holds no IMU channel (/imu with sensor_msgs/msg/Imu measurements): only "
            + ", ".join(d.topics.get("imu", "?") for d in devices.values()),
            file=path,
        )
    if case.device is not None:
        if case.device not in imu:
            raise BenchError(f"no device '{case.device}' (devices: {', '.join(imu)})", file=path)
        imu = {case.device: imu[case.device]}
    with_truth = {n: d for n, d in imu.items() if has_truth(n, d)}
    if not with_truth:
        raise BenchError(
            "has no truth channel (/truth/imu with the true attitude): the bench compares estimates with the truth",
            file=path,
        )
    return with_truth


def log_label(path: Path, name: str, devices: int, case: LogCase, has_mag: bool) -> str:
    """A device's case name in the report: the file's (with the device's when the log has several)."""
    label = path.name if devices == 1 else f"{path.name}:{name}"
    return label + (" (6D)" if case.six_d and has_mag else "")


def no_reference_error(path: Path, name: str) -> BenchError:
    """The error for a device none of whose samples has a finite reference attitude."""
    return BenchError(f"the truth channel of device '{name}' has no finite attitude at the IMU's stamps", file=path)


def mask_notes(path: Path, name: str, flags: bool | None, mask_count: int, no_ref: int, others: list[str]) -> list[str]:
    """The notes on which samples count, first, then ``others``, then (with a warning) a movement mask
    that marks no sample. ``flags``: whether the movement flags mark a sample (None: no movement topic)."""
    notes = list(others)
    if flags is False:
        msg = f"{path}: the movement mask of device '{name}' marks no sample; every sample counts"
        warnings.warn(msg, BenchWarning, stacklevel=4)
        notes.append(msg.split(": ", 1)[1])
    counted = f"the {mask_count} samples of its movement mask" if flags else "every sample"
    without = f", {no_ref} of them without a finite reference (ignored)" if no_ref else ""
    return [f"{counted} counted{without}", *notes]


def log_setup(
    metadata: dict[str, Any] | None,
    rate_hz: float,
    mode: str,
    case: LogCase,
    samples: tuple[np.ndarray, np.ndarray, np.ndarray | None],
    notes: list[str],
) -> FilterSetup:
    """The device's filter setup at ``rate_hz`` (Hz, the samples' nominal rate: ``rate_of`` their integer
    stamps), from its ``gyroemu`` metadata or the defaults, with the case's latencies; ``samples`` is
    ``(t − t₀, gyro, mag or None)``, of every sample where the field's lag is to be read from the log.
    Appends what it decided to ``notes``."""
    from gyroemu.pipelines.estimation.setup import latencies_for_log, setup_from_metadata

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an embedded config that no longer validates: defaults
        setup = setup_from_metadata(metadata, rate_hz, use_mag=mode == "9D")
    if case.latency_s:
        t_rel, gyro, mag = samples
        setup, lag = latencies_for_log(setup, case.latency_s, t_rel, gyro, mag)
        if lag is not None:
            notes.append(lag.describe())
    if setup.gyro_latency_s or setup.mag_latency_s:
        notes.append(
            f"latencies: gyro {setup.gyro_latency_s * 1e3:g} ms, magnetometer {setup.mag_latency_s * 1e3:g} ms "
            "(every filter fed the field at the gyro's instant, its attitudes moved to their stamps)"
        )
    return setup


@dataclass(frozen=True)
class LogDevice:
    """A device of a log to bench, found and counted without holding its samples (passes 1–3)."""

    label: str
    mode: str  # "9D" or "6D"
    setup: FilterSetup
    source: dict[str, Any]
    notes: list[str]
    device: StreamDevice
    samples: int
    counted: int  # samples in the mask with a finite reference
    first_ns: int  # the first sample's stamp: the filters run on seconds since it (``seconds_since``)
    t_first: float  # the first and the last sample on that clock, s (0 and the span)
    t_last: float
    dt_nominal: float
    flags: bool  # the movement flags are the mask
    rates: bool  # the truth has rates: the bias error
    first: DeviceBlock  # the first samples, for the warm-up (every sample when ``whole``)
    whole: bool
    q_bs: np.ndarray | None = None  # (4,) a gyroemu device's mounting: estimates turned into the body's


def _walk(path: Path, devices: Mapping[str, StreamDevice]) -> Iterator[tuple[str, DeviceBlock]]:
    """Each device's blocks, paired with their nearest truth, in one pass over the log (the last block
    of each once the file has ended)."""
    streams = {name: DeviceStream(d.channels, pair_truth=True, messages=d.messages) for name, d in devices.items()}
    for batch in McapRecordWalk(path).batches():
        for name, stream in streams.items():
            stream.feed(batch)
            yield name, stream.take()
    for name, stream in streams.items():
        yield name, stream.take(final=True)


def _blocks(path: Path, dev: LogDevice) -> Iterator[DeviceBlock]:
    """The device's samples for its filters, in time order: the census's first block (at least
    :data:`FIRST_BLOCK_S`: the MEKF starts from its first seconds, so every filter is given the same first
    block whatever the file's chunks), then the rest a block at a time as the log goes by."""
    first, last = dev.first, int(dev.first.stamp_ns[-1])
    yield first
    if len(first) == dev.samples:  # the census kept every sample
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)  # the census gave them
        for _, block in _walk(path, {dev.device.name: dev.device}):
            if block.through_ns is not None and block.through_ns > last:
                rest = block.after(last)
                if len(rest):
                    yield rest


def _reference(block: DeviceBlock, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The block's reference attitudes (n, 4) and rates (n, 3): its nearest truth within
    :data:`TRUTH_MATCH` sample intervals, NaN elsewhere."""
    assert block.truth is not None  # the walk pairs the truth
    hit = block.truth.gap_s <= TRUTH_MATCH * dt
    return np.where(hit[:, None], block.truth.q_wb, np.nan), np.where(hit[:, None], block.truth.omega_b, np.nan)


def _mask(block: DeviceBlock, flags: bool) -> np.ndarray:
    return block.movement if flags and block.movement is not None else np.ones(len(block), bool)


def stream_log_devices(case: LogCase, whole_samples: bool = False) -> list[LogDevice]:
    """The devices of the case's log to bench, from passes 1–3 (the module's notes): the same
    :class:`BenchError`, :class:`LogError` and warnings as the log read whole, before any filter runs.
    ``whole_samples``: keep every sample's gyro, accelerometer and field (a filter needs them at once).
    Raises :class:`~gyroemu.pipelines.formats.device_stream.NotStreamable` for a log one pass cannot
    pair (before it warns)."""
    path = check_log_case(case)
    whole = whole_samples or any(v == "auto" for v in (case.latency_s or {}).values())
    caught: list[warnings.WarningMessage] = []
    unpairable = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LogWarning)
            found, _ = scan_devices(path)  # LogError for an unreadable log, NotStreamable
            first_s = math.inf if whole else FIRST_BLOCK_S
            counted = count_samples(path, found, None, set(found), first_s, truth=True)
    except NotStreamable:
        unpairable = True  # the whole read gives the warnings anew
        raise
    finally:  # the passes' warnings, also before their error (a log refused warns first, as read whole)
        for w in [] if unpairable else caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    chosen = choose_devices(path, found, case, lambda n, d: counted[n].truth_attitudes > 0)
    figures: dict[str, dict[str, Any]] = {}
    for name in chosen:
        c = counted[name].census
        dt = c.rate.median() if c.count > 1 else math.nan  # too few samples: refused below, in order
        figures[name] = {"dt": dt, "counted": 0, "no_ref": 0, "mask": 0, "any": False}
    # pass 3: the reference, now that the sample interval is known
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)
        for name, block in _walk(path, chosen):
            f = figures[name]
            q_true, _ = _reference(block, f["dt"])
            mask = _mask(block, counted[name].census.flagged)
            finite = np.isfinite(q_true).all(axis=1)
            f["counted"] += int((mask & finite).sum())
            f["no_ref"] += int((mask & ~finite).sum())
            f["mask"] += int(mask.sum())
            f["any"] = f["any"] or bool(finite.any())
    out = []
    for name, dev in chosen.items():  # device by device, as the whole read checks and warns
        c, f = counted[name].census, figures[name]
        if c.not_increasing is not None:
            raise not_increasing_error(path, name, c.not_increasing)
        note = check_counts(path, name, c.count, c.finite)  # LogError: too few, all NaN
        if note:
            warnings.warn(f"{path}: {note}", BenchWarning, stacklevel=2)
        if not f["any"]:
            raise no_reference_error(path, name)
        flags = c.flagged if MOVEMENT_ROLE in dev.channels else None
        notes = mask_notes(path, name, flags, f["mask"], f["no_ref"], [note] if note else [])
        mode = "9D" if c.field_rows and not case.six_d else "6D"
        first = counted[name].first
        assert first is not None and c.first_ns is not None and c.last_ns is not None  # check_counts: 2 or more
        t = seconds_since(first.stamp_ns, c.first_ns)
        samples = (t, np.asarray(first.gyro, float), np.asarray(first.mag, float) if mode == "9D" else None)
        setup = log_setup(dev.metadata, c.rate.rate(), mode, case, samples, notes)
        t_first, t_last = seconds_since(np.array([c.first_ns, c.last_ns]), c.first_ns)
        out.append(
            LogDevice(
                label=log_label(path, name, len(found), case, c.field_rows),
                mode=mode,
                setup=setup,
                source={"log": str(path), "device": name},
                notes=notes,
                device=dev,
                samples=c.count,
                counted=f["counted"],
                first_ns=c.first_ns,
                t_first=float(t_first),
                t_last=float(t_last),
                dt_nominal=f["dt"],
                flags=bool(c.flagged),
                rates=counted[name].truth_rates > 0,
                first=first,
                whole=whole,
                q_bs=mounting_from_metadata(dev.metadata),
            )
        )
    return out


@dataclass
class FilterRun:
    """One filter over one log device: its result and its error curve (every ``step``-th sample)."""

    spec: str
    name: str
    result: RunResult
    curve_t: np.ndarray
    curve_total: np.ndarray
    curve_inclination: np.ndarray


@dataclass
class _Running:
    """A filter under way over a log: its metrics, its curve, its time, and why it stopped."""

    spec: str
    flt: Any
    metrics: RunMetrics
    curve: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # total, inclination, deg
    reason: str = ""
    given: tuple[np.ndarray, np.ndarray | None] | None = None  # a whole-log filter's output, given out in blocks
    at: int = 0

    def timed(self, call: Callable[..., Any], *args: Any) -> Any:
        """``call(*args)``, its time added to the run's."""
        started = time.perf_counter()
        try:
            return call(*args)
        finally:
            self.metrics.wall_s += time.perf_counter() - started


def bench_log_device(
    path: Path, dev: LogDevice, filters: list[str], threshold_deg: float, describe: Callable[[str], None]
) -> list[FilterRun]:
    """Every filter of ``filters`` over the device's samples, a block at a time (passes 4 and 5); a filter
    that raises is stopped and reported as diverged (its exception the reason)."""
    six_d = dev.mode == "6D"
    first_t = seconds_since(dev.first.stamp_ns, dev.first_ns)
    first_mag = None if six_d else dev.first.mag
    step = max(1, dev.samples // PLOT_POINTS)
    window = max(1, int(round(BIAS_WINDOW_S * dev.setup.rate_hz))) if dev.rates and dev.setup.rate_hz else None
    running = []
    for spec in filters:
        describe(f"{dev.label}: {spec}")
        warm_up(spec, dev.setup, first_t, dev.first.gyro, dev.first.accel, first_mag)
        r = _Running(spec, make_filter(spec, dev.setup), _metrics(dev, threshold_deg, window))
        if registry.takes_whole_log(spec):  # the whole log at once
            assert dev.whole, "stream_log_devices(whole_samples=True) keeps every sample for such a filter"
            t = first_t
            try:
                est = r.timed(r.flt.process, t, dev.first.gyro, dev.first.accel, first_mag)
                r.given = check_estimate(est, dev.samples, str(r.flt.name))
            except Exception as exc:  # noqa: BLE001 - a filter that fails is reported, not fatal
                r.reason = f"process() raised {type(exc).__name__}: {exc}"
        running.append(r)
    learners = [r for r in running if learns_in_blocks(r.flt) and not r.reason]
    if learners:
        for block in _blocks(path, dev):
            t, mag = seconds_since(block.stamp_ns, dev.first_ns), None if six_d else block.mag
            for r in learners:
                if not r.reason:
                    _step(r, r.flt.learn, t, block.gyro, block.accel, mag)
    offset, curve_t = 0, []
    for block in _blocks(path, dev):
        n = len(block)
        t = seconds_since(block.stamp_ns, dev.first_ns)
        q_true, omega = _reference(block, dev.dt_nominal)
        mask = _mask(block, dev.flags)
        mag = None if six_d else block.mag
        picked = np.flatnonzero((offset + np.arange(n)) % step == 0)
        curve_t.append(t[picked] - dev.t_first)
        for r in running:
            if r.reason:
                continue
            if r.given is not None:
                q, b = r.given[0][r.at : r.at + n], None if r.given[1] is None else r.given[1][r.at : r.at + n]
                r.at += n
            else:
                out = _step(r, r.flt.process, t, block.gyro, block.accel, mag)
                if r.reason:
                    continue
                q, b = _checked(r, out, n)
                if r.reason:
                    continue
            q, b, gyro = in_body_axes(q, b, block.gyro, dev.q_bs)  # a mounted sensor's estimate as the body's
            errors = r.metrics.add(t, q, q_true, mask, b, omega if window else None, gyro)
            r.curve.append((errors["total"][picked], errors["inclination"][picked]))
        offset += n
    for r in running:
        if learns_in_blocks(r.flt):
            r.flt.close()
    t = np.concatenate(curve_t) if curve_t else np.empty(0)
    return [_finished(r, dev, threshold_deg, t) for r in running]


def _metrics(dev: LogDevice, threshold_deg: float, bias_window: int | None) -> RunMetrics:
    """A filter's metrics over the device's run."""
    return RunMetrics(
        samples=dev.samples,
        counted=dev.counted,
        t_first=dev.t_first,
        t_last=dev.t_last,
        six_d=dev.mode == "6D",
        threshold_deg=threshold_deg,
        bias_window=bias_window,
    )


def _step(r: _Running, call: Callable[..., Any], *args: Any) -> Any:
    """``call(*args)`` timed; an exception stops the filter with it as the reason."""
    try:
        return r.timed(call, *args)
    except Exception as exc:  # noqa: BLE001 - a filter that fails is reported, not fatal
        r.reason = f"process() raised {type(exc).__name__}: {exc}"
        return None


def _checked(r: _Running, est: Any, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        return check_estimate(est, n, str(r.flt.name))
    except Exception as exc:  # noqa: BLE001
        r.reason = f"process() raised {type(exc).__name__}: {exc}"
        return np.empty((0, 4)), None


def _finished(r: _Running, dev: LogDevice, threshold_deg: float, curve_t: np.ndarray) -> FilterRun:
    """The filter's result and curve: its metrics, or, for one that failed, those of a run without an
    estimate (as a log read whole reports it: every error NaN, diverged, the exception the reason)."""
    name = str(r.flt.name)
    if r.reason:
        failed = _metrics(dev, threshold_deg, None)
        failed.wall_s = r.metrics.wall_s
        nan = np.full(len(curve_t), np.nan)
        return FilterRun(r.spec, name, failed.result(reason=r.reason), curve_t, nan, nan.copy())
    total, inclination = (np.concatenate([c[i] for c in r.curve]) if r.curve else np.empty(0) for i in range(2))
    return FilterRun(r.spec, name, r.metrics.result(), curve_t, total, inclination)
