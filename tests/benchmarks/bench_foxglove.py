"""CPU that the Foxglove view adds to a 1 kHz ``gyroemu stream`` (target: under 10 %).

    python tests/benchmarks/bench_foxglove.py [--duration 20] [--repeats 2] [--rate 60]

A script, not a test (pytest does not collect it). Each run is a ``gyroemu stream`` child process
(``smooth_manoeuvre`` through ``consumer_mems``, 1 kHz, 4 topics a sample, ``--wait 0``, listening on a
free loopback port, no zenoh subscriber), in three variants, alternated ``--repeats`` times:

- baseline: no ``--foxglove``;
- ``--foxglove`` with no client connected;
- ``--foxglove`` with a client (a plain WebSocket client in this script, on its own thread)
  subscribed to every channel: the Foxglove app open on the view.

The child's CPU time (user + system) is read from ``/proc/<pid>/stat`` when it prints
``stream: publishing`` and again when it prints ``stream: sent`` (its clock has stopped; start-up,
simulation ahead of the first message and the linger at the end are outside the window), and divided by
the stream's span: CPU seconds per second of stream. The whole process's CPU (``os.times()``' children
figures around each run) is printed too. The view's overhead is the median of a variant over the
baseline's median, measured in the same run. Also printed: the pacing report of each run (the view must
not make the stream late) and whether the view dropped batches.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TICKS = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """utime + stime of a live process, s (fields 14 and 15 of /proc/<pid>/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def wait_for(log: Path, proc: subprocess.Popen, text: str, timeout: float) -> float:
    """Poll ``log`` until it holds ``text``; the process's CPU seconds then."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if text in log.read_text(errors="replace"):
            return cpu_seconds(proc.pid)
        if proc.poll() is not None:
            break
        time.sleep(0.005)
    raise RuntimeError(f"no {text!r} in {log} (exit {proc.poll()}):\n{log.read_text(errors='replace')}")


def client(port: int, stop: threading.Event, counts: dict) -> None:
    """Connect to the view, subscribe to every channel, count what arrives until ``stop``."""
    from websockets.sync.client import connect

    end = time.monotonic() + 60
    while True:
        try:
            ws = connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"])
            break
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.02)
    channels: dict[int, str] = {}
    subscribed: set[int] = set()
    with ws:
        while not stop.is_set():
            try:
                frame = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # the server closed: the stream has ended
                return
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise":
                    new = [c for c in msg["channels"] if c["id"] not in subscribed]
                    channels.update({c["id"]: c["topic"] for c in new})
                    subscribed.update(c["id"] for c in new)
                    subs = [{"id": c["id"], "channelId": c["id"]} for c in new]
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif frame[0] == 1:
                topic = channels[int.from_bytes(frame[1:5], "little")]
                counts[topic] = counts.get(topic, 0) + 1


def run(folder: Path, name: str, duration: float, foxglove: bool, with_client: bool, rate: float) -> dict:
    log = folder / f"{name}.log"
    args = ["stream", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", str(duration)]
    args += ["--wait", "0", "--listen", f"tcp/127.0.0.1:{free_port()}", "--mode", "peer"]
    port = free_port()
    if foxglove:
        args += ["--foxglove", "--foxglove-port", str(port), "--foxglove-rate", str(rate)]
    before = os.times()
    stop, counts = threading.Event(), {}
    watcher = threading.Thread(target=client, args=(port, stop, counts), daemon=True) if with_client else None
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyroemu", *args], cwd=ROOT, stdout=out, stderr=subprocess.STDOUT
        )
    try:
        if watcher is not None:
            wait_for(log, proc, "Foxglove view on", 120)
            watcher.start()
        c0 = wait_for(log, proc, "stream: publishing", 120)
        c1 = wait_for(log, proc, "stream: sent", duration + 120)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        stop.set()
        if watcher is not None:
            watcher.join(5)
    after = os.times()
    text = log.read_text(errors="replace")
    pacing = next((line for line in text.splitlines() if line.startswith("stream: pacing")), "")
    return {
        "cpu_per_s": (c1 - c0) / duration,
        "total_cpu_s": (after.children_user - before.children_user) + (after.children_system - before.children_system),
        "pacing": pacing.replace("stream: pacing: ", ""),
        "dropped": "dropped" in text,
        "received": counts,
        "exit": proc.returncode,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=20.0, help="seconds of stream per run (default 20)")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each variant, alternated (default 2)")
    parser.add_argument("--rate", type=float, default=30.0, help="the view's --foxglove-rate (default 30, gyroemu's)")
    args = parser.parse_args(argv)
    variants = {
        "baseline (no --foxglove)": (False, False),
        "--foxglove, no client": (True, False),
        "--foxglove, client subscribed to all": (True, True),
    }
    results: dict[str, list[dict]] = {name: [] for name in variants}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeats):
            for i, (name, (fox, cl)) in enumerate(variants.items()):
                r = run(Path(tmp), f"run{k}_{i}", args.duration, fox, cl, args.rate)
                results[name].append(r)
                print(
                    f"  {name}: {r['cpu_per_s'] * 100:.1f} % of a core while streaming, process total "
                    f"{r['total_cpu_s']:.2f} s CPU, exit {r['exit']}, dropped: {r['dropped']}; {r['pacing']}",
                    flush=True,
                )
                if r["received"]:
                    print(f"    client received: {r['received']}", flush=True)
    base = statistics.median(r["cpu_per_s"] for r in results["baseline (no --foxglove)"])
    print(f"\n1 kHz stream, {args.duration:g} s per run, {args.repeats} runs per variant, view at {args.rate:g} Hz")
    print(f"{'variant':40s} {'CPU while streaming':>22s} {'vs baseline':>12s}")
    ok = True
    for name, rs in results.items():
        cpu = statistics.median(r["cpu_per_s"] for r in rs)
        over = (cpu - base) / base * 100
        print(f"{name:40s} {cpu * 100:20.1f} % {over:+11.1f} %")
        if name != "baseline (no --foxglove)":
            ok &= over < 10.0
    print("target (< 10 % added CPU):", "met" if ok else "NOT met")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
