"""The input log copied with an estimate after each IMU message: what ``gyroemu estimate`` writes.

Every channel of the input (gyroemu's or anyone's: ``/tf``, cameras, ...) is copied record for record,
with its schema, metadata, message bytes, sequence numbers and log and publish times, and so are the
file's metadata records (the copy reads and writes Message records in bulk:
:class:`~gyroemu.pipelines.formats.mcap_records.McapRecordWalk`,
:meth:`~gyroemu.pipelines.formats.mcap_records.McapFileWriter.add_raw_messages`); after each message of
an :class:`EstimateTarget`'s IMU topic, the estimate at its stamp goes to the target's topic, and for a
gyroemu device ``map -> body_estimate`` on a /tf channel of its own, thinned to
:data:`~gyroemu.pipelines.formats.frames.TF_LOG_RATE_HZ`.

The estimates are either made before the copy, for the whole log (:func:`copy_with_estimates` with the
targets' rows filled), or as it goes (with a :class:`StreamFeed`): each device's samples come from a
:class:`~gyroemu.pipelines.formats.device_stream.DeviceStream` over the same chunks the copy reads, a
:class:`BlockRun` filters them a block at a time, and each chunk is written once the estimates of its
IMU messages exist, by the same calls to the writer in the same order, so the same bytes.
"""

from __future__ import annotations

import os
import secrets
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gyroemu.pipelines.estimation.protocol import AttitudeFilter
from gyroemu.pipelines.estimation.series import estimate_series
from gyroemu.pipelines.formats.channels import series_fields
from gyroemu.pipelines.formats.device_stream import POSE_MATCH_NS, DeviceBlock, DeviceStream, NotStreamable
from gyroemu.pipelines.formats.frames import TF_LOG_RATE_HZ, TfThinning, tf_indices
from gyroemu.pipelines.formats.mcap_log import DeviceLog
from gyroemu.pipelines.formats.mcap_records import (
    OFFERED_QOS_PROFILES,
    McapFileWriter,
    McapRecordWalk,
    RawMessages,
)
from gyroemu.pipelines.formats.messages import IMU, ns_to_stamps, seconds_since

__all__ = [
    "ESTIMATE_CHANNEL",
    "BlockRun",
    "EstimateTarget",
    "StreamFeed",
    "add_estimate_tf",
    "copy_with_estimates",
]

ESTIMATE_CHANNEL = "estimate"
"""Channel metadata ``gyroemu`` of an estimate's channel (``/estimate/imu`` or the ``--topic-out`` given):
what ``gyroemu estimate`` may replace when it estimates the log again (any other topic of the input is
the user's data)."""


@dataclass
class EstimateTarget:
    """One IMU topic to follow with estimates."""

    topic: str
    topic_out: str
    stamp_ns: np.ndarray  # (N,) int64, increasing: the filtered samples' header stamps
    fields: dict[str, Any]  # Imu body fields of the estimate, (N, ...) each
    frame_id: str | None  # None: the IMU message's
    channel_out: int = 0
    sequence: int = 0
    tf_keep: np.ndarray | None = None  # (N,) bool: rows whose estimate also goes on /tf (map -> body_estimate)
    tf_pos: np.ndarray | None = None  # (N, 3): the true position there (zeros without /truth/pose)
    tf_channel_out: int = 0
    tf_sequence: int = 0


@dataclass
class BlockRun:
    """One device filtered a block at a time as the copy reads the log, its estimates in ``target``'s
    rows from the first not yet written on. :meth:`start` with the first block, then :meth:`add` the
    stream's blocks (the first block's samples among them are passed over)."""

    target: EstimateTarget
    stream: DeviceStream
    flt: AttitudeFilter
    nine: bool
    first_ns: int  # the first sample's stamp: the filter runs on seconds since it (``seconds_since``)
    count: int  # the device's samples (the census)
    pose: bool  # /tf positions from /truth/pose (else the origin)
    thinning: TfThinning | None  # the device whose estimate also goes on /tf
    q_bs: np.ndarray | None = None  # (4,) the device's mounting: its estimate turned into the body's (None: as is)
    done: int = 0
    ready_ns: int | None = None  # every IMU message up to this stamp has its estimate (or was dropped)
    _started_ns: int | None = field(default=None, init=False)  # the first block's IMU messages end here

    def start(self, first: DeviceBlock) -> None:
        """Filter the first block, read before the copy."""
        self._started_ns = first.through_ns
        self.add(first)

    def add(self, block: DeviceBlock) -> None:
        """Filter the stream's next samples (those after the first block)."""
        block = block.after(self._started_ns) if self.done else block
        if len(block):
            self._filter(block)
        if block.through_ns is not None:
            self.ready_ns = max(block.through_ns, self.ready_ns or block.through_ns)

    def _filter(self, block: DeviceBlock) -> None:
        t = ns_to_stamps(block.stamp_ns)
        t_rel = seconds_since(block.stamp_ns, self.first_ns)
        est = self.flt.process(t_rel, block.gyro, block.accel, block.mag if self.nine else None)
        series = estimate_series(t, est, block.gyro, self.q_bs)
        fields = {k: np.asarray(v) for k, v in series_fields(series).items()}
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


@dataclass
class StreamFeed:
    """The targets' estimates made as :func:`copy_with_estimates` reads the log."""

    runs: list[BlockRun]

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
        """A chunk whose IMU messages end at ``last`` (per run) is written: its rows are not needed."""
        for run, s in zip(self.runs, last):
            if s is not None:
                run.written(s)

    def finish(self) -> None:
        """The file has ended: every sample left is complete."""
        for run in self.runs:
            run.add(run.stream.take(final=True))


def add_estimate_tf(targets: list[EstimateTarget], chosen: list[tuple[DeviceLog, str]]) -> None:
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
            if np.abs(pose_ns - target.stamp_ns).max(initial=0) <= POSE_MATCH_NS:
                pos = np.asarray(pose.pos_w, dtype=float)
        target.tf_keep, target.tf_pos = keep, pos
        return


def copy_with_estimates(
    path: Path, out: Path, profile: str, targets: list[EstimateTarget], feed: StreamFeed | None = None
) -> None:
    """Write ``out``: every record of ``path`` but the channels of the targets' topics, and after each
    message of a target's IMU topic the estimate at its stamp (when it has one). With a ``feed``, the
    targets' rows are made as the copy goes (:class:`StreamFeed`): each chunk's records wait until the
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
            follows: dict[int, EstimateTarget] = {}  # input channel id -> the target whose IMU it carries
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
                        metadata = {"offered_qos_profiles": OFFERED_QOS_PROFILES, "gyroemu": ESTIMATE_CHANNEL}
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


def _register_estimate_tf(writer: McapFileWriter, targets: list[EstimateTarget]) -> None:
    """The /tf channel of the estimate's transforms, when a target has them."""
    from gyroemu.pipelines.formats.frames import TF_TOPIC
    from gyroemu.pipelines.formats.tf_messages import TF_MESSAGE_TYPE, tf_schema

    for target in targets:
        if target.tf_keep is not None:
            schema_id = writer.register_schema(TF_MESSAGE_TYPE, "ros2msg", tf_schema().encode())
            metadata = {"offered_qos_profiles": OFFERED_QOS_PROFILES, "gyroemu": _ESTIMATE_TF}
            target.tf_channel_out = writer.register_channel(TF_TOPIC, "cdr", schema_id, metadata)


def _estimate_tf_rows(target: EstimateTarget, row: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """``map -> body_estimate`` TFMessages at ``stamps`` (the target's rows ``row``)."""
    from gyroemu.pipelines.formats.channels import ESTIMATE_FRAME, WORLD_FRAME
    from gyroemu.pipelines.formats.tf_messages import encode_tf

    assert target.tf_pos is not None
    xyzw = np.asarray(target.fields["orientation"])[row]
    return encode_tf(stamps, [(WORLD_FRAME, ESTIMATE_FRAME)], target.tf_pos[row][:, None], xyzw[:, None])


def _with_estimates(
    batch: RawMessages, channel_ids: np.ndarray, follows: dict[int, EstimateTarget]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The arguments of :meth:`McapFileWriter.add_raw_messages` for ``batch``: its messages on their
    output channels (dropped channels left out), each target's estimate right after its IMU message."""
    channel = batch.channel_id.astype(np.int64)
    n = len(channel)
    position = [np.arange(n, dtype=np.int64) * 2]  # sort keys: message i at 2 i, its estimate at 2 i + 1
    parts: list[tuple[np.ndarray, ...]] = [
        (channel_ids[channel], batch.sequence, batch.log_time, batch.publish_time, batch.start, batch.size)
    ]
    buffers = [batch.buffer]
    base = len(batch.buffer)

    def add(rows: np.ndarray, channel_out: int, first_sequence: int, k: np.ndarray) -> int:
        """Put encoded ``rows`` (m, size) on ``channel_out`` right after the input messages ``k`` (m,),
        with their log and publish times; returns m."""
        nonlocal base
        m: int
        size: int
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
        if not len(mine) or not len(target.stamp_ns):  # none here, or every estimate of it already written
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
