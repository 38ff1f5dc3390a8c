"""``gyroemu replay``: recorded files republished over zenoh between real processes on loopback.

Run alone with ``pytest tests/pipelines/test_replay.py -n 0 -s`` (``-s`` shows the measured figures).
Every process is killed in a ``finally`` block; ports are picked free. About 30 s in all.
"""

import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from live_processes import Listener, free_port, mcap_messages, procs, write_foreign  # noqa: E402,F401
from signal_output import SignalOn  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENARIO, DEVICE, DURATION = "heavy_top", "consumer_mems", 5.0
TOPICS = ("/imu", "/mag", "/truth/imu", "/truth/pose", "/raw/mems")  # every topic of the simulated file
N = 5000  # samples per topic at 1 kHz


@pytest.fixture(scope="module")
def gyroemu_mcap(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "x.mcap"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "gyroemu",
            "simulate",
            "--scenario",
            SCENARIO,
            "--device",
            DEVICE,
            "--duration",
            str(DURATION),
            "--out",
            str(path),
        ],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    return path


@pytest.fixture
def listener():
    lst = Listener()
    try:
        yield lst
    finally:
        lst.close()


@pytest.mark.slow
def test_gyroemu_file_recorded_back_complete_and_byte_exact(procs, tmp_path, gyroemu_mcap):
    """(1) --rate 1 into `gyroemu record`: every message, sequences 0..N-1 per key, payloads identical."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start(
        "rec", "record", "--out", str(tmp_path / "r.mcap"), "--listen", endpoint, "--report", str(tmp_path / "r.json")
    )
    procs.wait_for("rec", "subscribed")
    procs.start("replay", "replay", str(gyroemu_mcap), "--connect", endpoint)
    assert procs.wait("replay", 60) == 0, procs.log("replay")
    assert "publishing anyway" not in procs.log("replay")
    time.sleep(0.5)
    assert procs.stop("rec") == 0, procs.log("rec")
    print("\n" + procs.log("replay") + procs.log("rec"))
    report = json.loads((tmp_path / "r.json").read_text())
    by_topic = {r["topic"]: r for r in report["publishers"].values()}
    # the metadata's device_name, for the device's topics and the file's tf tree
    assert sorted(by_topic) == sorted(f"{DEVICE}{t}" for t in (*TOPICS, "/tf", "/tf_static"))
    for tf in ("/tf", "/tf_static"):  # the tree recorded back as the file's, every message, bytes unchanged
        r = by_topic.pop(f"{DEVICE}{tf}")
        want = mcap_messages(gyroemu_mcap, tf)
        assert (r["received"], r["missing"], r["duplicates"]) == (len(want), 0, 0), r
        assert [g[2] for g in mcap_messages(tmp_path / "r.mcap", tf)] == [w[2] for w in want]
    for r in by_topic.values():
        assert (r["received"], r["first"], r["last"], r["missing"], r["duplicates"], r["late"]) == (
            N,
            0,
            N - 1,
            0,
            0,
            0,
        ), r
    for topic in TOPICS:
        got, want = mcap_messages(tmp_path / "r.mcap", topic), mcap_messages(gyroemu_mcap, topic)
        assert len(got) == len(want) == N
        assert [g[2] for g in got] == [w[2] for w in want], f"{topic}: payload bytes differ"
        assert [g[1] for g in got] == [w[1] for w in want]
    assert os.access(gyroemu_mcap, os.R_OK) and mcap_messages(gyroemu_mcap, "/imu")  # input untouched


def test_rate_4_takes_a_quarter_of_the_time(procs, listener, gyroemu_mcap):
    """(2) --rate 4: the send stamps span about D/4 of the log's duration D (= 4.999 s).

    Bounds: the schedule never sends before a deadline, so the span is at least D/4 (0.25 D) minus the
    first message's lateness; 0.15 D leaves room for that and fails a replay that ignores the pacing
    (20 000 messages as fast as possible take well under 0.1 D here). The upper bound 0.6 D fails a
    replay that ignores --rate (1.0 D) while allowing 1.7 s of stalls on a busy shared machine.
    """
    procs.start("replay", "replay", str(gyroemu_mcap), "--rate", "4", "--connect", listener.endpoint)
    assert procs.wait("replay", 60) == 0, procs.log("replay")
    time.sleep(0.3)
    samples = listener.drain()
    log = mcap_messages(gyroemu_mcap)
    assert len(samples) == len(log)  # every message: the device's topics and the thinned tf tree
    assert sum(s[0].split("/", 2)[2] == "imu" for s in samples) == N  # gyroemu/<device>/imu
    duration_s = (log[-1][1] - log[0][1]) * 1e-9
    stamps = np.array([s[3] for s in samples])
    span_s = (stamps.max() - stamps.min()) * 1e-9
    print(f"\n--rate 4: {duration_s:.3f} s of log sent in {span_s:.3f} s ({span_s / duration_s:.3f} of it)")
    assert 0.15 * duration_s < span_s < 0.6 * duration_s


@pytest.mark.slow
def test_foreign_file_and_pacing(procs, listener, tmp_path):
    """(3) someone else's /sensors/imu_raw goes to gyroemu/imu0/sensors/imu_raw, bytes unchanged (and
    its String topic to gyroemu/imu0/rosout_text). (4) Pacing: send stamps against
    t_start + (log_time - log_time_0) at irregular intervals; p50/p99 printed, drift asserted."""
    n = 1200  # about 6 s
    path = tmp_path / "foreign.mcap"
    log_time = write_foreign(path, n)
    before = path.read_bytes()
    procs.start("replay", "replay", str(path), "--connect", listener.endpoint)
    assert procs.wait("replay", 60) == 0, procs.log("replay")
    time.sleep(0.3)
    samples = listener.drain()
    print("\n" + procs.log("replay"))
    assert path.read_bytes() == before
    imu = [s for s in samples if s[0] == "gyroemu/imu0/sensors/imu_raw"]
    text = [s for s in samples if s[0] == "gyroemu/imu0/rosout_text"]
    assert len(imu) + len(text) == len(samples)
    assert [s[1] for s in imu] == [m[2] for m in mcap_messages(path, "/sensors/imu_raw")]
    assert [s[1] for s in text] == [m[2] for m in mcap_messages(path, "/rosout_text")]
    assert [s[2] for s in imu] == list(range(n)) and [s[2] for s in text] == list(range(n // 10))

    sent = np.array([s[3] for s in imu], dtype=np.int64)
    offset = (sent - (log_time - log_time[0])) * 1e-9  # send time minus the log-time offset: t_start + lateness
    error = offset - offset.min()
    p50, p99, worst = np.percentile(error, 50) * 1e3, np.percentile(error, 99) * 1e3, error.max() * 1e3
    drift = (np.median(error[-200:]) - np.median(error[:200])) * 1e3
    own = [line for line in procs.log("replay").splitlines() if "pacing" in line]
    print(
        f"replay pacing from attachment stamps ({n} irregular deadlines): p50 {p50:.3f} ms, p99 {p99:.3f} ms, "
        f"max {worst:.3f} ms; drift over the run {drift:.3f} ms\n{own}"
    )
    assert abs(drift) < 2.0  # ms: no accumulating drift (sleep-per-message would add ~0.1 ms x 1200)


def test_loop_repeats_with_increasing_deadlines_until_sigterm(procs, listener, tmp_path):
    """--loop: passes follow each other (sequences continue), SIGTERM ends it with status 0."""
    path = tmp_path / "short.mcap"
    log_time = write_foreign(path, 100)  # about 0.5 s
    procs.start(
        "replay",
        "replay",
        str(path),
        "--loop",
        "--rate",
        "2",
        "--topics",
        "/sensors/imu_raw",
        "--connect",
        listener.endpoint,
    )
    procs.wait_for("replay", "publishing")
    time.sleep(1.2)  # about 4 passes at --rate 2
    assert procs.stop("replay", signal.SIGTERM) == 0, procs.log("replay")
    samples = listener.drain()
    assert {s[0] for s in samples} == {"gyroemu/imu0/sensors/imu_raw"}
    seq = [s[2] for s in samples]
    assert seq == list(range(len(seq))) and len(seq) > 2 * 100
    payloads = [m[2] for m in mcap_messages(path, "/sensors/imu_raw")]
    assert [s[1] for s in samples[:100]] == payloads  # pass 0: the recorded bytes
    # Later passes: the recorded bytes but the header stamp (bytes 4-11), moved forward.
    assert [s[1][:4] + s[1][12:] for s in samples] == [
        payloads[k % 100][:4] + payloads[k % 100][12:] for k in range(len(seq))
    ]
    stamps = np.array([s[3] for s in samples[:200]])
    gap = (stamps[100] - stamps[99]) * 1e-9  # from the end of pass 0 to the start of pass 1
    interval = (log_time[-1] - log_time[0]) / 99 / 2 * 1e-9
    print(
        f"\n--loop: {len(seq)} messages in {len(seq) / 100:.1f} passes; gap between passes {gap * 1e3:.2f} ms "
        f"(mean interval / rate {interval * 1e3:.2f} ms)"
    )
    assert 0 < gap < 10 * interval + 0.01


def test_bad_inputs_exit_2_naming_the_file(tmp_path, gyroemu_mcap, capsys):
    """(5) missing, not MCAP, truncated before its first chunk, corrupt, no Imu channel, unknown topic."""
    from mcap_ros2.writer import Writer

    from gyroemu.pipelines.cli import main

    data = gyroemu_mcap.read_bytes()
    bad = {"missing.mcap": None, "text.mcap": b"hello, not an MCAP file\n", "head.mcap": data[:200]}
    corrupt = bytearray(data)
    middle = len(corrupt) // 2
    corrupt[middle : middle + 64] = bytes(64)
    bad["corrupt.mcap"] = bytes(corrupt)
    for name, content in bad.items():
        if content is not None:
            (tmp_path / name).write_bytes(content)
    with open(tmp_path / "text_only.mcap", "wb") as f:
        writer = Writer(f)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        writer.write_message("/chatter", schema, {"data": "hi"}, log_time=1)
        writer.finish()
    for name in (*bad, "text_only.mcap"):
        path = tmp_path / name
        try:
            status = main(["replay", str(path), "--wait", "0"])
        except SystemExit as e:
            status = e.code
        err = capsys.readouterr().err
        print(f"{name}: exit {status}: {err.strip()}")
        assert status == 2 and str(path) in err, (name, status, err)
    try:  # a ReplayError (a ConfigError): main returns 2
        status = main(["replay", str(gyroemu_mcap), "--topics", "/imu", "/nope", "--wait", "0"])
    except SystemExit as e:
        status = e.code
    err = capsys.readouterr().err
    print(err.strip())
    assert status == 2 and "/nope" in err and str(gyroemu_mcap) in err
    assert gyroemu_mcap.read_bytes() == data


@pytest.mark.parametrize("rate", ["1e300", "1e-300", "2e6", "5e-7"])
def test_rate_beyond_what_the_pacing_can_do_is_refused(tmp_path, rate, monkeypatch):
    """--rate 1e300 was an OverflowError traceback (the /clock step, infinite), 1e-300 too (the
    deadlines): refused naming --rate, before the log is read or a session opened."""
    from cli_runs import run_cli

    from gyroemu.pipelines.transport import replay
    from gyroemu.pipelines.transport.replay import MAX_RATE, MIN_RATE, ReplayError, ReplayOptions

    monkeypatch.setattr(replay, "open_session", lambda *a, **k: pytest.fail("a session was opened"))
    log = tmp_path / "never-read.mcap"
    code, _, stderr = run_cli(["replay", str(log), "--rate", rate, "--wait", "0"])
    assert code == 2 and f"argument --rate: must be a speed factor from {MIN_RATE:g} to {MAX_RATE:g}" in stderr, stderr
    assert "Traceback" not in stderr
    for good in (MIN_RATE, 1.0, MAX_RATE):  # taken: on to the log, which is missing
        code, _, stderr = run_cli(["replay", str(log), "--rate", str(good), "--wait", "0"])
        assert code == 2 and "--rate" not in stderr and str(log) in stderr, stderr
    with pytest.raises(ReplayError, match="argument --rate"):
        replay._channels_to_publish(ReplayOptions(log, rate=float("nan")), sys.stdout)


def test_foreign_bag_replayed_and_recorded_keeps_its_schemas(procs, tmp_path):
    """A rosbags-written bag whose IMU topic has no gyroemu role (``/robot1/imu/data_raw``), replayed
    into ``gyroemu record``: the recording's channel has the bag's schema (name and text; it was
    schemaless), so ``gyroemu estimate`` reads it and rosbags' AnyReader opens it."""
    from foreign_bags import write_foreign_bag
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from gyroemu.pipelines.formats.mcap_log import read_mcap

    bag = write_foreign_bag(tmp_path / "bag", imu_topics=("/robot1/imu/data_raw",), mag_topic="/robot1/imu/mag", n=300)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    recording = tmp_path / "r.mcap"
    procs.start("rec", "record", "--out", str(recording), "--listen", endpoint, "--key", "gyroemu/**")
    procs.wait_for("rec", "subscribed")
    procs.start("replay", "replay", str(bag), "--connect", endpoint, "--device-name", "robot", "--rate", "10")
    assert procs.wait("replay", 60) == 0, procs.log("replay")
    time.sleep(0.5)
    assert procs.stop("rec") == 0, procs.log("rec")

    def schemas(path):
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return {
            c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].data)
            for c in summary.channels.values()
            if c.schema_id
        }, {c.topic for c in summary.channels.values()}

    original, _ = schemas(bag)
    recorded, topics = schemas(recording)
    assert topics == {"/robot1/imu/data_raw", "/robot1/imu/mag", "/tf"}, procs.log("rec")
    assert recorded.get("/robot1/imu/data_raw") == original["/robot1/imu/data_raw"]  # the bag's own text
    assert recorded["/robot1/imu/mag"][0] == "sensor_msgs/msg/MagneticField"  # typed by its role
    assert [m[2] for m in mcap_messages(recording, "/robot1/imu/data_raw")] == [
        m[2] for m in mcap_messages(bag, "/robot1/imu/data_raw")
    ]
    out = tmp_path / "re.mcap"
    procs.start("estimate", "estimate", str(recording), "--out", str(out))
    assert procs.wait("estimate", 60) == 0, procs.log("estimate")
    device = read_mcap(out).device
    assert len(device.samples.t) == 300 and device.estimate is not None and len(device.estimate) == 300
    with AnyReader([recording]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
    assert counts["/robot1/imu/data_raw"] == 300 and counts["/robot1/imu/mag"] == 300


def test_recorder_holds_an_untyped_key_until_its_types_come(tmp_path):
    """Without processes: a key the recorder cannot type by role waits for its device's announced types
    (:meth:`Recorder.add_types`, the replay's ``@types`` answer) and gets the announced schema; one whose
    device announces nothing is recorded without a schema (at the types' answer, the grace or the end);
    a topic of a gyroemu role is typed by its role at once."""
    from mcap_ros2.writer import Writer
    from zenoh_samples import Sample

    from gyroemu.pipelines.formats.mcap_records import mcap_channel_info
    from gyroemu.pipelines.formats.messages import IMU
    from gyroemu.pipelines.transport.record import Recorder
    from gyroemu.pipelines.transport.replay import announced_types
    from gyroemu.pipelines.transport.zenoh_io import pack_attachment, topic_types, types_payload

    path = tmp_path / "f.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        text = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        writer.write_message("/a/b", text, {"data": "x"}, log_time=1)
        writer.write_message("/raw/x", text, {"data": "x"}, log_time=1)  # no raw type: announced as it is
        writer.finish()
    channels = mcap_channel_info(path)
    keys = {"/a/b": "gyroemu/d/a/b", "/raw/x": "gyroemu/d/raw/x"}
    types = announced_types(keys, {"/a/b": "d", "/raw/x": "d"}, channels)
    assert set(types) == {"d"} and types["d"]["gyroemu/d/a/b"].name == "std_msgs/msg/String"
    assert topic_types(types_payload(types["d"])) == types["d"]
    imu = bytes(IMU.encode(np.array([1_000_000_000]), "d")[0])
    asked = []
    recorder = Recorder(tmp_path / "r.mcap", on_new_device=asked.append, config_grace_s=60.0)
    recorder.add(Sample("gyroemu/d/a/b", imu, pack_attachment(0, 1, bytes(16))))
    recorder.add(Sample("gyroemu/d/imu", imu, pack_attachment(0, 1, bytes(range(16)))))
    recorder.add(Sample("gyroemu/e/c", imu, pack_attachment(0, 1, bytes(range(1, 17)))))
    recorder.flush()
    assert asked == ["d", "e"]
    assert [c.topic for c in mcap_channel_info(tmp_path / "r.mcap")] == ["/imu"]  # the others wait
    recorder.add_types("d", types["d"])
    recorder.add(Sample("gyroemu/d/a/b", imu, pack_attachment(1, 1, bytes(16))))
    recorder.add_types("e", {})  # e's answer is over: nothing announced
    recorder.close()
    recorded = {c.topic: c for c in mcap_channel_info(tmp_path / "r.mcap")}
    assert list(recorded) == ["/imu", "/a/b", "/e/c"]
    assert recorded["/a/b"].schema_name == "std_msgs/msg/String" and recorded["/a/b"].schema_data == b"string data\n"
    assert recorded["/e/c"].schema_name == "" and recorded["/imu"].schema_name == IMU.name
    assert [m[1] for m in mcap_messages(tmp_path / "r.mcap", "/a/b")] == [1_000_000_000] * 2
    assert recorder.messages == 4


def test_topic_keys_rule():
    """Without processes: gyroemu topics by prefix / metadata / --device-name; foreign topics under the device."""
    from gyroemu.pipelines.transport.replay import topic_keys

    meta = [{"device_name": "d0", "topic_prefix": ""}, {"device_name": "a", "topic_prefix": "/a"}]
    keys, bad = topic_keys(["/imu", "/truth/imu", "/a/raw/fog", "/sensors/imu_raw", "/robot/imu", "/x*"], meta, "zz")
    assert keys == {
        "/imu": "gyroemu/d0/imu",
        "/truth/imu": "gyroemu/d0/truth/imu",
        "/a/raw/fog": "gyroemu/a/raw/fog",
        "/sensors/imu_raw": "gyroemu/zz/sensors/imu_raw",
        "/robot/imu": "gyroemu/zz/robot/imu",
    }
    assert list(bad) == ["/x*"]
    assert topic_keys(["/imu", "/truth/imu"], [])[0] == {
        "/imu": "gyroemu/imu0/imu",
        "/truth/imu": "gyroemu/imu0/truth/imu",
    }


def test_iter_mcap_batches_in_log_time_order(tmp_path, gyroemu_mcap):
    """The read-ahead iterator: the mcap library's log-time order, also for chunks whose log times are
    shuffled (within a chunk and across neighbouring chunks), and --topics filtering."""
    from mcap_ros2.writer import Writer

    from gyroemu.pipelines.formats.mcap_records import iter_mcap_batches

    def flat(path, topics=None):
        return [(m.topic, m.log_time, m.data) for batch in iter_mcap_batches(path, topics) for m in batch]

    assert flat(gyroemu_mcap) == mcap_messages(gyroemu_mcap)
    assert flat(gyroemu_mcap, ["/mag"]) == mcap_messages(gyroemu_mcap, "/mag")
    rng = np.random.default_rng(3)
    times = np.arange(2000) * 1000 + rng.integers(0, 5000, 2000)  # jitter of 5 messages: out of order
    path = tmp_path / "shuffled.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=4096)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        for k, t in enumerate(times):
            writer.write_message("/s", schema, {"data": str(k)}, log_time=int(t))
        writer.finish()
    got = flat(path)
    assert [g[1] for g in got] == sorted(times.tolist())
    assert sorted(g[2] for g in got) == sorted(m[2] for m in mcap_messages(path))


def _short_gyroemu_log(path, n=50):
    """A gyroemu log of ``n`` samples at 100 Hz (with /mag); returns the /imu header stamps, ns."""
    from gyroemu.pipelines.formats.mcap_log import McapLogWriter
    from gyroemu.sensors.samples import ImuSamples

    rng = np.random.default_rng(5)
    samples = ImuSamples(
        t=100.0 + np.arange(n) * 0.01,
        gyro=rng.normal(size=(n, 3)),
        accel=rng.normal(size=(n, 3)),
        mag=rng.normal(size=(n, 3)),
        device="imu0",
    )
    with McapLogWriter(path) as log:
        log.write(samples)
    return np.round(samples.t * 1e9).astype(np.int64)


def test_loop_moves_header_stamps_forward_each_pass(tmp_path):
    """--loop (the reader thread alone): pass 0 is the recorded bytes; pass k's header stamps are pass 0's
    plus k (span + one interval), so they keep increasing; only the stamp's 8 bytes differ."""
    from gyroemu.pipelines.formats.messages import IMU, MAGNETIC_FIELD
    from gyroemu.pipelines.transport.replay import ReadAhead

    path = tmp_path / "short.mcap"
    stamps = _short_gyroemu_log(path, 20)
    recorded = {t: [m[2] for m in mcap_messages(path, t)] for t in ("/imu", "/mag")}
    reader = ReadAhead(path, {"/imu": "k/imu", "/mag": "k/mag"}, 1.0, True, depth=4, stamped={"/imu", "/mag"})
    reader.start()
    got = {"k/imu": [], "k/mag": []}
    deadlines = []
    try:
        for batch in reader.batches():
            for deadline, key, payload in batch:
                got[key].append(payload)
                deadlines.append(deadline)
            if len(got["k/imu"]) >= 60:
                break
    finally:
        reader.stopping.set()
    imu = got["k/imu"][:60]
    assert imu[:20] == recorded["/imu"]  # pass 0 unchanged
    shift = (stamps[-1] - stamps[0]) + 10_000_000  # span + one interval
    t = IMU.decode(imu).stamp_ns
    assert np.all(np.diff(t) > 0)
    assert np.array_equal(t[20:40], t[:20] + shift) and np.array_equal(t[40:60], t[20:40] + shift)
    assert all(a[:4] + a[12:] == b[:4] + b[12:] for a, b in zip(imu[20:], recorded["/imu"] * 2))
    m = MAGNETIC_FIELD.decode(got["k/mag"][:40]).stamp_ns
    assert np.array_equal(m[20:40], m[:20] + shift)
    assert np.all(np.diff(deadlines) >= 0)


@pytest.mark.slow
def test_loop_stamps_increase_at_the_subscriber(procs, listener, tmp_path):
    """``gyroemu replay --loop --clock`` of a gyroemu log: the subscriber sees header stamps that increase
    across the pass boundary, pass 2's = pass 1's + span + one interval, and a /clock that only moves
    forward, from the first stamp."""
    from gyroemu.pipelines.formats.messages import IMU

    path = tmp_path / "short.mcap"
    stamps = _short_gyroemu_log(path, 50)  # 0.5 s
    procs.start(
        "replay",
        "replay",
        str(path),
        "--loop",
        "--clock",
        "--rate",
        "4",
        "--topics",
        "/imu",
        "--connect",
        listener.endpoint,
    )
    procs.wait_for("replay", "publishing")
    deadline = time.monotonic() + 20
    while len(listener.drain()) < 120 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert procs.stop("replay", signal.SIGTERM) == 0, procs.log("replay")
    received = listener.drain()
    samples = [s for s in received if s[0] == "gyroemu/imu0/imu"]
    clock = [struct.unpack("<iI", s[1][4:]) for s in received if s[0] == "gyroemu/imu0/clock"]
    assert len(samples) >= 100, procs.log("replay")
    clock_ns = np.array([sec * 10**9 + nanosec for sec, nanosec in clock])
    assert len(clock_ns) > 4 and clock_ns[0] == stamps[0] and np.all(np.diff(clock_ns) > 0)
    t = IMU.decode([s[1] for s in samples]).stamp_ns
    assert np.all(np.diff(t) > 0)
    assert np.array_equal(t[:50], stamps)
    assert np.array_equal(t[50:100], stamps + (stamps[-1] - stamps[0]) + 10_000_000)


def test_clock_messages_and_keys(tmp_path):
    """--clock: a rosgraph_msgs/Clock of the shifted log time with the first message of each step of at
    least rate / CLOCK_HZ; its key gyroemu/<device>/clock, or in ROS 2 mode /clock's rmw_zenoh key."""
    from gyroemu.pipelines.formats.ros2_keys import Ros2Keys
    from gyroemu.pipelines.transport.replay import CLOCK_HZ, ReadAhead, ReplayOptions, _clock_key

    path = tmp_path / "short.mcap"
    stamps = _short_gyroemu_log(path, 20)  # 100 Hz: a clock every 3rd sample at CLOCK_HZ 40
    reader = ReadAhead(path, {"/imu": "k/imu"}, 1.0, True, depth=4, clock_key="k/clock")
    reader.start()
    clock = []
    try:
        for batch in reader.batches():
            clock += [struct.unpack("<iI", p[4:]) for _, key, p in batch if key == "k/clock"]
            if len(clock) >= 16:
                break
    finally:
        reader.stopping.set()
    ns = np.array([s * 10**9 + n for s, n in clock])
    assert ns[0] == stamps[0] and np.all(np.diff(ns) >= 1e9 / CLOCK_HZ) and np.all(np.diff(ns) <= 3e7)
    shift = (stamps[-1] - stamps[0]) + 10_000_000  # each pass's: span + one interval
    assert set(ns.tolist()) <= set(np.concatenate([stamps, stamps + shift, stamps + 2 * shift]).tolist())
    assert ns[-1] >= stamps[0] + 2 * shift  # into pass 2
    options = ReplayOptions(path=path, clock=True)
    assert _clock_key(options, {"/imu": "gyroemu/left/imu"}, None) == "gyroemu/left/clock"
    assert _clock_key(options, {"/a": "gyroemu/x/a", "/b": "gyroemu/y/b"}, None) == "gyroemu/imu0/clock"
    key = _clock_key(options, {}, Ros2Keys(0, "replay"))
    rosbags = pytest.importorskip("rosbags.typesys")
    hash_ = rosbags.get_typestore(rosbags.Stores.ROS2_JAZZY).hash_rihs01("rosgraph_msgs/msg/Clock")
    assert key.startswith("0/clock/rosgraph_msgs::msg::dds_::Clock_/") and key.endswith(hash_)


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_a_single_pass_stopped_by_a_signal_returns_its_status(tmp_path, sig, status):
    """A pass interrupted by SIGINT ends with 130, by SIGTERM with 143 (it was 130 for both). In process,
    on a loopback endpoint; --loop's 0 is test_loop_repeats_with_increasing_deadlines_until_sigterm's."""
    from gyroemu.pipelines.transport.replay import ReplayOptions, run_replay
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions, SessionOptions

    path = tmp_path / "short.mcap"
    write_foreign(path, 100)
    options = ReplayOptions(
        path=path,
        session=SessionOptions(listen=(f"tcp/127.0.0.1:{free_port()}",)),
        pacing=PacingOptions(wait_s=0.0),
    )
    out = SignalOn(sig, "replay: publishing")
    assert run_replay(options, out=out) == status, "".join(out.text)  # type: ignore[arg-type]


def test_a_bad_endpoint_is_refused_before_the_plan(tmp_path):
    """--listen notaproto/xyz printed the whole topic plan, then blamed --connect/--listen/--config once
    the session failed to open; a config file zenoh refuses was a 6-line error; an endpoint of the config
    file that zenoh refuses when the session opens came after the plan. Now one line naming the argument,
    nothing printed before it."""
    import io

    from cli_runs import run_cli

    from gyroemu.pipelines.transport.replay import ReplayOptions, run_replay
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions, SessionOptions

    path = tmp_path / "short.mcap"
    write_foreign(path, 10)
    code, _, stderr = run_cli(["replay", str(path), "--listen", "notaproto/xyz", "--wait", "0"])
    assert code == 2 and stderr.count("\n") == 1, stderr
    assert stderr.startswith("gyroemu replay: error: argument --listen: 'notaproto/xyz': no zenoh protocol"), stderr
    broken = tmp_path / "bad.json5"
    broken.write_text('{ mode: "peer", listen: { endpoints: ["tcp/127.0.0.1:0"] }, bogus: 3, ')
    for command in (["replay", str(path)], ["router"]):
        code, _, stderr = run_cli([*command, "--config", str(broken)])
        assert code == 2 and stderr.count("\n") == 1, stderr
        assert f"argument --config: {broken}: not a zenoh JSON5 config: line 1, column 71: expected" in stderr, stderr
    foreign = tmp_path / "endpoint.json5"
    foreign.write_text('{ listen: { endpoints: ["notaproto/xyz"] }, scouting: { multicast: { enabled: false } } }')
    cases = [
        (SessionOptions(listen=("notaproto/xyz",)), "argument --listen: 'notaproto/xyz': no zenoh protocol"),
        (SessionOptions(config_file=foreign), "argument --config: an endpoint of no zenoh protocol 'notaproto'"),
    ]
    for session, named in cases:
        printed = io.StringIO()
        with pytest.raises(ValueError, match=named):
            run_replay(ReplayOptions(path=path, session=session, pacing=PacingOptions(wait_s=0.0)), out=printed)
        assert printed.getvalue() == ""
