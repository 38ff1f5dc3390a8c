"""Real ``gyroemu`` processes for the live-stream tests: free loopback ports, start, wait, stop, kill;
a zenoh listener in the test process, and the MCAP files the replay tests feed it.

Shared by ``tests/pipelines/test_zenoh.py``, ``test_replay.py``, ``test_ros2.py`` and
``test_router_restart.py``; the ``procs`` fixture kills every process it started when the test ends,
whatever happened.
"""

import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Procs:
    """Started subprocesses, output to files; all killed on exit."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name, *args):
        out = open(self.folder / f"{name}.log", "wb")
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.procs[name] = subprocess.Popen(
            [sys.executable, "-m", "gyroemu", *args], cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT
        )
        out.close()
        return self.procs[name]

    def log(self, name) -> str:
        return (self.folder / f"{name}.log").read_text(errors="replace")

    def wait_for(self, name, text, timeout=30.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in self.log(name):
                return
            if self.procs[name].poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f"{name} did not print {text!r} (exit {self.procs[name].poll()}):\n{self.log(name)}")

    def wait(self, name, timeout=60.0) -> int:
        try:
            return self.procs[name].wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{name} still running after {timeout} s:\n{self.log(name)}") from None

    def stop(self, name, sig=signal.SIGINT, timeout=30.0) -> int:
        self.procs[name].send_signal(sig)
        return self.wait(name, timeout)

    def kill_all(self):
        for p in self.procs.values():
            if p.poll() is None:
                p.kill()
        for p in self.procs.values():
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                pass


@pytest.fixture
def procs(tmp_path):
    p = Procs(tmp_path)
    try:
        yield p
    finally:
        p.kill_all()


class Listener:
    """An in-test zenoh peer listening on a free port (the process under test connects to it),
    collecting ``(key, payload, sequence, send stamp ns)`` of everything under ``key_expr``."""

    def __init__(self, key_expr="gyroemu/**"):
        from gyroemu.pipelines.transport.zenoh_io import open_session, session_config, subscribe

        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.session = open_session(session_config(listen=[self.endpoint], mode="peer"))
        self.sub = subscribe(self.session, key_expr, capacity=1 << 17)
        self.samples = []

    def drain(self):
        while (sample := self.sub.try_recv()) is not None:
            seq, stamp, _, _ = struct.unpack("<qqB16s", sample.attachment.to_bytes())
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes(), seq, stamp))
        return self.samples

    def close(self):
        self.session.close()


def mcap_messages(path, topic=None) -> list:
    """``(topic, log_time, payload)`` of a file's messages (of ``topic`` only, when given), in log-time
    order, as the mcap library reads them."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [
            (c.topic, m.log_time, m.data)
            for _, c, m in make_reader(f).iter_messages(topics=None if topic is None else [topic], log_time_order=True)
        ]


def write_foreign(path, n, seed=11) -> np.ndarray:
    """Someone else's bag (mcap_ros2's writer): /sensors/imu_raw at irregular 4-6 ms intervals, log
    times 2 ms after the stamps, and a String topic every 10th sample. Returns the Imu log times."""
    from mcap_ros2.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000 * 10**9 + np.cumsum(rng.integers(4_000_000, 6_000_000, n))
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=16384)
        imu = writer.register_msgdef(
            "sensor_msgs/msg/Imu",
            get_typestore(Stores.ROS2_HUMBLE)
            .generate_msgdef("sensor_msgs/msg/Imu")[0]
            .replace("time stamp", "builtin_interfaces/Time stamp")
            + "=" * 80
            + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        )
        text = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        for k in range(n):
            sec, nanosec = divmod(int(stamps[k]), 10**9)
            writer.write_message(
                "/sensors/imu_raw",
                imu,
                {
                    "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": "imu_link"},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": [-1.0] + [0.0] * 8,
                    "angular_velocity": dict(zip("xyz", rng.normal(size=3))),
                    "angular_velocity_covariance": [0.0] * 9,
                    "linear_acceleration": dict(zip("xyz", rng.normal(size=3))),
                    "linear_acceleration_covariance": [0.0] * 9,
                },
                log_time=int(stamps[k]) + 2_000_000,
            )
            if k % 10 == 0:
                writer.write_message("/rosout_text", text, {"data": f"sample {k}"}, log_time=int(stamps[k]) + 2_000_001)
        writer.finish()
    return stamps + 2_000_000
