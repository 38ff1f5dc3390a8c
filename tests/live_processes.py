"""Real ``gyroemu`` processes for the live-stream tests: free loopback ports, start, wait, stop, kill.

Shared by ``tests/pipelines/test_zenoh.py``, ``test_replay.py`` and ``test_router_restart.py``; the
``procs`` fixture kills every process it started when the test ends, whatever happened.
"""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

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
        self.procs[name] = subprocess.Popen([sys.executable, "-m", "pipelines.cli", *args], cwd=ROOT, env=env,
                                            stdout=out, stderr=subprocess.STDOUT)
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
