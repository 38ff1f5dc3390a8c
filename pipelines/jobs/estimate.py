"""``gyroemu estimate``: run an attitude filter over a recorded log and write its estimate.

The output is the input file with an estimate channel added: every channel of the input (gyroemu's
or anyone's: ``/tf``, cameras, ...) is copied record for record, with its schema, metadata, message
bytes, sequence numbers and log and publish times, and so are the file's metadata records
(:mod:`gyroemu.pipelines.jobs.estimate_copy`). Attachments are not copied. An online filter runs as
the copy reads the log, a block at a time, in memory that does not grow with the log
(:mod:`gyroemu.pipelines.formats.device_stream`); the smoother (``mekf-smooth``, a
:class:`~gyroemu.pipelines.estimation.protocol.BlockLearner`) learns the log a block at a time in one
more pass first, its storage on disk; another offline filter is given the device's samples at once.

The estimate (``sensor_msgs/msg/Imu``: the estimated ``q_wb`` with its covariance when the filter has
one, and the bias-corrected rate) goes to ``topic_out`` (default ``/estimate/imu``): one message per
message of the IMU topic it follows, right after it in the file, with its log and publish times and its
header stamp. Its ``frame_id`` is the IMU message's, except for a gyroemu log's device, whose estimates
are in ``base_link`` as ``interface.md`` has them: the body's, the filter's sensor-frame attitude and
rate turned by the device's ``[mounting] q_bs`` from the log's embedded config
(:mod:`gyroemu.pipelines.estimation.mounting`: ``q̂_wb = q̂_ws ⊗ q_bs*``, ``ω̂_b = R(q_bs) ω̂_s``, the
world-axes covariance as it is; an identity mounting turns nothing). The channel uses the IMU
channel's schema. An input channel of the same topic is replaced when it is an earlier estimate (a
topic ``.../estimate/imu`` of type ``sensor_msgs/msg/Imu``); any other topic the input has, and the
contract's other topics (``/imu``, ``/mag``, ``/truth/imu``, ``/truth/pose``, ``/raw/<kind>``,
``/movement``, under any device prefix, and ``/tf``, ``/tf_static``), are refused (:data:`RESERVED_TOPICS`).

Which IMU topic: ``topic`` when given (any ``sensor_msgs/msg/Imu`` topic that
:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` takes as a device's measurements). Without it the
file's only IMU topic; a gyroemu log of several devices gets every device filtered, each estimate on
its own ``/<device>/estimate/imu``; any other file with several IMU topics is an error
(:class:`EstimateTopicError`) that lists them. The output is written to a temporary name and renamed
when complete.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from gyroemu.errors import ConfigError
from gyroemu.pipelines.estimation import registry
from gyroemu.pipelines.estimation.mounting import mounting_from_metadata
from gyroemu.pipelines.estimation.protocol import AttitudeFilter, learns_in_blocks
from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.estimation.series import (
    check_counts,
    check_samples,
    estimate_series,
    not_increasing_error,
    rate_of,
)
from gyroemu.pipelines.estimation.setup import (
    FIELD_LAG_FROM_LOG,
    check_latency_sensors,
    latencies_for_log,
    setup_from_metadata,
)
from gyroemu.pipelines.formats.atomic import output_file_problem
from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    absolute_topic,
    role_topic,
    series_fields,
    split_topic,
)
from gyroemu.pipelines.formats.device_stream import (
    FIRST_BLOCK_S,
    Counted,
    DeviceBlock,
    DeviceCensus,
    DeviceStream,
    NotStreamable,
    StreamDevice,
    count_samples,
    scan_devices,
)
from gyroemu.pipelines.formats.frames import TF_LOG_RATE_HZ, TfThinning
from gyroemu.pipelines.formats.mcap_log import DeviceLog, LogWarning, read_mcap
from gyroemu.pipelines.formats.mcap_records import ChannelInfo, McapRecordWalk
from gyroemu.pipelines.formats.messages import IMU, seconds_since
from gyroemu.pipelines.jobs.disk_space import MCAP_RECORD_OVERHEAD, free_bytes, human_size
from gyroemu.pipelines.jobs.estimate_copy import (
    ESTIMATE_CHANNEL,
    BlockRun,
    EstimateTarget,
    StreamFeed,
    add_estimate_tf,
    copy_with_estimates,
)

if TYPE_CHECKING:
    from gyroemu.pipelines.estimation.field_lag import FieldLag

_Device = TypeVar("_Device", DeviceLog, StreamDevice)  # a log's device, read whole or found for the streamed path

__all__ = [
    "DEFAULT_TOPIC_OUT",
    "EstimateError",
    "EstimateSummary",
    "EstimateTopicError",
    "RESERVED_TOPICS",
    "check_disk",
    "check_options",
    "estimate_log",
]

DEFAULT_TOPIC_OUT = "/estimate/imu"
"""Where the estimate goes unless the caller names a topic."""


RESERVED_TOPICS = ("/tf", "/tf_static")
"""Topics an estimate never goes to, besides the roles of ``interface.md`` other than the estimate's
(``imu``, ``mag``, ``truth/imu``, ``truth/pose``, ``raw/<kind>``, ``movement``, under any prefix)."""


class EstimateError(ConfigError):
    """Bad options of ``gyroemu estimate`` (the message names the argument)."""


class EstimateTopicError(EstimateError):
    """The IMU topic to filter, or the topic to write, cannot be chosen (the message names the argument)."""


def check_options(
    path: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    force: bool = False,
    plot: bool = False,
    topic_out: str | None = None,
) -> None:
    """:class:`EstimateError` for an output that cannot be written (a folder, the input itself, in a
    missing, read-only or unwritable folder, or an existing file without ``force``:
    :func:`~gyroemu.pipelines.formats.atomic.output_file_problem`); with ``plot``, the same of
    the picture :func:`~gyroemu.pipelines.jobs.plots.plot_estimate` draws beside ``out``
    (``OUT.estimate.png``); a ``topic_out`` that is no topic name or one of the reserved topics
    (module's notes)."""
    path, out = Path(path), Path(out)
    problem = output_file_problem(out, force=force, inputs=(path,))
    if problem is not None:
        raise EstimateError(f"argument --out: {problem}")
    if plot:
        from gyroemu.pipelines.jobs.plots import estimate_plot_path

        problem = output_file_problem(estimate_plot_path(out), force=force, inputs=(path,))
        if problem is not None:
            raise EstimateError(f"argument --plot: {problem}")
    if topic_out is not None:
        _check_topic_out_name(topic_out)


_TOPIC_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MAX_TOPIC_LENGTH = 255 - 8
"""ROS 2's longest fully qualified topic name (rmw's ``RMW_TOPIC_MAX_NAME_LENGTH``: 8 characters of the
DDS topic's 255 are its prefix)."""


def _topic_name_problem(topic: str) -> str | None:
    """Why ``topic`` is no fully qualified ROS 2 topic name (rmw's ``validate_full_topic_name``), or None:
    it starts with '/', and each token between slashes is letters, digits and '_', not starting with a
    digit (so no empty token: no '//', no trailing '/'), 247 characters at most."""
    if not topic.startswith("/"):
        return "it does not start with '/'"
    if len(topic) > _MAX_TOPIC_LENGTH:
        return f"{len(topic)} characters, ROS 2 takes {_MAX_TOPIC_LENGTH} at most"
    for token in topic[1:].split("/"):
        if not token:
            return "an empty name between slashes ('//', or a '/' at the end)"
        if _TOPIC_TOKEN.fullmatch(token) is None:
            if token[0] in "0123456789":
                return f"its name {token!r} starts with a digit"
            return f"its name {token!r} has a character other than A-Z, a-z, 0-9 and '_'"
    return None


def _check_topic_out_name(topic_out: str) -> None:
    """:class:`EstimateTopicError` for a ``topic_out`` that is no ROS 2 topic name (:func:`_topic_name_problem`),
    or a reserved topic."""
    problem = _topic_name_problem(topic_out)
    if problem is not None:
        raise EstimateTopicError(
            f"argument --topic-out: {topic_out!r} is not a ROS 2 topic name like /estimate/imu: {problem}"
        )
    role = split_topic(topic_out)[1]
    if topic_out in RESERVED_TOPICS or (role and role != ESTIMATE_ROLE):
        raise EstimateTopicError(
            f"argument --topic-out: {topic_out} is a topic of the log format's own (interface.md): "
            "name another topic, e.g. /estimate/imu"
        )


@dataclass(frozen=True)
class EstimateSummary:
    """What :func:`estimate_log` did.

    Attributes
    ----------
    path : Path
        The file written.
    devices : list of tuple
        Per filtered device ``(name, samples, filter name, 9D?)``.
    topics : list of tuple
        Per filtered device ``(IMU topic, estimate topic, estimate messages written)``.
    field_lags : list of tuple
        Per device whose field's lag was read from the log (``latency_s={"mag": "auto"}``)
        ``(name, FieldLag, the magnetometer's latency used, s)``.
    """

    path: Path
    devices: list[tuple[str, int, str, bool]]
    topics: list[tuple[str, str, int]] = field(default_factory=list)
    field_lags: list[tuple[str, FieldLag, float]] = field(default_factory=list)


def _choose(
    devices_found: Iterable[_Device], path: Path, topic: str | None, topic_out: str | None
) -> list[tuple[_Device, str]]:
    """``[(device, estimate topic)]`` by the rules of the module's notes (a device: anything with
    ``topics`` and ``metadata``, a :class:`DeviceLog` or a :class:`StreamDevice`)."""
    devices = {d.topics[IMU_ROLE]: d for d in devices_found}
    if topic_out is not None:
        _check_topic_out_name(topic_out)
    if topic is not None:
        name = absolute_topic(topic)
        if name not in devices:
            raise EstimateTopicError(
                f"argument --topic: {path}: no sensor_msgs/msg/Imu topic {topic!r} "
                f"(IMU topics: {', '.join(sorted(devices))})"
            )
        out = topic_out or DEFAULT_TOPIC_OUT
        if out == name:
            raise EstimateTopicError(f"argument --topic-out: {out} is the IMU topic being filtered")
        return [(devices[name], out)]
    candidates = {t: d for t, d in devices.items() if t != (topic_out or DEFAULT_TOPIC_OUT)} or devices
    if len(candidates) == 1:
        ((name, device),) = candidates.items()
        default = role_topic(ESTIMATE_ROLE, split_topic(name)[0]) if device.metadata is not None else DEFAULT_TOPIC_OUT
        out = topic_out or default
        if out == name:
            raise EstimateTopicError(f"argument --topic-out: {out} is the IMU topic being filtered")
        return [(device, out)]
    if topic_out is None and all(d.metadata is not None for d in candidates.values()):
        return [(d, role_topic(ESTIMATE_ROLE, split_topic(t)[0])) for t, d in candidates.items()]
    raise EstimateTopicError(
        f"argument --topic: {path} holds {len(candidates)} IMU topics ({', '.join(sorted(candidates))}): "
        "choose the one to filter with --topic"
    )


def estimate_log(
    path: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    filter_name: str = "mekf",
    use_mag: bool | None = None,
    topic: str | None = None,
    topic_out: str | None = None,
    force: bool = False,
    latency_s: Mapping[str, float | str] | None = None,
    read_whole: bool = False,
) -> EstimateSummary:
    """Filter the IMU topic(s) of the log ``path`` and write ``out``: the input with the estimate added.

    The log is read a block at a time (:mod:`~gyroemu.pipelines.formats.device_stream`): an online filter
    runs as it is read, in memory that does not grow with the log's length, and so does the smoother
    (``mekf-smooth``: it learns the log a block at a time in one more pass, its storage in temporary
    files beside ``out``); another offline filter and a field lag read from the samples
    (``latency_s={"mag": "auto"}``) get the filtered devices' samples at once (their rows of gyro,
    accelerometer and field only, not the log). A log whose topics one
    pass cannot pair is read whole into memory first (:func:`read_mcap`). All give the same bytes.

    Parameters
    ----------
    path, out : path-like
        The input MCAP file (only read) and the file to write.
    filter_name : str
        The filter (:func:`gyroemu.pipelines.estimation.registry.make_filter`).
    use_mag : bool or None
        None: 9D where the device has a magnetometer.
    topic : str, optional
        The IMU topic to filter (see the module's notes for the default).
    topic_out : str, optional
        The estimate's topic (default ``/estimate/imu``; ``/<device>/estimate/imu`` for the devices of
        a several-device gyroemu log).
    force : bool
        Overwrite ``out`` when it exists.
    latency_s : mapping, optional
        How long each named sensor (``gyro``, ``mag``) lags the motion, s: the field is moved to the
        gyro's instant and the attitudes to their stamps
        (:mod:`gyroemu.pipelines.estimation.latency`). A sensor not named keeps a gyroemu log's
        device's ``latency_s``, 0 for any other log. ``"mag": "auto"``: the gyro's latency plus the
        field's lag behind the gyro read from each device's samples where it is observable
        (:func:`~gyroemu.pipelines.estimation.setup.latencies_for_log`; ``EstimateSummary.field_lags``).
    read_whole : bool
        Read the log into memory first even where it could be read a block at a time (the same output).

    Raises
    ------
    LogError
        A log the filter cannot use (see :func:`check_samples`).
    EstimateError
        ``out`` cannot be written (:func:`check_options`), or ``latency_s`` names another sensor.
    EstimateTopicError
        No IMU topic can be chosen, or ``topic_out`` cannot be written.
    FilterError
        An unknown filter.
    """
    path, out = Path(path), Path(out)
    try:
        check_latency_sensors(latency_s or {})
    except ValueError as e:
        raise EstimateError(f"argument --latency: {e}") from None
    check_options(path, out, force=force, topic_out=topic_out)
    if not read_whole:
        try:
            return _estimate_streamed(path, out, filter_name, use_mag, topic, topic_out, latency_s or {})
        except NotStreamable:
            pass  # a log a single pass cannot pair: read whole, with the same result
    return _estimate_whole(path, out, filter_name, use_mag, topic, topic_out, latency_s)


def _estimate_whole(
    path: Path,
    out: Path,
    filter_name: str,
    use_mag: bool | None,
    topic: str | None,
    topic_out: str | None,
    latency_s: Mapping[str, float | str] | None,
) -> EstimateSummary:
    """:func:`estimate_log` with the log read into memory (a log whose topics
    :mod:`~gyroemu.pipelines.formats.device_stream` cannot pair in one pass, or ``read_whole``)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        log = read_mcap(path)
    _pass_on(caught)
    chosen = _choose(log.devices.values(), path, topic, topic_out)
    _check_topics_out(path, chosen, log.channels)
    check_disk(path, out, [(_size_frame(dev), len(dev.samples), 0) for dev, _ in chosen])
    targets, done, field_lags = [], [], []
    for dev, name in chosen:
        samples = dev.samples
        note = check_samples(path, dev.name, samples.t, samples.gyro, samples.accel)
        if note:
            warnings.warn(f"{path}: {note}", UserWarning, stacklevel=2)
        t_rel = dev.seconds_from_first()  # exact from the nanoseconds, as the streamed path has them
        rate_hz = rate_of(dev.stamp_ns)  # from the integer stamps, as the streamed census has it
        nine, flt, lag = _device_filter(
            dev, rate_hz, samples.has_mag, use_mag, filter_name, latency_s, t_rel, samples.gyro, samples.mag
        )
        field_lags += lag
        est = flt.process(t_rel, samples.gyro, samples.accel, samples.mag if nine else None)
        # a gyroemu device's estimate in base_link: the body's, out of its mounted sensor's axes
        fields = series_fields(estimate_series(samples.t, est, samples.gyro, mounting_from_metadata(dev.metadata)))
        targets.append(
            _target(dev, name, np.asarray(dev.stamp_ns, dtype=np.int64), {k: np.asarray(v) for k, v in fields.items()})
        )
        done.append((dev.name, len(samples), getattr(flt, "name", filter_name), nine))
    add_estimate_tf(targets, chosen)
    copy_with_estimates(path, out, log.profile, targets)
    topics = [(t.topic, t.topic_out, t.sequence) for t in targets]
    return EstimateSummary(path=out, devices=done, topics=topics, field_lags=field_lags)


def _estimate_streamed(
    path: Path,
    out: Path,
    filter_name: str,
    use_mag: bool | None,
    topic: str | None,
    topic_out: str | None,
    latency_s: Mapping[str, float | str],
) -> EstimateSummary:
    """:func:`estimate_log` a block at a time: three passes over the log (validate it and find its devices;
    count their samples, keeping the first minute, or all of them for an offline filter or a field lag
    read from the samples; copy it while filtering), in memory that does not grow with its length for
    an online filter. The same bytes as :func:`_estimate_whole` (``tests/pipelines/test_estimate_stream.py``).
    Raises :class:`NotStreamable` for a log a single pass cannot pair, before it warns or writes; or,
    should a filter's last valid attitude lie in a chunk already written, while the temporary output is
    written (which is then removed)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        devices, scan = scan_devices(path)
        chosen = _choose(devices.values(), path, topic, topic_out)
        _check_topics_out(path, chosen, scan.channel_info())
        tf_device = next((d.name for d, _ in chosen if d.metadata is not None), None)
        # an offline filter that cannot learn a block at a time, and the field's lag read from the
        # samples, need every sample at once
        whole = registry.takes_whole_log(filter_name)
        first_s = math.inf if whole or FIELD_LAG_FROM_LOG in latency_s.values() else FIRST_BLOCK_S
        found = count_samples(path, devices, tf_device, {d.name for d, _ in chosen}, first_s)
    # past the passes that may find the log unpairable (and fall back to the whole read, which warns anew)
    _pass_on(caught)
    runs, done, field_lags, filters = [], [], [], []
    for dev, _ in chosen:
        counted, first = found[dev.name].census, found[dev.name].first
        if counted.not_increasing is not None:  # as the whole read's check_samples
            raise not_increasing_error(path, dev.name, counted.not_increasing)
        note = check_counts(path, dev.name, counted.count, counted.finite)
        if note:
            warnings.warn(f"{path}: {note}", UserWarning, stacklevel=2)
        assert counted.first_ns is not None and first is not None  # check_counts: at least two samples
        t_rel = seconds_since(first.stamp_ns, counted.first_ns)  # with "auto", ``first`` is every sample
        nine, flt, lag = _device_filter(
            dev, counted.rate.rate(), counted.has_mag, use_mag, filter_name, latency_s, t_rel, first.gyro, first.mag
        )
        if learns_in_blocks(flt):
            flt.spool_in(out.parent)  # beside the output, whose size it is of (not in a small /tmp)
        field_lags += lag
        filters.append(_DeviceFilter(dev, flt, nine, counted.first_ns, first))
    check_disk(path, out, [(_size_frame(f.dev), *_spooled(f.flt, found[f.dev.name].census)) for f in filters])
    try:
        _learn(path, [f for f in filters if learns_in_blocks(f.flt)])
        for (dev, name), f in zip(chosen, filters):
            runs.append(_block_run(dev, name, f, found[dev.name], tf_device))
            done.append((dev.name, found[dev.name].census.count, getattr(f.flt, "name", filter_name), f.nine))
        copy_with_estimates(path, out, scan.profile, [r.target for r in runs], StreamFeed(runs))
    finally:
        for f in filters:
            if learns_in_blocks(f.flt):
                f.flt.close()
    topics = [(r.target.topic, r.target.topic_out, r.target.sequence) for r in runs]
    return EstimateSummary(path=out, devices=done, topics=topics, field_lags=field_lags)


def _size_frame(dev: DeviceLog | StreamDevice) -> str:
    """A frame id as long as the estimate's of ``dev`` (:func:`_target`: ``base_link``, or its IMU's,
    whose name is about the device's)."""
    return BODY_FRAME if dev.metadata is not None else dev.name


def _spooled(flt: AttitudeFilter, counted: DeviceCensus) -> tuple[int, int]:
    """A device's sample count, and the bytes its filter keeps in temporary files over them."""
    if not learns_in_blocks(flt):
        return counted.count, 0
    assert counted.first_ns is not None and counted.last_ns is not None  # check_counts: two samples at least
    span = (counted.last_ns - counted.first_ns) * 1e-9  # the stamps' span: a gap's time has windows too
    return counted.count, flt.spool_bytes(counted.count, span)


def check_disk(path: Path, out: Path, devices: list[tuple[str, int, int]]) -> None:
    """Refuse an estimate whose output and temporary files need more disk than ``out``'s folder has
    free, before the work: :class:`EstimateError` naming ``--out``.

    ``devices``: each filtered device's estimate ``frame_id``, sample count, and the bytes its filter
    keeps in temporary files there (a smoother learning in blocks,
    :meth:`~gyroemu.pipelines.estimation.protocol.BlockLearner.spool_bytes`). The output is the log's
    copy (its size: the copy keeps its records and compression) and an estimate message a sample (before
    compression: at most what they add)."""
    need = copy = path.stat().st_size
    estimates = spooled = 0
    for frame_id, count, spool in devices:
        estimates += count * (IMU.message_size(frame_id) + MCAP_RECORD_OVERHEAD)
        spooled += spool
    need += estimates + spooled
    free = free_bytes(out.parent)
    if need > free:
        what = f"the log's copy {human_size(copy)}, the estimates {human_size(estimates)} before compression"
        what += f", the smoother's temporary files {human_size(spooled)}" if spooled else ""
        raise EstimateError(
            f"argument --out: the estimate needs about {human_size(need)} of disk ({what}), but {out.parent} has "
            f"{human_size(free)} free: write to another folder (--out)"
        )


@dataclass(frozen=True, eq=False)
class _DeviceFilter:
    """A device's filter in the streamed path, with what it runs on."""

    dev: StreamDevice
    flt: AttitudeFilter
    nine: bool
    first_ns: int  # the device's first stamp: the filter runs on seconds since it (``seconds_since``)
    first: DeviceBlock  # its first block of samples (:data:`FIRST_BLOCK_S`), or all of them

    def feed(self, block: DeviceBlock, rest: bool) -> None:
        """``learn`` the block; with ``rest``, only its samples after the first block (given first)."""
        block = block.after(self.first.through_ns) if rest else block
        if len(block):
            t = seconds_since(block.stamp_ns, self.first_ns)
            assert learns_in_blocks(self.flt)
            self.flt.learn(t, block.gyro, block.accel, block.mag if self.nine else None)


def _learn(path: Path, filters: list[_DeviceFilter]) -> None:
    """Give each offline filter that learns a log a block at a time its device's samples in time order,
    from one more pass over the log: its first block, then the rest as the log goes by."""
    if not filters:
        return
    streams = [DeviceStream(f.dev.channels, messages=f.dev.messages) for f in filters]
    for f in filters:
        f.feed(f.first, rest=False)
    for batch in McapRecordWalk(path).batches():
        for f, stream in zip(filters, streams):
            stream.feed(batch)
            f.feed(stream.take(), rest=True)
    for f, stream in zip(filters, streams):
        f.feed(stream.take(final=True), rest=True)


def _block_run(dev: StreamDevice, name: str, f: _DeviceFilter, counted: Counted, tf_device: str | None) -> BlockRun:
    """The :class:`BlockRun` of device ``dev``'s filter ``f`` (its census ``counted``), started."""
    target = _target(dev, name, np.empty(0, np.int64), {})
    if dev.name == tf_device:
        target.tf_keep, target.tf_pos = np.zeros(0, dtype=bool), np.zeros((0, 3))
    run = BlockRun(
        target=target,
        stream=DeviceStream(dev.channels, pair_pose=counted.pose_pairs, messages=dev.messages),
        flt=f.flt,
        nine=f.nine,
        first_ns=f.first_ns,
        count=counted.census.count,
        pose=counted.pose_pairs,
        thinning=TfThinning(TF_LOG_RATE_HZ) if dev.name == tf_device else None,
        q_bs=mounting_from_metadata(dev.metadata),
    )
    run.start(f.first)
    return run


def _pass_on(caught: list[warnings.WarningMessage]) -> None:
    """Warn again what reading the log warned, but the topics skipped: every topic is copied."""
    for w in caught:
        if not (issubclass(w.category, LogWarning) and "skipping topic" in str(w.message)):
            warnings.warn(w.message, w.category, stacklevel=3)


def _device_filter(
    dev: DeviceLog | StreamDevice,
    rate_hz: float,
    has_mag: bool,
    use_mag: bool | None,
    filter_name: str,
    latency_s: Mapping[str, float | str] | None,
    t_rel: np.ndarray,
    gyro: np.ndarray,
    mag: np.ndarray | None,
) -> tuple[bool, AttitudeFilter, list[tuple[str, FieldLag, float]]]:
    """``(9D?, the filter, [(device, FieldLag, the magnetometer's latency)] or [])`` for device ``dev``
    (anything with ``name`` and ``metadata``) of samples at ``rate_hz``; ``t_rel``, ``gyro``, ``mag`` the
    samples the field's lag is read from when ``latency_s`` asks for it (every sample of the device)."""
    nine = has_mag if use_mag is None else (use_mag and has_mag)
    setup = setup_from_metadata(dev.metadata, rate_hz, use_mag=nine)
    lag = None
    if latency_s:
        setup, lag = latencies_for_log(setup, latency_s, t_rel, gyro, mag if nine else None)
    return (
        nine,
        make_filter(filter_name, setup, argument="--filter"),
        [] if lag is None else [(dev.name, lag, setup.mag_latency_s)],
    )


def _target(
    dev: DeviceLog | StreamDevice, topic_out: str, stamp_ns: np.ndarray, fields: dict[str, Any]
) -> EstimateTarget:
    """The estimate of device ``dev`` (a gyroemu device's in ``base_link``, turned into the body's by its
    mounting where ``fields`` are made; another's in its IMU's frame)."""
    frame_id = BODY_FRAME if dev.metadata is not None else None
    return EstimateTarget(dev.topics[IMU_ROLE], topic_out, stamp_ns, fields, frame_id)


def _check_topics_out(path: Path, chosen: Sequence[tuple[object, str]], channels: Sequence[ChannelInfo]) -> None:
    """:class:`EstimateTopicError` for an estimate topic the log holds already, unless it is an earlier
    estimate, which the copy replaces: of type ``sensor_msgs/msg/Imu``, and a channel ``gyroemu estimate``
    marked as its own (:data:`~.estimate_copy.ESTIMATE_CHANNEL`), or named ``.../estimate/imu`` (logs
    estimated before the mark)."""
    types = {c.topic: c.schema_name for c in channels}
    marked = {c.topic for c in channels if c.metadata.get("gyroemu") == ESTIMATE_CHANNEL}
    for _, name in chosen:
        if name not in types:
            continue
        if types[name] not in ("sensor_msgs/msg/Imu", "sensor_msgs/Imu"):
            raise EstimateTopicError(
                f"argument --topic-out: {path} has {name} of type {types[name]}: name another topic"
            )
        if name not in marked and split_topic(name)[1] != ESTIMATE_ROLE:
            raise EstimateTopicError(
                f"argument --topic-out: {path} has {name} already, and not as an estimate gyroemu wrote: name "
                "another topic (an earlier estimate is replaced)"
            )
