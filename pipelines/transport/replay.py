"""``gyroemu replay``: republish an MCAP file's messages over zenoh with their recorded timing.

What goes out
-------------
Every ``cdr`` channel of the file (or those named by ``--topics``), each message's recorded bytes
unchanged, on the key expression of its topic (``interface.md``, "Live streams: Eclipse Zenoh"):

- gyroemu's topics (``/imu``, ``/mag``, ``/truth/imu``, ``/truth/pose``, ``/estimate/imu``,
  ``/raw/<kind>``: the roles of live streams, :func:`gyroemu.pipelines.formats.channels.is_stream_role`)
  go to ``gyroemu/<device>/<topic>``.
  The device is the topic's prefix when the file's ``gyroemu`` metadata names that prefix
  (``/<device>/imu`` of a several-device file), else the ``device_name`` of the file's ``gyroemu``
  metadata for unprefixed topics, else ``--device-name`` (default ``imu0``).
- the tf tree (``/tf``, ``/tf_static``: the file's, unprefixed) goes to ``gyroemu/<device>/tf`` and
  ``gyroemu/<device>/tf_static``, the device of the file's unprefixed topics (as ``gyroemu stream``
  publishes it), else ``--device-name``.
- any other topic ``/a/b`` (someone else's file) goes to ``gyroemu/<device-name>/a/b``.

An older gyroemu log's raw topic of a hyphenated kind (``/raw/rate-gyro``) goes out under today's name
(``gyroemu/<device>/raw/rate_gyro``, :func:`gyroemu.pipelines.formats.channels.canonical_role`).

Types
-----
A key carries a topic's bytes, not its type: a recorder types gyroemu's own topics by their role, but
only the file knows what ``/robot1/imu/data_raw`` holds. So before it publishes, the replay declares,
for each device of its keys, a queryable on ``gyroemu/<device>/@types``
(:class:`gyroemu.pipelines.transport.zenoh_io.TypesAnnouncer`) that answers with every key's message
type and schema (the channel's schema name, encoding and text, as the file has them; a channel without
a schema, or whose schema is not UTF-8 text, is left out). ``gyroemu record`` asks it when it first sees
the device, whenever it started, and registers a topic it cannot type by role with that schema, so the
recording of a replayed bag holds the bag's schemas. Why a queryable: the per-device config reply
carries a device's TOML, which someone else's file does not have, and the attachment is rmw_zenoh's 33
bytes that every subscriber parses; a queryable adds nothing to the data keys and answers a recorder
that joins late. In ROS 2 mode the keys are rmw_zenoh's, and the answer names them.

The attachment is the publisher's (:class:`gyroemu.pipelines.transport.zenoh_io.PacedPublisher`): a sequence per key
from 0 (continuing across ``--loop`` passes), the send time, a random publisher id per key.

ROS 2 mode (``--ros2``, ``--domain``): the topic that would go to ``gyroemu/<device>/<topic>`` goes to
ROS 2 topic ``/<device>/<topic>`` on rmw_zenoh's key ``<domain>/<device>/<topic>/<type>/<hash>``
(:mod:`gyroemu.pipelines.formats.ros2_keys`), with the liveliness tokens of a node ``gyroemu_replay_<pid>`` and its
publishers. ``/tf`` and ``/tf_static`` are the ROS 2 graph's own topics, not a device's
(:data:`~gyroemu.pipelines.formats.ros2_keys.GLOBAL_TOPICS`): they go to ``/tf`` and ``/tf_static``,
their publishers advertising tf2's QoS (``/tf_static`` transient local;
:func:`~gyroemu.pipelines.formats.ros2_keys.topic_qos`), so tf2 listeners on rmw_zenoh get the tree.
zenoh keeps no history for a listener that joins later, so, as ``gyroemu stream`` does, the replay
sends the file's ``/tf_static`` messages again, the same bytes, every
:data:`~gyroemu.pipelines.formats.frames.TF_STATIC_REPEAT_S` of log time after the first (the distinct
ones seen so far, :data:`TF_STATIC_KEEP` at most, with the deadline of the message they precede).
The type is the channel's schema name; the hash is the channel's ``topic_type_hash``
metadata (rosbag2 records it since Iron) or else computed by REP-2011 from the channel's ``ros2msg``
schema. A channel with neither (no schema, an IDL schema and no recorded hash) is skipped with a
message, as is a topic that is not a valid ROS 2 name.

Timing
------
Message i goes out at ``t_start + (log_time_i - log_time_0) / rate`` (``t_start``: when publishing
starts, monotonic clock): the publisher sleeps until each absolute deadline, or sends at once when
behind, so its error never accumulates (:meth:`PacedPublisher.run_schedule`). With ``--loop``, pass k
is shifted by k times the file's span plus one mean message interval, so deadlines keep increasing,
and so do the stamps a subscriber sees: from pass 1 on, the header stamp of every message whose type
starts with a ``std_msgs/Header`` (gyroemu's types, and any type whose schema says so:
:func:`gyroemu.pipelines.formats.messages.starts_with_header`) is moved by the same shift
(:func:`~gyroemu.pipelines.formats.messages.shift_header_stamp`); the other bytes, and every byte of
pass 0 and of headerless types, are the recorded ones.

A reader thread (:class:`gyroemu.pipelines.transport.read_ahead.ReadAheadThread`, shared with ``gyroemu
stream``) walks the file a chunk at a time (:func:`gyroemu.pipelines.formats.mcap_records.iter_mcap_batches`),
turns each chunk's messages into batches of ``BATCH`` ``(deadline offset, key, payload)`` and queues
them (a bounded queue of ``READ_AHEAD`` batches), so decompressing a chunk happens while the
publisher waits for its deadlines, never on its schedule; memory stays bounded by the queue, whatever
the file's size. Batches are small because the publisher frees each spent one (a list of tuples of
bytes: one deallocation per object, holding the GIL) just after a send: 256 messages take ~50 us,
a whole 1 MiB chunk's 4000 took ~0.7 ms, long enough to make the next deadline late. The reader
frees its own per-chunk objects a slice at a time for the same reason. How the publisher waits and
keeps the reader from delaying it: :class:`gyroemu.pipelines.transport.zenoh_io.Timing`.

Before the clock starts the file is validated with :func:`gyroemu.pipelines.formats.mcap_log.read_mcap` (not MCAP,
corrupt, truncated before its first chunk, no ``sensor_msgs/msg/Imu`` message: a ``LogError`` naming the
file), the replay waits (``--wait``, default 10 s) until every key has a subscriber, as
``gyroemu stream`` does, and then until the reader has filled its queue (at most 10 s more): its
start-up, competing for the GIL with the first deadlines, made them up to 15 ms late. The input is
only ever opened for reading.

Clock (``--clock``)
------------------
A ``rosgraph_msgs/msg/Clock`` on ``/clock`` (key ``gyroemu/<device>/clock``, the device of the replayed
keys or ``--device-name``; in ROS 2 mode ROS 2 topic ``/clock`` on its rmw_zenoh key): the replayed log
time (shifted as the stamps are, so it only moves forward across ``--loop`` passes), sent with the
first message of each log-time step of at least ``rate / CLOCK_HZ`` s (:data:`CLOCK_HZ` a second of
wall time, as ``ros2 bag play --clock``), at that message's deadline. ``--wait`` waits for a ``/clock``
subscriber too.

From Python: ``run_replay(ReplayOptions(path=Path("run.mcap"), rate=2.0))`` (:class:`ReplayOptions`).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Generator, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.channels import (
    canonical_role,
    is_device_prefix,
    is_stream_role,
    role_topic,
    split_topic,
)
from gyroemu.pipelines.formats.frames import TF_STATIC_REPEAT_S, TF_STATIC_TOPIC, TF_TOPIC
from gyroemu.pipelines.formats.mcap_log import check_mcap_noting
from gyroemu.pipelines.formats.mcap_records import iter_mcap_batches
from gyroemu.pipelines.formats.messages import CLOCK_TYPE, encode_clock, shift_header_stamp, starts_with_header
from gyroemu.pipelines.formats.tf_messages import TF_MESSAGE_TYPE, shift_tf_stamps
from gyroemu.pipelines.transport.read_ahead import BATCH, READ_AHEAD, Batch, ReadAheadThread
from gyroemu.pipelines.transport.zenoh_io import (
    PacingOptions,
    SessionOptions,
    TopicType,
    TypesAnnouncer,
    check_pacing_options,
    key_to_topic,
    live_session,
    open_session,
    topic_to_key,
)

if TYPE_CHECKING:
    from gyroemu.pipelines.formats.mcap_records import ChannelInfo
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys
    from gyroemu.pipelines.transport.foxglove_view import FoxgloveView, ViewOptions

__all__ = [
    "ReplayOptions",
    "topic_keys",
    "ros2_topic_keys",
    "announced_types",
    "ReadAhead",
    "run_replay",
    "READ_AHEAD",
    "BATCH",
    "CLOCK_HZ",
    "TF_STATIC_KEEP",
    "MIN_RATE",
    "MAX_RATE",
]

CLOCK_HZ = 40.0
"""``--clock``: /clock messages a second of wall time, at most (``ros2 bag play --clock``'s default)."""

TF_STATIC_KEEP = 64
"""ROS 2 mode: distinct ``/tf_static`` messages a replay re-sends every
:data:`~gyroemu.pipelines.formats.frames.TF_STATIC_REPEAT_S` of log time, at most (the latest): a tree
has a few (one per static broadcaster of a bag; gyroemu's logs one per device), so this only bounds the
memory of a file that writes a new one at every message."""

# The speed factors the pacing can do. A deadline is round(log time since the start / rate) ns: at 1e6
# a 1 kHz log's 1 ms becomes the deadline's 1 ns, so a faster factor changes nothing (the publisher
# already sends as fast as it can) -- and 1e300 overflowed (the /clock step, rate * 1e9 / CLOCK_HZ, is
# infinite). At 1e-6 a log's second takes 11.6 days of wall time: slower is no replay, and 1e-300 made
# the deadlines infinite (OverflowError).
MIN_RATE, MAX_RATE = 1e-6, 1e6


class ReplayError(ConfigError):
    """Bad usage of ``gyroemu replay`` (the message names the argument; a ``ValueError`` too)."""


@dataclass(frozen=True)
class ReplayOptions:
    """What ``gyroemu replay`` republishes and how.

    Attributes
    ----------
    path : Path
        The MCAP file to replay (only ever read).
    rate : float
        Speed factor, :data:`MIN_RATE` to :data:`MAX_RATE`: message i goes out at
        ``t_start + (log_time_i - log_time_0) / rate`` (2: twice as fast as recorded).
    loop : bool
        Repeat the file until SIGINT/SIGTERM, deadlines increasing across passes.
    topics : tuple of str or None
        Replay only these topics (each must be in the file and cdr-encoded); None: every cdr topic.
    device_name : str
        Device of the topics the file's ``gyroemu`` metadata does not name (keys ``gyroemu/<device_name>/...``).
    session : SessionOptions
        The zenoh session (and ROS 2 mode).
    pacing : PacingOptions
        Waiting for subscribers, how deadlines are waited for, lingering at the end.
    clock : bool
        Also publish ``rosgraph_msgs/msg/Clock`` on ``/clock`` (see the module's notes).
    foxglove : ViewOptions or None
        Also serve a live 3D view on a Foxglove WebSocket (``--foxglove``,
        :mod:`gyroemu.pipelines.transport.foxglove_view`): the replayed channels, ``/tf`` and ``/scene``.
    """

    path: Path
    rate: float = 1.0
    loop: bool = False
    topics: tuple[str, ...] | None = None
    device_name: str = "imu0"
    session: SessionOptions = field(default_factory=SessionOptions)
    pacing: PacingOptions = field(default_factory=PacingOptions)
    clock: bool = False
    foxglove: ViewOptions | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if self.topics is not None:
            object.__setattr__(self, "topics", tuple(self.topics))


def topic_keys(
    topics: Iterable[str], metadata: list[dict[str, str]], device_name: str = "imu0"
) -> tuple[dict[str, str], dict[str, str]]:
    """``({topic: key}, {topic: why it cannot be published})`` by the rule in the module's notes."""
    by_prefix = {m.get("topic_prefix", ""): m.get("device_name") or "" for m in metadata}
    if "" not in by_prefix and len(metadata) == 1:
        by_prefix[""] = metadata[0].get("device_name") or ""
    keys, bad = {}, {}
    for topic in topics:
        name = topic if topic.startswith("/") else "/" + topic
        device, rest = device_name, name
        prefix, role = split_topic(name)
        if is_stream_role(role) and is_device_prefix(prefix) and prefix in by_prefix:
            device, rest = by_prefix[prefix] or prefix.strip("/") or device_name, role_topic(canonical_role(role))
        elif name in (TF_TOPIC, TF_STATIC_TOPIC):
            device = by_prefix.get("") or device_name
        try:
            if any(c in rest for c in "*$?#"):
                raise ValueError(f"topic {topic!r}: '*', '$', '?' and '#' cannot go in a key expression")
            keys[topic] = topic_to_key(device, rest)
        except ValueError as e:
            bad[topic] = str(e)
    return keys, bad


def ros2_topic_keys(
    keys: dict[str, str], channels: Iterable[ChannelInfo], ros: Ros2Keys
) -> tuple[dict[str, str], dict[str, str]]:
    """ROS 2 mode: ``({topic: rmw_zenoh key}, {topic: why not})`` from the gyroemu keys of
    :func:`topic_keys`, the file's :class:`gyroemu.pipelines.formats.mcap_records.ChannelInfo` and a
    :class:`~gyroemu.pipelines.formats.ros2_keys.Ros2Keys` (which keeps each key's topic, type and hash for
    its tokens)."""
    from gyroemu.pipelines.formats.ros2_keys import (
        Ros2Error,
        full_type_name,
        is_type_hash,
        parse_definitions,
        ros_topic,
        type_hash,
    )

    info = {c.topic: c for c in channels}
    out, bad = {}, {}
    for topic, key in keys.items():
        c = info[topic]
        try:
            name = ros_topic(*key_to_topic(key))
            if not c.schema_name:
                raise Ros2Error("the channel has no schema, so its ROS 2 type is unknown")
            type_name = full_type_name(c.schema_name)
            recorded = c.metadata.get("topic_type_hash", "")
            if is_type_hash(recorded):
                hash_ = recorded
            elif c.schema_encoding == "ros2msg":
                hash_ = type_hash(type_name, parse_definitions(c.schema_data.decode("utf-8"), type_name))
            else:
                raise Ros2Error(
                    f"no topic_type_hash recorded and a {c.schema_encoding or 'missing'} schema, "
                    "from which gyroemu cannot compute the type hash"
                )
            out[topic] = ros.key(name, type_name, hash_)
        except (ValueError, UnicodeDecodeError) as e:
            bad[topic] = f"no ROS 2 key: {e}"
    return out, bad


def announced_types(
    keys: dict[str, str], devices: dict[str, str], channels: Iterable[ChannelInfo]
) -> dict[str, dict[str, TopicType]]:
    """What each device's :class:`~gyroemu.pipelines.transport.zenoh_io.TypesAnnouncer` answers:
    ``{device: {key: type}}`` of the replayed topics (``keys``: topic -> key as published; ``devices``:
    topic -> its device) whose channel has a schema of UTF-8 text (the others are left out)."""
    out: dict[str, dict[str, TopicType]] = {}
    for c in channels:
        if c.topic not in keys or not c.schema_name:
            continue
        try:
            schema = c.schema_data.decode("utf-8")
        except UnicodeDecodeError:
            continue
        out.setdefault(devices[c.topic], {})[keys[c.topic]] = TopicType(c.schema_name, c.schema_encoding, schema)
    return out


class ReadAhead(ReadAheadThread):
    """Reads the file in a thread and queues ``[(deadline offset ns, key, payload), ...]`` batches (of
    at most ``BATCH``; :class:`gyroemu.pipelines.transport.read_ahead.ReadAheadThread`): ``None`` ends
    the stream, an exception object is raised by :meth:`batches`.

    With ``loop``, the messages of the topics in ``stamped`` (types that start with a header) get their
    header stamps moved by each pass's shift (none in pass 0). ``clock_key``: a ``rosgraph_msgs/msg/Clock``
    of the (shifted) log time goes there with the first message of every log-time step of at least
    ``rate / CLOCK_HZ`` s. ``repeat_static`` (ROS 2 mode: ``/tf_static``): that topic's distinct
    messages seen so far go out again, as last sent, every
    :data:`~gyroemu.pipelines.formats.frames.TF_STATIC_REPEAT_S` of log time after the first, each
    time just before the message then due (:data:`TF_STATIC_KEEP` at most).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        keys: dict[str, str],
        rate: float,
        loop: bool,
        depth: int = READ_AHEAD,
        stamped: Iterable[str] = (),
        clock_key: str | None = None,
        repeat_static: str | None = None,
    ) -> None:
        super().__init__(depth, name="replay-read-ahead")
        self.path, self.keys, self.rate, self.loop = path, keys, float(rate), loop
        self.stamped = frozenset(stamped)
        self.clock_key = clock_key
        self.repeat_static = repeat_static if repeat_static in keys else None
        self.passes = 0

    def produce(self) -> Generator[Batch, None, None]:
        keys, rate, stamped, clock_key = self.keys, self.rate, self.stamped, self.clock_key
        clock_step = round(rate * 1e9 / CLOCK_HZ)  # ns of log time between /clock messages, at least
        clock_next = None
        static_topic = self.repeat_static
        static_key = "" if static_topic is None else keys[static_topic]  # (unused without one)
        static_step = round(TF_STATIC_REPEAT_S * 1e9)  # ns of log time between repeats
        statics: dict[bytes, bytes] = {}  # /tf_static as recorded -> as last sent (stamps shifted by --loop)
        static_next: int | None = None  # the (shifted) log time of the next repeat
        offset = 0  # ns of log time added to this pass
        first = None
        while not self.stopping.is_set():
            pass_first = last = previous = None
            distinct = 0
            for batch in iter_mcap_batches(self.path, topics=keys):
                if pass_first is None:
                    pass_first = batch[0].log_time
                    if first is None:
                        first = pass_first
                assert first is not None  # set from the first batch of the first pass
                shift = offset - first
                items = []
                for m in batch:
                    if m.log_time != previous:
                        distinct += 1
                        previous = m.log_time
                    data = shift_header_stamp(m.data, offset) if offset and m.topic in stamped else m.data
                    if offset and m.schema == TF_MESSAGE_TYPE:  # every transform's header stamp
                        data = shift_tf_stamps(m.data, offset)
                    deadline = round((m.log_time + shift) / rate)
                    if clock_key is not None and (clock_next is None or m.log_time + offset >= clock_next):
                        items.append((deadline, clock_key, encode_clock(m.log_time + offset)))
                        clock_next = m.log_time + offset + clock_step
                    if static_next is not None and m.log_time + offset >= static_next:
                        items.extend((deadline, static_key, payload) for payload in statics.values())
                        static_next = m.log_time + offset + static_step
                    items.append((deadline, keys[m.topic], data))
                    if m.topic == static_topic:
                        statics.pop(m.data, None)  # the latest last
                        statics[m.data] = data
                        if len(statics) > TF_STATIC_KEEP:
                            del statics[next(iter(statics))]
                        if static_next is None:
                            static_next = m.log_time + offset + static_step
                last = batch[-1].log_time
                while batch:  # free the McapMessage tuples a slice at a time: a deallocation holds
                    del batch[-BATCH:]  # the GIL throughout, and 4000 at once take ~0.5 ms
                for start in range(0, len(items), BATCH):
                    yield items[start : start + BATCH]
            self.passes += 1
            if not self.loop or pass_first is None:
                break
            assert last is not None  # set with pass_first, by every batch
            span = last - pass_first
            interval = span / (distinct - 1) if distinct > 1 else 1e9
            offset += span + round(interval)


def _channels_to_publish(
    options: ReplayOptions, out: TextIO
) -> tuple[dict[str, str], Ros2Keys | None, frozenset[str], dict[str, dict[str, TopicType]]]:
    """Validate the file and the options; ``({topic: key}, ROS 2 keys or None, the topics whose type
    starts with a header, each device's announced types)``, skipped topics said on ``out``."""
    path, topics = options.path, options.topics
    rate = options.rate
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not MIN_RATE <= rate <= MAX_RATE:
        raise ReplayError(f"argument --rate: must be a speed factor from {MIN_RATE:g} to {MAX_RATE:g}, got {rate}")
    check_pacing_options(options.pacing)  # LiveOptionError naming --wait
    if options.foxglove is not None:
        from gyroemu.pipelines.transport.foxglove_view import check_view_options

        check_view_options(options.foxglove)
    ros = None
    if options.session.ros2:
        from gyroemu.pipelines.formats.ros2_keys import Ros2Keys

        ros = Ros2Keys(options.session.domain, "replay")  # Ros2Error names --domain or ROS_DOMAIN_ID
    try:
        topic_to_key(options.device_name, "/imu")
    except ValueError as e:
        raise ReplayError(f"argument --device-name: {e}") from None
    # validation: LogError naming the file
    log = check_mcap_noting(path, lambda message: print(f"replay: warning: {message}", file=out))
    channels = log.channels  # the pass that validated the file found them
    cdr = [c.topic for c in channels if c.message_encoding == "cdr"]
    if topics:
        known = {c.topic for c in channels}
        for topic in topics:
            if topic not in known:
                raise ReplayError(f"argument --topics: {path}: no topic {topic!r} (it has {', '.join(sorted(known))})")
            if topic not in cdr:
                raise ReplayError(f"argument --topics: {path}: topic {topic!r} is not cdr-encoded")
        cdr = [t for t in cdr if t in set(topics)]
    for c in channels:
        if c.message_encoding != "cdr" and not topics:
            print(f"replay: skipping {c.topic}: message encoding {c.message_encoding!r}, not cdr", file=out)
    keys, bad = topic_keys(cdr, log.metadata, options.device_name)
    devices = {topic: key_to_topic(key)[0] for topic, key in keys.items()}
    if ros is not None:
        keys, more = ros2_topic_keys(keys, channels, ros)
        bad.update(more)
    for topic, why in bad.items():
        if topics:
            raise ReplayError(f"argument --topics: {path}: topic {topic!r} has no key expression: {why}")
        print(f"replay: skipping {topic}: {why}", file=out)
    if not keys:
        raise ReplayError(f"argument LOG: {path}: no topic to publish")
    stamped = frozenset(
        c.topic
        for c in channels
        if c.topic in keys
        and starts_with_header(
            c.schema_name, c.schema_data.decode("utf-8", "replace") if c.schema_encoding == "ros2msg" else ""
        )
    )
    return keys, ros, stamped, announced_types(keys, devices, channels)


def _clock_key(options: ReplayOptions, keys: dict[str, str], ros: Ros2Keys | None) -> str:
    """The key of ``/clock``: ROS 2 topic ``/clock``'s in ROS 2 mode, else ``gyroemu/<device>/clock``
    with the device of every replayed key when they share one, else ``--device-name``."""
    if ros is not None:
        key = ros.key("/clock", CLOCK_TYPE)
    else:
        devices = {key_to_topic(k)[0] for k in keys.values()}
        key = topic_to_key(devices.pop() if len(devices) == 1 else options.device_name, "/clock")
    clash = [t for t, k in keys.items() if k == key]
    if clash:
        raise ReplayError(f"argument --clock: topic {clash[0]} of {options.path} is already published on {key}")
    return key


def _start_view(options: ReplayOptions, keys: dict[str, str], stamped: frozenset[str]) -> FoxgloveView:
    """The Foxglove view of the replayed channels (their recorded schemas), its server listening."""
    from gyroemu.pipelines.formats.mcap_records import mcap_channel_info
    from gyroemu.pipelines.transport.foxglove_view import FoxgloveView, log_channel_specs, log_mounting

    assert options.foxglove is not None
    specs = log_channel_specs(mcap_channel_info(options.path), keys, stamped)
    return FoxgloveView(
        options.foxglove,
        specs,
        {key: topic for topic, key in keys.items()},
        name=f"gyroemu replay {options.path.name}",
        mounting=log_mounting(options.path),
    )


def run_replay(options: ReplayOptions, *, out: TextIO = sys.stdout) -> int:
    """Replay ``options.path`` (see the module's notes); progress goes to ``out``. Returns the exit
    status: 0 when done (or, with ``loop``, when stopped by SIGINT/SIGTERM), 130 (SIGINT) or 143
    (SIGTERM) when a single pass was interrupted. Raises
    :class:`gyroemu.pipelines.formats.mcap_records.LogError` for bad input and ``ValueError`` naming the
    argument at fault (the endpoints and config before the plan is printed)."""
    config = options.session.config()
    keys, ros, stamped, types = _channels_to_publish(options, out)
    clock_key = _clock_key(options, keys, ros) if options.clock else None
    path, rate, loop, pacing = options.path, options.rate, options.loop, options.pacing
    session = open_session(config)  # a taken --listen, a client without a router: refused before the plan
    reader = view = None
    announcers: list[TypesAnnouncer] = []
    with live_session(session) as live:
        try:
            print(f"replay: {path}: {len(keys)} topics at rate x{rate:g}{', looping' if loop else ''}", file=out)
            for topic, key in keys.items():
                print(f"  {topic} -> {key}", file=out)
            # the keys' types, for recorders: declared before the first message goes out
            announcers = [TypesAnnouncer(session, device, device_types) for device, device_types in types.items()]
            for announcer in announcers:
                print(f"  {announcer.key} (the topics' types, queryable)", file=out)
            if clock_key is not None:
                print(f"  /clock -> {clock_key} ({CLOCK_TYPE}, the log time, {CLOCK_HZ:g} Hz at most)", file=out)
            view = _start_view(options, keys, stamped) if options.foxglove is not None else None
            if view is not None:
                print(f"replay: Foxglove view on {view.url} ({view.options.rate_hz:g} Hz)", file=out, flush=True)
            live.node = ros
            publisher = live.publish(sorted(set(keys.values()) | ({clock_key} if clock_key else set())), pacing.timing)
            if ros is not None:
                ros.declare(session, out)
            # ROS 2 mode: /tf_static advertised transient local, but zenoh keeps no history: repeated
            repeat_static = TF_STATIC_TOPIC if ros is not None else None
            reader = ReadAhead(
                path, keys, rate, loop, stamped=stamped, clock_key=clock_key, repeat_static=repeat_static
            )
            reader.start()  # fills its queue while we wait for subscribers
            stop = live.stopped
            wait_s = pacing.wait_s
            if wait_s > 0 and not publisher.wait_for_subscribers(wait_s, stop=stop):
                print(f"replay: no subscriber on every key after {wait_s:g} s: publishing anyway", file=out)
            # The reader's start-up (imports, the first chunks) would compete with the first deadlines for
            # the GIL: start the clock once its queue is full (at most 10 s from here).
            end = time.monotonic() + 10.0
            while not reader.ready.wait(0.1) and not stop() and time.monotonic() < end:
                pass
            print("replay: publishing", file=out, flush=True)
            batches = reader.batches(stop)
            report = publisher.run_schedule(batches if view is None else view.tap(batches), stop=stop)
            print(f"replay: sent {report.messages} messages ({reader.passes} complete passes)", file=out)
            print(f"replay: {report.summary('t_start + (log_time - log_time_0) / rate')}", file=out)
            time.sleep(pacing.linger_s)  # let queued messages drain before the session closes
        finally:
            if reader is not None:
                reader.stopping.set()
            if view is not None:
                view.close()
            for announcer in announcers:
                announcer.close()
    out.flush()
    return 0 if loop else live.stop_status()
