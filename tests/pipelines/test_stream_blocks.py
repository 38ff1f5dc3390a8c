"""``gyroemu stream`` computing and sending a block at a time: the same bytes as the whole run encoded
at once, the same schedule, bounded memory, and a stream without end stopped by SIGINT/SIGTERM.

The in-process tests need no zenoh traffic (they drain :class:`BlockProducer`'s queue directly); the
process tests use the helpers of ``tests/live_processes.py``.
"""

import itertools
import json
import signal
import time
import tracemalloc

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.truth_source import ScenarioTruth, truth_source
from gyroemu.pipelines.formats.channels import topic_message_type
from gyroemu.pipelines.formats.mcap_log import truth_series
from gyroemu.pipelines.formats.messages import split_payloads
from gyroemu.pipelines.transport.stream import BlockProducer, encode_block, encode_run, runs_without_end
from gyroemu.sensors import load_device

DEVICE, RATE = "consumer_mems", 1000.0
TOPICS = ("/imu", "/mag", "/truth/imu", "/raw/mems")
KEYS = {topic: f"gyroemu/t{topic}" for topic in TOPICS}


def produced(run, rate=RATE, keys=KEYS, depth=64) -> list:
    """Every message a :class:`BlockProducer` of ``run`` queues, ``(offset ns, key, payload)``, in order."""
    producer = BlockProducer(run, keys, rate, depth)
    producer.start()
    out = [m for batch in producer.batches() for m in batch]
    producer.join(10)
    return out


def assert_rows_close(topic: str, got: list, want: list, ulps: float = 16, per_column: bool = True) -> int:
    """Messages of ``topic``: same headers, fields equal to ``ulps`` of each column's largest magnitude
    (of the field's, with ``per_column`` False); the bounds are derived where they are used. Returns how
    many messages differ in their bytes at all."""
    mtype = topic_message_type(topic)
    a, b = mtype.decode(got), mtype.decode(want)
    np.testing.assert_array_equal(a.stamp_ns, b.stamp_ns)
    assert list(a.frame_id) == list(b.frame_id)
    for name, value in b.fields.items():
        scale = np.max(np.abs(value), axis=0 if per_column else None, keepdims=True) if value.size else 0.0
        assert np.all(np.abs(a[name] - value) <= ulps * np.finfo(float).eps * scale), f"{topic} {name}"
    return sum(g != w for g, w in zip(got, want))


@pytest.mark.parametrize(
    "scenario, duration",
    [("smooth_manoeuvre", 36.0), ("heavy_top", 20.0)],  # pointwise (3 blocks), integrated (2 blocks)
)
def test_blocked_stream_is_the_whole_run_encoded(scenario, duration):
    """The messages a blocked stream queues: per key the whole run's encoding (``encode_run`` of
    ``device.measure(scenario.simulate(duration))``) — /imu, /mag, /raw byte for byte, /truth/imu to
    round-off (and identical bytes in practice) — each sample's messages in topic order at
    ``round(k * 1e9 / rate)``."""
    scen = load_scenario(scenario)
    traj = scen.simulate(duration=duration)
    samples = load_device(DEVICE, seed=5).measure(traj)
    whole = encode_run(samples, truth_series(traj, samples))
    assert list(whole) == list(TOPICS)
    n = len(samples.t)

    run = load_device(DEVICE, seed=5).run(truth_source(scen, duration))
    assert run.count == n and run.block_samples < n  # more than one block
    messages = produced(run)
    assert len(messages) == n * len(TOPICS)
    offsets = [m[0] for m in messages]
    assert offsets == [round(k * 1e9 / RATE) for k in range(n) for _ in TOPICS]
    assert [m[1] for m in messages] == list(KEYS.values()) * n
    by_key = {key: [m[2] for m in messages if m[1] == key] for key in KEYS.values()}
    for topic in ("/imu", "/mag", "/raw/mems"):
        assert by_key[KEYS[topic]] == split_payloads(whole[topic]), topic
    # /truth/imu to round-off: q_wb (Slerp) and omega_b (cubic Hermite) are local interpolants, the same
    # arithmetic on the same samples in a window as in the whole run; specific_force_b is a not-a-knot
    # cubic spline, whose dependence on a sample decays by 2 - sqrt(3) ~ 0.27 per sample, so the 32
    # samples of margin of a window (truth_source.WINDOW_MARGIN) change it by 0.27**32 ~ 2e-18 of the
    # data's scale; what remains is the round-off of solving a smaller tridiagonal system, a few ulps of
    # the column's scale: 16 ulps bound both.
    differ = assert_rows_close("/truth/imu", by_key[KEYS["/truth/imu"]], split_payloads(whole["/truth/imu"]))
    print(f"\n{scenario}: /truth/imu messages differing in their bytes from the whole run's: {differ} of {n}")


def test_as_fast_as_possible_has_no_deadlines():
    """``rate=None`` (``--as-fast-as-possible``): every offset 0, the same messages."""
    scen = load_scenario("bench_static")
    paced = produced(load_device(DEVICE, seed=1).run(truth_source(scen, 3.0)))
    fast = produced(load_device(DEVICE, seed=1).run(truth_source(scen, 3.0)), rate=None)
    assert {m[0] for m in fast} == {0}
    assert [m[1:] for m in fast] == [m[1:] for m in paced]


def test_what_runs_without_end():
    """Pointwise kinds with no bounded span stream until stopped; a recording (bounded span) and the
    integrated kinds do not."""
    assert runs_without_end(load_scenario("smooth_manoeuvre"))
    assert runs_without_end(load_scenario("bench_static"))
    assert not runs_without_end(load_scenario("recorded_motion"))
    assert not runs_without_end(load_scenario("heavy_top"))


def test_endless_run_is_the_bounded_run_continued():
    """A source without end gives the messages of a bounded run of the same scenario, in the same
    order at the same offsets, over the first block (its windows end before the bounded run's last
    samples, where a spline's end condition makes it differ from one that goes on by its truncation
    error), equal to round-off but not bit for bit: the truth is evaluated in segments of another
    length (the bounded run's one segment ends with it), which rounds the motion's formula
    differently, and the differences, of an ulp per operation, add up along a segment to ~10 ulps of
    a field's magnitude. The device's linear error model carries them through at the scale of its
    output: 64 ulps of each field's largest magnitude bound them."""
    scen = load_scenario("smooth_manoeuvre")
    run = load_device(DEVICE, seed=2).run(truth_source(scen, 20.0))
    bounded = produced(run)[: run.block_samples * len(TOPICS)]
    endless = BlockProducer(load_device(DEVICE, seed=2).run(ScenarioTruth(scen, None)), KEYS, RATE)
    head = list(itertools.islice((m for batch in endless.produce() for m in batch), len(bounded)))
    assert [m[:2] for m in head] == [m[:2] for m in bounded]
    differ = {
        topic: assert_rows_close(
            topic, [m[2] for m in head if m[1] == key], [m[2] for m in bounded if m[1] == key], 64, False
        )
        for topic, key in KEYS.items()
    }
    print(f"\nendless vs 20 s run, messages differing in their bytes: {differ} of {run.block_samples} each")


def test_first_messages_long_before_the_whole_run():
    """An hour at 1 kHz: the first batch is queued after one block's computation, in far less time
    than simulating and measuring only a tenth of the run takes, and the producer holds a few blocks.
    Both timed warm: the first batch of the same stream first, untimed, loads or compiles what a
    process does once (numba's kernels, lazy imports: 0.5 s alone, none when the worker ran an earlier
    stream), which the tenth, timed after, would otherwise not pay. A shorter stream would not do: a
    run shorter than a block takes other paths (on an empty numba cache a 60 s stream's first batch
    still compiled for 0.2 s after a 1 s stream's, and so failed on a clean clone's CI, 0.37 s against
    0.25 s)."""
    scen = load_scenario("smooth_manoeuvre")
    warm = BlockProducer(load_device(DEVICE, seed=3).run(truth_source(scen, 3600.0)), KEYS, RATE, depth=4)
    warm.start()
    try:
        next(warm.batches())
    finally:
        warm.stopping.set()
        warm.join(30)
    started = time.perf_counter()
    run = load_device(DEVICE, seed=3).run(truth_source(scen, 3600.0))
    producer = BlockProducer(run, KEYS, RATE, depth=64)
    producer.start()
    try:
        next(producer.batches())
        first = time.perf_counter() - started
        producer.ready.wait(30)
    finally:
        producer.stopping.set()
        producer.join(30)
    started = time.perf_counter()
    load_device(DEVICE, seed=3).measure(scen.simulate(duration=360.0))
    tenth = time.perf_counter() - started
    print(f"\nfirst batch of a 3600 s stream after {first:.2f} s; simulating and measuring 360 s: {tenth:.2f} s")
    assert first < tenth
    assert producer.samples <= 2 * run.block_samples  # queued ahead: a block's worth at most here


@pytest.mark.slow
def test_producer_memory_does_not_grow_with_the_duration():
    """tracemalloc's peak over a whole run, its queue drained as fast as it fills: 40 s (more than two
    blocks, so the queue fills) and 160 s peak alike, where the whole run's messages alone would take
    four times the memory. A short run first, untraced, makes the one-time allocations (lazy imports,
    caches) that would otherwise count in the first traced run only."""
    scen = load_scenario("smooth_manoeuvre")
    sum(1 for _ in drain(load_device(DEVICE, seed=4).run(truth_source(scen, 2.0)), 64))
    peaks = {}
    for duration in (40.0, 160.0):
        run = load_device(DEVICE, seed=4).run(truth_source(scen, duration))
        depth = 64 + run.block_samples // 64
        tracemalloc.start()
        try:
            count = sum(1 for _ in drain(run, depth))
            peaks[duration] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert count == round(duration * RATE) * len(TOPICS)
    print(f"\nproducer peak: {', '.join(f'{d:g} s: {p / 1e6:.1f} MB' for d, p in peaks.items())}")
    assert peaks[160.0] < 1.2 * peaks[40.0]


def drain(run, depth):
    """The messages of a producer of ``run``, dropped as they come (nothing kept)."""
    producer = BlockProducer(run, KEYS, RATE, depth)
    producer.start()
    for batch in producer.batches():
        yield from batch
    producer.join(10)


# --------------------------------------------------------------------------------------------------
# Processes.

zenoh = pytest.importorskip("zenoh")

from live_processes import free_port, procs  # noqa: E402,F401  (procs is a fixture)
from signal_output import SignalOn  # noqa: E402


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_endless_stream_publishes_at_once_and_stops_on_signal(procs, tmp_path, sig, status):
    """No ``--duration``, a pointwise scenario: the stream says it runs until stopped, publishes within
    seconds of its start, and on SIGINT/SIGTERM stops with exit 130/143; the recorder got every topic from
    sequence 0 without a gap, every topic the same number of samples, /imu the bytes of the same run
    computed in-process."""
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    procs.start(
        "stream",
        "stream",
        "--scenario",
        "smooth_manoeuvre",
        "--device",
        DEVICE,
        "--seed",
        "9",
        "--listen",
        endpoint,
        "--device-name",
        "endless",
    )
    procs.wait_for("stream", "gyroemu/endless/imu")
    assert "until stopped (Ctrl-C)" in procs.log("stream")
    procs.start(
        "rec",
        "record",
        "--out",
        str(tmp_path / "e.mcap"),
        "--connect",
        endpoint,
        "--report",
        str(tmp_path / "e.json"),
    )
    procs.wait_for("stream", "stream: publishing", timeout=30)
    latency = time.monotonic() - started
    time.sleep(3.0)
    assert procs.stop("stream", sig, timeout=30) == status, procs.log("stream")
    time.sleep(0.5)
    assert procs.stop("rec") == 0, procs.log("rec")
    print(f"\nstream publishing {latency:.2f} s after its start (python start-up and recorder included)")
    print(procs.log("stream") + procs.log("rec"))
    assert latency < 20.0  # the recorder's start-up is in it; an hour's simulation would not be
    assert "publishing anyway" not in procs.log("stream")
    assert "stream: sent" in procs.log("stream")
    report = json.loads((tmp_path / "e.json").read_text())
    by_topic = {r["topic"]: r for r in report["publishers"].values()}
    assert sorted(by_topic) == sorted(f"endless{t}" for t in (*TOPICS, "/tf", "/tf_static"))
    for tf in ("endless/tf", "endless/tf_static"):  # the sparse tf tree: nothing lost either
        r = by_topic.pop(tf)
        assert (r["first"], r["last"], r["missing"], r["duplicates"]) == (0, r["received"] - 1, 0, 0), r
    received = {r["received"] for r in by_topic.values()}
    assert len(received) == 1, by_topic  # stopped between samples: every topic the same count
    n = received.pop()
    assert n > 500, by_topic
    for r in by_topic.values():
        assert (r["first"], r["last"], r["missing"], r["duplicates"]) == (0, n - 1, 0, 0), r
    log = read_mcap(tmp_path / "e.mcap")
    from mcap.reader import make_reader

    from gyroemu.pipelines.formats.imu_covariance import measurement_variances
    from gyroemu.pipelines.formats.messages import stamps_to_ns
    from gyroemu.pipelines.transport.zenoh_io import header_stamp_ns

    with open(tmp_path / "e.mcap", "rb") as f:
        got = [m.data for _, _, m in make_reader(f).iter_messages(topics=["/imu"], log_time_order=True)]
    scen = load_scenario("smooth_manoeuvre")
    device = load_device(DEVICE, seed=9)
    run = device.run(ScenarioTruth(scen, None))
    want, start_ns = [], None
    for block in run:
        if start_ns is None:  # the stream's clock: the wall clock at its start
            start_ns = header_stamp_ns(got[0]) - int(stamps_to_ns(block.samples.t[:1])[0])
        want += split_payloads(encode_block(block, start_ns=start_ns, variances=measurement_variances(device))["/imu"])
        if len(want) >= n:
            break
    assert not log.truncated and got == want[:n]


@pytest.mark.slow
def test_endless_stream_with_live_estimate_through_a_router(procs, tmp_path):
    """``--estimate`` on a stream without end (its filter warmed up on the first block): estimates are
    published alongside, and SIGINT stops both with exit 130."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start("router", "router", "--listen", endpoint)
    procs.wait_for("router", "listening")
    client = ["--connect", endpoint, "--mode", "client"]
    procs.start("rec", "record", "--out", str(tmp_path / "r.mcap"), *client, "--report", str(tmp_path / "r.json"))
    procs.wait_for("rec", "subscribed")
    procs.start(
        "stream", "stream", "--scenario", "bench_static", "--device", DEVICE, "--estimate", *client, "--wait", "5"
    )
    procs.wait_for("stream", "stream: publishing", timeout=60)
    time.sleep(4.0)
    assert procs.stop("stream") == 130, procs.log("stream")
    time.sleep(0.5)
    assert procs.stop("rec") == 0, procs.log("rec")
    print("\n" + procs.log("stream") + procs.log("rec"))
    assert "gyroemu/imu0/estimate/imu (mekf" in procs.log("stream")
    assert "estimates published" in procs.log("stream")
    report = json.loads((tmp_path / "r.json").read_text())
    by_topic = {r["topic"]: r for r in report["publishers"].values()}
    assert by_topic["imu0/estimate/imu"]["received"] > 100, by_topic
    assert by_topic["imu0/imu"]["missing"] == 0 and by_topic["imu0/imu"]["received"] > 1000
    assert procs.stop("router") == 0


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_a_stream_stopped_by_a_signal_returns_its_status(sig, status):
    """SIGINT ends a stream with 130 and SIGTERM with 143, as any command (it was 130 for both: the
    stream's own handlers only noted that a signal came). In process, on a loopback endpoint."""
    from gyroemu.pipelines.transport.stream import StreamOptions, run_stream
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions, SessionOptions

    options = StreamOptions(
        scenario="smooth_manoeuvre",
        device=DEVICE,
        duration=2.0,
        device_name=f"sig{free_port()}",
        session=SessionOptions(listen=(f"tcp/127.0.0.1:{free_port()}",)),
        pacing=PacingOptions(wait_s=0.0),
    )
    out = SignalOn(sig, "stream: publishing")
    assert run_stream(options, out=out) == status, "".join(out.text)  # type: ignore[arg-type]
    assert "stream: sent" in "".join(out.text)
