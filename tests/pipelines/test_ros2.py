"""ROS 2 mode (``--ros2``): REP-2011 type hashes, rmw_zenoh key expressions and liveliness tokens, and
``gyroemu stream --ros2`` -> ``gyroemu router`` -> ``gyroemu record --ros2`` between real processes.

The reference hashes below are not computed here: they are the values ``rosidl_generator_c`` writes
into the generated ``<type>__description.c`` files of the ROS 2 packages (for instance
``sensor_msgs/msg/detail/imu__description.c``, ``sensor_msgs__msg__Imu__get_type_hash``, as shipped in
the micro-ROS build of hpmicro/hpm_sdk, ``middleware/microros/kilted/include/...``; the same
``RIHS01_7d9a00ff...`` is what rmw_zenoh publishers of ``sensor_msgs/msg/Imu`` put in their keys on
Jazzy). gyroemu computes its hashes from the ``.msg`` texts; the test holds them to these values.

Run alone with ``pytest tests/pipelines/test_ros2.py -n 0 -s``; the live test takes about 15 s.
"""

import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from live_processes import Listener, free_port, mcap_messages, procs, write_foreign  # noqa: E402,F401
from zenoh_samples import Sample  # noqa: E402

from gyroemu.pipelines.formats import ros2_keys  # noqa: E402
from gyroemu.pipelines.formats.ros2_keys import (  # noqa: E402
    Ros2Error,
    data_key,
    domain_id,
    entity_token,
    gyroemu_topic,
    node_token,
    parse_data_key,
    parse_definitions,
    qos_keyexpr,
    ros_topic,
    type_description,
    type_hash,
)

ROOT = Path(__file__).resolve().parents[2]

# rosidl_generator_c's values (see the module's notes): type -> RIHS01 hash.
PUBLISHED = {
    "sensor_msgs/msg/Imu": "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "sensor_msgs/msg/MagneticField": "RIHS01_e80f32f56a20486c9923008fc1a1db07bbb273cbbf6a5b3bfa00835ee00e4dff",
    "std_msgs/msg/Header": "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
    "builtin_interfaces/msg/Time": "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
    "geometry_msgs/msg/Quaternion": "RIHS01_8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684",
    "geometry_msgs/msg/Vector3": "RIHS01_cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d",
}
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"  # std_msgs/msg/String
CHAR_HASH = "RIHS01_3ad2d04dd29ba19d04b16659afa3ccaedd691914b02a64e82e252f2fa6a586a9"  # std_msgs/msg/Char


def test_type_hashes_equal_the_published_values():
    """Imu, MagneticField and the types they reference, from gyroemu's own .msg texts; String and Char
    from one-line definitions (``char`` is ``uint8`` in ROS 2: FieldType 3, not 13)."""
    for name, expected in PUBLISHED.items():
        assert type_hash(name) == expected, name
    assert type_hash("std_msgs/msg/String", {"std_msgs/String": "string data\n"}) == STRING_HASH
    assert type_hash("std_msgs/msg/Char", {"std_msgs/Char": "char data\n"}) == CHAR_HASH
    imu = type_description("sensor_msgs/msg/Imu")
    assert [t["type_name"] for t in imu["referenced_type_descriptions"]] == [
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Vector3",
        "std_msgs/msg/Header",
    ]
    assert imu["type_description"]["fields"][2] == {
        "name": "orientation_covariance",
        "type": {"type_id": 59, "capacity": 9, "string_capacity": 0, "nested_type_name": ""},
    }  # DOUBLE (11) + ARRAY (48)


def test_hash_depends_on_fields_only():
    """Comments, blank lines, constants and default values do not change the hash; a field's name, its
    type or an array's size does (each edit below would pass unnoticed by a hash of the wrong input)."""
    base = "float64 x 0\nfloat64[9] c\nstring<=8 s\nint32[<=4] q\nuint8 K=3\n"
    h = type_hash("p/msg/T", {"p/T": base})
    assert (
        type_hash(
            "p/msg/T", {"p/T": "# hi\n\nfloat64 x 1.5  # default\nfloat64[9] c\nstring<=8 s\nint32[<=4] q\nuint8 K=4\n"}
        )
        == h
    )
    for changed in (
        "float64 y\nfloat64[9] c\nstring<=8 s\nint32[<=4] q\n",
        "float32 x\nfloat64[9] c\nstring<=8 s\nint32[<=4] q\n",
        "float64 x\nfloat64[8] c\nstring<=8 s\nint32[<=4] q\n",
        "float64 x\nfloat64[9] c\nstring<=9 s\nint32[<=4] q\n",
        "float64 x\nfloat64[9] c\nstring<=8 s\nint32[] q\n",
    ):
        assert type_hash("p/msg/T", {"p/T": changed}) != h, changed
    with pytest.raises(Ros2Error, match="no definition"):
        type_hash("p/msg/U", {"p/U": "p/Missing m\n"})


def test_hash_agrees_with_rosbags_for_every_ros2_type():
    """An independent implementation (rosbags' ``hash_rihs01``), over every message type of its Jazzy
    store, parsed from the ``.msg`` text rosbags generates: equal, except where rosbags maps ``char``
    to FieldType CHAR (13) -- there gyroemu follows rosidl (``uint8``), whose Char hash is above."""
    rosbags_typesys = pytest.importorskip("rosbags.typesys")
    store = rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_JAZZY)
    compared = uses_char = 0
    for name in sorted(store.fielddefs):
        if "/msg/" not in name:
            continue
        text = store.generate_msgdef(name, ros_version=2)[0]
        ours = type_hash(name, parse_definitions(text, name))
        if any(line.split(" ")[0].startswith("char") for line in text.splitlines()):
            uses_char += 1
            assert ours != store.hash_rihs01(name), name
            continue
        assert ours == store.hash_rihs01(name), name
        compared += 1
    print(f"\n{compared} types equal to rosbags' hash; {uses_char} with char fields differ as expected")
    assert compared > 100 and uses_char >= 1


def test_gyroemu_mcap_schema_gives_the_same_hash(tmp_path):
    """The ``ros2msg`` schema gyroemu writes into MCAP (definition + MSG: sections) parses back to the
    same hash, for Imu and for every raw type."""
    from gyroemu.pipelines.formats.messages import MESSAGE_TYPES

    for name, mtype in MESSAGE_TYPES.items():
        assert type_hash(name, parse_definitions(mtype.schema, name)) == type_hash(name), name


def test_keys_and_tokens_follow_rmw_zenoh():
    """Data keys ``<domain>/<topic>/<type>/<hash>`` and liveliness tokens with the 9 (node) and 13
    (publisher) chunks rmw_zenoh's ``Entity::make`` parses, none empty; QoS chunk parts as its
    ``keyexpr_to_qos`` splits them."""
    imu = PUBLISHED["sensor_msgs/msg/Imu"]
    assert ros_topic("imu0", "/raw/rate_gyro") == "/imu0/raw/rate_gyro"
    assert ros_topic("imu0", "/raw/rate-gyro") == "/imu0/raw/rate_gyro"  # an older log's name, replayed
    assert gyroemu_topic("/imu0/raw/rate_gyro") == ("imu0", "/raw/rate_gyro")
    assert gyroemu_topic("/imu0/truth/imu") == ("imu0", "/truth/imu")
    for bad in ("/raw/x.y", "/2d/imu"):
        with pytest.raises(Ros2Error):
            ros_topic("imu0", bad)
    with pytest.raises(Ros2Error):
        gyroemu_topic("/rosout")
    key = data_key(7, "/imu0/imu", "sensor_msgs/msg/Imu", imu)
    assert key == f"7/imu0/imu/sensor_msgs::msg::dds_::Imu_/{imu}"
    parsed = parse_data_key(key)
    assert (parsed.domain, parsed.topic, parsed.type_name, parsed.type_hash) == (
        7,
        "/imu0/imu",
        "sensor_msgs/msg/Imu",
        imu,
    )
    with pytest.raises(Ros2Error):
        parse_data_key("gyroemu/imu0/imu")

    zid = "8e7efefe973896f23b94768cad80842b"
    node = node_token(0, zid, 0, "gyroemu_stream_1")
    assert node == f"@ros2_lv/0/{zid}/0/0/NN/%/%/gyroemu_stream_1"
    pub = entity_token("MP", 0, zid, 0, 3, "gyroemu_stream_1", "/imu0/imu", "sensor_msgs/msg/Imu", imu)
    assert pub == (
        f"@ros2_lv/0/{zid}/0/3/MP/%/%/gyroemu_stream_1/%imu0%imu/sensor_msgs::msg::dds_::Imu_/{imu}/::2,:,:,:,,"
    )
    assert len(node.split("/")) == 9 and len(pub.split("/")) == 13
    assert all(node.split("/")) and all(pub.split("/"))
    qos = pub.split("/")[-1].split(":")  # reliability, durability, history+depth, deadline, lifespan, liveliness
    assert len(qos) == 6 and qos[2].split(",") == ["2", ""] and len(qos[5].split(",")) == 3
    assert qos_keyexpr(reliability=ros2_keys.BEST_EFFORT, history=ros2_keys.KEEP_LAST, depth=5) == "2::,5:,:,:,,"
    assert qos_keyexpr(history=ros2_keys.KEEP_LAST, depth=42) == "::,:,:,:,,"  # all rmw_zenoh's defaults

    assert domain_id(None, {}) == 0 and domain_id(None, {"ROS_DOMAIN_ID": " 42 "}) == 42
    assert domain_id(5, {"ROS_DOMAIN_ID": "42"}) == 5
    for value, env, what in ((233, {}, "--domain"), (None, {"ROS_DOMAIN_ID": "x"}, "ROS_DOMAIN_ID")):
        with pytest.raises(Ros2Error, match=what):
            domain_id(value, env)


def test_bad_ros2_usage_exits_2_naming_the_argument(tmp_path):
    env = dict(os.environ, ROS_DOMAIN_ID="abc")
    cases = [
        (
            ["stream", "--scenario", "heavy_top", "--device", "consumer_mems", "--ros2", "--domain", "300"],
            os.environ,
            "argument --domain",
        ),
        (["record", "--out", str(tmp_path / "x.mcap"), "--ros2"], env, "ROS_DOMAIN_ID"),
        (["replay", str(tmp_path / "x.mcap"), "--domain", "3"], os.environ, "argument --domain: only with --ros2"),
        (
            ["stream", "--scenario", "heavy_top", "--device", "consumer_mems", "--ros2", "--device-name", "9x"],
            os.environ,
            "argument --device-name",
        ),
    ]
    for args, environ, text in cases:
        run = subprocess.run(
            [sys.executable, "-m", "gyroemu", *args], cwd=ROOT, env=environ, capture_output=True, text=True, timeout=60
        )
        assert run.returncode == 2 and text in run.stderr, (args, run.returncode, run.stderr)
    assert not (tmp_path / "x.mcap").exists()


def _client(endpoint: str):
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    return zenoh.open(config)


@pytest.mark.slow
def test_stream_router_record_in_ros2_mode(procs, tmp_path):
    """``stream --ros2`` and ``record --ros2`` as clients of ``gyroemu router`` (three processes), with a
    plain zenoh client beside them that watches the liveliness tokens and the data keys: the tokens
    of one node and its four publishers appear (and go when the stream ends), the keys are rmw_zenoh's
    with the published Imu hash, and the recording holds every message, byte for byte what the same
    scenario, device and seed encode, on the plain topics, with the type hash in its channel metadata."""
    duration, seed, name, domain = 4.0, 5, "ros", 17
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start("router", "router", "--listen", endpoint)
    procs.wait_for("router", "listening")
    plain = _client(endpoint)
    try:
        tokens = plain.liveliness().declare_subscriber(
            f"@ros2_lv/{domain}/**", zenoh.handlers.FifoChannel(256), history=True
        )
        data = plain.declare_subscriber(f"{domain}/**", zenoh.handlers.FifoChannel(1 << 16))
        procs.start(
            "rec",
            "record",
            "--out",
            str(tmp_path / "r.mcap"),
            "--ros2",
            "--domain",
            str(domain),
            "--connect",
            endpoint,
            "--mode",
            "client",
            "--report",
            str(tmp_path / "r.json"),
        )
        procs.wait_for("rec", "subscribed")
        procs.start(
            "stream",
            "stream",
            "--scenario",
            "heavy_top",
            "--device",
            "consumer_mems",
            "--duration",
            str(duration),
            "--seed",
            str(seed),
            "--device-name",
            name,
            "--ros2",
            "--domain",
            str(domain),
            "--connect",
            endpoint,
            "--mode",
            "client",
            "--start-time",
            "0",  # stamps from 0 s, as encode_run's below
        )
        assert procs.wait("stream", 120) == 0, procs.log("stream")
        time.sleep(1.0)
        assert procs.stop("rec") == 0, procs.log("rec")
        events = []
        while (sample := tokens.try_recv()) is not None:
            events.append((str(sample.kind).split(".")[-1], str(sample.key_expr)))
        keys: dict[str, list[int]] = {}
        while (sample := data.try_recv()) is not None:
            keys.setdefault(str(sample.key_expr), []).append(struct.unpack_from("<q", sample.attachment.to_bytes())[0])
    finally:
        plain.close()
    print("\n" + procs.log("stream") + procs.log("rec"))
    n = int(round(duration * 1000))
    imu = PUBLISHED["sensor_msgs/msg/Imu"]
    expected_keys = {
        f"{domain}/{name}/imu/sensor_msgs::msg::dds_::Imu_/{imu}",
        f"{domain}/{name}/truth/imu/sensor_msgs::msg::dds_::Imu_/{imu}",
        f"{domain}/{name}/mag/sensor_msgs::msg::dds_::MagneticField_/{PUBLISHED['sensor_msgs/msg/MagneticField']}",
        f"{domain}/{name}/raw/mems/gyroemu_msgs::msg::dds_::MemsRaw_/{type_hash('gyroemu_msgs/msg/MemsRaw')}",
    }
    from gyroemu.pipelines.formats.tf_messages import TF_DEFINITIONS

    tf_hash = type_hash("tf2_msgs/msg/TFMessage", TF_DEFINITIONS)
    tf_keys = {f"{domain}/{topic}/tf2_msgs::msg::dds_::TFMessage_/{tf_hash}" for topic in ("tf", "tf_static")}
    assert set(keys) == expected_keys | tf_keys  # the tf tree on the global ROS 2 topics /tf, /tf_static
    assert all(keys[k] == list(range(n)) for k in expected_keys)  # the plain client saw every message in order
    assert all(keys[k] == list(range(len(keys[k]))) for k in tf_keys)

    stream_tokens = [k for kind, k in events if kind == "PUT" and "/gyroemu_stream_" in k]
    gone = {k for kind, k in events if kind == "DELETE"}
    nodes = [k for k in stream_tokens if k.split("/")[5] == "NN"]
    pubs = [k for k in stream_tokens if k.split("/")[5] == "MP"]
    assert len(nodes) == 1 and len(pubs) == 6, events
    zid = nodes[0].split("/")[2]
    assert all(k.split("/")[2] == zid for k in pubs)
    for k in pubs:  # the token's topic, type and hash are those of a data key
        parts = k.split("/")
        assert f"{domain}/{parts[9].replace('%', '/').strip('/')}/{parts[10]}/{parts[11]}" in expected_keys | tf_keys
        if parts[9] == "%tf_static":  # tf2's StaticBroadcasterQoS: transient local, keep-last 1
            assert parts[12] == ":1:,1:,:,:,,"
    assert set(stream_tokens) <= gone  # withdrawn when the stream ended
    record_tokens = [k for kind, k in events if kind == "PUT" and "/gyroemu_record_" in k]
    assert sum(k.split("/")[5] == "MS" for k in record_tokens) == 6  # one subscription per recorded topic

    report = json.loads((tmp_path / "r.json").read_text())
    rows = {r["topic"]: r for r in report["publishers"].values()}
    assert sorted(rows) == sorted(
        [*(f"{name}{t}" for t in ("/imu", "/mag", "/truth/imu", "/raw/mems")), "/tf", "/tf_static"]
    )
    for tf in ("/tf", "/tf_static"):  # the file's tree, no device
        r = rows.pop(tf)
        assert (r["first"], r["missing"], r["duplicates"]) == (0, 0, 0), r
    assert all(
        (r["received"], r["first"], r["last"], r["missing"], r["duplicates"]) == (n, 0, n - 1, 0, 0)
        for r in rows.values()
    ), rows

    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.imu_covariance import measurement_variances
    from gyroemu.pipelines.formats.mcap_log import read_mcap, truth_series
    from gyroemu.pipelines.formats.mcap_records import mcap_channel_info
    from gyroemu.pipelines.transport.stream import encode_run
    from gyroemu.sensors import load_device

    traj = load_scenario("heavy_top").simulate(duration=duration)
    samples = load_device("consumer_mems", seed=seed).measure(traj)
    variances = measurement_variances(load_device("consumer_mems"))
    encoded = encode_run(samples, truth_series(traj, samples), variances=variances)
    from mcap.reader import make_reader

    with open(tmp_path / "r.mcap", "rb") as f:
        got: dict[str, list[bytes]] = {}
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            got.setdefault(channel.topic, []).append(message.data)
    assert sorted(got) == sorted([*encoded, "/tf", "/tf_static"])
    for topic, rows_ in encoded.items():
        assert got[topic] == [bytes(r) for r in rows_], f"{topic}: payload bytes differ"
    hashes = {c.topic: c.metadata.get("topic_type_hash") for c in mcap_channel_info(tmp_path / "r.mcap")}
    assert hashes["/imu"] == hashes["/truth/imu"] == imu
    log = read_mcap(tmp_path / "r.mcap")
    np.testing.assert_array_equal(log.device.samples.gyro, samples.gyro)
    assert procs.stop("router") == 0


def test_replay_ros2_of_a_foreign_file(procs, tmp_path):
    """``replay --ros2`` of someone else's bag (mcap_ros2 writer, no recorded hash): its Imu topic and its
    String topic go out on rmw_zenoh keys with hashes computed from the file's schemas (equal to the
    published values), bytes unchanged."""
    path = tmp_path / "foreign.mcap"
    write_foreign(path, 200)
    listener = Listener("0/**")
    try:
        procs.start(
            "replay", "replay", str(path), "--ros2", "--domain", "0", "--rate", "4", "--connect", listener.endpoint
        )
        assert procs.wait("replay", 60) == 0, procs.log("replay")
        time.sleep(0.3)
        got: dict[str, list[bytes]] = {}
        for key, payload, _, _ in listener.drain():
            got.setdefault(key, []).append(payload)
    finally:
        listener.close()
    print("\n" + procs.log("replay"))
    imu_key = f"0/imu0/sensors/imu_raw/sensor_msgs::msg::dds_::Imu_/{PUBLISHED['sensor_msgs/msg/Imu']}"
    text_key = f"0/imu0/rosout_text/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert set(got) == {imu_key, text_key}
    assert got[imu_key] == [m[2] for m in mcap_messages(path, "/sensors/imu_raw")]
    assert got[text_key] == [m[2] for m in mcap_messages(path, "/rosout_text")]


def test_recorder_maps_ros2_keys_back_to_topics(tmp_path):
    """Without processes: a raw topic keeps its ROS 2 name, gyroemu's own (``/raw/rate_gyro``), the
    type hash goes into the channel metadata, the schema is the key's type, and a key of a
    one-token topic (``/rosout``) or of another form is skipped, counted."""
    import numpy as np

    from gyroemu.pipelines.formats.mcap_records import mcap_channel_info
    from gyroemu.pipelines.formats.messages import IMU, RAW_MESSAGE_TYPES
    from gyroemu.pipelines.transport.record import Recorder, ros2_key
    from gyroemu.pipelines.transport.zenoh_io import pack_attachment

    raw = RAW_MESSAGE_TYPES["rate-gyro"]
    raw_hash = type_hash(raw.name)
    imu_payload = bytes(IMU.encode(np.array([1_000_000_000]), "dev")[0])
    raw_payload = bytes(raw.encode(np.array([1_000_000_000]), "dev", {"gimbal_angle_rad": [[0.1, 0.2, 0.3]]})[0])
    gid = bytes(range(16))
    recorder = Recorder(tmp_path / "r.mcap", parse_key=ros2_key)
    recorder.add(
        Sample(data_key(0, "/dev/imu", IMU.name, PUBLISHED[IMU.name]), imu_payload, pack_attachment(0, 1, gid))
    )
    recorder.add(
        Sample(
            data_key(0, ros_topic("dev", "/raw/rate-gyro"), raw.name, raw_hash),
            raw_payload,
            pack_attachment(0, 1, bytes(16)),
        )
    )
    recorder.add(
        Sample(
            f"0/rosout/rcl_interfaces::msg::dds_::Log_/{PUBLISHED[IMU.name]}", imu_payload, pack_attachment(0, 1, gid)
        )
    )
    recorder.add(Sample("gyroemu/dev/imu", imu_payload, pack_attachment(1, 1, gid)))
    recorder.close()
    assert (recorder.messages, recorder.skipped) == (2, 2)
    channels = {c.topic: c for c in mcap_channel_info(tmp_path / "r.mcap")}
    assert sorted(channels) == ["/imu", "/raw/rate_gyro"]
    assert channels["/raw/rate_gyro"].schema_name == raw.name
    assert channels["/raw/rate_gyro"].metadata["topic_type_hash"] == raw_hash
    assert channels["/imu"].metadata["topic_type_hash"] == PUBLISHED[IMU.name]


# -- /tf_static of a ROS 2 replay: advertised transient local, so sent again for late listeners ------------


def _bag_with_tf_static(folder: Path, seconds: float) -> Path:
    """A bag written by rosbags (MCAP storage): ``/imu`` at 100 Hz for ``seconds`` from 2024-06-01 and
    ``/tf_static`` (``base_link`` -> ``imu_link``) once, with the first sample. Returns the MCAP file."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    Header, Time = t["std_msgs/msg/Header"], t["builtin_interfaces/msg/Time"]
    Q, V, Imu = t["geometry_msgs/msg/Quaternion"], t["geometry_msgs/msg/Vector3"], t["sensor_msgs/msg/Imu"]
    TS, Tr, TF = t["geometry_msgs/msg/TransformStamped"], t["geometry_msgs/msg/Transform"], t["tf2_msgs/msg/TFMessage"]
    t0, cov = 1_717_200_000 * 10**9, np.zeros(9)

    def header(ns: int, frame: str):
        return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        ci = w.add_connection("/imu", Imu.__msgtype__, typestore=ts)
        cs = w.add_connection("/tf_static", TF.__msgtype__, typestore=ts)
        for k in range(round(seconds * 100)):
            lt = t0 + k * 10_000_000
            if k == 0:
                mount = Tr(translation=V(x=0.1, y=0.0, z=0.0), rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0))
                static = TF(transforms=[TS(header=header(lt, "base_link"), child_frame_id="imu_link", transform=mount)])
                w.write(cs, lt, ts.serialize_cdr(static, TF.__msgtype__))
            imu = Imu(
                header=header(lt, "imu_link"),
                orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=cov,
                angular_velocity=V(x=0.0, y=0.0, z=0.1 * k),
                angular_velocity_covariance=cov,
                linear_acceleration=V(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=cov,
            )
            w.write(ci, lt, ts.serialize_cdr(imu, Imu.__msgtype__))
    (path,) = folder.glob("*.mcap")
    return path


def _produced(path: Path, keys: dict[str, str], loop: bool = False, until_ns: int | None = None, **kw) -> list:
    """Every ``(deadline ns, key, payload)`` a replay's reader makes of ``path`` at rate 1 (its generator,
    no thread), up to deadline ``until_ns`` when looping."""
    from gyroemu.pipelines.transport.replay import ReadAhead

    out = []
    for batch in ReadAhead(path, keys, 1.0, loop, **kw).produce():
        out.extend(batch)
        if until_ns is not None and batch[-1][0] > until_ns:
            break
    return out


def test_replay_sends_tf_static_again_every_second_of_log_time(tmp_path):
    """ROS 2 mode: the reader sends the file's ``/tf_static`` again, the same bytes, every
    TF_STATIC_REPEAT_S of log time (as ``gyroemu stream`` does); every other message is as it was, in
    the same order. With ``--loop`` the repeats are the pass's message (stamps shifted)."""
    from gyroemu.pipelines.formats.frames import TF_STATIC_REPEAT_S

    path = _bag_with_tf_static(tmp_path / "bag", 3.5)
    keys = {"/imu": "d/imu", "/tf_static": "d/tf_static"}
    recorded = [d for _, _, d in mcap_messages(path, "/tf_static")]
    plain = _produced(path, keys)
    repeated = _produced(path, keys, repeat_static="/tf_static")
    assert [x for x in repeated if x[1] != "d/tf_static"] == [x for x in plain if x[1] != "d/tf_static"]
    statics = [(t, d) for t, k, d in repeated if k == "d/tf_static"]
    step = round(TF_STATIC_REPEAT_S * 1e9)
    assert [t for t, _ in statics] == [0, step, 2 * step, 3 * step]
    assert all(d == recorded[0] for _, d in statics)
    assert [d for t, k, d in plain if k == "d/tf_static"] == recorded  # without: once
    # looping: pass 1's message (stamps moved by the pass's shift) and its repeats
    looped = _produced(path, keys, True, 6 * step, repeat_static="/tf_static")
    second = [(t, d) for t, k, d in looped if k == "d/tf_static" and t >= 3.5 * step]
    assert second and second[0][1] != recorded[0] and all(d == second[0][1] for _, d in second)


@pytest.mark.slow
def test_a_tf2_listener_joining_a_ros2_replay_late_gets_the_mounting(procs, tmp_path):
    """``replay --ros2`` advertises ``/tf_static`` transient local (tf2's StaticBroadcasterQoS) but zenoh
    keeps no history: a listener that joins 1.5 s in gets the file's ``/tf_static`` (the same bytes) from
    the repeats; it got none."""
    from gyroemu.pipelines.transport.zenoh_io import drain, open_session, session_config, subscribe

    path = _bag_with_tf_static(tmp_path / "bag", 3.5)
    recorded = [d for _, _, d in mcap_messages(path, "/tf_static")]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    try:
        procs.start("replay", "replay", str(path), "--ros2", "--domain", "57", "--wait", "0", "--connect", endpoint)
        procs.wait_for("replay", "replay: publishing")
        time.sleep(1.5)
        late = subscribe(session, "57/tf_static/**")
        assert procs.wait("replay", 30) == 0, procs.log("replay")
        time.sleep(0.3)
        got = [bytes(s.payload.to_bytes()) for s in drain(late)]
    finally:
        session.close()
    assert got and all(d == recorded[0] for d in got), (len(got), procs.log("replay"))
