"""A router restarted in the middle of a stream: the publisher and the recorder (both zenoh clients of
the router) reconnect by themselves, and the recorder reports exactly which sequence numbers fell into
the gap.

Run alone with ``pytest tests/pipelines/test_router_restart.py -n 0 -s``. Bounded in time (about
25 s on an idle machine); every process is killed in the fixture's ``finally`` block.
"""

import json
import signal
import time

import pytest

pytest.importorskip("zenoh")

from live_processes import free_port, procs  # noqa: E402,F401  (procs is a fixture)

pytestmark = pytest.mark.slow  # long statistical or multi-process runs: `pytest -m slow`

SCENARIO, DEVICE, RATE = "heavy_top", "consumer_mems", 1000.0
TOPICS = ("/imu", "/mag", "/truth/imu", "/raw/mems")

DURATION, SEED, NAME = 12.0, 3, "restarted"


def expected_stamps() -> dict[str, dict[int, int]]:
    """Topic -> {header stamp (ns): sequence number} of what the stream sends (same code, same seed)."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.mcap_log import truth_series
    from gyroemu.pipelines.formats.messages import split_payloads
    from gyroemu.pipelines.transport.stream import encode_run
    from gyroemu.pipelines.transport.zenoh_io import header_stamp_ns
    from gyroemu.sensors import load_device

    traj = load_scenario(SCENARIO).simulate(duration=DURATION)
    samples = load_device(DEVICE, seed=SEED).measure(traj)
    encoded = encode_run(samples, truth_series(traj, samples))
    return {
        topic: {header_stamp_ns(p): k for k, p in enumerate(split_payloads(rows))} for topic, rows in encoded.items()
    }


def test_router_restart_mid_stream_reconnects_and_reports_the_gap(procs, tmp_path):  # noqa: F811
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    client = ["--connect", endpoint, "--mode", "client"]
    procs.start("router1", "router", "--listen", endpoint)
    procs.wait_for("router1", "listening")
    procs.start("rec", "record", "--out", str(tmp_path / "r.mcap"), *client, "--report", str(tmp_path / "r.json"))
    procs.wait_for("rec", "subscribed")
    procs.start(
        "stream",
        "stream",
        "--scenario",
        SCENARIO,
        "--device",
        DEVICE,
        "--duration",
        str(DURATION),
        "--seed",
        str(SEED),
        "--device-name",
        NAME,
        "--wait",
        "30",
        "--start-time",
        "0",  # stamps from 0, as expected_stamps() makes them
        *client,
    )
    procs.wait_for("stream", "stream: publishing", timeout=60)
    time.sleep(3.0)
    procs.stop("router1", signal.SIGKILL)  # no goodbye to the clients: the links just break
    time.sleep(1.0)
    procs.start("router2", "router", "--listen", endpoint)
    procs.wait_for("router2", "listening")
    assert procs.wait("stream", 90) == 0, procs.log("stream")
    time.sleep(1.0)
    assert procs.stop("rec") == 0, procs.log("rec")
    print("\n" + procs.log("rec"))
    assert procs.stop("router2") == 0

    n = int(round(DURATION * RATE))
    report = json.loads((tmp_path / "r.json").read_text())
    by_topic = {r["topic"]: r for r in report["publishers"].values()}
    # the sample topics and the stream's tf tree (/tf at its display rate, /tf_static every second)
    assert sorted(by_topic) == sorted(f"{NAME}{t}" for t in (*TOPICS, "/tf", "/tf_static")), by_topic.keys()

    from gyroemu.pipelines.formats.mcap_records import iter_mcap_batches

    recorded: dict[str, list[int]] = {t: [] for t in TOPICS}
    stamps = expected_stamps()
    for batch in iter_mcap_batches(tmp_path / "r.mcap"):
        for m in batch:
            if m.topic in ("/tf", "/tf_static"):
                continue  # the stream's tf tree, at its display rate
            recorded[m.topic].append(stamps[m.topic][m.log_time])  # KeyError: a message the stream never sent
    gaps = set()
    for topic in TOPICS:
        r = by_topic[f"{NAME}{topic}"]
        got = recorded[topic]
        assert len(got) == len(set(got)) == r["received"], f"{topic}: duplicates in the file"
        assert r["duplicates"] == 0 and r["late"] == 0, r
        # The recorder was subscribed before the clock started, the stream's end came after the restart.
        assert r["first"] == 0 and min(got) == 0, r
        assert r["last"] == n - 1 and max(got) == n - 1, r
        absent = sorted(set(range(n)) - set(got))
        reported = [k for a, b in r["missing_ranges"] for k in range(a, b + 1)]
        assert reported == absent and r["missing"] == len(absent), (topic, r["missing_ranges"])
        # The kill happened: a gap of at least the router's second of absence, all in one stretch
        # (possibly split by a message or two in flight), after the first 3 s and before the end.
        assert len(absent) >= 0.5 * RATE, r["missing_ranges"]
        assert absent[0] > 1.0 * RATE and absent[-1] < n - 1, r["missing_ranges"]
        gaps.add(len(absent))
    print(f"router down: {sorted(gaps)} messages missing per topic, reported exactly")
