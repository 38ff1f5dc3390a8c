"""``gyroemu stream``: simulate a scenario through a device, then publish it live over zenoh.

The whole run is simulated and encoded first (the same CDR bytes an MCAP log of the run holds: frame
ids and fields as :class:`pipelines.mcap_io.McapLogWriter` writes them), then sample k's messages
(``/imu``, ``/mag`` when the device has a magnetometer, ``/truth/imu``, ``/raw/<kind>``) go out at
``t0 + k / rate`` on ``gyroemu/<device-name>/<topic>`` (:mod:`pipelines.zenoh_io`).

Before its clock starts the stream waits (``--wait``, default 10 s) until every key has a subscriber,
so a recorder started just after the stream loses nothing; when the wait runs out it starts anyway.
After the last sample it lingers briefly so that queued messages reach their subscribers.
"""

from __future__ import annotations

import signal
import sys
import time

import numpy as np

from .messages import IMU, MAGNETIC_FIELD, RAW_MESSAGE_TYPES, raw_fields, split_payloads, stamps_to_ns
from .zenoh_io import PacedPublisher, open_session, session_config, topic_to_key

__all__ = ["encode_run", "run_stream"]


def encode_run(samples, truth=None) -> dict[str, np.ndarray]:
    """Topic -> ``(N, size)`` encoded rows of a device's samples (and truth), as an MCAP log holds them."""
    from .mcap_io import BODY_FRAME, _series_fields

    stamp_ns = stamps_to_ns(samples.t)
    frame = samples.device
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0
    out = {"/imu": IMU.encode(stamp_ns, frame, {
        "orientation": (0.0, 0.0, 0.0, 1.0), "orientation_covariance": no_orientation,
        "angular_velocity": samples.gyro, "linear_acceleration": samples.accel})}
    if samples.has_mag:
        out["/mag"] = MAGNETIC_FIELD.encode(stamp_ns, frame, {"magnetic_field": samples.mag})
    if truth is not None:
        out["/truth/imu"] = IMU.encode(stamps_to_ns(truth.t), BODY_FRAME, _series_fields(truth))
    for kind, observables in samples.raw.items():
        if kind in RAW_MESSAGE_TYPES:
            mtype, fields, _ = raw_fields(kind, observables)
            out[f"/raw/{kind}"] = mtype.encode(stamp_ns, frame, fields)
    return out


def run_stream(*, scenario: str, device: str, duration: float | None = None, seed: int = 0,
               as_fast_as_possible: bool = False, device_name: str = "imu0", wait_s: float = 10.0,
               connect=None, listen=None, mode=None, config_file=None, out=sys.stdout) -> int:
    from dynamics import load_scenario
    from sensors import load_device

    from .mcap_io import truth_series

    config = session_config(connect=connect, listen=listen, mode=mode, config_file=config_file)
    try:
        topic_to_key(device_name, "/imu")  # checks the device name before the (slow) simulation
    except ValueError as e:
        raise ValueError(f"argument --device-name: {e}") from None
    scen = load_scenario(scenario)
    dev = load_device(device, seed=seed)
    started = time.perf_counter()
    traj = scen.simulate(duration=duration)
    samples = dev.measure(traj)
    encoded = encode_run(samples, truth_series(traj, samples))
    batches = {topic_to_key(device_name, topic): split_payloads(rows) for topic, rows in encoded.items()}
    n = len(samples.t)
    rate = (n - 1) / float(samples.t[-1] - samples.t[0]) if n > 1 else dev.spec.rate_hz
    rate = float(dev.spec.rate_hz) if dev.spec.rate_hz else rate
    print(f"stream: {scen.name} through {dev.name}: {n} samples at {rate:g} Hz, {len(batches)} topics "
          f"(encoded in {time.perf_counter() - started:.2f} s)", file=out, flush=True)

    session = open_session(config)
    stopping = []
    previous = {s: signal.signal(s, lambda *_: stopping.append(1)) for s in (signal.SIGINT, signal.SIGTERM)}
    publisher = None
    try:
        publisher = PacedPublisher(session, list(batches))
        for key in batches:
            print(f"  {key}", file=out)
        if wait_s > 0 and not publisher.wait_for_subscribers(wait_s, stop=lambda: bool(stopping)):
            print(f"stream: no subscriber on every key after {wait_s:g} s: publishing anyway", file=out)
        print("stream: publishing", file=out, flush=True)
        report = publisher.run(batches, None if as_fast_as_possible else rate, stop=lambda: bool(stopping))
        print(f"stream: sent {report.messages} messages", file=out)
        if not as_fast_as_possible:
            print(f"stream: {report.summary()}", file=out)
        time.sleep(0.5)  # let queued messages drain before the session closes
    finally:
        if publisher is not None:
            publisher.close()
        session.close()
        for s, h in previous.items():
            signal.signal(s, h)
    out.flush()
    return 130 if stopping else 0
