"""``gyroemu stream``: simulate a scenario through a device and publish it live over zenoh, as it computes.

Sample k's messages (``/imu``, ``/mag`` when the device has a magnetometer, ``/truth/imu``,
``/raw/<kind>``: the same CDR bytes an MCAP log of the run holds, frame ids and fields by the channel
vocabulary, :mod:`gyroemu.pipelines.formats.channels`, as
:class:`gyroemu.pipelines.formats.mcap_log.McapLogWriter` writes them) go out at ``t0 + k / rate`` on
``gyroemu/<device-name>/<topic>`` (:mod:`gyroemu.pipelines.transport.zenoh_io`), in that topic order.

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
(:func:`runs_without_end`) streams until SIGINT/SIGTERM (exit status 130), and a recording (a bounded
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
from typing import TYPE_CHECKING, TextIO

import numpy as np

from gyroemu.pipelines.formats.channels import (
    IMU_ROLE,
    MAG_ROLE,
    TRUTH_ROLE,
    encode_mag,
    encode_measured,
    encode_raw,
    encode_series,
    raw_role,
    role_message_type,
    role_topic,
    topic_message_type,
)
from gyroemu.pipelines.formats.messages import split_payloads, stamps_to_ns
from gyroemu.pipelines.transport.read_ahead import BATCH, READ_AHEAD, Batch, ReadAheadThread
from gyroemu.pipelines.transport.zenoh_io import (
    SLEEP_ONLY,
    ConfigAnnouncer,
    PacingOptions,
    SessionOptions,
    connect_warning,
    live_session,
    open_session,
    topic_to_key,
)

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.pipelines.formats.channels import ImuSeries
    from gyroemu.pipelines.transport.live_estimate import LiveEstimator
    from gyroemu.sensors import Device
    from gyroemu.sensors.device_run import MeasuredBlock
    from gyroemu.sensors.samples import ImuSamples

__all__ = [
    "StreamOptions",
    "encode_run",
    "encode_block",
    "topic_types",
    "runs_without_end",
    "BlockProducer",
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
    session : SessionOptions
        The zenoh session (and ROS 2 mode).
    pacing : PacingOptions
        Waiting for subscribers, how deadlines are waited for, lingering at the end.
    """

    scenario: str
    device: str
    duration: float | None = None
    seed: int = 0
    device_name: str = "imu0"
    estimate: str | None = None
    as_fast_as_possible: bool = False
    session: SessionOptions = field(default_factory=SessionOptions)
    pacing: PacingOptions = field(default_factory=PacingOptions)


def encode_run(samples: ImuSamples, truth: ImuSeries | None = None) -> dict[str, np.ndarray]:
    """Topic -> ``(N, size)`` encoded rows of a device's samples (and truth), as an MCAP log holds them."""
    stamp_ns = stamps_to_ns(samples.t)
    frame = samples.device
    out = {role_topic(IMU_ROLE): encode_measured(stamp_ns, frame, samples)}
    if samples.has_mag:
        out[role_topic(MAG_ROLE)] = encode_mag(stamp_ns, frame, samples)
    if truth is not None:
        out[role_topic(TRUTH_ROLE)] = encode_series(stamps_to_ns(truth.t), truth)
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


def _check(options: StreamOptions) -> None:
    """Refuse a bad device name or filter before the (slow) simulation: ``ValueError`` naming the argument."""
    from gyroemu.pipelines.formats.ros2_keys import ros_topic

    try:
        topic_to_key(options.device_name, role_topic(IMU_ROLE))
        if options.session.ros2:
            ros_topic(options.device_name, role_topic(IMU_ROLE))
    except ValueError as e:
        raise ValueError(f"argument --device-name: {e}") from None
    if options.estimate is not None and options.session.ros2:
        raise ValueError("argument --estimate: not available with --ros2")
    if options.estimate is not None:
        from gyroemu.pipelines.estimation.registry import FilterError, filter_class

        try:
            filter_class(options.estimate)
        except FilterError as e:
            raise ValueError(f"argument --estimate: {e}") from None


def _start_estimator(options: StreamOptions, dev: Device, scen: Scenario, samples: ImuSamples) -> LiveEstimator:
    """The live filter of ``options.estimate``, on a session of its own, started."""
    from gyroemu.pipelines.estimation.registry import make_filter
    from gyroemu.pipelines.estimation.setup import setup_for
    from gyroemu.pipelines.transport.live_estimate import LiveEstimator

    assert options.estimate is not None
    setup = setup_for(dev, scen)
    # a throwaway run first, so that loading the compiled kernels does not stall the paced clock
    make_filter(options.estimate, setup).process(
        samples.t[:64] - samples.t[0],
        samples.gyro[:64],
        samples.accel[:64],
        samples.mag[:64] if setup.use_mag else None,
    )
    return LiveEstimator(
        open_session(options.session.config()),
        options.device_name,
        make_filter(options.estimate, setup),
        setup.use_mag,
    ).start()


def runs_without_end(scenario: Scenario) -> bool:
    """Whether ``gyroemu stream`` without ``--duration`` streams ``scenario`` until stopped: its kind is
    pointwise (:attr:`gyroemu.dynamics.scenarios.ScenarioSpec.pointwise`) with no bounded span (a
    recording's is) and no magnetic environment along the path (simulated whole). Otherwise the
    scenario's own duration."""
    spec = scenario.spec
    site = getattr(spec, "site", None)
    return bool(spec.pointwise) and spec.max_span_s() is None and getattr(site, "magnetic_environment", None) is None


class BlockProducer(ReadAheadThread):
    """Encodes a device run's blocks in a thread and queues their messages as batches
    ``[(round(k * 1e9 / rate), key, payload), ...]`` (k: the sample's index from the run's start),
    sample by sample, each sample's messages in the order of ``keys``.

    Parameters
    ----------
    blocks : iterable of MeasuredBlock
        The run's blocks, in order from its start (a :class:`gyroemu.sensors.device_run.DeviceRun`, or
        what is left of one): iterated in the thread, a block computed as the queue has room.
    keys : dict
        ``{topic: key expression}`` of every topic a block encodes to (:func:`encode_block`).
    rate : float or None
        Samples per second of the deadlines; None: every deadline 0 (as fast as possible).
    depth : int
        Batches queued ahead of the publisher, at most.

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
    ) -> None:
        super().__init__(depth, name="stream-read-ahead")
        self._blocks = blocks
        self.keys = dict(keys)
        self.rate = None if rate is None else float(rate)
        self.samples = 0

    def produce(self) -> Generator[Batch, None, None]:
        keys = list(self.keys.values())
        per_batch = max(1, BATCH // len(keys))  # samples per batch
        for block in self._blocks:
            encoded = encode_block(block)
            del block  # the block's arrays are not needed past its encoding
            if list(encoded) != list(self.keys):
                raise RuntimeError(f"a block encoded to topics {list(encoded)}, the run's first to {list(self.keys)}")
            columns = [split_payloads(encoded[topic]) for topic in self.keys]
            del encoded
            n, k0 = len(columns[0]), self.samples
            if self.rate is None:
                offsets = [0] * n
            else:
                offsets = [round(k * 1e9 / self.rate) for k in range(k0, k0 + n)]
            for start in range(0, n, per_batch):
                stop = min(start + per_batch, n)
                yield [(offsets[i], key, column[i]) for i in range(start, stop) for key, column in zip(keys, columns)]
                self.samples = k0 + stop
            del columns, offsets


def encode_block(block: MeasuredBlock) -> dict[str, np.ndarray]:
    """Topic -> encoded rows of one block of a device run (:class:`gyroemu.sensors.device_run.MeasuredBlock`):
    :func:`encode_run` of its samples and of its ``/truth/imu`` (interpolated in the block's truth window)."""
    from gyroemu.pipelines.formats.mcap_log import truth_series

    return encode_run(block.samples, truth_series(block.truth, block.samples, block.interpolants))


def run_stream(options: StreamOptions, *, out: TextIO = sys.stdout) -> int:
    """Simulate, encode and publish a block at a time (see the module's notes); progress goes to ``out``.
    Returns the exit status (0, or 130 when stopped by SIGINT/SIGTERM). Raises ``ValueError`` naming the
    argument at fault, before simulating."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.dynamics.truth_source import ScenarioTruth, truth_source
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys, ros_topic
    from gyroemu.sensors import load_device

    config = options.session.config()
    ros = Ros2Keys(options.session.domain, "stream") if options.session.ros2 else None
    _check(options)
    device_name, pacing = options.device_name, options.pacing
    scen = load_scenario(options.scenario)
    dev = load_device(options.device, seed=options.seed)
    started = time.perf_counter()
    endless = options.duration is None and runs_without_end(scen)
    # an integrated kind is simulated whole here (truth_source); a pointwise one is read window by window
    source = ScenarioTruth(scen, None) if endless else truth_source(scen, options.duration)
    run = dev.run(source)
    blocks = iter(run)
    first = next(blocks)  # computed here: it names the topics, and the live filter warms up on it
    topics = list(encode_block(first))
    if ros is not None:
        types = topic_types(topics)
        keys = {topic: ros.key(ros_topic(device_name, topic), types[topic]) for topic in topics}
    else:
        keys = {topic: topic_to_key(device_name, topic) for topic in topics}
    rate = float(dev.spec.rate_hz)
    what = "until stopped (Ctrl-C)" if run.count is None else f"{run.count} samples"
    print(
        f"stream: {scen.name} through {dev.name}: {what} at {rate:g} Hz, {len(keys)} topics "
        f"(computed and sent in blocks of {run.block_samples} samples; the first ready in "
        f"{time.perf_counter() - started:.2f} s)",
        file=out,
        flush=True,
    )
    # The queue holds a block's messages and some: the next block is computed while it drains.
    depth = READ_AHEAD + math.ceil(run.block_samples / max(1, BATCH // len(keys)))
    pace = None if options.as_fast_as_possible else rate
    producer = BlockProducer(itertools.chain([first], blocks), keys, pace, depth)
    estimator = None
    try:
        if options.estimate is not None:
            estimator = _start_estimator(options, dev, scen, first.samples)
        del first
        producer.start()  # fills its queue while the session opens and subscribers are waited for
        session = open_session(config)
        if estimator is not None:
            print(f"  {estimator.key} ({options.estimate}, {'9D' if estimator.use_mag else '6D'}, live)", file=out)
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
            report = publisher.run_schedule(producer.batches(stop), stop=stop)
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
    out.flush()
    return 130 if live.stopped() else 0
