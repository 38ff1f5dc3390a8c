"""The Foxglove live view (``--foxglove``, ``gyroemu view``), tested as the Foxglove app sees it: a plain
WebSocket client (the ``websockets`` package, not the SDK) speaking Foxglove's WebSocket protocol
(subprotocol ``foxglove.sdk.v1``; ``foxglove.websocket.v1`` before), subscribing to the advertised
channels and decoding each message by its advertised schema: ``ros2msg`` by ``mcap_ros2``'s dynamic
decoder, ``protobuf`` from the advertised ``FileDescriptorSet``.
"""

import base64
import json
import signal
import struct
import sys
import threading
import time
from contextlib import ExitStack

import numpy as np
import pytest
import websockets.exceptions as websockets_exceptions
import websockets.sync.client as websockets_sync
from live_processes import procs  # noqa: F401  (fixture)

from gyroemu.pipelines.formats.channels import ImuSeries, encode_series
from gyroemu.pipelines.formats.messages import IMU, MAGNETIC_FIELD, split_payloads
from gyroemu.pipelines.transport.foxglove_view import (
    FoxgloveView,
    Mounting,
    ViewOptions,
    channel_specs,
    check_view_options,
)

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01  # server binary opcode: uint32 subscription id, uint64 log time, payload
EPS = np.finfo(float).eps


class FoxgloveClient:
    """A minimal Foxglove WebSocket client: channels advertised, subscriptions, decoded messages."""

    def __init__(self, port: int, timeout: float = 10.0):
        self._exit = ExitStack()  # entered as a context manager: websockets ≥ 15 deprecates a bare connect()
        self.ws = self._exit.enter_context(
            websockets_sync.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=timeout)
        )
        assert self.ws.subprotocol in SUBPROTOCOLS
        self.channels: dict[int, dict] = {}
        self.server_info: dict = {}
        self.subscriptions: dict[int, dict] = {}
        self.received: dict[str, list[tuple[int, bytes]]] = {}
        self.texts: list[dict] = []
        self.binary_other: list[bytes] = []  # binary server messages other than message data
        self._decoders: dict[int, object] = {}

    def close(self):
        self._exit.close()

    def _handle(self, frame) -> None:
        if isinstance(frame, str):
            msg = json.loads(frame)
            self.texts.append(msg)
            if msg.get("op") == "serverInfo":
                self.server_info = msg
            elif msg.get("op") == "advertise":
                for c in msg["channels"]:
                    self.channels[c["id"]] = c
            return
        if frame[0] != MESSAGE_DATA:
            self.binary_other.append(bytes(frame))
            return
        sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
        topic = self.subscriptions[sub_id]["topic"]
        self.received.setdefault(topic, []).append((log_time, bytes(frame[13:])))

    def pump(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                self._handle(self.ws.recv(timeout=left))
            except TimeoutError:
                return
            except websockets_exceptions.ConnectionClosed:
                return

    def wait_for_topics(self, topics, timeout: float = 10.0) -> None:
        end = time.monotonic() + timeout
        while not set(topics) <= {c["topic"] for c in self.channels.values()}:
            assert time.monotonic() < end, f"advertised {[c['topic'] for c in self.channels.values()]}"
            self.pump(0.05)

    def subscribe_all(self) -> None:
        subs = []
        for cid, c in self.channels.items():
            sid = len(self.subscriptions) + 1
            self.subscriptions[sid] = c
            subs.append({"id": sid, "channelId": cid})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def decoded(self, topic: str) -> list[tuple[int, object]]:
        """``(log time, message)`` of a topic, decoded by its advertised schema."""
        channel = next(c for c in self.channels.values() if c["topic"] == topic)
        decode = self._decoder(channel)
        return [(t, decode(data)) for t, data in self.received.get(topic, [])]

    def _decoder(self, channel: dict):
        if channel["id"] in self._decoders:
            return self._decoders[channel["id"]]
        if channel.get("schemaEncoding") == "ros2msg":
            assert channel["encoding"] == "cdr"
            from mcap.records import Schema
            from mcap_ros2.decoder import DecoderFactory

            schema = Schema(id=1, name=channel["schemaName"], encoding="ros2msg", data=channel["schema"].encode())
            decode = DecoderFactory().decoder_for("cdr", schema)
        elif channel["encoding"] == "json":
            assert channel.get("schemaEncoding") == "jsonschema"
            properties = json.loads(channel["schema"])["properties"]

            def decode(data: bytes) -> dict:
                msg = json.loads(data)
                assert set(msg) <= set(properties), f"{set(msg) - set(properties)} not in the schema"
                return msg
        else:
            assert channel["encoding"] == "protobuf" and channel.get("schemaEncoding") == "protobuf"
            from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

            files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"])).file
            pool = descriptor_pool.DescriptorPool()
            pending = list(files)
            while pending:  # dependencies first, whatever the set's order
                f = pending.pop(0)
                try:
                    pool.Add(f)
                except TypeError:
                    pending.append(f)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
            decode = cls.FromString
        self._decoders[channel["id"]] = decode
        return decode


def _rotate(q, v):
    """``R(q) v`` for unit quaternion (w, x, y, z): ``v + 2 w (u x v) + 2 u x (u x v)``, u the vector part."""
    w, u = q[0], np.asarray(q[1:])
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


BIAS = np.array([0.02, -0.01, 0.005])  # rad/s
BIAS_HAT = np.array([0.018, -0.012, 0.004])  # rad/s


def synthetic_run(n: int, rate: float, seed: int = 7):
    """Topic -> payloads of a synthetic run: the body turning about a tilted axis, an estimate off by a
    small rotation, a magnetometer reading the field ``m_w`` in body axes; a gyro reading the true rate
    plus ``BIAS`` and noise, an estimate whose bias-corrected rate is the gyro's less ``BIAS_HAT``."""
    rng = np.random.default_rng(seed)
    t = 1_700_000_000.0 + np.arange(n) / rate
    angle = 0.8 * (t - t[0])
    axis = np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93])
    q = np.column_stack([np.cos(angle / 2), np.outer(np.sin(angle / 2), axis)])
    err = np.array([np.cos(0.05), np.sin(0.05), 0.0, 0.0])  # 0.1 rad about x
    w1, v1 = q[:, :1], q[:, 1:]
    q_est = np.column_stack([w1[:, 0] * err[0] - v1 @ err[1:], w1 * err[1:] + err[0] * v1 + np.cross(v1, err[1:])])
    stamp_ns = np.round(t * 1e9).astype(np.int64)
    m_w = np.array([0.0, 2.2e-5, -4.1e-5])
    m_b = np.array([_rotate(qq * [1, -1, -1, -1], m_w) for qq in q])
    omega = np.outer(np.full(n, 0.8), axis)  # body rate of a turn about a fixed axis: the axis times the rate
    gyro = omega + BIAS + 0.01 * rng.normal(size=(n, 3))
    fields = {"angular_velocity": gyro, "linear_acceleration": rng.normal(size=(n, 3))}
    return (
        {
            "/imu": split_payloads(IMU.encode(stamp_ns, "imu0", fields)),
            "/mag": split_payloads(MAGNETIC_FIELD.encode(stamp_ns, "imu0", {"magnetic_field": m_b})),
            "/truth/imu": split_payloads(encode_series(stamp_ns, ImuSeries(t=t, q_wb=q, omega_b=omega))),
            "/estimate/imu": split_payloads(
                encode_series(stamp_ns, ImuSeries(t=t, q_wb=q_est, omega_b=gyro - BIAS_HAT))
            ),
        },
        stamp_ns,
        q,
        q_est,
        m_w,
        gyro,
        omega,
    )


def in_sensor_axes(payloads, stamp_ns, q, m_w, gyro, q_bs, seed: int = 3):
    """``payloads`` of :func:`synthetic_run` with ``/imu`` and ``/mag`` measured by an IMU mounted by
    ``q_bs`` (sensor -> body): the gyro's rates and the field in the IMU's axes, ``R_sb v_b``; the truth
    and the estimate stay the body's (as ``gyroemu estimate`` writes a mounted device's)."""
    q_sb = np.asarray(q_bs) * [1, -1, -1, -1]
    gyro_s = np.array([_rotate(q_sb, g) for g in gyro])
    m_s = np.array([_rotate(q_sb, _rotate(qq * [1, -1, -1, -1], m_w)) for qq in q])
    accel = np.random.default_rng(seed).normal(size=(len(gyro), 3))
    out = dict(payloads)
    fields = {"angular_velocity": gyro_s, "linear_acceleration": accel}
    out["/imu"] = split_payloads(IMU.encode(stamp_ns, "imu0", fields))
    out["/mag"] = split_payloads(MAGNETIC_FIELD.encode(stamp_ns, "imu0", {"magnetic_field": m_s}))
    return out


def test_live_view_as_a_client_sees_it():
    """Batches tapped from a paced publisher reach a plain WebSocket client: every forwarded message with
    its header stamp, /tf at the display rate equal to the truth and the estimate at the same stamps,
    and a scene whose gravity and field arrows are R_bw g_w and R_bw m_w (round-off). The IMU is
    mounted (its rates and field in its own axes): the errors are in body axes."""
    n, rate, display = 240, 400.0, 40.0  # 0.6 s of samples, frames every 25 ms
    payloads, stamp_ns, q, q_est, m_w, gyro, omega = synthetic_run(n, rate)
    q_bs = np.array([0.5, 0.5, -0.5, 0.5])  # a 120° turn: the IMU's axes permuted
    payloads = in_sensor_axes(payloads, stamp_ns, q, m_w, gyro, q_bs)
    topics = list(payloads)
    keys = {topic: f"gyroemu/imu0{topic}" for topic in topics}
    mounting = Mounting("imu_x", q_bs, np.array([0.01, -0.02, 0.03]))
    specs = channel_specs(topics)
    view = FoxgloveView(ViewOptions(port=0, rate_hz=display), specs, {k: t for t, k in keys.items()}, mounting=mounting)
    client = FoxgloveClient(view.port)
    try:
        client.wait_for_topics(topics + ["/tf", "/tf_static", "/scene", "/view/errors"])
        client.subscribe_all()
        client.pump(0.2)  # the server registers the subscriptions
        step = round(1e9 / rate)
        batches = [
            [(k * step, keys[topic], payloads[topic][k]) for k in range(start, start + 16) for topic in topics]
            for start in range(0, n, 16)
        ]

        def publish():  # a paced publisher: each batch taken at its first deadline
            t0 = time.monotonic_ns()
            for batch in view.tap(batches):
                while time.monotonic_ns() < t0 + batch[0][0]:
                    time.sleep(0.001)

        feeder = threading.Thread(target=publish)
        feeder.start()
        client.pump(n / rate + 0.5)
        feeder.join()
        client.pump(0.3)  # the worker's last frames
        view.close()
    finally:
        client.close()
        if view._thread.is_alive():
            view.close()
    assert view.dropped == 0
    # every forwarded message, in order, stamped with its header stamp, bytes unchanged
    for topic in topics:
        got = client.received[topic]
        assert [d for _, d in got] == payloads[topic], topic
        assert [t for t, _ in got] == stamp_ns.tolist(), topic
    truth = {m.header.stamp.sec * 10**9 + m.header.stamp.nanosec: m for _, m in client.decoded("/truth/imu")}
    assert len(truth) == n
    # /tf_static: the mounting (base_link -> the IMU's frame) with the first frame, the doubles unchanged
    static = client.decoded("/tf_static")
    assert static and all(len(m.transforms) == 1 for _, m in static)
    mount = static[0][1].transforms[0]
    assert (mount.parent_frame_id, mount.child_frame_id) == ("base_link", "imu_x")
    r, p = mount.rotation, mount.translation
    assert [r.w, r.x, r.y, r.z] == q_bs.tolist() and [p.x, p.y, p.z] == mounting.lever_arm_m.tolist()
    tf = client.decoded("/tf")
    # a frame a tick of 1/display s of wall time, when a truth or an estimate came in
    span = (stamp_ns[-1] - stamp_ns[0]) * 1e-9
    assert 0.5 * span * display <= len(tf) <= span * display + 2  # ticks can be late on a loaded machine
    by_index = {int(s): i for i, s in enumerate(stamp_ns)}
    base = []
    for k, (log_time, msg) in enumerate(tf):
        frames = {x.child_frame_id: x for x in msg.transforms}
        assert set(frames) <= {"base_link", "body_estimate"} and "base_link" in frames
        if k:  # the estimate of a sample comes after its truth: maybe none yet at the first frame
            assert set(frames) == {"base_link", "body_estimate"}
        for name, qs in (("base_link", q), ("body_estimate", q_est)):
            if name not in frames:
                continue
            x = frames[name]
            assert x.parent_frame_id == "map"
            stamp = _tf_stamp(x)
            i = by_index[stamp]  # a stamp of the stream
            r = x.rotation
            # the same doubles as the Imu message of that stamp (copied, not computed)
            np.testing.assert_array_equal([r.w, r.x, r.y, r.z], qs[i])
            if name == "base_link":
                o = truth[stamp].orientation
                assert (o.x, o.y, o.z, o.w) == (r.x, r.y, r.z, r.w)
                assert log_time == stamp
                base.append(i)
    assert np.all(np.diff(base) >= 0)  # 0: drawn again as only the estimate moved on
    # the scene: boxes with axes in base_link and body_estimate and the truth's vectors in map when they
    # first can be drawn; every frame the estimate's vectors on the body, R^_bw g_w and R^_bw m_w
    m_hat = m_w / np.linalg.norm(m_w)
    g = np.array([0, 0, -1.0])

    def direction(arrow):
        o = arrow.pose.orientation
        return _rotate([o.w, o.x, o.y, o.z], np.array([1.0, 0, 0]))

    entities = {}
    scenes = client.decoded("/scene")
    assert len(scenes) == len(tf)
    for (_, scene), (_, msg) in zip(scenes, tf):
        now = {e.id: e for e in scene.entities}
        entities.update(now)
        if "estimate_vectors" not in now:
            continue
        e = now["estimate_vectors"]
        assert e.frame_id == "base_link" and e.frame_locked
        j = by_index[next(_tf_stamp(x) for x in msg.transforms if x.child_frame_id == "body_estimate")]
        r_bw = q_est[j] * [1, -1, -1, -1]  # R_bw v = R(q*) v
        # round-off of a few products of unit-size numbers; m_w is the normalised mean of R_wb m_b
        np.testing.assert_allclose(direction(e.arrows[0]), _rotate(r_bw, g), atol=64 * EPS)
        np.testing.assert_allclose(direction(e.arrows[1]), _rotate(r_bw, m_hat), atol=64 * EPS)
    assert entities["body"].frame_id == "base_link" and entities["estimate"].frame_id == "body_estimate"
    assert entities["body"].frame_locked and len(entities["body"].cubes) == len(entities["estimate"].cubes) == 1
    assert entities["estimate"].cubes[0].color.a < 1.0  # translucent
    assert len(entities["body"].arrows) == len(entities["estimate"].arrows) == 3  # axes
    fixed = entities["truth_vectors"]
    assert fixed.frame_id == "map"
    np.testing.assert_allclose(direction(fixed.arrows[0]), g, atol=64 * EPS)
    np.testing.assert_allclose(direction(fixed.arrows[1]), m_hat, atol=64 * EPS)

    # /view/errors, every 4th frame: the gyro's error against the truth over the samples since the last
    # (the true bias plus their mean noise), the filter's bias, the attitude error (0.1 rad about body x)
    errors = client.decoded("/view/errors")
    assert len(errors) == len(tf) // 4
    scale = np.max(np.abs(gyro))
    previous = -1
    for _, e in errors:
        end = by_index[e["timestamp"]["sec"] * 10**9 + e["timestamp"]["nsec"]]
        window = slice(previous + 1, end + 1)
        previous = end
        want = np.mean(gyro[window] - omega[window], axis=0)
        np.testing.assert_allclose(e["gyro_error_rad_s"], want, rtol=0, atol=16 * EPS * scale)
        np.testing.assert_allclose(e["bias_estimate_rad_s"], BIAS_HAT, rtol=0, atol=4 * EPS * scale)
        assert abs(e["attitude_error_rad"] - 0.1) <= 64 * EPS
        np.testing.assert_allclose(e["attitude_error_xyz_rad"], [0.1, 0, 0], rtol=0, atol=64 * EPS)


def test_bad_port_and_rate_are_refused_before_any_work():
    with pytest.raises(ValueError, match="--foxglove-port"):
        check_view_options(ViewOptions(port=70000))
    with pytest.raises(ValueError, match="--foxglove-rate"):
        check_view_options(ViewOptions(rate_hz=0.0))
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        with pytest.raises(ValueError, match="--foxglove-port.*cannot listen"):
            check_view_options(ViewOptions(port=s.getsockname()[1]))


@pytest.mark.parametrize("port", [8765, 0])
@pytest.mark.parametrize("host", ["bad!!", "bad:host!!", "192.0.2.1"])  # 192.0.2.1: TEST-NET-1, no interface's
def test_a_bad_host_is_named_not_the_port(host, port):
    """``gyroemu view --host 'bad!!'`` blamed --port; with --port 0 the host went unchecked."""
    from cli_runs import run_cli

    with pytest.raises(ValueError, match=r"argument --host: cannot listen on .*name an address of this machine"):
        check_view_options(ViewOptions(port=port, host=host), "--port", "--rate")
    code, _, err = run_cli(["view", "/nonexistent/run.mcap", "--host", host, "--port", str(port)])
    assert code == 2 and "argument --host" in err and "--port" not in err, err


# -- processes: `gyroemu stream --foxglove`, `gyroemu view` ------------------------------------------------


def _stamp(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def _tf_stamp(transform) -> int:
    return transform.timestamp.seconds * 10**9 + transform.timestamp.nanos


def _check_transforms(client, child: str, topic: str) -> int:
    """Every /tf transform to ``child`` holds the attitude of ``topic``'s message of the same stamp, to
    the bit. Returns how many were checked."""
    by_stamp = {_stamp(m.header): m.orientation for _, m in client.decoded(topic)}
    checked = 0
    for _, msg in client.decoded("/tf"):
        for x in msg.transforms:
            if x.child_frame_id != child:
                continue
            assert x.parent_frame_id == "map"
            stamp = _tf_stamp(x)
            if stamp not in by_stamp:  # sent before the client subscribed to `topic`
                continue
            o = by_stamp[stamp]
            assert (x.rotation.x, x.rotation.y, x.rotation.z, x.rotation.w) == (o.x, o.y, o.z, o.w)
            checked += 1
    return checked


@pytest.mark.slow
def test_stream_foxglove_process(procs):
    """``gyroemu stream --foxglove --estimate``: a client connected while the stream waits for zenoh
    subscribers gets every sample's /imu and /truth/imu, the live estimate, and /tf at 30 Hz of stream
    time holding the truth's and the estimate's attitudes at their stamps."""
    from live_processes import free_port

    from gyroemu.pipelines.transport.zenoh_io import open_session, session_config, subscribe

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    port = free_port()
    procs.start(
        "stream",
        *("stream", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "3"),
        *("--wait", "30", "--connect", endpoint, "--mode", "peer", "--estimate"),
        *("--foxglove", "--foxglove-port", str(port)),
    )
    try:
        procs.wait_for("stream", f"Foxglove view on ws://localhost:{port}")
        client = FoxgloveClient(port)
        topics = ["/imu", "/truth/imu", "/estimate/imu", "/tf", "/tf_static", "/scene", "/view/errors"]
        client.wait_for_topics(topics)
        client.subscribe_all()
        client.pump(0.3)
        sub = subscribe(session, "gyroemu/**")  # every key has a subscriber now: the stream starts
        client.pump(15.0)  # until the stream ends and its server closes the connection
        assert procs.wait("stream", 30) == 0
        sub.undeclare()
    finally:
        session.close()
    assert "dropped" not in procs.log("stream")
    # another peer on the machine subscribed to gyroemu/** may start the stream before this client
    # subscribes: what it gets is then the end of the run, but without a gap
    truth = [_stamp(m.header) for _, m in client.decoded("/truth/imu")]
    assert len(truth) >= 2000 and set(np.diff(truth).tolist()) == {1_000_000}  # 1 kHz, none lost
    assert abs(len(client.received["/imu"]) - len(truth)) <= 1
    # /mag is read for the field's arrow, not served (nor /raw/mems): each message served costs CPU
    assert {c["topic"] for c in client.channels.values()} == set(topics)
    assert len(client.received["/estimate/imu"]) >= len(truth) - 100  # the filter's last block may be cut
    # /tf: the truth at the display rate (default 30 Hz), a frame a tick of wall time (the stream's clock)
    base = [_tf_stamp(x) for _, m in client.decoded("/tf") for x in m.transforms if x.child_frame_id == "base_link"]
    # (a frame is drawn again when only the estimate moved on: the same truth stamp, a gap of 0)
    gaps = np.diff(base) * 1e-9
    assert np.all(gaps >= 0) and 0.8 / 30 < np.mean(gaps[gaps > 0]) < 1.5 / 30  # late ticks on a loaded machine
    span = (truth[-1] - truth[0]) * 1e-9
    assert _check_transforms(client, "base_link", "/truth/imu") == len(base) >= 0.6 * span * 30
    assert _check_transforms(client, "body_estimate", "/estimate/imu") >= 0.5 * span * 30


def _playback_request(command: int, speed: float, seek_ns: int | None, request_id: str) -> bytes:
    """Client binary opcode 3, PlaybackControlRequest: command (0 play, 1 pause), f32 speed, had_seek,
    u64 seek time, u32 length + request id."""
    rid = request_id.encode()
    return struct.pack("<BBfBQI", 3, command, speed, seek_ns is not None, seek_ns or 0, len(rid)) + rid


def _playback_states(client) -> list[tuple[int, int, float, bool, str]]:
    """Server binary opcode 5, PlaybackState: (status, current time, speed, did_seek, request id)."""
    out = []
    for frame in client.binary_other:
        if frame[0] == 5:
            status, now, speed, seek, n = struct.unpack_from("<BQfBI", frame, 1)
            out.append((status, now, speed, bool(seek), bytes(frame[19 : 19 + n]).decode()))
    return out


@pytest.mark.slow
def test_view_log_process(procs, tmp_path):
    """``gyroemu view LOG``: playback control advertised with the log's time range; a seek and play from
    a plain client answered with the state, the messages from the time sought on, /tf equal to the
    truth at the same stamps, Ended at the end; SIGTERM ends it with 143, SIGINT with 130."""
    from live_processes import free_port, mcap_messages

    from gyroemu.pipelines.cli import main

    log = tmp_path / "run.mcap"
    args = ["simulate", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "2"]
    assert main([*args, "--rate", "200", "--out", str(log)]) == 0
    stamps = [t for _, t, _ in mcap_messages(log, "/truth/imu")]
    port, port2 = free_port(), free_port()
    procs.start("view", "view", str(log), "--port", str(port), "--paused")
    procs.start("view2", "view", str(log), "--port", str(port2))
    procs.wait_for("view", f"ws://localhost:{port}")
    client = FoxgloveClient(port)
    client.wait_for_topics(["/imu", "/truth/imu", "/tf", "/scene"])
    info = client.server_info
    assert {"playbackControl", "time"} <= set(info["capabilities"])
    client.subscribe_all()
    client.pump(0.3)
    assert not client.received  # paused
    seek = stamps[len(stamps) // 2]
    client.ws.send(_playback_request(0, 2.0, seek, "req-1"))
    client.pump(1.5)  # 1 s of log at speed 2: the end
    states = _playback_states(client)
    assert states[0][0] == 0 and states[0][1] == seek and states[0][3] and states[0][4] == "req-1"
    assert states[-1][0] == 3  # Ended
    truth = [_stamp(m.header) for _, m in client.decoded("/truth/imu")]
    assert truth == [t for t in stamps if t >= seek]
    assert _check_transforms(client, "base_link", "/truth/imu") >= 10  # 1 s of log at x2: 15 frames at 30/s
    assert procs.stop("view", signal.SIGTERM) == 143
    procs.wait_for("view2", f"ws://localhost:{port2}")
    assert procs.stop("view2", signal.SIGINT) == 130
    for name in ("view", "view2"):
        assert "Traceback" not in procs.log(name)


def test_layout_ships_and_names_what_the_view_serves():
    """configs/foxglove/gyroemu.json is package data, and every plotted path names a channel the view
    serves and a field of it: the Imu messages' angular_velocity, the errors' schema properties."""
    from importlib.resources import files

    from gyroemu.pipelines.transport.foxglove_view import ERRORS_SCHEMA, ERRORS_TOPIC

    layout = json.loads(files("gyroemu.configs.foxglove").joinpath("gyroemu.json").read_text())
    panels = layout["configById"]
    assert panels["3D!gyroemu"]["topics"]["/scene"]["visible"] and panels["3D!gyroemu"]["followTf"] == "map"
    fields = {
        "/imu": {"angular_velocity"},
        "/truth/imu": {"angular_velocity"},
        ERRORS_TOPIC: set(ERRORS_SCHEMA["properties"]),
    }
    paths = [p["value"] for c in panels.values() for p in c.get("paths", [])]
    assert len(paths) == 6 + 4 + 6
    for path in paths:
        topic, field = path.split(".", 1)
        assert field.split(".")[0].split("[")[0] in fields[topic], path

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


def test_cli_refuses_a_port_in_use_with_status_2(capsys):
    """``gyroemu view --port`` and ``gyroemu stream --foxglove-port`` of a port in use: status 2 and a
    message naming the argument, before any work (the log is not even opened, nothing is simulated)."""
    import socket

    from gyroemu.pipelines.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        busy = str(s.getsockname()[1])
        # a ViewOptionError (a ConfigError): main returns 2
        assert main(["view", "/nonexistent/run.mcap", "--port", busy]) == 2
        assert "argument --port" in capsys.readouterr().err
        stream = ["stream", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "1"]
        assert main([*stream, "--foxglove", "--foxglove-port", busy]) == 2
        assert "argument --foxglove-port" in capsys.readouterr().err
        with pytest.raises(SystemExit) as e:
            main([*stream, "--foxglove-rate", "30"])
        assert e.value.code == 2 and "only with --foxglove" in capsys.readouterr().err


@pytest.mark.slow
def test_replay_foxglove_process(procs, tmp_path):
    """``gyroemu replay LOG --foxglove``: every cdr channel of the log served with its recorded bytes and
    schema (a log's own /tf replaced by the view's), /tf equal to the truth at the same stamps."""
    from live_processes import free_port, mcap_messages

    from gyroemu.pipelines.cli import main
    from gyroemu.pipelines.formats.mcap_log import read_tf
    from gyroemu.pipelines.transport.zenoh_io import open_session, session_config, subscribe

    log = tmp_path / "run.mcap"
    args = ["simulate", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "2"]
    assert main([*args, "--out", str(log)]) == 0
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    port = free_port()
    view = ["--foxglove", "--foxglove-port", str(port)]
    procs.start("replay", "replay", str(log), "--wait", "30", "--connect", endpoint, "--mode", "peer", *view)
    try:
        procs.wait_for("replay", f"Foxglove view on ws://localhost:{port}")
        client = FoxgloveClient(port)
        client.wait_for_topics(["/imu", "/truth/imu", "/tf", "/scene"])
        client.subscribe_all()
        client.pump(0.3)
        sub = subscribe(session, "gyroemu/**")
        client.pump(8.0)
        assert procs.wait("replay", 30) == 0
        sub.undeclare()
    finally:
        session.close()
    topics = [c["topic"] for c in client.channels.values()]
    assert sorted(topics) == sorted(set(topics)) and topics.count("/tf") == 1 and topics.count("/tf_static") == 1
    (x,) = client.decoded("/tf_static")[0][1].transforms  # the log's own mounting, in the view's /tf_static
    ((want_frame, want_q),) = [(m.child_frame_id[0], m.q[0]) for m in [read_tf(log, static=True)]]
    assert (x.parent_frame_id, x.child_frame_id) == ("base_link", want_frame)
    assert [x.rotation.w, x.rotation.x, x.rotation.y, x.rotation.z] == want_q.tolist()
    for topic in ("/imu", "/truth/imu"):
        assert [d for _, d in client.received[topic]] == [d for _, _, d in mcap_messages(log, topic)]
    assert _check_transforms(client, "base_link", "/truth/imu") >= 0.8 * 2 * 30


# -- faults found by a hunt: a stalled client, a mounted IMU, schemaless channels, unstamped types, --------
# -- a port in TIME_WAIT, a foreign bag's tree --------------------------------------------------------------


def _stalled_client(port: int, timeout: float = 10.0):
    """A Foxglove client that completes the WebSocket handshake (subprotocol ``foxglove.sdk.v1``),
    subscribes to every advertised channel and then never reads again, with a receive buffer of a few
    kB (a frozen app): the standard library's socket, no WebSocket package. Returns the socket."""
    import os
    import socket

    end = time.monotonic() + timeout
    while True:
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # before connect: the window stays small
        try:
            s.connect(("127.0.0.1", port))
            break
        except OSError:
            s.close()
            assert time.monotonic() < end, f"nothing listens on {port}"
            time.sleep(0.05)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        ).encode()
    )
    s.settimeout(timeout)
    data = b""
    while b"\r\n\r\n" not in data:
        data += s.recv(4096)
    head, data = data.split(b"\r\n\r\n", 1)
    assert head.startswith(b"HTTP/1.1 101") and b"foxglove.sdk.v1" in head.lower(), head
    channels: list[int] = []

    def frame() -> bytes:  # one unmasked server frame, text or binary
        nonlocal data
        while len(data) < 2 or len(data) < 2 + {126: 2, 127: 8}.get(data[1] & 0x7F, 0):
            data += s.recv(65536)
        n, at = data[1] & 0x7F, 2
        if n >= 126:
            width = 2 if n == 126 else 8
            n, at = int.from_bytes(data[2 : 2 + width], "big"), 2 + width
        while len(data) < at + n:
            data += s.recv(65536)
        payload, data = data[at : at + n], data[at + n :]
        return payload

    while not channels:  # serverInfo, then the advertise
        payload = frame()
        if payload[:1] == b"{" and json.loads(payload).get("op") == "advertise":
            channels = [c["id"] for c in json.loads(payload)["channels"]]
    subscriptions = [{"id": i + 1, "channelId": c} for i, c in enumerate(channels)]
    _send_frame(s, json.dumps({"op": "subscribe", "subscriptions": subscriptions}).encode(), text=True)
    return s


def _send_frame(s, body: bytes, text: bool = False) -> None:
    """One masked client frame (text or binary) on a raw socket."""
    import os

    mask = os.urandom(4)
    size = bytes([0x80 | len(body)]) if len(body) < 126 else bytes([0x80 | 126]) + struct.pack(">H", len(body))
    s.sendall(bytes([0x81 if text else 0x82]) + size + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(body)))


@pytest.mark.slow
def test_a_client_that_stops_reading_does_not_hold_the_exit(procs, tmp_path):
    """A client subscribed to everything that never reads again: ``gyroemu view`` still ends on SIGINT
    with 130, and ``gyroemu replay --foxglove --loop`` with 0, within STOP_TIMEOUT_S (plus the
    interpreter's exit) of the signal. The SDK's ``server.stop()`` waited for the client without a
    limit, the main thread in native code, where Ctrl-C is not seen. (Enough is sent for the server's
    socket buffer, up to 4 MiB on Linux, to fill: the view's log played again and again, the replay
    looped.)"""
    from live_processes import free_port

    from gyroemu.pipelines.cli import main
    from gyroemu.pipelines.transport.foxglove_view import STOP_TIMEOUT_S
    from gyroemu.pipelines.transport.zenoh_io import open_session, session_config, subscribe

    log = tmp_path / "run.mcap"
    args = ["simulate", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "2"]
    assert main([*args, "--out", str(log)]) == 0
    bound = STOP_TIMEOUT_S + 3.0  # the stop's wait, then the interpreter's exit on a loaded machine
    port = free_port()
    procs.start("view", "view", str(log), "--port", str(port), "--paused")
    procs.wait_for("view", f"ws://localhost:{port}")
    stalled = _stalled_client(port)
    try:
        for i in range(10):  # the log (3 MB, 2 s) from its start at x100, ten times
            _send_frame(stalled, _playback_request(0, 100.0, 0, f"again-{i}"))
            time.sleep(0.1)
        t0 = time.monotonic()
        assert procs.stop("view", signal.SIGINT, timeout=bound + 5) == 130
        assert time.monotonic() - t0 < bound, time.monotonic() - t0
    finally:
        stalled.close()
    assert "Traceback" not in procs.log("view")
    assert "did not stop within" in procs.log("view")  # the client did hold the server's stop

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    port = free_port()
    view = ["--foxglove", "--foxglove-port", str(port)]
    replay = ("replay", str(log), "--wait", "30", "--connect", endpoint, "--mode", "peer", "--rate", "10", "--loop")
    procs.start("replay", *replay, *view)
    try:
        procs.wait_for("replay", f"Foxglove view on ws://localhost:{port}")
        stalled = _stalled_client(port)
        sub = subscribe(session, "gyroemu/**")  # every key has a subscriber: the replay starts
        procs.wait_for("replay", "replay: publishing")
        time.sleep(1.0)  # five passes of the log
        t0 = time.monotonic()
        # the view's close drains its queue (<= 2 s) before the server's stop (<= STOP_TIMEOUT_S)
        assert procs.stop("replay", signal.SIGINT, timeout=bound + 2.0 + 5) == 0
        assert time.monotonic() - t0 < bound + 2.0, time.monotonic() - t0
        sub.undeclare()
        stalled.close()
    finally:
        session.close()
    assert "Traceback" not in procs.log("replay")
    assert "did not stop within" in procs.log("replay")


def _serve_in_process(specs, mounting, payloads, n, frame_every, sink):
    """Feed a ViewPublisher (a context recorded by an MCAP sink, no server) a run's messages in stamp
    order, a frame every ``frame_every`` samples; returns the publisher."""
    import foxglove

    from gyroemu.pipelines.transport.foxglove_view import ViewPublisher

    context = foxglove.Context()
    writer = foxglove.open_mcap(sink, context=context)
    publisher = ViewPublisher(context, specs, mounting)
    for k in range(n):
        for topic, rows in payloads.items():
            publisher.message(topic, rows[k])
        if k % frame_every == frame_every - 1:
            publisher.frame()
    writer.close()
    return publisher


def _sink_errors(sink) -> list[dict]:
    from mcap.reader import make_reader

    with open(sink, "rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/view/errors"])]


def test_a_mounted_imu_gives_the_errors_and_field_of_an_unmounted_one(tmp_path):
    """A device mounted 90° about z (``q_bs``): its ``/imu`` rates and ``/mag`` field are in the IMU's
    axes, ``/truth/imu`` and ``/estimate/imu`` (``gyroemu estimate`` writes a mounted device's estimate
    as the body's) in the body's. The view turns the measurements into body axes, so the same motion
    gives the same ``/view/errors`` (gyro error, bias estimate) and the same field arrow in ``map`` as
    an unmounted device, to the round-off of one rotation (a few ulp of the rates); the view had
    subtracted body rates from sensor rates (|error| ~ the 0.8 rad/s turn) and put the field 90° off."""
    n, rate = 200, 400.0
    payloads, stamp_ns, q, q_est, m_w, gyro, omega = synthetic_run(n, rate)
    q_bs = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])  # 90° about z
    mounted = in_sensor_axes(payloads, stamp_ns, q, m_w, gyro, q_bs)  # what the IMU measures, in its axes
    specs = channel_specs(list(payloads))
    plain = Mounting("imu0", np.array([1.0, 0, 0, 0]), np.zeros(3))
    turned = Mounting("imu0", q_bs, np.zeros(3))
    views = {}
    for name, mounting, rows in (("unmounted", plain, payloads), ("mounted", turned, mounted)):
        sink = tmp_path / f"{name}.mcap"
        publisher = _serve_in_process(specs, mounting, rows, n, 5, sink)
        views[name] = (publisher.field_w, _sink_errors(sink))
    (field_u, errors_u), (field_m, errors_m) = views["unmounted"], views["mounted"]
    assert len(errors_u) == len(errors_m) == n // 5 // 4
    scale = np.max(np.abs(gyro))
    previous = -1
    for eu, em in zip(errors_u, errors_m):
        end = int(np.searchsorted(stamp_ns, eu["timestamp"]["sec"] * 10**9 + eu["timestamp"]["nsec"]))
        want = np.mean(gyro[previous + 1 : end + 1] - omega[previous + 1 : end + 1], axis=0)
        previous = end
        for e in (eu, em):
            np.testing.assert_allclose(e["gyro_error_rad_s"], want, rtol=0, atol=16 * EPS * scale)
            np.testing.assert_allclose(e["bias_estimate_rad_s"], BIAS_HAT, rtol=0, atol=16 * EPS * scale)
        np.testing.assert_allclose(em["gyro_error_rad_s"], eu["gyro_error_rad_s"], rtol=0, atol=16 * EPS * scale)
    m_hat = m_w / np.linalg.norm(m_w)
    np.testing.assert_allclose(field_u, m_hat, atol=64 * EPS)
    np.testing.assert_allclose(field_m, m_hat, atol=64 * EPS)


def _log_with_a_schemaless_channel(tmp_path):
    """A bag (:func:`_rosbags_bag`) plus a cdr channel without a schema, a message with every ``/imu``
    one (as ``gyroemu record`` stores a topic it could not type)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    src, dst = _rosbags_bag(tmp_path / "bag"), tmp_path / "schemaless.mcap"
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader, writer = make_reader(f), Writer(g)
        writer.start(profile="ros2", library="test")
        summary = reader.get_summary()
        schemas = {i: writer.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
        channels = {
            i: writer.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0), c.metadata)
            for i, c in summary.channels.items()
        }
        extra = writer.register_channel("/other/thing", "cdr", 0, {})
        for _, channel, m in reader.iter_messages(log_time_order=True):
            writer.add_message(channels[channel.id], m.log_time, m.data, m.publish_time, m.sequence)
            if channel.topic == "/imu":
                writer.add_message(extra, m.log_time, b"\x00\x01\x00\x00" + bytes(8), m.log_time)
        writer.finish()
    return dst


class _ViewThread:
    """``run_view`` on a thread of the test process (port 0): its output, its port, a stop."""

    def __init__(self, path, **options):
        import io
        import queue

        from gyroemu.pipelines.jobs.view import ViewLogOptions, run_view

        self.out, self._stop, ports = io.StringIO(), threading.Event(), queue.Queue()
        opts = ViewLogOptions(path=path, view=ViewOptions(port=0), **options)
        self.result: list = []

        def run():
            try:
                self.result.append(run_view(opts, out=self.out, stop=self._stop.is_set, on_ready=ports.put))
            except BaseException as e:  # noqa: BLE001 - handed to the test
                self.result.append(e)
                ports.put(None)

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()
        self.port = ports.get(timeout=30)
        assert self.port is not None, self.result

    def stop(self) -> int:
        self._stop.set()
        self.thread.join(10)
        assert not self.thread.is_alive()
        return self.result[0]


def test_a_channel_without_a_schema_is_skipped_not_a_crash(tmp_path, caplog):
    """A cdr channel without a schema (``record`` writes one for a topic it could not type): ``view``
    and the live view of ``replay --foxglove`` skip it with a warning naming it and serve the rest;
    the SDK had raised ``TypeError: Invalid schema type: NoneType`` before anything was served."""
    import foxglove

    from gyroemu.pipelines.formats.mcap_records import mcap_channel_info
    from gyroemu.pipelines.transport.foxglove_view import ViewPublisher, log_channel_specs

    path = _log_with_a_schemaless_channel(tmp_path)
    view = _ViewThread(path, playing=False)
    try:
        client = FoxgloveClient(view.port)
        client.wait_for_topics(["/imu", "/status", "/tf", "/tf_static", "/scene"])
        client.pump(0.2)
        topics = sorted(c["topic"] for c in client.channels.values())
        client.close()
    finally:
        assert view.stop() == 0
    assert topics == ["/imu", "/scene", "/status", "/tf", "/tf_static", "/view/errors"]
    assert "skipping topic /other/thing: no schema" in view.out.getvalue()
    # the replay's view (FoxgloveView's publisher) of the same channels
    channels = mcap_channel_info(path)
    specs = log_channel_specs(channels, [c.topic for c in channels], ["/imu"])
    with caplog.at_level("WARNING"):
        publisher = ViewPublisher(foxglove.Context(), specs)
    assert publisher.skipped == {"/other/thing": "no schema"} and "/imu" in publisher.topics
    assert any("skipping topic /other/thing" in r.getMessage() for r in caplog.records)


def _rosbags_bag(folder):
    """A foreign bag written by rosbags (MCAP storage), 2 s at 100 Hz from 2024-06-01: ``/imu`` stamped
    3 ms before its log time, ``/status`` (``std_msgs/msg/String``: no header) every 50th sample,
    ``/tf`` (``odom`` -> ``base_footprint``) every 10th, ``/tf_static`` (``base_footprint`` ->
    ``imu_link``) once. Returns the MCAP file."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    Header, Time = t["std_msgs/msg/Header"], t["builtin_interfaces/msg/Time"]
    Q, V = t["geometry_msgs/msg/Quaternion"], t["geometry_msgs/msg/Vector3"]
    TS, Tr, TF = t["geometry_msgs/msg/TransformStamped"], t["geometry_msgs/msg/Transform"], t["tf2_msgs/msg/TFMessage"]
    Imu, String = t["sensor_msgs/msg/Imu"], t["std_msgs/msg/String"]
    t0 = 1_717_200_000 * 10**9

    def header(ns, frame):
        return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    def tf(ns, parent, child, x):
        return TF(
            transforms=[
                TS(
                    header=header(ns, parent),
                    child_frame_id=child,
                    transform=Tr(translation=V(x=x, y=0.0, z=0.0), rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                )
            ]
        )

    cov = np.zeros(9)
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        ci = w.add_connection("/imu", Imu.__msgtype__, typestore=ts)
        cs = w.add_connection("/status", String.__msgtype__, typestore=ts)
        ct = w.add_connection("/tf", TF.__msgtype__, typestore=ts)
        cst = w.add_connection("/tf_static", TF.__msgtype__, typestore=ts)
        for k in range(200):
            lt = t0 + k * 10_000_000
            a = 0.003 * k
            imu = Imu(
                header=header(lt - 3_000_000, "imu_link"),
                orientation=Q(x=0.0, y=0.0, z=np.sin(a / 2), w=np.cos(a / 2)),
                orientation_covariance=cov,
                angular_velocity=V(x=0.0, y=0.0, z=0.3),
                angular_velocity_covariance=cov,
                linear_acceleration=V(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=cov,
            )
            w.write(ci, lt, ts.serialize_cdr(imu, Imu.__msgtype__))
            if k == 0:
                w.write(cst, lt, ts.serialize_cdr(tf(lt, "base_footprint", "imu_link", 0.1), TF.__msgtype__))
            if k % 50 == 0:
                w.write(cs, lt + 1, ts.serialize_cdr(String(data=f"status {k}"), String.__msgtype__))
            if k % 10 == 0:
                w.write(
                    ct, lt + 2, ts.serialize_cdr(tf(lt - 3_000_000, "odom", "base_footprint", 0.01 * k), TF.__msgtype__)
                )
    (path,) = folder.glob("*.mcap")
    return path


def test_a_foreign_bag_keeps_its_log_times_and_its_tree(tmp_path):
    """``gyroemu view`` of a rosbags-written bag: a type without a header (``std_msgs/msg/String``) goes
    out at its record's log time (it went out at the wall clock, years from the bag's range), a stamped
    one at its header stamp; the bag's own ``/tf`` and ``/tf_static``, which the view has nothing to
    replace with (no ``/truth/imu``, no ``/estimate/imu``), are served as recorded (they were dropped)."""
    from live_processes import mcap_messages

    path = _rosbags_bag(tmp_path / "bag")
    view = _ViewThread(path, playing=False)
    try:
        client = FoxgloveClient(view.port)
        client.wait_for_topics(["/imu", "/status", "/tf", "/tf_static"])
        client.subscribe_all()
        client.pump(0.3)
        client.ws.send(_playback_request(0, 8.0, None, "play"))  # 2 s of log at x8
        end = time.monotonic() + 10
        while not any(s[0] == 3 for s in _playback_states(client)) and time.monotonic() < end:  # Ended
            client.pump(0.1)
        client.close()
    finally:
        assert view.stop() == 0
    advertised = [c for c in client.channels.values() if c["topic"] in ("/tf", "/tf_static")]
    assert len(advertised) == 2 and all(c["schemaName"] == "tf2_msgs/msg/TFMessage" for c in advertised)
    for topic in ("/status", "/tf", "/tf_static"):
        want = [(t, d) for _, t, d in mcap_messages(path, topic)]
        assert client.received[topic] == want, topic
    imu = client.received["/imu"]
    assert [d for _, d in imu] == [d for _, _, d in mcap_messages(path, "/imu")]
    assert [t for t, _ in imu] == [t - 3_000_000 for _, t, _ in mcap_messages(path, "/imu")]  # header stamps


def test_replaced_topics_keep_a_foreign_tree():
    """The view's /tf and /tf_static replace a log's where it draws them (a truth or an estimate), not
    otherwise; /scene and /view/errors always."""
    from gyroemu.pipelines.transport.foxglove_view import replaced_topics

    assert replaced_topics(["/imu", "/truth/imu", "/tf", "/tf_static"]) >= {"/tf", "/tf_static", "/scene"}
    assert replaced_topics(["/dev1/imu", "/dev1/estimate/imu", "/tf"]) >= {"/tf", "/tf_static"}
    assert replaced_topics(["/imu", "/status", "/tf", "/tf_static"]) == {"/scene", "/view/errors"}


@pytest.mark.skipif(sys.platform == "win32", reason="SO_REUSEADDR means something else on Windows")
def test_a_port_in_time_wait_is_free_one_listened_on_is_not():
    """A port whose last connection lingers in TIME_WAIT (a client closed, up to 60 s) is free for the
    view, as it is for the SDK's listener; one a socket listens on (127.0.0.1, 0.0.0.0 or ::) is not."""
    import socket

    with socket.socket() as listener:  # a server as the SDK's (tokio's) listener binds it: SO_REUSEADDR
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # (Linux: TIME_WAIT then yields to
        listener.bind(("127.0.0.1", 0))  # a bind only where both sockets set it)
        listener.listen()
        port = listener.getsockname()[1]
        client = socket.create_connection(("127.0.0.1", port))
        accepted, _ = listener.accept()
        accepted.close()  # the server's side closes first: its end of the connection goes to TIME_WAIT
        client.recv(1)
        client.close()
    time.sleep(0.05)
    check_view_options(ViewOptions(port=port))  # was: "cannot listen on 127.0.0.1:port: Address already in use"
    for host, family in (("127.0.0.1", socket.AF_INET), ("0.0.0.0", socket.AF_INET), ("::", socket.AF_INET6)):
        for reuse in (0, 1):
            with socket.socket(family) as held:
                held.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, reuse)
                held.bind((host, 0))
                held.listen()
                with pytest.raises(ValueError, match="--foxglove-port.*cannot listen"):
                    check_view_options(ViewOptions(port=held.getsockname()[1]))


def test_a_live_view_serves_a_type_without_a_header_at_its_schedule():
    """The live view (``stream``, ``replay --foxglove``): a message of a type without a header goes out
    at its schedule's time, the wall clock of its deadline (the view's start plus its offset), not
    whenever the view's worker got to it."""
    from gyroemu.pipelines.transport.foxglove_view import ChannelSpec

    spec = ChannelSpec("/status", "std_msgs/msg/String", "ros2msg", b"string data\n", stamped=False)
    view = FoxgloveView(ViewOptions(port=0, rate_hz=20.0), [spec], {"k/status": "/status"})
    client = FoxgloveClient(view.port)
    try:
        client.wait_for_topics(["/status"])
        client.subscribe_all()
        client.pump(0.2)
        offsets = [0, 30_000_000, 170_000_000]
        text = b"\x00\x01\x00\x00\x03\x00\x00\x00ok\x00"
        before = time.time_ns()
        view.offer([(t, "k/status", text) for t in offsets])  # due over 0.17 s, forwarded a tick at a time
        after = time.time_ns()
        client.pump(0.6)
        view.close()
    finally:
        client.close()
    got = [t for t, _ in client.received["/status"]]
    assert [t - got[0] for t in got] == offsets  # to the ns: the schedule's, not the worker's ticks
    assert before <= got[0] <= after
