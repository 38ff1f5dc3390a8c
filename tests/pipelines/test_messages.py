"""CDR codecs of gyroemu.pipelines.formats.messages against the CDR rules and two independent ROS 2 serialisers.

Exactness: encoding copies float64/int64/bool values into bytes and decoding copies them back, so
round trips are bit-exact (no tolerance); stamps are integers. The only rounding is seconds to
nanoseconds in ``stamps_to_ns``: at most 0.5 ns plus the float64 rounding of ``t * 1e9``.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gyroemu.pipelines.formats.messages import (
    IMU,
    MAGNETIC_FIELD,
    MESSAGE_TYPES,
    POSE_STAMPED,
    RAW_MESSAGE_TYPES,
    message_type,
    ns_to_stamps,
    raw_fields,
    raw_observables,
    schema_text,
    split_payloads,
    stamps_to_ns,
)

ALL_TYPES = list(MESSAGE_TYPES.values())
FRAME_IDS = ["imu0", "", "a", "base_link", "capteur_é"]  # lengths 4, 0, 1, 9, 10 bytes (utf-8)


def _typestore():
    store = get_typestore(Stores.ROS2_HUMBLE)
    for mtype in MESSAGE_TYPES.values():
        if mtype.name.startswith("gyroemu_msgs/"):  # the project's own types (raw observables, Flag)
            store.register(get_types_from_msg(mtype.schema, mtype.name))
    return store


STORE = _typestore()


def random_fields(mtype, n, rng):
    """Random values for every body field (integers over the full int64 range, NaN and inf included)."""
    fields = {}
    for spec in mtype.body:
        shape = (n,) if spec.count == 1 else (n, spec.count)
        if spec.dtype == "?":
            fields[spec.name] = rng.random(shape) < 0.5
        elif spec.dtype == "<i8":
            fields[spec.name] = rng.integers(-(2**63), 2**63 - 1, shape, dtype=np.int64)
        else:
            values = rng.normal(0, 10.0 ** rng.integers(-12, 12, shape), shape)
            values.flat[:3] = [np.nan, np.inf, -0.0][: values.size]
            fields[spec.name] = values
    return fields


def random_stamps(n, rng):
    return np.sort(rng.integers(-(2**31) * 10**9, (2**31 - 1) * 10**9, n))


# ---------------------------------------------------------------------------------------------------
# Layout from the CDR rules.


@pytest.mark.parametrize("frame_id", FRAME_IDS)
def test_imu_layout_follows_the_cdr_alignment_rules(frame_id):
    length = len(frame_id.encode()) + 1  # with NUL
    body = -(-(12 + length) // 8) * 8  # first float64 on an 8-byte boundary of the payload
    assert IMU.message_size(frame_id) == 4 + body + (4 + 9 + 3 + 9 + 3 + 9) * 8
    layout = IMU.layout(len(frame_id.encode()))
    assert layout.fields["orientation"][1] == 4 + body
    assert layout.fields["linear_acceleration_covariance"][1] == 4 + body + (4 + 9 + 3 + 9 + 3) * 8
    assert IMU.message_size("imu0") == 324


def test_raw_layouts_follow_the_cdr_alignment_rules():
    # frame_id "imu0": header ends at payload offset 17; float64/int64 fields start at 24.
    assert RAW_MESSAGE_TYPES["rlg"].message_size("imu0") == 4 + 24 + 3 * 3 * 8
    assert RAW_MESSAGE_TYPES["fog"].message_size("imu0") == 4 + 24 + 3 * 3 * 8 + 1  # bool, no tail padding
    assert RAW_MESSAGE_TYPES["free-gyro"].message_size("imu0") == 4 + 24 + 7 * 8 + 1


def test_header_bytes():
    rows = IMU.encode([1_500_000_007], "imu0")
    assert rows[0, :4].tobytes() == b"\x00\x01\x00\x00"
    assert rows[0, 4:8].view("<i4")[0] == 1 and rows[0, 8:12].view("<u4")[0] == 500_000_007
    assert rows[0, 12:16].view("<u4")[0] == 5 and rows[0, 16:21].tobytes() == b"imu0\x00"
    assert not rows[0, 21:28].any()  # padding is zero


def test_negative_stamps_split_as_ros_time():
    # builtin_interfaces/Time: -1.7 s is {sec: -2, nanosec: 3e8}.
    rows = IMU.encode([-1_700_000_000], "x")
    view = rows.view(IMU.layout(1))[:, 0]
    assert view["sec"][0] == -2 and view["nanosec"][0] == 300_000_000
    assert IMU.decode(rows).stamp_ns[0] == -1_700_000_000
    with pytest.raises(ValueError, match="int32"):
        IMU.encode([2**31 * 10**9], "x")


def test_seconds_to_nanoseconds():
    rng = np.random.default_rng(1)
    t = rng.uniform(0, 1e5, 10_000)
    ns = stamps_to_ns(t)
    # |t·1e9 − ns| ≤ 0.5 ns + the rounding of the product (≤ 1 ulp of 1e14 ns ≈ 0.016 ns).
    assert np.max(np.abs(t * 1e9 - ns)) <= 0.5 + 2 * np.spacing(1e14)
    assert np.array_equal(stamps_to_ns(ns_to_stamps(ns)), ns)
    with pytest.raises(ValueError):
        stamps_to_ns([np.nan])


# ---------------------------------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("mtype", ALL_TYPES, ids=lambda t: t.name)
@pytest.mark.parametrize("frame_id", FRAME_IDS)
def test_round_trip_is_exact(mtype, frame_id):
    rng = np.random.default_rng(zlib.crc32(f"{mtype.name} {frame_id}".encode()))
    n = 257
    stamps = random_stamps(n, rng)
    fields = random_fields(mtype, n, rng)
    rows = mtype.encode(stamps, frame_id, fields)
    assert rows.shape == (n, mtype.message_size(frame_id)) and rows.dtype == np.uint8
    decoded = mtype.decode(rows)
    assert np.array_equal(decoded.stamp_ns, stamps)
    assert list(decoded.frame_id) == [frame_id] * n
    for name, values in fields.items():
        got = decoded[name]
        assert got.dtype == values.dtype
        assert np.array_equal(got.view(np.uint8), np.ascontiguousarray(values).view(np.uint8)), name  # bit-exact
    again = mtype.encode(decoded.stamp_ns, frame_id, {k: decoded[k] for k in fields})
    assert np.array_equal(again, rows)
    # per-message bytes decode the same
    assert np.array_equal(mtype.decode(split_payloads(rows)).stamp_ns, stamps)


def test_decode_mixed_frame_ids_and_lengths_keeps_order():
    rng = np.random.default_rng(2)
    payloads, expected = [], []
    for k in range(60):
        frame = FRAME_IDS[k % len(FRAME_IDS)] * (k % 3)
        fields = random_fields(IMU, 1, rng)
        payloads += split_payloads(IMU.encode([k], frame, fields))
        expected.append((frame, fields["angular_velocity"][0]))
    decoded = IMU.decode(payloads)
    assert list(decoded.stamp_ns) == list(range(60))
    for k, (frame, gyro) in enumerate(expected):
        assert decoded.frame_id[k] == frame
        assert np.array_equal(decoded["angular_velocity"][k], gyro, equal_nan=True)


def test_decode_accepts_xtypes_tail_padding():
    # DDS-XTypes: a writer may pad to a multiple of 4 and count the padding in the option bytes.
    rows = RAW_MESSAGE_TYPES["fog"].encode([5, 6], "imu0", {"sagnac_phase_rad": [[1.0, 2.0, 3.0]] * 2})
    padding = (-rows.shape[1]) % 4
    padded = np.concatenate([rows, np.zeros((2, padding), np.uint8)], axis=1)
    padded[:, 3] = padding
    decoded = RAW_MESSAGE_TYPES["fog"].decode(padded)
    assert np.array_equal(decoded["sagnac_phase_rad"], [[1.0, 2.0, 3.0]] * 2)


@pytest.mark.parametrize("damage", ["big_endian", "short", "long", "string_length"])
def test_decode_rejects_malformed(damage):
    rows = IMU.encode([1, 2], "imu0").copy()
    if damage == "big_endian":
        rows[:, 1] = 0
        match = "little-endian"
    elif damage == "short":
        rows = rows[:, :-8]
        match = "bytes"
    elif damage == "long":
        rows = np.concatenate([rows, np.zeros((2, 8), np.uint8)], axis=1)
        match = "bytes"
    else:
        rows[:, 12] = 0
        match = "string length of 0"
    with pytest.raises(ValueError, match=match):
        IMU.decode(rows)


@pytest.mark.parametrize("size", [1, 4, 5, 12, 16])
def test_decode_refuses_messages_shorter_than_a_header(size):
    """A message needs the 4-byte encapsulation, the 12 fixed header bytes (stamp and the frame id's
    string length) and at least the string's NUL: anything up to 16 bytes is too short, whatever it holds."""
    rows = IMU.encode([1, 2], "imu0")[:, :size]
    with pytest.raises(ValueError, match=rf"^a {size}-byte message is too short for a sensor_msgs/msg/Imu$"):
        IMU.decode(rows)


def test_decode_numbers_the_bad_message_among_mixed_lengths():
    """Payloads 1 and 2 share a length (frame ids "ab" and "abc" pad to the same size) but not a string
    length; payload 2's string length is then zeroed: the error names message 2."""
    first, second, third = (split_payloads(IMU.encode([k], f))[0] for k, f in enumerate(["base_link", "ab", "abc"]))
    assert len(first) != len(second) == len(third)
    third = third[:12] + bytes(4) + third[16:]
    with pytest.raises(ValueError, match=r"^message 2: a CDR string length of 0"):
        IMU.decode([first, second, third])


@pytest.mark.parametrize("mtype", [IMU, MAGNETIC_FIELD], ids=lambda t: t.name)
def test_decode_of_no_rows_is_empty(mtype):
    decoded = mtype.decode(np.empty((0, mtype.message_size("imu0")), np.uint8))
    assert len(decoded) == 0 and decoded.stamp_ns.shape == (0,) and decoded.frame_id.shape == (0,)
    for spec in mtype.body:
        assert decoded[spec.name].shape[0] == 0


def test_encode_checks_names_and_shapes():
    with pytest.raises(ValueError, match="no field"):
        IMU.encode([0], "x", {"gyro": np.zeros((1, 3))})
    with pytest.raises(ValueError, match="shape"):
        IMU.encode([0, 1], "x", {"angular_velocity": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="NUL"):
        IMU.encode([0], "a\x00b")


def test_fog_feedback_presence_flag():
    fog = RAW_MESSAGE_TYPES["fog"]
    open_loop = {"sagnac_phase_rad": np.ones((2, 3)), "detector_power_w": np.ones((2, 3))}
    mtype, fields, ignored = raw_fields("fog", {**open_loop, "extra_v": np.ones(2)})
    assert ignored == ["extra_v"]
    decoded = fog.decode(fog.encode([0, 1], "x", fields))
    assert not decoded["closed_loop"].any() and np.isnan(decoded["feedback_phase_rad"]).all()
    assert set(raw_observables(fog, decoded)) == {"sagnac_phase_rad", "detector_power_w"}
    closed = dict(open_loop, feedback_phase_rad=np.zeros((2, 3)))
    decoded = fog.decode(fog.encode([0, 1], "x", raw_fields("fog", closed)[1]))
    assert decoded["closed_loop"].all()
    assert set(raw_observables(fog, decoded)) == set(closed)
    with pytest.raises(ValueError, match="lack"):
        raw_fields("rlg", {"fringe_count": np.zeros((2, 3), np.int64)})


# ---------------------------------------------------------------------------------------------------
# Independent serialisers: rosbags (Humble type store) and mcap_ros2.


def _nested(mtype, stamp_ns, frame_id, fields, k):
    """Message k as the nested dict the ROS definitions describe."""
    sec, nanosec = divmod(int(stamp_ns[k]), 10**9)
    msg = {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}}
    for spec in mtype.body:
        value = fields[spec.name][k]
        if spec.name in ("orientation",):
            msg[spec.name] = dict(zip("xyzw", map(float, value)))
        elif mtype in (IMU, MAGNETIC_FIELD, POSE_STAMPED) and spec.count == 3:
            msg[spec.name] = dict(zip("xyz", map(float, value)))
        elif spec.count == 1:
            msg[spec.name] = value.item()
        else:
            msg[spec.name] = value.tolist()
    if mtype is POSE_STAMPED:  # geometry_msgs/Pose holds the position and orientation
        msg["pose"] = {"position": msg.pop("position"), "orientation": msg.pop("orientation")}
    return msg


def _rosbags_message(name, data):
    cls = STORE.types[name]
    kwargs = {}
    for field_name, (node, detail) in STORE.fielddefs[name][1]:
        value = data[field_name]
        if node == 2:  # a nested message
            kwargs[field_name] = _rosbags_message(detail, value)
        elif node == 3:
            kwargs[field_name] = np.array(value, dtype=detail[0][1][0].replace("float64", "f8").replace("int64", "i8"))
        else:
            kwargs[field_name] = value
    return cls(**kwargs)


@pytest.mark.parametrize("mtype", ALL_TYPES, ids=lambda t: t.name)
def test_bytes_identical_to_rosbags_and_mcap_ros2(mtype):
    rng = np.random.default_rng(7)
    n = 20
    stamps = random_stamps(n, rng)
    fields = random_fields(mtype, n, rng)
    frame_id = "imu_link"
    rows = mtype.encode(stamps, frame_id, fields)
    encode_mcap = serialize_dynamic(mtype.name, mtype.schema)[mtype.name]
    for k in range(n):
        nested = _nested(mtype, stamps, frame_id, fields, k)
        ours = rows[k].tobytes()
        assert bytes(STORE.serialize_cdr(_rosbags_message(mtype.name, nested), mtype.name)) == ours
        assert bytes(encode_mcap(nested)) == ours


@pytest.mark.parametrize("mtype", ALL_TYPES, ids=lambda t: t.name)
def test_independent_decoders_read_the_same_numbers(mtype):
    rng = np.random.default_rng(8)
    n = 20
    stamps = random_stamps(n, rng)
    fields = random_fields(mtype, n, rng)
    rows = mtype.encode(stamps, "imu0", fields)
    decode_mcap = generate_dynamic(mtype.name, mtype.schema)[mtype.name]
    for k in range(n):
        data = rows[k].tobytes()
        a = STORE.deserialize_cdr(data, mtype.name)
        b = decode_mcap(data)
        for msg in (a, b):
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamps[k]
            assert msg.header.frame_id == "imu0"
            for spec in mtype.body:
                value = getattr(msg.pose if mtype is POSE_STAMPED else msg, spec.name)
                if spec.name == "orientation":
                    value = [value.x, value.y, value.z, value.w]
                elif mtype in (IMU, MAGNETIC_FIELD, POSE_STAMPED) and spec.count == 3:
                    value = [value.x, value.y, value.z]
                assert np.array_equal(np.asarray(value, dtype=spec.dtype), fields[spec.name][k], equal_nan=True)


# ---------------------------------------------------------------------------------------------------
# Schemas.


@pytest.mark.parametrize("name", ["sensor_msgs/msg/Imu", "sensor_msgs/msg/MagneticField"])
def test_standard_schemas_define_the_humble_types(name):
    text = schema_text(name)
    parsed = get_types_from_msg(text, name)
    reference = get_typestore(Stores.ROS2_HUMBLE)
    for type_name, definition in parsed.items():
        assert definition == reference.fielddefs[type_name], type_name
    assert set(parsed) == {name, "geometry_msgs/msg/Vector3", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"} | (
        {"geometry_msgs/msg/Quaternion"} if name.endswith("Imu") else set()
    )


def test_schema_names_in_any_form():
    """``pkg/msg/Type`` and ``pkg/Type`` name the same schema; a name in neither form is looked up as
    given (an unknown one is a KeyError naming it)."""
    assert schema_text("sensor_msgs/Imu") == schema_text("sensor_msgs/msg/Imu")
    assert schema_text("Point", {"Point": "float64 x\n"}) == "float64 x\n"
    with pytest.raises(KeyError, match="Imu"):
        schema_text("Imu")
    with pytest.raises(KeyError, match="sensor_msgs/srv/Imu"):
        schema_text("sensor_msgs/srv/Imu")


def test_schema_concatenation_is_rosbag2s():
    text = schema_text("sensor_msgs/msg/Imu")
    assert text.startswith("# This is a message to hold data from an IMU (Inertial Measurement Unit)\n")
    # dependencies depth first, sorted at each level, each after "\n" + 80 "=" + "\nMSG: pkg/Type\n"
    order = [line for line in text.splitlines() if line.startswith("MSG: ")]
    assert order == [
        "MSG: geometry_msgs/Quaternion",
        "MSG: geometry_msgs/Vector3",
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]
    assert text.count("\n\n" + "=" * 80 + "\nMSG: ") == 4
    assert text.endswith("uint32 nanosec\n")


@pytest.mark.parametrize("mtype", list(RAW_MESSAGE_TYPES.values()), ids=lambda t: t.name)
def test_raw_schemas_parse_and_use_the_observable_names(mtype):
    parsed = get_types_from_msg(mtype.schema, mtype.name)
    fields = [name for name, _ in parsed[mtype.name][1]]
    assert fields == ["header"] + [spec.name for spec in mtype.body]
    assert message_type(mtype.name) is mtype
    assert message_type(mtype.name.replace("/msg/", "/")) is mtype
    assert mtype.kind in RAW_MESSAGE_TYPES
