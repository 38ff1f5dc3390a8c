"""``gyroemu stream``: simulate a scenario through a device, then publish it live over zenoh.

The whole run is simulated and encoded first (the same CDR bytes an MCAP log of the run holds: frame
ids and fields by the channel vocabulary, :mod:`gyroemu.pipelines.channels`, as
:class:`gyroemu.pipelines.mcap_log.McapLogWriter` writes them), then sample k's messages
(``/imu``, ``/mag`` when the device has a magnetometer, ``/truth/imu``, ``/raw/<kind>``) go out at
``t0 + k / rate`` on ``gyroemu/<device-name>/<topic>`` (:mod:`gyroemu.pipelines.zenoh_io`).

Before its clock starts the stream waits (``--wait``, default 10 s) until every key has a subscriber,
so a recorder started just after the stream loses nothing; when the wait runs out it starts anyway.
After the last sample it lingers briefly so that queued messages reach their subscribers.

ROS 2 mode (``--ros2``, ``--domain``): the same bytes go on rmw_zenoh's keys instead,
``<domain>/<device>/<topic>/<type>/<RIHS01 hash>`` (``0/imu0/imu/sensor_msgs::msg::dds_::Imu_/RIHS01_7d9a...``),
and the process declares the liveliness tokens of a ROS 2 node ``gyroemu_stream_<pid>`` and of one
publisher per topic, so that ROS 2 nodes on rmw_zenoh see and subscribe to the topics
(:mod:`gyroemu.pipelines.ros2_keys`).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from .channels import (
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
from .messages import split_payloads, stamps_to_ns
from .zenoh_io import PacedPublisher, open_session, session_config, stop_on_signals, topic_to_key

if TYPE_CHECKING:
    from gyroemu.sensors.samples import ImuSamples

    from .channels import ImuSeries
    from .ros2_keys import Ros2Node

__all__ = ["encode_run", "topic_types", "run_stream", "Ros2Keys"]


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


class Ros2Keys:
    """Keys and graph tokens of a ROS 2 mode publisher (``--ros2``): one ROS 2 node per process, a
    publisher token per key. :meth:`key` gives a topic's rmw_zenoh key; :meth:`declare` the tokens."""

    def __init__(self, domain: int | None, command: str):
        from .ros2_keys import domain_id, node_name

        self.domain = domain_id(domain)  # Ros2Error (a ValueError) names --domain or ROS_DOMAIN_ID
        self.node_name = node_name(command)
        self.node: Ros2Node | None = None
        self.publishers: dict[str, tuple[str, str, str]] = {}  # key -> (ROS topic, type, hash)

    def key(self, ros_topic: str, type_name: str, type_hash: str | None = None) -> str:
        from .ros2_keys import data_key
        from .ros2_keys import type_hash as compute

        type_hash = type_hash or compute(type_name)
        key = data_key(self.domain, ros_topic, type_name, type_hash)
        self.publishers[key] = (ros_topic, type_name, type_hash)
        return key

    def declare(self, session, out) -> None:
        """Declare the node's and the publishers' liveliness tokens on ``session`` and print them."""
        from .ros2_keys import Ros2Node

        self.node = Ros2Node(session, self.domain, self.node_name)
        print(f"  ROS 2 domain {self.domain}, node /{self.node_name}; liveliness tokens:", file=out)
        print(f"    {self.node.keys[0]}", file=out)
        for ros_topic, type_name, type_hash in self.publishers.values():
            print(f"    {self.node.publisher(ros_topic, type_name, type_hash)}", file=out)

    def close(self) -> None:
        if self.node is not None:
            self.node.close()


def run_stream(
    *,
    scenario: str,
    device: str,
    duration: float | None = None,
    seed: int = 0,
    as_fast_as_possible: bool = False,
    device_name: str = "imu0",
    wait_s: float = 10.0,
    connect=None,
    listen=None,
    mode=None,
    config_file=None,
    ros2: bool = False,
    domain: int | None = None,
    estimate: str | None = None,
    out=sys.stdout,
) -> int:
    """Simulate, encode and publish (see the module's notes); returns the exit status (0, or 130 when
    stopped by SIGINT/SIGTERM). Raises ``ValueError`` naming the argument at fault, before simulating.

    ``estimate``: a filter name (``mekf``, ...; see :mod:`gyroemu.pipelines.estimation.registry`) to run live on
    the stream, in this process but on a session of its own (:class:`gyroemu.pipelines.live_estimate.LiveEstimator`),
    publishing ``gyroemu/<device>/estimate/imu``."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.sensors import load_device

    from .mcap_log import truth_series
    from .ros2_keys import ros_topic

    config = session_config(connect=connect, listen=listen, mode=mode, config_file=config_file)
    ros = Ros2Keys(domain, "stream") if ros2 else None
    try:
        topic_to_key(device_name, role_topic(IMU_ROLE))  # checks the device name before the (slow) simulation
        if ros is not None:
            ros_topic(device_name, role_topic(IMU_ROLE))
    except ValueError as e:
        raise ValueError(f"argument --device-name: {e}") from None
    if estimate is not None and ros is not None:
        raise ValueError("argument --estimate: not available with --ros2")
    if estimate is not None:
        from .estimation.registry import FilterError, filter_class

        try:
            filter_class(estimate)
        except FilterError as e:
            raise ValueError(f"argument --estimate: {e}") from None
    scen = load_scenario(scenario)
    dev = load_device(device, seed=seed)
    started = time.perf_counter()
    traj = scen.simulate(duration=duration)
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
    if estimate is not None:
        from .estimation.registry import make_filter
        from .estimation.setup import setup_for
        from .live_estimate import LiveEstimator

        setup = setup_for(dev, scen)
        # a throwaway run first, so that loading the compiled kernels does not stall the paced clock
        make_filter(estimate, setup).process(
            samples.t[:64] - samples.t[0],
            samples.gyro[:64],
            samples.accel[:64],
            samples.mag[:64] if setup.use_mag else None,
        )
        estimator = LiveEstimator(
            open_session(config), device_name, make_filter(estimate, setup), setup.use_mag
        ).start()
        print(f"  {estimator.key} ({estimate}, {'9D' if setup.use_mag else '6D'}, live)", file=out)
    publisher = None
    with stop_on_signals() as stopping:
        try:
            publisher = PacedPublisher(session, list(batches))
            for key in batches:
                print(f"  {key}", file=out)
            if ros is not None:
                ros.declare(session, out)
            if wait_s > 0 and not publisher.wait_for_subscribers(wait_s, stop=lambda: bool(stopping)):
                print(f"stream: no subscriber on every key after {wait_s:g} s: publishing anyway", file=out)
            print("stream: publishing", file=out, flush=True)
            report = publisher.run(batches, None if as_fast_as_possible else rate, stop=lambda: bool(stopping))
            print(f"stream: sent {report.messages} messages", file=out)
            if not as_fast_as_possible:
                print(f"stream: {report.summary()}", file=out)
            time.sleep(0.5)  # let queued messages drain before the session closes
            if estimator is not None:
                estimator.close(drain_s=2.0)
                print(f"stream: {estimator.published} estimates published", file=out)
                estimator = None
        finally:
            if estimator is not None:
                estimator.close(drain_s=0.0)
            if publisher is not None:
                publisher.close()
            if ros is not None:
                ros.close()
            session.close()
    out.flush()
    return 130 if stopping else 0
