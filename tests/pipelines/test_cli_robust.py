"""The command line holds up: bad numbers, outputs that would overwrite or not fit, and interruptions.

The contract: exit 2 on bad usage or bad input, before any work, with a message naming the argument;
130 or 143 when stopped by SIGINT or SIGTERM, with the partial file removed and no traceback; no
command overwrites an existing file without ``--force``.
"""

import errno
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import types

import numpy as np
import pytest
from cli_runs import run_cli
from live_processes import free_port
from zenoh_samples import Sample

from gyroemu.pipelines.formats.frames import SIMULATE_EPOCH_NS
from gyroemu.pipelines.jobs.simulate import SimulateError, SimulateOptions, check_options


def gyroemu(*args, **kwargs):
    return subprocess.run([sys.executable, "-m", "gyroemu", *args], capture_output=True, text=True, **kwargs)


# ---------------------------------------------------------------------------------------------------
# Bad numbers and outputs: exit 2 before any work, the argument named.


@pytest.mark.parametrize(
    "options, named",
    [
        (["--duration", "1e12"], "argument --duration: 1e+12 s is more than the limit"),
        (["--duration", "inf"], "argument --duration: must be a finite number"),
        (["--duration", "nan"], "argument --duration: must be a finite number"),
        (["--duration", "-3"], "argument --duration: must be positive"),
        (["--duration", "0"], "argument --duration: must be positive"),
        (["--duration", "ten"], "argument --duration: expected a number"),
        (["--rate", "1e9"], "argument --rate: 1e+09 Hz is more than the limit"),
        (["--rate", "inf"], "argument --rate: must be a finite number"),
        (["--seed", "-1"], "argument --seed: must be an integer from 0 to 2**128 - 1"),
        (["--seed", str(2**128)], "argument --seed: must be an integer from 0 to 2**128 - 1"),
        (["--seed", "1.5"], "argument --seed: invalid int value"),
    ],
)
def test_simulate_refuses_bad_numbers(tmp_path, options, named):
    code, _, stderr = run_cli(["simulate", "--scenario", "heavy_top", *options, "--out", str(tmp_path / "t.npz")])
    assert code == 2 and named in stderr, stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["stream", "bench"])
@pytest.mark.parametrize(
    "options, named",
    [
        (["--duration", "inf"], "argument --duration: must be a finite number"),
        (["--duration", "1e12"], "argument --duration: 1e+12 s is more than the limit"),
        (["--seed", "-1"], "argument --seed: must be an integer from 0 to 2**128 - 1"),
    ],
)
def test_stream_and_bench_refuse_bad_numbers(tmp_path, command, options, named):
    argv = [command, *options]
    if command == "stream":
        argv += ["--scenario", "heavy_top", "--device", "consumer_mems"]
    else:
        argv += ["--out", str(tmp_path / "bench")]
    code, _, stderr = run_cli(argv)
    assert code == 2 and named in stderr, stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["offline-vqf", "mekf-smooth"])
def test_stream_refuses_an_offline_live_estimate_before_streaming(name):
    """An offline filter cannot run on a live stream: refused by name before anything is streamed (it
    streamed, then a thread's traceback, then an error blaming the endpoints)."""
    code, stdout, stderr = run_cli(
        ["stream", "--scenario", "heavy_top", "--device", "consumer_mems", "--estimate", name]
    )
    assert code == 2 and f"argument --estimate: {name} is offline (it needs the whole log)" in stderr, stderr
    assert stdout == "" and "Traceback" not in stderr


@pytest.mark.parametrize(
    "values, named",
    [
        (["gyro=nan"], "argument --latency: gyro: must be a finite number of milliseconds under 1000 either way"),
        (["mag=1000"], "argument --latency: mag: must be a finite number of milliseconds under 1000 either way"),
        (["gyro=4 ms"], "argument --latency: gyro: expected a number of milliseconds, got '4 ms'"),
        (["4"], "argument --latency: expected SENSOR=MS with SENSOR one of gyro, mag, got '4'"),
        (["gps=4"], "argument --latency: expected SENSOR=MS with SENSOR one of gyro, mag, got 'gps=4'"),
        (["gyro=2", "gyro=3"], "argument --latency: gyro given twice"),
        (["mag=auto", "mag=3"], "argument --latency: mag given twice"),
        (["gyro=auto"], "argument --latency: gyro=auto: only the magnetometer's lag behind the gyro can be read"),
    ],
)
def test_estimate_refuses_a_bad_latency(tmp_path, values, named):
    source = tmp_path / "in.mcap"
    source.write_bytes(b"an input")
    argv = ["estimate", str(source), "--out", str(tmp_path / "o.mcap")]
    for value in values:
        argv += ["--latency", value]
    code, _, stderr = run_cli(argv)
    assert code == 2 and named in stderr, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.mcap"]


def test_record_refuses_a_bad_duration(tmp_path):
    code, _, stderr = run_cli(["record", "--out", str(tmp_path / "r.mcap"), "--duration", "nan"])
    assert code == 2 and "argument --duration: must be a finite number" in stderr, stderr


@pytest.mark.parametrize(
    "out, named",
    [
        ("folder", "argument --out: {tmp}/folder is a folder"),
        ("folder.npz", "argument --out: {tmp}/folder.npz is a folder"),
        ("missing/t.npz", "argument --out: {tmp}/missing: no such folder"),
        ("t.csv", "argument --out: {tmp}/t.csv: write a .mcap (ROS 2) or .npz file"),
    ],
)
def test_simulate_refuses_an_out_it_cannot_write(tmp_path, out, named):
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder.npz").mkdir()
    code, _, stderr = run_cli(["simulate", "--scenario", "heavy_top", "--out", str(tmp_path / out)])
    assert code == 2 and named.format(tmp=tmp_path) in stderr, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "folder.npz"]


@pytest.mark.parametrize("suffix", [".mcap", ".npz"])
def test_simulate_refuses_a_read_only_out_folder_before_work(tmp_path, monkeypatch, suffix):
    """A folder that cannot take the output (a read-only mount refuses even root, which a test cannot
    make: folder_problem is told so) is refused naming --out, before any work, not as an OSError at the end."""
    import gyroemu.pipelines.formats.atomic as atomic

    locked = tmp_path / "ro"
    locked.mkdir()
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if f == locked else None)
    argv = ["simulate", "--scenario", "heavy_top", "--device", "consumer_mems", "--duration", "1"]
    code, _, stderr = run_cli([*argv, "--out", str(locked / f"b{suffix}")])
    assert code == 2 and f"argument --out: {locked}: read-only file system" in stderr, stderr
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize(
    "options",
    [
        ["--duration", "5", "--start-time", "2038-01-19T03:14:06Z"],
        ["--start-time", "2038-01-19T03:10:00Z"],  # the scenario's own 300 s
    ],
)
def test_simulate_refuses_a_run_ending_beyond_ros_time_before_work(tmp_path, options):
    """The start is within ROS time's int32 seconds, its end is not: refused naming --start-time, not a
    ValueError from the writer mid-run."""
    argv = ["simulate", "--scenario", "smooth_manoeuvre", "--device", "consumer_mems", *options]
    code, _, stderr = run_cli([*argv, "--out", str(tmp_path / "c.mcap")])
    assert code == 2 and "argument --start-time: 2038-01-19T03:1" in stderr and "int32" in stderr, stderr
    assert list(tmp_path.iterdir()) == []
    fits = SimulateOptions(
        scenario="smooth_manoeuvre",
        device="consumer_mems",
        out=tmp_path / "c.mcap",
        duration=5.0,
        start_time="2038-01-19T03:14:00Z",
    )
    check_options(fits)
    device = tmp_path / "late.toml"  # the device's clock offset carries the stamps past it
    device.write_text('description = "x"\nrate_hz = 100\n\n[clock]\noffset_s = 1e12\n')
    code, _, stderr = run_cli(
        [*argv[:3], "--device", str(device), "--duration", "5", "--out", str(tmp_path / "c.mcap")]
    )
    assert code == 2 and f"{device}: key 'clock.offset_s'" in stderr, stderr


def test_a_clock_that_runs_behind_writes_its_stamps_before_the_start(tmp_path):
    """A device clock 0.5 s behind stamps its samples before ``--start-time``: valid ROS times, written
    (the writer refused stamps before the run's start, a traceback after the work); only stamps before
    1970 cannot be log times, refused before any work naming ``clock.offset_s``."""
    from mcap.reader import make_reader

    device = tmp_path / "behind.toml"
    device.write_text('description = "x"\nrate_hz = 100\n\n[clock]\noffset_s = -0.5\n')
    argv = ["simulate", "--scenario", "bench_static", "--device", str(device), "--duration", "2"]
    code, _, stderr = run_cli([*argv, "--start-time", "2025-01-01T00:00:00Z", "--out", str(tmp_path / "b.mcap")])
    assert code == 0, stderr
    with open(tmp_path / "b.mcap", "rb") as f:
        first = min(m.log_time for _, c, m in make_reader(f).iter_messages(topics=["/imu"]))
    assert first == SIMULATE_EPOCH_NS - 500_000_000 + 10_000_000  # the first sample, 10 ms in, 0.5 s early
    code, _, stderr = run_cli([*argv, "--start-time", "0", "--out", str(tmp_path / "c.mcap")])
    assert code == 2 and f"{device}: key 'clock.offset_s'" in stderr and "1970" in stderr, stderr
    assert not (tmp_path / "c.mcap").exists()


def test_simulate_names_the_argument_or_key_at_fault(tmp_path):
    """The argument or key that is wrong, not another: --rate too low for two truth samples (not the
    device's 'duration'), a device's absurd rate_hz (not --duration), a folder for a config (not 'no
    such file')."""
    device = tmp_path / "fast.toml"
    device.write_text('description = "x"\nrate_hz = 1e9\n')
    (tmp_path / "configs").mkdir()
    cases = [
        (["--device", "consumer_mems", "--rate", "0.1", "--duration", "5"], "argument --rate: 5 s at 0.1 Hz"),
        (["--device", str(device), "--duration", "5"], f"{device}: key 'rate_hz': 1e+09 is more than the limit"),
        (["--device", str(tmp_path / "configs")], f"{tmp_path}/configs: is a folder, not a device file"),
    ]
    for options, named in cases:
        code, _, stderr = run_cli(
            ["simulate", "--scenario", "smooth_manoeuvre", *options, "--out", str(tmp_path / "a.mcap")]
        )
        assert code == 2 and named in stderr, stderr
    code, _, stderr = run_cli(["simulate", "--scenario", str(tmp_path / "configs"), "--out", str(tmp_path / "a.npz")])
    assert code == 2 and f"{tmp_path}/configs: is a folder, not a scenario file" in stderr, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["configs", "fast.toml"]


@pytest.mark.parametrize(
    "change, named",
    [
        ({"duration": float("nan")}, "argument --duration: must be a finite number of s, got nan"),
        ({"duration": float("inf")}, "argument --duration: must be a finite number of s, got inf"),
        ({"duration": 1e12}, "argument --duration: 1e+12 s is more than the limit"),
        ({"duration": -1.0}, "argument --duration: must be positive"),
        ({"duration": "10"}, "argument --duration: expected a number of s"),
        ({"rate": 1e9}, "argument --rate: 1e+09 Hz is more than the limit"),
        ({"rate": 0}, "argument --rate: must be positive"),
        ({"seed": -1}, "argument --seed: must be an integer from 0 to 2**128 - 1, got -1"),
        ({"seed": 2**128}, "argument --seed: must be an integer"),
        ({"seed": 1.0}, "argument --seed: must be an integer"),
        ({"seed": True}, "argument --seed: must be an integer"),
    ],
)
def test_check_options_refuses_bad_numbers_from_python(tmp_path, change, named):
    options = SimulateOptions(scenario="heavy_top", out=tmp_path / "t.npz", **change)
    with pytest.raises(SimulateError) as e:
        check_options(options)
    assert named in str(e.value)


def test_check_options_accepts_good_numbers(tmp_path):
    check_options(
        SimulateOptions(scenario="heavy_top", out=tmp_path / "t.npz", duration=2, rate=500.0, seed=2**128 - 1)
    )


def test_simulate_mcap_larger_than_the_free_disk_is_refused(tmp_path, monkeypatch):
    free = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: free._replace(free=50_000_000))
    argv = ["simulate", "--scenario", "bench_static", "--device", "consumer_mems", "--duration", "3600"]
    code, _, stderr = run_cli([*argv, "--out", str(tmp_path / "run.mcap")])
    assert code == 2, stderr
    assert "argument --duration: 3600 s needs about" in stderr and "of disk" in stderr
    assert "50 MB free" in stderr and "shorten --duration" in stderr
    assert list(tmp_path.iterdir()) == []
    code, _, stderr = run_cli([*argv[:-1], "10", "--out", str(tmp_path / "run.mcap")])  # 10 s fits in 50 MB
    assert code == 0, stderr


def test_simulate_npz_larger_than_the_memory_is_refused(tmp_path, monkeypatch):
    sysconf = os.sysconf
    monkeypatch.setattr(os, "sysconf", lambda name: 1000 if name == "SC_PHYS_PAGES" else sysconf(name))
    memory = 1000 * sysconf("SC_PAGE_SIZE")
    code, _, stderr = run_cli(["simulate", "--scenario", "heavy_top", "--out", str(tmp_path / "t.npz")])
    assert code == 2, stderr
    assert "argument --duration: 60 s needs about" in stderr and "of memory" in stderr
    assert f"this machine's {memory / 1e6:.3g} MB" in stderr and "lower --rate" in stderr and ".mcap" in stderr
    assert list(tmp_path.iterdir()) == []


def _estimate_need(log, smooth: bool) -> int:
    """What ``check_disk`` counts for a gyroemu log of one device: the log's size, an ``/estimate/imu``
    message (in ``base_link``) and its record per sample, and with ``smooth`` the smoother's files."""
    from gyroemu.pipelines.estimation.mekf import MekfParams
    from gyroemu.pipelines.estimation.mekf_smoother_spool import spool_bytes
    from gyroemu.pipelines.formats.channels import BODY_FRAME
    from gyroemu.pipelines.formats.mcap_log import read_mcap
    from gyroemu.pipelines.formats.messages import IMU
    from gyroemu.pipelines.jobs.disk_space import MCAP_RECORD_OVERHEAD

    samples = next(iter(read_mcap(log).devices.values())).samples
    n, duration = len(samples), len(samples) / 1000.0  # consumer_mems at 1 kHz
    need = log.stat().st_size + n * (IMU.message_size(BODY_FRAME) + MCAP_RECORD_OVERHEAD)
    return need + (spool_bytes(n, duration, MekfParams().window_s) if smooth else 0)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """Two seconds of the consumer MEMS at 1 kHz."""
    log = tmp_path_factory.mktemp("small") / "in.mcap"
    argv = ["--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "2", "--out", str(log)]
    code, _, stderr = run_cli(["simulate", *argv])
    assert code == 0, stderr
    return log


@pytest.mark.parametrize("smooth", [False, True])
def test_estimate_larger_than_the_free_disk_is_refused(tmp_path, monkeypatch, small_log, smooth):
    """``estimate`` counts its output (the log's copy, an estimate a sample) and the smoother's files
    and refuses, before any work and naming ``--out``, a folder with a byte less free; with exactly that
    it runs, and what it wrote is no more than it counted (the estimates counted before compression)."""
    need = _estimate_need(small_log, smooth)
    usage = shutil.disk_usage(tmp_path)
    out = tmp_path / "out.mcap"
    argv = ["estimate", str(small_log), "--out", str(out)] + (["--smooth"] if smooth else [])
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=need - 1))
    code, _, stderr = run_cli(argv)
    assert code == 2, stderr
    assert f"argument --out: the estimate needs about {need / 1e6:.3g} MB of disk" in stderr, stderr
    assert ("the smoother's temporary files" in stderr) == smooth and "write to another folder" in stderr
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=need))
    code, _, stderr = run_cli(argv)
    assert code == 0, stderr
    assert [p.name for p in tmp_path.iterdir()] == ["out.mcap"] and out.stat().st_size <= need


class _FillsUp:
    """A binary file that takes ``room`` bytes, then refuses as a full disk does (ENOSPC)."""

    def __init__(self, f, room: int) -> None:
        self.f, self.room = f, room

    def write(self, data) -> int:
        n = memoryview(data).nbytes
        if n > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= n
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


@pytest.mark.parametrize("where", ["output", "smoother files"])
def test_a_disk_that_fills_while_estimate_writes_ends_it_in_one_line(tmp_path, monkeypatch, small_log, where):
    """A disk that fills all the same (another writer, a size under-estimated): exit 1, one line naming
    the output, no traceback, nothing left in the folder. The output's writer (or the smoother's
    temporary files) given a file that fills after 100 kB."""
    import tempfile

    from gyroemu.pipelines.estimation import mekf_smoother_spool
    from gyroemu.pipelines.jobs import estimate_copy

    if where == "output":
        writer = estimate_copy.McapFileWriter
        monkeypatch.setattr(estimate_copy, "McapFileWriter", lambda f, **kw: writer(_FillsUp(f, 100_000), **kw))
    else:
        spool_tempfile = types.SimpleNamespace(
            TemporaryFile=lambda **kw: _FillsUp(tempfile.TemporaryFile(**kw), 100_000)
        )
        monkeypatch.setattr(mekf_smoother_spool, "tempfile", spool_tempfile)
    out = tmp_path / "out.mcap"
    code, stdout, stderr = run_cli(["estimate", str(small_log), "--out", str(out), "--smooth"])
    assert code == 1, stderr
    assert stderr == (
        f"gyroemu estimate: error: {os.strerror(errno.ENOSPC)} writing {out}: stopped; an output written through "
        "a temporary file is removed, a recording keeps what it wrote (its complete chunks read back). Free "
        "some space, or write to another folder\n"
    )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("code, status", [(errno.ENOSPC, 1), (errno.EDQUOT, 1), (errno.EACCES, 2)])
def test_import_full_disk_is_not_the_arguments_fault(tmp_path, monkeypatch, code, status):
    """``import`` names ``--out`` (status 2) for an output it may not write, but a full disk or quota is
    not the argument's fault: status 1, as for every command."""
    from gyroemu.pipelines.formats import importers

    def write_fails(source, out, force=False):
        raise OSError(code, os.strerror(code), str(out))

    monkeypatch.setitem(importers.IMPORTERS, "broad", write_fails)
    out = tmp_path / "out.mcap"
    got, _, stderr = run_cli(["import", "broad", str(tmp_path / "in.hdf5"), "--out", str(out)])
    assert got == status, stderr
    said = f"argument --out: {out}: " if status == 2 else "stopped; an output written through a temporary file"
    assert said in stderr and os.strerror(code) in stderr and "Traceback" not in stderr


def test_another_os_error_is_not_taken_for_a_full_disk(monkeypatch, small_log, tmp_path):
    """Only ENOSPC and EDQUOT are a full disk: any other OSError still raises (a bug shows its traceback)."""
    from gyroemu.pipelines.jobs import estimate_copy

    def refuse(*args, **kwargs):
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    monkeypatch.setattr(estimate_copy, "McapFileWriter", refuse)
    with pytest.raises(OSError, match=os.strerror(errno.EIO)):
        run_cli(["estimate", str(small_log), "--out", str(tmp_path / "out.mcap")])
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------------
# Other people's files: --force, or exit 2 naming --out and --force.


def test_simulate_overwrites_only_with_force(tmp_path):
    out = tmp_path / "t.npz"
    out.write_bytes(b"someone's file")
    argv = ["simulate", "--scenario", "heavy_top", "--duration", "0.05", "--out", str(out)]
    code, _, stderr = run_cli(argv)
    assert code == 2 and f"argument --out: {out} exists (use --force to overwrite it)" in stderr, stderr
    assert out.read_bytes() == b"someone's file"
    code, _, stderr = run_cli([*argv, "--force"])
    assert code == 0, stderr
    assert out.read_bytes()[:2] == b"PK"  # the .npz (a zip) replaced it
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]


@pytest.mark.parametrize("command", ["import", "estimate", "record"])
def test_import_estimate_record_refuse_an_existing_out(tmp_path, command):
    source = tmp_path / "in.hdf5"
    source.write_bytes(b"an input")  # refused before any reading: the input's content does not matter
    out = tmp_path / "out.mcap"
    out.write_bytes(b"someone's log")
    argv = {
        "import": ["import", "broad", str(source), "--out", str(out)],
        "estimate": ["estimate", str(source), "--out", str(out)],
        "record": ["record", "--out", str(out), "--duration", "1"],
    }[command]
    code, _, stderr = run_cli(argv)
    assert code == 2, stderr
    assert f"argument --out: {out}" in stderr and "exists" in stderr and "--force" in stderr, stderr
    assert out.read_bytes() == b"someone's log" and source.read_bytes() == b"an input"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.hdf5", "out.mcap"]


@pytest.mark.parametrize(
    "command, argument, output",
    [
        ("simulate", "--out", "user.npz"),
        ("estimate", "--out", "user.mcap"),
        ("estimate", "--plot", "e.estimate.png"),
        ("info", "--plot", "in.info.png"),
        ("allan", "--out", "user.png"),
        ("allan", "--out (default: LOG with .allan.png)", "in.allan.png"),
        ("allan", "--kalibr", "user.yaml"),
        ("identify", "--out", "user.toml"),
        ("identify", "--site-out", "user.toml"),
        ("import", "--out", "user.mcap"),
        ("record", "--out", "user.mcap"),
        ("record", "--report", "user.json"),
    ],
)
def test_every_command_says_an_existing_output_alike(tmp_path, no_session, command, argument, output):
    """One check of an output file (``formats.atomic.output_file_problem``), one wording: someone's file is
    refused before any work, naming the option, the file and --force (``allan`` said "pass --force")."""
    source = tmp_path / ("in.hdf5" if command == "import" else "in.mcap")
    source.write_bytes(b"an input")  # refused before any reading: the input's content does not matter
    user = tmp_path / output
    user.write_bytes(b"someone's file")
    fresh = str(tmp_path / "fresh")
    argv = {
        "simulate": ["simulate", "--scenario", "heavy_top", "--out", str(user)],
        "estimate": ["estimate", str(source), "--out", str(user if argument == "--out" else tmp_path / "e.mcap")],
        "info": ["info", str(source)],
        "allan": ["allan", str(source)],
        "identify": ["identify", str(source), "--out", str(user if argument == "--out" else f"{fresh}.toml")],
        "import": ["import", "broad", str(source), "--out", str(user)],
        "record": ["record", "--out", str(user if argument == "--out" else f"{fresh}.mcap"), "--duration", "1"],
    }[command]
    argv += {"--plot": ["--plot"], "--kalibr": ["--kalibr", str(user)], "--site-out": ["--site-out", str(user)]}.get(
        argument, ["--out", str(user)] if argument == "--out" and command == "allan" else []
    )
    argv += ["--report", str(user)] if argument == "--report" else []
    code, stdout, stderr = run_cli(argv)
    assert code == 2, stderr
    assert f"gyroemu {command}: error: argument {argument}: {user} exists (use --force to overwrite it)\n" == stderr
    assert stdout == "" and user.read_bytes() == b"someone's file" and source.read_bytes() == b"an input"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({source.name, user.name})


@pytest.mark.parametrize("command", ["import", "record"])
def test_import_and_record_refuse_a_folder_as_out(tmp_path, command):
    source = tmp_path / "in.hdf5"
    source.write_bytes(b"an input")
    out = tmp_path / "out.mcap"
    out.mkdir()
    argv = {
        "import": ["import", "broad", str(source), "--out", str(out), "--force"],
        "record": ["record", "--out", str(out), "--duration", "1", "--force"],
    }[command]
    code, _, stderr = run_cli(argv)
    assert code == 2 and f"argument --out: {out}" in stderr and "is a folder" in stderr, stderr
    assert list(out.iterdir()) == []


@pytest.fixture
def no_session(monkeypatch):
    """The live jobs may not open a zenoh session: their bad options are refused before any work."""
    from gyroemu.pipelines.transport import record, replay, stream

    def refuse(*args, **kwargs):
        raise AssertionError("a zenoh session was opened before the options were checked")

    for module in (record, replay, stream):
        monkeypatch.setattr(module, "open_session", refuse)


@pytest.mark.parametrize(
    "report, force, named",
    [
        ("user.mcap", False, "argument --report: {tmp}/user.mcap exists (use --force to overwrite it)"),
        ("r.mcap", False, "argument --report: {tmp}/r.mcap is the --out file"),
        ("r.mcap", True, "argument --report: {tmp}/r.mcap is the --out file"),
        ("./r.mcap", True, "argument --report: {tmp}/r.mcap is the --out file"),
        ("missing/x.json", False, "argument --report: {tmp}/missing: no such folder"),
        ("folder", True, "argument --report: {tmp}/folder is a folder"),
        ("user.mcap/x.json", False, "argument --report: {tmp}/user.mcap: not a folder"),
    ],
)
def test_record_checks_its_report_like_its_out_before_any_work(tmp_path, no_session, report, force, named):
    """--report is an output as --out is: someone's file is not replaced without --force (it was, by the
    JSON report, with "no file written" said), nor is --out's, and a missing folder or a folder is named
    as --report before recording (it was found after, and blamed on --out)."""
    (tmp_path / "user.mcap").write_bytes(b"someone's log")
    (tmp_path / "folder").mkdir()
    out = tmp_path / "r.mcap"
    argv = ["record", "--out", str(out), "--duration", "1", "--report", f"{tmp_path}/{report}"]
    code, _, stderr = run_cli([*argv, *(["--force"] if force else [])])
    assert code == 2 and named.format(tmp=tmp_path) in stderr, stderr
    assert (tmp_path / "user.mcap").read_bytes() == b"someone's log"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "user.mcap"]


def test_record_report_over_a_file_needs_force(tmp_path):
    from gyroemu.pipelines.transport.record import RecordError, RecordOptions, check_record_options

    (tmp_path / "old.json").write_text("{}")
    options = RecordOptions(tmp_path / "r.mcap", report_path=tmp_path / "old.json")
    with pytest.raises(RecordError, match="argument --report: .*old.json exists"):
        check_record_options(options)
    check_record_options(RecordOptions(tmp_path / "r.mcap", report_path=tmp_path / "old.json", force=True))


@pytest.mark.parametrize("out", ["r.txt", "r", "r.mcap.json"])
def test_record_refuses_an_out_that_is_no_mcap_name(tmp_path, no_session, out):
    """record writes MCAP: another suffix is refused as simulate refuses it."""
    code, _, stderr = run_cli(["record", "--out", str(tmp_path / out), "--duration", "1"])
    assert code == 2 and f"argument --out: {tmp_path / out}: record writes an MCAP log" in stderr, stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("which", ["--out", "--report"])
def test_record_refuses_a_read_only_folder_before_work(tmp_path, monkeypatch, no_session, which):
    """A read-only mount (which refuses even root; a test cannot make one, so folder_problem is told so)
    is refused naming the option, before any session or recording (it recorded, then wrote nothing)."""
    import gyroemu.pipelines.formats.atomic as atomic

    locked = tmp_path / "ro"
    locked.mkdir()
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if f == locked else None)
    out, report = (
        (locked / "r.mcap", tmp_path / "r.json") if which == "--out" else (tmp_path / "r.mcap", locked / "r.json")
    )
    code, _, stderr = run_cli(["record", "--out", str(out), "--report", str(report), "--duration", "1"])
    assert code == 2 and f"argument {which}: {locked}: read-only file system" in stderr, stderr
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize(
    "key, named",
    [
        ("a//b", "argument --key: Invalid Key Expr `a//b`: empty chunks are forbidden"),
        ("", "argument --key: empty: name a key expression"),
        ("gyroemu/imu0#", "argument --key: Invalid Key Expr `gyroemu/imu0#`: `#` and `?` are forbidden"),
        ("gyroemu/**/**", "(write gyroemu/**)"),
    ],
)
def test_record_refuses_a_bad_key_before_any_work(tmp_path, no_session, key, named):
    """A key zenoh refuses was a zenoh.ZError traceback (exit 1) once the session was open; an empty one
    silently became gyroemu/**."""
    code, _, stderr = run_cli(["record", "--out", str(tmp_path / "r.mcap"), "--duration", "1", "--key", key])
    assert code == 2 and named in stderr and "Traceback" not in stderr, stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["stream", "replay"])
@pytest.mark.parametrize("wait", ["1e300", "inf", "nan", "-1", "86401"])
def test_stream_and_replay_refuse_a_bad_wait(tmp_path, no_session, command, wait):
    """--wait 1e300 blocked for ever; -1 and nan were taken. 0 to a day (MAX_WAIT_S) is."""
    argv = {
        "stream": ["stream", "--scenario", "heavy_top", "--device", "consumer_mems", "--duration", "1"],
        "replay": ["replay", str(tmp_path / "never-read.mcap")],
    }[command]
    code, _, stderr = run_cli([*argv, f"--wait={wait}"])
    assert code == 2 and "argument --wait: must be a number of seconds from 0 (no wait) to 86400" in stderr, stderr


def test_check_pacing_options_takes_0_to_a_day():
    from gyroemu.pipelines.transport.zenoh_io import MAX_WAIT_S, LiveOptionError, PacingOptions, check_pacing_options

    for good in (0, 0.0, 10.0, MAX_WAIT_S):
        check_pacing_options(PacingOptions(wait_s=good))
    for bad in (-0.001, MAX_WAIT_S * 1.001, float("nan"), float("inf"), True, "10"):
        with pytest.raises(LiveOptionError, match="argument --wait"):
            check_pacing_options(PacingOptions(wait_s=bad))


def test_recorder_that_records_nothing_leaves_no_file(tmp_path):
    from gyroemu.pipelines.transport.record import Recorder

    recorder = Recorder(tmp_path / "r.mcap")
    assert not (tmp_path / "r.mcap").exists()  # made with the first channel
    recorder.close()
    assert not recorder.written and list(tmp_path.iterdir()) == []


def test_record_receiving_nothing_says_so_and_keeps_the_old_file(tmp_path):
    """With --force over an existing file, nothing received: the file stays as it was."""
    out = tmp_path / "r.mcap"
    out.write_bytes(b"an older recording")
    port = free_port()
    key = f"gyroemu/robust{os.getpid()}x{port}/**"  # nobody publishes there
    result = gyroemu(
        "record", "--out", str(out), "--force", "--duration", "0.5", "--key", key, "--listen", f"tcp/127.0.0.1:{port}",
        timeout=60,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert f"record: nothing received on {key}: no file written" in result.stdout, result.stdout
    assert out.read_bytes() == b"an older recording"
    assert [p.name for p in tmp_path.iterdir()] == ["r.mcap"]


def test_record_receiving_nothing_reports_no_file(tmp_path):
    """--report of a recording that received nothing: written (the outcome a script waits for), saying
    no log was written ("file": null, 0 messages); it named the .mcap that does not exist. In process,
    on a loopback endpoint."""
    import io
    import json

    from gyroemu.pipelines.transport.record import RecordOptions, run_record
    from gyroemu.pipelines.transport.zenoh_io import SessionOptions

    port = free_port()
    options = RecordOptions(
        out_path=tmp_path / "r.mcap",
        duration=0.3,
        key_expr=f"gyroemu/robust{os.getpid()}x{port}/**",  # nobody publishes there
        report_path=tmp_path / "r.json",
        session=SessionOptions(listen=(f"tcp/127.0.0.1:{port}",)),
    )
    printed = io.StringIO()
    assert run_record(options, out=printed) == 0
    assert "no file written" in printed.getvalue(), printed.getvalue()
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["file"] is None and report["messages"] == 0 and report["publishers"] == {}, report


def test_stream_names_duration_longer_than_its_recording(no_session):
    """A --duration past a recorded motion's end is --duration's fault (it was blamed on --connect/--listen),
    found before any simulation or session."""
    argv = ["stream", "--scenario", "recorded_motion", "--device", "consumer_mems", "--duration", "1000", "--wait", "0"]
    code, _, stderr = run_cli(argv)
    assert code == 2 and "argument --duration: 1000 s is longer than the recording's 15 s" in stderr, stderr


@pytest.mark.parametrize(
    "options, named",
    [
        (["--duration", "5", "--runs", "3", "--seed", "2"], "argument --duration: sets the simulated cases"),
        (["--runs", "2"], "argument --runs: sets the simulated cases"),
        (["--seed", "0"], "argument --seed: sets the simulated cases"),  # the default, but given
        (["--batched"], "argument --batched: sets the simulated cases"),
    ],
)
def test_bench_of_logs_alone_refuses_the_simulation_options(tmp_path, options, named):
    """--log without --scenario/--device simulates nothing: --duration, --runs, --seed and --batched were
    silently ignored; each given is named. With a simulated case beside the log they apply (not refused)."""
    log = tmp_path / "x.mcap"
    log.write_bytes(b"not read: the options are refused first")
    code, _, stderr = run_cli(["bench", "--log", str(log), *options, "--out", str(tmp_path / "b")])
    assert code == 2 and named in stderr and f"drop {', '.join(o for o in options if o.startswith('--'))}" in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap"]


@pytest.mark.parametrize("again", ["{tmp}/x.mcap", "{tmp}/./x.mcap", "{tmp}/link.mcap"])
def test_bench_refuses_a_log_given_twice(tmp_path, again):
    """One recording given twice (as twin and identify refuse): two cases of the same numbers."""
    log = tmp_path / "x.mcap"
    log.write_bytes(b"not read: the option is refused first")
    (tmp_path / "link.mcap").symlink_to(log)
    second = again.format(tmp=tmp_path)
    code, _, stderr = run_cli(["bench", "--log", str(log), "--log", second, "--out", str(tmp_path / "b")])
    assert code == 2 and "argument --log: " in stderr and "is given twice" in stderr, stderr
    assert not (tmp_path / "b").exists()


@pytest.mark.parametrize("gravity", ["1e308", "98.1", "0.981", "1", "3.71", "9.5", "10.5"])
def test_identify_bounds_gravity_before_any_work(tmp_path, gravity):
    """--gravity 1e308 started the fit and then blamed the log; a value off the Earth's (a slip of units
    or digits) would scale every accelerometer figure. Refused naming --gravity before reading a log."""
    log = tmp_path / "x.mcap"
    log.write_bytes(b"not read: the option is refused first")
    code, _, stderr = run_cli(["identify", str(log), "--out", str(tmp_path / "d.toml"), "--gravity", gravity])
    assert code == 2 and "argument --gravity: local gravity in m/s^2, from 9.7 to 9.9" in stderr, stderr
    assert [p.name for p in tmp_path.iterdir()] == ["x.mcap"]


def test_identify_takes_gravity_anywhere_on_earth():
    from gyroemu.dynamics import normal_gravity
    from gyroemu.pipelines.jobs.identify import GRAVITY_RANGE_M_S2

    low, high = GRAVITY_RANGE_M_S2
    for latitude_deg, height_m in ((0, 0), (90, 0), (-90, 0), (28, 8849), (0, 12000), (45, -3000)):
        assert low <= float(normal_gravity(np.radians(latitude_deg), height_m)) <= high


def test_bench_out_is_a_folder_and_has_a_force(tmp_path):
    """bench writes its reports into a folder (each file whole, :mod:`gyroemu.pipelines.formats.atomic`);
    a file there is refused; --force overwrites an earlier report there (test_bench.py)."""
    report = tmp_path / "bench"
    report.write_text("a file")
    code, _, stderr = run_cli(["bench", "--out", str(report)])
    assert code == 2 and f"argument --out: {report} is not a folder" in stderr, stderr
    assert report.read_text() == "a file"
    code, stdout, _ = run_cli(["bench", "--help"])
    assert code == 0 and "--out" in stdout and "--force" in stdout


# ---------------------------------------------------------------------------------------------------
# SIGTERM in main: an exception, exit 143, the previous handler back.


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(), reason="signals: main thread only")
def test_sigterm_in_main_exits_143_and_restores_the_handler(monkeypatch):
    import gyroemu.dynamics

    def terminated():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises before this ends
        raise AssertionError("SIGTERM did not interrupt the command")

    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(gyroemu.dynamics, "list_scenarios", terminated)
    assert run_cli(["scenarios"])[0] == 143
    assert signal.getsignal(signal.SIGTERM) is before


# ---------------------------------------------------------------------------------------------------
# Interruptions: a real process, signalled once its temporary file exists.


@pytest.mark.slow
@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_simulate_interrupted_leaves_nothing(tmp_path, sig, status):
    out = tmp_path / "long.mcap"
    argv = ["simulate", "--scenario", "bench_static", "--device", "consumer_mems", "--duration", "3600"]
    child = subprocess.Popen(
        [sys.executable, "-m", "gyroemu", *argv, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # an interactive shell's background job ignores SIGINT: this one must not
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 60
        while not any(p.stat().st_size for p in tmp_path.glob(".long.mcap.*.tmp")):  # blocks being written
            assert child.poll() is None, child.communicate()
            assert time.monotonic() < deadline, "no data in a temporary file after 60 s"
            time.sleep(0.05)
        child.send_signal(sig)
        stdout, stderr = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == status, stderr
    assert "Traceback" not in stderr, stderr
    assert list(tmp_path.iterdir()) == []  # no .tmp left, no output
    assert str(out) not in stdout


def test_bench_latency_needs_a_log(tmp_path):
    code, _, stderr = run_cli(["bench", "--latency", "gyro=2", "--out", str(tmp_path / "b")])
    assert code == 2 and "argument --latency: times a --log; a simulated device has its own latency_s" in stderr, stderr
    assert list(tmp_path.iterdir()) == []


def test_a_truth_held_whole_beyond_the_memory_is_refused_before_work(tmp_path, monkeypatch):
    """A kind that integrates its motion (the heavy top) is simulated whole before it is measured, and
    ``bench`` holds any case's truth whole: with 1000 pages of memory (4 MB), ``simulate`` to an .mcap and
    ``stream`` refuse 60 s of the top (12 MB at its 1 kHz), ``bench`` 600 s of the smooth manoeuvre (24 MB
    at its 200 Hz), naming --duration and writing nothing; a pointwise kind, read in windows,
    is not held to it (``simulate`` of the smooth manoeuvre to an .mcap runs)."""
    sysconf = os.sysconf
    monkeypatch.setattr(os, "sysconf", lambda name: 1000 if name == "SC_PHYS_PAGES" else sysconf(name))
    heavy = ["--scenario", "heavy_top", "--device", "consumer_mems", "--duration", "60"]
    code, _, stderr = run_cli(["simulate", *heavy, "--out", str(tmp_path / "t.mcap")])
    assert code == 2, stderr
    assert "argument --duration: 60 s of heavy_top needs about" in stderr and "simulated whole" in stderr
    code, _, stderr = run_cli(["stream", *heavy, "--listen", f"tcp/127.0.0.1:{free_port()}"])
    assert code == 2 and "argument --duration: 60 s of heavy_top needs about" in stderr, stderr
    bench = ["bench", "--scenario", "smooth_manoeuvre", "--runs", "1", "--duration", "600"]  # 24 MB at 200 Hz
    code, _, stderr = run_cli([*bench, "--out", str(tmp_path / "b")])
    assert code == 2 and "argument --duration: 600 s of smooth_manoeuvre needs about" in stderr, stderr
    assert list(tmp_path.iterdir()) == []
    own = ["--scenario", "heavy_top", "--device", "consumer_mems"]  # the file's duration_s: named as its key
    code, _, stderr = run_cli(["simulate", *own, "--out", str(tmp_path / "t.mcap")])
    assert code == 2 and "heavy_top: key 'duration_s': " in stderr and "give a shorter --duration" in stderr, stderr
    code, _, stderr = run_cli(["simulate", *heavy, "--rate", "1000", "--out", str(tmp_path / "t.mcap")])
    assert code == 2 and "shorten --duration or lower --rate" in stderr, stderr
    smooth = ["--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "2"]
    code, _, stderr = run_cli(["simulate", *smooth, "--out", str(tmp_path / "s.mcap")])
    assert code == 0, stderr


def test_whole_truth_bytes_bounds_what_a_trajectory_holds():
    """``WHOLE_TRUTH_BYTES`` a sample is at least what a simulated trajectory's arrays take, and the count
    is the time grid's, made without the grid."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.dynamics.truth_source import WHOLE_TRUTH_BYTES, simulated_whole, whole_truth_bytes

    scenario = load_scenario("heavy_top")
    assert simulated_whole(scenario) and not simulated_whole(load_scenario("smooth_manoeuvre"))
    traj = scenario.simulate(duration=2.0, rate_hz=500.0)
    n = len(traj.t)
    held = sum(v.nbytes for v in vars(traj).values() if isinstance(v, np.ndarray))
    assert held <= n * WHOLE_TRUTH_BYTES
    assert whole_truth_bytes(scenario, 2.0, 500.0) == n * WHOLE_TRUTH_BYTES


def test_import_refuses_a_read_only_out_folder_before_reading_the_trial(tmp_path, monkeypatch):
    """A read-only mount (which a test cannot make; folder_problem is told so) is refused naming --out
    before the trial is read: a trial that cannot be read is not what it reports."""
    from gyroemu.pipelines.formats import atomic, importers

    def no_read(path):
        raise AssertionError("the trial was read before --out was checked")

    locked = tmp_path / "ro"
    locked.mkdir()
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if f == locked else None)
    monkeypatch.setattr(importers, "read_broad", no_read)
    trial = tmp_path / "t.hdf5"
    trial.write_bytes(b"not read")
    code, _, stderr = run_cli(["import", "broad", str(trial), "--out", str(locked / "b.mcap")])
    assert code == 2, stderr
    assert f"argument --out: {locked}: read-only file system" in stderr
    assert list(locked.iterdir()) == []


def test_the_command_line_and_the_scenario_files_have_the_same_limits():
    """``simulate --duration`` / ``--rate`` and a scenario file's ``duration_s`` / ``rate_hz`` are bounded
    alike (two constants, so that parsing numbers does not load the dynamics)."""
    from gyroemu.dynamics import scenarios
    from gyroemu.pipelines.jobs import simulate

    assert (simulate.MAX_DURATION_S, simulate.MAX_RATE_HZ) == (scenarios.MAX_DURATION_S, scenarios.MAX_RATE_HZ)


@pytest.mark.parametrize("argument", ["--out", "--site-out"])
def test_identify_refuses_a_toml_that_is_a_log_even_with_force(tmp_path, argument):
    """A ``.toml`` name that is a link to one of identify's logs is the log: refused with --force too
    (``output_file_problem`` is given the logs as inputs), and the log keeps its bytes."""
    log = tmp_path / "in.mcap"
    log.write_bytes(b"an input")
    link = tmp_path / "device.toml"
    link.symlink_to(log)
    out = link if argument == "--out" else tmp_path / "fresh.toml"
    argv = ["identify", str(log), "--out", str(out), "--force"]
    argv += ["--site-out", str(link)] if argument == "--site-out" else []
    code, stdout, stderr = run_cli(argv)
    assert code == 2 and stdout == "", stderr
    assert f"argument {argument}: {link} is an input ({log}): inputs are never overwritten" in stderr, stderr
    assert log.read_bytes() == b"an input" and link.is_symlink()


@pytest.mark.parametrize("target", ["motion", "scenario"])
def test_simulate_refuses_an_output_that_is_its_recorded_motion_or_scenario(tmp_path, target):
    """``simulate --force`` never writes over what it reads: the recorded motion's file and the scenario
    file (here reached through a link with the output's suffix) are inputs, refused before any work."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.motion_files import write_tum

    truth = load_scenario("smooth_manoeuvre").simulate(duration=2.0, rate_hz=100.0)
    motion = tmp_path / "m.tum"
    write_tum(motion, truth.t, truth.q_wb, truth.pos_w)
    scenario = tmp_path / "motion.toml"
    scenario.write_text('kind = "recorded"\npath = "m.tum"\nformat = "tum"\n')
    before = {p: p.read_bytes() for p in (motion, scenario)}
    out = tmp_path / "out.npz"
    out.symlink_to(motion if target == "motion" else scenario)
    code, stdout, stderr = run_cli(["simulate", "--scenario", str(scenario), "--out", str(out), "--force"])
    assert code == 2 and stdout == "", stderr
    assert f"argument --out: {out} is an input" in stderr and "inputs are never overwritten" in stderr, stderr
    assert {p: p.read_bytes() for p in before} == before and out.is_symlink()


@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_record_force_replaces_a_linked_out_and_not_what_it_links_to(tmp_path, link):
    """``record --force`` over a link makes a new file, as every other command's atomic write does: the
    link's target (a symbolic link) or the file's other name (a hard link) keeps its bytes."""
    from gyroemu.pipelines.formats.messages import IMU
    from gyroemu.pipelines.transport.record import Recorder
    from gyroemu.pipelines.transport.zenoh_io import pack_attachment

    someone = tmp_path / "someone.mcap"
    someone.write_bytes(b"someone's recording")
    out = tmp_path / "r.mcap"
    out.symlink_to(someone) if link == "symbolic" else os.link(someone, out)
    recorder = Recorder(out)
    payload = bytes(IMU.encode(np.array([1_000_000_000]), "dev")[0])
    recorder.add(Sample("gyroemu/dev/imu", payload, pack_attachment(0, 1, bytes(16))))
    recorder.close()
    assert recorder.messages == 1 and not out.is_symlink() and out.read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert someone.read_bytes() == b"someone's recording"
