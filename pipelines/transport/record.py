"""``gyroemu record`` (zenoh -> MCAP) and ``gyroemu router`` (a zenoh router process).

Recording
---------
The recorder subscribes to ``gyroemu/**`` (FIFO channel handler), maps each key back to its device and
topic (:func:`~gyroemu.pipelines.transport.zenoh_io.key_to_topic`) and copies the payload bytes into an MCAP file
(profile
``ros2``, zstd chunks) without re-encoding: only the header stamp is read, and it becomes the message's
``log_time`` and ``publish_time``. Channels are registered per topic as they appear, with the schema the
topic's role names (:func:`gyroemu.pipelines.formats.channels.topic_message_type`: ``/imu`` and ``/truth/imu``:
``sensor_msgs/msg/Imu``, ``/mag``: MagneticField, ``/raw/<kind>``: the kind's raw type; an older
gyroemu's ``/raw/rate-gyro`` is recorded as ``/raw/rate_gyro``, :func:`gyroemu_key`). The first device's
topics are unprefixed (``/imu``), any further device's are prefixed (``/<device>/imu``); a ``gyroemu``
metadata record per device gives its name and prefix (:func:`~gyroemu.pipelines.formats.mcap_log.device_metadata`), so
:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` names it.

The file is written in place (not through a temporary name):
:class:`~gyroemu.pipelines.formats.mcap_records.McapFileWriter`
writes sequentially, and the recorder flushes after every batch, so a recorder killed with SIGKILL leaves
a file whose complete chunks read back (chunks of 256 KiB, so at most that much is lost).
SIGINT/SIGTERM (or ``--duration``) end the recording properly: the remaining messages, the summary and
indexes, the footer. The file is created when the first recorded key arrives: a recording that
receives nothing says so and leaves no file (an existing file given with ``--force`` stays as it was),
and an existing file is replaced only with ``--force`` (:attr:`RecordOptions.force`).

Each device's record also holds its resolved config (``device``, ``seed``, ``scenario``: what
``gyroemu stream`` announces on ``gyroemu/<device>/config``,
:class:`~gyroemu.pipelines.transport.zenoh_io.ConfigAnnouncer`), so ``read_mcap(...).device``, ``gyroemu
estimate`` and ``gyroemu bench --log`` start from the device's noise. When the recorder first sees a
device it ``get``s that key (the stream's queryable answers, however late the recorder started), and a
config put on the key is taken too (not recorded as a topic). The record is written when the config
comes, or after :attr:`Recorder.config_grace_s` (1 s) with name and prefix only (a publisher that is no
gyroemu stream); a config coming later still writes a complete record, which supersedes the first
(readers take a device's last record). The report says which devices got their config.

The tf tree (``/tf`` and ``/tf_static``: ``gyroemu/<device>/tf`` and ``.../tf_static`` from ``gyroemu
stream``, the global ROS 2 topics in ROS 2 mode) is the file's, not a device's: it goes to the
unprefixed ``tf2_msgs/msg/TFMessage`` channels ``/tf`` and ``/tf_static`` as ``gyroemu simulate`` writes
them (``/tf_static`` with the transient-local QoS metadata,
:data:`~gyroemu.pipelines.formats.mcap_log.TF_STATIC_QOS_PROFILES`), each message's time the stamp of
its first transform, so :func:`~gyroemu.pipelines.formats.mcap_log.read_tf` reads the tree back. A
``/tf_static`` message that repeats one already recorded, byte for byte (a stream re-publishes its
mounting every second for late joiners), is counted but not stored again.

Other topics (a replayed bag's ``/robot1/imu/data_raw``) only their publisher can type: when the
recorder first sees a device it also ``get``s ``gyroemu/<device>/@types``, which ``gyroemu replay``
answers with each of its keys' type name, schema encoding and schema text as the file has them
(:class:`~gyroemu.pipelines.transport.zenoh_io.TypesAnnouncer`, :mod:`gyroemu.pipelines.transport.replay`'s
notes). A topic the recorder cannot type holds its messages (in memory, counted as recorded) until that
answer comes, and its channel gets the announced schema; when the ``get`` is over without one for the key
(a live publisher that says nothing), or :attr:`Recorder.config_grace_s` after its first message, or at
the end, the channel is registered without a schema (``schema_id`` 0: gyroemu's readers skip it, and
rosbags cannot open such a file). The answer comes on zenoh's thread and is queued, as the config's
replies are, for the recording loop to take in (:meth:`Recorder.add_types`). In ROS 2 mode the key names
the type: the announced schema is taken for a type gyroemu does not know, when the names agree.

From each message's attachment (sequence number, publisher id) the recorder counts, per publisher,
messages received, sequence gaps (the exact missing numbers), duplicates and late (out-of-order)
arrivals, and prints the report at the end (``--report FILE.json`` also writes it as JSON; its ``file``
is null when nothing was recorded, so no log was written).

ROS 2 mode (``--ros2``)
-----------------------
The recorder subscribes to ``<domain>/**`` instead (the data keys of rmw_zenoh,
:mod:`gyroemu.pipelines.formats.ros2_keys`): a key ``<domain>/<device>/<rest>/<pkg::msg::dds_::T_>/<RIHS01 hash>``
is recorded on topic ``/<rest>`` of device ``<device>`` (so what ``gyroemu stream --ros2`` publishes
comes back on the topics of a plain recording: ROS 2's ``/<device>/raw/rate_gyro`` is ``/raw/rate_gyro``),
with the schema the key's type names when gyroemu knows the type, and the type hash in the channel's
``topic_type_hash`` metadata, as rosbag2 records it. Keys of topics with a single name token
(``/rosout``) have no device and are skipped (counted). The process appears in the ROS graph as node
``gyroemu_record_<pid>``, with a subscription token per topic it records.

From Python: ``run_record(RecordOptions(out_path=Path("run.mcap"), duration=10.0))``
(:class:`RecordOptions`) and ``run_router(SessionOptions(listen=("tcp/0.0.0.0:7447",)))``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
import zenoh

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.atomic import output_file_problem, write_text_atomic
from gyroemu.pipelines.formats.channels import canonical_topic, topic_message_type
from gyroemu.pipelines.formats.file_names import same_file
from gyroemu.pipelines.formats.frames import TF_STATIC_TOPIC, TF_TOPIC
from gyroemu.pipelines.formats.messages import MESSAGE_TYPES
from gyroemu.pipelines.formats.tf_messages import TF_MESSAGE_TYPE, tf_stamp_ns
from gyroemu.pipelines.transport.zenoh_io import (
    CONFIG_TOPIC,
    SessionOptions,
    TopicType,
    check_key_expr,
    config_fields,
    config_key,
    connect_warning,
    drain,
    header_stamp_ns,
    key_to_topic,
    live_session,
    open_session,
    subscribe,
    topic_types,
    types_key,
    unpack_attachment,
)

if TYPE_CHECKING:
    from gyroemu.pipelines.formats.messages import MessageType

__all__ = [
    "RecordOptions",
    "RecordError",
    "check_record_options",
    "SequenceTracker",
    "Recorder",
    "KeyInfo",
    "gyroemu_key",
    "ros2_key",
    "format_report",
    "run_record",
    "run_router",
]


_TF_TOPICS = (TF_TOPIC, TF_STATIC_TOPIC)
_TF_TYPE = TF_MESSAGE_TYPE


def _ranges(numbers: Iterable[int]) -> list[list[int]]:
    """Sorted integers as [first, last] ranges."""
    out: list[list[int]] = []
    for n in sorted(numbers):
        if out and n == out[-1][1] + 1:
            out[-1][1] = n
        else:
            out.append([n, n])
    return out


@dataclass
class SequenceTracker:
    """Sequence accounting of one publisher: sequence numbers step by 1 from the first one received.

    ``missing`` holds the numbers skipped after the first received message (gaps); numbers before it
    (sent before the recorder joined) are reported as ``first`` only."""

    topic: str
    received: int = 0
    first: int | None = None
    next: int = 0
    missing: set[int] = field(default_factory=set)
    duplicates: int = 0
    late: int = 0

    def add(self, sequence: int) -> None:
        self.received += 1
        if self.first is None:
            self.first = self.next = sequence  # what was sent before the recorder joined is not a gap
        if sequence < self.first:
            self.late += 1  # sent before the first one received, arrived after it
        elif sequence >= self.next:
            self.missing.update(range(self.next, sequence))
            self.next = sequence + 1
        elif sequence in self.missing:
            self.missing.discard(sequence)
            self.late += 1
        else:
            self.duplicates += 1

    def report(self) -> dict[str, Any]:
        """The publisher's counts (JSON-ready)."""
        return {
            "topic": self.topic,
            "received": self.received,
            "first": self.first,
            "last": self.next - 1,
            "missing": len(self.missing),
            "missing_ranges": _ranges(self.missing),
            "duplicates": self.duplicates,
            "late": self.late,
        }


@dataclass(frozen=True)
class KeyInfo:
    """What a key expression says: the device and topic to record under, and (ROS 2 keys) the type."""

    device: str
    topic: str
    type_name: str | None = None
    type_hash: str | None = None
    ros_topic: str | None = None  # the ROS 2 topic the key carries (ROS 2 keys)


def gyroemu_key(key: str) -> KeyInfo:
    """``gyroemu/<device>/<topic>`` (``ValueError`` for other keys); an older gyroemu's raw topic of a
    hyphenated kind is recorded under today's name (``/raw/rate-gyro`` -> ``/raw/rate_gyro``,
    :func:`gyroemu.pipelines.formats.channels.canonical_topic`)."""
    device, topic = key_to_topic(key)
    return KeyInfo(device, canonical_topic(topic))


def ros2_key(key: str) -> KeyInfo:
    """``<domain>/<device>/<rest>/<type>/<hash>`` (rmw_zenoh) -> device, ``/<rest>``, type and hash."""
    from gyroemu.pipelines.formats.ros2_keys import gyroemu_topic, parse_data_key

    parsed = parse_data_key(key)
    device, topic = gyroemu_topic(parsed.topic)
    return KeyInfo(device, topic, parsed.type_name, parsed.type_hash, parsed.topic)


@dataclass
class _Held:
    """The samples of a key whose channel waits for its type (:meth:`Recorder.add_types`)."""

    info: KeyInfo
    since: float  # monotonic time of its first sample
    stamps: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)


class Recorder:
    """Copies received zenoh samples into an MCAP file (see the module's notes).

    ``parse_key`` turns a sample's key expression into a :class:`KeyInfo` (:func:`gyroemu_key`, or
    :func:`ros2_key` in ROS 2 mode); ``on_new_topic(info)`` is called once per new channel and
    ``on_new_device(device)`` once per new device (``run_record`` asks for its config and types there).
    The file is created with the first channel; :meth:`close` removes it if no message was recorded.

    A key of a topic the recorder cannot type (no role of gyroemu's, a ROS 2 type gyroemu does not know)
    holds its samples until its device's types come (:meth:`add_types`, what a replay announces), or
    ``config_grace_s`` after its first sample, or :meth:`close`: its channel then gets the announced
    schema, or none."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        chunk_size: int = 1 << 18,
        parse_key: Callable[[str], KeyInfo] = gyroemu_key,
        on_new_topic: Callable[[KeyInfo], None] | None = None,
        on_new_device: Callable[[str], None] | None = None,
        config_grace_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        self._on_new_device = on_new_device
        self.config_grace_s = config_grace_s
        self._configs: dict[str, dict[str, str]] = {}  # device -> metadata fields from its config
        self._seen: dict[str, float] = {}  # device -> when first seen (monotonic), until its record is written
        self._described: dict[str, bool] = {}  # device -> whether its written record holds its config
        self._chunk_size = chunk_size
        self._file: Any = None  # opened with the first channel (:meth:`_writer`)
        self._mcap: Any = None
        self._channels: dict[tuple[str, str], int] = {}
        self._devices: dict[str, str] = {}  # device -> topic prefix
        self._pending: dict[tuple[int, int], tuple[list[int], list[bytes]]] = {}  # (channel, size) -> stamps, payloads
        self.trackers: dict[bytes, SequenceTracker] = {}
        self._parse_key = parse_key
        self._on_new_topic = on_new_topic
        self._keys: dict[str, tuple[KeyInfo, int | None] | None] = {}  # key -> (info, channel or None: held)
        self._types: dict[str, dict[str, TopicType]] = {}  # device -> {key: type}, as its publisher announced them
        self._held: dict[str, _Held] = {}  # key -> its samples, while its channel waits for its type
        self._static: set[bytes] = set()  # /tf_static payloads recorded
        self.repeated = 0  # /tf_static messages not stored again
        self.messages = 0
        self.skipped = 0
        self.without_attachment = 0

    def _writer(self) -> Any:
        """The MCAP writer, opening the file the first time."""
        if self._mcap is None:
            from gyroemu.pipelines.formats.mcap_records import McapFileWriter

            # A new file, as every other command's atomic write makes: an existing one (told --force) is
            # unlinked first, so that a symbolic or hard link's other names keep what they had.
            self.path.unlink(missing_ok=True)
            self._file = open(self.path, "wb")
            self._mcap = McapFileWriter(self._file, chunk_size=self._chunk_size)
        return self._mcap

    def _tf_channel(self, info: KeyInfo) -> int:
        """The file's ``/tf`` or ``/tf_static`` channel (no device prefix), as ``simulate`` writes it."""
        from gyroemu.pipelines.formats.mcap_log import TF_STATIC_QOS_PROFILES
        from gyroemu.pipelines.formats.mcap_records import OFFERED_QOS_PROFILES
        from gyroemu.pipelines.formats.tf_messages import tf_schema

        key = ("", info.topic)
        if key not in self._channels:
            mcap = self._writer()
            schema_id = mcap.register_schema(TF_MESSAGE_TYPE, "ros2msg", tf_schema().encode())
            qos = TF_STATIC_QOS_PROFILES if info.topic == TF_STATIC_TOPIC else OFFERED_QOS_PROFILES
            metadata = {"offered_qos_profiles": qos}
            if info.type_hash:
                metadata["topic_type_hash"] = info.type_hash
            self._channels[key] = mcap.register_channel(info.topic, "cdr", schema_id, metadata)
            self._announce_topic(info)
        return self._channels[key]

    def _announce_topic(self, info: KeyInfo) -> None:
        """Tell ``on_new_topic`` of a new channel (a ROS 2 graph token: advisory, never lose data over it)."""
        if self._on_new_topic is not None:
            try:
                self._on_new_topic(info)
            except Exception:
                pass

    def _channel(self, key: str, info: KeyInfo) -> int | None:
        """The channel of ``key``, registered the first time; None while its type is awaited (a topic
        the recorder cannot type, whose device's types have not come)."""
        if info.topic in _TF_TOPICS and info.type_name in (None, _TF_TYPE):
            return self._tf_channel(info)
        if (info.device, info.topic) in self._channels:
            return self._channels[(info.device, info.topic)]
        self._writer()
        self._see(info.device)
        mtype = MESSAGE_TYPES.get(info.type_name) if info.type_name else topic_message_type(info.topic)
        if mtype is None and info.device not in self._types:
            return None
        return self._register(key, info, mtype)

    def _see(self, device: str) -> None:
        """Give a device seen for the first time its topic prefix, and its record or the question for its config."""
        if device in self._devices:
            return
        prefix = "" if not self._devices else f"/{device}"
        self._devices[device] = prefix
        self._seen[device] = time.monotonic()
        if device in self._configs:
            self._describe(device)
        elif self._on_new_device is not None:
            try:
                self._on_new_device(device)
            except Exception:  # asking for the config is advisory: never lose data over it
                pass

    def _register(self, key: str, info: KeyInfo, mtype: MessageType | None) -> int:
        """Register ``key``'s channel: ``mtype``'s schema, else the type its device announced for the key
        (the original's schema name, encoding and text), else none."""
        from gyroemu.pipelines.formats.mcap_records import OFFERED_QOS_PROFILES

        topic = self._devices[info.device] + info.topic
        # the type hash as rosbag2 (Iron and later) records it
        metadata = {"topic_type_hash": info.type_hash} if info.type_hash else None
        announced = self._types.get(info.device, {}).get(key)
        channel: int
        if mtype is None and announced is not None and info.type_name in (None, announced.name):
            schema_id = self._mcap.register_schema(announced.name, announced.encoding, announced.schema.encode())
            channel = self._mcap.register_channel(
                topic, "cdr", schema_id, {"offered_qos_profiles": OFFERED_QOS_PROFILES, **(metadata or {})}
            )
        else:
            channel = self._mcap.register_ros2_channel(topic, mtype, metadata)
        self._channels[(info.device, info.topic)] = channel
        self._announce_topic(info)
        return channel

    def add_types(self, device: str, types: dict[str, TopicType]) -> None:
        """Take in the types ``device``'s publisher announced (:func:`gyroemu.pipelines.transport.zenoh_io.topic_types`:
        key -> type; ``{}`` when it announced none, or its answer is over), and register the channels
        of its keys that waited for them. Later answers add to what came."""
        self._types.setdefault(device, {}).update(types)
        self._release(lambda held: held.info.device == device)

    def _release(self, due: Callable[[_Held], bool]) -> None:
        """Register the channels of the held keys that are ``due`` (with what is known of their types)
        and move their samples to the pending ones."""
        for key, held in list(self._held.items()):
            if not due(held):
                continue
            del self._held[key]
            info = held.info
            channel = self._channels.get((info.device, info.topic))
            if channel is None:
                channel = self._register(key, info, None)
            self._keys[key] = (info, channel)
            for stamp, payload in zip(held.stamps, held.payloads):
                stamps, payloads = self._pending.setdefault((channel, len(payload)), ([], []))
                stamps.append(stamp)
                payloads.append(payload)

    def _describe(self, device: str) -> None:
        """Write ``device``'s ``gyroemu`` metadata record: its name, prefix and (when known) config."""
        from gyroemu.pipelines.formats.mcap_log import device_metadata

        fields = self._configs.get(device, {})
        self._mcap.add_metadata("gyroemu", device_metadata(device, self._devices[device], **fields))
        self._seen.pop(device, None)
        self._described[device] = bool(fields)

    def add_config(self, device: str, fields: dict[str, str]) -> None:
        """Take in ``device``'s config (:func:`gyroemu.pipelines.transport.zenoh_io.config_fields`: ``device``,
        ``seed``, ``scenario``). Its metadata record is written now if the device has been seen, else
        when it is; a record already written without a config is superseded by a complete one
        (readers take a device's last record)."""
        fields = {k: v for k, v in fields.items() if k in ("device", "seed", "scenario")}
        if self._configs.get(device) == fields:
            return
        self._configs[device] = fields
        if device in self._devices and not self._described.get(device, False):
            self._describe(device)

    def _describe_overdue(self, everyone: bool = False) -> None:
        """Write the records of devices seen ``config_grace_s`` ago (all of them: ``everyone``) whose
        config has not come: name and prefix only."""
        now = time.monotonic()
        for device, seen in list(self._seen.items()):
            if everyone or now - seen >= self.config_grace_s:
                self._describe(device)

    @property
    def configured(self) -> list[str]:
        """The devices whose metadata record holds their config."""
        return [d for d, done in self._described.items() if done]

    def _key(self, key: str) -> tuple[KeyInfo, int | None] | None:
        """The parsed key and its channel (cached per key expression; None while the channel waits for
        its type); None for keys not recorded."""
        try:
            return self._keys[key]
        except KeyError:
            pass
        try:
            info = self._parse_key(key)
            found: tuple[KeyInfo, int | None] | None = (info, self._channel(key, info))
        except ValueError:
            found = None
        self._keys[key] = found
        return found

    def add(self, sample: zenoh.Sample) -> None:
        """Take in one received sample (skipped, and counted, when its key or payload is not a recording's)."""
        key = str(sample.key_expr)
        if key.endswith(CONFIG_TOPIC) and self._take_config(key, sample):
            return
        found = self._key(key)
        if found is None:
            self.skipped += 1
            return
        info, channel = found
        tf = info.topic in _TF_TOPICS and info.type_name in (None, _TF_TYPE)
        try:
            payload = sample.payload.to_bytes()
            stamp = tf_stamp_ns(payload) if tf else header_stamp_ns(payload)
        except Exception:
            self.skipped += 1
            return
        if stamp < 0:
            self.skipped += 1
            return
        attachment = sample.attachment
        if attachment is not None:
            try:
                sequence, _, gid = unpack_attachment(attachment.to_bytes())
                tracker = self.trackers.get(gid)
                if tracker is None:
                    tracker = self.trackers[gid] = SequenceTracker(topic=f"{info.device}{info.topic}")
                tracker.add(sequence)
            except ValueError:
                self.without_attachment += 1
        else:
            self.without_attachment += 1
        if tf and info.topic == _TF_TOPICS[1]:
            if payload in self._static:
                self.repeated += 1
                return
            self._static.add(payload)
        self.messages += 1
        if channel is None:  # its type is awaited
            held = self._held.get(key)
            if held is None:
                held = self._held[key] = _Held(info, time.monotonic())
            held.stamps.append(stamp)
            held.payloads.append(payload)
            return
        stamps, payloads = self._pending.setdefault((channel, len(payload)), ([], []))
        stamps.append(stamp)
        payloads.append(payload)

    def _take_config(self, key: str, sample: zenoh.Sample) -> bool:
        """A sample on ``gyroemu/<device>/config``: its config taken in (a bad one is skipped); False for
        other keys."""
        try:
            device, topic = key_to_topic(key)
        except ValueError:
            return False
        if topic != CONFIG_TOPIC:
            return False
        try:
            attachment = sample.attachment
            fields = config_fields(sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes())
        except ValueError:
            self.skipped += 1
            return True
        self.add_config(device, fields)
        return True

    def flush(self) -> None:
        """Hand the pending messages to the MCAP writer (complete chunks reach the disk), and write the
        metadata records of devices whose config has not come within ``config_grace_s``, and the channels
        of keys whose types have not come within it (without a schema)."""
        if self._mcap is not None and self._seen:
            self._describe_overdue()
        if self._held:
            now = time.monotonic()
            self._release(lambda held: now - held.since >= self.config_grace_s)
        if not self._pending:
            return
        batches = []
        for (channel, size), (stamps, payloads) in self._pending.items():
            rows = np.frombuffer(b"".join(payloads), np.uint8).reshape(len(payloads), size)
            batches.append((channel, np.array(stamps, dtype=np.int64), rows))
        self._pending = {}
        self._mcap.add_messages(batches)
        self._file.flush()

    def close(self) -> None:
        """Write what is pending, the summary, indexes and footer, and close the file; remove it if it
        holds no message (nothing recorded: no file)."""
        if self._mcap is None:
            return
        try:
            self._release(lambda held: True)
            self.flush()
            self._describe_overdue(everyone=True)
            self._mcap.finish()
            self._file.flush()
        finally:
            self._file.close()
            self._mcap = None
            if self.messages == 0:
                self.path.unlink(missing_ok=True)

    @property
    def devices(self) -> list[str]:
        """The devices recorded, in the order they appeared."""
        return list(self._devices)

    @property
    def written(self) -> bool:
        """Whether the recording left a file (it recorded at least one message)."""
        return self.messages > 0 and self.path.is_file()

    def report(self) -> dict[str, Any]:
        """Counts of the recording and of each publisher (JSON-ready; :func:`format_report` prints it);
        ``file`` is the log written, None when the recording wrote none (nothing recorded)."""
        return {
            "file": str(self.path) if self.written else None,
            "messages": self.messages,
            "skipped": self.skipped,
            "without_attachment": self.without_attachment,
            "tf_static_repeats": self.repeated,
            "publishers": {gid.hex(): t.report() for gid, t in self.trackers.items()},
        }


def format_report(report: dict[str, Any]) -> str:
    """The :meth:`Recorder.report` as the lines ``gyroemu record`` prints."""
    lines = [
        f"record: {report['messages']} messages -> {report['file']}"
        + (f" ({report['skipped']} skipped)" if report["skipped"] else "")
        + (f" ({report['without_attachment']} without a valid attachment)" if report["without_attachment"] else "")
    ]
    total_missing = total_dup = 0
    for gid, r in sorted(report["publishers"].items(), key=lambda kv: kv[1]["topic"]):
        total_missing += r["missing"]
        total_dup += r["duplicates"]
        head = f"  {r['topic']:<24} publisher {gid}: {r['received']} received, seq {r['first']}..{r['last']}"
        extra = []
        if r["first"]:
            extra.append(f"joined at seq {r['first']} (0..{r['first'] - 1} sent before)")
        if r["missing"]:
            ranges = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in r["missing_ranges"][:50])
            more = " ..." if len(r["missing_ranges"]) > 50 else ""
            extra.append(f"{r['missing']} missing: {ranges}{more}")
        if r["duplicates"]:
            extra.append(f"{r['duplicates']} duplicates")
        if r["late"]:
            extra.append(f"{r['late']} out of order")
        lines.append(head + ("; " + "; ".join(extra) if extra else "; no gaps, no duplicates"))
    lines.append(f"record: {len(report['publishers'])} publishers, {total_missing} missing, {total_dup} duplicates")
    return "\n".join(lines)


@dataclass(frozen=True)
class RecordOptions:
    """What ``gyroemu record`` records, and where.

    Attributes
    ----------
    out_path : Path
        The MCAP file to write (in place), a ``.mcap`` name.
    duration : float or None
        Seconds to record; None: until SIGINT/SIGTERM.
    key_expr : str or None
        Key expression to subscribe to (a valid zenoh one, not empty); None: ``gyroemu/**``
        (``<domain>/**`` in ROS 2 mode).
    report_path : Path or None
        Also write the sequence report there as JSON (a file other than ``out_path``).
    session : SessionOptions
        The zenoh session (and ROS 2 mode: rmw_zenoh's keys, a ROS 2 node with a subscription token per topic).
    force : bool
        Replace ``out_path`` and ``report_path`` if they exist (otherwise :class:`RecordError` before
        any work).

    :func:`check_record_options` checks them all before any work.
    """

    out_path: Path
    duration: float | None = None
    key_expr: str | None = None
    report_path: Path | None = None
    session: SessionOptions = field(default_factory=SessionOptions)
    force: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "out_path", Path(self.out_path))
        if self.report_path is not None:
            object.__setattr__(self, "report_path", Path(self.report_path))


class RecordError(ConfigError):
    """Bad options of ``gyroemu record``, found before any work (the message names the argument)."""


def _check_output(path: Path, argument: str, force: bool) -> None:
    """:class:`RecordError` naming ``argument`` when ``path`` cannot take a new file: a folder, in a folder
    that cannot take it, an existing file without ``force``
    (:func:`~gyroemu.pipelines.formats.atomic.output_file_problem`)."""
    problem = output_file_problem(path, force=force)
    if problem is not None:
        raise RecordError(f"argument {argument}: {problem}")


def check_record_options(options: RecordOptions) -> None:
    """:class:`RecordError` (or the session's ``LiveOptionError``) naming the argument at fault, before
    any work: ``--out`` not a ``.mcap`` file name, a folder, in a folder that cannot take it, or an
    existing file without ``--force``; ``--report`` the same file as ``--out``, or refused as ``--out``
    is (any suffix); ``--key`` empty or no zenoh key expression."""
    out = options.out_path
    if out.suffix != ".mcap" and not out.is_dir():  # a folder is said to be one, below
        raise RecordError(f"argument --out: {out}: record writes an MCAP log: name a .mcap file (got '{out.suffix}')")
    _check_output(out, "--out", options.force)
    report = options.report_path
    if report is not None:
        if same_file(report, out):
            raise RecordError(f"argument --report: {report} is the --out file: name another file for the report")
        _check_output(report, "--report", options.force)
    if options.key_expr is not None:
        check_key_expr(options.key_expr, "--key")


def _take_reply(recorder: Recorder, device: str, sample: zenoh.Sample | None) -> None:
    """A reply to the recorder's ``get`` of ``device``'s config or types, into the recorder (a bad one is
    ignored); None: the ``get`` of its types is over (:meth:`Recorder.add_types` with what came, if anything)."""
    if sample is None:
        recorder.add_types(device, {})
        return
    payload = sample.payload.to_bytes()
    if str(sample.key_expr) == types_key(device):
        try:
            types = topic_types(payload)
        except ValueError:
            return
        recorder.add_types(device, types)
        return
    try:
        attachment = sample.attachment
        fields = config_fields(payload, None if attachment is None else attachment.to_bytes())
    except ValueError:
        return
    recorder.add_config(device, fields)


def run_record(options: RecordOptions, *, out: TextIO = sys.stdout) -> int:
    """Record until SIGINT/SIGTERM or ``options.duration`` s (see the module's notes); the report goes to
    ``out``. Returns the exit status (0). Raises ``ValueError`` naming the argument at fault, before any
    work (:func:`check_record_options`: an existing ``out_path`` or ``report_path`` without ``force``
    among them). Nothing received: says so, writes no log; the report, if asked for, is written with
    ``"file": null`` (the outcome a script waiting for it reads: no log, zero messages)."""
    check_record_options(options)
    ros2, key_expr = options.session.ros2, options.key_expr
    domain = None
    if ros2:
        from gyroemu.pipelines.formats.ros2_keys import domain_id

        domain = domain_id(options.session.domain)
        parse_key = ros2_key
        key_expr = key_expr or f"{domain}/**"
    else:
        parse_key = gyroemu_key
        key_expr = key_expr or "gyroemu/**"
    session = open_session(options.session.config())
    on_new_topic: Callable[[KeyInfo], None] | None
    with live_session(session) as live:
        if ros2:
            from gyroemu.pipelines.formats.ros2_keys import Ros2Node, node_name

            assert domain is not None  # domain_id() above gave it its value
            node = live.node = Ros2Node(session, domain, node_name("record"))

            def on_new_topic(info: KeyInfo) -> None:
                # ros2_key, the parser in ROS 2 mode, sets all three
                assert info.ros_topic is not None and info.type_name is not None and info.type_hash is not None
                node.subscription(info.ros_topic, info.type_name, info.type_hash)

        else:
            on_new_topic = None
        # config and types replies (None: a types get is over), from zenoh's threads, taken in by this one
        replies: deque[tuple[str, zenoh.Sample | None]] = deque()

        def ask_config(device: str) -> None:
            def on_reply(reply: zenoh.Reply) -> None:
                if reply.ok is not None:
                    replies.append((device, reply.ok))

            session.get(config_key(device), on_reply, timeout=10.0)
            # what a replay announces of its keys' types; once the get is over (every queryable answered,
            # or none there), the keys held for their types are registered with what came
            session.get(
                types_key(device),
                zenoh.handlers.Callback(on_reply, lambda: replies.append((device, None))),
                timeout=10.0,
            )

        recorder = Recorder(options.out_path, parse_key=parse_key, on_new_topic=on_new_topic, on_new_device=ask_config)
        try:
            subscriber = subscribe(session, key_expr)
            what = f"ROS 2 domain {domain}: " if ros2 else ""
            print(f"record: subscribed to {what}{key_expr} -> {recorder.path}", file=out, flush=True)
            warning = connect_warning(session, options.session.connect)
            if warning:
                print(f"record: {warning}", file=out, flush=True)
            end = None if options.duration is None else time.monotonic() + options.duration
            last_flush = time.monotonic()
            while not live.stopped() and (end is None or time.monotonic() < end):
                samples = drain(subscriber)
                for sample in samples:
                    recorder.add(sample)
                while replies:
                    _take_reply(recorder, *replies.popleft())
                now = time.monotonic()
                if now - last_flush > 0.2:
                    recorder.flush()
                    last_flush = now
                if not samples:
                    time.sleep(0.002)
            for sample in drain(subscriber, 1 << 30):
                recorder.add(sample)
            while replies:
                _take_reply(recorder, *replies.popleft())
            subscriber.undeclare()
        finally:
            recorder.close()
    report = recorder.report()
    if recorder.written:
        print(format_report(report), file=out, flush=True)
        configured = recorder.configured
        bare = sorted(set(recorder.devices) - set(configured))
        if configured:
            print(f"record: device config stored for {', '.join(sorted(configured))}", file=out, flush=True)
        if bare:
            print(f"record: no device config came for {', '.join(bare)} (not a gyroemu stream?)", file=out, flush=True)
    else:
        print(f"record: nothing received on {key_expr}: no file written ({recorder.path})", file=out, flush=True)
    if options.report_path:
        try:
            write_text_atomic(options.report_path, json.dumps(report, indent=1))  # whole or not at all
        except OSError as e:
            from gyroemu.pipelines.jobs.disk_space import is_disk_full

            if is_disk_full(e):
                raise  # not the argument's fault: the command line says so, status 1
            raise RecordError(f"argument --report: {options.report_path}: {e.strerror or e}") from None
    return 0


def run_router(session: SessionOptions, *, out: TextIO = sys.stdout) -> int:
    """Run a zenoh router until SIGINT/SIGTERM: it listens on ``session.listen`` (default
    ``tcp/0.0.0.0:7447``) and connects to ``session.connect`` (other routers); ``mode`` and the ROS 2
    fields do not apply. Returns the exit status (0). Raises ``ValueError`` naming the argument at fault."""
    zenoh_session = open_session(session.router_config())
    with live_session(zenoh_session) as live:
        print(
            f"router: {zenoh_session.zid()} listening on {', '.join(session.listen or ['tcp/0.0.0.0:7447'])}",
            file=out,
            flush=True,
        )
        warning = connect_warning(zenoh_session, session.connect)
        if warning:
            print(f"router: {warning}", file=out, flush=True)
        while not live.stopped():
            time.sleep(0.1)
    return 0
