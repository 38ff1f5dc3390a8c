"""A live 3D view of a gyroemu stream in the Foxglove app: a Foxglove WebSocket server (foxglove-sdk).

What goes out (open ``ws://localhost:8765`` in the Foxglove app, layout ``configs/foxglove/gyroemu.json``):

- the stream's ``/imu``, ``/truth/imu`` and ``/estimate/imu`` (:func:`live_view_topics`; a replay's
  every channel) under their MCAP topics, as the **same ROS 2 CDR bytes** that go over zenoh and
  into MCAP logs, with the ``ros2msg`` schema a log holds (encoding ``cdr``). The app decodes ROS 2
  messages natively, so nothing is re-encoded: forwarding a message costs one call into the SDK
  (~0.3 us without a client), and a plot in Foxglove and a field of a recorded log are the same bytes.
  Each message's ``log_time`` is its header stamp; a type without a header goes out at its log
  record's time (``gyroemu view``) or its schedule's (a live stream: the wall clock of its deadline).
  A channel without a schema (:func:`unservable`) is skipped with a warning naming it: the app could
  not decode it, and the SDK refuses it.
- ``/tf`` (``foxglove.FrameTransforms``): ``map`` -> ``base_link`` (the true attitude ``q_wb`` of
  ``/truth/imu``) and ``map`` -> ``body_estimate`` (the estimate's), each stamped with its message's
  header stamp; attitude only, no translation. A log with neither a truth nor an estimate (someone
  else's bag) has its own ``/tf`` and ``/tf_static`` forwarded instead (:func:`replaced_topics`).
- ``/tf_static`` (``foxglove.FrameTransforms``): ``base_link`` -> the IMU's frame, the device's mounting
  (:class:`Mounting`: a stream's device, a log's own ``/tf_static``), so the IMU frame shows in the 3D
  panel; with the first frame and every :data:`STATIC_EVERY` frames (the server keeps no latched
  message for an app that connects later).
- ``/scene`` (``foxglove.SceneUpdate``): the body as an opaque box with its axes (frame ``base_link``),
  the estimate as a translucent box with its axes (frame ``body_estimate``); the truth's gravity
  ``g_w = (0, 0, -1)`` (ENU, unit length) and magnetic field ``m_w`` as arrows fixed in ``map`` (from
  the body's centre); the estimate's, ``R̂_bw g_w`` and ``R̂_bw m_w`` (where the estimate puts them in
  body axes), as translucent arrows on the true body, so that they depart from the truth's by the
  estimate's tilt and heading error. ``m_w`` is the direction of the mean of ``R_wb R_bs m_s`` over the
  measured field (``/mag``, in the IMU's axes, turned into the body's by the mounting ``q_bs``; read
  but not served by a live stream's view; no field arrows without a magnetometer). The boxes and the
  truth's arrows are sent when first drawable and every 2 s; the estimate's arrows every frame.
- ``/view/errors`` (JSON, :data:`ERRORS_SCHEMA`), every :data:`ERRORS_EVERY` frames: the attitude error
  (angle and rotation vector of ``q_truth^-1 (x) q_estimate``), the filter's bias estimate (measured less
  bias-corrected rate) and the device's error against the truth (its true bias plus the mean noise),
  means over the samples since the last one: what the layout plots. All in body axes: the measured
  ``/imu`` rate ``ω_s`` is turned by the mounting, ``R_bs ω_s``, as
  :mod:`gyroemu.pipelines.estimation.mounting` turns it (``/truth/imu`` and ``/estimate/imu`` are the
  body's); an identity mounting turns nothing.

Closing the view stops its server waiting :data:`STOP_TIMEOUT_S` at most (:func:`stop_view_server`): the
SDK's ``stop()`` waits for every client, and one that stopped reading held the command forever.

``/tf`` and ``/scene`` (built with ``foxglove.messages``, encoded by the SDK) go out at a display rate
(``--foxglove-rate``, default 30 Hz), not at the IMU's. The default is the benchmark's
(``tests/benchmarks/bench_foxglove.py``): at 30 frames a second the view adds under 10 % to the CPU of
a 1 kHz stream with the app connected; at 60 it adds ~12 %, dominated by the worker's wake-ups.

Never slowing the stream
------------------------
:meth:`FoxgloveView.tap` wraps the publisher's iterable of batches (``(deadline offset ns, key,
payload)`` lists of :mod:`gyroemu.pipelines.transport.read_ahead`): as the paced publisher takes a
batch, the view is offered it with a ``put_nowait`` into a bounded queue (a full queue drops the batch:
the view loses data, the stream loses nothing). A worker thread of the view ticks at the display rate:
it forwards the messages that are due (deadline ``t_start + offset`` passed, the publisher's clock, so
the view shows what zenoh subscribers see, not the blocks the stream computed ahead; everything queued
without pacing) and draws a frame of the latest truth and estimate. One wake-up a frame: in a process
whose other threads keep the caches busy, a wake-up costs more than the work it does, so the worker
does a frame's worth at a time. Reading a frame's few fields straight from the CDR bytes
(:func:`imu_fields`) keeps a frame at ~0.2 ms. The SDK's server runs on its own threads. A live estimate
(``gyroemu stream --estimate``, published on zenoh by another session) reaches the view through a zenoh
subscriber (:meth:`FoxgloveView.follow`), drained by the worker.

From Python::

    view = FoxgloveView(ViewOptions(port=8765), channel_specs(topics), key_topics, paced=True)
    report = publisher.run_schedule(view.tap(batches))
    view.close()
"""

from __future__ import annotations

import errno
import logging
import math
import os
import queue
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    MAG_ROLE,
    POSE_ROLE,
    TRUTH_ROLE,
    WORLD_FRAME,
    split_topic,
    topic_message_type,
)
from gyroemu.pipelines.transport.read_ahead import Batch
from gyroemu.pipelines.transport.zenoh_io import drain, subscribe

if TYPE_CHECKING:
    import foxglove
    import zenoh
    from foxglove.messages import ArrowPrimitive, CubePrimitive, FrameTransforms, SceneUpdate
    from foxglove.websocket import Capability, ServerListener, WebSocketServer

    from gyroemu.pipelines.formats.mcap_records import ChannelInfo

__all__ = [
    "DEFAULT_PORT",
    "DEFAULT_RATE_HZ",
    "ESTIMATE_FRAME",
    "TF_TOPIC",
    "SCENE_TOPIC",
    "ERRORS_TOPIC",
    "VIEW_TOPICS",
    "ViewOptions",
    "ChannelSpec",
    "Mounting",
    "log_mounting",
    "channel_specs",
    "live_view_topics",
    "imu_fields",
    "log_channel_specs",
    "replaced_topics",
    "unservable",
    "check_view_options",
    "ViewOptionError",
    "start_view_server",
    "stop_view_server",
    "STOP_TIMEOUT_S",
    "ViewPublisher",
    "FoxgloveView",
]

DEFAULT_PORT = 8765
"""The Foxglove app's default WebSocket port (``ws://localhost:8765``)."""
DEFAULT_RATE_HZ = 30.0
"""Frames (``/tf`` and ``/scene``) a second, by default."""
MAX_RATE_HZ = 1000.0
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
SCENE_TOPIC = "/scene"
ERRORS_TOPIC = "/view/errors"
VIEW_TOPICS = (TF_TOPIC, TF_STATIC_TOPIC, SCENE_TOPIC, ERRORS_TOPIC)
"""The view's own topics (and ``/tf_static``): a log's channels of these names are not forwarded (but a
log's ``/tf`` and ``/tf_static`` where the view draws no tree of its own: :func:`replaced_topics`)."""
STOP_TIMEOUT_S = 2.0
"""Seconds closing the view waits for the SDK's ``WebSocketServer.stop()``, which waits for every
client's connection to close, with no limit, in native code (where the main thread sees no Ctrl-C): a
client that stopped reading (a frozen app, a laptop's lid shut) held ``stream``, ``replay`` and ``view``
forever. A client that reads closes within milliseconds; after this the command exits without waiting
(:func:`stop_view_server`)."""
QUEUE_DEPTH = 64
"""Batches waiting for the view's worker, at most (then batches are dropped, never waited for)."""
FIELD_EVERY = 8
"""Frames between two samples of the field's mean direction (a decode each)."""
ERRORS_EVERY = 4
"""Frames between two ``/view/errors`` messages (7.5 a second at 30 frames a second), each over the
messages since the last."""
STATIC_EVERY = 60
"""Frames between two publications of the scene's fixed parts (the boxes, the truth's vectors)."""
RECENT = 2048
"""Messages of each followed topic kept by stamp, to pair the estimate (late by the filter's latency)
with the measurement and the truth of its stamp."""

ERRORS_SCHEMA = {
    "type": "object",
    "title": "gyroemu view errors",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        },
        "attitude_error_rad": {"type": "number", "description": "angle of q_truth^-1 q_estimate, rad"},
        "attitude_error_xyz_rad": {
            "type": "array",
            "items": {"type": "number"},
            "description": "rotation vector of q_truth^-1 q_estimate (body axes), rad",
        },
        "bias_estimate_rad_s": {
            "type": "array",
            "items": {"type": "number"},
            "description": "the filter's gyro bias: measured - bias-corrected rate, mean over the frame",
        },
        "gyro_error_rad_s": {
            "type": "array",
            "items": {"type": "number"},
            "description": "measured rate - true rate, mean over the frame: the device's true bias plus mean noise",
        },
    },
}
"""JSON schema of :data:`ERRORS_TOPIC` (JSON messages; absent fields: not available at that frame)."""

_log = logging.getLogger(__name__)
_GRAVITY_W = np.array([0.0, 0.0, -1.0])  # ENU: gravity points to -z (interface.md), unit length
_BOX = (0.6, 0.4, 0.15)  # m, the body's box (x, y, z)
_GRAVITY_RGBA = (0.2, 0.4, 1.0, 1.0)
_FIELD_RGBA = (1.0, 0.3, 0.9, 1.0)


@dataclass(frozen=True)
class ViewOptions:
    """Where the Foxglove WebSocket server listens and how often it draws.

    Attributes
    ----------
    port : int
        TCP port (0: any free port; :attr:`FoxgloveView.port` tells which).
    rate_hz : float
        Frames (``/tf`` and ``/scene``) a second, ``0 < rate_hz <= 1000``.
    host : str
        Address to listen on (default loopback; ``0.0.0.0`` for other machines).
    """

    port: int = DEFAULT_PORT
    rate_hz: float = DEFAULT_RATE_HZ
    host: str = "127.0.0.1"


@dataclass(frozen=True)
class ChannelSpec:
    """A channel the view forwards: its topic and schema as a log holds them.

    Attributes
    ----------
    topic : str
    schema_name : str
        ``sensor_msgs/msg/Imu``, ... (empty: no schema).
    schema_encoding : str
        ``ros2msg`` for gyroemu's channels.
    schema_data : bytes
        The schema's text.
    message_encoding : str
        ``cdr``.
    stamped : bool
        The message starts with a ``std_msgs/Header``: its stamp is the message's log time.
    forward : bool
        Serve the channel; False: only read it for the scene (a live stream's ``/mag``).
    """

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str = "cdr"
    stamped: bool = True
    forward: bool = True


@dataclass(frozen=True, eq=False)
class Mounting:
    """The IMU's frame on the body: ``base_link`` -> ``frame_id`` on the view's ``/tf_static``.

    Attributes
    ----------
    frame_id : str
        The IMU's frame (``/imu``'s ``frame_id``).
    q_bs : ndarray (4,)
        Unit quaternion (w, x, y, z) turning IMU-frame vectors into body axes.
    lever_arm_m : ndarray (3,)
        The IMU's origin in body axes, m.
    """

    frame_id: str
    q_bs: NDArray[np.float64]
    lever_arm_m: NDArray[np.float64]


def log_mounting(path: str | os.PathLike[str]) -> Mounting | None:
    """The mounting a log's ``/tf_static`` holds (its first ``base_link`` -> IMU transform), or None
    (a log without one)."""
    from gyroemu.pipelines.formats.mcap_log import read_tf

    static = read_tf(path, static=True)
    rows = np.flatnonzero(static.frame_id == BODY_FRAME)
    if not len(rows):
        return None
    i = int(rows[0])
    return Mounting(str(static.child_frame_id[i]), static.q[i].copy(), static.translation[i].copy())


def channel_specs(topics: Iterable[str], read_only: Iterable[str] = ()) -> list[ChannelSpec]:
    """:class:`ChannelSpec` of gyroemu topics (their message type by role; ``ValueError`` for a topic
    without one); those of ``read_only`` are read for the scene, not served."""
    out, read_only = [], set(read_only)
    for topic in topics:
        mtype = topic_message_type(topic)
        if mtype is None:
            raise ValueError(f"topic {topic!r} has no gyroemu message type")
        out.append(
            ChannelSpec(topic, mtype.name, "ros2msg", mtype.schema.encode("utf-8"), forward=topic not in read_only)
        )
    return out


def live_view_topics(topics: Iterable[str]) -> tuple[list[str], list[str]]:
    """``(served, read only)``: the topics a live stream's view serves, the measurement, truth and
    estimate (``/imu``, ``/truth/imu``, ``/estimate/imu``, ``/truth/pose``), and those it only reads for
    the scene (``/mag``). Not the gyros' raw observables (``/raw/<kind>``): every message served costs
    the stream CPU (``tests/benchmarks/bench_foxglove.py``), and these are no part of the view."""
    roles = (IMU_ROLE, TRUTH_ROLE, ESTIMATE_ROLE, POSE_ROLE)
    topics = list(topics)
    return [t for t in topics if split_topic(t)[1] in roles], [t for t in topics if split_topic(t)[1] == MAG_ROLE]


def replaced_topics(topics: Iterable[str]) -> frozenset[str]:
    """The topics of a log (``topics``) whose channels the view's own take the place of: ``/scene`` and
    ``/view/errors`` always; ``/tf`` and ``/tf_static`` when the log has a truth or an estimate
    (``/truth/imu``, ``/estimate/imu``) for the view to draw them from. A log without either (someone
    else's bag) keeps its own tree: the view would put nothing on ``/tf``."""
    draws = any(split_topic(t)[1] in (TRUTH_ROLE, ESTIMATE_ROLE) for t in topics)
    return frozenset(VIEW_TOPICS if draws else (SCENE_TOPIC, ERRORS_TOPIC))


def unservable(schema_name: str, message_encoding: str) -> str:
    """Why the view cannot serve a channel (``''``: it can): a channel without a schema, unless it is
    JSON (``gyroemu record`` stores a topic it could not type without one; the Foxglove app decodes a
    ``cdr`` message only by its schema, and the SDK refuses such a channel)."""
    return "" if schema_name or message_encoding == "json" else "no schema"


def log_channel_specs(
    channels: Iterable[ChannelInfo], topics: Iterable[str], stamped: Iterable[str]
) -> list[ChannelSpec]:
    """:class:`ChannelSpec` of an MCAP file's channels (:class:`gyroemu.pipelines.formats.mcap_records.ChannelInfo`)
    of ``topics``, their schemas as recorded; ``stamped``: the topics whose type starts with a header.
    The channels the view's own take the place of (:func:`replaced_topics`: a log's ``/tf`` and
    ``/tf_static`` where it has a truth or an estimate, any ``/scene``, ``/view/errors``) are left out."""
    topics = list(topics)
    wanted, stamped = set(topics) - replaced_topics(topics), set(stamped)
    return [
        ChannelSpec(c.topic, c.schema_name, c.schema_encoding, c.schema_data, c.message_encoding, c.topic in stamped)
        for c in channels
        if c.topic in wanted
    ]


class ViewOptionError(ConfigError):
    """A bad Foxglove view option (port, rate, host), found before any work; the message names the argument."""


def check_view_options(
    options: ViewOptions,
    port_arg: str = "--foxglove-port",
    rate_arg: str = "--foxglove-rate",
    host_arg: str = "--host",
) -> None:
    """:class:`ViewOptionError` (a ``ValueError``) naming ``port_arg``, ``rate_arg`` or ``host_arg``
    unless the port is in 0..65535 and free on ``options.host``, the host an address of this machine
    (a name that does not resolve, or an address no interface has, is the host's fault, not the port's),
    and the rate is in (0, 1000] Hz; done before any work."""
    rate = options.rate_hz
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 < rate <= MAX_RATE_HZ):
        raise ViewOptionError(f"argument {rate_arg}: must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate}")
    port = options.port
    if not (isinstance(port, int) and 0 <= port <= 65535):
        raise ViewOptionError(f"argument {port_arg}: must be a TCP port, 0 to 65535, got {port}")
    host = options.host
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as s:
        if os.name != "nt":
            # as the SDK's listener (tokio) binds: a port whose last connection lingers in TIME_WAIT (a
            # client closed cleanly, for up to 60 s) is free to listen on; one a socket listens on (on
            # this address, 0.0.0.0 or ::) is still refused. (Not on Windows, where the option lets a
            # socket take a port another one listens on.)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))  # port 0: any free one, so only the host is checked
        except OSError as e:
            if isinstance(e, socket.gaierror) or e.errno == errno.EADDRNOTAVAIL:
                raise ViewOptionError(
                    f"argument {host_arg}: cannot listen on {host!r}: {e.strerror or e} (name an address of "
                    "this machine: 127.0.0.1, 0.0.0.0 for every interface, ::1, or a host name that resolves to one)"
                ) from None
            raise ViewOptionError(
                f"argument {port_arg}: cannot listen on {host}:{port}: {e.strerror or e} "
                "(another Foxglove server? choose another port, or 0 for any)"
            ) from None


def start_view_server(
    options: ViewOptions,
    name: str,
    *,
    capabilities: Iterable[Capability] = (),
    playback_time_range: tuple[int, int] | None = None,
    server_listener: ServerListener | None = None,
    port_arg: str = "--foxglove-port",
) -> tuple[foxglove.Context, WebSocketServer]:
    """Start a Foxglove WebSocket server on a context of its own: ``(context, server)``. ``ValueError``
    naming ``port_arg`` when it cannot listen."""
    import foxglove

    check_view_options(options, port_arg)
    context = foxglove.Context()
    try:
        server = foxglove.start_server(
            name=name,
            host=options.host,
            port=options.port,
            context=context,
            capabilities=list(capabilities) or None,
            playback_time_range=playback_time_range,
            server_listener=server_listener,
        )
    except RuntimeError as e:
        raise ValueError(f"argument {port_arg}: {options.host}:{options.port}: {e}") from None
    return context, server


def stop_view_server(server: WebSocketServer, timeout_s: float = STOP_TIMEOUT_S) -> bool:
    """Stop a server (``server.stop()``) waiting at most ``timeout_s`` (:data:`STOP_TIMEOUT_S`); True
    when it stopped. The SDK's stop waits for every client without a limit: it runs on a daemon
    thread, which a client that never reads leaves behind (the process exits without it). The wait
    is in Python, so a SIGINT or SIGTERM during it still raises in the main thread."""
    stopper = threading.Thread(target=server.stop, name="gyroemu-foxglove-stop", daemon=True)
    stopper.start()
    stopper.join(timeout_s)
    if stopper.is_alive():
        _log.warning(
            "the Foxglove server did not stop within %g s (a client that stopped reading): exiting without it",
            timeout_s,
        )
        return False
    return True


def _matrix(q: Sequence[float]) -> NDArray[np.float64]:
    """Rotation matrix ``R_wb`` (3, 3) of a unit quaternion (w, x, y, z), Hamilton convention (the
    standard closed form, e.g. Sola, "Quaternion kinematics for the error-state Kalman filter", eq. 115)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _x_to(d: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """The shortest rotation (x, y, z, w) turning +x onto unit vector ``d`` (an arrow points along its
    pose's +x): half-way quaternion ``(1 + x.d, x cross d)`` normalised."""
    c = 1.0 + d[0]
    if c < 1e-9:  # d = -x: half a turn about z
        return 0.0, 0.0, 1.0, 0.0
    v = (0.0, -d[2], d[1])  # x cross d
    n = math.sqrt(c * c + v[1] * v[1] + v[2] * v[2])
    return v[0] / n, v[1] / n, v[2] / n, c / n


_IMU_BODY = 37
"""float64 fields of ``sensor_msgs/msg/Imu`` after its header: orientation (x, y, z, w) and its covariance
(9), angular velocity (3) and its covariance (9), linear acceleration (3) and its covariance (9)."""


def imu_fields(
    payloads: list[bytes],
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_]]:
    """What the view reads of ``sensor_msgs/msg/Imu`` CDR messages, straight from their bytes:
    ``(stamp ns (N,), q_wb (N, 4) w x y z, has_q (N,), angular velocity (N, 3) rad/s, has_rate (N,))``,
    ``has_*`` False where the covariance's element 0 is -1 ("no estimate") or the quaternion is not finite.

    :meth:`gyroemu.pipelines.formats.messages.MessageType.decode` reads every field of any type and costs
    ~5 us a message; a frame reads ~60, 60 times a second, so the view reads its few fields itself, the
    messages of one frame id a numpy view at a time (~10 us). Layout (XCDR1 little endian, offsets from
    the 4-byte encapsulation header on): int32 sec, uint32 nanosec, uint32 length of the frame id
    (with its NUL) and its bytes, then, aligned to 8, the 37 float64 of :data:`_IMU_BODY`. ``ValueError``
    for a message too short for its frame id.
    """
    n = len(payloads)
    stamps = np.empty(n, dtype=np.int64)
    body = np.empty((n, _IMU_BODY))
    groups: dict[tuple[int, int], list[int]] = {}
    for i, payload in enumerate(payloads):
        groups.setdefault((len(payload), int.from_bytes(payload[12:16], "little")), []).append(i)
    for (size, name_len), index in groups.items():
        start = _body_offset(payloads[index[0]])
        if size < start + 8 * _IMU_BODY:
            raise ValueError(f"an Imu message of {size} bytes is too short for its frame id of {name_len} bytes")
        raw = np.frombuffer(b"".join([payloads[i] for i in index]), dtype=np.uint8).reshape(len(index), size)
        sec = raw[:, 4:8].copy().view("<i4")[:, 0].astype(np.int64)
        nanosec = raw[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
        stamps[index] = sec * 1_000_000_000 + nanosec
        body[index] = raw[:, start : start + 8 * _IMU_BODY].copy().view("<f8")
    q = body[:, [3, 0, 1, 2]]  # x, y, z, w -> w, x, y, z
    has_q = (body[:, 4] != -1.0) & np.all(np.isfinite(q), axis=1)
    return stamps, q, has_q, body[:, 13:16], body[:, 16] != -1.0


class _Track:
    """A followed topic: its latest message, those since the last frame, and the last :data:`RECENT` by
    header stamp (to pair topics at the same stamps)."""

    def __init__(self, topic: str | None) -> None:
        self.topic = topic
        self.payload: bytes | None = None
        self.stamp: int | None = None
        self.since: list[tuple[int, bytes]] = []
        self.by_stamp: dict[int, bytes] = {}
        self._order: deque[int] = deque()

    def add(self, payload: bytes, stamp: int) -> None:
        self.payload, self.stamp = payload, stamp
        self.since.append((stamp, payload))
        if len(self.since) > RECENT:  # no frame for a long while: keep the newest
            del self.since[: RECENT // 2]
        self.by_stamp[stamp] = payload
        self._order.append(stamp)
        if len(self._order) > RECENT:
            self.by_stamp.pop(self._order.popleft(), None)

    def take(self) -> list[tuple[int, bytes]]:
        """The messages since the last call, ``(stamp ns, payload)``."""
        out, self.since = self.since, []
        return out

    def clear(self) -> None:
        self.payload = self.stamp = None
        self.since = []
        self.by_stamp.clear()
        self._order.clear()


class ViewPublisher:
    """Forwards messages to a server's context and draws frames (``/tf``, ``/scene``) from the latest
    truth, estimate and field; used by one thread at a time.

    Parameters
    ----------
    context : foxglove.Context
        The server's context (:func:`start_view_server`).
    channels : iterable of ChannelSpec
        The forwarded channels. The first ``truth/imu`` topic's device is drawn: its ``/truth/imu``
        drives ``base_link``, its ``/estimate/imu`` ``body_estimate``, its ``/mag`` the field arrows.
        A channel the SDK cannot serve (:func:`unservable`: ``cdr`` without a schema) is skipped with a
        warning naming it. A forwarded ``/tf`` or ``/tf_static`` (a log the view draws nothing of:
        :func:`replaced_topics`) takes the place of the view's own.
    mounting : Mounting or None
        The IMU's frame on the body, published on ``/tf_static``; None: no ``/tf_static``. Its turn
        ``q_bs`` also takes the IMU's sensor-axes ``/imu`` rate and ``/mag`` field into body axes, where
        ``/truth/imu`` and ``/estimate/imu`` are (``gyroemu estimate`` writes a mounted device's
        estimate as the body's), for ``/view/errors`` and the field's arrow.

    Attributes
    ----------
    messages, frames : int
        Messages forwarded and frames drawn so far.
    skipped : dict
        ``{topic: why}`` of the channels not served.
    """

    def __init__(
        self, context: foxglove.Context, channels: Iterable[ChannelSpec], mounting: Mounting | None = None
    ) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        # sensor axes -> body axes (None: an identity mounting, nothing turned, the bytes as they were);
        # first, so that the slow part (an import, a compiled loop) does not split the channels' advertising
        self._q_bs: NDArray[np.float64] | None = None
        self._turn: Callable[[Any, NDArray[np.float64]], NDArray[np.float64]] | None = None
        if mounting is not None and np.any(np.asarray(mounting.q_bs, dtype=float)[1:] != 0.0):
            # imported only for a turned mounting: the estimation package takes ~0.6-0.9 s to import
            from gyroemu.pipelines.estimation.mounting import body_vectors, mounting_turn

            self._q_bs, self._turn = mounting_turn(mounting.q_bs), body_vectors
            if self._q_bs is not None:  # its compiled loops loaded now, not in the first frames (~0.3 s):
                for rows in (1, 2):  # one row (a field) and several (rates; q_bs broadcast, not contiguous)
                    body_vectors(np.zeros((rows, 3)), self._q_bs)

        self._channels: dict[str, tuple[foxglove.Channel | None, bool]] = {}
        self.skipped: dict[str, str] = {}
        for spec in channels:
            why = unservable(spec.schema_name, spec.message_encoding) if spec.forward else ""
            if why:
                self.skipped[spec.topic] = why
                _log.warning("Foxglove view: skipping topic %s: %s (the app cannot decode it)", spec.topic, why)
                continue
            schema = (
                foxglove.Schema(name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data)
                if spec.schema_name
                else None
            )
            channel = (
                foxglove.Channel(spec.topic, schema=schema, message_encoding=spec.message_encoding, context=context)
                if spec.forward
                else None
            )
            self._channels[spec.topic] = (channel, spec.stamped)
        roles = {topic: split_topic(topic) for topic in self._channels}
        truth = next((t for t, (_, role) in roles.items() if role == TRUTH_ROLE), None)
        estimate = next((t for t, (_, role) in roles.items() if role == ESTIMATE_ROLE), None)
        prefix = roles[truth][0] if truth else roles[estimate][0] if estimate else ""

        def of(role: str) -> _Track:
            return _Track(next((t for t, (p, r) in roles.items() if r == role and p == prefix), None))

        self.truth, self.estimate, self.mag, self.imu = of(TRUTH_ROLE), of(ESTIMATE_ROLE), of(MAG_ROLE), of(IMU_ROLE)
        tracks = (self.truth, self.estimate, self.mag, self.imu)
        self._followed = {x.topic: x for x in tracks if x.topic is not None}
        # topic -> (the SDK channel's own log, whether stamped, its track): the hot path, ~1 us a message
        self._route = {
            t: (None if c is None else c.base.log, stamped, self._followed.get(t))
            for t, (c, stamped) in self._channels.items()
        }
        forwarded = set(self.topics)
        # a log's own tree, forwarded (replaced_topics), or the view's drawn one
        self._tf = None if TF_TOPIC in forwarded else FrameTransformsChannel(TF_TOPIC, context=context)
        self.mounting = mounting
        self._tf_static = (
            None
            if mounting is None or TF_STATIC_TOPIC in forwarded
            else FrameTransformsChannel(TF_STATIC_TOPIC, context=context)
        )
        self._scene = SceneUpdateChannel(SCENE_TOPIC, context=context)
        self._errors = foxglove.Channel(ERRORS_TOPIC, schema=ERRORS_SCHEMA, context=context)
        self._field_sum = [0.0, 0.0, 0.0]
        self.field_w: NDArray[np.float64] | None = None
        self._field_seen: bytes | None = None
        self._static_drawn: dict[str, bool] = {}
        self.messages = 0
        self.frames = 0

    @property
    def topics(self) -> list[str]:
        """The served topics."""
        return [t for t, (c, _) in self._channels.items() if c is not None]

    def message(self, topic: str, payload: bytes, log_time: int | None = None) -> None:
        """Forward one message: its header stamp as log time, or, for a type without a header,
        ``log_time`` (a log's record's; None: the SDK's, now). Unknown topics are ignored."""
        route = self._route.get(topic)
        if route is None:
            return
        log, stamped, track = route
        if not stamped:
            if log is not None:
                log(payload, log_time, None)
                self.messages += 1
            return
        sec, nanosec = _STAMP.unpack_from(payload, 4)  # header.stamp after the encapsulation header
        stamp = sec * 1_000_000_000 + nanosec
        if log is not None:
            log(payload, stamp, None)
            self.messages += 1
        if track is not None:
            track.add(payload, stamp)

    def clear(self) -> None:
        """Forget the messages seen (after a seek)."""
        for track in self._followed.values():
            track.clear()

    def _mounting_transforms(self, stamp_ns: int) -> FrameTransforms:
        """``base_link`` -> the IMU's frame as ``foxglove.FrameTransforms`` stamped ``stamp_ns``."""
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3

        assert self.mounting is not None
        q, p = (np.asarray(v, dtype=float).tolist() for v in (self.mounting.q_bs, self.mounting.lever_arm_m))
        return FrameTransforms(
            transforms=[
                FrameTransform(
                    timestamp=Timestamp(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000),
                    parent_frame_id=BODY_FRAME,
                    child_frame_id=self.mounting.frame_id,
                    translation=Vector3(x=p[0], y=p[1], z=p[2]),
                    rotation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0]),
                )
            ]
        )

    def frame(self) -> bool:
        """Publish ``/tf`` of the latest truth and estimate, ``/scene``, and every :data:`ERRORS_EVERY`
        frames ``/view/errors`` over the messages since; False (nothing drawn) before a truth or an
        estimate has arrived."""
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3

        truth = _orientation(self.truth.payload, self.truth.stamp)
        estimate = _orientation(self.estimate.payload, self.estimate.stamp)
        if truth is None and estimate is None:
            return False
        self.frames += 1
        transforms = []
        for frame, att in ((BODY_FRAME, truth), (ESTIMATE_FRAME, estimate)):
            if att is None:
                continue
            t_ns, q = att
            transforms.append(
                FrameTransform(
                    timestamp=Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000),
                    parent_frame_id=WORLD_FRAME,
                    child_frame_id=frame,
                    translation=Vector3(x=0.0, y=0.0, z=0.0),
                    rotation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0]),
                )
            )
        stamp_ns = max(att[0] for att in (truth, estimate) if att is not None)
        if self._tf is not None:
            self._tf.log(FrameTransforms(transforms=transforms), log_time=stamp_ns)
        if self._tf_static is not None and self.frames % STATIC_EVERY == 1:
            self._tf_static.log(self._mounting_transforms(stamp_ns), log_time=stamp_ns)
        if self.frames % FIELD_EVERY == 1:
            self._update_field(truth)
        scene = self._scene_update(stamp_ns, truth, estimate)
        if scene is not None:
            self._scene.log(scene, log_time=stamp_ns)
        if self.frames % ERRORS_EVERY == 0:
            errors = self._error_fields()
            if errors:
                errors["timestamp"] = {"sec": stamp_ns // 1_000_000_000, "nsec": stamp_ns % 1_000_000_000}
                self._errors.log(errors, log_time=stamp_ns)
        return True

    def _error_fields(self) -> dict[str, Any]:
        """``/view/errors`` fields (:data:`ERRORS_SCHEMA`) of the messages since the last call."""
        truths, estimates = self.truth.take(), self.estimate.take()
        gyro_at, truth_at = self.imu.by_stamp, self.truth.by_stamp
        wanted: list[bytes] = []

        def rows(payloads: Iterable[bytes]) -> slice:
            start = len(wanted)
            wanted.extend(payloads)
            return slice(start, len(wanted))

        paired_truths = [(s, p) for s, p in truths if s in gyro_at]
        truth_rows, truth_gyro = rows(p for _, p in paired_truths), rows(gyro_at[s] for s, _ in paired_truths)
        paired_estimates = [(s, p) for s, p in estimates if s in gyro_at]
        estimate_rows = rows(p for _, p in paired_estimates)
        estimate_gyro = rows(gyro_at[s] for s, _ in paired_estimates)
        stamp = self.estimate.stamp
        truth_then = _orientation(truth_at.get(stamp) if stamp is not None else None, stamp)
        estimate = _orientation(self.estimate.payload, stamp)
        errors: dict[str, Any] = {}
        if wanted:
            _, _, _, rate, has_rate = imu_fields(wanted)  # one read of every message needed
            q_bs, turn = self._q_bs, self._turn

            def measured(rows: slice) -> NDArray[np.float64]:
                """``/imu``'s rates in body axes, ``R(q_bs) ω_s``, as the truth's and the estimate's are."""
                # (contiguous rows: the layout the compiled loop was loaded for in __init__)
                return rate[rows] if q_bs is None or turn is None else turn(np.ascontiguousarray(rate[rows]), q_bs)

            if truth_rows.stop > truth_rows.start and np.all(has_rate[truth_rows]):
                # the device's error against the truth: its true bias plus the window's mean noise
                errors["gyro_error_rad_s"] = np.mean(measured(truth_gyro) - rate[truth_rows], axis=0).tolist()
            if estimate_rows.stop > estimate_rows.start and np.all(has_rate[estimate_rows]):
                # the filter's bias: measured rate less its bias-corrected rate
                errors["bias_estimate_rad_s"] = np.mean(measured(estimate_gyro) - rate[estimate_rows], axis=0).tolist()
        if truth_then is not None and estimate is not None:
            # body-frame error dq = q_truth^* (x) q_estimate (Hamilton product), so q_estimate = q_truth (x) dq
            a0, a1, a2, a3 = truth_then[1]
            b0, b1, b2, b3 = estimate[1]
            a1, a2, a3 = -a1, -a2, -a3  # the conjugate
            w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
            v = (
                a0 * b1 + b0 * a1 + a2 * b3 - a3 * b2,
                a0 * b2 + b0 * a2 + a3 * b1 - a1 * b3,
                a0 * b3 + b0 * a3 + a1 * b2 - a2 * b1,
            )
            if w < 0:
                w, v = -w, (-v[0], -v[1], -v[2])
            norm = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            angle = 2.0 * math.atan2(norm, w)
            errors["attitude_error_rad"] = angle
            errors["attitude_error_xyz_rad"] = [c * angle / norm if norm > 0 else 0.0 for c in v]
        return {k: v for k, v in errors.items() if all(map(math.isfinite, np.ravel(v)))}

    def _update_field(self, truth: tuple[int, list[float]] | None) -> None:
        """Add ``R_wb R_bs m_s`` of the latest measured field (``m_s``: the IMU's axes) to the running sum
        whose direction is ``m_w``."""
        payload = self.mag.payload
        if truth is None or payload is None or payload is self._field_seen:
            return
        self._field_seen = payload
        # sensor_msgs/msg/MagneticField: the header, then (8-aligned) magnetic_field x, y, z, tesla
        m_b: tuple[float, ...] = _STRUCT_3D.unpack_from(payload, _body_offset(payload))
        if not all(map(math.isfinite, m_b)):
            return
        if self._q_bs is not None and self._turn is not None:
            m_b = tuple(self._turn(np.array([m_b]), self._q_bs)[0].tolist())  # m_b = R_bs m_s
        m_w = _rotate(truth[1], m_b)
        total = self._field_sum = [a + b for a, b in zip(self._field_sum, m_w)]
        norm = math.sqrt(sum(c * c for c in total))
        self.field_w = np.array(total) / norm if norm > 0 else None

    def _scene_update(
        self, stamp_ns: int, truth: tuple[int, list[float]] | None, estimate: tuple[int, list[float]] | None
    ) -> SceneUpdate | None:
        """The scene's changes (None: none): the estimate's vectors every frame; the boxes, their axes and
        the truth's vectors (fixed in their frames) when they first can be drawn and every
        :data:`STATIC_EVERY` frames (for clients that connect later)."""
        from foxglove.messages import Duration, SceneEntity, SceneUpdate, Timestamp

        stamp = Timestamp(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
        forever = Duration(0, 0)
        field_w = self.field_w
        static = {"body": truth is not None, "estimate": estimate is not None, "field": field_w is not None}
        entities = []
        if static != self._static_drawn or self.frames % STATIC_EVERY == 1:
            self._static_drawn = static
            axes = [np.eye(3)[i] for i in range(3)]  # x red, y green, z blue
            for name, frame_id, rgba in (
                ("body", BODY_FRAME, (0.7, 0.7, 0.7, 1.0)),
                ("estimate", ESTIMATE_FRAME, (1.0, 0.6, 0.1, 0.35)),
            ):
                if static[name]:
                    entities.append(
                        SceneEntity(
                            timestamp=stamp,
                            frame_id=frame_id,
                            id=name,
                            lifetime=forever,
                            frame_locked=True,
                            cubes=[_box(rgba)],
                            arrows=[_arrow(a, 0.5, (*a, rgba[3])) for a in axes],
                        )
                    )
            # the truth's gravity and field, fixed in the world: drawn from the body's centre
            vectors = [_arrow(_GRAVITY_W, 1.0, _GRAVITY_RGBA)]
            if field_w is not None:
                vectors.append(_arrow(field_w, 1.0, _FIELD_RGBA))
            entities.append(
                SceneEntity(timestamp=stamp, frame_id=WORLD_FRAME, id="truth_vectors", lifetime=forever, arrows=vectors)
            )
        if estimate is not None and truth is not None:
            # the estimate's gravity and field in body axes, R^_bw g_w and R^_bw m_w, drawn on the true body
            r_bw = _matrix(estimate[1]).T
            vectors = [_arrow(r_bw @ _GRAVITY_W, 1.0, (*_GRAVITY_RGBA[:3], 0.4))]
            if field_w is not None:
                vectors.append(_arrow(r_bw @ field_w, 1.0, (*_FIELD_RGBA[:3], 0.4)))
            entities.append(
                SceneEntity(
                    timestamp=stamp,
                    frame_id=BODY_FRAME,
                    id="estimate_vectors",
                    lifetime=forever,
                    frame_locked=True,
                    arrows=vectors,
                )
            )
        return SceneUpdate(entities=entities) if entities else None


_STAMP = struct.Struct("<iI")
_STRUCT_3D = struct.Struct("<3d")


def _rotate(q: list[float], v: tuple[float, ...]) -> list[float]:
    """``R(q) v`` for a unit quaternion ``q`` (w, x, y, z): ``v + 2 w (u x v) + 2 u x (u x v)``, u the
    vector part (Sola, "Quaternion kinematics for the error-state Kalman filter", eq. 116 expanded)."""
    w, x, y, z = q
    tx, ty, tz = 2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])  # 2 u x v
    return [
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    ]


def _body_offset(payload: bytes) -> int:
    """Byte offset of an Imu message's body (its float64 fields), 8-aligned after the frame id (XCDR1:
    alignment counts from the end of the 4-byte encapsulation header)."""
    return 4 + ((12 + int.from_bytes(payload[12:16], "little") + 7) & ~7)


def _orientation(payload: bytes | None, stamp: int | None) -> tuple[int, list[float]] | None:
    """``(stamp, q_wb [w, x, y, z])`` of an Imu message, None without one or without its orientation."""
    if payload is None or stamp is None:
        return None
    x, y, z, w, cov0 = struct.unpack_from("<5d", payload, _body_offset(payload))
    if cov0 == -1.0 or not all(map(math.isfinite, (x, y, z, w))):
        return None
    return stamp, [w, x, y, z]


def _arrow(direction: NDArray[np.float64], length: float, rgba: tuple[float, ...]) -> ArrowPrimitive:
    """A ``foxglove.ArrowPrimitive`` from the frame's origin along unit ``direction``, ``length`` m long."""
    from foxglove.messages import ArrowPrimitive, Color, Pose, Quaternion, Vector3

    x, y, z, w = _x_to(direction)
    return ArrowPrimitive(
        pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=x, y=y, z=z, w=w)),
        shaft_length=0.8 * length,
        shaft_diameter=0.03,
        head_length=0.2 * length,
        head_diameter=0.08,
        color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
    )


def _box(rgba: tuple[float, ...]) -> CubePrimitive:
    """A ``foxglove.CubePrimitive``: the body's box, centred on its frame's origin."""
    from foxglove.messages import Color, CubePrimitive, Pose, Quaternion, Vector3

    return CubePrimitive(
        pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
        size=Vector3(x=_BOX[0], y=_BOX[1], z=_BOX[2]),
        color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
    )


class FoxgloveView:
    """A Foxglove WebSocket server fed from a paced publisher's batches, never blocking it (see the
    module's notes).

    Parameters
    ----------
    options : ViewOptions
    channels : iterable of ChannelSpec
        The channels to forward (their topics are the values of ``key_topics``).
    key_topics : mapping
        ``{key expression: topic}`` of the batches' keys; other keys are ignored.
    paced : bool
        The batches' offsets are deadlines (ns from the publisher's start): frames go out at them.
        False: frames every ``1 / rate`` s of wall time.
    name : str
        The server's name, shown by the app.
    mounting : Mounting or None
        The IMU's frame on the body, served on ``/tf_static`` (:class:`ViewPublisher`).

    Attributes
    ----------
    port : int
        The port the server listens on.
    dropped : int
        Batches dropped because the view was behind.
    """

    def __init__(
        self,
        options: ViewOptions,
        channels: Iterable[ChannelSpec],
        key_topics: Mapping[str, str],
        *,
        paced: bool = True,
        name: str = "gyroemu",
        mounting: Mounting | None = None,
    ) -> None:
        self.options = options
        self._context, self._server = start_view_server(options, name)
        self.port: int = self._server.port
        self.publisher = ViewPublisher(self._context, channels, mounting)
        self._key_topics = dict(key_topics)
        self._paced = paced
        self._queue: queue.Queue[Batch] = queue.Queue(QUEUE_DEPTH)
        self._pending: deque[Batch] = deque()  # taken from the queue, not yet all due
        self._cursor = 0  # the first message of pending[0] not yet forwarded
        self._anchor_ns: int | None = None
        self._anchor_epoch_ns = 0  # the wall clock (ns since the epoch) at the anchor
        self._followed: list[tuple[zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]], str]] = []
        self._follow_lock = threading.Lock()
        self._stop = threading.Event()
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name="gyroemu-foxglove-view", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """``ws://host:port`` to open in the Foxglove app."""
        host = "localhost" if self.options.host in ("127.0.0.1", "0.0.0.0", "::", "::1") else self.options.host
        return f"ws://{host}:{self.port}"

    def offer(self, batch: Batch) -> bool:
        """Queue a batch for the view without waiting: False (dropped) when the view is behind. The first
        call starts the view's clock (the publisher's ``t_start``)."""
        if self._anchor_ns is None:
            self._anchor_ns, self._anchor_epoch_ns = time.monotonic_ns(), time.time_ns()
        try:
            self._queue.put_nowait(batch)
            return True
        except queue.Full:
            self.dropped += 1
            return False

    def tap(self, batches: Iterable[Batch]) -> Iterator[Batch]:
        """``batches``, unchanged, each offered to the view (:meth:`offer`) as it is taken."""
        for batch in batches:
            self.offer(batch)
            yield batch

    def follow(self, session: zenoh.Session, key_topics: Mapping[str, str]) -> None:
        """Also forward what arrives on zenoh keys (``{key: topic}``, e.g. a live estimate published by
        another session), drained by the view's worker."""
        with self._follow_lock:
            for key, topic in key_topics.items():
                self._followed.append((subscribe(session, key, capacity=1 << 14), topic))

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the worker (what is queued and due within ``timeout_s`` is still shown), the
        subscribers and the server (waiting for it :data:`STOP_TIMEOUT_S` at most:
        :func:`stop_view_server`)."""
        end = time.monotonic() + timeout_s
        while (not self._queue.empty() or self._pending) and time.monotonic() < end and self._thread.is_alive():
            time.sleep(0.01)
        self._stop.set()
        self._thread.join(timeout=5.0)
        with self._follow_lock:
            for subscriber, _ in self._followed:
                try:
                    subscriber.undeclare()
                except Exception:  # zenoh.ZError: its session has closed already
                    pass
            self._followed.clear()
        stop_view_server(self._server)

    def _drain_followed(self) -> None:
        with self._follow_lock:
            for subscriber, topic in list(self._followed):
                try:
                    samples = drain(subscriber, 1 << 12)
                except Exception:  # zenoh.ZError: its session has closed: nothing more will come
                    self._followed.remove((subscriber, topic))
                    continue
                for sample in samples:
                    self.publisher.message(topic, bytes(sample.payload.to_bytes()))

    def _run(self) -> None:
        """Tick at the display rate: forward what is due (paced: offset <= now - t_start; else all that
        is queued), then draw a frame if a truth or an estimate came in. One wake-up a frame, the
        messages forwarded a frame's worth at a time. A message of a type without a header goes out at
        its schedule's time (paced: the wall clock of its deadline; else the SDK's, now)."""
        step_ns = round(1e9 / self.options.rate_hz)
        publisher, key_topics, pending = self.publisher, self._key_topics, self._pending
        next_tick = time.monotonic_ns()
        while not self._stop.is_set():
            left = next_tick - time.monotonic_ns()
            if left > 0:
                self._stop.wait(left * 1e-9)
            now = time.monotonic_ns()
            next_tick = max(next_tick + step_ns, now - step_ns)  # keep the schedule, not a backlog
            while True:
                try:
                    pending.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            due = (now - self._anchor_ns) if self._paced and self._anchor_ns is not None else None
            epoch = self._anchor_epoch_ns  # + offset: a message's deadline on the wall clock
            before = publisher.truth.stamp, publisher.estimate.stamp
            while pending:
                batch = pending[0]
                i, n = self._cursor, len(batch)
                while i < n:
                    offset, key, payload = batch[i]
                    if due is not None and offset > due:
                        break
                    topic = key_topics.get(key)
                    if topic is not None:
                        publisher.message(topic, payload, None if due is None else epoch + offset)
                    i += 1
                if i < n:
                    self._cursor = i
                    break
                pending.popleft()
                self._cursor = 0
            self._drain_followed()
            if (publisher.truth.stamp, publisher.estimate.stamp) != before:
                publisher.frame()
