"""``gyroemu stream``: simulate a scenario through a device and publish it live over zenoh, as it computes.

Sample k's messages (``/imu``, ``/mag`` when the device has a magnetometer, ``/truth/imu``,
``/raw/<kind>``: the same CDR bytes an MCAP log of the run holds, frame ids and fields by the channel
vocabulary, :mod:`gyroemu.pipelines.formats.channels`, as
:class:`gyroemu.pipelines.formats.mcap_log.McapLogWriter` writes them) go out at ``t0 + k / rate`` on
``gyroemu/<device-name>/<topic>`` (:mod:`gyroemu.pipelines.transport.zenoh_io`), in that topic order.

The tf tree goes out too (:class:`StreamTf`), as sparse topics of the same schedule: ``/tf_static``
(``base_link`` -> the IMU's frame, ``--frame-id``, the device's mounting) at the first sample and again,
the same bytes, every second of samples (zenoh has no latching; a queryable, as for the config, would
serve only gyroemu's own recorder, while a re-publication reaches any subscriber, a ROS 2 tf2 listener
included, for one message a second), and ``/tf`` (``map`` -> ``base_link``, the truth's pose) at a
display's rate (``--tf-rate``, default 30 Hz), thinned as logs thin it
(:class:`~gyroemu.pipelines.formats.frames.TfThinning`: the first sample of every ``1/rate`` of stamps,
and the run's last), each at its sample's deadline. Keys ``gyroemu/<device-name>/tf`` and
``.../tf_static``; in ROS 2 mode the global topics ``/tf`` and ``/tf_static`` with tf2's QoS.

The run is computed a block at a time (:class:`gyroemu.sensors.device_run.DeviceRun` reading its truth
a window at a time, :mod:`gyroemu.dynamics.truth_source`): a thread (:class:`BlockProducer`) measures
and encodes each block and queues its messages, a bounded queue of a block's worth and some
(:class:`gyroemu.pipelines.transport.read_ahead.ReadAheadThread`, as ``gyroemu replay`` reads ahead),
while the publisher sends them at their deadlines
(:meth:`gyroemu.pipelines.transport.zenoh_io.PacedPublisher.run_schedule`). Memory is that of a few
blocks whatever the run's length, and the first message goes out once the queue has filled, not after
the whole run. The bytes are those of the whole run simulated and encoded at once: a run's samples do
not depend on its blocks, and ``/truth/imu``, interpolated in each block's window of truth, agrees
with the whole run's interpolation to round-off (bit for bit in practice).

How long: ``--duration`` seconds; without it, a scenario whose motion is a closed form in time
(:func:`runs_without_end`) streams until SIGINT/SIGTERM (exit status 130/143), and a recording (a bounded
span), a kind that integrates equations of motion (simulated whole before the first message) or a
motion with a magnetic environment along its path stream the scenario's own duration.

The device's resolved config (``Device.to_toml()``, with the seed and the scenario's TOML) is announced
on ``gyroemu/<device-name>/config`` (:class:`gyroemu.pipelines.transport.zenoh_io.ConfigAnnouncer`): a
queryable answers every ``get`` while the stream runs (a recorder asks when it first sees the device,
whenever it started), and the config is also put once as publishing starts. ``gyroemu record`` stores it
in the device's ``gyroemu`` metadata record, so filters run on the log start from the device's noise.

Before its clock starts the stream waits (``--wait``, default 10 s) until every key has a subscriber,
so a recorder started just after the stream loses nothing; when the wait runs out it starts anyway.
Then it waits (at most 10 s more) until the producer has filled its queue, so that the first deadlines
are not missed. After the last sample it lingers briefly so that queued messages reach their subscribers.

ROS 2 mode (``--ros2``, ``--domain``): the same bytes go on rmw_zenoh's keys instead,
``<domain>/<device>/<topic>/<type>/<RIHS01 hash>`` (``0/imu0/imu/sensor_msgs::msg::dds_::Imu_/RIHS01_7d9a...``),
and the process declares the liveliness tokens of a ROS 2 node ``gyroemu_stream_<pid>`` and of one
publisher per topic, so that ROS 2 nodes on rmw_zenoh see and subscribe to the topics
(:mod:`gyroemu.pipelines.formats.ros2_keys`).

From Python: ``run_stream(StreamOptions(scenario="smooth_manoeuvre", device="consumer_mems",
session=SessionOptions(connect=("tcp/host:7447",))))`` (:class:`StreamOptions`; the session and pacing
options are :mod:`gyroemu.pipelines.transport.zenoh_io`'s).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Generator, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, TextIO, TypeAlias

import numpy as np
from numpy.typing import NDArray

from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    MAG_ROLE,
    TRUTH_ROLE,
    WORLD_FRAME,
    encode_mag,
    encode_measured,
    encode_raw,
    encode_series,
    raw_role,
    role_message_type,
    role_topic,
    topic_message_type,
)
from gyroemu.pipelines.formats.frames import TF_STREAM_RATE_HZ
from gyroemu.pipelines.formats.imu_covariance import measurement_variances
from gyroemu.pipelines.formats.messages import split_payloads, stamps_to_ns
from gyroemu.pipelines.transport.read_ahead import BATCH, READ_AHEAD, Batch, ReadAheadThread
from gyroemu.pipelines.transport.zenoh_io import (
    SLEEP_ONLY,
    ConfigAnnouncer,
    PacingOptions,
    SessionOptions,
    check_pacing_options,
    connect_warning,
    live_session,
    open_session,
    topic_to_key,
)

if TYPE_CHECKING:
    import zenoh

    from gyroemu.dynamics import Scenario
    from gyroemu.pipelines.formats.channels import ImuSeries
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys
    from gyroemu.pipelines.transport.foxglove_view import FoxgloveView, ViewOptions
    from gyroemu.pipelines.transport.live_estimate import LiveEstimator
    from gyroemu.sensors import Device
    from gyroemu.sensors.device_run import MeasuredBlock
    from gyroemu.sensors.samples import ImuSamples

    _Variances: TypeAlias = tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]
    """``(gyro (3,), accel (3,))`` per-sample variances for ``/imu``'s covariances, each None when unknown."""

__all__ = [
    "StreamOptions",
    "encode_run",
    "encode_block",
    "topic_types",
    "runs_without_end",
    "BlockProducer",
    "SparseTopics",
    "StreamTf",
    "run_stream",
]


@dataclass(frozen=True)
class StreamOptions:
    """What ``gyroemu stream`` simulates and how it publishes it.

    Attributes
    ----------
    scenario : str
        Built-in scenario name or TOML path.
    device : str
        Built-in device name or TOML path.
    duration : float or None
        Seconds to stream; None: until SIGINT/SIGTERM where the scenario allows it
        (:func:`runs_without_end`), else the scenario's own duration.
    seed : int
        Seed of every random draw of the device.
    device_name : str
        The device's name on the wire: keys ``gyroemu/<device_name>/<topic>`` (ROS 2 topics
        ``/<device_name>/<topic>``).
    estimate : str or None
        A filter (``mekf``, ...; :mod:`gyroemu.pipelines.estimation.registry`) to run live on the stream,
        in this process but on a session of its own (:class:`gyroemu.pipelines.transport.live_estimate.LiveEstimator`),
        publishing ``gyroemu/<device_name>/estimate/imu``; None: none. Not with ROS 2 mode.
    as_fast_as_possible : bool
        Publish without pacing to the sample clock (otherwise sample k goes out at ``t0 + k / rate``,
        the device's output rate in Hz).
    start_time : str, float or None
        The stamp of the run's time 0: ISO 8601 or Unix epoch seconds
        (:func:`~gyroemu.pipelines.formats.frames.parse_start_time`); None: the wall clock when the
        stream starts.
    session : SessionOptions
        The zenoh session (and ROS 2 mode).
    pacing : PacingOptions
        Waiting for subscribers, how deadlines are waited for, lingering at the end.
    foxglove : ViewOptions or None
        Also serve a live 3D view on a Foxglove WebSocket (``--foxglove``,
        :mod:`gyroemu.pipelines.transport.foxglove_view`); None: none.
    frame_id : str or None
        The IMU's frame: ``frame_id`` of ``/imu``, ``/mag``, ``/raw/...`` and child of ``base_link`` on
        ``/tf_static`` (``--frame-id``); None: the device's name.
    tf_rate_hz : float
        ``/tf`` messages per second, at most (``--tf-rate``; :class:`StreamTf`).
    """

    scenario: str
    device: str
    duration: float | None = None
    seed: int = 0
    device_name: str = "imu0"
    estimate: str | None = None
    as_fast_as_possible: bool = False
    start_time: str | float | None = None
    session: SessionOptions = field(default_factory=SessionOptions)
    pacing: PacingOptions = field(default_factory=PacingOptions)
    foxglove: ViewOptions | None = None
    frame_id: str | None = None
    tf_rate_hz: float = TF_STREAM_RATE_HZ


def encode_run(
    samples: ImuSamples,
    truth: ImuSeries | None = None,
    *,
    start_ns: int = 0,
    variances: _Variances = (None, None),
    frame_id: str | None = None,
) -> dict[str, NDArray[np.uint8]]:
    """Topic -> ``(N, size)`` encoded rows of a device's samples (and truth), as an MCAP log holds them:
    stamps ``start_ns`` + the samples' times; ``variances``: ``(gyro (3,), accel (3,))`` per-sample
    variances for ``/imu``'s covariances (:func:`~gyroemu.pipelines.formats.imu_covariance.measurement_variances`);
    ``frame_id``: the measured channels' frame (None: the device's name)."""
    stamp_ns = stamps_to_ns(samples.t) + start_ns
    frame = frame_id or samples.device
    out = {role_topic(IMU_ROLE): encode_measured(stamp_ns, frame, samples, *variances)}
    if samples.has_mag:
        out[role_topic(MAG_ROLE)] = encode_mag(stamp_ns, frame, samples)
    if truth is not None:
        out[role_topic(TRUTH_ROLE)] = encode_series(stamps_to_ns(truth.t) + start_ns, truth)
    for kind, observables in samples.raw.items():
        if role_message_type(raw_role(kind)) is not None:
            out[role_topic(raw_role(kind))] = encode_raw(stamp_ns, frame, kind, observables)[1]
    return out


def topic_types(topics: Iterable[str]) -> dict[str, str]:
    """``{topic: ROS type name}`` of gyroemu topics (``/imu`` -> ``sensor_msgs/msg/Imu``, ...);
    ``ValueError`` for a topic that has no gyroemu message type."""
    out = {}
    for topic in topics:
        mtype = topic_message_type(topic)
        if mtype is None:
            raise ValueError(f"topic {topic!r} has no gyroemu message type")
        out[topic] = mtype.name
    return out


def stream_start_ns(options: StreamOptions) -> int:
    """The stamp of the run's time 0, ns since the Unix epoch: ``options.start_time``, or the wall clock
    now. ``ValueError`` naming ``--start-time`` for a bad one."""
    from gyroemu.pipelines.formats.frames import parse_start_time

    if options.start_time is None:
        return time.time_ns()
    return parse_start_time(options.start_time)


def _check(options: StreamOptions) -> None:
    """Refuse a bad device name or filter before the (slow) simulation: ``ValueError`` naming the argument."""
    from gyroemu.pipelines.formats.ros2_keys import ros_topic

    try:
        topic_to_key(options.device_name, role_topic(IMU_ROLE))
        if options.session.ros2:
            ros_topic(options.device_name, role_topic(IMU_ROLE))
    except ValueError as e:
        raise ValueError(f"argument --device-name: {e}") from None
    if options.start_time is not None:
        stream_start_ns(options)  # ValueError naming --start-time
    check_pacing_options(options.pacing)  # LiveOptionError naming --wait
    if options.frame_id is not None:
        from gyroemu.pipelines.formats.frames import check_frame_id

        try:
            check_frame_id(options.frame_id)
        except ValueError as e:
            raise ValueError(f"argument --frame-id: {e}") from None
    if not (math.isfinite(options.tf_rate_hz) and options.tf_rate_hz > 0):
        raise ValueError(f"argument --tf-rate: must be a positive number of Hz, got {options.tf_rate_hz}")
    if options.estimate is not None and options.session.ros2:
        raise ValueError("argument --estimate: not available with --ros2")
    if options.estimate is not None:
        from gyroemu.pipelines.estimation.registry import FilterError, filter_class, is_offline

        try:
            filter_class(options.estimate)
        except FilterError as e:
            raise ValueError(f"argument --estimate: {e}") from None
        if is_offline(options.estimate):
            raise ValueError(
                f"argument --estimate: {options.estimate} is offline (it needs the whole log): "
                "choose an online filter, or record the stream and run 'gyroemu estimate' on it"
            )
    if options.foxglove is not None:
        from gyroemu.pipelines.transport.foxglove_view import check_view_options

        check_view_options(options.foxglove)


def _start_view(options: StreamOptions, keys: dict[str, str], tf: StreamTf) -> FoxgloveView:
    """The Foxglove view of the stream's topics (and of the live estimate's), its server listening; the
    IMU's frame on the body (``tf``'s mounting) on its ``/tf_static``."""
    from gyroemu.pipelines.transport.foxglove_view import FoxgloveView, Mounting, channel_specs, live_view_topics

    assert options.foxglove is not None
    served, read = live_view_topics(list(keys) + ([role_topic(ESTIMATE_ROLE)] if options.estimate is not None else []))
    key_topics = {key: topic for topic, key in keys.items() if topic in served or topic in read}
    return FoxgloveView(
        options.foxglove,
        channel_specs(served + read, read_only=read),
        key_topics,
        paced=not options.as_fast_as_possible,
        name=f"gyroemu stream {options.device_name}",
        mounting=Mounting(tf.frame_id, tf.q_bs, tf.lever_arm_m),
    )


def _start_estimator(options: StreamOptions, dev: Device, scen: Scenario, samples: ImuSamples) -> LiveEstimator:
    """The live filter of ``options.estimate``, on a session of its own, started."""
    from gyroemu.pipelines.estimation.registry import make_filter
    from gyroemu.pipelines.estimation.setup import setup_for
    from gyroemu.pipelines.formats.frames import mounting_of
    from gyroemu.pipelines.transport.live_estimate import LiveEstimator

    assert options.estimate is not None
    setup = setup_for(dev, scen)
    mounting = mounting_of(dev)
    # a throwaway run first, so that loading the compiled kernels does not stall the paced clock
    make_filter(options.estimate, setup, argument="--estimate").process(
        samples.t[:64] - samples.t[0],
        samples.gyro[:64],
        samples.accel[:64],
        samples.mag[:64] if setup.use_mag else None,
    )
    return LiveEstimator(
        open_session(options.session.beside_config()),
        options.device_name,
        make_filter(options.estimate, setup, argument="--estimate"),
        setup.use_mag,
        tf_rate_hz=options.tf_rate_hz,  # map -> body_estimate beside the stream's map -> base_link
        q_bs=None if mounting is None else mounting[0],  # the body's estimate, not the sensor's
    ).start()


def _stream_tf(options: StreamOptions, dev: Device, first: MeasuredBlock, start_ns: int, rate: float) -> StreamTf:
    """The stream's tf tree (:class:`StreamTf`): the IMU's frame, the device's mounting, ``/tf_static``
    every :data:`~gyroemu.pipelines.formats.frames.TF_STATIC_REPEAT_S` of samples."""
    from gyroemu.pipelines.formats.frames import TF_STATIC_REPEAT_S, mounting_of

    mounting = mounting_of(dev) or (np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3))
    return StreamTf(
        options.frame_id or first.samples.device,
        mounting,
        options.tf_rate_hz,
        start_ns=start_ns,
        static_every=max(1, round(TF_STATIC_REPEAT_S * rate)),
    )


def runs_without_end(scenario: Scenario) -> bool:
    """Whether ``gyroemu stream`` without ``--duration`` streams ``scenario`` until stopped: its kind is
    pointwise (:attr:`gyroemu.dynamics.scenarios.ScenarioSpec.pointwise`) with no bounded span (a
    recording's is) and no magnetic environment along the path (simulated whole). Otherwise the
    scenario's own duration."""
    spec = scenario.spec
    site = getattr(spec, "site", None)
    return bool(spec.pointwise) and spec.max_span_s() is None and getattr(site, "magnetic_environment", None) is None


class SparseTopics(Protocol):
    """Topics with a message at some samples only (``/tf``, ``/tf_static``), for :class:`BlockProducer`.

    ``topics``: their names, in the order their messages go out at a sample they share.
    ``encode(block, k0)``: ``[(k, topic, payload), ...]`` of a block whose first sample is sample ``k0``
    of the run, ``k`` ascending in ``k0 ... k0 + len(block) - 1``. ``finish(k_last)``: what is still due
    after the run's last block (``k_last`` its last sample), in the same form."""

    topics: list[str]

    def encode(self, block: MeasuredBlock, k0: int) -> list[tuple[int, str, bytes]]: ...

    def finish(self, k_last: int) -> list[tuple[int, str, bytes]]: ...


class BlockProducer(ReadAheadThread):
    """Encodes a device run's blocks in a thread and queues their messages as batches
    ``[(round(k * 1e9 / rate), key, payload), ...]`` (k: the sample's index from the run's start),
    sample by sample, each sample's messages in the order of ``keys``.

    Dense topics (:func:`encode_block`'s, one message per sample) and sparse ones (``sparse``: a message
    at some samples, :class:`SparseTopics`) share the schedule: a sparse message of sample k goes out at
    sample k's deadline, after that sample's dense messages. The dense messages, their order, deadlines
    and batches are the same with or without sparse topics (batches hold ``BATCH // len(dense keys)``
    samples, a sparse message joining its sample's batch).

    Parameters
    ----------
    blocks : iterable of MeasuredBlock
        The run's blocks, in order from its start (a :class:`gyroemu.sensors.device_run.DeviceRun`, or
        what is left of one): iterated in the thread, a block computed as the queue has room.
    keys : dict
        ``{topic: key expression}`` of every topic a block encodes to (:func:`encode_block`), and of
        the sparse topics.
    rate : float or None
        Samples per second of the deadlines; None: every deadline 0 (as fast as possible).
    depth : int
        Batches queued ahead of the publisher, at most.
    sparse : SparseTopics or None
        The sparse topics' encoder (its topics must be in ``keys``).

    Attributes
    ----------
    samples : int
        Samples queued so far.
    """

    def __init__(
        self,
        blocks: Iterable[MeasuredBlock],
        keys: dict[str, str],
        rate: float | None,
        depth: int = READ_AHEAD,
        *,
        start_ns: int = 0,
        variances: _Variances = (None, None),
        sparse: SparseTopics | None = None,
        frame_id: str | None = None,
    ) -> None:
        super().__init__(depth, name="stream-read-ahead")
        self._blocks = blocks
        self.keys = dict(keys)
        self.sparse = sparse
        sparse_topics = [] if sparse is None else list(sparse.topics)
        missing = [t for t in sparse_topics if t not in self.keys]
        if missing:
            raise ValueError(f"sparse topics {missing} have no key")
        self.dense = [t for t in self.keys if t not in sparse_topics]
        self.rate = None if rate is None else float(rate)
        self.samples = 0
        self.start_ns = int(start_ns)
        self.variances = variances
        self.frame_id = frame_id

    def _offset(self, k: int) -> int:
        return 0 if self.rate is None else round(k * 1e9 / self.rate)

    def produce(self) -> Generator[Batch, None, None]:
        keys = [self.keys[t] for t in self.dense]
        per_batch = max(1, BATCH // len(keys))  # samples per batch
        sparse = self.sparse
        for block in self._blocks:
            k0 = self.samples
            extra = [] if sparse is None else sparse.encode(block, k0)
            encoded = encode_block(block, start_ns=self.start_ns, variances=self.variances, frame_id=self.frame_id)
            del block  # the block's arrays are not needed past its encoding
            if list(encoded) != self.dense:
                raise RuntimeError(f"a block encoded to topics {list(encoded)}, the run's first to {self.dense}")
            columns = [split_payloads(encoded[topic]) for topic in self.dense]
            del encoded
            n = len(columns[0])
            if self.rate is None:
                offsets = [0] * n
            else:
                offsets = [round(k * 1e9 / self.rate) for k in range(k0, k0 + n)]
            j = 0  # the next sparse message
            for start in range(0, n, per_batch):
                stop = min(start + per_batch, n)
                if j < len(extra) and extra[j][0] < k0 + stop:
                    batch: Batch = []
                    for i in range(start, stop):
                        batch.extend((offsets[i], key, column[i]) for key, column in zip(keys, columns))
                        while j < len(extra) and extra[j][0] == k0 + i:
                            batch.append((offsets[i], self.keys[extra[j][1]], extra[j][2]))
                            j += 1
                    yield batch
                else:
                    yield [
                        (offsets[i], key, column[i]) for i in range(start, stop) for key, column in zip(keys, columns)
                    ]
                self.samples = k0 + stop
            if j != len(extra):
                raise RuntimeError(f"sparse messages at samples {[e[0] for e in extra[j:]]} outside the block")
            del columns, offsets
        if sparse is not None and self.samples:
            tail = sparse.finish(self.samples - 1)
            if tail:
                yield [(self._offset(k), self.keys[topic], payload) for k, topic, payload in tail]


class StreamTf:
    """The tf tree of a live stream, as :class:`SparseTopics` of :class:`BlockProducer`:

    - ``/tf_static``: ``base_link`` -> the IMU's frame (the device's mounting), stamped with the run's
      first stamp, at sample 0 and again, the same bytes, every ``static_every`` samples (zenoh has no
      latching: a subscriber that joins later gets it within that period);
    - ``/tf``: ``map`` -> ``base_link``, the true pose (position: the cubic Hermite spline of the truth's
      ``pos_w``, ``vel_w``; attitude: the device's truth interpolant, at the instants the device
      sampled, as ``simulate`` writes ``/truth/pose``), at the first sample of every ``1/rate_hz`` of
      stamps and at the run's last sample (:class:`~gyroemu.pipelines.formats.frames.TfThinning`, as
      logs thin it: tf2 interpolates between the stamps and cannot extrapolate past the last).

    Parameters
    ----------
    frame_id : str
        The IMU's frame (``--frame-id``; the device's name by default).
    mounting : (q_bs (4,) w, x, y, z; lever_arm_m (3,))
        The device's mounting (:func:`~gyroemu.pipelines.formats.frames.mounting_of`).
    rate_hz : float
        ``/tf`` messages per second, at most.
    start_ns : int
        The stamp of the run's time 0, ns.
    static_every : int
        Samples between ``/tf_static`` messages.
    """

    def __init__(
        self,
        frame_id: str,
        mounting: tuple[NDArray[np.float64], NDArray[np.float64]],
        rate_hz: float,
        *,
        start_ns: int = 0,
        static_every: int = 1000,
    ) -> None:
        from gyroemu.pipelines.formats.frames import TF_STATIC_TOPIC, TF_TOPIC, TfThinning

        self.topics = [TF_STATIC_TOPIC, TF_TOPIC]
        self.frame_id = frame_id
        self.q_bs, self.lever_arm_m = (np.asarray(v, dtype=float) for v in mounting)
        self.thinning = TfThinning(rate_hz)
        self.start_ns = int(start_ns)
        self.static_every = max(1, int(static_every))
        self._static: bytes | None = None
        self._last: bytes | None = None  # the /tf message of the last sample seen

    def _tf(self, stamp_ns: NDArray[np.int64], pos_w: NDArray[np.float64], q_wb: NDArray[np.float64]) -> list[bytes]:
        from gyroemu.pipelines.formats.tf_messages import encode_tf

        rows = encode_tf(stamp_ns, [(WORLD_FRAME, BODY_FRAME)], pos_w[:, None, :], q_wb[:, None, [1, 2, 3, 0]])
        return split_payloads(rows)

    def encode(self, block: MeasuredBlock, k0: int) -> list[tuple[int, str, bytes]]:
        from scipy.interpolate import CubicHermiteSpline

        from gyroemu.pipelines.formats.tf_messages import encode_tf

        static_topic, tf_topic = self.topics
        samples = block.samples
        n = len(samples.t)
        if not n:
            return []
        stamp_ns = stamps_to_ns(samples.t) + self.start_ns
        if self._static is None:
            lever, xyzw = self.lever_arm_m[None, None], self.q_bs[None, None, [1, 2, 3, 0]]
            rows = encode_tf(stamp_ns[:1], [(BODY_FRAME, self.frame_id)], lever, xyzw)
            self._static = bytes(rows[0])
        keep = self.thinning.keep(stamp_ns)
        at = np.union1d(keep, [n - 1])  # the kept samples and the block's last
        instants = (samples.t_true if samples.t_true is not None else samples.t)[at]
        q_wb = block.interpolants.attitude_world(instants)
        truth = block.truth
        pos_w = CubicHermiteSpline(truth.t, truth.pos_w, truth.vel_w, axis=0)(instants)
        payloads = self._tf(stamp_ns[at], pos_w, q_wb)
        self._last = payloads[-1]
        tf_at = {k0 + i: p for i, p in zip(at.tolist(), payloads)}
        kept = {k0 + i for i in keep.tolist()}
        first_static = -(-k0 // self.static_every) * self.static_every
        statics = set(range(first_static, k0 + n, self.static_every))
        out: list[tuple[int, str, bytes]] = []
        for k in sorted(statics | kept):
            if k in statics:
                out.append((k, static_topic, self._static))
            if k in kept:
                out.append((k, tf_topic, tf_at[k]))
        return out

    def finish(self, k_last: int) -> list[tuple[int, str, bytes]]:
        if self._last is not None and self.thinning.last():
            return [(k_last, self.topics[1], self._last)]
        return []


def encode_block(
    block: MeasuredBlock, *, start_ns: int = 0, variances: _Variances = (None, None), frame_id: str | None = None
) -> dict[str, NDArray[np.uint8]]:
    """Topic -> encoded rows of one block of a device run (:class:`gyroemu.sensors.device_run.MeasuredBlock`):
    :func:`encode_run` of its samples and of its ``/truth/imu`` (interpolated in the block's truth window)."""
    from gyroemu.pipelines.formats.mcap_log import truth_series

    truth = truth_series(block.truth, block.samples, block.interpolants)
    return encode_run(block.samples, truth, start_ns=start_ns, variances=variances, frame_id=frame_id)


def run_stream(options: StreamOptions, *, out: TextIO = sys.stdout) -> int:
    """Simulate, encode and publish a block at a time (see the module's notes); progress goes to ``out``.
    Returns the exit status (0, or 130 when stopped by SIGINT, 143 by SIGTERM). Raises ``ValueError`` naming the
    argument at fault, before simulating."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys
    from gyroemu.sensors import load_device

    config = options.session.config()
    ros = Ros2Keys(options.session.domain, "stream") if options.session.ros2 else None
    _check(options)
    scen = load_scenario(options.scenario)
    longest = scen.spec.max_span_s()  # a recording's span: its motion stops there
    if options.duration is not None and longest is not None and options.duration > longest * (1 + 1e-9):
        raise ValueError(f"argument --duration: {options.duration:g} s is longer than the recording's {longest:.6g} s")
    dev = load_device(options.device, seed=options.seed)
    # Opened before any work: a taken --listen port or a client with no router is named first (it was
    # named after the first block had been computed and announced). Closed by live_session below, or here
    # on anything that stops the stream before that.
    session = open_session(config)
    try:
        return _stream_on(options, session, ros, scen, dev, out)
    except BaseException:
        session.close()  # closing twice is harmless: live_session may have closed it already
        raise


def _stream_on(
    options: StreamOptions,
    session: zenoh.Session,
    ros: Ros2Keys | None,
    scen: Scenario,
    dev: Device,
    out: TextIO,
) -> int:
    """The stream of :func:`run_stream` on its open ``session`` (checked options, loaded configs)."""
    from gyroemu.dynamics.truth_source import ScenarioTruth, simulated_whole, truth_source
    from gyroemu.pipelines.formats.ros2_keys import ros_topic, type_hash
    from gyroemu.pipelines.formats.tf_messages import TF_DEFINITIONS, TF_MESSAGE_TYPE
    from gyroemu.pipelines.jobs.disk_space import whole_truth_problem

    device_name, pacing = options.device_name, options.pacing
    started = time.perf_counter()
    endless = options.duration is None and runs_without_end(scen)
    # an integrated kind is simulated whole here (truth_source); a pointwise one is read window by window
    if not endless and simulated_whole(scen):
        problem = whole_truth_problem(scen, options.duration)
        if problem is not None:
            raise ValueError(problem)
    source = ScenarioTruth(scen, None) if endless else truth_source(scen, options.duration)
    run = dev.run(source)
    blocks = iter(run)
    first = next(blocks)  # computed here: it names the topics, and the live filter warms up on it
    start_ns = stream_start_ns(options)
    variances = measurement_variances(dev) or (None, None)
    topics = list(encode_block(first, start_ns=start_ns, variances=variances, frame_id=options.frame_id))
    rate = float(dev.spec.rate_hz)
    tf = _stream_tf(options, dev, first, start_ns, rate)
    if ros is not None:
        types = topic_types(topics)
        keys = {topic: ros.key(ros_topic(device_name, topic), types[topic]) for topic in topics}
        tf_hash = type_hash(TF_MESSAGE_TYPE, TF_DEFINITIONS)
        keys.update({topic: ros.key(ros_topic(device_name, topic), TF_MESSAGE_TYPE, tf_hash) for topic in tf.topics})
    else:
        keys = {topic: topic_to_key(device_name, topic) for topic in topics + tf.topics}
    what = "until stopped (Ctrl-C)" if run.count is None else f"{run.count} samples"
    print(
        f"stream: {scen.name} through {dev.name}: {what} at {rate:g} Hz, {len(keys)} topics "
        f"(computed and sent in blocks of {run.block_samples} samples; the first ready in "
        f"{time.perf_counter() - started:.2f} s)",
        file=out,
        flush=True,
    )
    # The queue holds a block's messages and some: the next block is computed while it drains.
    depth = READ_AHEAD + math.ceil(run.block_samples / max(1, BATCH // len(topics)))
    pace = None if options.as_fast_as_possible else rate
    producer = BlockProducer(
        itertools.chain([first], blocks),
        keys,
        pace,
        depth,
        start_ns=start_ns,
        variances=variances,
        sparse=tf,
        frame_id=options.frame_id,
    )
    estimator = view = None
    try:
        if options.foxglove is not None:
            view = _start_view(options, keys, tf)
            print(f"stream: Foxglove view on {view.url} ({options.foxglove.rate_hz:g} Hz)", file=out, flush=True)
        if options.estimate is not None:
            estimator = _start_estimator(options, dev, scen, first.samples)
        del first
        producer.start()  # fills its queue while subscribers are waited for
        if estimator is not None:
            print(f"  {estimator.key} ({options.estimate}, {'9D' if estimator.use_mag else '6D'}, live)", file=out)
            if view is not None:
                view.follow(session, {estimator.key: role_topic(ESTIMATE_ROLE)})
        with live_session(session) as live:
            live.node = ros
            warning = connect_warning(session, options.session.connect)
            if warning:
                print(f"stream: {warning}", file=out, flush=True)
            # the device's config, for recorders: answered to every get for as long as the stream runs
            announcer = ConfigAnnouncer(session, device_name, dev.to_toml(), options.seed, scen.to_toml())
            timing = SLEEP_ONLY if options.as_fast_as_possible else pacing.timing
            publisher = live.publish(list(keys.values()), timing)
            for key in keys.values():
                print(f"  {key}", file=out)
            print(f"  {announcer.key} (the device's config, queryable)", file=out)
            if ros is not None:
                ros.declare(session, out)
            stop = live.stopped
            wait_s = pacing.wait_s
            if wait_s > 0 and not publisher.wait_for_subscribers(wait_s, stop=stop):
                print(f"stream: no subscriber on every key after {wait_s:g} s: publishing anyway", file=out)
            # The producer's start-up would compete with the first deadlines for the GIL: start the clock
            # once its queue is full (at most 10 s from here), as replay does.
            end = time.monotonic() + 10.0
            while not producer.ready.wait(0.1) and not stop() and time.monotonic() < end:
                pass
            announcer.announce()
            print("stream: publishing", file=out, flush=True)
            batches = producer.batches(stop)
            report = publisher.run_schedule(batches if view is None else view.tap(batches), stop=stop)
            print(f"stream: sent {report.messages} messages", file=out)
            if not options.as_fast_as_possible:
                print(f"stream: {report.summary()}", file=out)
            time.sleep(pacing.linger_s)  # let queued messages drain before the session closes
            if estimator is not None:
                estimator.close(drain_s=2.0)
                print(f"stream: {estimator.published} estimates published", file=out)
                estimator = None
            announcer.close()
    finally:
        producer.stopping.set()
        if producer.is_alive():
            producer.join(timeout=10.0)  # it stops at its next batch, a block's computation at most
        if estimator is not None:
            estimator.close(drain_s=0.0)
        if view is not None:
            view.close()
            if view.dropped:
                print(f"stream: the Foxglove view dropped {view.dropped} batches (behind)", file=out)
    out.flush()
    return live.stop_status()
