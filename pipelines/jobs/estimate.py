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
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.estimation.series import check_samples, estimate_series, rate_of
from gyroemu.pipelines.estimation.setup import check_latency_sensors, latencies_for_log, setup_from_metadata
from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    role_topic,
    series_fields,
    split_topic,
)
from gyroemu.pipelines.formats.mcap_log import DeviceLog, LogWarning, read_mcap
from gyroemu.pipelines.formats.mcap_records import (
    OFFERED_QOS_PROFILES,
    McapFileWriter,
    McapRecordWalk,
    RawMessages,
)
from gyroemu.pipelines.formats.messages import IMU

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


def _choose(log, path, topic: str | None, topic_out: str | None) -> list[tuple[DeviceLog, str]]:
    """``[(device, estimate topic)]`` by the rules of the module's notes."""
    devices = {d.topics[IMU_ROLE]: d for d in log.devices.values()}
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
) -> EstimateSummary:
    """Filter the IMU topic(s) of the log ``path`` and write ``out``: the input with the estimate added.

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
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        log = read_mcap(path)
    for w in caught:  # every topic is copied: "skipping topic" is not news here
        if not (issubclass(w.category, LogWarning) and "skipping topic" in str(w.message)):
            warnings.warn(w.message, w.category, stacklevel=2)
    chosen = _choose(log, path, topic, topic_out)
    types = {c.topic: c.schema_name for c in log.channels}
    for _, name in chosen:
        if name in types and types[name] not in ("sensor_msgs/msg/Imu", "sensor_msgs/Imu"):
            raise EstimateTopicError(
                f"argument --topic-out: {path} has {name} of type {types[name]}: name another topic"
            )
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


def _add_estimate_tf(targets: list[_Target], chosen: list[tuple[DeviceLog, str]]) -> None:
    """Mark the rows of the first target of a gyroemu device (one with a ``gyroemu`` metadata record;
    another program's tree names its own frames) whose ``map -> body_estimate`` goes on /tf:
    thinned to :data:`~gyroemu.pipelines.formats.frames.TF_LOG_RATE_HZ` with the last row kept
    (:mod:`gyroemu.pipelines.formats.frames`), placed at the true position where the log has a
    ``/truth/pose`` at the same stamps."""
    from gyroemu.pipelines.formats.frames import TF_LOG_RATE_HZ, tf_indices
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


def _copy_with_estimates(path: Path, out: Path, profile: str, targets: list[_Target]) -> None:
    """Write ``out``: every record of ``path`` but the channels of the targets' topics, and after each
    message of a target's IMU topic the estimate at its stamp (when it has one)."""
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

            for batch in walk.batches():
                for m in walk.metadata[metadata_done:]:
                    writer.add_metadata(m.name, dict(m.metadata))
                metadata_done = len(walk.metadata)
                for channel_id in np.unique(batch.channel_id).tolist():
                    if channel_id not in seen:
                        register(channel_id)
                writer.add_raw_messages(*_with_estimates(batch, channel_ids, follows))
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
        decoded = IMU.decode([batch.payload(int(k)) for k in mine])
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
