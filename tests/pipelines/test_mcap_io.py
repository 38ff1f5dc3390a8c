"""MCAP logs (gyroemu.pipelines.mcap_io) against interface.md, the MCAP specification and independent readers.

Tolerances: values go through CDR bit-exactly, so decoded arrays equal the written ones exactly. Time
stamps are stored as integer nanoseconds: ``|t_read − t| ≤ 0.5 ns + rounding``, with the rounding of
``t·1e9`` and of ``ns / 1e9`` each within one ulp (``spacing(t)`` is 4e-16 s for t < 4 s).
"""

from __future__ import annotations

import hashlib
import re
import struct
import tomllib
import warnings
import zlib
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as PlainMcapWriter
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2McapWriter
from plain_mcap import write_plain_imu
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gyroemu.dynamics import ConfigError, load_scenario
from gyroemu.errors import GyroemuError
from gyroemu.pipelines.formats.channels import BODY_FRAME, ImuSeries, encode_movement, topic_message_type
from gyroemu.pipelines.formats.mcap_log import LogWarning, McapLogWriter, Recording, read_mcap, truth_series, write_mcap
from gyroemu.pipelines.formats.mcap_records import LogError
from gyroemu.pipelines.formats.messages import FLAG, IMU, MAGNETIC_FIELD, RAW_MESSAGE_TYPES, schema_text
from gyroemu.sensors import load_device
from gyroemu.sensors.samples import ImuSamples

PRESETS = [
    "classic_rate_gyro",
    "consumer_mems",
    "floated_rig",
    "free_gyro",
    "ideal",
    "navigation_fog",
    "navigation_rlg",
    "tactical_mems",
]


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("smooth_manoeuvre")


@pytest.fixture(scope="module")
def trajectory(scenario):
    return scenario.simulate(duration=0.5)


@pytest.fixture(scope="module")
def runs(trajectory):
    """Every preset's samples and truth over the trajectory."""
    out = {}
    for name in PRESETS:
        device = load_device(name, seed=3)
        samples = device.measure(trajectory)
        out[name] = (device, samples, truth_series(trajectory, samples))
    return out


def stamps_close(t_read, t):
    return np.max(np.abs(t_read - t), initial=0.0) <= 0.5e-9 + 2 * np.spacing(np.max(np.abs(t), initial=1.0))


def assert_samples_equal(got: ImuSamples, want: ImuSamples, n=None):
    n = len(want) if n is None else n
    assert len(got) == n
    assert stamps_close(got.t, want.t[:n])
    assert np.array_equal(got.gyro, want.gyro[:n])
    assert np.array_equal(got.accel, want.accel[:n])
    assert np.array_equal(got.mag, want.mag[:n], equal_nan=True)
    assert set(got.raw) == set(want.raw)
    for kind, observables in want.raw.items():
        assert set(got.raw[kind]) == set(observables)
        for name, values in observables.items():
            assert got.raw[kind][name].dtype == values.dtype, (kind, name)
            assert np.array_equal(got.raw[kind][name], values[:n], equal_nan=True), (kind, name)


def file_digest(path):
    stat = Path(path).stat()
    return hashlib.sha256(Path(path).read_bytes()).hexdigest(), stat.st_mtime_ns, stat.st_size


def read_quietly(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # gyroemu's own files read without any warning
        return read_mcap(path)


# ---------------------------------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("preset", PRESETS)
def test_round_trip_every_preset(tmp_path, runs, scenario, preset):
    device, samples, truth = runs[preset]
    path = write_mcap(tmp_path / "run.mcap", Recording(samples, truth=truth, device=device), scenario=scenario)
    log = read_quietly(path)
    assert list(log.devices) == [device.name] and not log.truncated
    d = log.device
    assert_samples_equal(d.samples, samples)
    assert d.samples.device == device.name
    assert stamps_close(d.truth.t, samples.t)
    for name in ("q_wb", "omega_b", "specific_force_b"):
        assert np.array_equal(getattr(d.truth, name), getattr(truth, name)), name
    assert d.truth.q_wb_covariance is None and d.estimate is None
    expected_topics = {"imu": "/imu", "truth/imu": "/truth/imu"}
    # the kind with "-" as "_" (/raw/rate_gyro): a ROS 2 name
    expected_topics.update({f"raw/{k.replace('-', '_')}": f"/raw/{k.replace('-', '_')}" for k in samples.raw})
    if samples.has_mag:
        expected_topics["mag"] = "/mag"
    assert d.topics == expected_topics
    meta = d.metadata
    assert meta["seed"] == "3" and meta["device_name"] == device.name and meta["topic_prefix"] == ""
    assert tomllib.loads(meta["device"]) == tomllib.loads(device.to_toml())
    assert tomllib.loads(meta["scenario"]) == tomllib.loads(scenario.to_toml())
    assert meta["version"]


def test_bare_samples_and_several_blocks(tmp_path, runs):
    _, samples, truth = runs["navigation_rlg"]
    whole = read_quietly(write_mcap(tmp_path / "whole.mcap", Recording(samples, truth=truth)))
    cuts = [0, 7, 130, len(samples)]
    with McapLogWriter(tmp_path / "blocks.mcap", chunk_size=4096) as log:
        for a, b in zip(cuts[:-1], cuts[1:]):
            log.write(Recording(_slice(samples, a, b), truth=_slice_series(truth, a, b)))
    blocks = read_quietly(tmp_path / "blocks.mcap")
    assert_samples_equal(blocks.samples, whole.samples)
    assert np.array_equal(blocks.truth.q_wb, whole.truth.q_wb)
    with open(tmp_path / "blocks.mcap", "rb") as f:
        reader = make_reader(f)
        assert len(reader.get_summary().chunk_indexes) > 3
        sequences = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            sequences.setdefault(channel.topic, []).append(message.sequence)
    assert all(seq == list(range(len(seq))) for seq in sequences.values())
    assert all(len(seq) == len(samples) for topic, seq in sequences.items() if topic != "/tf")  # /tf is thinned
    bare = read_quietly(write_mcap(tmp_path / "bare.mcap", samples))
    assert_samples_equal(bare.samples, samples)
    assert bare.truth is None and bare.device.metadata["seed"] == "" and bare.device.metadata["device"] == ""


def test_blocks_must_follow_in_time(tmp_path, runs):
    _, samples, _ = runs["ideal"]
    with pytest.raises(ValueError, match="time order"):
        with McapLogWriter(tmp_path / "x.mcap") as log:
            log.write(_slice(samples, 100, 200))
            log.write(_slice(samples, 0, 100))
    assert not (tmp_path / "x.mcap").exists() and not list(tmp_path.iterdir())


def _slice(s: ImuSamples, a, b) -> ImuSamples:
    return ImuSamples(
        t=s.t[a:b],
        gyro=s.gyro[a:b],
        accel=s.accel[a:b],
        mag=s.mag[a:b],
        raw={k: {n: v[a:b] for n, v in o.items()} for k, o in s.raw.items()},
        device=s.device,
    )


def _slice_series(s: ImuSeries, a, b) -> ImuSeries:
    return ImuSeries(t=s.t[a:b], q_wb=s.q_wb[a:b], omega_b=s.omega_b[a:b], specific_force_b=s.specific_force_b[a:b])


def test_estimate_channel_round_trip(tmp_path, runs):
    _, samples, truth = runs["tactical_mems"]
    rng = np.random.default_rng(5)
    n = len(samples)
    a = rng.normal(size=(n, 3, 3)) * 1e-3
    estimate = ImuSeries(
        t=samples.t,
        q_wb=truth.q_wb,
        omega_b=samples.gyro - 1e-4,
        q_wb_covariance=a @ a.transpose(0, 2, 1),
        omega_b_covariance=np.broadcast_to(np.eye(3) * 1e-6, (n, 3, 3)),
    )
    log = read_quietly(write_mcap(tmp_path / "e.mcap", Recording(samples, truth=truth, estimate=estimate)))
    got = log.device.estimate
    assert log.device.topics["estimate/imu"] == "/estimate/imu"
    assert np.array_equal(got.q_wb, estimate.q_wb) and np.array_equal(got.omega_b, estimate.omega_b)
    assert np.array_equal(got.q_wb_covariance, estimate.q_wb_covariance)
    assert np.array_equal(got.omega_b_covariance, estimate.omega_b_covariance)
    assert got.specific_force_b is None and got.specific_force_b_covariance is None  # written as covariance[0] = -1


def test_several_devices_prefixed_and_interleaved(tmp_path, runs, scenario):
    recordings = [
        Recording(runs[name][1], truth=runs[name][2], device=runs[name][0])
        for name in ("consumer_mems", "classic_rate_gyro", "navigation_fog")
    ]  # 1000, 200, 1000 Hz
    path = write_mcap(tmp_path / "three.mcap", recordings, scenario=scenario)
    log = read_quietly(path)
    assert list(log.devices) == ["consumer_mems", "classic_rate_gyro", "navigation_fog"]
    for recording in recordings:
        d = log.devices[recording.samples.device]
        assert_samples_equal(d.samples, recording.samples)
        assert all(topic.startswith(f"/{d.name}/") for topic in d.topics.values())
        assert d.metadata["topic_prefix"] == f"/{d.name}" and d.metadata["device_name"] == d.name
    assert len(log.metadata) == 3
    _check_contract(path)
    with pytest.raises(ValueError, match="devices"):
        _ = log.samples
    with pytest.raises(ValueError, match="prefix"):
        with McapLogWriter(tmp_path / "bad.mcap") as writer:
            writer.write(recordings[0])
            writer.write(recordings[1])


def test_bad_inputs_to_the_writer(tmp_path, runs):
    _, samples, _ = runs["ideal"]
    early = ImuSamples(t=samples.t - 0.1, gyro=samples.gyro, accel=samples.accel, mag=samples.mag)
    with pytest.raises(ValueError, match="before 1970"):
        write_mcap(tmp_path / "n.mcap", early)
    renamed = ImuSamples(t=samples.t, gyro=samples.gyro, accel=samples.accel, mag=samples.mag, device="raw")
    with pytest.raises(ValueError, match="cannot prefix"):
        write_mcap(tmp_path / "n.mcap", [renamed, samples])
    odd = ImuSamples(
        t=samples.t,
        gyro=samples.gyro,
        accel=samples.accel,
        mag=samples.mag,
        raw={"laser-vortex": {"x": np.zeros(len(samples))}},
    )
    with pytest.warns(LogWarning, match="laser-vortex"):
        write_mcap(tmp_path / "n.mcap", odd)
    assert read_quietly(tmp_path / "n.mcap").samples.raw == {}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.mcap"]  # no temporary files left


def test_interrupted_write_leaves_nothing(tmp_path, runs):
    _, samples, _ = runs["consumer_mems"]
    target = tmp_path / "run.mcap"
    target.write_bytes(b"an older file")
    with pytest.raises(RuntimeError):
        with McapLogWriter(target) as log:
            log.write(samples)
            raise RuntimeError("simulated crash")
    assert target.read_bytes() == b"an older file"
    assert [p.name for p in tmp_path.iterdir()] == ["run.mcap"]


# ---------------------------------------------------------------------------------------------------
# The file against interface.md and the MCAP specification, read by the mcap library.


def _check_contract(path):
    """Profile, encodings, summary, indexes, CRCs, time order, stamps, sequences."""
    data = Path(path).read_bytes()
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        summary = reader.get_summary()
        messages = list(reader.iter_messages(log_time_order=False))  # validates chunk CRCs
    assert header.profile == "ros2"
    assert summary is not None and summary.statistics is not None
    assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
    assert all(c.message_encoding == "cdr" for c in summary.channels.values())
    assert all("offered_qos_profiles" in c.metadata for c in summary.channels.values())
    assert summary.chunk_indexes and all(ci.compression == "zstd" for ci in summary.chunk_indexes)
    assert summary.statistics.message_count == len(messages)
    assert summary.statistics.chunk_count == len(summary.chunk_indexes)
    with open(path, "rb") as f:
        assert [m.name for m in make_reader(f).iter_metadata()].count("gyroemu") >= 1
    # Footer: summary CRC over the summary section and the footer's fields before the CRC.
    footer = data[-8 - 29 : -8]
    summary_start, summary_offset_start, crc = struct.unpack("<QQI", footer[9:])
    assert data[-8:] == b"\x89MCAP0\r\n" and summary_offset_start > summary_start
    assert zlib.crc32(data[summary_start : len(data) - 8 - 29] + footer[:25]) == crc
    # Messages: time order in the file; log = publish = header stamp; sequences from 0 per channel.
    times = [m.log_time for _, _, m in messages]
    assert times == sorted(times)
    counts = {}
    for schema, channel, message in messages:
        # A TFMessage starts with its transforms' count; the first transform's header follows.
        sec, nanosec = struct.unpack_from("<iI", message.data, 8 if schema.name == "tf2_msgs/msg/TFMessage" else 4)
        assert message.log_time == message.publish_time == sec * 10**9 + nanosec
        assert message.sequence == counts.get(channel.id, 0)
        counts[channel.id] = message.sequence + 1
    assert counts == summary.statistics.channel_message_counts
    # Message indexes: every channel of every chunk, entries pointing at its Message records.
    for ci in summary.chunk_indexes:
        chunk = next(
            StreamReader(
                BytesIO(data[ci.chunk_start_offset : ci.chunk_start_offset + ci.chunk_length]),
                skip_magic=True,
                emit_chunks=True,
            ).records
        )
        assert isinstance(chunk, Chunk)
        records = breakup_chunk(chunk, validate_crc=True)
        raw = zstandard.decompress(chunk.data, chunk.uncompressed_size)
        in_chunk = {r.channel_id for r in records if hasattr(r, "sequence")}
        assert set(ci.message_index_offsets) == in_chunk
        for channel_id, offset in ci.message_index_offsets.items():
            index = next(StreamReader(BytesIO(data[offset:]), skip_magic=True).records)
            assert isinstance(index, MessageIndex) and index.channel_id == channel_id
            for log_time, at in index.records:
                opcode, _, channel, _, logged = struct.unpack_from("<BQHIQ", raw, at)
                assert (opcode, channel, logged) == (5, channel_id, log_time)


def test_contract_structure(tmp_path, runs, scenario):
    device, samples, truth = runs["consumer_mems"]
    path = write_mcap(
        tmp_path / "c.mcap", Recording(samples, truth=truth, device=device), scenario=scenario, chunk_size=8192
    )
    _check_contract(path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert topics == {
        "/imu": "sensor_msgs/msg/Imu",
        "/mag": "sensor_msgs/msg/MagneticField",
        "/truth/imu": "sensor_msgs/msg/Imu",
        "/raw/mems": "gyroemu_msgs/msg/MemsRaw",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/tf_static": "tf2_msgs/msg/TFMessage",
    }
    assert summary.schemas[1].data.decode() == schema_text(summary.schemas[1].name)
    # Same stamp: /imu, /mag, /truth/imu, /raw/mems in that order, sample after sample; the tf tree
    # (the mounting once, the thinned truth) after them at its stamps.
    with open(path, "rb") as f:
        first = [c.topic for _, c, _ in list(make_reader(f).iter_messages(log_time_order=False))[:10]]
    assert first == ["/imu", "/mag", "/truth/imu", "/raw/mems", "/tf_static", "/tf"] + [
        "/imu",
        "/mag",
        "/truth/imu",
        "/raw/mems",
    ]


def test_independent_readers_agree(tmp_path, runs):
    device, samples, truth = runs["consumer_mems"]
    path = write_mcap(tmp_path / "c.mcap", Recording(samples, truth=truth, device=device))
    log = read_quietly(path)
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(RAW_MESSAGE_TYPES["mems"].schema, RAW_MESSAGE_TYPES["mems"].name))
    rows = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages():
            if channel.topic in ("/tf", "/tf_static"):  # the tf tree: tests/pipelines/test_ros2_conventions.py
                continue
            other = store.deserialize_cdr(message.data, schema.name)
            rows.setdefault(channel.topic, []).append((ros, other))
    assert [len(v) for v in rows.values()] == [len(samples)] * 4
    for k, (a, b) in enumerate(rows["/imu"]):
        for msg in (a, b):
            assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == list(samples.gyro[k])
            assert [msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z] == list(
                samples.accel[k]
            )
            assert msg.orientation_covariance[0] == -1.0
            assert msg.header.frame_id == device.name
    for k, (a, b) in enumerate(rows["/mag"]):
        for msg in (a, b):
            assert [msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z] == list(samples.mag[k])
    for k, (a, b) in enumerate(rows["/truth/imu"]):
        for msg in (a, b):
            q = [msg.orientation.w, msg.orientation.x, msg.orientation.y, msg.orientation.z]
            assert q == list(truth.q_wb[k])  # scalar-first numpy, x y z w in the message
            assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == list(truth.omega_b[k])
            assert list(msg.orientation_covariance) == [0.0] * 9 and msg.header.frame_id == BODY_FRAME
    for k, (a, b) in enumerate(rows["/raw/mems"]):
        for msg in (a, b):
            assert list(msg.sense_in_phase_v) == list(samples.raw["mems"]["sense_in_phase_v"][k])
            assert list(msg.sense_quadrature_v) == list(samples.raw["mems"]["sense_quadrature_v"][k])
    assert np.array_equal(log.samples.gyro, samples.gyro)


def test_messages_identical_to_mcap_ros2_writer(tmp_path, runs):
    """The same content written message by message with mcap_ros2: byte-identical payloads, same
    stamps, sequences and order."""
    _, samples, truth = runs["navigation_rlg"]
    ours = write_mcap(tmp_path / "ours.mcap", Recording(samples, truth=truth))
    theirs = tmp_path / "theirs.mcap"
    raw = samples.raw["rlg"]
    with open(theirs, "wb") as f:
        writer = Ros2McapWriter(f)
        schemas = {
            name: writer.register_msgdef(name, schema_text(name))
            for name in ("sensor_msgs/msg/Imu", "gyroemu_msgs/msg/RlgRaw")
        }
        for k in range(len(samples)):
            sec, nanosec = divmod(int(round(samples.t[k] * 1e9)), 10**9)
            header = {"stamp": {"sec": sec, "nanosec": nanosec}}
            stamp = sec * 10**9 + nanosec
            vec = lambda v: dict(zip("xyz", map(float, v)))  # noqa: E731
            writer.write_message(
                "/imu",
                schemas["sensor_msgs/msg/Imu"],
                {
                    "header": {**header, "frame_id": samples.device},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": [-1.0] + [0.0] * 8,
                    "angular_velocity": vec(samples.gyro[k]),
                    "angular_velocity_covariance": [0.0] * 9,
                    "linear_acceleration": vec(samples.accel[k]),
                    "linear_acceleration_covariance": [0.0] * 9,
                },
                log_time=stamp,
                publish_time=stamp,
                sequence=k,
            )
            q = truth.q_wb[k]
            writer.write_message(
                "/truth/imu",
                schemas["sensor_msgs/msg/Imu"],
                {
                    "header": {**header, "frame_id": BODY_FRAME},
                    "orientation": dict(zip("wxyz", map(float, q))),
                    "orientation_covariance": [0.0] * 9,
                    "angular_velocity": vec(truth.omega_b[k]),
                    "angular_velocity_covariance": [0.0] * 9,
                    "linear_acceleration": vec(truth.specific_force_b[k]),
                    "linear_acceleration_covariance": [0.0] * 9,
                },
                log_time=stamp,
                publish_time=stamp,
                sequence=k,
            )
            writer.write_message(
                "/raw/rlg",
                schemas["gyroemu_msgs/msg/RlgRaw"],
                {
                    "header": {**header, "frame_id": samples.device},
                    "fringe_count": [int(x) for x in raw["fringe_count"][k]],
                    "beat_phase_rad": list(map(float, raw["beat_phase_rad"][k])),
                    "dither_angle_rad": list(map(float, raw["dither_angle_rad"][k])),
                },
                log_time=stamp,
                publish_time=stamp,
                sequence=k,
            )
        writer.finish()

    def messages(path):
        with open(path, "rb") as f:
            return [
                (c.topic, m.log_time, m.publish_time, m.sequence, m.data)
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)
            ]

    assert [m for m in messages(ours) if m[0] != "/tf"] == messages(theirs)  # /tf: test_ros2_conventions.py
    # and our reader reads their file to the same numbers
    assert_samples_equal(read_quietly(theirs).samples, samples)


# ---------------------------------------------------------------------------------------------------
# Damaged and foreign files.


def _chunk_message_counts(path):
    """(end offset, messages per channel topic) of each chunk, from the summary."""
    data = Path(path).read_bytes()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    out = []
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        chunk = next(
            StreamReader(
                BytesIO(data[ci.chunk_start_offset : ci.chunk_start_offset + ci.chunk_length]),
                skip_magic=True,
                emit_chunks=True,
            ).records
        )
        topics = [summary.channels[r.channel_id].topic for r in breakup_chunk(chunk) if hasattr(r, "sequence")]
        out.append((ci.chunk_start_offset + ci.chunk_length, topics))
    return out


@pytest.mark.parametrize("fraction", [0.25, 0.5, 0.9, "summary"])
def test_truncated_file_recovers_complete_chunks(tmp_path, runs, fraction):
    _, samples, truth = runs["navigation_rlg"]
    full = write_mcap(tmp_path / "full.mcap", Recording(samples, truth=truth), chunk_size=8192)
    data = full.read_bytes()
    summary_start = struct.unpack("<QQI", data[-8 - 29 + 9 : -8])[0]  # from the Footer record
    cut = summary_start + 40 if fraction == "summary" else int(len(data) * fraction)
    cut_path = tmp_path / "cut.mcap"
    cut_path.write_bytes(data[:cut])
    before = file_digest(cut_path)
    # Theory: the messages of the chunks that end before the cut.
    kept = [topics for end, topics in _chunk_message_counts(full) if end <= cut]
    expected = {}
    for topics in kept:
        for topic in topics:
            expected[topic] = expected.get(topic, 0) + 1
    with pytest.warns(LogWarning) as caught:
        log = read_mcap(cut_path)
    messages = [str(w.message) for w in caught]
    assert any(re.search(rf"truncated at byte \d+ .*recovered {sum(expected.values())} messages", m) for m in messages)
    assert log.truncated and log.message_count == sum(expected.values())
    n = min(expected["/imu"], expected["/raw/rlg"])  # samples need their raw observables
    assert any("no message on /raw/rlg" in m for m in messages) == (expected["/imu"] > n)
    assert_samples_equal(log.samples, samples, n=n)
    assert len(log.truth) == expected["/truth/imu"]
    assert np.array_equal(log.truth.q_wb, truth.q_wb[: expected["/truth/imu"]])
    assert file_digest(cut_path) == before
    if fraction == "summary":
        assert n == len(samples)


def test_truncated_before_any_chunk(tmp_path, runs):
    _, samples, _ = runs["ideal"]
    data = write_mcap(tmp_path / "full.mcap", samples).read_bytes()
    first_chunk = _chunk_message_counts(tmp_path / "full.mcap")[0][0]
    for cut in (8, 40, first_chunk - 1):
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        with pytest.warns(LogWarning, match="truncated"), pytest.raises(LogError, match="truncated") as e:
            read_mcap(path)
        assert e.value.file == str(path)


@pytest.mark.parametrize(
    "case", ["text", "empty", "garbage_after_magic", "flipped_chunk_byte", "crc", "folder", "missing", "no_imu"]
)
def test_unreadable_files_raise_log_error_naming_the_file(tmp_path, runs, case):
    _, samples, _ = runs["ideal"]
    path = tmp_path / "bad.mcap"
    good = write_mcap(tmp_path / "good.mcap", samples).read_bytes()
    first_chunk = good.index(bytes([6]), 8 + 9)  # the first Chunk record follows header, schema, channel, metadata
    with open(tmp_path / "good.mcap", "rb") as f:
        ci = make_reader(f).get_summary().chunk_indexes[0]
    if case == "text":
        path.write_text("timestamp,gx,gy,gz\n0.001,0.1,0.2,0.3\n")
        match = "not an MCAP file"
    elif case == "empty":
        path.write_bytes(b"")
        match = "not an MCAP file"
    elif case == "garbage_after_magic":
        path.write_bytes(good[:8] + bytes(range(256)) * 4)
        match = "corrupt|truncated|no sensor_msgs"
    elif case == "flipped_chunk_byte":
        damaged = bytearray(good)
        damaged[ci.chunk_start_offset + ci.chunk_length // 2] ^= 0xFF
        path.write_bytes(bytes(damaged))
        match = "corrupt chunk"
    elif case == "crc":
        damaged = bytearray(good)
        crc_at = ci.chunk_start_offset + 9 + 24  # after opcode, length, start, end, uncompressed size
        damaged[crc_at] ^= 0x01
        path.write_bytes(bytes(damaged))
        match = "CRC"
    elif case == "folder":
        path.mkdir()
        match = "folder"
    elif case == "missing":
        match = "cannot open"
    else:
        with open(path, "wb") as f:
            writer = Ros2McapWriter(f)
            schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
            writer.write_message("/chatter", schema, {"data": "hello"}, log_time=1)
            writer.finish()
        match = "no sensor_msgs/msg/Imu"
    assert first_chunk > 0
    before = file_digest(path) if path.is_file() else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)
        with pytest.raises(LogError, match=match) as e:
            read_mcap(path)
    assert e.value.file == str(path) and str(path) in str(e.value)
    assert isinstance(e.value, GyroemuError) and isinstance(e.value, ValueError)
    assert not isinstance(e.value, ConfigError)  # a log is not a config
    if before is not None:
        assert file_digest(path) == before


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
def test_foreign_file(tmp_path, compression):
    """Someone else's bag: an Imu topic of another name, frame ids of several lengths, log times after
    the stamps, a String channel (skipped with a warning) and a MagneticField topic beside the Imu one
    (``/sensors/mag``, the IMU's field: a driver's names), at every tenth sample."""
    rng = np.random.default_rng(11)
    n = 500
    stamps = 1_700_000_000 * 10**9 + np.cumsum(rng.integers(4_000_000, 6_000_000, n))
    gyro, accel = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        writer = Ros2McapWriter(f, chunk_size=16384, compression=compression)
        imu = writer.register_msgdef(
            "sensor_msgs/msg/Imu",
            get_typestore(Stores.ROS2_HUMBLE)
            .generate_msgdef("sensor_msgs/msg/Imu")[0]
            .replace("time stamp", "builtin_interfaces/Time stamp")
            + "=" * 80
            + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        )
        text = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        mag = writer.register_msgdef("sensor_msgs/msg/MagneticField", schema_text("sensor_msgs/msg/MagneticField"))
        for k in range(n):
            sec, nanosec = divmod(int(stamps[k]), 10**9)
            header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ["imu_link", "imu", ""][k % 3]}
            writer.write_message(
                "/sensors/imu_raw",
                imu,
                {
                    "header": header,
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": [0.0] * 9,
                    "angular_velocity": dict(zip("xyz", gyro[k])),
                    "angular_velocity_covariance": [0.0] * 9,
                    "linear_acceleration": dict(zip("xyz", accel[k])),
                    "linear_acceleration_covariance": [0.0] * 9,
                },
                log_time=int(stamps[k]) + 2_000_000,
            )
            if k % 10 == 0:
                writer.write_message("/rosout_text", text, {"data": f"sample {k}"}, log_time=int(stamps[k]) + 2_000_001)
                writer.write_message(
                    "/sensors/mag",
                    mag,
                    {
                        "header": header,
                        "magnetic_field": {"x": 1e-5, "y": 0.0, "z": 0.0},
                        "magnetic_field_covariance": [0.0] * 9,
                    },
                    log_time=int(stamps[k]) + 2_000_002,
                )
        writer.finish()
    with pytest.warns(LogWarning) as caught:
        log = read_mcap(path)
    text = " ".join(str(w.message) for w in caught)
    assert "/rosout_text" in text and "std_msgs/msg/String" in text and "/sensors/mag" not in text
    assert set(log.skipped) == {"/rosout_text"}
    assert list(log.devices) == ["sensors/imu_raw"] and not log.truncated
    assert log.device.topics == {"imu": "/sensors/imu_raw", "mag": "/sensors/mag"}
    s = log.samples
    assert np.array_equal(s.gyro, gyro) and np.array_equal(s.accel, accel)
    assert np.array_equal(log.device.stamp_ns, stamps)  # the header stamps, not the log times
    assert np.all(np.abs(s.t - stamps / 1e9) <= np.spacing(s.t) / 2)  # float64 seconds: nearest value
    field = np.arange(n) % 10 == 0
    assert np.array_equal(s.mag[field], np.tile([1e-5, 0.0, 0.0], (n // 10, 1))) and np.isnan(s.mag[~field]).all()
    assert s.raw == {}
    assert log.message_count == n + 2 * (n // 10)


def test_unchunked_foreign_file(tmp_path):
    path = tmp_path / "plain.mcap"
    rows = IMU.encode(np.arange(1, 51) * 10**7, "imu", {"angular_velocity": np.arange(150.0).reshape(50, 3)})
    write_plain_imu(path, rows, use_chunking=False)
    log = read_quietly(path)
    assert list(log.devices) == ["imu0"]
    assert np.array_equal(log.samples.gyro, np.arange(150.0).reshape(50, 3))


def test_rosbags_anyreader_reads_our_log(tmp_path, runs):
    """rosbags' high-level reader (rosbag2 semantics) takes the file as a bag, custom raw type included."""
    from rosbags.highlevel import AnyReader

    _, samples, truth = runs["navigation_rlg"]
    path = write_mcap(tmp_path / "run.mcap", Recording(samples, truth=truth))
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/imu": "sensor_msgs/msg/Imu",
            "/truth/imu": "sensor_msgs/msg/Imu",
            "/raw/rlg": "gyroemu_msgs/msg/RlgRaw",
            "/tf": "tf2_msgs/msg/TFMessage",
        }
        counts = {}
        for connection, log_time, data in reader.messages():
            msg = reader.deserialize(data, connection.msgtype)
            k = counts.get(connection.topic, 0)
            counts[connection.topic] = k + 1
            header = msg.transforms[0].header if connection.topic == "/tf" else msg.header
            assert log_time == header.stamp.sec * 10**9 + header.stamp.nanosec
            if connection.topic == "/raw/rlg":
                assert np.array_equal(msg.fringe_count, samples.raw["rlg"]["fringe_count"][k])
            elif connection.topic == "/imu":
                assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == list(samples.gyro[k])
    assert 0 < counts.pop("/tf") < len(samples)  # thinned to the /tf rate: test_ros2_conventions.py
    assert counts == {"/imu": len(samples), "/truth/imu": len(samples), "/raw/rlg": len(samples)}


def test_an_unchunked_file_is_handed_out_in_batches(tmp_path, monkeypatch):
    """Messages outside chunks (rosbag2's 'fastwrite' preset) go out LOOSE_BATCH at a time, in file order,
    every field as found, with the channels' other records between them; check() counts them all
    (a message at a time, the copy cost 0.35 ms a message). The walk's batches of a chunked file are
    its chunks, as before."""
    from gyroemu.pipelines.formats import mcap_records
    from gyroemu.pipelines.formats.mcap_records import McapRecordWalk, McapScan

    monkeypatch.setattr(mcap_records, "LOOSE_BATCH", 16)
    path = tmp_path / "plain.mcap"
    n = 50
    rows = IMU.encode(np.arange(1, n + 1) * 10**7, "imu", {"angular_velocity": np.arange(3.0 * n).reshape(n, 3)})
    with open(path, "wb") as f:
        writer = PlainMcapWriter(f, use_chunking=False)
        writer.start("ros2", "test")
        schema = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", IMU.schema.encode())
        first = writer.register_channel("/imu", "cdr", schema)
        for k, row in enumerate(rows):
            if k == 20:  # a channel defined between the messages
                second = writer.register_channel("/imu2", "cdr", schema)
            channel = first if k < 20 or k % 2 else second
            writer.add_message(channel, log_time=(k + 1) * 10**7, data=row.tobytes(), publish_time=k, sequence=7 * k)
        writer.finish()
    batches = list(McapRecordWalk(path).batches())
    assert [len(b.size) for b in batches] == [16, 16, 16, 2]
    joined = [(int(b.channel_id[k]), int(b.sequence[k]), int(b.log_time[k]), int(b.publish_time[k]), b.payload(k))
              for b in batches for k in range(len(b.size))]  # fmt: skip
    assert [(s, t, p) for _, s, t, p, _ in joined] == [(7 * k, (k + 1) * 10**7, k) for k in range(n)]
    assert [payload for *_, payload in joined] == [row.tobytes() for row in rows]
    assert sum(McapScan(path).check().values()) == n


def test_rosbag2_mcap_written_by_rosbags_is_read(tmp_path):
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as BagWriter

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    rng = np.random.default_rng(4)
    gyro, accel = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    stamps = 1_000 * 10**9 + np.arange(40) * 2_500_000
    with BagWriter(tmp_path / "bag", version=8, storage_plugin=StoragePlugin.MCAP) as bag:
        connection = bag.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=store)
        for k in range(40):
            sec, nanosec = divmod(int(stamps[k]), 10**9)
            msg = t["sensor_msgs/msg/Imu"](
                header=t["std_msgs/msg/Header"](
                    stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id="imu_link"
                ),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=t["geometry_msgs/msg/Vector3"](*gyro[k]),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=t["geometry_msgs/msg/Vector3"](*accel[k]),
                linear_acceleration_covariance=np.zeros(9),
            )
            bag.write(connection, int(stamps[k]) + 1000, store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    log = read_quietly(next((tmp_path / "bag").glob("*.mcap")))
    assert list(log.devices) == ["imu/data"]
    assert np.array_equal(log.samples.gyro, gyro) and np.array_equal(log.samples.accel, accel)
    assert np.array_equal(log.device.stamp_ns, stamps)


def test_chunks_split_where_messages_start(tmp_path):
    """McapFileWriter's chunk k holds the messages whose records start in [k, k + 1) × chunk_size of the
    records laid end to end (31 bytes of Message record head before each payload), from the first call:
    with chunk_size = 3 r + 1, message 3 starts at byte 3 r = chunk_size − 1, still in chunk 0."""
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter

    n = 12
    payloads = IMU.encode(np.arange(n), "imu0")
    record = 31 + payloads.shape[1]
    chunk_size = 3 * record + 1
    path = tmp_path / "chunks.mcap"
    with open(path, "wb") as f:
        writer = McapFileWriter(f, chunk_size=chunk_size)
        channel = writer.register_ros2_channel("/imu", IMU)
        writer.add_messages([(channel, 10 * np.arange(n), payloads)])
        writer.finish()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chunk_of = np.arange(n) * record // chunk_size
    expected = [
        (10 * int(np.flatnonzero(chunk_of == k)[0]), 10 * int(np.flatnonzero(chunk_of == k)[-1]))
        for k in range(chunk_of[-1] + 1)
    ]
    assert expected[0] == (0, 30)
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert [(c.message_start_time, c.message_end_time) for c in chunks] == expected
    assert [c.uncompressed_size for c in chunks] == [record * int(np.sum(chunk_of == k)) for k in range(len(expected))]


def test_imu_series_compares_by_identity_and_is_hashable():
    """Like every array record of the package (frozen, eq=False): == is identity (a field-wise == of
    arrays would be ambiguous) and a series can key a dict."""
    t = np.arange(3.0)
    a = ImuSeries(t=t, omega_b=np.zeros((3, 3)))
    b = ImuSeries(t=t, omega_b=np.zeros((3, 3)))
    assert a == a and a != b
    assert {a: "a", b: "b"}[b] == "b"


def test_stamps_match_nothing_on_an_empty_channel():
    from gyroemu.pipelines.formats.mcap_log import match_stamps

    i, j = match_stamps(np.array([5, 7, 9], np.int64), np.empty(0, np.int64))
    assert i.shape == j.shape == (0,) and i.dtype == j.dtype == np.int64
    i, j = match_stamps(np.array([5, 7, 9], np.int64), np.array([9, 5], np.int64))
    assert list(i) == [0, 2] and list(j) == [1, 0]


def test_a_field_pairs_with_the_first_sample_at_or_after_it():
    """match_latest against its definition written out: sample i takes the latest message stamped in
    (reference[i−1], reference[i]] (the first sample: in (previous, reference[0]], or at its own stamp
    without a previous), at equal stamps the later in file order; and a series cut into blocks, each
    given the last stamp of the block before, pairs as it does whole."""
    from gyroemu.pipelines.formats.mcap_log import match_latest, match_stamps

    rng = np.random.default_rng(4)
    for _ in range(200):
        reference = np.cumsum(rng.integers(1, 6, rng.integers(1, 30))).astype(np.int64)
        stamps = rng.integers(-2, int(reference[-1]) + 3, rng.integers(0, 40)).astype(np.int64)
        previous = None if rng.random() < 0.5 else int(reference[0]) - int(rng.integers(1, 4))
        want_i, want_j = [], []
        for i, s_i in enumerate(reference):
            low = (int(reference[0]) - 1 if previous is None else previous) if i == 0 else int(reference[i - 1])
            inside = [j for j, m in enumerate(stamps) if low < m <= s_i]
            if inside:
                latest = max(stamps[j] for j in inside)
                want_i.append(i)
                want_j.append(max(j for j in inside if stamps[j] == latest))
        i, j = match_latest(reference, stamps, previous)
        assert list(i) == want_i and list(j) == want_j
        cut = int(rng.integers(1, len(reference) + 1))
        a_i, a_j = match_latest(reference[:cut], stamps, previous)
        b_i, b_j = match_latest(reference[cut:], stamps, int(reference[cut - 1]))
        assert list(np.concatenate([a_i, b_i + cut])) == want_i and list(np.concatenate([a_j, b_j])) == want_j
    exact = np.array([5, 7, 9], np.int64)
    for stamps in (exact, np.array([9, 5], np.int64), np.array([7], np.int64)):  # at the samples' stamps
        assert [list(x) for x in match_latest(exact, stamps)] == [list(x) for x in match_stamps(exact, stamps)]


def test_topic_message_types_by_role():
    """Live-stream topics by their role, whatever the device prefix; /movement is for files only."""
    assert topic_message_type("/imu") is IMU and topic_message_type("/imu0/imu") is IMU
    assert topic_message_type("/truth/imu") is IMU and topic_message_type("/a/b/estimate/imu") is IMU
    assert topic_message_type("/imu0/mag") is MAGNETIC_FIELD
    assert topic_message_type("/imu0/raw/fog") is RAW_MESSAGE_TYPES["fog"]
    assert topic_message_type("/movement") is None and topic_message_type("/camera") is None


def test_movement_flags_as_booleans_or_zeros_and_ones():
    stamp_ns = np.array([10, 20, 30, 40], np.int64)
    flags = np.array([False, True, True, False])
    rows = encode_movement(stamp_ns, "imu0", flags)
    assert np.array_equal(FLAG.decode(rows)["data"], flags)
    assert np.array_equal(encode_movement(stamp_ns, "imu0", flags.astype(np.int64)), rows)
    assert np.array_equal(encode_movement(stamp_ns, "imu0", flags.astype(float)), rows)
    for bad in (np.array([0, 1, 2, 0]), flags[:3], np.array([0.0, 0.5, 1.0, 1.0])):
        with pytest.raises(ValueError, match="movement must be 4 booleans"):
            encode_movement(stamp_ns, "imu0", bad)


def test_exact_stamps_reach_a_truth_at_the_same_times_only(tmp_path, runs):
    """With ``stamp_ns``, a truth within 1 us of the samples' times is stamped with them exactly; one
    2 us off keeps its own stamps (to the nanosecond)."""
    _, samples, truth = runs["ideal"]
    stamp_ns = np.rint(samples.t * 1e9).astype(np.int64) + 7  # not what samples.t rounds to
    for shift_ns, want_ns in ((400, stamp_ns), (2000, np.rint(samples.t * 1e9).astype(np.int64) + 2000)):
        shifted = ImuSeries(t=truth.t + shift_ns * 1e-9, q_wb=truth.q_wb, omega_b=truth.omega_b)
        path = write_mcap(tmp_path / f"{shift_ns}.mcap", Recording(samples, truth=shifted, stamp_ns=stamp_ns))
        with open(path, "rb") as f:
            stamps = [
                message.log_time
                for _, channel, message in make_reader(f).iter_messages()
                if channel.topic == "/truth/imu"
            ]
        assert np.array_equal(stamps, want_ns), shift_ns


def test_raw_observables_without_a_field_warn_once_per_device(tmp_path, runs):
    _, samples, _ = runs["navigation_fog"]
    extra = {k: {**o, "coil_temperature_degC": np.full(len(samples), 25.0)} for k, o in samples.raw.items()}
    odd = ImuSamples(t=samples.t, gyro=samples.gyro, accel=samples.accel, mag=samples.mag, raw=extra)
    with pytest.warns(LogWarning, match="has no field for coil_temperature_degC; not recorded") as caught:
        with McapLogWriter(tmp_path / "odd.mcap") as log:
            log.write(_slice(odd, 0, 50))
            log.write(_slice(odd, 50, len(odd)))
    assert sum("coil_temperature_degC" in str(w.message) for w in caught) == 1
    assert_samples_equal(read_quietly(tmp_path / "odd.mcap").samples, samples)


def test_samples_without_a_movement_flag_read_as_false_with_a_warning(tmp_path, runs):
    _, samples, _ = runs["ideal"]
    n = len(samples)
    with McapLogWriter(tmp_path / "part.mcap") as log:
        log.write(Recording(_slice(samples, 0, 100), movement=np.ones(100, bool)))
        log.write(_slice(samples, 100, n))
    with pytest.warns(LogWarning, match=f"{n - 100} samples of /imu have no message on /movement"):
        d = read_mcap(tmp_path / "part.mcap").device
    assert d.movement[:100].all() and not d.movement[100:].any()


def test_exact_stamps_reach_a_short_truth_too(tmp_path, runs):
    """The same snapping for a recording of a few samples (lengths compared by value, at any length)."""
    _, full, truth = runs["ideal"]
    k = 100
    samples = ImuSamples(t=full.t[:k], gyro=full.gyro[:k], accel=full.accel[:k], mag=full.mag[:k])
    stamp_ns = np.rint(samples.t * 1e9).astype(np.int64) + 7
    shifted = ImuSeries(t=truth.t[:k] + 400e-9, q_wb=truth.q_wb[:k], omega_b=truth.omega_b[:k])
    path = write_mcap(tmp_path / "short.mcap", Recording(samples, truth=shifted, stamp_ns=stamp_ns))
    with open(path, "rb") as f:
        stamps = [m.log_time for _, c, m in make_reader(f).iter_messages() if c.topic == "/truth/imu"]
    assert np.array_equal(stamps, stamp_ns)


def test_truth_series_is_taken_at_the_true_sampling_instants(trajectory, runs):
    """``/truth/imu`` is the body truth at ``t_true`` (where the device really sampled), stamped ``t``."""
    _, full, _ = runs["ideal"]
    t = full.t[5:-5]
    late = t + 0.37 * (t[1] - t[0])
    stamped = ImuSamples(t=t, gyro=full.gyro[5:-5], accel=full.accel[5:-5], mag=full.mag[5:-5], t_true=late)
    at_late = ImuSamples(t=late, gyro=stamped.gyro, accel=stamped.accel, mag=stamped.mag)
    a, b = truth_series(trajectory, stamped), truth_series(trajectory, at_late)
    assert np.array_equal(a.t, t)
    assert np.array_equal(a.omega_b, b.omega_b) and np.array_equal(a.q_wb, b.q_wb)
    assert (
        np.abs(
            a.omega_b
            - truth_series(trajectory, ImuSamples(t=t, gyro=stamped.gyro, accel=stamped.accel, mag=stamped.mag)).omega_b
        ).max()
        > 0
    )


def test_a_chunk_of_unknown_compression_is_refused_by_name(tmp_path, runs):
    """A chunk whose compression is not "", "lz4" or "zstd" is refused, naming it, even when its bytes
    happen to be valid zstd (here the name "zstd" is overwritten with "zzzz")."""
    _, samples, truth = runs["ideal"]
    path = write_mcap(tmp_path / "z.mcap", Recording(samples, truth=truth))
    data = path.read_bytes()
    assert data.count(b"\x04\x00\x00\x00zstd") >= 1
    path.write_bytes(data.replace(b"\x04\x00\x00\x00zstd", b"\x04\x00\x00\x00zzzz"))
    with pytest.raises(LogError, match="unknown compression 'zzzz'"):
        read_mcap(path)


def test_messages_of_equal_log_time_keep_their_file_order(tmp_path):
    """Log-time order, file order for equal times: a chunked file whose messages all share one log
    time reads back in the order written, chunk by chunk."""
    path = tmp_path / "same_time.mcap"
    rows = IMU.encode(np.arange(1, 51) * 10**7, "imu", {"angular_velocity": np.arange(150.0).reshape(50, 3)})
    with open(path, "wb") as f:
        writer = PlainMcapWriter(f, chunk_size=1024, compression=CompressionType.NONE)
        writer.start("ros2", "test")
        schema = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", IMU.schema.encode())
        channel = writer.register_channel("/imu", "cdr", schema)
        for k, row in enumerate(rows):
            writer.add_message(channel, log_time=10**9, data=row.tobytes(), publish_time=0, sequence=k)
        writer.finish()
    log = read_quietly(path)
    assert np.array_equal(log.samples.gyro, np.arange(150.0).reshape(50, 3))
    assert np.array_equal(log.device.stamp_ns, np.arange(1, 51) * 10**7)


def test_equal_log_times_keep_file_order_across_payload_sizes(tmp_path):
    """Frame ids of two lengths make payloads of two sizes, decoded a size at a time: with every log
    time equal, only the messages' file order puts them back in sequence."""
    path = tmp_path / "two_sizes.mcap"
    n = 40
    rows = [IMU.encode([k + 1], ["imu", "imu_link"][k % 2], {"angular_velocity": [[k, 0.0, 0.0]]})[0] for k in range(n)]
    write_plain_imu(
        path, np.array(rows, dtype=object), log_time=10**9, chunk_size=4096, compression=CompressionType.NONE
    )
    log = read_quietly(path)
    assert np.array_equal(log.samples.gyro[:, 0], np.arange(n))


def test_record_walk_hands_out_every_message_unchanged(tmp_path):
    """:class:`McapRecordWalk` gives each Message record's fields and payload as written, from chunks
    and from records outside chunks alike."""
    from gyroemu.pipelines.formats.mcap_records import McapRecordWalk

    rows = IMU.encode(np.arange(1, 31) * 10**7, "imu", {"angular_velocity": np.arange(90.0).reshape(30, 3)})
    for chunked in (True, False):
        path = tmp_path / f"walk_{chunked}.mcap"
        write_plain_imu(path, rows, use_chunking=chunked, chunk_size=4096, compression=CompressionType.NONE)
        batches = list(McapRecordWalk(path).batches())
        assert (1 < len(batches) < 30) if chunked else (len(batches) == 1)  # a batch per chunk; LOOSE_BATCH loose
        payloads = [b.payload(k) for b in batches for k in range(len(b.size))]
        assert payloads == [row.tobytes() for row in rows]
        assert np.all(np.concatenate([b.size for b in batches]) == rows.shape[1])  # not just slices cut short
        assert np.array_equal(np.concatenate([b.sequence for b in batches]), 3 * np.arange(30))
        assert np.array_equal(np.concatenate([b.publish_time for b in batches]), 7 * np.arange(30))
        assert np.array_equal(np.concatenate([b.log_time for b in batches]), np.arange(1, 31) * 10**7)


def test_raw_messages_are_copied_from_anywhere_in_a_buffer(tmp_path):
    """``add_raw_messages`` takes payloads of several sizes at any offsets of a buffer (gaps between them,
    out of order) with their own sequence numbers and publish times, and writes them as given, into
    a file that already holds messages."""
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter

    rng = np.random.default_rng(5)
    sizes = np.array([5, 40, 1, 17, 64, 3])
    start = np.array([100, 7, 300, 60, 200, 290])  # gaps, and not in buffer order
    buffer = rng.integers(0, 256, 400, dtype=np.uint8)
    path = tmp_path / "raw.mcap"
    with open(path, "wb") as f:
        writer = McapFileWriter(f, chunk_size=64)
        channel = writer.register_ros2_channel("/imu", IMU)
        other = writer.register_ros2_channel("/other", IMU)
        writer.add_messages([(channel, [1, 2], IMU.encode([1, 2], "imu"))])
        writer.add_raw_messages(
            np.array([channel, other, channel, other, channel, other]),
            np.array([9, 8, 7, 6, 5, 4]),
            np.arange(3, 9),
            np.arange(100, 106),
            buffer,
            start,
            sizes,
        )
        writer.finish()
    with open(path, "rb") as f:
        messages = [
            (c.topic, m.sequence, m.log_time, m.publish_time, m.data) for _, c, m in make_reader(f).iter_messages()
        ]
    assert messages[2:] == [
        (["/imu", "/other"][k % 2], 9 - k, 3 + k, 100 + k, buffer[start[k] : start[k] + sizes[k]].tobytes())
        for k in range(6)
    ]


def test_several_batches_of_one_channel_continue_its_sequence_numbers(tmp_path):
    """Two batches of one channel in one call, after an earlier call: the channel's messages are numbered
    in file order, continuing from the earlier call's."""
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter

    path = tmp_path / "seq.mcap"
    with open(path, "wb") as f:
        writer = McapFileWriter(f)
        channel = writer.register_ros2_channel("/imu", IMU)
        writer.add_messages([(channel, [0, 1, 2, 3, 4], IMU.encode(np.arange(5), "imu"))])
        writer.add_messages(
            [(channel, [10, 12, 14], IMU.encode([10, 12, 14], "imu")), (channel, [11, 13], IMU.encode([11, 13], "imu"))]
        )
        writer.finish()
    with open(path, "rb") as f:
        got = [(m.log_time, m.sequence) for _, _, m in make_reader(f).iter_messages()]
    assert got == [(t, k) for k, t in enumerate([0, 1, 2, 3, 4, 10, 11, 12, 13, 14])]


def test_chunk_indexes_span_their_message_indexes(tmp_path, runs):
    """Each Chunk Index gives the bytes of the Message Index records that follow its chunk: the next
    chunk starts right after them."""
    path = tmp_path / "index.mcap"
    _, samples, _ = runs["consumer_mems"]
    write_mcap(path, samples, chunk_size=4096)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) > 3
    for this, following in zip(chunks, chunks[1:]):
        assert this.chunk_start_offset + this.chunk_length + this.message_index_length == following.chunk_start_offset


def test_message_batches_carry_the_payloads_written(tmp_path):
    """``iter_mcap_batches`` hands out each message's payload bytes as written."""
    from gyroemu.pipelines.formats.mcap_records import iter_mcap_batches

    rows = IMU.encode(np.arange(1, 21) * 10**7, "imu_frame", {"angular_velocity": np.arange(60.0).reshape(20, 3)})
    path = tmp_path / "batches.mcap"
    write_plain_imu(path, rows, chunk_size=4096, compression=CompressionType.NONE)
    got = [m.data for batch in iter_mcap_batches(path) for m in batch]
    assert got == [row.tobytes() for row in rows]


def test_a_record_cut_inside_its_head_is_refused():
    """Records are walked by their 9-byte heads (opcode, length): fewer than 9 bytes left after the last
    whole record is a partial record, refused by name."""
    from gyroemu.pipelines.formats.mcap_records import _record_positions

    record = struct.pack("<BQ", 0x05, 4) + b"abcd"
    data = record * 3 + record[:5]
    with pytest.raises(ValueError, match="a partial record at its end"):
        _record_positions(data, np.frombuffer(data, np.uint8))


@pytest.mark.parametrize(
    "topics, devices, skipped",
    [
        (["/a/imu", "/a/mag", "/a/truth/imu", "/b/imu", "/b/mag"], {"/a": "/a/mag", "/b": "/b/mag"}, set()),
        (["/imu/data_raw", "/imu/mag", "/mag"], {"/imu/data_raw": "/imu/mag"}, {"/mag"}),  # the nearest field
        (
            ["/r1/imu/data_raw", "/r1/imu/mag", "/r2/imu/data_raw", "/r2/imu/mag"],
            {"/r1/imu/data_raw": "/r1/imu/mag", "/r2/imu/data_raw": "/r2/imu/mag"},
            set(),
        ),  # fmt: skip
        (["/mag", "/a/imu", "/b/imu"], {"/a": "/mag", "/b": "/mag"}, set()),  # one field for the robot
        (["/a/truth/imu", "/mag"], {"/a/truth/imu": None}, {"/mag"}),  # a truth is no magnetometer's device
        (["/imu/data_raw", "/estimate/imu"], {"/imu/data_raw": None}, set()),
    ],
)
def test_devices_are_grouped_whatever_the_channels_order(topics, devices, skipped):
    """group_devices' namespace and lone-estimate rules give the same devices, fields and skipped topics
    for the channels in either order (the first field met went to every IMU topic under the root, and a
    truth promoted early counted as a measured device)."""
    from types import SimpleNamespace

    from gyroemu.pipelines.formats.mcap_log import group_devices

    for order in (topics, topics[::-1]):
        channels = [SimpleNamespace(topic=t, mtype=MAGNETIC_FIELD if t.endswith("mag") else IMU) for t in order]
        found: dict[str, str] = {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LogWarning)
            groups = group_devices(Path("x.mcap"), channels, found)
        assert {k: (g["mag"].topic if "mag" in g else None) for k, g in groups.items()} == devices, order
        assert set(found) == skipped, order
    if "/estimate/imu" in topics:
        assert groups["/imu/data_raw"]["estimate/imu"].topic == "/estimate/imu"
