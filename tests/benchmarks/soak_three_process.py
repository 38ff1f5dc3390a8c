"""Soak: publisher, router and recorder in three processes, a 1 kHz stream for ``--duration`` seconds.

    python tests/benchmarks/soak_three_process.py [--duration 600] [--seed 1] [--keep FOLDER]

A script, not a test (``tests/pipelines/test_soak.py`` runs the same check for 15 s in the suite).
On loopback, with a free port:

1. ``gyroemu router --listen tcp/127.0.0.1:P``;
2. ``gyroemu record --connect tcp/127.0.0.1:P --mode client`` (subscribed before the stream starts);
3. ``gyroemu stream --scenario heavy_top --device consumer_mems --seed S --duration D`` as a client of
   the same router: ``/imu``, ``/mag``, ``/truth/imu``, ``/raw/mems`` at 1 kHz, paced to the clock.

When the stream has ended the recorder is stopped with SIGINT and the checks run:

- sequence numbers (the recorder's per-publisher report, from the attachments): every topic received
  exactly 0..N-1, nothing missing, no duplicate, nothing out of order;
- the file, independently: each topic holds N messages whose header stamps are the N expected ones,
  each once;
- bytes: the payloads recorded on each topic are, in order, the bytes the library encodes for the
  same scenario, device and seed (:func:`gyroemu.pipelines.transport.stream.encode_run`, what the stream published).

It prints the figures (messages, rates, the stream's pacing, each process's CPU time and peak memory,
the file's size) and exits with status 1 on any loss, duplicate or byte mismatch (2 on bad usage).
Every process it starts is stopped (SIGINT, then SIGKILL after a timeout) on the way out.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

SCENARIO, DEVICE, NAME = "heavy_top", "consumer_mems", "soak"
TOPICS = ("/imu", "/mag", "/truth/imu", "/raw/mems")
TF_TOPICS = ("/tf", "/tf_static")  # the stream publishes its tf tree too (display rate; the mounting once)
_TICK = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Process:
    """A ``gyroemu`` subprocess with its output in a file, and its CPU time and peak memory from /proc."""

    def __init__(self, folder: Path, name: str, *args):
        self.name, self.log = name, folder / f"{name}.log"
        with open(self.log, "wb") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "gyroemu", *args],
                cwd=ROOT,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=dict(os.environ, PYTHONUNBUFFERED="1"),
            )
        self.cpu_s = 0.0
        self.peak_mb = 0.0

    def text(self) -> str:
        return self.log.read_text(errors="replace")

    def sample(self) -> None:
        """Record CPU seconds (user + system) and peak resident memory so far, while it runs."""
        try:
            fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            self.cpu_s = (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime (after pid, comm)
            for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    self.peak_mb = int(line.split()[1]) / 1024
        except (OSError, IndexError, ValueError):
            pass

    def wait_for(self, text: str, timeout: float) -> None:
        end = time.monotonic() + timeout
        while text not in self.text():
            if self.proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"{self.name} did not print {text!r} (exit {self.proc.poll()}):\n{self.text()}")
            time.sleep(0.05)

    def stop(self, timeout: float = 120.0) -> int:
        if self.proc.poll() is None:
            self.sample()
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        return self.proc.returncode


def expected_payloads(duration: float, seed: int) -> dict[str, np.ndarray]:
    """Topic -> (N, size) rows: what the stream encodes and publishes for this scenario, device and seed."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.imu_covariance import measurement_variances
    from gyroemu.pipelines.mcap_io import truth_series
    from gyroemu.pipelines.transport.stream import encode_run
    from gyroemu.sensors import load_device

    traj = load_scenario(SCENARIO).simulate(duration=duration)
    device = load_device(DEVICE, seed=seed)
    samples = device.measure(traj)
    variances = measurement_variances(device) or (None, None)
    return encode_run(samples, truth_series(traj, samples), variances=variances)


def check(folder: Path, duration: float, seed: int) -> tuple[bool, list[str]]:
    """The checks of the module's notes on ``folder/soak.mcap`` and ``folder/soak.json``: (ok, lines)."""
    from gyroemu.pipelines.mcap_io import iter_mcap_batches
    from gyroemu.pipelines.transport.zenoh_io import header_stamp_ns

    expected = expected_payloads(duration, seed)
    n = len(expected["/imu"])
    lines, ok = [], True
    report = json.loads((folder / "soak.json").read_text())
    by_topic = {r["topic"]: r for r in report["publishers"].values()}
    lines.append(f"  sequence numbers (recorder's report, {len(by_topic)} publishers):")
    for topic in TOPICS:
        r = by_topic.get(f"{NAME}{topic}")
        good = r is not None and (r["received"], r["first"], r["last"], r["missing"], r["duplicates"], r["late"]) == (
            n,
            0,
            n - 1,
            0,
            0,
            0,
        )
        ok &= good
        lines.append(
            f"    {topic:<11} "
            + (
                "no report"
                if r is None
                else f"received {r['received']} of {n}, seq {r['first']}..{r['last']}, missing {r['missing']}, "
                f"duplicates {r['duplicates']}, out of order {r['late']}"
            )
            + ("" if good else "  <-- FAIL")
        )
    ok &= len(by_topic) == len(TOPICS) + len(TF_TOPICS)  # and the stream's tf tree

    recorded: dict[str, list[bytes]] = {t: [] for t in expected}
    other = 0
    tree = dict.fromkeys(TF_TOPICS, 0)
    for batch in iter_mcap_batches(folder / "soak.mcap"):
        for m in batch:
            if m.topic in recorded:
                recorded[m.topic].append(m.data)
            elif m.topic in tree:
                tree[m.topic] += 1
            else:
                other += 1
    lines.append("  the tf tree: " + ", ".join(f"{count} on {topic}" for topic, count in tree.items()))
    ok &= all(tree.values())
    lines.append(
        f"  the file ({(folder / 'soak.mcap').stat().st_size / 1e6:.1f} MB), per topic against the "
        f"library's encoding of the same run:"
    )
    for topic, rows in expected.items():
        got = recorded[topic]
        stamps = np.array([header_stamp_ns(p) for p in got], dtype=np.int64)
        want_stamps = (
            rows[:, 4:8].copy().view("<i4")[:, 0].astype(np.int64) * 1_000_000_000
            + rows[:, 8:12].copy().view("<u4")[:, 0]
        )  # int32 sec, uint32 nanosec after the 4-byte encapsulation
        unique = len(np.unique(stamps))
        stamps_ok = len(got) == len(rows) and np.array_equal(np.sort(stamps), want_stamps) and unique == len(got)
        bytes_ok = len(got) == len(rows) and b"".join(got) == np.ascontiguousarray(rows).tobytes()
        ok &= stamps_ok and bytes_ok
        lines.append(
            f"    {topic:<11} {len(got)} messages of {len(rows)}, {len(got) - unique} repeated stamps, "
            f"stamps {'as expected' if stamps_ok else 'DIFFER'}, bytes "
            f"{'identical' if bytes_ok else 'DIFFER'} ({rows.shape[1]} B each)"
            + ("" if stamps_ok and bytes_ok else "  <-- FAIL")
        )
    if other:
        lines.append(f"    {other} messages on other topics  <-- FAIL")
        ok = False
    return ok, lines


def run(duration: float, seed: int, folder: Path, out=sys.stdout) -> bool:
    """Run the soak in ``folder``; prints the figures to ``out``; True when nothing was lost,
    duplicated or changed."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    router = Process(folder, "router", "router", "--listen", endpoint)
    procs = [router]
    try:
        router.wait_for("listening", 60)
        rec = Process(
            folder,
            "record",
            "record",
            "--out",
            str(folder / "soak.mcap"),
            "--connect",
            endpoint,
            "--mode",
            "client",
            "--report",
            str(folder / "soak.json"),
        )
        procs.append(rec)
        rec.wait_for("subscribed", 60)
        stream = Process(
            folder,
            "stream",
            "stream",
            "--scenario",
            SCENARIO,
            "--device",
            DEVICE,
            "--duration",
            str(duration),
            "--seed",
            str(seed),
            "--device-name",
            NAME,
            "--connect",
            endpoint,
            "--mode",
            "client",
            "--wait",
            "60",
            "--start-time",
            "0",  # stamps from 0, as the reference below is encoded
        )
        procs.append(stream)
        stream.wait_for("publishing", 600)
        publishing = time.monotonic()
        while stream.proc.poll() is None:
            for p in procs:
                p.sample()
            if time.monotonic() - publishing > 3 * duration + 120:
                raise RuntimeError(f"the stream still runs after {3 * duration + 120:g} s:\n{stream.text()}")
            time.sleep(1.0)
        ended = time.monotonic()
        if stream.proc.returncode != 0:
            raise RuntimeError(f"the stream failed ({stream.proc.returncode}):\n{stream.text()}")
        time.sleep(2.0)  # the last messages reach the recorder
        rec_status = rec.stop()
        if rec_status != 0:
            raise RuntimeError(f"the recorder failed ({rec_status}):\n{rec.text()}")
        router_status = router.stop()
    finally:
        for p in procs:
            p.stop(30)
    ok, lines = check(folder, duration, seed)
    n = int(round(duration * 1000))
    pacing = [line for line in stream.text().splitlines() if "pacing" in line]
    print(
        f"soak: {SCENARIO} through {DEVICE} (seed {seed}), {len(TOPICS)} topics at 1 kHz for {duration:g} s: "
        f"stream -> router -> record, three processes on loopback ({endpoint})",
        file=out,
    )
    print(
        f"  published {n * len(TOPICS)} messages ({n} per topic); {ended - publishing:.1f} s from 'publishing' "
        f"to the stream's exit; whole run {time.monotonic() - started:.1f} s",
        file=out,
    )
    if pacing:
        print(f"  {pacing[0].strip()}", file=out)
    for p in procs:
        print(
            f"  {p.name:<7} CPU {p.cpu_s:8.1f} s ({100 * p.cpu_s / max(ended - publishing, 1e-9):5.1f} % of the "
            f"publishing time), peak memory {p.peak_mb:7.0f} MB",
            file=out,
        )
    print(f"  router exit status {router_status}", file=out)
    for line in lines:
        print(line, file=out)
    print(
        f"soak: {'PASS' if ok else 'FAIL'}: "
        f"{'no sample lost, none duplicated, bytes equal' if ok else 'see the lines marked FAIL'}",
        file=out,
    )
    return ok


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=600.0, help="seconds of 1 kHz stream (default 600)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the device (default 1)")
    parser.add_argument(
        "--keep",
        default=None,
        metavar="FOLDER",
        help="keep the recording, the report and the logs in FOLDER (default: a temporary folder)",
    )
    args = parser.parse_args(argv)
    if not args.duration > 0:
        parser.error(f"argument --duration: must be positive, got {args.duration}")
    if args.keep:
        folder = Path(args.keep)
        folder.mkdir(parents=True, exist_ok=True)
        return 0 if run(args.duration, args.seed, folder) else 1
    with tempfile.TemporaryDirectory(prefix="soak_") as tmp:
        return 0 if run(args.duration, args.seed, Path(tmp)) else 1


if __name__ == "__main__":
    sys.exit(main())
