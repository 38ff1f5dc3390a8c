"""Recorded IMU logs: MCAP files (profile ``ros2``) written and read whole arrays at a time.

What a gyroemu file holds (``interface.md``)
--------------------------------------------
Schema encoding ``ros2msg``, message encoding ``cdr`` (the bytes of :mod:`gyroemu.pipelines.messages`),
zstd-compressed chunks, message indexes after each chunk, and a summary (schemas, channels,
statistics, chunk and metadata indexes, summary offsets). Channels, per device:

=================  ===================================  =========================================
topic              type                                 holds
=================  ===================================  =========================================
``/imu``           ``sensor_msgs/msg/Imu``              ``gyro``, ``accel``; ``orientation_covariance[0] = -1``
``/mag``           ``sensor_msgs/msg/MagneticField``    ``mag`` (tesla), only for devices with one
``/truth/imu``     ``sensor_msgs/msg/Imu``              true ``q_wb``, ``omega_b``, ``specific_force_b``
``/estimate/imu``  ``sensor_msgs/msg/Imu``              estimated ``q_wb`` (+ covariance), rate, ...
``/raw/<kind>``    ``gyroemu_msgs/msg/<Kind>Raw``       the gyro kind's physical observables
``/movement``      ``gyroemu_msgs/msg/Flag``            an imported dataset's mask of the samples that count
=================  ===================================  =========================================

With several devices the topics are prefixed: ``/<device>/imu``. Every message's ``log_time`` and
``publish_time`` are its header stamp (ns), ``sequence`` counts from 0 per channel, and messages are
in time order across channels (same stamp: the order of the table). Frame ids: the device name for
what the sensor measures (``/imu``, ``/mag``, ``/raw/...``), ``base_link`` for body-frame truth and
estimates. Each device has a metadata record ``gyroemu`` with ``version``, ``seed``, ``scenario``
(TOML), ``device`` (TOML), ``device_name`` and ``topic_prefix``, plus any keys the recording adds
(an imported file: ``source``, ``source_format``, ``citation``, ...; :mod:`gyroemu.pipelines.importers`).

Writing
-------
:class:`McapLogWriter` (and :func:`write_mcap`) encode every channel of a block of samples as one
``(N, size)`` array (:meth:`MessageType.encode`), build the MCAP Message records of the block with
numpy (one structured row per message), interleave the channels in time order (when the channels share
their stamps, as gyroemu's do, by concatenating rows: no sort), cut the result into chunks of
``chunk_size`` uncompressed bytes and compress each with zstd. The small records (header, schemas,
channels, metadata, indexes, statistics, summary offsets, footer) are ``mcap.records`` objects
serialised by the ``mcap`` library; Chunk and Message Index records are packed here because they carry
the bulk. ``mcap.writer.Writer`` is not used for the messages: it costs about 3 us per message in
Python (about 300 k/s for empty payloads on the development machine), which alone exceeds the budget
of 200 k IMU messages/s with four channels per sample. The file is written to a temporary name in the
target folder and renamed when complete, so an interrupted write leaves no partial file under the name.

Reading
-------
:func:`read_mcap` reads any ``ros2`` MCAP file: it walks the records, decompresses each chunk, finds its
Message records in one pass, and gathers each channel's payloads into ``(N, size)`` arrays that
:meth:`MessageType.decode` views as structured arrays. Every channel of type ``sensor_msgs/msg/Imu``
counts, whatever its topic; channels of unknown types are skipped with a :class:`LogWarning`. A file
cut short (a recorder killed mid-write, no footer) yields the messages of its complete chunks, with a
warning that says so and how many were recovered. Files that are not MCAP, are corrupt, or hold no IMU
messages raise :class:`LogError`, which names the file. The input is opened read-only.
:func:`iter_mcap_batches` walks the same records but hands out every message (topic, schema name,
log time, payload bytes) in log-time order, a batch per chunk, for ``gyroemu replay``.

Sources: MCAP format specification (https://mcap.dev/spec) and its appendix (well-known encodings,
``ros2`` profile); ``rosbag2_storage_mcap`` (channel metadata ``offered_qos_profiles``).
"""

from __future__ import annotations

import bisect
import functools
import operator
import os
import re
import secrets
import struct
import warnings
import zlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import NamedTuple

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from gyroemu.dynamics import ConfigError
from gyroemu.sensors.samples import ImuSamples

from .messages import (
    FLAG,
    IMU,
    MAGNETIC_FIELD,
    RAW_MESSAGE_TYPES,
    DecodedBatch,
    MessageType,
    message_type,
    ns_to_stamps,
    raw_fields,
    raw_observables,
    stamps_to_ns,
)

__all__ = [
    "LogError",
    "McapMessage",
    "iter_mcap_batches",
    "ChannelInfo",
    "mcap_channel_info",
    "LogWarning",
    "ImuSeries",
    "Recording",
    "DeviceLog",
    "McapLog",
    "McapLogWriter",
    "McapFileWriter",
    "write_mcap",
    "read_mcap",
    "truth_series",
    "BODY_FRAME",
    "OFFERED_QOS_PROFILES",
]

MAGIC = b"\x89MCAP0\r\n"
BODY_FRAME = "base_link"
"""``frame_id`` of body-frame channels (``/truth/imu``, ``/estimate/imu``), REP-105's name for the body."""

OFFERED_QOS_PROFILES = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n"
    "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  liveliness: 1\n"
    "  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  avoid_ros_namespace_conventions: false\n"
)
"""Channel metadata the ``ros2`` profile requires: a reliable, volatile publisher, as rosbag2 (Humble)
records it, so ``ros2 bag play`` replays gyroemu files with matching QoS."""

_RESERVED_NAMES = frozenset({"truth", "estimate", "raw", "imu", "mag"})
_DEVICE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class LogError(ConfigError):
    """A log file gyroemu cannot read: not MCAP, corrupt, or without IMU messages.

    A :class:`gyroemu.dynamics.ConfigError` (so a ``ValueError``): ``file`` names the file, ``reason`` says what
    is wrong, and the command line reports it with exit status 2.
    """


class LogWarning(UserWarning):
    """Something in a log that was skipped or recovered: an unknown channel, a truncated file."""


@functools.cache
def _version() -> str:
    try:
        from importlib.metadata import version

        return version("gyroemu")
    except Exception:  # not installed (running from a checkout)
        return "0+unknown"


# ==================================================================================================
# What goes in and comes out besides ImuSamples.


@dataclass(frozen=True, eq=False)
class ImuSeries:
    """The contents of a body-frame ``sensor_msgs/msg/Imu`` channel (truth or estimate), SI units.

    Attributes
    ----------
    t : ndarray (N,)
        Stamps, s.
    q_wb : ndarray (N, 4) or None
        Attitude, unit quaternion (w, x, y, z) turning body vectors into the world frame.
    omega_b : ndarray (N, 3) or None
        Angular velocity, body axes, rad/s.
    specific_force_b : ndarray (N, 3) or None
        Specific force, body axes, m/s².
    q_wb_covariance, omega_b_covariance, specific_force_b_covariance : ndarray (N, 3, 3) or None
        Covariances (orientation: rad², about the x, y, z axes). None writes zeros ("unknown").

    A quantity that is None is written as ``covariance[0] = -1`` ("no estimate"); reading gives None
    when every message says so, and NaN rows where only some do.
    """

    t: np.ndarray
    q_wb: np.ndarray | None = None
    omega_b: np.ndarray | None = None
    specific_force_b: np.ndarray | None = None
    q_wb_covariance: np.ndarray | None = None
    omega_b_covariance: np.ndarray | None = None
    specific_force_b_covariance: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.t)
        for name, width in (
            ("q_wb", (4,)),
            ("omega_b", (3,)),
            ("specific_force_b", (3,)),
            ("q_wb_covariance", (3, 3)),
            ("omega_b_covariance", (3, 3)),
            ("specific_force_b_covariance", (3, 3)),
        ):
            value = getattr(self, name)
            if value is not None and np.shape(value) != (n, *width):
                raise ValueError(f"{name} must have shape {(n, *width)}, got {np.shape(value)}")

    def __len__(self) -> int:
        return len(self.t)


def truth_series(trajectory, samples: ImuSamples) -> ImuSeries:
    """Body truth at the instants the device sampled (``samples.t_true``), stamped with the device's
    stamps ``samples.t``: what ``/truth/imu`` holds."""
    from gyroemu.sensors.sampling import SensorTruth

    instants = samples.t_true if samples.t_true is not None else samples.t
    q_wb, omega_b, force_b = SensorTruth(trajectory).body_truth(instants)
    return ImuSeries(t=np.asarray(samples.t, dtype=float), q_wb=q_wb, omega_b=omega_b, specific_force_b=force_b)


@dataclass(frozen=True, eq=False)
class Recording:
    """One device's block of output for :class:`McapLogWriter`.

    Attributes
    ----------
    samples : ImuSamples
        The device's samples; ``samples.device`` names it.
    truth, estimate : ImuSeries, optional
        Written to ``/truth/imu`` and ``/estimate/imu``.
    device : Device or str, optional
        The device (or its resolved config as TOML text), for the metadata record.
    seed : int, optional
        The run's seed (default: ``device.seed`` when ``device`` is a Device).
    movement : ndarray (N,) bool, optional
        A mask aligned to ``samples`` (an imported dataset's samples over which errors are computed),
        written to ``/movement`` as ``gyroemu_msgs/msg/Flag`` at the samples' stamps.
    stamp_ns : ndarray (N,) int64, optional
        The samples' stamps exactly, ns, used instead of ``samples.t`` (which, as float seconds, does
        not resolve nanoseconds at Unix-epoch times); a truth or estimate series of the same length
        and times is stamped with them too. For rewriting a log read by :func:`read_mcap`.
    metadata : dict of str to str, optional
        Further keys of the device's ``gyroemu`` metadata record (e.g. an import's ``source``); they
        may not replace the writer's own keys (``version``, ``seed``, ``scenario``, ``device``,
        ``device_name``, ``topic_prefix``).
    """

    samples: ImuSamples
    truth: ImuSeries | None = None
    estimate: ImuSeries | None = None
    device: object = None
    seed: int | None = None
    movement: np.ndarray | None = None
    metadata: dict | None = None
    stamp_ns: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class DeviceLog:
    """One device's channels in a log.

    Attributes
    ----------
    name : str
        ``imu0``-style device name: the topic prefix without slashes, the gyroemu metadata's
        ``device_name`` for an unprefixed file, or a foreign IMU topic without its leading slash.
    topics : dict of str to str
        Role (``imu``, ``mag``, ``truth``, ``estimate``, ``raw/<kind>``) to topic.
    samples : ImuSamples
    stamp_ns : ndarray (N,) int64
        The samples' header stamps exactly, ns (``samples.t`` is their float64 value in seconds, which
        resolves 0.24 us at Unix-epoch times).
    truth, estimate : ImuSeries or None
    metadata : dict of str to str or None
        The device's ``gyroemu`` metadata record, when there is one.
    movement : ndarray (N,) bool or None
        The ``/movement`` flags at the samples' stamps (False, with a warning, for samples without a
        flag at their stamp); None when the device has no ``/movement`` topic.
    """

    name: str
    topics: dict
    samples: ImuSamples
    stamp_ns: np.ndarray
    truth: ImuSeries | None = None
    estimate: ImuSeries | None = None
    metadata: dict | None = None
    movement: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class McapLog:
    """What :func:`read_mcap` found.

    Attributes
    ----------
    path : Path
    devices : dict of str to DeviceLog
        Keyed by device name, in the order of their IMU channels.
    metadata : list of dict
        Every ``gyroemu`` metadata record.
    profile : str
        The MCAP header's profile.
    message_count : int
        Messages read (every channel, decoded or not).
    truncated : bool
        The file ends before its footer: only complete chunks were read.
    skipped : dict of str to str
        Topics not decoded, with the reason.
    channels : tuple of ChannelInfo
        Every channel of the file (decoded or not) with its schema, in file order.
    """

    path: Path
    devices: dict
    metadata: list
    profile: str
    message_count: int
    truncated: bool = False
    skipped: dict = field(default_factory=dict)
    channels: tuple = ()

    @property
    def device(self) -> DeviceLog:
        """The only device (``ValueError`` when the log has several: pick one from :attr:`devices`)."""
        if len(self.devices) != 1:
            raise ValueError(
                f"{self.path}: {len(self.devices)} devices ({', '.join(self.devices)}); choose one from .devices"
            )
        return next(iter(self.devices.values()))

    @property
    def samples(self) -> ImuSamples:
        """The only device's samples."""
        return self.device.samples

    @property
    def truth(self) -> ImuSeries | None:
        """The only device's truth."""
        return self.device.truth


# ==================================================================================================
# Low level: MCAP records, Message records in bulk.

_MESSAGE_HEAD = 1 + 8 + 2 + 4 + 8 + 8
"""Bytes of a Message record before its data: opcode, record length, channel id, sequence, log and
publish time."""

_MESSAGE_FIELDS = np.dtype(
    {
        "names": ["channel_id", "sequence", "log_time", "publish_time"],
        "formats": ["<u2", "<u4", "<u8", "<u8"],
        "offsets": [0, 2, 6, 14],
        "itemsize": 22,
    }
)


def _message_records(channel_id: int, sequence: np.ndarray, log_time: np.ndarray, data: np.ndarray) -> np.ndarray:
    """MCAP Message records of N payloads of equal size, one per row: (N, 31 + size) uint8.

    Record layout (MCAP spec, "Message", opcode 0x05): opcode u8, record length u64 (= 22 + size),
    channel_id u16, sequence u32, log_time u64, publish_time u64, then the payload; all little endian.
    """
    n, size = data.shape
    out = np.empty((n, _MESSAGE_HEAD + size), dtype=np.uint8)
    out[:, _MESSAGE_HEAD:] = data
    out[:, :11] = np.frombuffer(struct.pack("<BQH", Opcode.MESSAGE, _MESSAGE_HEAD - 9 + size, channel_id), np.uint8)
    head = out.view(
        np.dtype(
            {
                "names": ["sequence", "log_time", "publish_time"],
                "formats": ["<u4", "<u8", "<u8"],
                "offsets": [11, 15, 23],
                "itemsize": _MESSAGE_HEAD + size,
            }
        )
    )[:, 0]
    head["sequence"] = sequence
    head["log_time"] = log_time
    head["publish_time"] = log_time
    return out


@dataclass
class _Stream:
    """Encoded messages of one channel in a block."""

    channel_id: int
    log_time: np.ndarray  # (N,) uint64
    records: np.ndarray  # (N, record size) uint8


def _no_messages():
    """``(data, channel_id, log_time, offset)`` of no message (see :func:`_interleave`)."""
    return np.empty(0, np.uint8), np.empty(0, np.uint16), np.empty(0, np.uint64), np.empty(0, np.int64)


def _interleave(streams: Sequence[_Stream]):
    """Records of several channels in time order (ties: the order of ``streams``).

    Returns ``(data, channel_id, log_time, offset)``: the concatenated records (uint8) and, per message,
    its channel, log time and offset in ``data``.
    """
    streams = [s for s in streams if len(s.log_time)]
    if not streams:
        return _no_messages()
    sizes = np.array([s.records.shape[1] for s in streams], dtype=np.int64)
    first = streams[0].log_time
    if all(len(s.log_time) == len(first) and np.array_equal(s.log_time, first) for s in streams[1:]):
        # Same stamps on every channel: row k of every stream, in stream order, is sample k's group.
        n, k = len(first), len(streams)
        data = np.concatenate([s.records for s in streams], axis=1) if k > 1 else streams[0].records
        data = data.reshape(-1)
        channel = np.tile(np.array([s.channel_id for s in streams], dtype=np.uint16), n)
        log_time = np.repeat(first, k)
        offset = np.concatenate([[0], np.cumsum(np.tile(sizes, n))[:-1]]).astype(np.int64)
        return data, channel, log_time, offset
    # General case: a stable sort of every message by time, then a byte gather in pieces.
    log_time = np.concatenate([s.log_time for s in streams])
    which = np.repeat(np.arange(len(streams)), [len(s.log_time) for s in streams])
    row = np.concatenate([np.arange(len(s.log_time)) for s in streams])
    order = np.argsort(log_time, kind="stable")
    log_time, which, row = log_time[order], which[order], row[order]
    size = sizes[which]
    offset = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)
    source = np.concatenate([s.records.reshape(-1) for s in streams])
    base = np.concatenate([[0], np.cumsum([s.records.size for s in streams])[:-1]]).astype(np.int64)
    start = base[which] + row * size
    data = np.empty(int(size.sum()), dtype=np.uint8)
    piece = 1 << 16  # messages per gather: bounds the index array
    for a in range(0, len(order), piece):
        b = min(a + piece, len(order))
        lo, hi = offset[a], offset[b - 1] + size[b - 1]
        index = np.repeat(start[a:b] - offset[a:b], size[a:b]) + np.arange(lo, hi)
        data[lo:hi] = source[index]
    channel = np.array([s.channel_id for s in streams], dtype=np.uint16)[which]
    return data, channel, log_time, offset


class McapFileWriter:
    """An MCAP writer that takes messages in bulk: chunked, zstd, message and chunk indexes, summary.

    Parameters
    ----------
    stream : binary file
        Written sequentially (never seeked).
    profile : str
        The Header record's profile.
    chunk_size : int
        Uncompressed bytes of records after which a chunk is closed.
    compression_level : int
        zstd level.
    """

    def __init__(
        self,
        stream,
        *,
        profile: str = "ros2",
        library: str | None = None,
        chunk_size: int = 1 << 20,
        compression_level: int = 3,
    ):
        self._out = stream
        self._position = 0
        self._chunk_size = int(chunk_size)
        self._compressor = zstandard.ZstdCompressor(level=compression_level)
        self._schemas: dict[int, Schema] = {}
        self._schema_ids: dict[tuple, int] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_count = 0
        self._channel_counts: dict[int, int] = {}
        self._time_range: list[int] | None = None
        self._metadata_count = 0
        self._pending = _no_messages()
        self._finished = False
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=library or f"gyroemu/{_version()}"))

    # ---------------------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        self._out.write(data)
        self._position += len(data)

    def _write_record(self, record) -> int:
        """Write one ``mcap.records`` record; returns its offset."""
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        offset = self._position
        self._write(data)
        return offset

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Schema id of ``name`` (written once)."""
        key = (name, encoding, bytes(data))
        if key not in self._schema_ids:
            schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=bytes(data))
            self._schemas[schema.id] = schema
            self._schema_ids[key] = schema.id
            self._write_record(schema)
        return self._schema_ids[key]

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict | None = None) -> int:
        """A new channel's id (written before any of its messages)."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels[channel.id] = channel
        self._channel_counts[channel.id] = 0
        self._write_record(channel)
        return channel.id

    def register_ros2_channel(self, topic: str, mtype: MessageType | None, metadata: dict | None = None) -> int:
        """A new ``cdr`` channel of type ``mtype`` (its ``ros2msg`` schema, registered once; None: no
        schema) with the ``offered_qos_profiles`` of the ``ros2`` profile, then ``metadata``."""
        schema_id = 0 if mtype is None else self.register_schema(mtype.name, "ros2msg", mtype.schema.encode())
        return self.register_channel(
            topic, "cdr", schema_id, {"offered_qos_profiles": OFFERED_QOS_PROFILES, **(metadata or {})}
        )

    def add_metadata(self, name: str, data: dict) -> None:
        """A Metadata record (and its index in the summary)."""
        offset = self._write_record(Metadata(name=name, metadata={str(k): str(v) for k, v in data.items()}))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._position - offset, name=name))
        self._metadata_count += 1

    def add_messages(self, batches: Iterable[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Append messages of several channels, interleaved in time order.

        Parameters
        ----------
        batches : iterable of (channel_id, log_time_ns, payloads)
            Per channel: ``log_time_ns`` (N,) non-negative integers, also written as publish time, and
            ``payloads`` (N, size) uint8, one serialised message per row (e.g. from
            :meth:`MessageType.encode`, or received bytes stacked with ``np.frombuffer``). Messages with
            equal times keep the order of ``batches``; sequence numbers continue per channel from 0.
        """
        if self._finished:
            raise ValueError("the MCAP file is finished")
        checked = []
        for channel_id, log_time, payloads in batches:  # check everything before changing any state
            if channel_id not in self._channels:
                raise ValueError(f"channel {channel_id} is not registered")
            log_time = np.asarray(log_time, dtype=np.int64).reshape(-1)
            payloads = np.asarray(payloads, dtype=np.uint8)
            if payloads.ndim != 2 or len(payloads) != len(log_time):
                raise ValueError(
                    f"channel {channel_id}: payloads must be an (N, size) array for {len(log_time)} "
                    f"log times, got shape {payloads.shape}"
                )
            if len(log_time) and log_time.min() < 0:
                raise ValueError(f"channel {channel_id}: negative log times")
            checked.append((channel_id, log_time, payloads))
        streams = []
        for channel_id, log_time, payloads in checked:
            first = self._channel_counts[channel_id]
            sequence = (np.arange(first, first + len(log_time), dtype=np.int64) % (1 << 32)).astype(np.uint32)
            self._channel_counts[channel_id] += len(log_time)
            log_time = log_time.astype(np.uint64)
            streams.append(_Stream(channel_id, log_time, _message_records(channel_id, sequence, log_time, payloads)))
        data, channel, log_time, offset = _interleave(streams)
        if not len(log_time):
            return
        self._message_count += len(log_time)
        lo, hi = int(log_time.min()), int(log_time.max())
        self._time_range = (
            [lo, hi] if self._time_range is None else [min(self._time_range[0], lo), max(self._time_range[1], hi)]
        )
        p_data, p_channel, p_time, p_offset = self._pending
        if len(p_data):
            data = np.concatenate([p_data, data])
            offset = np.concatenate([p_offset, offset + len(p_data)])
            channel = np.concatenate([p_channel, channel])
            log_time = np.concatenate([p_time, log_time])
        # Chunk k holds the messages that start in [k, k + 1) * chunk_size: at most one message over.
        chunk = offset // self._chunk_size
        cuts = np.flatnonzero(np.diff(chunk)) + 1
        bounds = np.concatenate([[0], cuts, [len(offset)]])
        for a, b in zip(bounds[:-2], bounds[1:-1]):
            end = offset[b] if b < len(offset) else len(data)
            self._write_chunk(data[offset[a] : end], channel[a:b], log_time[a:b], offset[a:b] - offset[a])
        a = bounds[-2]
        self._pending = (data[offset[a] :].copy(), channel[a:], log_time[a:], offset[a:] - offset[a])

    def _write_chunk(self, records: np.ndarray, channel: np.ndarray, log_time: np.ndarray, offset: np.ndarray) -> None:
        """One Chunk record (opcode 0x06) and its Message Index records (0x07)."""
        if not len(channel):
            return
        raw = memoryview(np.ascontiguousarray(records))  # type: ignore[arg-type]  # numpy stubs: __buffer__ 3.12+ only
        compressed = self._compressor.compress(raw)
        compression = b"zstd"
        start_time, end_time = int(log_time.min()), int(log_time.max())
        # Chunk: message_start_time u64, message_end_time u64, uncompressed_size u64,
        # uncompressed_crc u32, compression string (u32 length + bytes), records (u64 length + bytes).
        body = 8 + 8 + 8 + 4 + 4 + len(compression) + 8 + len(compressed)
        head = (
            struct.pack(
                "<BQQQQII", Opcode.CHUNK, body, start_time, end_time, len(raw), zlib.crc32(raw), len(compression)
            )
            + compression
            + struct.pack("<Q", len(compressed))
        )
        chunk_start = self._position
        self._write(head)
        self._write(compressed)
        chunk_length = self._position - chunk_start
        # Message Index per channel: channel_id u16, records (u32 byte length + (log_time u64, offset u64)...).
        index_start = self._position
        index_offsets = {}
        channels, first = np.unique(channel, return_index=True)
        for c in channels[np.argsort(first)]:
            mask = channel == c
            entries = np.empty((int(mask.sum()), 2), dtype="<u8")
            entries[:, 0] = log_time[mask]
            entries[:, 1] = offset[mask]
            index_offsets[int(c)] = self._position
            self._write(struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + entries.nbytes, int(c), entries.nbytes))
            self._write(entries.tobytes())
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start_time,
                message_end_time=end_time,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=index_offsets,
                message_index_length=self._position - index_start,
                compression=compression.decode(),
                compressed_size=len(compressed),
                uncompressed_size=len(raw),
            )
        )

    def finish(self) -> None:
        """Close the last chunk; write Data End, the summary section, its offsets, Footer and magic."""
        if self._finished:
            return
        data, channel, log_time, offset = self._pending
        self._write_chunk(data, channel, log_time, offset)
        self._pending = _no_messages()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._position
        builder = RecordBuilder()
        groups = []

        def group(opcode, records):
            start = builder.count
            for record in records:
                record.write(builder)
            groups.append(
                SummaryOffset(
                    group_opcode=opcode, group_start=summary_start + start, group_length=builder.count - start
                )
            )

        start, end = self._time_range or (0, 0)
        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(
            Opcode.STATISTICS,
            [
                Statistics(
                    message_count=self._message_count,
                    schema_count=len(self._schemas),
                    channel_count=len(self._channels),
                    attachment_count=0,
                    metadata_count=self._metadata_count,
                    chunk_count=len(self._chunk_indexes),
                    message_start_time=start,
                    message_end_time=end,
                    channel_message_counts=dict(self._channel_counts),
                )
            ],
        )
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + builder.count
        for offset_record in groups:
            offset_record.write(builder)
        summary = builder.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start), crc)
        self._write(summary)
        self._write_record(
            Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc)
        )
        self._write(MAGIC)
        self._finished = True


# ==================================================================================================
# gyroemu logs.


@dataclass
class _DeviceChannels:
    name: str
    prefix: str
    channels: dict  # role -> channel id
    frame_id: str
    warned: set = field(default_factory=set)


def _device_metadata(
    device_name: str, topic_prefix: str, *, seed: str = "", scenario: str = "", device: str = ""
) -> dict:
    """A device's ``gyroemu`` metadata record: the writer's own keys (empty: not known)."""
    return {
        "version": _version(),
        "seed": seed,
        "scenario": scenario,
        "device": device,
        "device_name": device_name,
        "topic_prefix": topic_prefix,
    }


def _toml(value) -> str:
    if value is None:
        return ""
    return value if isinstance(value, str) else value.to_toml()


class McapLogWriter:
    """Writes a gyroemu log: devices' samples, truth and estimates as ``ros2`` MCAP channels.

    Parameters
    ----------
    path : str or Path
        The file to write; it appears (atomically) when :meth:`close` succeeds.
    scenario : Scenario or str, optional
        The scenario (or its TOML text) for the metadata records.
    prefix_topics : bool, optional
        Prefix topics with the device name (``/<device>/imu``). Default: when the first :meth:`write`
        holds more than one device.
    chunk_size : int
        Uncompressed bytes per chunk (default 1 MiB, as the ``mcap`` library).
    compression_level : int
        zstd level (default 3, zstd's default).

    Use as a context manager: on an exception inside the block the temporary file is removed and
    nothing appears at ``path``::

        with McapLogWriter("run.mcap", scenario=scenario) as log:
            log.write(Recording(samples, truth=truth_series(trajectory, samples), device=device))
    """

    def __init__(
        self,
        path,
        *,
        scenario=None,
        prefix_topics: bool | None = None,
        chunk_size: int = 1 << 20,
        compression_level: int = 3,
    ):
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise FileNotFoundError(f"{self.path.parent} is not a folder")
        self._tmp = self.path.with_name(f".{self.path.name}.{secrets.token_hex(4)}.tmp")
        fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # mode 0o666 minus umask
        self._file = os.fdopen(fd, "wb", buffering=1 << 20)
        try:
            self._mcap = McapFileWriter(self._file, chunk_size=chunk_size, compression_level=compression_level)
        except BaseException:
            self._file.close()
            self._tmp.unlink(missing_ok=True)
            raise
        self._scenario = _toml(scenario)
        self._prefix = prefix_topics
        self._devices: dict[str, _DeviceChannels] = {}
        self._last_time = -1
        self._closed = False

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # ---------------------------------------------------------------------------------------------

    def _channel(self, device: _DeviceChannels, role: str, mtype: MessageType) -> int:
        if role not in device.channels:
            device.channels[role] = self._mcap.register_ros2_channel(f"{device.prefix}/{role}", mtype)
        return device.channels[role]

    def _device(self, recording: Recording, several: bool) -> _DeviceChannels:
        name = recording.samples.device
        if name in self._devices:
            return self._devices[name]
        if self._prefix is None:
            self._prefix = several
        if self._devices and not self._prefix:
            raise ValueError(
                f"a second device ({name!r}) in a log without topic prefixes: "
                "pass prefix_topics=True to write several devices"
            )
        if self._prefix and (not _DEVICE_NAME.match(name) or name in _RESERVED_NAMES):
            raise ValueError(
                f"device name {name!r} cannot prefix topics: use letters, digits and '_', "
                f"starting with a letter, and none of {', '.join(sorted(_RESERVED_NAMES))}"
            )
        entry = _DeviceChannels(name=name, prefix=f"/{name}" if self._prefix else "", channels={}, frame_id=name)
        self._devices[name] = entry
        device = recording.device
        seed = recording.seed if recording.seed is not None else getattr(device, "seed", None)
        record = _device_metadata(
            name,
            entry.prefix,
            seed="" if seed is None else str(int(seed)),
            scenario=self._scenario,
            device=_toml(device),
        )
        extra = dict(recording.metadata or {})
        clash = sorted(set(extra) & set(record))
        if clash:
            raise ValueError(f"Recording.metadata may not set the writer's own key(s) {', '.join(clash)}")
        self._mcap.add_metadata("gyroemu", {**record, **extra})
        return entry

    def write(self, *recordings: Recording | ImuSamples) -> None:
        """Append a block: one :class:`Recording` (or bare :class:`ImuSamples`) per device.

        All channels of all devices in one call are interleaved in time order; successive calls must
        follow each other in time (``ValueError`` otherwise).
        """
        if self._closed:
            raise ValueError(f"{self.path}: the log is closed")
        block = [r if isinstance(r, Recording) else Recording(samples=r) for r in recordings]
        names = [r.samples.device for r in block]
        if len(set(names)) != len(names):
            raise ValueError(f"one block holds device {max(names, key=names.count)!r} twice")
        batches = []
        for recording in block:
            device = self._device(recording, several=len(block) > 1)
            batches += self._encode(device, recording)
        times = [stamps for _, stamps, _ in batches if len(stamps)]
        if times:
            first = min(int(stamps.min()) for stamps in times)
            if first < self._last_time:
                raise ValueError(
                    f"this block starts at {first * 1e-9:.9f} s, before the end of the previous "
                    f"block ({self._last_time * 1e-9:.9f} s): write blocks in time order"
                )
            self._mcap.add_messages(batches)
            self._last_time = max(self._last_time, max(int(stamps.max()) for stamps in times))

    def _encode(self, device: _DeviceChannels, recording: Recording) -> list[tuple]:
        """``(channel_id, stamp_ns, payloads)`` of every channel of a recording."""
        samples = recording.samples
        stamp_ns = _log_stamps(samples.t, "samples.t")
        if recording.stamp_ns is not None:
            exact = np.asarray(recording.stamp_ns, dtype=np.int64)
            if exact.shape != stamp_ns.shape or np.abs(exact - stamp_ns).max(initial=0) > 1000:
                raise ValueError("stamp_ns must be the samples' stamps (samples.t) in ns")
            stamp_ns = exact
        n = len(stamp_ns)
        batches = []
        rows = IMU.encode(stamp_ns, device.frame_id, _measured_fields(samples))
        batches.append((self._channel(device, "imu", IMU), stamp_ns, rows))
        if samples.has_mag or "mag" in device.channels:
            rows = MAGNETIC_FIELD.encode(stamp_ns, device.frame_id, {"magnetic_field": samples.mag})
            batches.append((self._channel(device, "mag", MAGNETIC_FIELD), stamp_ns, rows))
        for role, series in (("truth/imu", recording.truth), ("estimate/imu", recording.estimate)):
            if series is not None:
                series_ns = _log_stamps(series.t, f"{role.split('/')[0]}.t")
                if (
                    recording.stamp_ns is not None
                    and len(series_ns) == n
                    and np.abs(series_ns - stamp_ns).max(initial=0) <= 1000
                ):
                    series_ns = stamp_ns
                rows = IMU.encode(series_ns, BODY_FRAME, _series_fields(series))
                batches.append((self._channel(device, role, IMU), series_ns, rows))
        for kind, observables in samples.raw.items():
            if kind not in RAW_MESSAGE_TYPES:
                if kind not in device.warned:
                    device.warned.add(kind)
                    warnings.warn(
                        f"{self.path}: no message type for the raw observables of gyro kind {kind!r}; not recorded",
                        LogWarning,
                        stacklevel=3,
                    )
                continue
            mtype, fields, ignored = raw_fields(kind, observables)
            if ignored and kind + "/ignored" not in device.warned:
                device.warned.add(kind + "/ignored")
                warnings.warn(
                    f"{self.path}: {mtype.name} has no field for {', '.join(ignored)}; not recorded",
                    LogWarning,
                    stacklevel=3,
                )
            for name, value in fields.items():
                if len(value) != n:
                    raise ValueError(f"raw[{kind!r}][{name!r}] has {len(value)} rows for {n} samples")
            rows = mtype.encode(stamp_ns, device.frame_id, fields)
            batches.append((self._channel(device, f"raw/{kind}", mtype), stamp_ns, rows))
        if recording.movement is not None:
            movement = np.asarray(recording.movement)
            if movement.shape != (n,) or not (movement.dtype == bool or np.isin(movement, (0, 1)).all()):
                raise ValueError(
                    f"movement must be {n} booleans (one per sample), got {movement.dtype} {movement.shape}"
                )
            rows = FLAG.encode(stamp_ns, device.frame_id, {"data": movement.astype(bool)})
            batches.append((self._channel(device, "movement", FLAG), stamp_ns, rows))
        return batches

    def close(self) -> None:
        """Finish the file (summary, footer), flush it to disk and move it to :attr:`path`."""
        if self._closed:
            return
        try:
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            os.replace(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise
        self._closed = True

    def abort(self) -> None:
        """Drop the temporary file; nothing appears at :attr:`path`."""
        self._closed = True
        try:
            self._file.close()
        finally:
            self._tmp.unlink(missing_ok=True)


def _log_stamps(t: np.ndarray, what: str) -> np.ndarray:
    stamp_ns = stamps_to_ns(t)
    if len(stamp_ns) and stamp_ns.min() < 0:
        raise ValueError(f"{what} has stamps before 0 s ({stamp_ns.min() * 1e-9:g} s): MCAP log times are unsigned")
    return stamp_ns


_IMU_QUANTITIES = (
    ("q_wb", "q_wb_covariance", "orientation", "orientation_covariance"),
    ("omega_b", "omega_b_covariance", "angular_velocity", "angular_velocity_covariance"),
    ("specific_force_b", "specific_force_b_covariance", "linear_acceleration", "linear_acceleration_covariance"),
)
"""(ImuSeries attribute, its covariance, Imu field, its covariance) for each quantity of an Imu message."""

_NO_ESTIMATE = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
_NO_ESTIMATE.flags.writeable = False
"""An Imu covariance with element 0 at -1: "no estimate" of its quantity (sensor_msgs/msg/Imu)."""


def _measured_fields(samples: ImuSamples) -> dict:
    """Imu message fields of a device's samples (``/imu``): rate and specific force, no orientation."""
    return {
        "orientation": (0.0, 0.0, 0.0, 1.0),
        "orientation_covariance": _NO_ESTIMATE,
        "angular_velocity": samples.gyro,
        "linear_acceleration": samples.accel,
    }


def _series_fields(series: ImuSeries) -> dict:
    """Imu message fields of an :class:`ImuSeries` (scalar-first quaternions to x, y, z, w)."""
    n = len(series)
    fields: dict[str, np.ndarray | tuple[float, ...]] = {}
    for value_name, cov_name, field_name, cov_field in _IMU_QUANTITIES:
        value, cov = getattr(series, value_name), getattr(series, cov_name)
        if value is None:
            fields[cov_field] = _NO_ESTIMATE
            if field_name == "orientation":
                fields[field_name] = (0.0, 0.0, 0.0, 1.0)
            continue
        value = np.asarray(value, dtype=float)
        fields[field_name] = value[:, [1, 2, 3, 0]] if field_name == "orientation" else value
        if cov is not None:
            fields[cov_field] = np.asarray(cov, dtype=float).reshape(n, 9)
    return fields


def write_mcap(
    path,
    recordings,
    *,
    scenario=None,
    prefix_topics: bool | None = None,
    chunk_size: int = 1 << 20,
    compression_level: int = 3,
) -> Path:
    """Write a whole log at once: ``recordings`` is an :class:`ImuSamples`, a :class:`Recording`, or a
    list of them (one per device). Returns the path written. See :class:`McapLogWriter`."""
    if isinstance(recordings, (ImuSamples, Recording)):
        recordings = [recordings]
    with McapLogWriter(
        path, scenario=scenario, prefix_topics=prefix_topics, chunk_size=chunk_size, compression_level=compression_level
    ) as log:
        log.write(*recordings)
    return log.path


# ==================================================================================================
# Reading.

_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length


@dataclass
class _ChannelData:
    """Messages of one channel gathered while scanning: blocks of equal-length payloads."""

    channel: Channel
    mtype: MessageType | None = None  # None: not decoded
    order: list = field(default_factory=list)  # global message ordinal per block
    header: list = field(default_factory=list)  # _MESSAGE_FIELDS arrays
    payload: list = field(default_factory=list)  # (m, L) uint8
    loose: list = field(default_factory=list)  # messages outside chunks: (ordinal, (1,) fields, bytes)


class _Scan:
    """A pass over an MCAP file: schemas, channels, metadata and the messages of wanted channels."""

    def __init__(self, path: Path):
        self.path = path
        self.profile = ""
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: list[Metadata] = []
        self.data: dict[int, _ChannelData] = {}
        self.skipped: dict[str, str] = {}
        self.message_count = 0
        self.chunks = 0
        self.truncated_at: int | None = None
        self.footer = False

    def error(self, reason: str) -> LogError:
        return LogError(reason, file=self.path)

    def run(self) -> _Scan:
        for _ in self.walk():
            pass
        return self

    def walk(self):
        """Read the file record by record (chunks decompressed and handled whole), yielding after each."""
        try:
            f = open(self.path, "rb")
        except IsADirectoryError:
            raise self.error("is a folder, not an MCAP file") from None
        except OSError as e:
            raise self.error(f"cannot open: {e.strerror or e}") from None
        with f:
            size = os.fstat(f.fileno()).st_size
            if f.read(8) != MAGIC:
                raise self.error("not an MCAP file (it does not start with the MCAP magic bytes)")
            position = 8
            while True:
                if position == size:
                    self.truncated_at = position
                    break
                head = f.read(9)
                if len(head) < 9:
                    self.truncated_at = position
                    break
                opcode, length = _RECORD_HEAD.unpack(head)
                if length > size - position - 9:
                    self.truncated_at = position
                    break
                content = f.read(length)
                try:
                    self._record(opcode, content, position)
                except LogError:
                    raise
                except (ValueError, struct.error, UnicodeDecodeError, IndexError, KeyError) as e:
                    raise self.error(f"corrupt {_opcode_name(opcode)} record at byte {position}: {e}") from None
                position += 9 + length
                if opcode == Opcode.FOOTER:
                    if f.read(8) != MAGIC:
                        self.truncated_at = position
                    else:
                        self.footer = True
                    break
                yield opcode

    def _record(self, opcode: int, content: bytes, position: int) -> None:
        if opcode == Opcode.HEADER:
            self.profile = Header.read(ReadDataStream(BytesIO(content))).profile
        elif opcode == Opcode.SCHEMA:
            schema = Schema.read(ReadDataStream(BytesIO(content)))
            self.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            self._channel(Channel.read(ReadDataStream(BytesIO(content))))
        elif opcode == Opcode.CHUNK:
            self._chunk(content, position)
        elif opcode == Opcode.MESSAGE:
            self._loose_message(content)
        elif opcode == Opcode.METADATA:
            self.metadata.append(Metadata.read(ReadDataStream(BytesIO(content))))

    def _channel(self, channel: Channel) -> None:
        """Register a channel (once: the summary repeats them) and decide whether to decode it."""
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        schema = self.schemas.get(channel.schema_id)
        mtype = message_type(schema.name) if schema is not None else None
        if schema is None:
            reason = "no schema"
        elif channel.message_encoding != "cdr":
            reason = f"message encoding {channel.message_encoding!r}, not cdr"
        elif mtype is None:
            reason = f"type {schema.name} is not one gyroemu decodes"
        else:
            reason = ""
        if reason:
            self.skipped[channel.topic] = reason
        self.data[channel.id] = _ChannelData(channel, mtype=None if reason else mtype)

    def _loose_fields(self, content: bytes) -> tuple[np.ndarray, int]:
        """The fixed fields (``(1,)`` :data:`_MESSAGE_FIELDS`) and channel id of a Message record outside chunks."""
        if len(content) < 22:
            raise ValueError("a Message record shorter than its fixed fields")
        fields = np.frombuffer(content[:22], dtype=_MESSAGE_FIELDS)
        channel_id = int(fields["channel_id"][0])
        if channel_id not in self.data:
            raise ValueError(f"a message on channel {channel_id}, which no Channel record defines")
        return fields, channel_id

    def _loose_message(self, content: bytes) -> None:
        fields, channel_id = self._loose_fields(content)
        if self.data[channel_id].mtype is not None:
            self.data[channel_id].loose.append((self.message_count, fields, content[22:]))
        self.message_count += 1

    def _chunk(self, content: bytes, position: int) -> None:
        start, end, usize, crc, clen = _CHUNK_HEAD.unpack_from(content, 0)
        p = _CHUNK_HEAD.size
        compression = content[p : p + clen].decode()
        p += clen
        (rlen,) = struct.unpack_from("<Q", content, p)
        p += 8
        if p + rlen > len(content):
            raise ValueError("its records run past its end")
        packed = memoryview(content)[p : p + rlen]
        try:
            if compression == "zstd":
                data = zstandard.ZstdDecompressor().decompress(packed, max_output_size=usize)
            elif compression == "lz4":
                import lz4.frame

                data = lz4.frame.decompress(packed)
            elif compression == "":
                data = bytes(packed)
            else:
                raise self.error(f"chunk at byte {position}: unknown compression {compression!r}")
        except zstandard.ZstdError as e:
            raise self.error(f"corrupt chunk at byte {position}: {e}") from None
        if len(data) != usize:
            raise self.error(
                f"corrupt chunk at byte {position}: {len(data)} bytes after decompression, {usize} declared"
            )
        if crc and zlib.crc32(data) != crc:
            raise self.error(f"corrupt chunk at byte {position}: CRC mismatch")
        self._chunk_records(data, position)
        self.chunks += 1

    def _chunk_records(self, data: bytes, position: int) -> None:
        """Read the Schema and Channel records of a decompressed chunk, then hand its Message records'
        fixed fields (``header``), starts and lengths to :meth:`_chunk_messages`."""
        buffer = np.frombuffer(data, dtype=np.uint8)
        try:
            starts, opcodes, lengths = _record_positions(data, buffer)
        except ValueError as e:
            raise self.error(f"corrupt chunk at byte {position}: {e}") from None
        for index in np.flatnonzero(opcodes != Opcode.MESSAGE):
            p, q = int(starts[index]) + 9, int(starts[index] + 9 + lengths[index])
            if opcodes[index] == Opcode.SCHEMA:
                schema = Schema.read(ReadDataStream(BytesIO(data[p:q])))
                self.schemas[schema.id] = schema
            elif opcodes[index] == Opcode.CHANNEL:
                self._channel(Channel.read(ReadDataStream(BytesIO(data[p:q]))))
        is_message = opcodes == Opcode.MESSAGE
        starts, lengths = starts[is_message], lengths[is_message]
        if not len(starts):
            return
        if lengths.min() < 22:
            raise self.error(f"corrupt chunk at byte {position}: a Message record shorter than its fixed fields")
        header = _gather(buffer, starts + 9, 22).view(_MESSAGE_FIELDS)[:, 0]
        self._chunk_messages(data, buffer, header, starts, lengths, position)

    def _chunk_messages(self, data, buffer, header, starts, lengths, position) -> None:
        """Gather each wanted channel's payloads, in bulk."""
        ordinal = self.message_count + np.arange(len(starts))
        self.message_count += len(starts)
        channel_ids = header["channel_id"]
        for channel_id in np.unique(channel_ids):
            target = self.data.get(int(channel_id))
            if target is None:
                raise self.error(
                    f"corrupt chunk at byte {position}: a message on channel {int(channel_id)}, "
                    "which no Channel record defines"
                )
            if target.mtype is None:
                continue
            mine = np.flatnonzero(channel_ids == channel_id)
            payload_length = lengths[mine] - 22
            distinct = np.unique(payload_length)
            for length in distinct:
                sub = mine if len(distinct) == 1 else mine[payload_length == length]
                target.order.append(ordinal[sub])
                target.header.append(header[sub])
                target.payload.append(_gather(buffer, starts[sub] + 9 + 22, int(length)))


def _record_positions(data: bytes, buffer: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start offset, opcode and content length of every record in a decompressed chunk.

    Records follow each other (opcode u8, length u64, content), so finding them is a walk. It runs in
    Python until the last few records repeat a pattern (a sample's group of channels: the same opcodes
    and lengths every P records, B bytes); then it predicts the following records' positions a whole
    array at a time and checks each predicted opcode and length. Every checked record proves where the
    next one starts, so the accepted run is exact; the walk resumes after the first mismatch.
    """
    unpack = _RECORD_HEAD.unpack_from
    size = len(data)
    starts, opcodes, lengths = [], [], []
    p = 0
    while p < size:
        walked_p, walked_op, walked_len = [], [], []
        for _ in range(32):
            if p >= size:
                break
            if size - p < 9:
                raise ValueError("a partial record at its end")
            opcode, length = unpack(data, p)
            if length > size - p - 9:
                raise ValueError("a record runs past its end")
            walked_p.append(p)
            walked_op.append(opcode)
            walked_len.append(length)
            p += 9 + length
        starts.append(np.array(walked_p, dtype=np.int64))
        opcodes.append(np.array(walked_op, dtype=np.uint8))
        lengths.append(np.array(walked_len, dtype=np.int64))
        if p >= size:
            break
        period = next(
            (
                k
                for k in range(1, 9)
                if 2 * k <= len(walked_p)
                and walked_len[-k:] == walked_len[-2 * k : -k]
                and walked_op[-k:] == walked_op[-2 * k : -k]
            ),
            None,
        )
        if period is None:
            continue
        pattern_op = np.array(walked_op[-period:], dtype=np.uint8)
        pattern_len = np.array(walked_len[-period:], dtype=np.int64)
        within = np.concatenate([[0], np.cumsum(9 + pattern_len)[:-1]])
        stride = int(np.sum(9 + pattern_len))
        repeats = (size - p) // stride
        if repeats == 0:
            continue
        predicted = p + np.arange(repeats, dtype=np.int64)[:, None] * stride + within  # (repeats, period)
        found_op = buffer[predicted]
        found_len = buffer[(predicted + 1)[..., None] + np.arange(8)].view("<u8")[..., 0].astype(np.int64)
        good = np.all((found_op == pattern_op) & (found_len == pattern_len), axis=1)
        accepted = int(np.argmin(good)) if not good.all() else repeats
        if accepted:
            starts.append(predicted[:accepted].reshape(-1))
            opcodes.append(np.tile(pattern_op, accepted))
            lengths.append(np.tile(pattern_len, accepted))
            p += accepted * stride
    if not starts:
        return np.empty(0, np.int64), np.empty(0, np.uint8), np.empty(0, np.int64)
    return np.concatenate(starts), np.concatenate(opcodes), np.concatenate(lengths)


def _gather(buffer: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """Rows ``buffer[s:s + width]`` for each start ``s``: (M, width) uint8, a copy. Equally spaced
    starts (the usual case inside a chunk of interleaved channels) are taken with one strided copy."""
    m = len(starts)
    if m == 0:
        return np.empty((0, width), np.uint8)
    if m > 1:
        step = starts[1] - starts[0]
        if step >= width and np.all(np.diff(starts) == step):
            view = np.lib.stride_tricks.as_strided(buffer[starts[0] :], shape=(m, width), strides=(int(step), 1))
            return view.copy()
    return buffer[starts[:, None] + np.arange(width)]


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.title().replace("_", " ")
    except ValueError:
        return f"opcode 0x{opcode:02x}"


# -- message by message, in log-time order (replay) -------------------------------------------------


class McapMessage(NamedTuple):
    """One message as recorded: its channel's topic and schema name, ``log_time`` (ns), payload bytes."""

    topic: str
    schema: str
    log_time: int
    data: bytes


class _MessageWalk(_Scan):
    """A :class:`_Scan` that hands out each record's messages (of the wanted topics) instead of gathering
    channel arrays; Schema and Channel records are registered as the scan does."""

    def __init__(self, path: Path, topics=None):
        super().__init__(path)
        self.topics = None if topics is None else frozenset(topics)
        self.out: list[McapMessage] = []
        self.wanted: dict[int, tuple[str, str] | None] = {}  # channel id -> (topic, schema name) or None

    def _channel(self, channel: Channel) -> None:
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        self.data[channel.id] = _ChannelData(channel)  # mtype None: nothing gathered
        schema = self.schemas.get(channel.schema_id)
        keep = self.topics is None or channel.topic in self.topics
        self.wanted[channel.id] = (channel.topic, schema.name if schema is not None else "") if keep else None

    def _loose_message(self, content: bytes) -> None:
        fields, channel_id = self._loose_fields(content)
        self.message_count += 1
        wanted = self.wanted[channel_id]
        if wanted is not None:
            self.out.append(McapMessage(wanted[0], wanted[1], int(fields["log_time"][0]), bytes(content[22:])))

    def _chunk_messages(self, data, buffer, header, starts, lengths, position) -> None:
        """Hand out each wanted message as its own :class:`McapMessage`, in file order."""
        self.message_count += len(starts)
        unknown = [int(c) for c in np.unique(header["channel_id"]) if int(c) not in self.wanted]
        if unknown:
            raise self.error(
                f"corrupt chunk at byte {position}: a message on channel {unknown[0]}, which no Channel record defines"
            )
        wanted = self.wanted
        out = self.out
        for channel_id, log_time, start, length in zip(
            header["channel_id"].tolist(),
            header["log_time"].tolist(),
            (starts + 9 + 22).tolist(),
            (lengths - 22).tolist(),
        ):
            w = wanted[channel_id]
            if w is not None:
                out.append(McapMessage(w[0], w[1], log_time, data[start : start + length]))


def iter_mcap_batches(path, topics=None) -> Iterator[list[McapMessage]]:
    """The messages of an MCAP file (of ``topics`` only, when given), in log-time order, a batch per chunk.

    The file is read record by record (one decompressed chunk in memory at a time, plus what is held
    back for ordering): each chunk's messages are sorted by log time (stable: file order for equal
    times) and merged with those held back; the messages earlier than the start of the chunk just
    read are handed out. So files whose chunks start in time order (what writers that log as they go
    produce; gyroemu's chunks do not even overlap) come out in exact log-time order with one chunk of
    look-ahead. A file cut short ends with the messages of its complete chunks. Raises
    :class:`LogError` (naming the file) for what :func:`read_mcap` rejects as not MCAP or corrupt.
    The input is opened read-only.
    """
    walk = _MessageWalk(Path(path), topics)
    held: list[McapMessage] = []
    by_time = operator.attrgetter("log_time")
    for _ in walk.walk():
        if not walk.out:
            continue
        batch, walk.out = walk.out, []
        batch.sort(key=by_time)
        threshold = batch[0].log_time
        overlap = held and held[-1].log_time > threshold
        held.extend(batch)
        if overlap:
            held.sort(key=by_time)  # two sorted runs: a linear merge for timsort
        cut = bisect.bisect_left(held, threshold, key=by_time)
        if cut:
            yield held[:cut]
            held = held[cut:]
    if held:
        yield held


class ChannelInfo(NamedTuple):
    """A channel of an MCAP file with its schema (what ``gyroemu replay --ros2`` needs to name its type)."""

    topic: str
    message_encoding: str
    schema_name: str  # '' when the channel has no schema
    schema_encoding: str
    schema_data: bytes
    metadata: dict


def _channel_info(scan: _Scan) -> list[ChannelInfo]:
    """The channels a scan found, with their schemas, in file order."""
    out = []
    for c in scan.channels.values():
        schema = scan.schemas.get(c.schema_id)
        out.append(
            ChannelInfo(
                c.topic,
                c.message_encoding,
                schema.name if schema else "",
                schema.encoding if schema else "",
                bytes(schema.data) if schema else b"",
                dict(c.metadata),
            )
        )
    return out


def mcap_channel_info(path) -> list[ChannelInfo]:
    """Every channel of an MCAP file with its schema record and metadata, in file order (a pass that
    decodes no message; :attr:`McapLog.channels` holds the same). Raises :class:`LogError` as
    :func:`read_mcap` does."""
    return _channel_info(_MessageWalk(Path(path), topics=()).run())


# -- from channels to devices -----------------------------------------------------------------------

_ROLE = re.compile(r"^(?P<prefix>.*?)/(?P<role>truth/imu|estimate/imu|raw/(?P<kind>[^/]+)|imu|mag|movement)$")


def _role(topic: str) -> tuple[str, str]:
    """``(prefix, role)`` of a topic by gyroemu's naming; role '' when the topic does not follow it."""
    m = _ROLE.match(topic)
    if not m:
        return topic, ""
    return m.group("prefix"), m.group("role")


@dataclass
class _Decoded:
    topic: str
    mtype: MessageType
    log_time: np.ndarray
    batch: DecodedBatch


def _decode_channel(scan: _Scan, data: _ChannelData, mtype: MessageType) -> _Decoded:
    """All messages of a channel, decoded, in log-time order (file order for equal times)."""
    orders, headers, batches = [], [], []
    by_width: dict[int, list] = {}
    for order, header, payload in zip(data.order, data.header, data.payload):
        by_width.setdefault(payload.shape[1], []).append((order, header, payload))
    for ordinal, fields, payload in data.loose:
        by_width.setdefault(len(payload), []).append(
            (np.array([ordinal]), fields, np.frombuffer(payload, np.uint8)[None, :])
        )
    for blocks in by_width.values():
        rows = np.concatenate([b[2] for b in blocks]) if len(blocks) > 1 else blocks[0][2]
        try:
            batches.append(mtype.decode(rows))
        except ValueError as e:
            raise LogError(f"topic {data.channel.topic}: corrupt {mtype.name} message: {e}", file=scan.path) from None
        orders.append(np.concatenate([b[0] for b in blocks]))
        headers.append(np.concatenate([b[1] for b in blocks]))
    order = np.concatenate(orders) if len(orders) > 1 else orders[0]
    header = np.concatenate(headers) if len(headers) > 1 else headers[0]
    batch = (
        batches[0]
        if len(batches) == 1
        else DecodedBatch(
            stamp_ns=np.concatenate([b.stamp_ns for b in batches]),
            frame_id=np.concatenate([b.frame_id for b in batches]),
            fields={name: np.concatenate([b.fields[name] for b in batches]) for name in batches[0].fields},
        )
    )
    log_time = header["log_time"].astype(np.uint64)
    # File order, then a stable sort by log time (both no-ops for files gyroemu writes).
    index = None if np.all(np.diff(order) > 0) else np.argsort(order, kind="stable")
    ordered = log_time if index is None else log_time[index]
    if np.any(ordered[1:] < ordered[:-1]):
        by_time = np.argsort(ordered, kind="stable")
        index = by_time if index is None else index[by_time]
    if index is not None:
        log_time = log_time[index]
        batch = DecodedBatch(
            stamp_ns=batch.stamp_ns[index],
            frame_id=batch.frame_id[index],
            fields={k: v[index] for k, v in batch.fields.items()},
        )
    return _Decoded(topic=data.channel.topic, mtype=mtype, log_time=log_time, batch=batch)


def _imu_series(decoded: _Decoded) -> ImuSeries:
    """An :class:`ImuSeries` from decoded Imu messages (x, y, z, w to scalar-first; -1 covariances to
    None or NaN rows)."""
    batch = decoded.batch
    n = len(batch)
    out: dict[str, np.ndarray | None] = {}
    for value_name, cov_name, field_name, cov_field in _IMU_QUANTITIES:
        cov = batch[cov_field]
        absent = cov[:, 0] == -1.0
        if n and np.all(absent):
            out[value_name] = out[cov_name] = None
            continue
        value = batch[field_name]
        value = value[:, [3, 0, 1, 2]] if field_name == "orientation" else value.copy()
        cov = cov.reshape(n, 3, 3).copy()
        if np.any(absent):
            value[absent] = np.nan
            cov[absent] = np.nan
        out[value_name] = value
        out[cov_name] = cov if np.any(cov) else None
    return ImuSeries(t=ns_to_stamps(batch.stamp_ns), **out)


def _match(reference_ns: np.ndarray, stamp_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i, j)`` with ``reference_ns[i] == stamp_ns[j]`` (first match of each, in order)."""
    if len(reference_ns) == len(stamp_ns) and np.array_equal(reference_ns, stamp_ns):
        index = np.arange(len(stamp_ns))
        return index, index
    if not len(stamp_ns):
        return np.empty(0, np.int64), np.empty(0, np.int64)
    order = np.argsort(stamp_ns, kind="stable")
    ordered = stamp_ns[order]
    position = np.minimum(np.searchsorted(ordered, reference_ns), len(ordered) - 1)
    i = np.flatnonzero(ordered[position] == reference_ns)
    return i, order[position[i]]


def read_mcap(path) -> McapLog:
    """Read a ``ros2`` MCAP log: every ``sensor_msgs/msg/Imu`` channel becomes a device's samples.

    Topics named as gyroemu names them (``[/<device>]/imu``, ``/mag``, ``/truth/imu``,
    ``/estimate/imu``, ``/raw/<kind>``, ``/movement``) are grouped by device; any other Imu topic is a
    device of its own, named after the topic. Measured samples get the ``/mag`` field (NaN where absent)
    and the raw observables at their stamps (samples without raw counterparts are dropped, with a
    warning); ``/movement`` becomes :attr:`DeviceLog.movement` at the same stamps (False, with a warning,
    where a sample has none).

    Raises
    ------
    LogError
        The file cannot be opened, is not MCAP, is corrupt, or holds no IMU messages (also when it is
        truncated before the first complete chunk).

    Warns
    -----
    LogWarning
        For channels of types gyroemu does not decode (skipped), and for a truncated file (with the
        number of messages recovered).
    """
    path = Path(path)
    scan = _Scan(path).run()
    skipped = dict(scan.skipped)

    if scan.truncated_at is not None:
        warnings.warn(
            f"{path}: truncated at byte {scan.truncated_at} (no MCAP footer): recovered "
            f"{scan.message_count} messages from {scan.chunks} complete chunks",
            LogWarning,
            stacklevel=2,
        )
    for topic, reason in skipped.items():
        warnings.warn(f"{path}: skipping topic {topic}: {reason}", LogWarning, stacklevel=2)

    decoded: dict[int, _Decoded] = {}
    for channel_id, data in scan.data.items():
        if data.mtype is not None and (data.payload or data.loose):
            decoded[channel_id] = _decode_channel(scan, data, data.mtype)

    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    devices = _devices(path, decoded, metadata, skipped)
    if not devices:
        state = (
            f"; truncated at byte {scan.truncated_at}, {scan.message_count} messages recovered"
            if scan.truncated_at is not None
            else ""
        )
        raise LogError(
            f"holds no sensor_msgs/msg/Imu messages ({len(scan.channels)} channels, "
            f"{scan.message_count} messages{state})",
            file=path,
        )
    return McapLog(
        path=path,
        devices=devices,
        metadata=metadata,
        profile=scan.profile,
        message_count=scan.message_count,
        truncated=scan.truncated_at is not None,
        skipped=skipped,
        channels=tuple(_channel_info(scan)),
    )


def _devices(path: Path, decoded: dict, metadata: list, skipped: dict) -> dict:
    """Group decoded channels into devices."""
    groups: dict[str, dict[str, _Decoded]] = {}
    for d in decoded.values():
        prefix, role = _role(d.topic)
        if role.startswith("raw/") and d.mtype.kind is None:
            role = ""  # a /raw/x topic of a standard type: take it as a plain topic
        if role in ("imu", "truth/imu", "estimate/imu") and d.mtype is not IMU:
            role = ""
        if role == "mag" and d.mtype is not MAGNETIC_FIELD:
            role = ""
        if role == "movement" and d.mtype is not FLAG:
            role = ""
        if not role:
            if d.mtype is IMU:
                groups.setdefault(d.topic, {})["imu"] = d
            else:
                skipped[d.topic] = f"a {d.mtype.name} topic that belongs to no IMU topic"
                warnings.warn(f"{path}: skipping topic {d.topic}: {skipped[d.topic]}", LogWarning, stacklevel=3)
            continue
        groups.setdefault(prefix, {})[role] = d
    # Truth or estimate without a measured IMU: a device of its own (it holds Imu messages).
    for prefix in list(groups):
        group = groups[prefix]
        if "imu" not in group:
            for role in ("truth/imu", "estimate/imu"):
                if role in group:
                    groups[f"{prefix}/{role}"] = {"imu": group.pop(role)}
            for d in group.values():
                skipped[d.topic] = "no IMU topic of the same device"
                warnings.warn(f"{path}: skipping topic {d.topic}: {skipped[d.topic]}", LogWarning, stacklevel=3)
            del groups[prefix]
    records = {m.get("topic_prefix", ""): m for m in metadata}
    devices = {}
    for prefix, group in groups.items():
        if not len(group["imu"].batch):
            continue
        meta = records.get(prefix) or (metadata[0] if prefix == "" and len(metadata) == 1 else None)
        name = (meta or {}).get("device_name") or (prefix.strip("/") or "imu0")
        device = _device_log(path, name, group, meta)
        devices[name] = device
    return devices


def _device_log(path: Path, name: str, group: dict, meta: dict | None) -> DeviceLog:
    imu = group["imu"]
    stamp_ns = imu.batch.stamp_ns
    keep = np.arange(len(stamp_ns))
    raw: dict[str, dict[str, np.ndarray]] = {}
    for role, d in group.items():
        if role.startswith("raw/"):
            i, j = _match(stamp_ns[keep], d.batch.stamp_ns)
            if len(i) < len(keep):
                warnings.warn(
                    f"{path}: {len(keep) - len(i)} samples of {imu.topic} have no message on {d.topic} "
                    "at their stamp; dropped",
                    LogWarning,
                    stacklevel=4,
                )
                keep = keep[i]
                raw = {k: {n: v[i] for n, v in obs.items()} for k, obs in raw.items()}
            raw[d.mtype.kind] = {n: v[j] for n, v in raw_observables(d.mtype, d.batch).items()}
    mag = np.full((len(keep), 3), np.nan)
    if "mag" in group:
        d = group["mag"]
        i, j = _match(stamp_ns[keep], d.batch.stamp_ns)
        mag[i] = d.batch["magnetic_field"][j]
    movement = None
    if "movement" in group:
        d = group["movement"]
        i, j = _match(stamp_ns[keep], d.batch.stamp_ns)
        movement = np.zeros(len(keep), dtype=bool)
        movement[i] = d.batch["data"][j]
        if len(i) < len(keep):
            warnings.warn(
                f"{path}: {len(keep) - len(i)} samples of {imu.topic} have no message on {d.topic} "
                "at their stamp; their movement flag is False",
                LogWarning,
                stacklevel=4,
            )
    batch = imu.batch
    samples = ImuSamples(
        t=ns_to_stamps(stamp_ns[keep]),
        gyro=batch["angular_velocity"][keep],
        accel=batch["linear_acceleration"][keep],
        mag=mag,
        raw=raw,
        device=name,
    )
    return DeviceLog(
        name=name,
        topics={role: d.topic for role, d in group.items()},
        samples=samples,
        stamp_ns=stamp_ns[keep],
        truth=_imu_series(group["truth/imu"]) if "truth/imu" in group else None,
        estimate=_imu_series(group["estimate/imu"]) if "estimate/imu" in group else None,
        metadata=meta,
        movement=movement,
    )
