"""``gyroemu allan`` reading a log in batches (``allan_of_log``) against the in-memory path (``read_mcap``
and ``allan_report``), and its errors for logs it cannot use.

Tolerances: the streamed and allantools' Allan deviations differ by round-off only, bounded as in
``tests/sensors/test_allan_stream.py``: a second difference has an error of at most
ε·[P·(m + 2r + 5.5) + m·Δt·Y] (P the largest phase magnitude rounded, r the re-basings of a point, Y the
largest |y − offset|), a relative error of σ of at most δ/rms(D) + ½(δ/rms(D))², for each of the two
computations. The accumulator's phases are differences of sums of y − c with c its offset (a mean of
samples, so |ȳ − c| ≤ max|y − ȳ| = Y), hence P ≤ 2(P_ref + Y·N·Δt) with P_ref allantools' largest
|x|. The sample intervals: the in-memory path takes the median step of the float stamps t = ns/10⁹,
the streamed one the median of the integer steps, /10⁹; each float stamp is within ε/2·T of its value
(T the largest stamp), so the steps, and τ, agree within ε(T/Δt + 2) relative.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from gyroemu.errors import LogError
from gyroemu.pipelines.formats.mcap_log import LogWarning, read_mcap, write_mcap
from gyroemu.pipelines.jobs.allan import BATCH, AllanLogError, allan_of_log, allan_report
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
from gyroemu.sensors.samples import ImuSamples

EPS = np.finfo(float).eps


def assert_reports_agree(streamed, reference, gyro, t, dt):
    """σ within the round-off bound, τ within the stamps' rounding, and the printed tables equal."""
    n = len(gyro)
    tau_bound = EPS * (np.abs(t).max() / dt + 2) + 4 * EPS
    for axis, (ours, ref) in enumerate(zip(streamed.fits, reference.fits)):
        a, b = ours.allan, ref.allan
        np.testing.assert_array_equal(a.clusters, b.clusters)
        np.testing.assert_allclose(a.tau, b.tau, rtol=tau_bound, atol=0)
        y = gyro[:, axis] - gyro[:, axis].mean()
        x = np.concatenate([[0.0], np.cumsum(y) * dt])
        P_ref, Y = np.abs(x).max(), np.abs(y).max()
        P_ours = 2 * (P_ref + Y * n * dt)
        for i, m in enumerate(np.round(b.tau / dt).astype(int)):
            d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
            rms = np.sqrt(np.mean(d * d))
            rebases = min(2 * m, n // BATCH + 1)
            bound = 8 * EPS * np.log2(n)
            for P, r in ((P_ref, 0), (P_ours, rebases)):
                q = EPS * (P * (m + 2 * r + 5.5) + m * dt * Y) / rms
                bound += q + q * q / 2
            assert abs(a.adev[i] / b.adev[i] - 1) <= bound, (axis, m, a.adev[i] / b.adev[i] - 1, bound)
    assert streamed.spec == reference.spec
    assert_tables_agree(streamed.table(), reference.table())


def assert_tables_agree(ours: str, reference: str) -> None:
    """The same text, but that a printed number may differ by one unit in its last digit: values equal
    to round-off can straddle a rounding boundary (0.16549… and 0.16550… print as 0.165 and 0.166)."""
    number = r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?"
    assert re.sub(number, "#", ours) == re.sub(number, "#", reference)
    for a, b in zip(re.findall(number, ours), re.findall(number, reference)):
        if a != b:
            decimals = len(b.split(".")[1].split("e")[0]) if "." in b else 0
            exponent = float("1e" + b.split("e")[1]) if "e" in b else 1.0
            assert abs(float(a) - float(b)) <= 1.000001 * 10.0**-decimals * exponent, (a, b)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("allan")
    logs = {}
    for suffix in ("mcap", "npz"):
        logs[suffix] = folder / f"static.{suffix}"
        run_simulate(
            SimulateOptions(
                scenario="bench_static", out=logs[suffix], device="consumer_mems", duration=120.0, progress=False
            )
        )
    return logs


def test_mcap_log_gives_the_in_memory_result(simulated):
    """120 000 samples: two batches, octaves up to 2^15 (all exact: 2m ≤ N − 1)."""
    streamed = allan_of_log(simulated["mcap"])
    samples = read_mcap(simulated["mcap"]).device.samples
    dt = float(np.median(np.diff(samples.t)))
    reference = allan_report(samples.gyro, dt, streamed.spec)
    assert_reports_agree(streamed, reference, samples.gyro, samples.t, dt)


def test_npz_log_gives_the_in_memory_result(simulated):
    streamed = allan_of_log(simulated["npz"])
    with np.load(simulated["npz"]) as data:
        gyro, t = data["imu/gyro"], data["imu/t"]
    dt = float(np.median(np.diff(t)))
    assert_reports_agree(streamed, allan_report(gyro, dt, streamed.spec), gyro, np.zeros(1), dt)


def samples(n, rate=100.0, device="imu0", seed=0, start=1.0):
    rng = np.random.default_rng(seed)
    t = start + np.arange(n) / rate
    gyro = rng.normal(0.0, 1e-3, (n, 3))
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    return ImuSamples(t=t, gyro=gyro, accel=accel, mag=np.full((n, 3), np.nan), device=device)


def test_truncated_mcap_warns_as_read_mcap_and_uses_the_recovered_samples(tmp_path):
    whole = write_mcap(tmp_path / "whole.mcap", samples(20000), chunk_size=1 << 16)
    cut = tmp_path / "cut.mcap"
    data = whole.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recovered = read_mcap(cut).device.samples
        streamed = allan_of_log(cut)
    messages = [str(w.message) for w in caught if issubclass(w.category, LogWarning)]
    assert len(messages) == 2 and messages[0] == messages[1] and re.search(r"truncated at byte \d+", messages[0])
    assert 64 < len(recovered.t) < 20000
    dt = float(np.median(np.diff(recovered.t)))
    assert_reports_agree(streamed, allan_report(recovered.gyro, dt), recovered.gyro, recovered.t, dt)


def test_a_file_that_is_not_mcap_raises_read_mcaps_error(tmp_path):
    bad = tmp_path / "notes.mcap"
    bad.write_text("not a log\n")
    with pytest.raises(LogError) as expected:
        read_mcap(bad)
    with pytest.raises(LogError) as got:
        allan_of_log(bad)
    assert str(got.value) == str(expected.value)


def test_a_short_log_and_a_log_with_nan_are_refused_as_before(tmp_path):
    short = write_mcap(tmp_path / "short.mcap", samples(40))
    with pytest.raises(
        AllanLogError,
        match=re.escape(f"{short}: an Allan analysis needs a (N, 3) gyro record with N >= 64, got shape (40, 3)"),
    ):
        allan_of_log(short)
    bad = samples(500)
    bad.gyro[300, 1] = np.nan
    nan_log = write_mcap(tmp_path / "nan.mcap", bad)
    with pytest.raises(AllanLogError, match=re.escape(f"{nan_log}: the gyro record has NaN or infinite samples")):
        allan_of_log(nan_log)
    with pytest.raises(AllanLogError, match="no such file") as missing:
        allan_of_log(tmp_path / "missing.mcap")
    # One of gyroemu's log errors, naming the file.
    assert isinstance(missing.value, LogError) and missing.value.file == str(tmp_path / "missing.mcap")


def test_a_log_of_two_devices_asks_for_a_topic(tmp_path):
    """Two devices: the error names their IMU topics and asks for one; ``topic`` picks the device
    read_mcap reads under that name."""
    log = write_mcap(tmp_path / "two.mcap", [samples(200, device="a"), samples(200, device="b", seed=1)])
    with pytest.raises(AllanLogError, match=r"2 IMU topics \(/a/imu, /b/imu\): choose the one to analyse with --topic"):
        allan_of_log(log)
    device = read_mcap(log).devices["b"]
    dt = float(np.median(np.diff(device.samples.t)))
    reference = allan_report(device.samples.gyro, dt)
    assert_reports_agree(allan_of_log(log, topic="/b/imu"), reference, device.samples.gyro, device.samples.t, dt)


def test_a_prefixed_single_device_log_is_read(tmp_path):
    log = write_mcap(tmp_path / "one.mcap", samples(3000, device="left"), prefix_topics=True)
    device = read_mcap(log).device
    assert device.topics["imu"] == "/left/imu"
    dt = float(np.median(np.diff(device.samples.t)))
    reference = allan_report(device.samples.gyro, dt)
    assert_reports_agree(allan_of_log(log), reference, device.samples.gyro, device.samples.t, dt)


def test_jittered_stamps_give_the_median_step_within_half_a_bin(tmp_path):
    """Stamps jittered by ±100 us at 100 Hz: about 200 000 distinct steps in ns, more than the step
    histogram's 65 536 bins, so they are merged by powers of two. With steps spread over a range W ns,
    2^s-ns bins number at most W/2^s + 2, so s ≤ ⌈log2(W/65 534)⌉; the median is the middle of its
    bin, within 2^(s−1) ns of ``np.median`` of the integer steps (plus the float stamps' rounding)."""
    rng = np.random.default_rng(2)
    n = 150_000
    jittered = samples(n)
    t = jittered.t + rng.uniform(-1e-4, 1e-4, n)
    log = write_mcap(tmp_path / "jitter.mcap", ImuSamples(t, jittered.gyro, jittered.accel, jittered.mag))
    stamps = read_mcap(log).device.stamp_ns
    steps = np.diff(stamps)
    assert len(np.unique(steps)) > 1 << 16
    shift = int(np.ceil(np.log2((steps.max() - steps.min()) / (65536 - 2))))
    tau = allan_of_log(log).fits[0].allan.tau[0]
    expected = float(np.median(steps)) * 1e-9
    assert abs(tau - expected) <= 2 ** (shift - 1) * 1e-9 + 4 * EPS * expected


def test_stamps_that_do_not_increase_are_refused_as_estimate_refuses_them(tmp_path):
    """Two samples swapped and one repeated (a relay that reorders, a driver that repeats): estimate
    refuses the log; allan, which took the samples in log order, gave figures for an order that is not
    the stamps'. Both now refuse it, in the same words."""
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter
    from gyroemu.pipelines.formats.messages import IMU
    from gyroemu.pipelines.jobs.estimate import estimate_log

    n = 400
    log_time = 1_700_000_000 * 10**9 + np.arange(n, dtype=np.int64) * 10_000_000
    stamps = log_time.copy()  # the header stamps; the messages are logged in order
    stamps[[100, 101]] = stamps[[101, 100]]
    stamps[300] = stamps[299]
    rng = np.random.default_rng(2)
    fields = {"angular_velocity": rng.normal(0, 1e-3, (n, 3)), "linear_acceleration": np.tile([0, 0, 9.81], (n, 1))}
    log = tmp_path / "swapped.mcap"
    with open(log, "wb") as f:
        writer = McapFileWriter(f)
        writer.add_messages([(writer.register_ros2_channel("/imu", IMU), log_time, IMU.encode(stamps, "imu", fields))])
        writer.finish()
    with pytest.raises(LogError) as estimated:
        estimate_log(log, tmp_path / "out.mcap")
    with pytest.raises(AllanLogError) as analysed:
        allan_of_log(log)
    assert "IMU stamps of device 'imu0' are not increasing: sample 101 at 1700000001.0 s follows 1700000001.01 s" in (
        str(analysed.value)
    )
    assert "(2 such steps)" in str(analysed.value) and str(analysed.value) == str(estimated.value)
