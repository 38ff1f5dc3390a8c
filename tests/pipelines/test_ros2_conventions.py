"""ROS 2 conventions of gyroemu's logs (issue #20): absolute stamps, the tf tree, REP 145 covariances.

The logs are read with rosbags (its own MCAP reader and CDR deserialiser), not gyroemu's reader.

Tolerances
----------
- **tf tree against the truth.** tf2 interpolates a frame between its two neighbouring stamps ``h``
  apart: slerp for the rotation, linear for the translation. Writing ``q(t) = q(t₀) ⊗ exp(r(t)/2)``,
  slerp is the linear interpolant of the rotation vector ``r`` (``r(t₀) = 0``), whose error is at most
  ``h²/8 · max|r''|`` (the linear interpolant's remainder); ``r' = J⁻¹(r) ω`` with ``J⁻¹ = I + r×/2 + …``
  and ``|r| ≤ h |ω|`` give ``|r''| ≤ |ω̇| + h |ω| (|ω̇| + |ω|²)``. The bound uses the largest ``h`` of the
  file, the largest ``|ω|`` and ``|ω̇|`` of the truth (``ω̇`` from central differences of ``/truth/imu``:
  the difference quotient is a mean of ``ω̇`` over two samples, so its largest value can miss the true
  maximum by ``T·max|ω̈|``; a factor 1.5 covers that for the smooth scenario's ``ω̈``), plus a round-off
  of 100 ε. The translation's error is ``h²/8 · max|a|`` (``a`` the true acceleration, from second
  differences of ``/truth/pose``, same factor).
- **Covariances.** The covariance on ``/imu`` is checked against the closed form from the preset's
  numbers (``σ² = N²/T``; the preset's ``N`` already holds the quantiser's ``LSB²T/12``, README "Noise
  density"; the mechanism's own share kept by ``g = T ∫|H|² sinc²(fT) df``, here by adaptive
  quadrature against the code's trapezoidal rule: 1e-6 relative). The sample variance of a
  static run is checked against it with the chi-square distribution: for Gaussian noise uncorrelated
  from sample to sample ``(n − 2) s²/σ² ~ χ²(n − 2)`` (a straight line removed per axis); with a
  false-alarm rate of 1e-6 per axis and ``n`` = 10 000 the band is about ±7 %. Over the run the bias
  instability (5 °/h) and rate random walk (40 °/h/√h) add less than 1e-3 of σ² (σ = 0.088 °/s) once
  the line is removed. The slow test takes ``n`` = 310 000, for which the band at a false-alarm rate of
  1e-4 per axis is within ±1 %. (The MEMS mechanism's demodulator filter makes its share of the noise
  slightly correlated between samples; that changes the sample variance's spread by a negligible
  amount, its share being 11 % of the variance.)
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from scipy.stats import chi2
from tf_tree import interpolation_bound, tf_lookup
from tf_tree import quat_angle as _angle
from tf_tree import quat_mul as _mul

from gyroemu.dynamics.config import config_dir
from gyroemu.pipelines.formats.channels import raw_role
from gyroemu.pipelines.formats.frames import (
    ESTIMATE_FRAME,
    SIMULATE_EPOCH_NS,
    TfThinning,
    parse_start_time,
    tf_indices,
)
from gyroemu.pipelines.formats.mcap_log import McapLogWriter, Recording, read_mcap, read_tf
from gyroemu.pipelines.formats.tf_messages import decode_tf, encode_tf, shift_tf_stamps
from gyroemu.pipelines.jobs.estimate import estimate_log
from gyroemu.pipelines.jobs.simulate import SimulateError, SimulateOptions, run_simulate
from gyroemu.sensors.samples import ImuSamples

STORE = get_typestore(Stores.ROS2_HUMBLE)
EPS = np.finfo(float).eps
G0 = 9.80665  # standard gravity, m/s² (the ug in the preset)


# ---------------------------------------------------------------------------------------------------
# Helpers: quaternions (w, x, y, z) and reading with rosbags.


def _read_with_rosbags(path, topics=None):
    """Per topic (all, or ``topics``): list of (log_time, message), the channels' QoS and types, by rosbags."""
    out: dict[str, list] = {}
    with AnyReader([path], default_typestore=STORE) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
        wanted = [c for c in reader.connections if topics is None or c.topic in topics]
        for connection, log_time, data in reader.messages(connections=wanted):
            out.setdefault(connection.topic, []).append((log_time, reader.deserialize(data, connection.msgtype)))
    return out, qos, types


def _stamp(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _xyzw_to_wxyz(r):
    return np.array([r.w, r.x, r.y, r.z])


# ---------------------------------------------------------------------------------------------------
# The codec.


@pytest.mark.parametrize(
    "pairs",
    [
        [("map", "base_link")],
        [("map", "base_link"), ("map", ESTIMATE_FRAME)],
        [("base_link", "imu")],
        [("", "x"), ("abc", "")],
    ],
)
def test_tf_message_bytes_identical_to_rosbags(pairs):
    rng = np.random.default_rng(3)
    n, k = 7, len(pairs)
    stamps = rng.integers(0, 2**31 * 10**9, n)
    translation, rotation = rng.normal(size=(n, k, 3)), rng.normal(size=(n, k, 4))
    rows = encode_tf(stamps, pairs, translation, rotation)
    t = STORE.types
    for i in range(n):
        sec, nanosec = divmod(int(stamps[i]), 10**9)
        transforms = [
            t["geometry_msgs/msg/TransformStamped"](
                header=t["std_msgs/msg/Header"](
                    stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame
                ),
                child_frame_id=child,
                transform=t["geometry_msgs/msg/Transform"](
                    translation=t["geometry_msgs/msg/Vector3"](*translation[i, j]),
                    rotation=t["geometry_msgs/msg/Quaternion"](*rotation[i, j]),
                ),
            )
            for j, (frame, child) in enumerate(pairs)
        ]
        message = t["tf2_msgs/msg/TFMessage"](transforms=transforms)
        assert bytes(STORE.serialize_cdr(message, "tf2_msgs/msg/TFMessage")) == rows[i].tobytes()
    decoded = decode_tf([r.tobytes() for r in rows])
    assert np.array_equal(decoded.stamp_ns, np.repeat(stamps, k))
    assert np.array_equal(decoded.translation, translation.reshape(-1, 3))
    assert np.array_equal(decoded.q, rotation.reshape(-1, 4)[:, [3, 0, 1, 2]])
    shifted = decode_tf([shift_tf_stamps(r.tobytes(), -12_345) for r in rows])
    assert np.array_equal(shifted.stamp_ns, decoded.stamp_ns - 12_345)
    assert np.array_equal(shifted.translation, decoded.translation)


def test_thinning_does_not_depend_on_blocks():
    stamps = np.cumsum(np.random.default_rng(5).integers(900_000, 1_100_000, 5000))  # ~1 kHz, uneven
    whole = tf_indices(stamps, 100.0)
    thinning, parts, start = TfThinning(100.0), [], 0
    for stop in (7, 1000, 1001, 3333, 5000):
        parts.append(start + thinning.keep(stamps[start:stop]))
        start = stop
    blocks = np.concatenate(parts + ([[len(stamps) - 1]] if thinning.last() else []))
    assert np.array_equal(blocks, whole)
    assert whole[0] == 0 and whole[-1] == len(stamps) - 1
    assert np.diff(stamps[whole]).max() <= 10_000_000 + 1_100_000  # a 10 ms bin, plus one sample at most


def test_start_time_forms():
    assert parse_start_time("2025-01-01T00:00:00Z") == SIMULATE_EPOCH_NS
    assert parse_start_time("2025-01-01T01:00:00+01:00") == SIMULATE_EPOCH_NS
    assert parse_start_time("2025-01-01T00:00:00.25") == SIMULATE_EPOCH_NS + 250_000_000  # no zone: UTC
    assert parse_start_time("1735689600.5") == SIMULATE_EPOCH_NS + 500_000_000
    # Epoch seconds to the nanosecond, from their digits (as doubles they read 21 ns and 1 ns off)
    assert parse_start_time("1735689600.123456789") == SIMULATE_EPOCH_NS + 123_456_789
    assert parse_start_time("1735689600.000000001") == SIMULATE_EPOCH_NS + 1
    assert parse_start_time("1.7356896e9") == SIMULATE_EPOCH_NS
    assert parse_start_time(0) == 0
    for bad in ("yesterday", "nan", "-1", "2040-01-01T00:00:00Z"):
        with pytest.raises(ValueError, match="--start-time"):
            parse_start_time(bad)


# ---------------------------------------------------------------------------------------------------
# A simulate log through rosbags: the tree at every IMU stamp.


@pytest.fixture(scope="module")
def manoeuvre(tmp_path_factory):
    """8 s of aktos_t_broad (a measured mounting, 285.714 Hz, latencies) on smooth_manoeuvre."""
    path = tmp_path_factory.mktemp("ros2") / "manoeuvre.mcap"
    run_simulate(SimulateOptions(scenario="smooth_manoeuvre", device="aktos_t_broad", duration=8.0, out=path, seed=2))
    return path


def test_simulate_log_tf_tree_resolves_to_the_truth_at_every_imu_stamp(manoeuvre):
    from gyroemu.sensors import load_device

    messages, qos, types = _read_with_rosbags(manoeuvre)
    assert types["/tf"] == types["/tf_static"] == "tf2_msgs/msg/TFMessage"
    assert qos["/tf_static"][0].durability.value == 1 and qos["/tf"][0].durability.value == 2  # latched mounting
    device = load_device("aktos_t_broad")
    imu = messages["/imu"]
    stamps = np.array([_stamp(m.header) for _, m in imu])
    assert stamps[0] > SIMULATE_EPOCH_NS and stamps[0] - SIMULATE_EPOCH_NS < 10**9  # absolute, from the epoch
    assert all(log_time == _stamp(m.header) for log_time, m in imu)
    frame = imu[0][1].header.frame_id
    # /tf_static: base_link -> the IMU's frame, the device's mounting.
    ((_, static),) = messages["/tf_static"]
    (mount,) = static.transforms
    assert (mount.header.frame_id, mount.child_frame_id) == ("base_link", frame)
    q_bs = _xyzw_to_wxyz(mount.transform.rotation)
    expected = np.array(device.spec.mounting.q_bs) / np.linalg.norm(device.spec.mounting.q_bs)
    assert np.allclose(q_bs, expected, rtol=0, atol=4 * EPS)
    # /tf: map -> base_link, thinned, spanning every IMU stamp.
    tf = [tr for _, m in messages["/tf"] for tr in m.transforms]
    assert {(tr.header.frame_id, tr.child_frame_id) for tr in tf} == {("map", "base_link")}
    tf_ns = np.array([_stamp(tr.header) for tr in tf])
    tf_q = np.array([_xyzw_to_wxyz(tr.transform.rotation) for tr in tf])
    tf_p = np.array([[tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z] for tr in tf])
    assert tf_ns[0] == stamps[0] and tf_ns[-1] == stamps[-1] and np.all(np.diff(tf_ns) > 0)
    assert len(tf) < len(stamps) / 2  # thinned: 100 Hz of 285.7 Hz
    # tf2's lookup at every IMU stamp: neighbours, slerp and linear interpolation.
    q_wb, p_w = tf_lookup(tf_ns, tf_q, tf_p, stamps)
    q_ws = _mul(q_wb, q_bs)  # map -> base_link -> IMU
    # The truth at the same stamps.
    truth = messages["/truth/imu"]
    pose = messages["/truth/pose"]
    assert [_stamp(m.header) for _, m in truth] == stamps.tolist() == [_stamp(m.header) for _, m in pose]
    true_q = np.array([_xyzw_to_wxyz(m.orientation) for _, m in truth])
    true_w = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for _, m in truth])
    true_p = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for _, m in pose])
    # The bound (module notes).
    bound_q, bound_p = interpolation_bound(stamps, tf_ns, true_w, true_p)
    error_q = _angle(q_ws, _mul(true_q, q_bs))
    error_p = np.linalg.norm(p_w - true_p, axis=1)
    assert error_q.max() <= bound_q, (error_q.max(), bound_q)
    assert error_p.max() <= bound_p, (error_p.max(), bound_p)
    # At the /tf stamps themselves the tree is the truth (to round-off).
    at = np.isin(stamps, tf_ns)
    assert at.sum() == len(tf_ns) and error_q[at].max() <= 8 * EPS


def test_estimate_adds_body_estimate_to_the_tree(manoeuvre, tmp_path):
    out = tmp_path / "est.mcap"
    estimate_log(manoeuvre, out, filter_name="mekf")
    messages, _, _ = _read_with_rosbags(out)
    est = {_stamp(m.header): _xyzw_to_wxyz(m.orientation) for _, m in messages["/estimate/imu"]}
    tf = [tr for _, m in messages["/tf"] for tr in m.transforms]
    mine = [tr for tr in tf if tr.child_frame_id == ESTIMATE_FRAME]
    truth = [tr for tr in tf if tr.child_frame_id == "base_link"]
    assert len(mine) == len(truth) and all(tr.header.frame_id == "map" for tr in mine)
    for tr in mine:  # the estimate itself, at the true position
        assert np.array_equal(_xyzw_to_wxyz(tr.transform.rotation), est[_stamp(tr.header)])
    assert [_stamp(tr.header) for tr in mine] == [_stamp(tr.header) for tr in truth]
    assert max(est) == _stamp(mine[-1].header)  # the last estimate is in the tree
    # Estimating the output again replaces the estimate's transforms instead of doubling them.
    again = tmp_path / "again.mcap"
    estimate_log(out, again, filter_name="mekf")
    assert len(read_tf(again)) == len(read_tf(out))


# ---------------------------------------------------------------------------------------------------
# Covariances (REP 145).


def _imu_rows(path):
    """``/imu`` of a log through rosbags' reader: the first messages deserialised by rosbags, and every
    message's angular velocity from its CDR bytes (Imu with one frame id: all the same length; the
    vector follows the header string, 8-aligned, then orientation (4) and its covariance (9) float64)."""
    with AnyReader([path], default_typestore=STORE) as reader:
        (connection,) = [c for c in reader.connections if c.topic == "/imu"]
        raw = [data for _, _, data in reader.messages(connections=[connection])]
        first = [reader.deserialize(data, connection.msgtype) for data in raw[:50]]
    frame = first[0].header.frame_id.encode()
    start = -(-(12 + len(frame) + 1) // 8) * 8 + 8 * (4 + 9)  # payload offset of angular_velocity
    block = np.frombuffer(b"".join(raw), dtype=np.uint8).reshape(len(raw), -1)
    gyro = block[:, 4 + start : 4 + start + 24].copy().view("<f8")
    for k, m in enumerate(first):  # the byte view agrees with rosbags' deserialiser
        assert gyro[k].tolist() == [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
    return first, gyro


def _expected_variances():
    """consumer_mems's per-sample variances from its preset numbers (module notes): N = 2.8 mdps/√Hz and
    70 ug/√Hz at 1 kHz, N²/T; for the gyro, the mechanism's own share N_mech²/T kept by
    g = T ∫|H|² sinc²(fT) df, integrated here with scipy's adaptive quadrature."""
    from scipy.integrate import quad

    from gyroemu.sensors import load_device

    device = load_device("consumer_mems")
    rate, response = 1000.0, device.mechanism.rate_response
    g = 0.0
    for a, b in [(k * 500.0, (k + 1) * 500.0) for k in range(100)]:
        g += quad(lambda f: abs(response([f])[0]) ** 2 * np.sinc(f / rate) ** 2, a, b, epsabs=0, epsrel=1e-10)[0]
    g *= 2 / rate
    n_mech = device.intrinsic_noise_density
    gyro = (0.0028 * math.pi / 180) ** 2 * rate - (1 - g) * n_mech**2 * rate
    return gyro, (70e-6 * G0) ** 2 * rate


def _static_gyro_check(path, n_expected, alpha):
    first, gyro = _imu_rows(path)
    assert len(gyro) == n_expected
    gyro_var, accel_var = _expected_variances()
    for m in first:
        assert m.orientation_covariance[0] == -1.0
        cov_w = np.asarray(m.angular_velocity_covariance).reshape(3, 3)
        cov_a = np.asarray(m.linear_acceleration_covariance).reshape(3, 3)
        # trapezoid (the code) against adaptive quadrature (here): both to better than 1e-6 of g's share
        assert np.allclose(cov_w, np.diag([gyro_var] * 3), rtol=1e-6, atol=0)
        assert np.allclose(cov_a, np.diag([accel_var] * 3), rtol=1e-12, atol=0)
    t = np.arange(len(gyro), dtype=float)
    residual = gyro - np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyfit(t, gyro, 1)).T
    dof = len(gyro) - 2  # a line removed per axis
    s2 = (residual**2).sum(axis=0) / dof
    low, high = chi2.ppf(alpha / 2, dof) / dof, chi2.ppf(1 - alpha / 2, dof) / dof
    ratio = s2 / np.asarray(first[0].angular_velocity_covariance).reshape(3, 3).diagonal()
    assert np.all((low <= ratio) & (ratio <= high)), (ratio, low, high)
    return high - 1


def test_imu_covariance_is_the_devices_white_noise(tmp_path):
    path = tmp_path / "static.mcap"
    run_simulate(SimulateOptions(scenario="bench_static", device="consumer_mems", duration=10.0, out=path, seed=4))
    assert _static_gyro_check(path, 10_000, alpha=1e-6) < 0.075


@pytest.mark.slow
def test_imu_covariance_within_one_percent(tmp_path):
    path = tmp_path / "static.mcap"
    run_simulate(SimulateOptions(scenario="bench_static", device="consumer_mems", duration=310.0, out=path, seed=6))
    assert _static_gyro_check(path, 310_000, alpha=1e-4) <= 0.01


# ---------------------------------------------------------------------------------------------------
# Old logs, options.


def test_old_style_log_without_tf_is_read_and_estimated(tmp_path):
    """A log as gyroemu wrote it before the tree: stamps from 0 s, no /tf, no covariances."""
    n = 2000
    t = (np.arange(n) + 1) * 1e-3
    rng = np.random.default_rng(9)
    samples = ImuSamples(
        t=t,
        gyro=rng.normal(0, 1e-3, (n, 3)),
        accel=np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 1e-2, (n, 3)),
        mag=np.full((n, 3), np.nan),
    )
    old = tmp_path / "old.mcap"
    with McapLogWriter(old, tf_rate_hz=None) as log:
        log.write(Recording(samples))
    log = read_mcap(old)
    assert np.array_equal(log.device.stamp_ns, np.rint(t * 1e9).astype(np.int64))
    assert log.device.gyro_variance is None and log.device.accel_variance is None and not log.skipped
    assert len(read_tf(old)) == 0
    out = tmp_path / "est.mcap"
    estimate_log(old, out, filter_name="mekf")
    tree = read_tf(out)
    assert set(tree.child_frame_id.tolist()) == {ESTIMATE_FRAME}
    assert tree.stamp_ns[0] == 1_000_000 and tree.stamp_ns[-1] == 2_000_000_000  # the old stamps kept
    assert np.all(tree.translation == 0)  # no /truth/pose: at the origin


# ---------------------------------------------------------------------------------------------------
# Topic names.

ROS_TOPIC = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
"""A fully qualified ROS 2 topic name (rcl, rmw): tokens of letters, digits and ``_``, none starting with
a digit, joined by single ``/``; no ``-``."""
DEVICES = sorted(p.stem for p in (config_dir() / "devices").glob("*.toml"))


def _topics(path: Path) -> list[str]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return [c.topic for c in summary.channels.values()]


@pytest.mark.parametrize("device", DEVICES)
def test_every_topic_written_is_a_ros2_name(device, tmp_path):
    """Every topic of a shipped device's log is a valid ROS 2 name: the raw topics of the kinds
    ``rate-gyro``, ``rate-integrating`` and ``free-gyro`` were ``/raw/rate-gyro`` ..., which ``ros2 bag
    play`` cannot publish; they are the kind with ``-`` as ``_``."""
    from gyroemu.pipelines.formats.messages import RAW_MESSAGE_TYPES
    from gyroemu.sensors import load_device

    path = tmp_path / f"{device}.mcap"
    run_simulate(SimulateOptions(scenario="rate_table_steps", device=device, duration=0.3, out=path))
    topics = _topics(path)
    assert [t for t in topics if not ROS_TOPIC.match(t)] == [], topics
    kind = load_device(device).kind
    if kind in RAW_MESSAGE_TYPES:  # a kind with raw observables: its topic is there, by that rule
        assert "/raw/" + kind.replace("-", "_") in topics, topics


def _rename_topics(src: Path, dst: Path, renames: dict[str, str]) -> None:
    """``src`` written again (mcap's own writer) with its channels' topics renamed: every schema, channel
    metadata, metadata record and message (times, sequence, bytes) as they were."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(g, compression=CompressionType.ZSTD)
        writer.start(profile=reader.get_header().profile, library=reader.get_header().library)
        schemas = {i: writer.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
        channels = {
            i: writer.register_channel(
                renames.get(c.topic, c.topic), c.message_encoding, schemas.get(c.schema_id, 0), c.metadata
            )
            for i, c in summary.channels.items()
        }
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        for _, c, m in reader.iter_messages(log_time_order=False):
            writer.add_message(channels[c.id], m.log_time, m.data, m.publish_time, m.sequence)
        writer.finish()


def test_a_log_with_the_older_hyphenated_raw_topic_still_reads(tmp_path):
    """A log written before the raw topics became ROS 2 names (``/raw/rate-gyro``) reads as today's: its
    raw channel by read_mcap, info and the streamed reader, estimate copies it through, and replay and
    record put it under today's name."""
    from gyroemu.pipelines.formats.device_stream import scan_devices
    from gyroemu.pipelines.jobs.info import log_info
    from gyroemu.pipelines.transport.record import gyroemu_key
    from gyroemu.pipelines.transport.replay import topic_keys

    new, old = tmp_path / "new.mcap", tmp_path / "old.mcap"
    run_simulate(SimulateOptions(scenario="rate_table_steps", device="classic_rate_gyro", duration=0.5, out=new))
    _rename_topics(new, old, {"/raw/rate_gyro": "/raw/rate-gyro"})
    assert "/raw/rate-gyro" in _topics(old) and "/raw/rate_gyro" not in _topics(old)
    role = raw_role("rate-gyro")
    a, b = read_mcap(new), read_mcap(old)
    assert not b.skipped and b.device.topics[role] == "/raw/rate-gyro" and a.device.topics[role] == "/raw/rate_gyro"
    assert list(b.device.samples.raw) == ["rate-gyro"]
    for name, value in a.device.samples.raw["rate-gyro"].items():
        assert np.array_equal(b.device.samples.raw["rate-gyro"][name], value), name
    assert np.array_equal(a.device.samples.gyro, b.device.samples.gyro) and len(b.device.samples.t) == 100
    info = log_info(old)
    assert info.devices[0].topics[role] == "/raw/rate-gyro" and not info.skipped
    streamed, _ = scan_devices(old)
    assert streamed["classic_rate_gyro"].topics[role] == "/raw/rate-gyro"
    out = tmp_path / "est.mcap"
    estimate_log(old, out, filter_name="mekf")
    copied = read_mcap(out).device
    assert copied.topics[role] == "/raw/rate-gyro" and copied.estimate is not None
    angle = a.device.samples.raw["rate-gyro"]["gimbal_angle_rad"]
    assert np.array_equal(copied.samples.raw["rate-gyro"]["gimbal_angle_rad"], angle)
    keys, bad = topic_keys(["/raw/rate-gyro"], b.metadata, "zz")
    assert keys == {"/raw/rate-gyro": "gyroemu/classic_rate_gyro/raw/rate_gyro"} and not bad
    assert gyroemu_key("gyroemu/dev/raw/rate-gyro").topic == "/raw/rate_gyro"  # an older stream, recorded


def test_start_time_and_frame_id_options(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    opts = dict(scenario="bench_static", device="consumer_mems", duration=0.5, seed=1)
    run_simulate(SimulateOptions(out=a, **opts))
    run_simulate(SimulateOptions(out=b, start_time="2030-06-01T12:00:00Z", frame_id="imu_link", **opts))
    da, db = read_mcap(a).device, read_mcap(b).device
    shift = parse_start_time("2030-06-01T12:00:00Z") - SIMULATE_EPOCH_NS
    assert np.array_equal(db.stamp_ns - da.stamp_ns, np.full(len(da.stamp_ns), shift))
    assert np.array_equal(db.samples.gyro, da.samples.gyro)
    assert da.frame_id == "consumer_mems" and db.frame_id == "imu_link"
    static = read_tf(b, static=True)
    assert static.child_frame_id.tolist() == ["imu_link"] and static.frame_id.tolist() == ["base_link"]
    with pytest.raises(SimulateError, match="--start-time"):
        run_simulate(SimulateOptions(out=tmp_path / "c.mcap", start_time="soon", **opts))
    with pytest.raises(SimulateError, match="--frame-id"):
        run_simulate(SimulateOptions(out=tmp_path / "c.mcap", frame_id="base_link", **opts))
    assert not (tmp_path / "c.mcap").exists()


def test_cli_start_time_error_exits_2(tmp_path, capsys):
    from gyroemu.pipelines.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(
            ["simulate", "--scenario", "bench_static", "--device", "consumer_mems", "--duration", "1", "--out",
             str(tmp_path / "x.mcap"), "--start-time", "2040-01-01"]
        )  # fmt: skip
    assert exit_info.value.code == 2 and "--start-time" in capsys.readouterr().err
    assert not (tmp_path / "x.mcap").exists()


def test_interleaving_a_thinned_channel_keeps_time_order_bytes_and_sequences():
    """The MCAP writer's merge of channels of different stamps (every sample's channels, a thinned /tf,
    and a second batch on the /tf channel, as two tf edges are) against a plain Python merge: messages
    sorted by time, ties in batch order with batches of equal stamps kept together, bytes unchanged,
    and each channel's sequence counting 0, 1, 2, ... in file order. Read back by the mcap library."""
    import io

    from mcap.reader import make_reader

    from gyroemu.pipelines.formats.mcap_records import McapFileWriter

    rng = np.random.default_rng(11)
    t = np.arange(3000, dtype=np.int64) * 1000
    thin_t = t[::10].copy()
    odd_t = np.sort(rng.integers(0, 3_000_000, 77))

    def rows(n, size):
        return rng.integers(0, 256, (n, size), dtype=np.uint8)

    for layout in ("main+thin", "main+thin+odd", "thin+odd"):
        buffer = io.BytesIO()
        writer = McapFileWriter(buffer, chunk_size=1 << 14)
        ids = {name: writer.register_channel(name, "cdr", 0) for name in ("/a", "/b", "/tf")}
        batches = []
        if layout.startswith("main"):
            batches += [(ids["/a"], t, rows(3000, 40)), (ids["/b"], t, rows(3000, 24))]
        batches.append((ids["/tf"], thin_t, rows(300, 16)))
        if layout.endswith("odd"):
            batches.append((ids["/tf"], odd_t, rows(77, 8)))  # the same channel, other stamps
        writer.add_messages(batches)
        writer.finish()
        units = []  # (time, group, [(channel id, payload)]): batches of equal stamps form one group
        firsts: list = []
        for _, stamps, _ in batches:
            if not any(np.array_equal(f, stamps) for f in firsts):
                firsts.append(stamps)
        for g, first in enumerate(firsts):
            members = [(c, r) for c, stamps, r in batches if np.array_equal(stamps, first)]
            for row, stamp in enumerate(first.tolist()):
                units.append((stamp, g, [(c, r[row].tobytes()) for c, r in members]))
        units.sort(key=lambda u: (u[0], u[1]))
        want = [(c, u[0], b) for u in units for c, b in u[2]]
        buffer.seek(0)
        messages = [
            (m.channel_id, m.log_time, m.data, m.sequence)
            for _, _, m in make_reader(buffer).iter_messages(log_time_order=False)
        ]
        assert [m[:3] for m in messages] == want, layout
        counts: dict[int, int] = {}
        for channel_id, _, _, sequence in messages:
            assert sequence == counts.get(channel_id, 0), layout
            counts[channel_id] = sequence + 1
