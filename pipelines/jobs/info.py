"""``gyroemu info``: what an MCAP log holds, devices and topics, with counts, rates and gaps.

:func:`log_info` gathers it into a :class:`LogInfo`, which prints itself as text (:meth:`LogInfo.text`)
or as a JSON-ready dict (:meth:`LogInfo.to_dict`). The devices come from
:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` (with its warnings: a truncated file, skipped
topics). The per-topic figures come from :func:`topic_stats`, a second pass over the file's Message
records that reads their log times only (no payload is decoded) and keeps, per topic, a fixed-size
summary instead of the stamps, so its memory does not grow with the log's length.

Per topic: the message count, the first and last log time, the mean rate ``(count - 1) / span``, the
median interval between consecutive messages, and the gaps: intervals longer than 1.5 times the
median, counted, with the longest. Intervals are kept as a histogram of bins 2^(1/1024) wide (0.07 %),
each with its count and the sum of its intervals: the median is the mean of its bin (exact when the
intervals of that bin are equal, as in a log of a fixed rate; within 0.07 % otherwise), a bin counts
as gaps when its mean exceeds the threshold, and the longest gap is exact. Each chunk's messages of a
topic are taken in log-time order; a chunk whose first message of a topic is earlier than the
previous chunk's last is counted in ``out_of_order`` (that one interval is not counted).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.channels import IMU_ROLE
from gyroemu.pipelines.formats.messages import MessageType

if TYPE_CHECKING:
    from gyroemu.pipelines.formats.mcap_records import RawMessages

__all__ = ["GAP_FACTOR", "InfoError", "TopicStats", "DeviceInfo", "LogInfo", "check_plot", "topic_stats", "log_info"]

GAP_FACTOR = 1.5
"""An interval longer than this many median intervals is a gap."""

_BINS_PER_OCTAVE = 1024


class InfoError(ConfigError):
    """Bad options of ``gyroemu info`` (the message names the argument)."""


def check_plot(path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """The picture ``gyroemu info --plot`` draws of the log ``path`` (``LOG.info.png``, beside it), checked
    before any work: :class:`InfoError` naming ``--plot`` when its folder cannot take it (read-only, not
    writable), it is a folder or the log itself, or it exists and ``force`` is not given."""
    from gyroemu.pipelines.formats.atomic import output_file_problem
    from gyroemu.pipelines.jobs.plots import info_plot_path

    path = Path(path)
    picture = info_plot_path(path)
    if not picture.parent.is_dir():
        return picture  # no log there either: reading it says so, naming it
    problem = output_file_problem(picture, force=force, inputs=(path,))
    if problem is not None:
        raise InfoError(f"argument --plot: {problem}")
    return picture


def _finite(value: float | None) -> float | None:
    """``value``, or None when it is None or not finite (JSON has no NaN)."""
    return value if value is not None and math.isfinite(value) else None


@dataclass
class TopicStats:
    """One topic's messages, from their log times.

    Attributes
    ----------
    topic : str
    schema : str
        The channel's schema name ('' without one).
    count : int
        Messages.
    first_ns, last_ns : int or None
        Earliest and latest log time, ns (None without messages).
    median_interval_s : float or None
        Median interval between consecutive messages (None with fewer than two).
    gaps : int
        Intervals longer than :data:`GAP_FACTOR` times the median.
    longest_gap_s : float or None
        The longest of those (None without gaps).
    out_of_order : int
        Chunks whose messages of this topic start before the previous chunk's end.
    """

    topic: str
    schema: str
    count: int
    first_ns: int | None
    last_ns: int | None
    median_interval_s: float | None
    gaps: int
    longest_gap_s: float | None
    out_of_order: int = 0

    @property
    def span_s(self) -> float:
        """Seconds from the first message to the last (0 with fewer than two)."""
        return 0.0 if self.first_ns is None or self.last_ns is None else (self.last_ns - self.first_ns) * 1e-9

    @property
    def rate_hz(self) -> float:
        """Mean rate ``(count - 1) / span``, Hz; NaN when the span is 0."""
        span = self.span_s
        return (self.count - 1) / span if span > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """The figures as JSON-ready values (None for what is undefined).

        Returns
        -------
        dict
        """
        return {
            "topic": self.topic,
            "schema": self.schema,
            "count": self.count,
            "first_stamp_s": None if self.first_ns is None else self.first_ns * 1e-9,
            "last_stamp_s": None if self.last_ns is None else self.last_ns * 1e-9,
            "span_s": self.span_s,
            "rate_hz": _finite(self.rate_hz),
            "median_interval_s": self.median_interval_s,
            "gaps": self.gaps,
            "longest_gap_s": self.longest_gap_s,
            "out_of_order": self.out_of_order,
        }

    def text(self) -> str:
        """One line: count, stamps, rate and gaps.

        Returns
        -------
        str
        """
        if self.first_ns is None or self.last_ns is None:
            return f"{self.topic:<28} no messages"
        gaps = "no gaps" if not self.gaps else f"{self.gaps} gaps (longest {self.longest_gap_s:.6g} s)"
        order = f", {self.out_of_order} chunks out of order" if self.out_of_order else ""
        if self.first_ns >= _ABSOLUTE_NS:  # a date: ISO 8601 and the span
            from gyroemu.pipelines.formats.frames import format_stamp

            stamps = f"from {format_stamp(self.first_ns)} for {(self.last_ns - self.first_ns) * 1e-9:.6g} s"
        else:
            stamps = f"{self.first_ns * 1e-9:.6g} to {self.last_ns * 1e-9:.6g} s"
        rate = f" ({self.rate_hz:.6g} Hz)" if self.count > 1 else ""
        return f"{self.topic:<28} {self.count} messages, {stamps}{rate}, {gaps}{order}"


_ABSOLUTE_NS = 365 * 86_400 * 1_000_000_000
"""Log times from a year after the Unix epoch on are dates (absolute stamps), printed as ISO 8601;
earlier ones are times since a start (logs written before stamps were absolute)."""


class _Intervals:
    """Count, first and last log time, and a histogram of the intervals of one channel's messages."""

    def __init__(self) -> None:
        self.count = 0
        self.first: int | None = None
        self.last: int | None = None
        self.previous: int | None = None
        self.out_of_order = 0
        self.longest = 0
        self.bins: np.ndarray = np.empty(0, np.int64)
        self.counts: np.ndarray = np.empty(0, np.int64)
        self.sums: np.ndarray = np.empty(0, np.float64)

    def add(self, times: np.ndarray) -> None:
        """Take the next chunk's log times (ns, uint64) of the channel."""
        if not len(times):
            return
        if len(times) > 1 and np.any(times[1:] < times[:-1]):
            times = np.sort(times)
        head, tail = int(times[0]), int(times[-1])
        self.count += len(times)
        self.first = head if self.first is None else min(self.first, head)
        self.last = tail if self.last is None else max(self.last, tail)
        steps = np.diff(times)
        if self.previous is not None:
            if head >= self.previous:
                steps = np.concatenate((np.array([head - self.previous], np.uint64), steps))
            else:
                self.out_of_order += 1
        self.previous = tail
        if not len(steps):
            return
        self.longest = max(self.longest, int(steps.max()))
        nanoseconds = steps.astype(np.float64)  # exact below 2**53 ns (104 days)
        bins = np.zeros(len(steps), np.int64)
        positive = steps > 0
        bins[positive] = np.floor(np.log2(nanoseconds[positive]) * _BINS_PER_OCTAVE).astype(np.int64) + 1
        self._merge(bins, np.ones(len(steps), np.int64), nanoseconds)

    def _merge(self, bins: np.ndarray, counts: np.ndarray, sums: np.ndarray) -> None:
        keys, inverse = np.unique(np.concatenate((self.bins, bins)), return_inverse=True)
        self.counts = np.bincount(inverse, weights=np.concatenate((self.counts, counts)), minlength=len(keys)).astype(
            np.int64
        )
        self.sums = np.bincount(inverse, weights=np.concatenate((self.sums, sums)), minlength=len(keys))
        self.bins = keys

    def stats(self, topic: str, schema: str) -> TopicStats:
        """The figures of :class:`TopicStats`."""
        total = int(self.counts.sum())
        if not total:
            return TopicStats(topic, schema, self.count, self.first, self.last, None, 0, None, self.out_of_order)
        mean = self.sums / self.counts
        cumulative = np.cumsum(self.counts)
        lower = mean[np.searchsorted(cumulative, (total - 1) // 2, side="right")]
        upper = mean[np.searchsorted(cumulative, total // 2, side="right")]
        median = 0.5 * (lower + upper)
        gaps = int(self.counts[mean > GAP_FACTOR * median].sum())
        return TopicStats(
            topic,
            schema,
            self.count,
            self.first,
            self.last,
            median * 1e-9,
            gaps,
            self.longest * 1e-9 if gaps else None,
            self.out_of_order,
        )


def topic_stats(path: str | os.PathLike[str]) -> list[TopicStats]:
    """Count, stamps, rate and gaps of every topic of an MCAP file, from the log times of its Message
    records (see the module's notes), in the order of the file's channels.

    Parameters
    ----------
    path : str or path-like
        An MCAP file (read only; a truncated one gives its complete chunks).

    Returns
    -------
    list of TopicStats
        One per channel, also for channels without messages.

    Raises
    ------
    LogError
        The file is not MCAP or is corrupt.
    """
    return _LogWalk(Path(path), imu_channels=False).run().topic_stats()


class _HeaderStamps:
    """A channel's message count and the header stamps of its earliest and latest message by log time."""

    def __init__(self) -> None:
        self.count = 0
        self.first: tuple[int, int] | None = None  # (log time, stamp), ns
        self.last: tuple[int, int] | None = None

    def add(self, log_time: np.ndarray, stamp_ns: np.ndarray) -> None:
        self.count += len(log_time)
        if not len(log_time):
            return
        lo, hi = int(np.argmin(log_time)), int(np.argmax(log_time[::-1]))
        hi = len(log_time) - 1 - hi  # the last of the latest (file order breaks ties, as a stable sort)
        low = (int(log_time[lo]), int(stamp_ns[lo]))
        high = (int(log_time[hi]), int(stamp_ns[hi]))
        if self.first is None or low[0] < self.first[0]:
            self.first = low
        if self.last is None or high[0] >= self.last[0]:
            self.last = high


@dataclass
class _ChannelSummary:
    """What :func:`~gyroemu.pipelines.formats.mcap_log.group_devices` needs of a channel, and its stamps."""

    topic: str
    mtype: MessageType
    stamps: _HeaderStamps


class _LogWalk:
    """One pass over an MCAP file's records: the log times of every channel (:func:`topic_stats`) and,
    with ``imu_channels``, the header stamps of the ``sensor_msgs/msg/Imu`` channels' messages, read
    from the payloads without decoding them (CDR: a 4-byte encapsulation header, then the message's
    ``std_msgs/Header``, whose stamp is an int32 of seconds and a uint32 of nanoseconds)."""

    def __init__(self, path: Path, imu_channels: bool = True) -> None:
        from gyroemu.pipelines.formats.mcap_records import McapRecordWalk

        self.path = path
        self.walk = McapRecordWalk(path)
        self.imu_channels = imu_channels
        self.intervals: dict[int, _Intervals] = {}
        self.stamps: dict[int, _HeaderStamps] = {}

    def run(self) -> _LogWalk:
        for batch in self.walk.batches():
            channel = batch.channel_id.astype(np.int64)
            times = batch.log_time.astype(np.uint64)
            if self.imu_channels:
                self._imu_stamps(batch, channel)
            if len(channel) and np.all(channel == channel[0]):
                self.intervals.setdefault(int(channel[0]), _Intervals()).add(times)
                continue
            order = np.argsort(channel, kind="stable")
            channel, times = channel[order], times[order]
            cuts = np.flatnonzero(np.diff(channel)) + 1
            for ids, group in zip(np.split(channel, cuts), np.split(times, cuts)):
                self.intervals.setdefault(int(ids[0]), _Intervals()).add(group)
        return self

    def _imu_stamps(self, batch: RawMessages, channel: np.ndarray) -> None:
        from gyroemu.pipelines.formats.mcap_records import decoded_type
        from gyroemu.pipelines.formats.messages import IMU, not_cdr

        for channel_id in np.unique(channel):
            record = self.walk.channels[int(channel_id)]
            mtype, _ = decoded_type(record, self.walk.schemas.get(record.schema_id))
            if mtype is not IMU:
                continue
            mine = channel == channel_id
            start, size = batch.start[mine], batch.size[mine]
            if np.any(size < 12):
                raise self.walk.error(f"a message on {record.topic} is too short for its header")
            head = batch.buffer[start[:, None] + np.arange(12)]
            plain = (head[:, 0] == 0) & (head[:, 1] <= 1)  # encapsulation CDR_LE (0x0001) or CDR_BE (0x0000)
            if not plain.all():  # a compressed or foreign payload: its stamp is no stamp
                k = int(np.flatnonzero(~plain)[0])
                raise self.walk.error(f"topic {record.topic}: a message {not_cdr(bytes(head[k, :4]))}")
            little = head[:, 1] == 1
            words = np.ascontiguousarray(head[:, 4:12])
            sec = np.where(little, words[:, :4].view("<i4")[:, 0], words[:, :4].view(">i4")[:, 0]).astype(np.int64)
            nsec = np.where(little, words[:, 4:].view("<u4")[:, 0], words[:, 4:].view(">u4")[:, 0]).astype(np.int64)
            self.stamps.setdefault(int(channel_id), _HeaderStamps()).add(
                batch.log_time[mine].astype(np.int64), sec * 1_000_000_000 + nsec
            )

    def topic_stats(self) -> list[TopicStats]:
        out = []
        for channel_id, record in self.walk.channels.items():
            schema = self.walk.schemas.get(record.schema_id)
            stats = self.intervals.get(channel_id, _Intervals())
            out.append(stats.stats(record.topic, schema.name if schema else ""))
        return out


@dataclass
class DeviceInfo:
    """A device of the log, as :func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` finds it.

    Attributes
    ----------
    name : str
    samples : int
        Its measured samples.
    span_s : float
        Seconds from the first sample to the last.
    rate_hz : float
        ``(samples - 1) / span`` (NaN when the span is 0).
    topics : dict of str to str
        Role (``imu``, ``truth``, ...) to topic.
    metadata : dict or None
        Its ``gyroemu`` metadata record.
    """

    name: str
    samples: int
    span_s: float
    rate_hz: float
    topics: dict[str, str]
    metadata: dict[str, Any] | None = None


@dataclass
class LogInfo:
    """What :func:`log_info` found.

    Attributes
    ----------
    path : Path
    size_bytes : int
    profile : str
        The MCAP header's profile.
    message_count : int
        Messages read (every channel).
    truncated : bool
        The file ends before its footer: only complete chunks were read.
    summary, indexed : bool
        The file has a summary section; its chunks are indexed there (every chunk a chunk index, and
        chunks to index).
    devices : list of DeviceInfo
    topics : list of TopicStats
        Every channel, from :func:`topic_stats`.
    skipped : dict of str to str
        Topics not decoded, with the reason.
    """

    path: Path
    size_bytes: int
    profile: str
    message_count: int
    truncated: bool
    summary: bool = True
    indexed: bool = True
    devices: list[DeviceInfo] = field(default_factory=list)
    topics: list[TopicStats] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

    def to_dict(self, configs: bool = False) -> dict[str, Any]:
        """The same content as :meth:`text`, as JSON-ready values.

        Parameters
        ----------
        configs : bool
            Keep the embedded ``scenario`` and ``device`` configs (TOML text) in each device's metadata.

        Returns
        -------
        dict
        """
        devices = []
        for d in self.devices:
            meta = None
            if d.metadata is not None:
                meta = {k: v for k, v in d.metadata.items() if configs or k not in ("scenario", "device")}
            devices.append(
                {
                    "name": d.name,
                    "samples": d.samples,
                    "span_s": d.span_s,
                    "rate_hz": _finite(d.rate_hz),
                    "topics": dict(d.topics),
                    "metadata": meta,
                }
            )
        return {
            "path": str(self.path),
            "format": "MCAP",
            "profile": self.profile,
            "size_bytes": self.size_bytes,
            "message_count": self.message_count,
            "truncated": self.truncated,
            "summary": self.summary,
            "indexed": self.indexed,
            "devices": devices,
            "topics": [t.to_dict() for t in self.topics],
            "skipped": dict(self.skipped),
        }

    def text(self, configs: bool = False) -> str:
        """The summary ``gyroemu info`` prints.

        Parameters
        ----------
        configs : bool
            Also print the embedded scenario and device configs.

        Returns
        -------
        str
        """
        if self.truncated:
            state = "TRUNCATED: only complete chunks were recovered"
        elif not self.summary:
            state = "complete, without a summary or indexes"
        else:
            state = "complete (summary and indexes)" if self.indexed else "complete (summary, no chunk indexes)"
        lines = [
            f"{self.path}: MCAP, profile '{self.profile}', {self.size_bytes / 1e6:.3g} MB, "
            f"{self.message_count} messages, {state}"
        ]
        for dev in self.devices:
            lines.append(f"  device '{dev.name}': {dev.samples} samples over {dev.span_s:.6g} s ({dev.rate_hz:.6g} Hz)")
            for role, topic in dev.topics.items():
                lines.append(f"    {topic:<28} {role}")
            meta = dev.metadata
            if meta:
                seed = meta.get("seed", "?")
                lines.append(f"    gyroemu {meta.get('version', '?')}" + (f", seed {seed}" if seed else ""))
                if meta.get("source"):
                    lines.append(f"    imported from {meta['source']} ({meta.get('source_format', '?')})")
                    if meta.get("citation"):
                        licence = f" ({meta['license']})" if meta.get("license") else ""
                        lines.append(f"    cite: {meta['citation']}{licence}")
                if configs:
                    for key in ("scenario", "device"):
                        if meta.get(key):
                            lines.append(f"    --- {key} ---")
                            lines.extend("    " + line for line in meta[key].splitlines())
        if self.topics:
            lines.append("  topics (log times):")
            lines.extend(f"    {t.text()}" for t in self.topics)
        for topic, why in self.skipped.items():
            lines.append(f"  skipped {topic}: {why}")
        return "\n".join(lines)


def log_info(path: str | os.PathLike[str]) -> LogInfo:
    """Devices and per-topic figures of an MCAP log, in one pass over its records in bounded memory.

    The devices are grouped as :func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` groups them, from
    the channels alone; a device's samples are its measured Imu topic's messages and its span that of
    their header stamps (read from the payloads, nothing else decoded). Unlike :func:`read_mcap`, no
    sample is dropped for lacking a raw observable at its stamp.

    Parameters
    ----------
    path : str or path-like
        The log (read only).

    Returns
    -------
    LogInfo

    Raises
    ------
    LogError
        The file cannot be opened, is not MCAP, is corrupt, or holds no IMU messages.

    Warns
    -----
    LogWarning
        As :func:`read_mcap`: a truncated file, skipped topics.
    """
    from gyroemu.pipelines.formats.mcap_log import announce_scan, device_name, group_devices, no_imu_error
    from gyroemu.pipelines.formats.mcap_records import decoded_type
    from gyroemu.pipelines.formats.messages import IMU, ns_to_stamps

    path = Path(path)
    walked = _LogWalk(path).run()
    scan = walked.walk
    channels = []
    for channel_id, record in scan.channels.items():
        mtype, reason = decoded_type(record, scan.schemas.get(record.schema_id))
        if reason:
            scan.skipped[record.topic] = reason
        elif channel_id in walked.intervals:  # a channel with messages, as read_mcap decodes them
            assert mtype is not None  # decoded_type gives a type where it gives no reason
            channels.append(_ChannelSummary(record.topic, mtype, walked.stamps.get(channel_id, _HeaderStamps())))
    skipped = announce_scan(path, scan)
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    devices: dict[str, DeviceInfo] = {}
    for prefix, group in group_devices(path, channels, skipped).items():
        measured = group[IMU_ROLE]
        stamps = measured.stamps
        if measured.mtype is not IMU or not stamps.count or stamps.first is None or stamps.last is None:
            continue
        name, meta = device_name(prefix, metadata)
        first, last = ns_to_stamps(np.array([stamps.first[1], stamps.last[1]], dtype=np.int64))
        span = float(last - first) if stamps.count > 1 else 0.0
        rate = (stamps.count - 1) / span if span > 0 else float("nan")
        devices[name] = DeviceInfo(name, stamps.count, span, rate, {r: c.topic for r, c in group.items()}, meta)
    if not devices:
        raise no_imu_error(scan, path)
    return LogInfo(
        path=path,
        size_bytes=path.stat().st_size,
        profile=scan.profile,
        message_count=scan.message_count,
        truncated=scan.truncated_at is not None,
        summary=scan.summary,
        indexed=scan.summary and scan.chunks > 0 and scan.chunk_indexes >= scan.chunks,
        devices=list(devices.values()),
        topics=walked.topic_stats(),
        skipped=dict(skipped),
    )
