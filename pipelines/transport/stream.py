"""``gyroemu stream``: simulate a scenario through a device, then publish it live over zenoh.

The whole run is simulated and encoded first (the same CDR bytes an MCAP log of the run holds: frame
ids and fields by the channel vocabulary, :mod:`gyroemu.pipelines.formats.channels`, as
:class:`gyroemu.pipelines.formats.mcap_log.McapLogWriter` writes them), then sample k's messages
(``/imu``, ``/mag`` when the device has a magnetometer, ``/truth/imu``, ``/raw/<kind>``) go out at
``t0 + k / rate`` on ``gyroemu/<device-name>/<topic>`` (:mod:`gyroemu.pipelines.transport.zenoh_io`).

Before its clock starts the stream waits (``--wait``, default 10 s) until every key has a subscriber,
so a recorder started just after the stream loses nothing; when the wait runs out it starts anyway.
After the last sample it lingers briefly so that queued messages reach their subscribers.

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

import sys
import time
from collections.abc import Iterable
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
from gyroemu.pipelines.transport.zenoh_io import PacingOptions, SessionOptions, live_session, open_session, topic_to_key

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.pipelines.formats.channels import ImuSeries
    from gyroemu.pipelines.transport.live_estimate import LiveEstimator
    from gyroemu.sensors import Device
    from gyroemu.sensors.samples import ImuSamples

__all__ = ["StreamOptions", "encode_run", "topic_types", "run_stream"]


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
        Seconds to simulate; None: the scenario's.
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


def run_stream(options: StreamOptions, *, out: TextIO = sys.stdout) -> int:
    """Simulate, encode and publish (see the module's notes); progress goes to ``out``. Returns the exit
    status (0, or 130 when stopped by SIGINT/SIGTERM). Raises ``ValueError`` naming the argument at
    fault, before simulating."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.mcap_log import truth_series
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys, ros_topic
    from gyroemu.sensors import load_device

    config = options.session.config()
    ros = Ros2Keys(options.session.domain, "stream") if options.session.ros2 else None
    _check(options)
    device_name, pacing = options.device_name, options.pacing
    scen = load_scenario(options.scenario)
    dev = load_device(options.device, seed=options.seed)
    started = time.perf_counter()
    traj = scen.simulate(duration=options.duration)
    samples = dev.measure(traj)
    encoded = encode_run(samples, truth_series(traj, samples))
    if ros is not None:
        types = topic_types(encoded)
        batches = {
            ros.key(ros_topic(device_name, topic), types[topic]): split_payloads(rows)
            for topic, rows in encoded.items()
        }
    else:
        batches = {topic_to_key(device_name, topic): split_payloads(rows) for topic, rows in encoded.items()}
    del encoded  # the batches hold the bytes now (half the memory of a long run)
    n = len(samples.t)
    rate = (n - 1) / float(samples.t[-1] - samples.t[0]) if n > 1 else dev.spec.rate_hz
    rate = float(dev.spec.rate_hz) if dev.spec.rate_hz else rate
    print(
        f"stream: {scen.name} through {dev.name}: {n} samples at {rate:g} Hz, {len(batches)} topics "
        f"(encoded in {time.perf_counter() - started:.2f} s)",
        file=out,
        flush=True,
    )

    session = open_session(config)
    estimator = None
    if options.estimate is not None:
        estimator = _start_estimator(options, dev, scen, samples)
        print(f"  {estimator.key} ({options.estimate}, {'9D' if estimator.use_mag else '6D'}, live)", file=out)
    with live_session(session) as live:
        try:
            live.node = ros
            publisher = live.publish(list(batches), pacing.timing)
            for key in batches:
                print(f"  {key}", file=out)
            if ros is not None:
                ros.declare(session, out)
            wait_s = pacing.wait_s
            if wait_s > 0 and not publisher.wait_for_subscribers(wait_s, stop=live.stopped):
                print(f"stream: no subscriber on every key after {wait_s:g} s: publishing anyway", file=out)
            print("stream: publishing", file=out, flush=True)
            report = publisher.run(batches, None if options.as_fast_as_possible else rate, stop=live.stopped)
            print(f"stream: sent {report.messages} messages", file=out)
            if not options.as_fast_as_possible:
                print(f"stream: {report.summary()}", file=out)
            time.sleep(pacing.linger_s)  # let queued messages drain before the session closes
            if estimator is not None:
                estimator.close(drain_s=2.0)
                print(f"stream: {estimator.published} estimates published", file=out)
                estimator = None
        finally:
            if estimator is not None:
                estimator.close(drain_s=0.0)
    out.flush()
    return 130 if live.stopped() else 0
