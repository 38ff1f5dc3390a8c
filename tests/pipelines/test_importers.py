"""``gyroemu import broad``: a BROAD trial into the MCAP contract, checked exactly against the HDF5 arrays.

Exactness: the importer copies float64 values into CDR unchanged, so gyro, accel and the reference
quaternions read back bit-identical (NaN rows included); the magnetometer reads back as the same
product ``µT · 1e-6``. Stamps: ``t_k = k / fs`` rounded to the nearest ns, so ``|stamp_k − k·10⁹/fs| ≤ 0.5 ns``
plus the float64 rounding of ``k·10⁹/fs`` (under 10⁻⁴ ns for these magnitudes); at 2000/7 Hz exactly
``k · 3.5 ms``. The real trials live in ``../shared/datasets/broad/`` (``GYROEMU_BROAD_DIR`` overrides);
tests that need them skip when the folder is absent. Error cases use small synthetic HDF5 files.
"""

from __future__ import annotations

import hashlib
import inspect
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
from broad_trials import BROAD_DIR, needs_trial, require_trial
from cli_runs import run_cli
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gyroemu.pipelines.formats.importers import BROAD_CITATION, ImportInputError, import_broad, read_broad
from gyroemu.pipelines.formats.mcap_log import LogWarning, Recording, read_mcap, read_tf, write_mcap
from gyroemu.pipelines.formats.mcap_records import McapFileWriter
from gyroemu.pipelines.formats.messages import FLAG, IMU, schema_text
from gyroemu.sensors.samples import ImuSamples

TRIAL = "33_disturbed_attached_magnet_2cm.hdf5"  # the smallest of the eight (48,279 samples)
needs_broad = needs_trial(TRIAL)


def fingerprint(path):
    """(sha256, mtime_ns, size): a file's bytes and modification time."""
    stat = Path(path).stat()
    return hashlib.sha256(Path(path).read_bytes()).hexdigest(), stat.st_mtime_ns, stat.st_size


def read_quietly(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an imported file reads without any warning
        return read_mcap(path)


def hdf5_arrays(path):
    with h5py.File(path, "r") as f:
        return {name: f[name][()] for name in f}, float(f.attrs["sampling_rate"])


# ---------------------------------------------------------------------------------------------------
# A real trial.


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """The trial imported once (library call), with the input's fingerprint before and after."""
    require_trial(TRIAL)
    source = BROAD_DIR / TRIAL
    before = fingerprint(source)
    out = tmp_path_factory.mktemp("broad") / "trial.mcap"
    summary = import_broad(source, out)
    after = fingerprint(source)
    arrays, fs = hdf5_arrays(source)
    return source, out, summary, arrays, fs, before, after


@needs_broad
def test_real_trial_reads_back_exactly(imported):
    source, out, summary, h5, fs, before, after = imported
    assert after == before  # bytes and mtime of the input unchanged
    assert sorted(p.name for p in out.parent.iterdir()) == ["trial.mcap"]  # no temporary left
    n = len(h5["imu_gyr"])
    assert summary.samples == n and summary.rate_hz == fs
    assert summary.truth_nan_rows == int(np.isnan(h5["opt_quat"]).any(axis=1).sum()) > 0
    log = read_quietly(out)
    assert list(log.devices) == ["imu0"] and not log.truncated and not log.skipped
    d = log.device
    assert d.topics == {
        "imu": "/imu",
        "mag": "/mag",
        "truth/imu": "/truth/imu",
        "truth/pose": "/truth/pose",
        "movement": "/movement",
    }
    assert log.message_count == 5 * n + len(read_tf(out))  # and the tf tree of the optical truth
    s = d.samples
    assert len(s) == n
    assert s.gyro.dtype == h5["imu_gyr"].dtype and s.gyro.tobytes() == h5["imu_gyr"].tobytes()
    assert s.accel.tobytes() == h5["imu_acc"].tobytes()
    assert np.array_equal(s.mag, h5["imu_mag"] * 1e-6)  # tesla
    # Reference attitude: same numbers, NaN rows at the same places, rate and force "no estimate".
    q = d.truth.q_wb
    assert np.array_equal(np.isnan(q), np.isnan(h5["opt_quat"]))
    assert q.tobytes() == h5["opt_quat"].tobytes()  # bit-identical, NaN payloads included
    assert d.truth.omega_b is None and d.truth.specific_force_b is None and d.truth.q_wb_covariance is None
    # Reference position with the same attitude, bit-identical, on the same stamps.
    assert d.pose.pos_w.tobytes() == h5["opt_pos"].tobytes() and d.pose.q_wb.tobytes() == h5["opt_quat"].tobytes()
    assert np.array_equal(d.pose.t, d.truth.t)
    # Movement mask.
    assert d.movement.dtype == bool and np.array_equal(d.movement, h5["movement"])
    assert 0 < d.movement.sum() < n
    # Stamps: k / fs from 0, exact ns; every channel on the same stamps.
    k = np.arange(n)
    exact = k * 1e9 / fs
    assert d.stamp_ns[0] == 0 and np.all(np.abs(d.stamp_ns - exact) <= 0.5 + 1e-3)
    if fs == 2000 / 7:
        assert np.array_equal(d.stamp_ns, k * 3_500_000)
    assert np.array_equal(np.rint(d.truth.t * 1e9).astype(np.int64), d.stamp_ns)
    assert np.all(np.abs(s.t - exact * 1e-9) <= 1e-9)
    # Metadata: what gyroemu info and the estimator read.
    meta = d.metadata
    assert meta["device_name"] == "imu0" and meta["topic_prefix"] == ""
    assert meta["source"] == TRIAL and meta["source_format"] == "BROAD"
    assert meta["citation"] == BROAD_CITATION and "Laidig" in meta["citation"] and "Data 6(7), 2021" in meta["citation"]
    assert meta["license"] == "CC BY 4.0" and float(meta["sampling_rate_hz"]) == fs
    assert meta["seed"] == "" and meta["device"] == "" and meta["scenario"] == "" and meta["version"]


def log_time_range(reader, start_ns: int, end_ns: int) -> dict:
    """``iter_decoded_messages``' arguments for log times in ``[start_ns, end_ns)``: mcap ≥ 1.6 names them
    ``starting_at``/``ending_before`` and deprecates ``start_time``/``end_time`` (the floor is 1.1)."""
    if "starting_at" in inspect.signature(reader.iter_decoded_messages).parameters:
        return {"starting_at": start_ns, "ending_before": end_ns}
    return {"start_time": start_ns, "end_time": end_ns}


@needs_broad
def test_real_trial_independent_decoders(imported):
    """mcap_ros2 and rosbags decode /imu, /movement and /truth/imu to the HDF5 values: every message in
    windows of ±40 samples around the start, the first NaN run of the reference that follows valid rows,
    the first and last movement edges and the end (decoding all 145 k messages twice takes about 5 s)."""
    _, out, _, h5, fs, _, _ = imported
    n = len(h5["imu_gyr"])
    movement, nan_rows = h5["movement"], np.isnan(h5["opt_quat"]).any(axis=1)
    edges = np.flatnonzero(np.diff(movement.astype(np.int8)))
    nan_starts = np.flatnonzero(np.diff(nan_rows.astype(np.int8)) == 1) + 1
    centres = [0, int(nan_starts[0]), int(edges[0]), int(edges[-1]), n - 1]
    window = set()
    for centre in centres:
        window |= set(range(max(0, centre - 40), min(n, centre + 41)))
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(FLAG.schema, FLAG.name))
    seen = {"/imu": set(), "/movement": set(), "/truth/imu": set()}
    step = 1e9 / fs
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for centre in centres:
            first, last = max(0, centre - 40), min(n - 1, centre + 40)
            for schema, channel, message, ros in reader.iter_decoded_messages(
                topics=list(seen), **log_time_range(reader, round(first * step), round(last * step) + 1)
            ):
                k = int(round(message.log_time / step))
                assert message.log_time == message.publish_time
                other = store.deserialize_cdr(message.data, schema.name)
                for msg in (ros, other):
                    assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == message.log_time
                    if channel.topic == "/imu":
                        assert msg.header.frame_id == "imu0" and msg.orientation_covariance[0] == -1.0
                        assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == h5[
                            "imu_gyr"
                        ][k].tolist()
                        assert [msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z] == h5[
                            "imu_acc"
                        ][k].tolist()
                    elif channel.topic == "/movement":
                        assert schema.name == "gyroemu_msgs/msg/Flag" and msg.header.frame_id == "imu0"
                        assert msg.data is bool(movement[k])
                    else:
                        o = msg.orientation
                        assert np.array_equal([o.w, o.x, o.y, o.z], h5["opt_quat"][k], equal_nan=True)
                        assert msg.angular_velocity_covariance[0] == -1.0
                        assert msg.linear_acceleration_covariance[0] == -1.0
                seen[channel.topic].add(k)
    assert all(v == window for v in seen.values())
    assert nan_rows[sorted(window)].any() and not nan_rows[sorted(window)].all()
    assert {0, n - 1, int(edges[0]), int(edges[0]) + 1, int(edges[-1]), int(edges[-1]) + 1} <= window


@needs_broad
def test_cli_import_and_info(tmp_path):
    """The command line end to end, in a subprocess: exit 0, a one-line summary, the input untouched;
    ``gyroemu info`` names the source and the citation."""
    source = BROAD_DIR / TRIAL
    before = fingerprint(source)
    out = tmp_path / "trial.mcap"
    result = subprocess.run(
        [sys.executable, "-m", "gyroemu", "import", "broad", str(source), "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert fingerprint(source) == before
    n = len(read_broad(source))
    assert f"{n} samples" in result.stdout and str(out) in result.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trial.mcap"]
    code, stdout, stderr = run_cli(["info", str(out)])
    assert code == 0, stderr
    assert f"{n} samples" in stdout and "/movement" in stdout and "285.714 Hz" in stdout
    assert f"imported from {TRIAL} (BROAD)" in stdout and "Laidig" in stdout and "CC BY 4.0" in stdout
    assert "seed" not in stdout


# ---------------------------------------------------------------------------------------------------
# Synthetic trials: round trip, and bad input.


def write_trial(path, n=50, rate=100.0, drop=None, replace=None, attrs=True):
    """A small BROAD-like HDF5 file; ``drop`` omits a dataset, ``replace`` swaps datasets' values."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[5:9] = np.nan
    data = {
        "imu_gyr": rng.normal(size=(n, 3)),
        "imu_acc": rng.normal(size=(n, 3)) + [0, 0, 9.81],
        "imu_mag": rng.normal(size=(n, 3)) * 30,
        "opt_quat": q,
        "opt_pos": rng.normal(size=(n, 3)),
        "movement": np.arange(n) % 7 < 4,
    }
    data.update(replace or {})
    with h5py.File(path, "w") as f:
        for name, value in data.items():
            if name != drop:
                f.create_dataset(name, data=value)
        if attrs:
            f.attrs["sampling_rate"] = rate
    return data


def test_synthetic_round_trip_and_nan_rows(tmp_path):
    source = tmp_path / "trial.hdf5"
    data = write_trial(source, n=80, rate=200.0)
    before = fingerprint(source)
    summary = import_broad(source, tmp_path / "t.mcap")
    assert fingerprint(source) == before and summary.truth_nan_rows == 4 and summary.samples == 80
    d = read_quietly(tmp_path / "t.mcap").device
    assert np.array_equal(d.stamp_ns, np.arange(80) * 5_000_000)
    assert d.samples.gyro.tobytes() == data["imu_gyr"].tobytes()
    assert np.array_equal(d.samples.mag, data["imu_mag"] * 1e-6)
    assert d.truth.q_wb.tobytes() == data["opt_quat"].tobytes() and np.isnan(d.truth.q_wb[5:9]).all()
    assert np.array_equal(d.movement, data["movement"])


def test_irrational_rate_stamps_within_half_ns(tmp_path):
    source = tmp_path / "trial.hdf5"
    write_trial(source, n=3000, rate=np.pi * 100)
    import_broad(source, tmp_path / "t.mcap")
    stamp_ns = read_quietly(tmp_path / "t.mcap").device.stamp_ns
    assert np.all(np.abs(stamp_ns - np.arange(3000) * 1e9 / (np.pi * 100)) <= 0.5 + 1e-6)


@pytest.mark.parametrize(
    "case, named",
    [
        ("missing_file", "no such file"),
        ("not_hdf5", "not an HDF5 file"),
        ("folder", "is a folder"),
        ("no_imu_gyr", "dataset 'imu_gyr': missing"),
        ("no_imu_mag", "dataset 'imu_mag': missing"),
        ("no_opt_quat", "dataset 'opt_quat': missing"),
        ("no_movement", "dataset 'movement': missing"),
        ("gyro_4_columns", "dataset 'imu_gyr': shape (50, 4), expected (50, 3)"),
        ("quat_3_columns", "dataset 'opt_quat': shape (50, 3), expected (50, 4)"),
        ("acc_short", "dataset 'imu_acc': shape (49, 3), expected (50, 3)"),
        ("movement_2d", "dataset 'movement': shape (50, 1), expected (50)"),
        ("movement_not_01", "dataset 'movement': values other than 0 and 1"),
        ("mag_text", "dataset 'imu_mag': type"),
        ("group", "dataset 'imu_acc': is a group"),
        ("empty", "dataset 'imu_gyr': holds no samples"),
        ("no_rate", "attribute 'sampling_rate': missing"),
        ("zero_rate", "attribute 'sampling_rate'"),
        # stamps k·1e9/fs overflow int64 ns (were: ValueError "stamps before 0 s", a traceback)
        ("tiny_rate", "attribute 'sampling_rate': 1e-06 Hz is outside 1 Hz … 100 kHz"),
        # every stamp rounds to the same ns (were: a log of repeated stamps; identify: an 894 GiB array)
        ("huge_rate", "attribute 'sampling_rate': 1e+12 Hz is outside 1 Hz … 100 kHz"),
        ("period_as_rate", "attribute 'sampling_rate': 0.0035 Hz is outside"),
        ("gyro_column_nan", "dataset 'imu_gyr': column y NaN in every row: no sample a filter could use"),
        ("accel_nan", "dataset 'imu_acc': NaN in every row"),
    ],
)
def test_bad_input_exits_2_naming_file_and_item(tmp_path, case, named):
    source = tmp_path / "trial.hdf5"
    if case == "not_hdf5":
        source.write_text("timestamp,gx,gy,gz\n0.0,0.1,0.2,0.3\n")
    elif case == "folder":
        source.mkdir()
    elif case.startswith("no_") and case != "no_rate":
        write_trial(source, drop=case[3:])
    elif case == "group":
        write_trial(source, drop="imu_acc")
        with h5py.File(source, "a") as f:
            f.create_group("imu_acc")
    elif case != "missing_file":
        replace = {
            "gyro_4_columns": {"imu_gyr": np.zeros((50, 4))},
            "quat_3_columns": {"opt_quat": np.zeros((50, 3))},
            "acc_short": {"imu_acc": np.zeros((49, 3))},
            "movement_2d": {"movement": np.ones((50, 1), bool)},
            "movement_not_01": {"movement": np.full(50, 2)},
            "mag_text": {"imu_mag": np.array([["a", "b", "c"]] * 50, dtype="S1")},
            "empty": {
                name: np.zeros((0, w)) for name, w in (("imu_gyr", 3), ("imu_acc", 3), ("imu_mag", 3), ("opt_quat", 4))
            }
            | {"movement": np.zeros(0, bool)},
            "gyro_column_nan": {"imu_gyr": np.zeros((50, 3)) + [0.0, np.nan, 0.0]},
            "accel_nan": {"imu_acc": np.full((50, 3), np.nan)},
        }.get(case)
        rate = {"zero_rate": 0.0, "tiny_rate": 1e-6, "huge_rate": 1e12, "period_as_rate": 0.0035}.get(case, 100.0)
        write_trial(source, replace=replace, attrs=case != "no_rate", rate=rate)
    before = fingerprint(source) if source.is_file() else None
    inputs = sorted(tmp_path.iterdir())
    out = tmp_path / "trial.mcap"
    code, stdout, stderr = run_cli(["import", "broad", str(source), "--out", str(out)])
    assert code == 2, (stdout, stderr)
    assert stderr.startswith("gyroemu import: error: ") and str(source) in stderr and named in stderr, stderr
    assert sorted(tmp_path.iterdir()) == inputs  # no output, no temporary left behind
    if before is not None:
        assert fingerprint(source) == before
    if case not in ("missing_file", "not_hdf5", "folder"):
        with pytest.raises(ImportInputError) as e:
            import_broad(source, out)
        assert e.value.file == str(source) and (e.value.item or "") in named


@pytest.mark.parametrize("rate", [1.0, 100_000.0])
def test_rates_at_the_bounds_import_and_identify_refuses_one_beyond(tmp_path, rate):
    """1 Hz and 100 kHz are IMU rates (BROAD_RATE_RANGE_HZ): stamps k·1e9/fs exactly, distinct; a rate
    beyond is refused by every reader of the trial, here identify's, exit 2 before any work."""
    source = tmp_path / "trial.hdf5"
    write_trial(source, n=60, rate=rate)
    import_broad(source, tmp_path / "t.mcap")
    stamp_ns = read_quietly(tmp_path / "t.mcap").device.stamp_ns
    assert np.array_equal(stamp_ns, np.arange(60) * round(1e9 / rate))
    write_trial(source, n=60, rate=rate * (0.5 if rate == 1.0 else 2.0))
    code, _, stderr = run_cli(["identify", str(source), "--out", str(tmp_path / "dev.toml")])
    assert code == 2 and f"{source}: attribute 'sampling_rate': " in stderr and "Traceback" not in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.mcap", "trial.hdf5"]


@pytest.mark.parametrize(
    "dataset, row, value, named",
    [
        ("imu_acc", 20, [0.0, np.inf, 9.81], "dataset 'imu_acc': inf at row 20: not a measurement"),
        ("imu_gyr", 3, [-np.inf, 0.0, 0.0], "dataset 'imu_gyr': inf at row 3"),
        ("opt_pos", 7, [np.inf, 0.0, 0.0], "dataset 'opt_pos': inf at row 7"),
        ("opt_quat", 30, [0.0, 0.0, 0.0, 0.0], "dataset 'opt_quat': [0.0, 0.0, 0.0, 0.0] at row 30 is not a unit"),
        ("opt_quat", 31, [2.0, 0.0, 0.0, 0.0], "dataset 'opt_quat': [2.0, 0.0, 0.0, 0.0] at row 31 is not a unit"),
    ],
)
def test_values_that_are_no_measurement_exit_2_naming_file_and_dataset(tmp_path, dataset, row, value, named):
    """inf is no measurement and a zero (or far from unit) quaternion no rotation: refused, naming the
    file, dataset and row; nothing written."""
    source = tmp_path / "trial.hdf5"
    data = write_trial(source)
    values = data[dataset].copy()
    values[row] = value
    with h5py.File(source, "a") as f:
        f[dataset][...] = values
    code, _, stderr = run_cli(["import", "broad", str(source), "--out", str(tmp_path / "t.mcap")])
    assert code == 2 and f"{source}: {named}" in stderr, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trial.hdf5"]


def test_sensor_nan_rows_are_dropouts_kept_and_counted(tmp_path):
    """A NaN sample is a dropout a filter bridges: imported as NaN, and the summary says how many rows."""
    source = tmp_path / "trial.hdf5"
    data = write_trial(source)
    gyro = data["imu_gyr"].copy()
    gyro[10:13] = np.nan
    with h5py.File(source, "a") as f:
        f["imu_gyr"][...] = gyro
    summary = import_broad(source, tmp_path / "t.mcap")
    assert summary.sample_nan_rows == 3 and "sensor NaN (dropouts, kept) in 3 rows" in str(summary)
    assert np.isnan(read_quietly(tmp_path / "t.mcap").device.samples.gyro[10:13]).all()


@pytest.mark.parametrize(
    "argv, named",
    [
        (["import", "broad", "{src}", "--out", "{tmp}/no/such/folder/t.mcap"], "argument --out: {tmp}/no/such/folder"),
        (["import", "broad", "{src}", "--out", "{tmp}/t.npz"], "argument --out: {tmp}/t.npz: write a .mcap file"),
        (["import", "csv", "{src}", "--out", "{tmp}/t.mcap"], "argument format: invalid choice: 'csv'"),
        (["import", "broad", "{src}"], "--out"),
    ],
)
def test_bad_arguments_exit_2_naming_them(tmp_path, argv, named):
    source = tmp_path / "trial.hdf5"
    write_trial(source)
    before = fingerprint(source)
    argv = [a.format(src=source, tmp=tmp_path) for a in argv]
    code, _, stderr = run_cli(argv)
    assert code == 2 and named.format(tmp=tmp_path) in stderr, stderr
    assert [p.name for p in tmp_path.iterdir()] == ["trial.hdf5"] and fingerprint(source) == before


def test_output_never_replaces_the_input(tmp_path):
    source = tmp_path / "trial.mcap"  # an HDF5 file with an .mcap name, so --out can name it
    write_trial(source)
    before = fingerprint(source)
    code, _, stderr = run_cli(["import", "broad", str(source), "--out", str(source)])
    said = f"argument --out: {source} is an input: inputs are never overwritten, even with --force"
    assert code == 2 and said in stderr and fingerprint(source) == before, stderr


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    """A failure while writing (disk full, say) removes the temporary file; an older output stays. A full
    disk is not the argument's fault: status 1 (``test_cli_robust.py``), the output named."""
    source = tmp_path / "trial.hdf5"
    write_trial(source)
    out = tmp_path / "t.mcap"
    out.write_bytes(b"an older file")

    def fail(self, batches):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(McapFileWriter, "add_messages", fail)
    code, _, stderr = run_cli(["import", "broad", str(source), "--out", str(out), "--force"])
    assert code == 1 and f"No space left on device writing {out}: stopped" in stderr, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.mcap", "trial.hdf5"]
    assert out.read_bytes() == b"an older file"


# ---------------------------------------------------------------------------------------------------
# The movement channel in general logs.


def _samples(n, device="imu0", t0=0.0):
    rng = np.random.default_rng(len(device))
    return ImuSamples(
        t=t0 + np.arange(n) * 0.01,
        gyro=rng.normal(size=(n, 3)),
        accel=rng.normal(size=(n, 3)),
        mag=np.full((n, 3), np.nan),
        device=device,
    )


def test_movement_with_topic_prefixes(tmp_path):
    a, b = _samples(30, "left"), _samples(20, "right")
    ma, mb = np.arange(30) % 3 == 0, np.arange(20) % 2 == 0
    path = write_mcap(tmp_path / "two.mcap", [Recording(a, movement=ma), Recording(b, movement=mb)])
    log = read_quietly(path)
    assert log.devices["left"].topics["movement"] == "/left/movement"
    assert log.devices["right"].topics["movement"] == "/right/movement"
    assert np.array_equal(log.devices["left"].movement, ma) and np.array_equal(log.devices["right"].movement, mb)
    plain = read_quietly(write_mcap(tmp_path / "plain.mcap", a))
    assert plain.device.movement is None


def test_movement_at_unknown_stamps_is_false_with_a_warning(tmp_path):
    """A /movement topic whose stamps cover only some samples: those without a flag read False (warned);
    flags at stamps without a sample are ignored."""
    n = 40
    stamps = np.arange(n) * 10_000_000
    flag_stamps = np.concatenate([stamps[::2], [stamps[-1] + 5]])
    flags = np.ones(len(flag_stamps), bool)
    path = tmp_path / "partial.mcap"
    with open(path, "wb") as f:
        w = McapFileWriter(f)
        imu = w.register_channel("/imu", "cdr", w.register_schema(IMU.name, "ros2msg", schema_text(IMU.name).encode()))
        mov = w.register_channel(
            "/movement", "cdr", w.register_schema(FLAG.name, "ros2msg", schema_text(FLAG.name).encode())
        )
        w.add_messages(
            [
                (imu, stamps, IMU.encode(stamps, "imu0")),
                (mov, flag_stamps, FLAG.encode(flag_stamps, "imu0", {"data": flags})),
            ]
        )
        w.finish()
    with pytest.warns(LogWarning, match=r"20 samples of /imu have no message on /movement .*False"):
        log = read_mcap(path)
    assert np.array_equal(log.device.movement, np.arange(n) % 2 == 0)


def test_writer_checks_movement_and_metadata(tmp_path):
    s = _samples(10)
    with pytest.raises(ValueError, match="movement must be 10 booleans"):
        write_mcap(tmp_path / "x.mcap", Recording(s, movement=np.ones(9, bool)))
    with pytest.raises(ValueError, match="device_name"):
        write_mcap(tmp_path / "x.mcap", Recording(s, metadata={"device_name": "other"}))
    assert list(tmp_path.iterdir()) == []
