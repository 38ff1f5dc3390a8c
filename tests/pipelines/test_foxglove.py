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


def test_live_view_as_a_client_sees_it():
    """Batches tapped from a paced publisher reach a plain WebSocket client: every forwarded message with
    its header stamp, /tf at the display rate equal to the truth and the estimate at the same stamps,
    and a scene whose gravity and field arrows are R_bw g_w and R_bw m_w (round-off)."""
    n, rate, display = 240, 400.0, 40.0  # 0.6 s of samples, frames every 25 ms
    payloads, stamp_ns, q, q_est, m_w, gyro, omega = synthetic_run(n, rate)
    topics = list(payloads)
    keys = {topic: f"gyroemu/imu0{topic}" for topic in topics}
    q_bs = np.array([0.5, 0.5, -0.5, 0.5])  # a 120° turn: the IMU's axes permuted
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
