"""MCAP records: a bulk writer, a scanner and a message walk, for any ``ros2`` MCAP file.

This is the lower of the two MCAP layers. It knows MCAP records (the MCAP specification) and the CDR
message types of :mod:`gyroemu.pipelines.formats.messages`, but not what gyroemu's channels mean: devices,
truth, recordings and metadata are :mod:`gyroemu.pipelines.formats.mcap_log`'s, which is built on this module
(and so is ``gyroemu record``, which copies received bytes into a file with :class:`McapFileWriter`).

Writing
-------
:class:`McapFileWriter` takes messages in bulk: per channel an ``(N, size)`` array of serialised
payloads (:meth:`MessageType.encode`). It builds the MCAP Message records of a block with numpy (one
structured row per message), interleaves the channels in time order (when the channels share their
stamps, by concatenating rows: no sort), cuts the result into chunks of ``chunk_size`` uncompressed
bytes and compresses each with zstd; message indexes follow each chunk, and :meth:`McapFileWriter.finish`
writes the summary (schemas, channels, statistics, chunk and metadata indexes, summary offsets). The
small records (header, schemas, channels, metadata, indexes, statistics, summary offsets, footer) are
``mcap.records`` objects serialised by the ``mcap`` library; Chunk and Message Index records are packed
here because they carry the bulk. ``mcap.writer.Writer`` is not used for the messages: it costs about
3 us per message in Python (about 300 k/s for empty payloads on the development machine), which alone
exceeds the budget of 200 k IMU messages/s with four channels per sample. Channels of the ``ros2``
profile (:meth:`McapFileWriter.register_ros2_channel`) carry :data:`OFFERED_QOS_PROFILES`.

Reading
-------
:class:`McapScan` walks a file record by record, decompresses each chunk, finds its Message records in
one pass and gathers the payloads of each channel of a type gyroemu decodes (:class:`ChannelData`);
:meth:`McapScan.decode` turns them into :class:`DecodedChannel` batches in log-time order. Channels of
other types, encodings or without a schema are noted in :attr:`McapScan.skipped`. A file cut short (a
recorder killed mid-write, no footer) yields the messages of its complete chunks and says where it was
cut (:attr:`McapScan.truncated_at`). Files that are not MCAP or are corrupt raise :class:`LogError`,
which names the file. Inputs are opened read-only.

:func:`iter_mcap_batches` walks the same records but hands out every message (topic, schema name, log
time, payload bytes) in log-time order, a batch per chunk, for ``gyroemu replay``;
:func:`mcap_channel_info` lists a file's channels with their schemas.

Sources: MCAP format specification (https://mcap.dev/spec) and its appendix (well-known encodings,
``ros2`` profile); ``rosbag2_storage_mcap`` (channel metadata ``offered_qos_profiles``).
"""

from __future__ import annotations

import bisect
import operator
import os
import struct
import threading
import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, NamedTuple, TypeAlias, cast

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from numpy.typing import ArrayLike, NDArray

import gyroemu
from gyroemu.errors import LogError
from gyroemu.pipelines.formats.messages import DecodedBatch, MessageType, message_type

if TYPE_CHECKING:
    from typing_extensions import Buffer

__all__ = [
    "folder_not_mcap",
    "COMPRESSION_LEVEL",
    "MAGIC",
    "OFFERED_QOS_PROFILES",
    "LogError",
    "McapFileWriter",
    "McapScan",
    "ChannelData",
    "decoded_type",
    "DecodedChannel",
    "McapMessage",
    "iter_mcap_batches",
    "ChannelInfo",
    "mcap_channel_info",
    "RawMessages",
    "McapRecordWalk",
]

MAGIC = b"\x89MCAP0\r\n"
"""The 8 bytes that start and end every MCAP file."""

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


# ==================================================================================================
# Writing: Message records in bulk.

_MESSAGE_HEAD = 1 + 8 + 2 + 4 + 8 + 8
"""Bytes of a Message record before its data: opcode, record length, channel id, sequence, log and
publish time."""

_SEQUENCE_AT = 1 + 8 + 2
"""Offset of a Message record's ``sequence`` (u32): after its opcode, record length and channel id."""

_MESSAGE_FIELDS = np.dtype(
    {
        "names": ["channel_id", "sequence", "log_time", "publish_time"],
        "formats": ["<u2", "<u4", "<u8", "<u8"],
        "offsets": [0, 2, 6, 14],
        "itemsize": 22,
    }
)


@dataclass
class _Member:
    """One channel's messages in a block, before their records are laid out."""

    channel_id: int
    sequence: NDArray[np.uint32]  # (N,)
    log_time: NDArray[np.uint64]  # (N,)
    payloads: NDArray[np.uint8]  # (N, size)


@dataclass
class _Group:
    """Message records of channels that share their log times: row k holds every channel's message k,
    in the channels' order, as one contiguous unit."""

    rows: NDArray[np.uint8]  # (N, total record size)
    channel: NDArray[np.uint16]  # (K,)
    sizes: NDArray[np.int64]  # (K,), record sizes
    log_time: NDArray[np.uint64]  # (N,)


def _group_records(members: Sequence[_Member]) -> _Group:
    """Lay out the MCAP Message records of channels that share their log times, row k being sample k.

    Record layout (MCAP spec, "Message", opcode 0x05): opcode u8, record length u64 (= 22 + size),
    channel_id u16, sequence u32, log_time u64, publish_time u64, then the payload; all little endian.
    Each payload is copied once, straight to its place in the row.
    """
    log_time = members[0].log_time
    sizes = np.array([_MESSAGE_HEAD + m.payloads.shape[1] for m in members], dtype=np.int64)
    rows = np.empty((len(log_time), int(sizes.sum())), dtype=np.uint8)
    names, formats, offsets = [], [], []
    column = 0
    for i, (member, size) in enumerate(zip(members, sizes.tolist())):
        rows[:, column : column + 11] = np.frombuffer(
            struct.pack("<BQH", Opcode.MESSAGE, size - 9, member.channel_id), np.uint8
        )
        rows[:, column + _MESSAGE_HEAD : column + size] = member.payloads
        names += [f"sequence{i}", f"log_time{i}", f"publish_time{i}"]
        formats += ["<u4", "<u8", "<u8"]
        offsets += [column + 11, column + 15, column + 23]
        column += size
    head = rows.view(np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": column}))[:, 0]
    for i, member in enumerate(members):
        head[f"sequence{i}"] = member.sequence
        head[f"log_time{i}"] = log_time
        head[f"publish_time{i}"] = log_time
    channel = np.array([m.channel_id for m in members], dtype=np.uint16)
    return _Group(rows, channel, sizes, log_time)


_Records: TypeAlias = tuple[NDArray[np.uint8], NDArray[np.uint16], NDArray[np.uint64], NDArray[np.int64]]
"""``(data, channel_id, log_time, offset)``: Message records laid end to end and, per message, its channel,
log time and offset in ``data``."""


def _no_messages() -> _Records:
    """``(data, channel_id, log_time, offset)`` of no message (see :func:`_interleave`)."""
    return np.empty(0, np.uint8), np.empty(0, np.uint16), np.empty(0, np.uint64), np.empty(0, np.int64)


def _groups(members: Sequence[_Member]) -> list[_Group]:
    """The members with messages, grouped by equal log times (in the order of each group's first)."""
    grouped: list[list[_Member]] = []
    for m in members:
        if not len(m.log_time):
            continue
        for group in grouped:
            first = group[0].log_time
            if len(first) == len(m.log_time) and np.array_equal(first, m.log_time):
                group.append(m)
                break
        else:
            grouped.append([m])
    return [_group_records(group) for group in grouped]


def _interleave(groups: Sequence[_Group]) -> _Records:
    """Records of several groups of channels (:func:`_groups`) in time order (ties: the order of
    ``groups``).

    Returns ``(data, channel_id, log_time, offset)``: the concatenated records (uint8) and, per message,
    its channel, log time and offset in ``data``.

    A group's row k (every channel's message k, in order) is one contiguous unit. One group is laid out
    already; several (e.g. every sample's channels and a thinned /tf) are merged by sorting their units
    by time and copying runs of consecutive units with slices, or, when the runs are short (channels of
    unrelated stamps), by a byte gather. The bytes are the same either way.
    """
    if not groups:
        return _no_messages()
    if len(groups) == 1:
        g = groups[0]
        n, k = len(g.log_time), len(g.channel)
        channel = np.tile(g.channel, n)
        log_time = np.repeat(g.log_time, k)
        offset = np.concatenate([[0], np.cumsum(np.tile(g.sizes, n))[:-1]]).astype(np.int64)
        return g.rows.reshape(-1), channel, log_time, offset
    # Units (one per group row) in time order; ties keep the group order.
    unit_time = np.concatenate([g.log_time for g in groups])
    unit_group = np.repeat(np.arange(len(groups)), [len(g.log_time) for g in groups])
    unit_row = np.concatenate([np.arange(len(g.log_time)) for g in groups])
    order = np.argsort(unit_time, kind="stable")
    unit_size = np.array([g.rows.shape[1] for g in groups], dtype=np.int64)[unit_group[order]]
    unit_count = np.array([len(g.channel) for g in groups], dtype=np.int64)[unit_group[order]]
    unit_offset = np.concatenate([[0], np.cumsum(unit_size)[:-1]]).astype(np.int64)
    unit_message = np.concatenate([[0], np.cumsum(unit_count)[:-1]]).astype(np.int64)
    total_messages = int(unit_count.sum())
    data = np.empty(int(unit_size.sum()), dtype=np.uint8)
    channel = np.empty(total_messages, dtype=np.uint16)
    log_time = np.empty(total_messages, dtype=np.uint64)
    offset = np.empty(total_messages, dtype=np.int64)
    position = np.empty(len(order), dtype=np.int64)
    position[order] = np.arange(len(order))  # where each unit lands
    start = 0
    for g in groups:
        at = position[start : start + len(g.log_time)]
        start += len(g.log_time)
        inner = np.concatenate([[0], np.cumsum(g.sizes)[:-1]])
        index = unit_message[at][:, None] + np.arange(len(g.channel))
        channel[index] = g.channel
        log_time[index] = g.log_time[:, None]
        offset[index] = unit_offset[at][:, None] + inner
    # Runs of consecutive rows of one group land contiguously: copy each run as one slice.
    g_sorted, r_sorted = unit_group[order], unit_row[order]
    breaks = np.flatnonzero((np.diff(g_sorted) != 0) | (np.diff(r_sorted) != 1)) + 1
    run_start = np.concatenate([[0], breaks])
    run_end = np.concatenate([breaks, [len(order)]])
    if len(run_start) * 512 <= len(data):  # runs of 512 bytes on average: a slice each beats a byte gather
        flat = [g.rows.reshape(-1) for g in groups]
        lo = unit_offset[run_start]
        hi = unit_offset[run_end - 1] + unit_size[run_end - 1]
        src = r_sorted[run_start] * unit_size[run_start]
        for group, a, b, c in zip(g_sorted[run_start].tolist(), lo.tolist(), hi.tolist(), src.tolist()):
            data[a:b] = flat[group][c : c + b - a]
        return data, channel, log_time, offset
    source = np.concatenate([g.rows.reshape(-1) for g in groups])
    base = np.concatenate([[0], np.cumsum([g.rows.size for g in groups])[:-1]]).astype(np.int64)
    src = (base[g_sorted] + r_sorted * unit_size).astype(np.int64)
    piece = 1 << 16  # units per gather: bounds the index array
    for a in range(0, len(order), piece):
        b = min(a + piece, len(order))
        lo, hi = unit_offset[a], unit_offset[b - 1] + unit_size[b - 1]
        index = np.repeat(src[a:b] - unit_offset[a:b], unit_size[a:b]) + np.arange(lo, hi)
        data[lo:hi] = source[index]
    return data, channel, log_time, offset


COMPRESSION_LEVEL = 1
"""zstd level of the chunks gyroemu writes. Level 1 against zstd's default 3, on 1 MiB chunks of a
simulated log (IMU, field, truth and raw channels: noisy floats): 874 against 536 MB/s, for 1.7 %
more bytes (ratio 4.90 against 4.98)."""


def _rows(buffer: NDArray[np.uint8], size: int) -> NDArray[np.uint8]:
    """Every run of ``size`` bytes of ``buffer`` (n,) as a row of a (n − size + 1, size) view: indexed by
    start offsets, it reads or writes whole payloads without an index per byte."""
    return _windows(buffer, size, writeable=bool(buffer.flags.writeable))


class McapFileWriter:
    """An MCAP writer that takes messages in bulk: chunked, zstd, message and chunk indexes, summary.

    Parameters
    ----------
    stream : binary file
        Written sequentially (never seeked).
    profile : str
        The Header record's profile.
    library : str, optional
        The Header record's library (default ``gyroemu/<version>``).
    chunk_size : int
        Uncompressed bytes of records after which a chunk is closed.
    compression_level : int
        zstd level (default :data:`COMPRESSION_LEVEL`).
    """

    def __init__(
        self,
        stream: BinaryIO,
        *,
        profile: str = "ros2",
        library: str | None = None,
        chunk_size: int = 1 << 20,
        compression_level: int = COMPRESSION_LEVEL,
    ) -> None:
        self._out = stream
        self._position = 0
        self._chunk_size = int(chunk_size)
        self._compressor = zstandard.ZstdCompressor(level=compression_level)
        self._parallel = zstandard.backend == "cext"  # the cffi backend has no multi_compress_to_buffer
        self._schemas: dict[int, Schema] = {}
        self._schema_ids: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_count = 0
        self._channel_counts: dict[int, int] = {}
        self._time_range: list[int] | None = None
        self._metadata_count = 0
        self._pending = _no_messages()
        self._held: list[tuple[McapRecord, str | None]] = []  # registered records not yet written (_hold)
        self._held_lock = threading.Lock()
        self._finished = False
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=library or f"gyroemu/{gyroemu.__version__}"))

    # ---------------------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        self._out.write(data)
        self._position += len(data)

    def _write_record(self, record: McapRecord) -> int:
        """Write one ``mcap.records`` record; returns its offset."""
        builder = RecordBuilder()
        record.write(builder)
        data: bytes = builder.end()
        offset = self._position
        self._write(data)
        return offset

    def _hold(self, record: McapRecord, metadata_name: str | None = None) -> None:
        """Queue a Schema, Channel or Metadata record: written, in order, before the next messages (or at
        :meth:`finish`), so that a thread preparing messages may register channels while another writes."""
        with self._held_lock:
            self._held.append((record, metadata_name))

    def _write_held(self) -> None:
        """Write the queued records (a Metadata record also gets its index in the summary)."""
        with self._held_lock:
            held, self._held = self._held, []
        for record, name in held:
            offset = self._write_record(record)
            if name is not None:
                self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._position - offset, name=name))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Schema id of ``name`` (written once, before any message of its channels)."""
        key = (name, encoding, bytes(data))
        if key not in self._schema_ids:
            schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=bytes(data))
            self._schemas[schema.id] = schema
            self._schema_ids[key] = schema.id
            self._hold(schema)
        return self._schema_ids[key]

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: Mapping[str, str] | None = None
    ) -> int:
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
        self._hold(channel)
        return channel.id

    def register_ros2_channel(
        self, topic: str, mtype: MessageType | None, metadata: Mapping[str, str] | None = None
    ) -> int:
        """A new ``cdr`` channel of type ``mtype`` (its ``ros2msg`` schema, registered once; None: no
        schema) with the ``offered_qos_profiles`` of the ``ros2`` profile, then ``metadata``."""
        schema_id = 0 if mtype is None else self.register_schema(mtype.name, "ros2msg", mtype.schema.encode())
        return self.register_channel(
            topic, "cdr", schema_id, {"offered_qos_profiles": OFFERED_QOS_PROFILES, **(metadata or {})}
        )

    def add_metadata(self, name: str, data: Mapping[str, object]) -> None:
        """A Metadata record (and its index in the summary), written before the next messages."""
        self._hold(Metadata(name=name, metadata={str(k): str(v) for k, v in data.items()}), name)
        self._metadata_count += 1

    def add_messages(self, batches: Iterable[tuple[int, ArrayLike, ArrayLike]]) -> None:
        """Append messages of several channels, interleaved in time order, after the records registered
        before them.

        Parameters
        ----------
        batches : iterable of (channel_id, log_time_ns, payloads)
            Per channel: ``log_time_ns`` (N,) non-negative integers, also written as publish time, and
            ``payloads`` (N, size) uint8, one serialised message per row (e.g. from
            :meth:`MessageType.encode`, or received bytes stacked with ``np.frombuffer``). Messages with
            equal times keep the order of ``batches``; sequence numbers continue per channel from 0, in file order.
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
        members = []
        for channel_id, log_time, payloads in checked:
            first = self._channel_counts[channel_id]
            sequence = (np.arange(first, first + len(log_time), dtype=np.int64) % (1 << 32)).astype(np.uint32)
            self._channel_counts[channel_id] += len(log_time)
            members.append(_Member(channel_id, sequence, log_time.astype(np.uint64), payloads))
        data, channel, log_time, offset = _interleave(_groups(members))
        self._write_held()
        if not len(log_time):
            return
        shared = [c for c in {c for c, _, _ in checked} if sum(c == d for d, _, _ in checked) > 1]
        for channel_id in shared:  # several batches of one channel: number its messages in file order
            at = offset[channel == channel_id]
            first = self._channel_counts[channel_id] - len(at)
            sequence = (np.arange(first, first + len(at), dtype=np.int64) % (1 << 32)).astype("<u4")
            data[at[:, None] + _SEQUENCE_AT + np.arange(4)] = sequence.view(np.uint8).reshape(-1, 4)
        self._append(data, channel, log_time, offset)

    def add_raw_messages(
        self,
        channel_id: ArrayLike,
        sequence: ArrayLike,
        log_time: ArrayLike,
        publish_time: ArrayLike,
        buffer: ArrayLike,
        start: ArrayLike,
        size: ArrayLike,
    ) -> None:
        """Append messages exactly as given, in the given order (no interleaving, no renumbering).

        For copying another file's messages (:class:`McapRecordWalk`) with their own sequence numbers
        and publish times, payloads of any length. The caller keeps the file's log times in the order it
        wants (a copy keeps the input's).

        Parameters
        ----------
        channel_id, sequence, log_time, publish_time : array_like (M,)
            Each message's Message record fields; ``channel_id`` must be registered here.
        buffer : ndarray uint8
            Bytes holding the payloads.
        start, size : array_like (M,) int
            Message k's payload is ``buffer[start[k] : start[k] + size[k]]``.
        """
        if self._finished:
            raise ValueError("the MCAP file is finished")
        channel = np.asarray(channel_id, dtype=np.uint16).reshape(-1)
        n = len(channel)
        if not n:
            return
        unknown = sorted(set(np.unique(channel).tolist()) - set(self._channels))
        if unknown:
            raise ValueError(f"channel {unknown[0]} is not registered")
        start = np.asarray(start, dtype=np.int64).reshape(-1)
        size = np.asarray(size, dtype=np.int64).reshape(-1)
        buffer = np.asarray(buffer, dtype=np.uint8).reshape(-1)
        if size.min() < 0 or (start.min() < 0 or (start + size).max() > len(buffer)):
            raise ValueError("a payload runs outside the buffer")
        head = np.empty(
            n,
            dtype=np.dtype(
                {
                    "names": ["opcode", "length", "channel_id", "sequence", "log_time", "publish_time"],
                    "formats": ["u1", "<u8", "<u2", "<u4", "<u8", "<u8"],
                    "offsets": [0, 1, 9, 11, 15, 23],
                    "itemsize": _MESSAGE_HEAD,
                }
            ),
        )
        head["opcode"] = Opcode.MESSAGE
        head["length"] = _MESSAGE_HEAD - 9 + size
        head["channel_id"] = channel
        head["sequence"] = np.asarray(sequence, dtype=np.uint32).reshape(-1)
        log_time = np.asarray(log_time, dtype=np.uint64).reshape(-1)
        head["log_time"] = log_time
        head["publish_time"] = np.asarray(publish_time, dtype=np.uint64).reshape(-1)
        record = _MESSAGE_HEAD + size
        offset = np.concatenate([[0], np.cumsum(record)[:-1]]).astype(np.int64)
        data = np.empty(int(record.sum()), dtype=np.uint8)
        _rows(data, _MESSAGE_HEAD)[offset] = head.view(np.uint8).reshape(n, _MESSAGE_HEAD)
        for z in np.unique(size[size > 0]).tolist():  # payloads a size at a time: a handful of sizes
            k = np.flatnonzero(size == z)
            _rows(data, z)[offset[k] + _MESSAGE_HEAD] = _rows(buffer, z)[start[k]]
        ids, counts = np.unique(channel, return_counts=True)
        for c, k in zip(ids.tolist(), counts.tolist()):
            self._channel_counts[c] += k
        self._write_held()
        self._append(data, channel, log_time, offset)

    def _append(
        self,
        data: NDArray[np.uint8],
        channel: NDArray[np.uint16],
        log_time: NDArray[np.uint64],
        offset: NDArray[np.int64],
    ) -> None:
        """Queue Message records (``data``; per message its channel, log time and offset in ``data``)
        for the chunks, writing every chunk they complete."""
        self._message_count += len(log_time)
        lo, hi = int(log_time.min()), int(log_time.max())
        self._time_range = (
            [lo, hi] if self._time_range is None else [min(self._time_range[0], lo), max(self._time_range[1], hi)]
        )
        p_data, p_channel, p_time, p_offset = self._pending
        # Chunk k holds the messages that start in [k, k + 1) * chunk_size of the records laid end to
        # end after the pending ones (chunk 0 continues the pending chunk): at most one message over.
        chunk = (offset + len(p_data)) // self._chunk_size
        last = int(chunk[-1])
        if last == 0:  # nothing completes
            self._pending = (
                np.concatenate([p_data, data]),
                np.concatenate([p_channel, channel]),
                np.concatenate([p_time, log_time]),
                np.concatenate([p_offset, offset + len(p_data)]),
            )
            return
        starts = np.searchsorted(chunk, np.arange(1, last + 1)).tolist()  # first message of chunks 1..last
        n = starts[0]
        pieces = [  # chunk 0: the pending records and the new ones up to chunk 1 (at most one chunk copied)
            (
                np.concatenate([p_data, data[: offset[n] if n < len(offset) else len(data)]]),
                np.concatenate([p_channel, channel[:n]]),
                np.concatenate([p_time, log_time[:n]]),
                np.concatenate([p_offset, offset[:n] + len(p_data)]),
            )
        ]
        for a, b in zip(starts[:-1], starts[1:]):  # whole chunks of the new records: views
            if b > a:
                pieces.append((data[offset[a] : offset[b]], channel[a:b], log_time[a:b], offset[a:b] - offset[a]))
        self._write_chunks([piece for piece in pieces if len(piece[1])])
        a = starts[-1]
        self._pending = (data[offset[a] :].copy(), channel[a:], log_time[a:], offset[a:] - offset[a])

    def _write_chunks(self, pieces: list[_Records]) -> None:
        """Chunks of ``(records, channel, log_time, offset)``, compressed on every core at once (zstd
        and zlib release the GIL; each chunk is one zstd frame, the same bytes as compressed alone), then
        written in order."""
        raws: list[bytes | bytearray | memoryview] = [
            memoryview(cast("Buffer", np.ascontiguousarray(records)))  # numpy's stubs: __buffer__ 3.12+ only
            for records, _, _, _ in pieces
        ]
        if len(raws) > 1 and self._parallel:
            with ThreadPoolExecutor(1, thread_name_prefix="mcap-crc") as summer:
                crcs = summer.submit(lambda: [zlib.crc32(raw) for raw in raws])
                frames = self._compressor.multi_compress_to_buffer(raws, threads=-1)
                compressed = [frames[k].tobytes() for k in range(len(raws))]
                crc = crcs.result()
        else:
            compressed = [self._compressor.compress(raw) for raw in raws]
            crc = [zlib.crc32(raw) for raw in raws]
        for (_, channel, log_time, offset), raw, packed, check in zip(pieces, raws, compressed, crc):
            self._write_chunk(raw, packed, check, channel, log_time, offset)

    def _write_chunk(
        self,
        raw: bytes | bytearray | memoryview,
        compressed: bytes,
        crc: int,
        channel: NDArray[np.uint16],
        log_time: NDArray[np.uint64],
        offset: NDArray[np.int64],
    ) -> None:
        """One Chunk record (opcode 0x06) and its Message Index records (0x07)."""
        compression = b"zstd"
        start_time, end_time = int(log_time.min()), int(log_time.max())
        # Chunk: message_start_time u64, message_end_time u64, uncompressed_size u64,
        # uncompressed_crc u32, compression string (u32 length + bytes), records (u64 length + bytes).
        body = 8 + 8 + 8 + 4 + 4 + len(compression) + 8 + len(compressed)
        head = (
            struct.pack("<BQQQQII", Opcode.CHUNK, body, start_time, end_time, len(raw), crc, len(compression))
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
        self._write_held()
        data, channel, log_time, offset = self._pending
        if len(channel):
            self._write_chunks([(data, channel, log_time, offset)])
        self._pending = _no_messages()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._position
        builder = RecordBuilder()
        groups = []

        def group(opcode: Opcode, records: Iterable[McapRecord]) -> None:
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
        summary: bytes = builder.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start), crc)
        self._write(summary)
        self._write_record(
            Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc)
        )
        self._write(MAGIC)
        self._finished = True


# ==================================================================================================
# Reading: a scan that gathers channels, a walk that hands out messages.

_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length


@dataclass
class ChannelData:
    """Messages of one channel gathered while scanning: blocks of equal-length payloads."""

    channel: Channel
    mtype: MessageType | None = None  # None: not decoded
    order: list[NDArray[np.int64]] = field(default_factory=list)  # global message ordinal per block
    header: list[NDArray[np.void]] = field(default_factory=list)  # _MESSAGE_FIELDS arrays
    payload: list[NDArray[np.uint8]] = field(default_factory=list)  # (m, L)
    # messages outside chunks: (ordinal, (1,) fields, bytes)
    loose: list[tuple[int, NDArray[np.void], bytes]] = field(default_factory=list)


@dataclass
class DecodedChannel:
    """A channel's messages decoded (:meth:`McapScan.decode`), in log-time order."""

    topic: str
    mtype: MessageType
    log_time: NDArray[np.uint64]  # (N,), ns
    batch: DecodedBatch


def decoded_type(channel: Channel, schema: Schema | None) -> tuple[MessageType | None, str]:
    """The message type gyroemu decodes ``channel`` as, or None and the reason it is skipped."""
    mtype = message_type(schema.name) if schema is not None else None
    if schema is None:
        return None, "no schema"
    if channel.message_encoding != "cdr":
        return None, f"message encoding {channel.message_encoding!r}, not cdr"
    if mtype is None:
        return None, f"type {schema.name} is not one gyroemu decodes"
    return mtype, ""


LOOSE_BATCH = 4096
"""Messages outside chunks (an unchunked file) taken together, at most: :meth:`McapScan.check` decodes a
channel's, :meth:`McapRecordWalk.batches` hands them out, this many at a time (one at a time, a message
cost 0.35 ms)."""


class McapScan:
    """A pass over an MCAP file: schemas, channels, metadata and the messages of the channels gyroemu
    decodes (see the module's notes). :meth:`run` reads the whole file, :meth:`walk` a record at a time.

    Attributes
    ----------
    path : Path
    profile : str
        The Header record's profile.
    schemas, channels : dict of int to mcap.records.Schema, Channel
        By id, in file order.
    metadata : list of mcap.records.Metadata
    data : dict of int to ChannelData
        Per channel id, its gathered messages.
    skipped : dict of str to str
        Topics not gathered, with the reason.
    message_count, chunks : int
        Messages (every channel) and complete chunks read.
    truncated_at : int or None
        The byte offset where a file without footer ends.
    footer : bool
        The footer and closing magic were read.
    summary : bool
        The footer points at a summary section (schemas, channels, statistics, indexes).
    chunk_indexes : int
        Chunk index records read (a summary's index of the chunks; 0 in an unchunked file).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.profile = ""
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: list[Metadata] = []
        self.data: dict[int, ChannelData] = {}
        self.skipped: dict[str, str] = {}
        self.message_count = 0
        self.chunks = 0
        self.truncated_at: int | None = None
        self.footer = False
        self.summary = False
        self.chunk_indexes = 0

    def error(self, reason: str, offset: int | None = None) -> LogError:
        """A :class:`LogError` about this file (``offset``: the byte of the record at fault)."""
        return LogError(reason, file=self.path, offset=offset)

    def run(self) -> McapScan:
        """Walk the whole file; returns the scan."""
        for _ in self.walk():
            pass
        return self

    def check(self) -> dict[int, int]:
        """Walk the whole file, decoding the messages gathered from each record at once and dropping them:
        every message of a type gyroemu decodes is validated (:class:`LogError` as :meth:`decode` raises
        it) in the memory of one chunk, or of :data:`LOOSE_BATCH` messages outside chunks a channel. Returns,
        per channel id, the messages decoded."""
        counts: dict[int, int] = {}

        def drop(every: bool) -> None:
            for channel_id, data in self.data.items():
                if data.mtype is not None and (data.payload or len(data.loose) >= (1 if every else LOOSE_BATCH)):
                    decoded = _decode_channel(self.path, data, data.mtype)
                    counts[channel_id] = counts.get(channel_id, 0) + len(decoded.log_time)
                    for held in (data.order, data.header, data.payload, data.loose):
                        held.clear()

        for _ in self.walk():
            drop(every=False)
        drop(every=True)
        return counts

    def decode(self) -> dict[int, DecodedChannel]:
        """Channel id -> the channel's gathered messages decoded, for every channel of a type gyroemu
        decodes that has messages (:class:`LogError` for a message its type cannot decode)."""
        decoded: dict[int, DecodedChannel] = {}
        for channel_id, data in self.data.items():
            if data.mtype is not None and (data.payload or data.loose):
                decoded[channel_id] = _decode_channel(self.path, data, data.mtype)
        return decoded

    def channel_info(self) -> list[ChannelInfo]:
        """The channels found, with their schemas, in file order."""
        out = []
        for c in self.channels.values():
            schema = self.schemas.get(c.schema_id)
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

    def walk(self) -> Iterator[int]:
        """Read the file record by record (chunks decompressed and handled whole), yielding after each."""
        try:
            f = open(self.path, "rb")
        except IsADirectoryError:
            raise self.error(folder_not_mcap(self.path)) from None
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
                except McapError as e:  # mcap's record parsers: a field runs past the record (EndOfFile)
                    reason = str(e) or "a field runs past the end of the record"
                    raise self.error(
                        f"corrupt {_opcode_name(opcode)} record at byte {position}: {reason}", position
                    ) from None
                except (ValueError, struct.error, UnicodeDecodeError, IndexError, KeyError) as e:
                    raise self.error(
                        f"corrupt {_opcode_name(opcode)} record at byte {position}: {e}", position
                    ) from None
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
        elif opcode == Opcode.CHUNK_INDEX:
            self.chunk_indexes += 1
        elif opcode == Opcode.FOOTER:
            self.summary = Footer.read(ReadDataStream(BytesIO(content))).summary_start != 0

    def _channel(self, channel: Channel) -> None:
        """Register a channel (once: the summary repeats them) and decide whether to decode it."""
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        mtype, reason = decoded_type(channel, self.schemas.get(channel.schema_id))
        if reason:
            self.skipped[channel.topic] = reason
        self.data[channel.id] = ChannelData(channel, mtype=mtype)

    def _loose_fields(self, content: bytes) -> tuple[NDArray[np.void], int]:
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
                data = _zstd_decompress(packed, usize)
            elif compression == "lz4":
                try:
                    import lz4.frame
                except ImportError:
                    raise self.error(
                        f"chunk at byte {position}: lz4 compression needs the lz4 package (pip install lz4)", position
                    ) from None
                data = lz4.frame.decompress(packed)
            elif compression == "":
                data = bytes(packed)
            else:
                raise self.error(f"chunk at byte {position}: unknown compression {compression!r}", position)
        except LogError:
            raise
        except (zstandard.ZstdError, ValueError, RuntimeError) as e:  # lz4 raises RuntimeError
            raise self.error(f"corrupt chunk at byte {position}: {e}", position) from None
        if len(data) != usize:
            raise self.error(
                f"corrupt chunk at byte {position}: {len(data)} bytes after decompression, {usize} declared", position
            )
        if crc and zlib.crc32(data) != crc:
            raise self.error(f"corrupt chunk at byte {position}: CRC mismatch", position)
        self._chunk_records(data, position)
        self.chunks += 1

    def _chunk_records(self, data: bytes, position: int) -> None:
        """Read the Schema and Channel records of a decompressed chunk, then hand its Message records'
        fixed fields (``header``), starts and lengths to :meth:`_chunk_messages`."""
        buffer = np.frombuffer(data, dtype=np.uint8)
        try:
            starts, opcodes, lengths = _record_positions(data, buffer)
        except ValueError as e:
            raise self.error(f"corrupt chunk at byte {position}: {e}", position) from None
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
            raise self.error(
                f"corrupt chunk at byte {position}: a Message record shorter than its fixed fields", position
            )
        header = _gather(buffer, starts + 9, 22).view(_MESSAGE_FIELDS)[:, 0]
        self._chunk_messages(data, buffer, header, starts, lengths, position)

    def _chunk_messages(
        self,
        data: bytes,
        buffer: NDArray[np.uint8],
        header: NDArray[np.void],
        starts: NDArray[np.int64],
        lengths: NDArray[np.int64],
        position: int,
    ) -> None:
        """Gather each wanted channel's payloads, in bulk."""
        ordinal = self.message_count + np.arange(len(starts))
        self.message_count += len(starts)
        channel_ids = header["channel_id"]
        for channel_id in np.unique(channel_ids):
            target = self.data.get(int(channel_id))
            if target is None:
                raise self.error(
                    f"corrupt chunk at byte {position}: a message on channel {int(channel_id)}, "
                    "which no Channel record defines",
                    position,
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


_ZSTD_PIECE = 1 << 20
"""Bytes a Chunk's zstd stream is read in: what is held never exceeds what the data decompress to."""


def _zstd_decompress(packed: memoryview, usize: int) -> bytes:
    """A chunk's records from their zstd frame, read piece by piece and never more than ``usize`` + 1 bytes.

    Neither the chunk's declared size ``usize`` nor the frame's own content size is trusted to size a
    buffer (a corrupt length would ask for GBs): memory follows the data actually decompressed. A frame
    that declares a size other than ``usize`` is corrupt (``ValueError``); the caller checks the length.
    """
    declared = zstandard.get_frame_parameters(packed).content_size  # ZstdError for a corrupt frame header
    if declared != zstandard.CONTENTSIZE_UNKNOWN and declared != usize:
        raise ValueError(f"its zstd frame declares {declared} bytes, the chunk {usize}")
    pieces, total = [], 0
    with zstandard.ZstdDecompressor().stream_reader(packed, read_across_frames=True) as reader:
        while total <= usize:
            piece = reader.read(min(_ZSTD_PIECE, usize + 1 - total))
            if not piece:
                break
            pieces.append(piece)
            total += len(piece)
    return b"".join(pieces)


_WALK = 256
"""Records :func:`_record_positions` walks in Python before it looks for a period: enough to see twice
a period of up to 128 records (a 1 kHz sample's five channels with a /tf every tenth sample: 51)."""


def _period(ops: list[int], lens: list[int]) -> int | None:
    """The period of the records just walked: the smallest k for which the whole window repeats every k
    records, else the smallest k <= 8 for which its last 2k records do (a run that has just begun)."""
    n = len(lens)
    if n >= 4:
        op, ln = np.array(ops), np.array(lens)
        for k in range(1, n // 2 + 1):
            if np.array_equal(ln[k:], ln[:-k]) and np.array_equal(op[k:], op[:-k]):
                return k
    return next(
        (k for k in range(1, 9) if 2 * k <= n and lens[-k:] == lens[-2 * k : -k] and ops[-k:] == ops[-2 * k : -k]),
        None,
    )


def _record_positions(
    data: bytes, buffer: NDArray[np.uint8]
) -> tuple[NDArray[np.int64], NDArray[np.uint8], NDArray[np.int64]]:
    """Start offset, opcode and content length of every record in a decompressed chunk.

    Records follow each other (opcode u8, length u64, content), so finding them is a walk. It runs in
    Python over up to :data:`_WALK` records, until those repeat a pattern (a sample's group of channels,
    with the thinned /tf's record where it falls: the same opcodes and lengths every P records, B bytes);
    then it predicts the following records' positions a whole array at a time and checks each predicted
    opcode and length. Every checked record proves where the next one starts, so the accepted run is
    exact; the walk resumes after the first mismatch.
    """
    unpack = _RECORD_HEAD.unpack_from
    size = len(data)
    starts, opcodes, lengths = [], [], []
    p = 0
    while p < size:
        walked_p: list[int] = []
        walked_op: list[int] = []
        walked_len: list[int] = []
        while len(walked_p) < _WALK and p < size:
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
        period = _period(walked_op, walked_len)
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


def _gather(buffer: NDArray[np.uint8], starts: NDArray[np.int64], width: int) -> NDArray[np.uint8]:
    """Rows ``buffer[s:s + width]`` for each start ``s``: (M, width) uint8, a copy. Indexing the rows of
    a sliding-window view copies each row whole (25 times faster than a gather of M × width bytes)."""
    if len(starts) == 0:
        return np.empty((0, width), np.uint8)
    return _windows(buffer, width, writeable=False)[starts]


def _windows(buffer: NDArray[np.uint8], width: int, *, writeable: bool) -> NDArray[np.uint8]:
    """The (n − width + 1, width) view of every run of ``width`` bytes of the 1-D ``buffer``: numpy's
    ``sliding_window_view`` without its checks, which cost 40 µs a call (a third of reading a small
    chunk; 170,000 calls for a log of 20,000 chunks)."""
    (step,) = buffer.strides
    rows = max(len(buffer) - width + 1, 0)
    return np.lib.stride_tricks.as_strided(buffer, (rows, width), (step, step), writeable=writeable)


def folder_not_mcap(folder: Path) -> str:
    """Why a folder given as a log is none, in words: a rosbag2 bag folder names the MCAP files it holds."""
    inside = sorted(p.name for p in folder.glob("*.mcap")) if folder.is_dir() else []
    if (folder / "metadata.yaml").is_file() and inside:
        files = ", ".join(inside[:3]) + (", ..." if len(inside) > 3 else "")
        return f"is a rosbag2 bag folder, not an MCAP file: give the file it holds ({files}), one at a time"
    return "is a folder, not an MCAP file"


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.title().replace("_", " ")
    except ValueError:
        return f"opcode 0x{opcode:02x}"


def _decode_channel(path: Path, data: ChannelData, mtype: MessageType) -> DecodedChannel:
    """All messages of a channel, decoded, in log-time order (file order for equal times)."""
    orders, headers, batches = [], [], []
    by_width: dict[int, list[tuple[NDArray[np.int64], NDArray[np.void], NDArray[np.uint8]]]] = {}
    payload: NDArray[np.uint8] | bytes  # a block's rows, then a loose message's bytes
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
            raise LogError(f"topic {data.channel.topic}: corrupt {mtype.name} message: {e}", file=path) from None
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
    return DecodedChannel(topic=data.channel.topic, mtype=mtype, log_time=log_time, batch=batch)


# -- message by message, in log-time order (replay) -------------------------------------------------


class McapMessage(NamedTuple):
    """One message as recorded: its channel's topic and schema name, ``log_time`` (ns), payload bytes."""

    topic: str
    schema: str
    log_time: int
    data: bytes


class _MessageWalk(McapScan):
    """A :class:`McapScan` that hands out each record's messages (of the wanted topics) instead of gathering
    channel arrays; Schema and Channel records are registered as the scan does."""

    def __init__(self, path: Path, topics: Iterable[str] | None = None) -> None:
        super().__init__(path)
        self.topics = None if topics is None else frozenset(topics)
        self.out: list[McapMessage] = []
        self.wanted: dict[int, tuple[str, str] | None] = {}  # channel id -> (topic, schema name) or None

    def _channel(self, channel: Channel) -> None:
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        self.data[channel.id] = ChannelData(channel)  # mtype None: nothing gathered
        schema = self.schemas.get(channel.schema_id)
        keep = self.topics is None or channel.topic in self.topics
        self.wanted[channel.id] = (channel.topic, schema.name if schema is not None else "") if keep else None

    def _loose_message(self, content: bytes) -> None:
        fields, channel_id = self._loose_fields(content)
        self.message_count += 1
        wanted = self.wanted[channel_id]
        if wanted is not None:
            self.out.append(McapMessage(wanted[0], wanted[1], int(fields["log_time"][0]), bytes(content[22:])))

    def _chunk_messages(
        self,
        data: bytes,
        buffer: NDArray[np.uint8],
        header: NDArray[np.void],
        starts: NDArray[np.int64],
        lengths: NDArray[np.int64],
        position: int,
    ) -> None:
        """Hand out each wanted message as its own :class:`McapMessage`, in file order."""
        self.message_count += len(starts)
        unknown = [int(c) for c in np.unique(header["channel_id"]) if int(c) not in self.wanted]
        if unknown:
            raise self.error(
                f"corrupt chunk at byte {position}: a message on channel {unknown[0]}, which no Channel record defines",
                position,
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


def iter_mcap_batches(path: str | os.PathLike[str], topics: Iterable[str] | None = None) -> Iterator[list[McapMessage]]:
    """The messages of an MCAP file (of ``topics`` only, when given), in log-time order, a batch per chunk.

    The file is read record by record (one decompressed chunk in memory at a time, plus what is held
    back for ordering): each chunk's messages are sorted by log time (stable: file order for equal
    times) and merged with those held back; the messages earlier than the start of the chunk just
    read are handed out. So files whose chunks start in time order (what writers that log as they go
    produce; gyroemu's chunks do not even overlap) come out in exact log-time order with one chunk of
    look-ahead. A file cut short ends with the messages of its complete chunks. Raises
    :class:`LogError` (naming the file) for a file that is not MCAP or is corrupt.
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
    metadata: dict[str, str]


def mcap_channel_info(path: str | os.PathLike[str]) -> list[ChannelInfo]:
    """Every channel of an MCAP file with its schema record and metadata, in file order (a pass that
    decodes no message; :attr:`gyroemu.pipelines.formats.mcap_log.McapLog.channels` holds the same). Raises
    :class:`LogError` for a file that is not MCAP or is corrupt."""
    return _MessageWalk(Path(path), topics=()).run().channel_info()


# -- every message record as found (copying a file) -------------------------------------------------


class RawMessages(NamedTuple):
    """The Message records of one chunk (or one record outside chunks), in file order, fields as found.

    Message k's payload is ``buffer[start[k] : start[k] + size[k]]``
    (:meth:`McapFileWriter.add_raw_messages` takes the same arrays).
    """

    channel_id: NDArray[np.uint16]  # (M,)
    sequence: NDArray[np.uint32]  # (M,)
    log_time: NDArray[np.uint64]  # (M,)
    publish_time: NDArray[np.uint64]  # (M,)
    buffer: NDArray[np.uint8]
    start: NDArray[np.int64]  # (M,)
    size: NDArray[np.int64]  # (M,)

    def payload(self, k: int) -> bytes:
        """Message k's payload bytes."""
        return self.buffer[int(self.start[k]) : int(self.start[k] + self.size[k])].tobytes()

    def payloads(self, index: NDArray[np.intp]) -> NDArray[np.uint8] | list[bytes]:
        """The payloads of messages ``index`` (m,), as :meth:`MessageType.decode` takes them: one (m, size)
        uint8 array when they are all of one size (a copy, row by row from a window view of the buffer),
        else a list of bytes."""
        size = self.size[index]
        if not len(size) or not np.all(size == size[0]):
            return [self.payload(int(k)) for k in index]
        return _rows(self.buffer, int(size[0]))[self.start[index]]

    @classmethod
    def from_headers(
        cls, headers: NDArray[np.void], buffer: NDArray[np.uint8], start: ArrayLike, size: ArrayLike
    ) -> RawMessages:
        """The messages whose 22-byte headers are ``headers`` (fields ``channel_id``, ``sequence``,
        ``log_time``, ``publish_time``), their payloads at ``start`` (M,) of ``size`` (M,) in ``buffer``."""
        return cls(
            headers["channel_id"].astype(np.uint16),
            headers["sequence"].astype(np.uint32),
            headers["log_time"].astype(np.uint64),
            headers["publish_time"].astype(np.uint64),
            buffer,
            np.asarray(start, dtype=np.int64),
            np.asarray(size, dtype=np.int64),
        )


class McapRecordWalk(McapScan):
    """A :class:`McapScan` that hands out every Message record unchanged, a :class:`RawMessages` per chunk
    (:meth:`batches`), for copying a file; nothing is decoded. :attr:`schemas`, :attr:`channels` and
    :attr:`metadata` grow as their records are read: a batch's channels are known when it is handed out.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(Path(path))
        self.out: list[RawMessages] = []
        self._loose: list[tuple[NDArray[np.void], bytes]] = []  # messages outside chunks, not yet handed out

    def _channel(self, channel: Channel) -> None:
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        self.data[channel.id] = ChannelData(channel)  # mtype None: nothing gathered

    def _loose_message(self, content: bytes) -> None:
        fields, _ = self._loose_fields(content)
        self.message_count += 1
        self._loose.append((fields, content))
        if len(self._loose) >= LOOSE_BATCH:
            self._hand_out_loose()

    def _hand_out_loose(self) -> None:
        """The messages read outside chunks since the last batch, as one batch (file order)."""
        if not self._loose:
            return
        held, self._loose = self._loose, []
        size = np.array([len(content) for _, content in held], dtype=np.int64)
        buffer = np.frombuffer(b"".join(content for _, content in held), dtype=np.uint8)
        start = np.concatenate(([0], np.cumsum(size)[:-1])) + 22
        self.out.append(RawMessages.from_headers(np.concatenate([f for f, _ in held]), buffer, start, size - 22))

    def _chunk_messages(
        self,
        data: bytes,
        buffer: NDArray[np.uint8],
        header: NDArray[np.void],
        starts: NDArray[np.int64],
        lengths: NDArray[np.int64],
        position: int,
    ) -> None:
        self._hand_out_loose()  # messages before this chunk come first
        self.message_count += len(starts)
        unknown = [int(c) for c in np.unique(header["channel_id"]) if int(c) not in self.channels]
        if unknown:
            raise self.error(
                f"corrupt chunk at byte {position}: a message on channel {unknown[0]}, which no Channel record defines",
                position,
            )
        self.out.append(RawMessages.from_headers(header, buffer, starts + 9 + 22, lengths - 22))

    def batches(self) -> Iterator[RawMessages]:
        """Walk the file (:meth:`McapScan.walk`), handing out its Message records as they are read: a
        chunk's at a time, and messages outside chunks (an unchunked file) :data:`LOOSE_BATCH` at a time
        (one at a time, the copy cost 0.35 ms a message)."""
        for _ in self.walk():
            if self.out:
                batches, self.out = self.out, []
                yield from batches
        self._hand_out_loose()
        yield from self.out
        self.out = []
