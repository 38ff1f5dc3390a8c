"""Live zenoh streams on loopback: many devices through ``gyroemu record``, and one-way latency.

    python tests/benchmarks/bench_live.py [--devices 50] [--rate 1000] [--duration 20] [--latency-duration 10]

A script, not a test (pytest does not collect it). Everything stays on 127.0.0.1 (free ports, no
scouting), every wait is bounded, and the started processes are killed on the way out.

(a) Throughput: this script publishes ``--devices`` keys ``gyroemu/dNN/imu`` at ``--rate`` each for
    ``--duration`` s with :class:`gyroemu.pipelines.transport.zenoh_io.PacedPublisher` (one process: ``gyroemu stream``
    publishes one device per process, and 50 such processes would be too heavy for a small machine);
    the payload is the ``/imu`` CDR of a simulated consumer MEMS device. ``gyroemu record`` (a separate
    process, zenoh client of the publisher's listening endpoint) writes them to an MCAP file; its JSON
    report gives per device the messages received, missing and duplicated. Loss = sent - received.
(b) Latency: ``gyroemu stream`` (one device, ``--rate`` from the device, ``--latency-duration`` s) publishes;
    a zenoh subscriber in this script stamps each ``/imu`` sample on arrival (``time.time_ns()`` in the
    callback) and subtracts the attachment's source stamp (same machine clock): p50, p99, max.
    Baseline in the same run: a plain zenoh-python publisher process (``put`` of a payload of the same
    size with a timestamp attachment, paced at the same rate, no gyroemu code) to the same subscriber.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402

from gyroemu.pipelines.transport.zenoh_io import PacedPublisher, open_session, session_config  # noqa: E402

SCENARIO, DEVICE = "heavy_top", "consumer_mems"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def gyroemu(log: Path, *args) -> subprocess.Popen:
    with open(log, "wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "gyroemu", *args],
            cwd=ROOT,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )


def wait_for(log: Path, proc: subprocess.Popen, text: str, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if log.exists() and text in log.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    raise RuntimeError(f"{log.name}: no {text!r} after {timeout} s:\n{log.read_text(errors='replace')}")


def stop(proc: subprocess.Popen, timeout: float = 30.0) -> int | None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
    return proc.returncode


def imu_payloads(duration: float) -> list[bytes]:
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.messages import split_payloads
    from gyroemu.pipelines.transport.stream import encode_run
    from gyroemu.sensors import load_device

    traj = load_scenario(SCENARIO).simulate(duration=duration)
    return split_payloads(encode_run(load_device(DEVICE, seed=0).measure(traj))["/imu"])


# --------------------------------------------------------------------------------------------------
# (a) many devices through the recorder.


def bench_throughput(folder: Path, devices: int, rate: float, duration: float) -> bool:
    payloads = imu_payloads(duration)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = [f"gyroemu/d{i:02d}/imu" for i in range(devices)]
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    rec_log, report_path, mcap_path = folder / "rec.log", folder / "rec.json", folder / "many.mcap"
    rec = None
    publisher = None
    try:
        publisher = PacedPublisher(session, keys)
        rec = gyroemu(
            rec_log,
            "record",
            "--out",
            str(mcap_path),
            "--connect",
            endpoint,
            "--mode",
            "client",
            "--report",
            str(report_path),
        )
        wait_for(rec_log, rec, "subscribed", 60)
        if not publisher.wait_for_subscribers(30):
            raise RuntimeError("the recorder's subscription did not reach every key in 30 s")
        hard_end = time.monotonic() + 3 * duration + 30
        pacing = publisher.run({k: payloads for k in keys}, rate, stop=lambda: time.monotonic() > hard_end)
        sent = pacing.messages // devices
        # Wait until the recorder's file stops growing (it flushes every 0.2 s): its backlog is written.
        end, last, still = time.monotonic() + 60, -1, 0.0
        while time.monotonic() < end and still < 1.5:
            size = mcap_path.stat().st_size if mcap_path.exists() else 0
            still = still + 0.25 if size == last else 0.0
            last = size
            time.sleep(0.25)
    finally:
        if rec is not None:
            stop(rec, 60)
        if publisher is not None:
            publisher.close()
        session.close()
    report = json.loads(report_path.read_text())
    rows = sorted(report["publishers"].values(), key=lambda r: r["topic"])
    print(
        f"(a) {devices} devices x {rate:g} Hz /imu ({len(payloads[0])} B payloads) for {duration:g} s "
        f"= {devices * rate:g} messages/s offered; published {pacing.messages} in {pacing.elapsed_s:.2f} s "
        f"({pacing.messages / pacing.elapsed_s:,.0f}/s achieved)"
    )
    print(f"    publisher {pacing.summary()}")
    print(f"    {'device':<10} {'sent':>7} {'received':>9} {'loss':>6} {'missing':>8} {'dup':>5} {'late':>5}")
    total_loss = total_dup = 0
    for r in rows:
        loss = sent - r["received"]
        total_loss += loss
        total_dup += r["duplicates"]
        print(
            f"    {r['topic']:<10} {sent:>7} {r['received']:>9} {loss:>6} {r['missing']:>8} {r['duplicates']:>5} "
            f"{r['late']:>5}"
        )
    absent = devices - len(rows)
    print(
        f"    total: {report['messages']} recorded of {pacing.messages} sent; loss {total_loss + absent * sent}, "
        f"duplicates {total_dup}; devices never seen {absent}; file {mcap_path.stat().st_size / 1e6:.1f} MB"
    )
    return total_loss == 0 and total_dup == 0 and absent == 0


# --------------------------------------------------------------------------------------------------
# (b) one-way latency.

RAW_PUBLISHER = r"""
import struct, sys, time, zenoh
endpoint, size, rate, duration = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
c = zenoh.Config()
c.insert_json5("mode", '"peer"'); c.insert_json5("listen/endpoints", f'["{endpoint}"]')
c.insert_json5("scouting/multicast/enabled", "false")
s = zenoh.open(c)
pub = s.declare_publisher("raw/imu", congestion_control=zenoh.CongestionControl.BLOCK)
payload = bytes(size)
print("raw: ready", flush=True)
end = time.monotonic() + 30
while not pub.matching_status.matching and time.monotonic() < end:
    time.sleep(0.01)
n = int(duration * rate)
t0 = time.monotonic_ns()
for k in range(n):
    deadline = t0 + round(k * 1e9 / rate)
    now = time.monotonic_ns()
    if deadline > now:
        time.sleep((deadline - now) * 1e-9)
    pub.put(payload, attachment=struct.pack("<qq", k, time.time_ns()))
time.sleep(0.5)
print(f"raw: sent {n}", flush=True)
s.close()
"""


def _latencies(proc: subprocess.Popen, endpoint: str, key: str, measured: str, timeout: float) -> np.ndarray:
    """Subscribe to ``key`` through ``endpoint`` until ``proc`` exits: arrival minus source stamp (s) of
    the samples on ``measured``."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    got: list[tuple[int, int]] = []
    lock = threading.Lock()

    def on_sample(sample):
        now = time.time_ns()
        if str(sample.key_expr) != measured:
            return
        stamp = struct.unpack_from("<q", sample.attachment.to_bytes(), 8)[0]
        with lock:
            got.append((now, stamp))

    session = zenoh.open(config)
    try:
        sub = session.declare_subscriber(key, on_sample)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        sub.undeclare()
    finally:
        session.close()
    arr = np.array(got, dtype=np.int64).reshape(-1, 2)
    return (arr[:, 0] - arr[:, 1]) * 1e-9


def _figures(name: str, lat: np.ndarray, expected: int) -> str:
    if not len(lat):
        return f"    {name:<34} no samples received"
    p50, p99, mx = (np.percentile(lat, 50) * 1e6, np.percentile(lat, 99) * 1e6, lat.max() * 1e6)
    return f"    {name:<34} {len(lat):>6}/{expected} samples: p50 {p50:8.1f} µs, p99 {p99:8.1f} µs, max {mx:9.1f} µs"


def bench_latency(folder: Path, rate: float, duration: float) -> None:
    size = len(imu_payloads(0.01)[0])
    n = int(round(duration * rate))
    timeout = duration + 120
    # gyroemu stream -> subscriber
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    log = folder / "stream.log"
    stream = gyroemu(
        log,
        "stream",
        "--scenario",
        SCENARIO,
        "--device",
        DEVICE,
        "--duration",
        str(duration),
        "--listen",
        endpoint,
        "--device-name",
        "lat",
        "--wait",
        "30",
    )
    try:
        wait_for(log, stream, "gyroemu/lat/imu", 120)
        # Every key is subscribed (the stream waits for that before its clock starts); /imu is measured.
        lat = _latencies(stream, endpoint, "gyroemu/lat/**", "gyroemu/lat/imu", timeout)
    finally:
        stop(stream)
    # plain zenoh-python baseline
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    raw_log = folder / "raw.log"
    with open(raw_log, "wb") as out:
        raw = subprocess.Popen(
            [sys.executable, "-c", RAW_PUBLISHER, endpoint, str(size), str(rate), str(duration)],
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        wait_for(raw_log, raw, "raw: ready", 60)
        base = _latencies(raw, endpoint, "raw/imu", "raw/imu", timeout)
    finally:
        stop(raw)
    topics = sum(1 for line in log.read_text().splitlines() if line.startswith("  gyroemu/lat/"))
    print(
        f"(b) one-way latency on loopback at {rate:g} Hz for {duration:g} s, {size} B /imu payloads "
        f"(arrival in the subscriber's callback minus the attachment's source stamp)"
    )
    print(_figures(f"gyroemu stream /imu ({topics} topics/sample)", lat, n))
    print(_figures("baseline: plain zenoh put (1 topic)", base, n))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--devices", type=int, default=50)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--latency-duration", type=float, default=10.0)
    parser.add_argument("--skip", choices=("throughput", "latency"), action="append", default=[])
    args = parser.parse_args(argv)
    ok = True
    with tempfile.TemporaryDirectory(prefix="bench_live_") as tmp:
        folder = Path(tmp)
        if "throughput" not in args.skip:
            ok = bench_throughput(folder, args.devices, args.rate, args.duration)
        if "latency" not in args.skip:
            bench_latency(folder, args.rate, args.latency_duration)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
