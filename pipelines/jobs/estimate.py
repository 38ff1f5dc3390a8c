"""``gyroemu estimate``: run an attitude filter over a recorded log and write its estimate.

The output is the input file with an estimate channel added: every channel of the input (gyroemu's
or anyone's: ``/tf``, cameras, ...) is copied record for record, with its schema, metadata, message
bytes, sequence numbers and log and publish times, and so are the file's metadata records (the
copy reads and writes Message records in bulk: :class:`~gyroemu.pipelines.formats.mcap_records.McapRecordWalk`,
:meth:`~gyroemu.pipelines.formats.mcap_records.McapFileWriter.add_raw_messages`). Attachments are not copied.

The estimate (``sensor_msgs/msg/Imu``: the estimated ``q_wb`` with its covariance when the filter has
one, and the bias-corrected rate) goes to ``topic_out`` (default ``/estimate/imu``): one message per
message of the IMU topic it follows, right after it in the file, with its log and publish times and its
header stamp. Its ``frame_id`` is the IMU message's, except for a gyroemu log's device, whose estimates
are in ``base_link`` as ``interface.md`` has them. The channel uses the IMU channel's schema. An input
channel of the same topic (an earlier estimate) is replaced; a topic of another type there is an error.

Which IMU topic: ``topic`` when given (any ``sensor_msgs/msg/Imu`` topic that
:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` takes as a device's measurements). Without it the
file's only IMU topic; a gyroemu log of several devices gets every device filtered, each estimate on
its own ``/<device>/estimate/imu``; any other file with several IMU topics is an error
(:class:`EstimateTopicError`) that lists them. The output is written to a temporary name and renamed
when complete.
"""

from __future__ import annotations

import os
import secrets
import warnings
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyroemu.pipelines.estimation.registry import is_offline, make_filter
from gyroemu.pipelines.estimation.series import check_counts, check_samples, estimate_series, rate_of
from gyroemu.pipelines.estimation.setup import (
    FIELD_LAG_FROM_LOG,
    check_latency_sensors,
    latencies_for_log,
    setup_from_metadata,
)
from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    POSE_ROLE,
    role_topic,
    series_fields,
    split_topic,
)
from gyroemu.pipelines.formats.device_stream import (
    DeviceBlock,
    DeviceCensus,
    DeviceStream,
    NotStreamable,
    warn_drops,
)
from gyroemu.pipelines.formats.frames import TF_LOG_RATE_HZ, TfThinning, tf_indices
from gyroemu.pipelines.formats.mcap_log import (
    DeviceLog,
    LogWarning,
    announce_scan,
    device_name,
    group_devices,
    no_imu_error,
    read_mcap,
)
from gyroemu.pipelines.formats.mcap_records import (
    OFFERED_QOS_PROFILES,
    McapFileWriter,
    McapRecordWalk,
    McapScan,
    RawMessages,
)
from gyroemu.pipelines.formats.messages import IMU, MessageType, ns_to_stamps

__all__ = [
    "DEFAULT_TOPIC_OUT",
    "EstimateError",
    "EstimateSummary",
    "EstimateTopicError",
    "check_options",
    "estimate_log",
]

DEFAULT_TOPIC_OUT = "/estimate/imu"
"""Where the estimate goes unless the caller names a topic."""


class EstimateError(ValueError):
    """Bad options of ``gyroemu estimate`` (the message names the argument)."""


class EstimateTopicError(EstimateError):
    """The IMU topic to filter, or the topic to write, cannot be chosen (the message names the argument)."""


def check_options(path: str | os.PathLike[str], out: str | os.PathLike[str], *, force: bool = False) -> None:
    """:class:`EstimateError` for an output that cannot be written: in a missing folder, a folder, the
    input itself, or an existing file without ``force``."""
    path, out = Path(path), Path(out)
    if not out.parent.is_dir():
        raise EstimateError(f"argument --out: {out.parent} is not a folder")
    if out.is_dir():
        raise EstimateError(f"argument --out: {out} is a folder")
    if out.exists() and path.exists() and out.resolve() == path.resolve():
        raise EstimateError(f"argument --out: {out} is the input: the input is never modified")
    if out.exists() and not force:
        raise EstimateError(f"argument --out: {out} exists (use --force to overwrite it)")


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
    devices: list
    topics: list = field(default_factory=list)
    field_lags: list = field(default_factory=list)


@dataclass
class _Target:
    """One IMU topic to follow with estimates."""

    topic: str
    topic_out: str
    stamp_ns: np.ndarray  # (N,) int64, increasing: the filtered samples' header stamps
    fields: dict  # Imu body fields of the estimate, (N, ...) each
    frame_id: str | None  # None: the IMU message's
    channel_out: int = 0
    sequence: int = 0
    tf_keep: np.ndarray | None = None  # (N,) bool: rows whose estimate also goes on /tf (map -> body_estimate)
    tf_pos: np.ndarray | None = None  # (N, 3): the true position there (zeros without /truth/pose)
    tf_channel_out: int = 0
    tf_sequence: int = 0


def _topic_name(topic: str) -> str:
    return topic if topic.startswith("/") else "/" + topic


def _choose(devices_found, path, topic: str | None, topic_out: str | None) -> list:
    """``[(device, estimate topic)]`` by the rules of the module's notes (a device: anything with
    ``topics`` and ``metadata``, a :class:`DeviceLog` or a :class:`_Streamed` device)."""
    devices = {d.topics[IMU_ROLE]: d for d in devices_found}
    if topic_out is not None:
        if not topic_out.startswith("/") or topic_out == "/" or any(c.isspace() for c in topic_out):
            raise EstimateTopicError(f"argument --topic-out: {topic_out!r} is not a topic name like /estimate/imu")
    if topic is not None:
        name = _topic_name(topic)
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

    An online filter runs as the log is read, a block at a time, in memory that does not grow with the
    log's length (:mod:`~gyroemu.pipelines.formats.device_stream`); an offline filter, a field lag read
    from the samples (``latency_s={"mag": "auto"}``) and a log whose topics one pass cannot pair read
    the log whole into memory first. Both give the same bytes.

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
    check_options(path, out, force=force)
    if not read_whole and not is_offline(filter_name) and FIELD_LAG_FROM_LOG not in (latency_s or {}).values():
        try:
            return _estimate_streamed(path, out, filter_name, use_mag, topic, topic_out, latency_s or {})
        except NotStreamable:
            pass  # a log a single pass cannot pair: read whole, with the same result
    return _estimate_whole(path, out, filter_name, use_mag, topic, topic_out, latency_s)


def _estimate_whole(path, out, filter_name, use_mag, topic, topic_out, latency_s) -> EstimateSummary:
    """:func:`estimate_log` with the log read into memory (an offline filter, a field lag read from the
    samples, a log whose topics :mod:`~gyroemu.pipelines.formats.device_stream` cannot pair in one pass)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        log = read_mcap(path)
    for w in caught:  # every topic is copied: "skipping topic" is not news here
        if not (issubclass(w.category, LogWarning) and "skipping topic" in str(w.message)):
            warnings.warn(w.message, w.category, stacklevel=2)
    chosen = _choose(log.devices.values(), path, topic, topic_out)
    _check_topics_out(path, chosen, log.channels)
    targets, done, field_lags = [], [], []
    for dev, name in chosen:
        samples = dev.samples
        note = check_samples(path, dev.name, samples.t, samples.gyro, samples.accel)
        if note:
            warnings.warn(f"{path}: {note}", UserWarning, stacklevel=2)
        nine = samples.has_mag if use_mag is None else (use_mag and samples.has_mag)
        setup = setup_from_metadata(dev.metadata, rate_of(samples.t), use_mag=nine)
        t_rel = samples.t - samples.t[0]  # relative times keep float64's resolution for the filter
        if latency_s:
            setup, lag = latencies_for_log(setup, latency_s, t_rel, samples.gyro, samples.mag if nine else None)
            if lag is not None:
                field_lags.append((dev.name, lag, setup.mag_latency_s))
        flt = make_filter(filter_name, setup)
        est = flt.process(t_rel, samples.gyro, samples.accel, samples.mag if nine else None)
        fields = series_fields(estimate_series(samples.t, est, samples.gyro))
        targets.append(
            _Target(
                topic=dev.topics[IMU_ROLE],
                topic_out=name,
                stamp_ns=np.asarray(dev.stamp_ns, dtype=np.int64),
                fields={k: np.asarray(v) for k, v in fields.items()},
                frame_id=BODY_FRAME if dev.metadata is not None else None,
            )
        )
        done.append((dev.name, len(samples), getattr(flt, "name", filter_name), nine))
    _add_estimate_tf(targets, chosen)
    _copy_with_estimates(path, out, log.profile, targets)
    topics = [(t.topic, t.topic_out, t.sequence) for t in targets]
    return EstimateSummary(path=out, devices=done, topics=topics, field_lags=field_lags)


FIRST_BLOCK_S = 60.0
"""A filter initialises from its first block (the MEKF reads at most its first 10 s, to find north from
Earth's rate): a log read a block at a time gives the filter its first minute at once."""


@dataclass
class _Channel:
    """A channel of a type gyroemu decodes, with messages (what :func:`group_devices` groups)."""

    channel_id: int
    topic: str
    mtype: MessageType


@dataclass(frozen=True)
class _Streamed:
    """A device of a log read a block at a time: :class:`DeviceLog`'s header without the samples."""

    name: str
    topics: dict[str, str]  # role -> topic
    metadata: dict | None
    channels: dict[str, tuple[int, MessageType]]  # role -> (channel id, type), in read_mcap's order


def _scan_devices(path: Path) -> tuple[dict[str, _Streamed], McapScan]:
    """The log's devices as :func:`read_mcap` finds them, from one pass of bounded memory that decodes
    every message and drops it (the same :class:`LogError` for a corrupt file, the same warnings)."""
    scan = McapScan(path)
    counts = scan.check()
    skipped = announce_scan(path, scan)
    typed = [
        _Channel(channel_id, data.channel.topic, data.mtype)
        for channel_id, data in scan.data.items()
        if data.mtype is not None and counts.get(channel_id)
    ]
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    devices = {}
    for prefix, group in group_devices(path, typed, skipped).items():
        name, meta = device_name(prefix, metadata)
        devices[name] = _Streamed(
            name=name,
            topics={role: c.topic for role, c in group.items()},
            metadata=meta,
            channels={role: (c.channel_id, c.mtype) for role, c in group.items()},
        )
    if not devices:
        raise no_imu_error(scan, path)
    topics = [c.topic for c in scan.channels.values()]
    if any(topics.count(t) > 1 for d in devices.values() for t in d.topics.values()):
        raise NotStreamable("a device's topic on several channels")
    return devices, scan


def _census(path: Path, devices: dict[str, _Streamed], pose_of: str | None) -> dict[str, tuple[DeviceCensus, bool]]:
    """Per device, the figures of its samples and whether ``/truth/pose`` gives each of them its position
    (asked for the device ``pose_of`` only), from one pass over the log; the warnings :func:`read_mcap`
    gives for samples dropped or unflagged."""
    streams = {
        name: DeviceStream(d.channels, pair_pose=name == pose_of and POSE_ROLE in d.channels)
        for name, d in devices.items()
    }
    census = {name: DeviceCensus() for name in devices}
    for batch in McapRecordWalk(path).batches():
        for name, stream in streams.items():
            stream.feed(batch)
            census[name].add(stream.take())
    out = {}
    for name, stream in streams.items():
        census[name].add(stream.take(final=True))
        warn_drops(path, stream, devices[name].topics)
        out[name] = (census[name], pose_of == name and census[name].pose_pairs(stream))
    return out


@dataclass
class _Run:
    """One device filtered a block at a time as the copy reads the log, its estimates in ``target``'s
    rows from the first not yet written on."""

    target: _Target
    stream: DeviceStream
    flt: object
    nine: bool
    t0: float  # the first sample's stamp, s: the filter runs on stamps relative to it
    count: int  # the device's samples (the census)
    pose: bool  # /tf positions from /truth/pose (else the origin)
    thinning: TfThinning | None  # the device whose estimate also goes on /tf
    done: int = 0
    ready_ns: int | None = None  # every IMU message up to this stamp has its estimate (or was dropped)
    waiting: list[DeviceBlock] = field(default_factory=list)

    def add(self, block: DeviceBlock, final: bool = False) -> None:
        """The stream's next samples: filtered, or held until the first block is long enough."""
        if self.done == 0 and (self.waiting or len(block)):
            self.waiting.append(block)
            stamps = [b.stamp_ns for b in self.waiting if len(b)]
            if not final and (not stamps or stamps[-1][-1] - stamps[0][0] < FIRST_BLOCK_S * 1e9):
                return
            block, self.waiting = _joined(self.waiting), []
        if len(block):
            self._filter(block)
        if block.through_ns is not None:
            self.ready_ns = block.through_ns

    def _filter(self, block: DeviceBlock) -> None:
        t = ns_to_stamps(block.stamp_ns)
        est = self.flt.process(t - self.t0, block.gyro, block.accel, block.mag if self.nine else None)  # type: ignore[attr-defined]
        fields = {k: np.asarray(v) for k, v in series_fields(estimate_series(t, est, block.gyro)).items()}
        n, target = len(block), self.target
        self.done += n
        target.stamp_ns = np.concatenate((target.stamp_ns, block.stamp_ns))
        target.fields = {
            k: np.concatenate((target.fields[k], v)) if v.ndim > 1 and k in target.fields else v
            for k, v in fields.items()
        }
        if self.thinning is None:
            return
        orientation = fields["orientation"]
        if orientation.ndim != 2:
            raise NotStreamable("an estimate without attitudes")
        keep = np.zeros(n, dtype=bool)
        index = np.flatnonzero(np.all(np.isfinite(orientation), axis=1))
        keep[index[self.thinning.keep(block.stamp_ns[index])]] = True
        if self.done == self.count and self.thinning.last():  # tf_indices keeps the last valid row
            if not len(index):
                raise NotStreamable("the last valid estimate is in a block already written")
            keep[index[-1]] = True
        assert target.tf_keep is not None and target.tf_pos is not None
        target.tf_keep = np.concatenate((target.tf_keep, keep))
        target.tf_pos = np.concatenate((target.tf_pos, block.pose_pos if self.pose else np.zeros((n, 3))))

    def written(self, last_ns: int) -> None:
        """Forget the rows up to ``last_ns``: their IMU messages are written."""
        target = self.target
        k = int(np.searchsorted(target.stamp_ns, last_ns, side="right"))
        target.stamp_ns = target.stamp_ns[k:]
        target.fields = {name: v[k:] if v.ndim > 1 else v for name, v in target.fields.items()}
        if target.tf_keep is not None and target.tf_pos is not None:
            target.tf_keep, target.tf_pos = target.tf_keep[k:], target.tf_pos[k:]


def _joined(blocks: list[DeviceBlock]) -> DeviceBlock:
    through = [b.through_ns for b in blocks if b.through_ns is not None]
    return DeviceBlock(
        **{
            name: np.concatenate([getattr(b, name) for b in blocks])
            for name in ("stamp_ns", "gyro", "accel", "mag", "pose_ns", "pose_pos")
        },
        through_ns=through[-1] if through else None,
    )


@dataclass
class _StreamFeed:
    """The targets' estimates made as :func:`_copy_with_estimates` reads the log."""

    runs: list[_Run]

    def push(self, batch: RawMessages) -> list[int | None]:
        """Read a chunk's messages into every run; returns, per run, the chunk's last IMU stamp (None: none)."""
        last = []
        for run in self.runs:
            last.append(run.stream.feed(batch))
            run.add(run.stream.take())
        return last

    def ready(self, last: list[int | None]) -> bool:
        """Whether a chunk whose IMU messages end at ``last`` (per run) can be written."""
        return all(s is None or (r.ready_ns is not None and s <= r.ready_ns) for r, s in zip(self.runs, last))

    def written(self, last: list[int | None]) -> None:
        for run, s in zip(self.runs, last):
            if s is not None:
                run.written(s)

    def finish(self) -> None:
        """The file has ended: every sample left is complete."""
        for run in self.runs:
            run.add(run.stream.take(final=True), final=True)


def _estimate_streamed(path, out, filter_name, use_mag, topic, topic_out, latency_s) -> EstimateSummary:
    """:func:`estimate_log` a block at a time: three passes over the log (validate it and find its devices;
    count their samples; copy it while filtering), in memory that does not grow with its length. The
    same bytes as :func:`_estimate_whole` (``tests/pipelines/test_estimate_stream.py``). Raises
    :class:`NotStreamable` for a log a single pass cannot pair, before ``out`` is written."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        devices, scan = _scan_devices(path)
        chosen = _choose(devices.values(), path, topic, topic_out)
        _check_topics_out(path, chosen, scan.channel_info())
        tf_device = next((d.name for d, _ in chosen if d.metadata is not None), None)
        census = _census(path, devices, tf_device)
        runs, done = [], []
        for dev, name in chosen:
            counted, pose = census[dev.name]
            note = check_counts(path, dev.name, counted.count, counted.finite)
            if note:
                warnings.warn(f"{path}: {note}", UserWarning, stacklevel=2)
            nine = counted.has_mag if use_mag is None else (use_mag and counted.has_mag)
            setup = setup_from_metadata(dev.metadata, counted.rate.rate(), use_mag=nine)
            if latency_s:
                setup, _ = latencies_for_log(setup, latency_s, np.empty(0), np.empty((0, 3)), None)
            flt = make_filter(filter_name, setup)
            target = _Target(
                topic=dev.topics[IMU_ROLE],
                topic_out=name,
                stamp_ns=np.empty(0, np.int64),
                fields={},
                frame_id=BODY_FRAME if dev.metadata is not None else None,
            )
            if dev.name == tf_device:
                target.tf_keep, target.tf_pos = np.zeros(0, dtype=bool), np.zeros((0, 3))
            assert counted.first_ns is not None  # check_counts: at least two samples
            runs.append(
                _Run(
                    target=target,
                    stream=DeviceStream(dev.channels, pair_pose=pose),
                    flt=flt,
                    nine=nine,
                    t0=float(ns_to_stamps(np.array([counted.first_ns]))[0]),
                    count=counted.count,
                    pose=pose,
                    thinning=TfThinning(TF_LOG_RATE_HZ) if dev.name == tf_device else None,
                )
            )
            done.append((dev.name, counted.count, getattr(flt, "name", filter_name), nine))
        _copy_with_estimates(path, out, scan.profile, [r.target for r in runs], _StreamFeed(runs))
    for w in caught:  # every topic is copied: "skipping topic" is not news here
        if not (issubclass(w.category, LogWarning) and "skipping topic" in str(w.message)):
            warnings.warn(w.message, w.category, stacklevel=3)
    topics = [(r.target.topic, r.target.topic_out, r.target.sequence) for r in runs]
    return EstimateSummary(path=out, devices=done, topics=topics)


def _check_topics_out(path: Path, chosen: list, channels) -> None:
    """:class:`EstimateTopicError` for an estimate topic the log holds with another type."""
    types = {c.topic: c.schema_name for c in channels}
    for _, name in chosen:
        if name in types and types[name] not in ("sensor_msgs/msg/Imu", "sensor_msgs/Imu"):
            raise EstimateTopicError(
                f"argument --topic-out: {path} has {name} of type {types[name]}: name another topic"
            )


def _add_estimate_tf(targets: list[_Target], chosen: list[tuple[DeviceLog, str]]) -> None:
    """Mark the rows of the first target of a gyroemu device (one with a ``gyroemu`` metadata record;
    another program's tree names its own frames) whose ``map -> body_estimate`` goes on /tf:
    thinned to :data:`~gyroemu.pipelines.formats.frames.TF_LOG_RATE_HZ` with the last row kept
    (:mod:`gyroemu.pipelines.formats.frames`), placed at the true position where the log has a
    ``/truth/pose`` at the same stamps."""
    from gyroemu.pipelines.formats.messages import stamps_to_ns

    for target, (dev, _) in zip(targets, chosen):
        if dev.metadata is None:  # another program's log: its tree names its own frames
            continue
        orientation = target.fields.get("orientation")
        if orientation is None or np.ndim(orientation) != 2:
            continue
        valid = np.all(np.isfinite(orientation), axis=1)
        keep = np.zeros(len(valid), dtype=bool)
        index = np.flatnonzero(valid)
        keep[index[tf_indices(target.stamp_ns[index], TF_LOG_RATE_HZ)]] = True
        pos = np.zeros((len(valid), 3))
        pose = dev.pose
        if pose is not None and len(pose) == len(valid):
            pose_ns = stamps_to_ns(pose.t)
            if np.abs(pose_ns - target.stamp_ns).max(initial=0) <= 1000:
                pos = np.asarray(pose.pos_w, dtype=float)
        target.tf_keep, target.tf_pos = keep, pos
        return


def _copy_with_estimates(
    path: Path, out: Path, profile: str, targets: list[_Target], feed: _StreamFeed | None = None
) -> None:
    """Write ``out``: every record of ``path`` but the channels of the targets' topics, and after each
    message of a target's IMU topic the estimate at its stamp (when it has one). With a ``feed``, the
    targets' rows are made as the copy goes (:class:`_StreamFeed`): each chunk's records wait until the
    estimates of its IMU messages exist, then go out as they would have (the same calls to the writer in
    the same order, so the same bytes)."""
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out.parent} is not a folder")
    replaced = {t.topic_out for t in targets}
    by_topic = {t.topic: t for t in targets}
    tmp = out.with_name(f".{out.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb", buffering=1 << 20) as f:
            writer = McapFileWriter(f, profile=profile or "ros2")
            _register_estimate_tf(writer, targets)
            walk = McapRecordWalk(path)
            schema_ids: dict[int, int] = {}
            channel_ids = np.full(1 << 16, -1, dtype=np.int64)  # input channel id -> output id, -1: dropped
            follows: dict[int, _Target] = {}  # input channel id -> the target whose IMU it carries
            seen: set[int] = set()
            metadata_done = 0

            def register(channel_id: int) -> None:
                seen.add(channel_id)
                c = walk.channels[channel_id]
                if c.topic in replaced or c.metadata.get("gyroemu") == _ESTIMATE_TF:
                    return
                schema = walk.schemas.get(c.schema_id)
                if schema is not None and c.schema_id not in schema_ids:
                    schema_ids[c.schema_id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                schema_id = schema_ids.get(c.schema_id, 0)
                channel_ids[channel_id] = writer.register_channel(c.topic, c.message_encoding, schema_id, c.metadata)
                target = by_topic.get(c.topic)
                if target is not None and schema is not None and c.message_encoding == "cdr":
                    follows[channel_id] = target
                    if not target.channel_out:
                        metadata = {"offered_qos_profiles": OFFERED_QOS_PROFILES}
                        if "topic_type_hash" in c.metadata:
                            metadata["topic_type_hash"] = c.metadata["topic_type_hash"]
                        target.channel_out = writer.register_channel(target.topic_out, "cdr", schema_id, metadata)

            def emit(batch: RawMessages, metadata_read: int) -> None:
                nonlocal metadata_done
                for m in walk.metadata[metadata_done:metadata_read]:
                    writer.add_metadata(m.name, dict(m.metadata))
                metadata_done = metadata_read
                for channel_id in np.unique(batch.channel_id).tolist():
                    if channel_id not in seen:
                        register(channel_id)
                writer.add_raw_messages(*_with_estimates(batch, channel_ids, follows))

            held: deque[tuple[RawMessages, int, list[int | None]]] = deque()
            for batch in walk.batches():
                if feed is None:
                    emit(batch, len(walk.metadata))
                    continue
                held.append((batch, len(walk.metadata), feed.push(batch)))
                while held and feed.ready(held[0][2]):
                    batch, metadata_read, last = held.popleft()
                    emit(batch, metadata_read)
                    feed.written(last)
            if feed is not None:
                feed.finish()
                for batch, metadata_read, _ in held:
                    emit(batch, metadata_read)
            for channel_id in walk.channels:  # channels without messages
                if channel_id not in seen:
                    register(channel_id)
            for m in walk.metadata[metadata_done:]:
                writer.add_metadata(m.name, dict(m.metadata))
            writer.finish()
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


_ESTIMATE_TF = "estimate_tf"
"""Channel metadata ``gyroemu`` of the /tf channel that holds ``map -> body_estimate``: a second /tf
channel (MCAP lets channels share a topic; players publish both on /tf), dropped when the output is
estimated again."""


def _register_estimate_tf(writer: McapFileWriter, targets: list[_Target]) -> None:
    """The /tf channel of the estimate's transforms, when a target has them."""
    from gyroemu.pipelines.formats.frames import TF_TOPIC
    from gyroemu.pipelines.formats.tf_messages import TF_MESSAGE_TYPE, tf_schema

    for target in targets:
        if target.tf_keep is not None:
            schema_id = writer.register_schema(TF_MESSAGE_TYPE, "ros2msg", tf_schema().encode())
            metadata = {"offered_qos_profiles": OFFERED_QOS_PROFILES, "gyroemu": _ESTIMATE_TF}
            target.tf_channel_out = writer.register_channel(TF_TOPIC, "cdr", schema_id, metadata)


def _estimate_tf_rows(target: _Target, row: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """``map -> body_estimate`` TFMessages at ``stamps`` (the target's rows ``row``)."""
    from gyroemu.pipelines.formats.channels import ESTIMATE_FRAME, WORLD_FRAME
    from gyroemu.pipelines.formats.tf_messages import encode_tf

    assert target.tf_pos is not None
    xyzw = np.asarray(target.fields["orientation"])[row]
    return encode_tf(stamps, [(WORLD_FRAME, ESTIMATE_FRAME)], target.tf_pos[row][:, None], xyzw[:, None])


def _with_estimates(batch: RawMessages, channel_ids: np.ndarray, follows: dict[int, _Target]) -> tuple:
    """The arguments of :meth:`McapFileWriter.add_raw_messages` for ``batch``: its messages on their
    output channels (dropped channels left out), each target's estimate right after its IMU message."""
    channel = batch.channel_id.astype(np.int64)
    n = len(channel)
    position = [np.arange(n, dtype=np.int64) * 2]  # sort keys: message i at 2 i, its estimate at 2 i + 1
    parts = [(channel_ids[channel], batch.sequence, batch.log_time, batch.publish_time, batch.start, batch.size)]
    buffers = [batch.buffer]
    base = len(batch.buffer)

    def add(rows: np.ndarray, channel_out: int, first_sequence: int, k: np.ndarray) -> int:
        """Put encoded ``rows`` (m, size) on ``channel_out`` right after the input messages ``k`` (m,),
        with their log and publish times; returns m."""
        nonlocal base
        m, size = rows.shape
        buffers.append(rows.reshape(-1))
        parts.append(
            (
                np.full(m, channel_out, dtype=np.int64),
                (first_sequence + np.arange(m)) % (1 << 32),
                batch.log_time[k],
                batch.publish_time[k],
                base + np.arange(m, dtype=np.int64) * size,
                np.full(m, size, dtype=np.int64),
            )
        )
        position.append(k * 2 + 1)
        base += rows.size
        return m

    for channel_id, target in follows.items():
        mine = np.flatnonzero(channel == channel_id)
        if not len(mine):
            continue
        decoded = IMU.decode(batch.payloads(mine))
        row = np.minimum(np.searchsorted(target.stamp_ns, decoded.stamp_ns), len(target.stamp_ns) - 1)
        hit = target.stamp_ns[row] == decoded.stamp_ns
        mine, row, stamps, frames = mine[hit], row[hit], decoded.stamp_ns[hit], decoded.frame_id[hit]
        if not len(mine):
            continue
        frame_ids = [target.frame_id] if target.frame_id is not None else sorted(set(frames.tolist()))
        for frame_id in frame_ids:
            group = np.arange(len(mine)) if target.frame_id is not None else np.flatnonzero(frames == frame_id)
            k = mine[group]
            fields = {  # per-sample arrays at the rows; constants (no estimate of a quantity) as they are
                name: value[row[group]] if value.ndim > 1 else value for name, value in target.fields.items()
            }
            rows = IMU.encode(stamps[group], frame_id, fields)
            target.sequence += add(rows, target.channel_out, target.sequence, k)
        if target.tf_keep is not None:
            sel = np.flatnonzero(target.tf_keep[row])
            if len(sel):
                rows = _estimate_tf_rows(target, row[sel], stamps[sel])
                target.tf_sequence += add(rows, target.tf_channel_out, target.tf_sequence, mine[sel])
    order = np.argsort(np.concatenate(position), kind="stable")
    columns = [np.concatenate(column)[order] for column in zip(*parts)]
    keep = columns[0] >= 0
    channel_out, sequence, log_time, publish_time, start, size = (c[keep] for c in columns)
    buffer = np.concatenate(buffers) if len(buffers) > 1 else buffers[0]
    return channel_out, sequence, log_time, publish_time, buffer, start, size
