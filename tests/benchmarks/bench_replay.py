"""Replay pacing at 1 kHz: how late ``gyroemu replay`` sends each message, with and without a recorder.

    python tests/benchmarks/bench_replay.py [--duration 10] [--repeats 3]

A script, not a test (pytest does not collect it). It simulates a ``--duration`` s gyroemu log
(heavy top through the consumer MEMS: ``/imu``, ``/mag``, ``/truth/imu``, ``/raw/mems`` at 1 kHz, so
a deadline every millisecond with 4 messages each) and replays it at ``--rate 1`` into

- a zenoh subscriber in this script (listening on a free loopback port; the replay connects to it),
  which keeps every ``/imu`` sample's attachment (sequence k, send stamp), and
- with ``recorder``: also ``gyroemu record`` in a third process (a zenoh client of the same endpoint),
  writing the MCAP file on the same two cores.

Pacing error of message k = send time - (t_start + (log_time_k - log_time_0) / rate). Two measures:
"own" is the replay's report (the monotonic clock when the wait for each deadline ends, before the
puts), "wire" is the attachment's send stamp of ``/imu`` (``time.time_ns()`` at the put) minus k ms,
less the smallest such offset of the run (so it counts from the earliest message, not from an
unknown ``t_start``). Each configuration runs ``--repeats`` times, interleaved so that machine load
hits them alike; the table gives each run, then the median of the runs.

Baseline, in the same run: the same replay with :data:`gyroemu.pipelines.transport.zenoh_io.SLEEP_ONLY` (sleep to each
deadline, Python's 5 ms GIL switch interval, the garbage collector on, the kernel's 50 us timer
slack: the replay before :data:`gyroemu.pipelines.transport.zenoh_io.PRECISE`).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from gyroemu.pipelines.transport.zenoh_io import open_session, session_config, subscribe  # noqa: E402

SCENARIO, DEVICE = "heavy_top", "consumer_mems"
TIMINGS = {"baseline (SLEEP_ONLY)": "SLEEP_ONLY", "gyroemu (PRECISE)": "PRECISE"}
_OWN = re.compile(r"p50 ([\d.]+) ms, p99 ([\d.]+) ms, max ([\d.]+) ms")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def replay_once(log: Path, folder: Path, timing: str, recorder: bool) -> dict:
    """One replay of ``log`` with ``gyroemu.pipelines.transport.zenoh_io.<timing>`` as the publisher's default."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(session_config(listen=[endpoint], mode="peer"))
    rec = None
    try:
        sub = subscribe(session, "gyroemu/**", capacity=1 << 17)
        if recorder:
            rec_log = folder / "rec.log"
            with open(rec_log, "wb") as out:
                rec = subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "gyroemu",
                        "record",
                        "--out",
                        str(folder / "rec.mcap"),
                        "--connect",
                        endpoint,
                        "--mode",
                        "client",
                    ],
                    cwd=ROOT,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    env=dict(os.environ, PYTHONUNBUFFERED="1"),
                )
            end = time.monotonic() + 60
            while "subscribed" not in rec_log.read_text(errors="replace"):
                if time.monotonic() > end or rec.poll() is not None:
                    raise RuntimeError(f"recorder did not start:\n{rec_log.read_text(errors='replace')}")
                time.sleep(0.05)
            time.sleep(1.0)  # its subscription reaches the replay's router-less peer mesh
        code = (
            "import sys, gyroemu.pipelines.transport.zenoh_io as z\n"
            f"z.PRECISE = z.{timing}\n"
            "from gyroemu.pipelines.cli import main\n"
            f"sys.exit(main(['replay', {str(log)!r}, '--connect', {endpoint!r}]))\n"
        )
        run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
        if run.returncode != 0:
            raise RuntimeError(f"replay failed ({run.returncode}):\n{run.stdout}\n{run.stderr}")
        time.sleep(0.5)
        sequence, stamp = [], []
        while (sample := sub.try_recv()) is not None:
            if str(sample.key_expr).endswith("/imu") and "/truth/" not in str(sample.key_expr):
                k, ns = struct.unpack_from("<qq", sample.attachment.to_bytes())
                sequence.append(k)
                stamp.append(ns)
    finally:
        session.close()
        if rec is not None:
            rec.send_signal(signal.SIGINT)
            try:
                rec.wait(60)
            except subprocess.TimeoutExpired:
                rec.kill()
    sequence, stamp = np.array(sequence, dtype=np.int64), np.array(stamp, dtype=np.int64)
    offset = stamp - sequence * 1_000_000  # the log's /imu stamps are k ms apart
    wire = (offset - offset.min()) * 1e-3  # us
    own = _OWN.search(run.stdout)
    if own is None:
        raise RuntimeError(f"no pacing line in the replay's output:\n{run.stdout}")
    return {
        "n": len(sequence),
        "own_p50": float(own.group(1)) * 1e3,
        "own_p99": float(own.group(2)) * 1e3,
        "own_max": float(own.group(3)) * 1e3,
        "wire_p50": float(np.percentile(wire, 50)),
        "wire_p99": float(np.percentile(wire, 99)),
        "wire_max": float(wire.max()),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=10.0, help="seconds of log (default 10)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each configuration (default 3)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_replay_") as tmp:
        folder = Path(tmp)
        log = folder / "x.mcap"
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
                str(args.duration),
                "--out",
                str(log),
            ],
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        results: dict[tuple[str, bool], list[dict]] = {}
        for repeat in range(args.repeats):
            for recorder in (False, True):
                for name, timing in TIMINGS.items():
                    r = replay_once(log, folder, timing, recorder)
                    results.setdefault((name, recorder), []).append(r)
                    print(
                        f"run {repeat + 1}: {name:<22} recorder {'yes' if recorder else 'no ':<3}  "
                        f"own p50 {r['own_p50']:7.0f} p99 {r['own_p99']:7.0f} max {r['own_max']:8.0f} us | "
                        f"wire p50 {r['wire_p50']:7.0f} p99 {r['wire_p99']:7.0f} max {r['wire_max']:8.0f} us "
                        f"({r['n']} /imu)",
                        flush=True,
                    )
        load = os.getloadavg()
        print(
            f"\nreplay pacing at 1 kHz ({args.duration:g} s log, 4 messages per deadline), median of "
            f"{args.repeats} runs per row; load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
            f"on {os.cpu_count()} cores"
        )
        print(
            f"  {'publisher timing':<24}{'recorder':<10}{'own p50':>9}{'own p99':>9}{'own max':>10}"
            f"{'wire p50':>10}{'wire p99':>10}{'wire max':>10}   (us)"
        )
        for recorder in (False, True):
            for name in TIMINGS:
                rows = results[(name, recorder)]
                med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
                print(
                    f"  {name:<24}{'yes' if recorder else 'no':<10}{med['own_p50']:9.0f}{med['own_p99']:9.0f}"
                    f"{med['own_max']:10.0f}{med['wire_p50']:10.0f}{med['wire_p99']:10.0f}{med['wire_max']:10.0f}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
