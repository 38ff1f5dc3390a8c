"""Campaigns under faults, with real ``dask scheduler`` and ``dask worker`` processes on loopback.

- A worker killed with SIGKILL mid-campaign: its tasks run on the other worker, and the store ends with
  every (task, seed, filter) row exactly once.
- The scheduler killed mid-campaign: ``gyroemu bench`` ends with status 1 and says so; a new scheduler
  and the same command resume from the store (the tasks stored are not run again) and finish with
  every row exactly once.
- A cell that raises (a recorded motion asked for longer than it lasts) on the embedded local cluster:
  reported with its error, status 1, the other cells' rows all stored.
- ``gyroemu generate``: a log of the dataset equals, byte for byte, ``gyroemu simulate`` with the
  arguments of its index row (in-process: threads, no worker processes).

Every process started here is killed in teardown.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

pa = pytest.importorskip("pyarrow")
pytest.importorskip("distributed")

GRID = """
name = "faults"
scenarios = ["smooth_manoeuvre"]
devices = ["consumer_mems"]
durations_s = [3.0]
seed_range = {{ start = 0, count = {count} }}
filters = ["madgwick", "mahony"]
batched = false
seeds_per_task = 1
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Loopback:
    """A scheduler and workers as processes on 127.0.0.1; :meth:`close` kills them all."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.procs: list[subprocess.Popen] = []
        self.scheduler: subprocess.Popen | None = None
        self.address = ""

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen:
        log = open(self.tmp / f"{name}.log", "ab")  # noqa: SIM115 - closed with the process
        proc = subprocess.Popen([sys.executable, "-m", *args], stdout=log, stderr=subprocess.STDOUT)
        log.close()
        self.procs.append(proc)
        return proc

    def start_scheduler(self) -> str:
        port = _free_port()
        self.scheduler = self._spawn(
            ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            f"scheduler-{port}",
        )
        self.address = f"tcp://127.0.0.1:{port}"
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    return self.address
            assert self.scheduler.poll() is None, "the scheduler exited"
            time.sleep(0.1)
        raise AssertionError("the scheduler did not start in 30 s")

    def start_worker(self, name: str) -> subprocess.Popen:
        return self._spawn(
            [
                "distributed.cli.dask_worker",
                self.address,
                "--nthreads",
                "1",
                "--no-nanny",
                "--no-dashboard",
                "--name",
                name,
            ],
            name,
        )

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout=30) as client:
            client.wait_for_workers(n, timeout=60)

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
        for proc in self.procs:
            proc.wait(timeout=30)


@pytest.fixture
def loopback(tmp_path):
    cluster = Loopback(tmp_path)
    try:
        yield cluster
    finally:
        cluster.close()


def _gyroemu(*args: str, cwd: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "gyroemu", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _wait_for_parts(runs: Path, n: int, proc: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if runs.is_dir() and len(list(runs.glob("part-*.parquet"))) >= n:
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError(f"no {n} parts in {timeout} s")


def _rows(out: Path) -> list[tuple]:
    import pyarrow.dataset as ds

    table = ds.dataset(out / "runs").to_table()
    return [(r["task"], r["seed"], r["filter"]) for r in table.to_pylist()]


def _expect_all_once(out: Path, seeds: int) -> None:
    rows = _rows(out)
    assert len(rows) == len(set(rows)) == seeds * 2
    assert sorted({(s, f) for _, s, f in rows}) == sorted((s, f) for s in range(seeds) for f in ("madgwick", "mahony"))


def test_worker_killed_mid_campaign(tmp_path, loopback):
    seeds = 8
    spec = tmp_path / "c.toml"
    spec.write_text(GRID.format(count=seeds))
    address = loopback.start_scheduler()
    victim = loopback.start_worker("victim")
    loopback.start_worker("survivor")
    loopback.wait_for_workers(2)
    out = tmp_path / "out"
    proc = _gyroemu("bench", "--campaign", str(spec), "--scheduler", address, "--out", str(out), cwd=tmp_path)
    try:
        _wait_for_parts(out / "runs", 2, proc)
        victim.send_signal(signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert victim.wait(timeout=10) == -signal.SIGKILL
    _expect_all_once(out, seeds)
    assert f"{seeds} task(s) run, 0 found in the store, 0 failed" in stdout


def test_scheduler_lost_then_resumed(tmp_path, loopback):
    seeds = 6
    spec = tmp_path / "c.toml"
    spec.write_text(GRID.format(count=seeds))
    address = loopback.start_scheduler()
    loopback.start_worker("w1")
    loopback.wait_for_workers(1)
    out = tmp_path / "out"
    proc = _gyroemu("bench", "--campaign", str(spec), "--scheduler", address, "--out", str(out), cwd=tmp_path)
    try:
        _wait_for_parts(out / "runs", 1, proc)
        assert loopback.scheduler is not None
        loopback.scheduler.kill()
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1
    assert "lost the Dask scheduler" in stderr and "run again to resume" in stderr
    stored = len(list((out / "runs").glob("part-*.parquet")))
    assert 1 <= stored < seeds
    assert len(_rows(out)) == 2 * stored

    address = loopback.start_scheduler()
    loopback.start_worker("w2")
    loopback.wait_for_workers(1)
    proc = _gyroemu("bench", "--campaign", str(spec), "--scheduler", address, "--out", str(out), cwd=tmp_path)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert f"{seeds - stored} task(s) run, {stored} found in the store, 0 failed" in stdout
    _expect_all_once(out, seeds)


def test_failing_cell_on_the_local_cluster(tmp_path):
    spec = tmp_path / "c.toml"
    # recorded_motion lasts 15 s: its 16 s cell raises in the task; smooth_manoeuvre's runs.
    spec.write_text(
        GRID.format(count=2)
        .replace('["smooth_manoeuvre"]', '["smooth_manoeuvre", "recorded_motion"]')
        .replace("[3.0]", "[16.0]")
        .replace('["madgwick", "mahony"]', '["madgwick"]')
        .replace("seeds_per_task = 1", "seeds_per_task = 2")
    )
    out = tmp_path / "out"
    proc = _gyroemu("bench", "--campaign", str(spec), "--workers", "2", "--out", str(out), cwd=tmp_path)
    try:
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, stderr
    assert "recorded_motion" in stderr and "15 s" in stderr
    assert "1 task(s) run, 0 found in the store, 1 failed" in stdout
    rows = _rows(out)
    assert sorted((s, f) for _, s, f in rows) == [(0, "madgwick"), (1, "madgwick")]
    md = (out / "bench.md").read_text()
    assert "Failed cells" in md and "recorded_motion" in md


def test_generated_log_equals_simulate(tmp_path):
    """In-process (a threads-only cluster): the bytes, not the processes, are what is held here."""
    import hashlib

    import pyarrow.parquet as pq

    from gyroemu.pipelines import cli
    from gyroemu.pipelines.formats.mcap_log import read_mcap
    from gyroemu.pipelines.jobs.generate import GenerateOptions, run_generate

    spec = tmp_path / "c.toml"
    spec.write_text(GRID.format(count=2).replace("[3.0]", "[1.0]"))
    out = tmp_path / "data"
    summary = run_generate(GenerateOptions(spec=spec, out_dir=out, workers=2, processes=False))
    assert (summary.made, summary.resumed, summary.failures) == (2, 0, [])
    index = pq.read_table(out / "index.parquet").to_pylist()
    assert [(r["seed"], r["duration_s"]) for r in index] == [(0, 1.0), (1, 1.0)]
    row = index[1]
    again = tmp_path / "again.mcap"
    args = ["--scenario", row["scenario"], "--device", row["device"], "--duration", str(row["duration_s"])]
    assert cli.main(["simulate", *args, "--seed", str(row["seed"]), "--out", str(again)]) == 0
    assert (out / row["file"]).read_bytes() == again.read_bytes()
    assert hashlib.sha256(again.read_bytes()).hexdigest() == row["sha256"]
    (meta,) = read_mcap(out / row["file"]).metadata  # the log carries its configs and seed
    assert meta["seed"] == "1" and "random-manoeuvre" in meta["scenario"] and "rate_hz" in meta["device"]
    # Started again: nothing to make, the same index.
    again_summary = run_generate(GenerateOptions(spec=spec, out_dir=out, workers=2, processes=False))
    assert (again_summary.made, again_summary.resumed) == (0, 2)
    assert pq.read_table(out / "index.parquet").to_pylist() == index
