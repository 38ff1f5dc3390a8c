"""``gyroemu bench --log`` a block at a time (:mod:`gyroemu.pipelines.jobs.bench_log`): the report of the log read
whole, but for the wall times, for every kind of log case; the same errors; logs one pass cannot pair
read whole; and memory that does not grow with the log.

Equal means equal: every metric of every run to the bit (the metrics do not depend on how the samples are
cut, ``test_bench_metrics.py``; the built-in filters give the same bytes in blocks, ``test_filter_blocks.py``),
the notes, the warnings and the error curves.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from memory_growth import assert_flat_when_streamed

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.formats.channels import ImuSeries
from gyroemu.pipelines.formats.device_stream import NotStreamable
from gyroemu.pipelines.formats.mcap_log import Recording, truth_series, write_mcap
from gyroemu.pipelines.jobs import bench_log
from gyroemu.pipelines.jobs.bench import BenchError, LogCase, run_bench
from gyroemu.sensors import load_device

RAISES = """\
import numpy as np
from gyroemu.pipelines.estimation.protocol import Estimate


class Raises:
    name = "raises"

    def __init__(self, setup):
        pass

    def process(self, t, gyro, accel, mag=None):
        raise RuntimeError("no estimate here")


class ShortByOne:
    name = "short"

    def __init__(self, setup):
        pass

    def process(self, t, gyro, accel, mag=None):
        return Estimate(q_wb=np.tile([1.0, 0.0, 0.0, 0.0], (len(t) - 1, 1)))
"""


def recording(seconds: float, seed: int, device: str = "consumer_mems", **changes) -> Recording:
    """The smooth manoeuvre measured by ``device``, its truth at the samples (``changes`` replace the
    recording's fields: a truth of another rate, a movement mask)."""
    scenario = load_scenario("smooth_manoeuvre")
    dev = load_device(device, seed=seed)
    traj = scenario.simulate(duration=seconds)
    samples = dev.measure(traj)
    rec = Recording(samples, truth=truth_series(traj, samples), device=dev)
    return dataclasses.replace(rec, **changes)


def bench_both(case: LogCase, filters: list[str]) -> tuple:
    """The bench of the log a block at a time and read whole: (reports, warnings) of each."""
    out = []
    for whole in (False, True):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            report = run_bench([dataclasses.replace(case, read_whole=whole)], filters=filters)
        out.append((report, [str(w.message) for w in caught]))
    return tuple(out)


def assert_same_report(streamed, whole) -> None:
    """Every figure but the wall times and settings, the notes and the error curves equal."""
    assert streamed.figures() == whole.figures()
    for a, b in zip(streamed.cases, whole.cases, strict=True):
        for fa, fb in zip(a.filters, b.filters, strict=True):
            for name in ("curve_t", "curve_total_deg", "curve_inclination_deg"):
                np.testing.assert_array_equal(getattr(fa, name), getattr(fb, name), err_msg=f"{fa.filter} {name}")


@pytest.fixture(scope="module")
def user_filters(tmp_path_factory):
    path = tmp_path_factory.mktemp("filters") / "failing.py"
    path.write_text(RAISES)
    return path


@pytest.fixture(scope="module")
def raises(user_filters):
    return f"{user_filters}:Raises"


def test_a_log_benched_in_blocks_is_the_whole_read(tmp_path, raises):
    """9D, the online built-ins and a filter that raises (diverged, its exception the reason, both ways)."""
    log = write_mcap(tmp_path / "run.mcap", recording(12.0, seed=1))
    (streamed, warned), (whole, warned_whole) = bench_both(LogCase(log), ["mekf", "madgwick", "vqf", raises])
    assert_same_report(streamed, whole)
    assert warned == warned_whole
    (case,) = streamed.cases
    assert case.mode == "9D" and case.samples == 12000 and case.notes == ["every sample counted"]
    failed = case.filters[-1].runs[0]
    assert failed.diverged and failed.reason == "process() raised RuntimeError: no estimate here"
    assert case.filters[0].runs[0].bias_error_deg_s is not None  # the truth's rate: the bias error


def test_a_sparse_truth_a_mask_and_the_offline_filters(tmp_path):
    """The truth every third sample, 0.1 ms off the samples' stamps (within a quarter interval), lost for
    a second; a movement mask over part of the run; 6D; the smoother (learning in blocks) and offline VQF
    (given every sample at once); the field's lag read from the log."""
    rec = recording(12.0, seed=2)
    t = rec.truth.t
    keep = (np.arange(len(t)) % 3 == 0) & ~((t > t[0] + 5.0) & (t < t[0] + 6.0))
    truth = ImuSeries(t=t[keep] + 1e-4, q_wb=rec.truth.q_wb[keep], omega_b=rec.truth.omega_b[keep])
    movement = np.zeros(len(rec.samples.t), bool)
    movement[2000:9000] = True
    log = write_mcap(tmp_path / "sparse.mcap", dataclasses.replace(rec, truth=truth, movement=movement))
    for case in (LogCase(log, six_d=True), LogCase(log, latency_s={"mag": "auto"})):
        (streamed, warned), (whole, warned_whole) = bench_both(case, ["mekf", "mekf-smooth", "offline-vqf"])
        assert_same_report(streamed, whole)
        assert warned == warned_whole
    note = streamed.cases[0].notes[0]
    assert note.startswith("the 7000 samples of its movement mask counted, ") and "without a finite reference" in note


def test_a_truth_without_rates(tmp_path):
    """A truth of attitudes only (as BROAD's optical one: its rates written "no estimate", the covariance's
    first element −1 over zero values): no bias error either way, the same report."""
    rec = recording(6.0, seed=3)
    truth = ImuSeries(t=rec.truth.t, q_wb=rec.truth.q_wb)
    log = write_mcap(tmp_path / "no_rates.mcap", dataclasses.replace(rec, truth=truth))
    (streamed, _), (whole, _) = bench_both(LogCase(log), ["mekf"])
    assert_same_report(streamed, whole)
    assert streamed.cases[0].filters[0].runs[0].bias_error_deg_s is None


@pytest.mark.parametrize("device, six_d", [("consumer_mems", False), ("navigation_fog", True)])
def test_small_chunks_the_filters_start_alike(tmp_path, device, six_d):
    """Chunks of 4 kB (a few samples each): every filter still starts from the same first block as the
    whole read (the MEKF reads its first 0.5 s, and 10 s at rest to find north from Earth's rate in 6D
    with a navigation gyro), so the reports are equal."""
    log = write_mcap(tmp_path / "small.mcap", recording(14.0, seed=8, device=device), chunk_size=1 << 12)
    (streamed, _), (whole, _) = bench_both(LogCase(log, six_d=six_d), ["mekf", "mekf-smooth", "vqf"])
    assert_same_report(streamed, whole)


def test_a_truth_that_starts_late(tmp_path):
    """The reference acquired 1 s in: the first chunks hold no truth message (the census read the truth's
    columns before any had come, and failed); the samples before it count without a reference."""
    rec = recording(3.0, seed=10)
    late = slice(1000, None)
    truth = ImuSeries(t=rec.truth.t[late], q_wb=rec.truth.q_wb[late], omega_b=rec.truth.omega_b[late])
    log = write_mcap(tmp_path / "late.mcap", dataclasses.replace(rec, truth=truth), chunk_size=1 << 14)
    (streamed, warned), (whole, warned_whole) = bench_both(LogCase(log), ["mekf"])
    assert_same_report(streamed, whole)
    assert warned == warned_whole
    assert streamed.cases[0].notes == ["every sample counted, 1000 of them without a finite reference (ignored)"]


def test_a_filter_short_by_one_is_said_alike(tmp_path, user_filters):
    """A user's filter returning one attitude fewer than it was given, on a log longer than the first
    block: diverged with the same reason both ways (it named the block's length, not the log's)."""
    log = write_mcap(tmp_path / "short.mcap", recording(62.0, seed=12))
    (streamed, _), (whole, _) = bench_both(LogCase(log), [f"{user_filters}:ShortByOne"])
    assert_same_report(streamed, whole)
    assert streamed.cases[0].filters[0].runs[0].reason == (
        "process() raised ValueError: short.process() returned 1 attitude fewer than the samples it was given"
    )


def test_two_bad_devices_refused_in_the_whole_reads_order(tmp_path):
    """Two devices, the first with some NaN samples or no reference at its stamps, the second's gyro all
    NaN: the same first error, after the same warnings, as the log read whole (device by device)."""
    rng = np.random.default_rng(13)

    def gyro_nan(rec, rows):
        gyro = rec.samples.gyro.copy()
        gyro[rows] = np.nan
        return dataclasses.replace(rec, samples=dataclasses.replace(rec.samples, gyro=gyro))

    second = gyro_nan(recording(2.0, seed=14, device="tactical_mems"), slice(None))
    second = dataclasses.replace(second, samples=dataclasses.replace(second.samples, device="second"))
    first = recording(2.0, seed=15)
    far = dataclasses.replace(first, truth=dataclasses.replace(first.truth, t=first.truth.t + 5e-4))
    for rec in (gyro_nan(first, rng.choice(2000, 5, replace=False)), far):
        log = write_mcap(tmp_path / "two.mcap", [rec, second], prefix_topics=True)
        said = []
        for whole in (False, True):
            with warnings.catch_warnings(record=True) as caught, pytest.raises(Exception) as e:  # noqa: PT011
                warnings.simplefilter("always")
                run_bench([LogCase(log, read_whole=whole)], filters=["mekf"])
            said.append((type(e.value), str(e.value), [str(w.message) for w in caught]))
        assert said[0] == said[1]


def test_a_log_refused_warns_first_both_ways(tmp_path):
    """A log with no IMU topic, only a string topic: the same warning (its topic skipped), then the same
    error, both ways (the streamed read dropped the warnings its passes had recorded)."""
    from gyroemu.errors import LogError
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter

    path = tmp_path / "noimu.mcap"
    with open(path, "wb") as f:
        w = McapFileWriter(f)
        schema = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = w.register_channel("/chatter", "cdr", schema, {})
        payload = np.frombuffer(bytes([0, 1, 0, 0, 3, 0, 0, 0, 104, 105, 0, 0]), np.uint8)
        w.add_messages([(channel, np.arange(5) * 10**6, np.tile(payload, (5, 1)))])
        w.finish()
    said = []
    for whole in (False, True):
        with warnings.catch_warnings(record=True) as caught, pytest.raises(LogError) as e:
            warnings.simplefilter("always")
            run_bench([LogCase(path, read_whole=whole)], filters=["mekf"])
        said.append((str(e.value), [str(w.message) for w in caught]))
    assert said[0] == said[1] and "skipping topic /chatter" in said[0][1][0]


def test_two_devices_each_a_case(tmp_path):
    """A log of two devices: each its own case, named file:device, both equal to the whole read's."""
    recs = [recording(6.0, seed=3), dataclasses.replace(recording(6.0, seed=4, device="tactical_mems"))]
    recs[1] = dataclasses.replace(recs[1], samples=dataclasses.replace(recs[1].samples, device="second"))
    log = write_mcap(tmp_path / "two.mcap", recs, prefix_topics=True)
    (streamed, _), (whole, _) = bench_both(LogCase(log), ["mekf", "madgwick"])
    assert_same_report(streamed, whole)
    assert [c.name for c in streamed.cases] == ["two.mcap:consumer_mems", "two.mcap:second"]


def test_a_log_one_pass_cannot_pair_is_read_whole(tmp_path, monkeypatch):
    """A truth with a stamp twice (a reference that re-stamped itself): one pass cannot pair it, so the log
    is read whole, with the report of ``read_whole``; a block-at-a-time read refuses it as such."""
    rec = recording(4.0, seed=5)
    t = rec.truth.t.copy()
    t[2001] = t[2000]
    log = write_mcap(tmp_path / "back.mcap", dataclasses.replace(rec, truth=dataclasses.replace(rec.truth, t=t)))
    with pytest.raises(NotStreamable):
        bench_log.stream_log_devices(LogCase(log))
    (streamed, warned), (whole, warned_whole) = bench_both(LogCase(log), ["mekf"])
    assert_same_report(streamed, whole)
    assert warned == warned_whole


@pytest.mark.parametrize(
    "change, message",
    [
        ({"truth": None}, "has no truth channel (/truth/imu with the true attitude)"),
        ("far", "the truth channel of device 'consumer_mems' has no finite attitude at the IMU's stamps"),
        ({"device": "other"}, "no device 'other' (devices: consumer_mems)"),
    ],
)
def test_the_same_errors_before_any_filter_runs(tmp_path, change, message):
    """No truth, a truth nowhere near the samples' stamps (half an interval off), a device not in the log:
    the whole read's errors, naming the file, from the passes before the filters."""
    rec = recording(2.0, seed=6)
    case = LogCase(tmp_path / "bad.mcap")
    if change == "far":
        rec = dataclasses.replace(rec, truth=dataclasses.replace(rec.truth, t=rec.truth.t + 5e-4))
    elif "truth" in change:
        rec = dataclasses.replace(rec, **change)
    else:
        case = LogCase(tmp_path / "bad.mcap", **change)
    write_mcap(case.path, rec)
    for whole in (False, True):
        with pytest.raises(BenchError, match=message.replace("(", r"\(").replace(")", r"\)")):
            run_bench([dataclasses.replace(case, read_whole=whole)], filters=["mekf"])


def test_a_mounted_devices_log_is_benched_as_the_body(tmp_path):
    """Logs of the ideal IMU unmounted and mounted 90° about x or 130° about (1, −2, 3) (the mounting in
    each log's embedded device config): benched a block at a time and read whole, the MEKF's and the
    smoother's figures are the unmounted log's to round-off (they are equivariant under a constant turn
    of the sensor's axes: 1e-6°, 1e-9 °/s, measured 1e-12°); the sensor's attitude compared with the
    body's truth (the fault) is off by the mounting, 90° or 130°."""
    from mounted_devices import mounted_ideal_configs

    figures = {}
    for name, config in mounted_ideal_configs(tmp_path).items():
        log = write_mcap(tmp_path / f"{name}.mcap", recording(10.0, seed=1, device=str(config)))
        (streamed, _), (whole, _) = bench_both(LogCase(log), ["mekf", "mekf-smooth"])
        assert_same_report(streamed, whole)
        figures[name] = [(f.filter, f.runs[0]) for f in streamed.cases[0].filters]
    reference = figures.pop("none")
    for name, runs in figures.items():
        for (spec, run), (_, ref) in zip(runs, reference, strict=True):
            assert not run.diverged and ref.total_deg < 10.0, (name, spec)  # the filters work on this log
            for metric in ("total_deg", "heading_deg", "inclination_deg"):
                assert abs(getattr(run, metric) - getattr(ref, metric)) <= 1e-6, (name, spec, metric)
            assert abs(run.bias_error_deg_s - ref.bias_error_deg_s) <= 1e-9, (name, spec)
            assert run.convergence_s == ref.convergence_s, (name, spec)


@pytest.mark.slow
def test_memory_does_not_grow_with_the_log(tmp_path):
    """Python's peak allocation (tracemalloc sees NumPy's buffers) for a log 4× longer: the same within the
    chunks' and blocks' buffers a block at a time; read whole, it grows with the samples."""
    logs = {m: write_mcap(tmp_path / f"m{m}.mcap", recording(60.0 * m, seed=7)) for m in (2, 8)}
    assert_flat_when_streamed(
        lambda minutes, whole: run_bench([LogCase(logs[minutes], read_whole=whole)], filters=["mekf", "madgwick"])
    )
