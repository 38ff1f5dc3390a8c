"""``gyroemu estimate`` a block at a time: the device's samples as ``read_mcap`` pairs them whole
(:class:`DeviceStream`), and the written file byte for byte the one of a log read whole, in memory that
does not grow with the log."""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import numpy as np
import pytest
from memory_growth import assert_flat_when_streamed

from gyroemu.pipelines.estimation.series import check_samples, rate_of
from gyroemu.pipelines.formats.channels import role_message_type
from gyroemu.pipelines.formats.device_stream import (
    FIRST_BLOCK_S,
    DeviceCensus,
    DeviceStream,
    NotStreamable,
    RateCounter,
    count_samples,
    scan_devices,
)
from gyroemu.pipelines.formats.mcap_log import (
    LogWarning,
    Recording,
    read_mcap,
    truth_pose,
    truth_series,
    unpaired_field,
    write_mcap,
)
from gyroemu.pipelines.formats.mcap_records import McapFileWriter, McapRecordWalk, RawMessages
from gyroemu.pipelines.formats.messages import FLAG, IMU, MAGNETIC_FIELD, POSE_STAMPED
from gyroemu.pipelines.jobs.estimate import estimate_log

from ..foreign_bags import write_foreign_bag

T0_NS = 1_700_000_000 * 10**9


def crafted_log(
    path,
    n=3000,
    chunk_size=2048,
    *,
    drop_raw=(),
    drop_mag=(),
    drop_flag=(),
    nan=(),
    pose=True,
    poses=None,
    mag_every=1,
    mag_offset_ns=0,
):
    """A device's topics written message by message: /imu at 100 Hz (rows ``nan`` NaN), /raw/mems,
    /mag, /movement and /truth/pose at the same stamps but where dropped (the first ``poses`` poses only:
    all when None), in small chunks (a chunk ends between an /imu message and its /mag). The field on a
    clock of its own: every ``mag_every``-th of its messages, ``mag_offset_ns`` from the sample's stamp."""
    rng = np.random.default_rng(11)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    gyro = rng.normal(0, 0.02, (n, 3))
    accel = rng.normal(0, 0.1, (n, 3)) + [0.3, -0.2, 9.8]
    gyro[list(nan)] = np.nan
    field = np.tile([2e-5, 1e-6, -4e-5], (n, 1)) + rng.normal(0, 1e-7, (n, 3))
    keep = lambda dropped: np.setdiff1d(np.arange(n), np.asarray(dropped, dtype=int))  # noqa: E731
    raw_type = role_message_type("raw/mems")
    with open(path, "wb") as f:
        w = McapFileWriter(f, chunk_size=chunk_size)
        imu = w.register_ros2_channel("/imu", IMU)
        mag = w.register_ros2_channel("/mag", MAGNETIC_FIELD)
        raw = w.register_ros2_channel("/raw/mems", raw_type)
        flag = w.register_ros2_channel("/movement", FLAG)
        k_raw, k_mag, k_flag = keep(drop_raw), keep(drop_mag)[::mag_every], keep(drop_flag)
        mag_ns = stamps[k_mag] + mag_offset_ns
        channels = [
            (imu, stamps, IMU.encode(stamps, "imu", {"angular_velocity": gyro, "linear_acceleration": accel})),
            (raw, stamps[k_raw], raw_type.encode(stamps[k_raw], "imu")),
            (mag, mag_ns, MAGNETIC_FIELD.encode(mag_ns, "imu", {"magnetic_field": field[k_mag]})),
            (flag, stamps[k_flag], FLAG.encode(stamps[k_flag], "imu", {"data": np.ones(len(k_flag), bool)})),
        ]
        if pose:
            p = w.register_ros2_channel("/truth/pose", POSE_STAMPED)
            position = np.cumsum(rng.normal(0, 1e-3, (n, 3)), axis=0)[:poses]
            channels.append((p, stamps[:poses], POSE_STAMPED.encode(stamps[:poses], "map", {"position": position})))
        w.add_messages(channels)
        w.finish()
    return path


def split(batch: RawMessages, rng: np.random.Generator) -> list[RawMessages]:
    """A chunk's messages cut at random places (a single message among the pieces)."""
    n = len(batch.size)
    cuts = np.unique(np.concatenate(([0, n], rng.integers(0, n + 1, 3))))
    return [
        RawMessages(
            batch.channel_id[i:j],
            batch.sequence[i:j],
            batch.log_time[i:j],
            batch.publish_time[i:j],
            batch.buffer,
            batch.start[i:j],
            batch.size[i:j],
        )  # fmt: skip
        for i, j in zip(cuts[:-1], cuts[1:])
    ]


def streamed(path, pair_pose=True, seed=0):
    """The log's one device read a block at a time, the blocks joined, and the stream and its census."""
    log = read_mcap(path)
    (dev,) = log.devices.values()
    ids = {c.topic: i for i, c in McapRecordWalk(path).channels.items()}
    walk = McapRecordWalk(path)
    rng = np.random.default_rng(seed)
    stream, census, blocks = None, DeviceCensus(), []
    for whole in walk.batches():
        if stream is None:
            ids = {c.topic: i for i, c in walk.channels.items()}
            roles = {role: (ids[topic], role_message_type(role)) for role, topic in dev.topics.items()}
            stream = DeviceStream(roles, pair_pose=pair_pose)
        for batch in split(whole, rng):
            stream.feed(batch)
            blocks.append(stream.take())
            census.add(blocks[-1])
    blocks.append(stream.take(final=True))
    census.add(blocks[-1])
    return dev, stream, census, blocks


@pytest.mark.parametrize(
    "damage",
    [
        {},
        {"drop_raw": [5, 6, 999, 2999], "drop_mag": [0, 40, 41, 1500], "drop_flag": [7, 2000], "nan": [3, 300]},
        {"drop_mag": list(range(100, 3000))},  # the field ends early
        {"mag_offset_ns": 1000, "drop_raw": [5, 6, 999]},  # a field 1 µs after each sample: the next one's
        {"mag_offset_ns": -3_000_000, "mag_every": 7, "drop_mag": [40]},  # its own, slower clock
    ],
    ids=["whole", "gaps", "field-ends", "field-late", "field-slower"],
)
def test_stream_pairs_the_topics_as_read_mcap(tmp_path, damage, request):
    case = request.node.callspec.id
    path = crafted_log(tmp_path / "log.mcap", **damage)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        dev, stream, census, blocks = streamed(path)
    want = dev.samples
    got = np.concatenate([b.stamp_ns for b in blocks])
    pieces = max(len(b) for b in blocks) < len(want.t) / 10  # read a little at a time
    # a field that ends early holds every later sample until the file ends: the field might yet come
    assert pieces == (len(damage.get("drop_mag", [])) < 100) and len(blocks) > 50
    assert np.array_equal(got, dev.stamp_ns)
    for name in ("gyro", "accel", "mag"):
        assert np.concatenate([getattr(b, name) for b in blocks]).tobytes() == getattr(want, name).tobytes(), name
    assert stream.raw_dropped == {"raw/mems": len(damage.get("drop_raw", []))}
    assert stream.movement_missing == len(set(damage.get("drop_flag", [])) - set(damage.get("drop_raw", [])))
    assert census.count == len(want.t) and census.has_mag == want.has_mag
    assert census.finite == int(np.isfinite(want.gyro).all(axis=1).sum())
    assert census.rate.rate() == rate_of(dev.stamp_ns)  # the same float
    assert census.pose_pairs(stream) == (len(damage.get("drop_raw", [])) == 0)  # a pose per sample kept
    read_warnings = [str(w.message) for w in caught if "have no message" in str(w.message)]
    assert len(read_warnings) == bool(damage.get("drop_raw")) + bool(damage.get("drop_flag"))
    # The field's messages no sample takes (match_latest): at a dropped sample's stamp, before a kept
    # sample's own (gaps: 5 and 6 before 7, 999 before 1000, 2999 after the last kept), after the last
    # sample (late), before the first with no sample before it to open its interval (slower).
    unused = {"whole": 0, "gaps": 4, "field-ends": 0, "field-late": 4, "field-slower": 1}[case]
    messages = len(np.setdiff1d(np.arange(3000), damage.get("drop_mag", []))[:: damage.get("mag_every", 1)])
    assert stream.field_used == messages - unused
    notes = [str(w.message) for w in caught if "are not used" in str(w.message)]
    assert notes == [unpaired_field(path, unused, messages, "/imu", "/mag")] * bool(unused)
    assert "1 of 7 messages on /mag are not used: before the first sample of /imu, after its last" in (
        unpaired_field(path, 1, 7, "/imu", "/mag")
    )


def test_rate_counter_is_numpys_median():
    """The counted rate is ``1e9 / median(diff(stamp_ns))`` to the bit, blocks or not, for clocked
    stamps (few distinct intervals), jittered ones (every interval its own) and an even or odd count,
    and for more intervals than it holds before merging a block's in (``test_log_rate.py``: any cut)."""
    rng = np.random.default_rng(2)
    for n in (2, 3, 1000, 1001):
        for stamps in (
            10**9 + np.arange(n, dtype=np.int64) * 5_000_000,
            T0_NS + np.cumsum(rng.integers(4_000_000, 6_000_000, n)),
            np.cumsum(rng.choice([10_000_000, 10_000_000, 11_000_000], n)),
        ):
            counter = RateCounter()
            for piece in np.array_split(stamps, rng.integers(1, 6)):
                counter.add(piece)
            assert counter.rate() == rate_of(stamps) == 1e9 / float(np.median(np.diff(stamps)))
    # a jittered clock: every interval its own, merged in several times along the way
    stamps = T0_NS + np.cumsum(rng.integers(900_000, 1_100_000, 300_001))
    counter = RateCounter()
    for piece in np.array_split(stamps, 300):
        counter.add(piece)
    assert counter.rate() == rate_of(stamps)


def test_check_samples_counts_as_before():
    """check_samples is check_counts on what it counts (the same errors and note)."""
    t = np.arange(5) * 0.01
    g, a = np.zeros((5, 3)), np.zeros((5, 3))
    g[1] = np.nan
    assert "1 of 5 IMU samples of device 'd' hold NaN" in check_samples("f", "d", t, g, a)
    with pytest.raises(Exception, match="has 1 IMU sample"):
        check_samples("f", "d", t[:1], g[:1], a[:1])
    with pytest.raises(Exception, match="not increasing: sample 2"):
        check_samples("f", "d", t[[0, 1, 1, 3, 4]], g, a)


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def both(tmp_path, log, **options):
    """The estimate written a block at a time and read whole: their sha256 and the warnings of each."""
    out = {}
    for whole in (False, True):
        target = tmp_path / f"{log.stem}_out_{whole}.mcap"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            summary = estimate_log(log, target, read_whole=whole, **options)
        notes = sorted(str(w.message) for w in caught if issubclass(w.category, UserWarning))
        out[whole] = (digest(target), notes, summary.devices, summary.topics, summary.field_lags)
    return out


def simulated_log(folder, scenario_name: str, device_name: str):
    """A log of 75 s (longer than the first block) as ``gyroemu simulate`` writes it (truth, pose, raw
    observables), in 64 kB chunks."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.sensors import load_device

    scenario = load_scenario(scenario_name)
    device = load_device(device_name, seed=4)
    traj = scenario.simulate(duration=1.25 * FIRST_BLOCK_S)
    samples = device.measure(traj)
    recording = Recording(samples, truth=truth_series(traj, samples), pose=truth_pose(traj, samples), device=device)
    log = write_mcap(folder / f"{device_name}.mcap", recording, scenario=scenario, chunk_size=1 << 16)
    assert set(read_mcap(log).device.topics) >= {"imu", "truth/pose"}
    return log


@pytest.fixture(scope="module")
def manoeuvre_log(tmp_path_factory):
    return simulated_log(tmp_path_factory.mktemp("sim"), "smooth_manoeuvre", "aktos_t_broad")  # 286 Hz, timed


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"use_mag": False},
        {"filter_name": "vqf"},
        {"latency_s": {"gyro": 0.004, "mag": 0.012}},
        {"filter_name": "mekf-smooth"},  # learned a block at a time, its storage on disk
        {"filter_name": "mekf-smooth", "latency_s": {"gyro": 0.004, "mag": 0.012}},
        {"latency_s": {"mag": "auto"}},  # the field's lag read from every sample
    ],
    ids=["9D", "6D", "vqf", "timed", "smoother", "timed-smoother", "field-lag"],
)
def test_streamed_estimate_is_the_whole_reads_bytes_on_a_gyroemu_log(manoeuvre_log, tmp_path, options):
    """The estimate, its /tf at the poses and every copied record, byte for byte."""
    if options.get("filter_name") == "vqf":
        pytest.importorskip("vqf")
    out = both(tmp_path, manoeuvre_log, **options)
    assert out[False] == out[True]


def test_streamed_estimate_of_a_gyrocompass(tmp_path):
    """A navigation FOG at rest finds north from Earth's rate over the first 10 s of its first block."""
    out = both(tmp_path, simulated_log(tmp_path, "bench_static", "navigation_fog"))
    assert out[False] == out[True]


def test_streamed_estimate_on_damaged_and_foreign_logs(tmp_path):
    """Dropped raw, field and flag messages, NaN samples, and a /truth/pose that pairs; then someone
    else's bag (rosbags) with two IMU topics: the same bytes and warnings both ways."""
    log = crafted_log(tmp_path / "gaps.mcap", n=9000, drop_raw=[5, 8000], drop_mag=[0, 4000], drop_flag=[7], nan=[30])
    out = both(tmp_path, log)
    assert out[False] == out[True]
    assert any("hold NaN" in n for n in out[False][1]) and any("dropped" in n for n in out[False][1])
    bag = write_foreign_bag(tmp_path / "bag")
    out = both(tmp_path, bag, topic="/imu_b", filter_name="madgwick")
    assert out[False] == out[True]


@pytest.mark.parametrize("filter_name", ["mekf", "mekf-smooth"])
def test_streamed_estimate_of_two_devices_at_two_rates(tmp_path, filter_name):
    """A gyroemu log of two devices sampling at 286 and 200 Hz in small chunks, each filtered into its
    own topic (the first one's estimate on /tf): every chunk waits for both, the same bytes; the
    smoother learns both devices in one pass."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.sensors import load_device

    scenario = load_scenario("smooth_manoeuvre")
    traj = scenario.simulate(duration=1.25 * FIRST_BLOCK_S)
    recordings = []
    for name in ("aktos_t_broad", "classic_rate_gyro"):
        device = load_device(name, seed=2)
        samples = device.measure(traj)
        recordings.append(Recording(samples, pose=truth_pose(traj, samples), device=device))
    log = write_mcap(tmp_path / "two.mcap", recordings, scenario=scenario, chunk_size=1 << 15)
    assert sorted(read_mcap(log).devices) == ["aktos_t_broad", "classic_rate_gyro"]
    out = both(tmp_path, log, filter_name=filter_name)
    assert out[False] == out[True]
    assert [t[1] for t in out[False][3]] == ["/aktos_t_broad/estimate/imu", "/classic_rate_gyro/estimate/imu"]


def test_a_log_one_pass_cannot_pair_is_read_whole(tmp_path):
    """Chunks that go back in time (the field of the first seconds written last): estimated as a whole
    read does it, not refused."""
    n = 3000
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    rng = np.random.default_rng(1)
    path = tmp_path / "late.mcap"
    with open(path, "wb") as f:
        w = McapFileWriter(f, chunk_size=4096)
        imu, mag = w.register_ros2_channel("/imu", IMU), w.register_ros2_channel("/mag", MAGNETIC_FIELD)
        accel = rng.normal(0, 0.1, (n, 3)) + [0, 0, 9.8]
        w.add_messages([(imu, stamps, IMU.encode(stamps, "imu", {"linear_acceleration": accel}))])
        field = MAGNETIC_FIELD.encode(stamps, "imu", {"magnetic_field": np.tile([2e-5, 0, -4e-5], (n, 1))})
        w.add_messages([(mag, stamps[n // 2 :], field[n // 2 :])])
        w.add_messages([(mag, stamps[: n // 2], field[: n // 2])])  # earlier log times, later in the file
        w.finish()
    devices, _ = scan_devices(path)
    with pytest.raises(NotStreamable, match="back in log time"):
        count_samples(path, devices, None, set(devices), FIRST_BLOCK_S)
    out = both(tmp_path, path)
    assert out[False] == out[True]


def late_and_ending_log(path, n=3000):
    """/status (a topic of no device) at 100 Hz from a second before the IMU's first message, /imu at 100 Hz; /mag
    for the first third of the samples, /raw/mems for the first two thirds (the whole read drops the
    samples after: no raw message at their stamp); 1 kB chunks."""
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    status = T0_NS - 10**9 + np.arange(100, dtype=np.int64) * 10**7  # chunks of it alone before the IMU's
    rng = np.random.default_rng(4)
    accel = rng.normal(0, 0.1, (n, 3)) + [0.3, -0.2, 9.8]
    field = np.tile([2e-5, 1e-6, -4e-5], (n, 1)) + rng.normal(0, 1e-7, (n, 3))
    raw_type, raw = role_message_type("raw/mems"), 2 * n // 3
    with open(path, "wb") as f:
        w = McapFileWriter(f, chunk_size=1024)
        channels = [
            (
                w.register_ros2_channel("/status", FLAG),
                status,
                FLAG.encode(status, "imu", {"data": np.ones(100, bool)}),
            ),
            (w.register_ros2_channel("/imu", IMU), stamps, IMU.encode(stamps, "imu", {"linear_acceleration": accel})),
            (w.register_ros2_channel("/raw/mems", raw_type), stamps[:raw], raw_type.encode(stamps[:raw], "imu")),
            (
                w.register_ros2_channel("/mag", MAGNETIC_FIELD),
                stamps[: n // 3],
                MAGNETIC_FIELD.encode(stamps[: n // 3], "imu", {"magnetic_field": field[: n // 3]}),
            ),
        ]
        w.add_messages(channels)
        w.finish()
    return path


def test_a_late_imu_and_topics_that_end_early(tmp_path, monkeypatch):
    """Chunks with no IMU message first (the stream took from an IMU topic with nothing read, and failed);
    a field that stops and a raw topic that ends early (the IMU messages after the raw topic's end all
    dropped: the copy looked up an estimate it had already written, and failed): the whole read's
    bytes and warnings, without reading the log whole. And once a paired topic has given every message
    the scan counted, it holds no sample back: every block is decided up to the last IMU message read
    (before, every sample after the field's end waited, and every chunk with it, to the file's end)."""
    from gyroemu.pipelines.formats import mcap_log

    log = late_and_ending_log(tmp_path / "late.mcap")
    with monkeypatch.context() as m, warnings.catch_warnings(record=True) as caught:
        m.setattr(mcap_log, "read_mcap", lambda *a, **k: pytest.fail("the log was read whole"))
        warnings.simplefilter("always")
        summary = estimate_log(log, tmp_path / "streamed.mcap")
    notes = sorted(str(w.message) for w in caught if issubclass(w.category, UserWarning))
    streamed = (digest(tmp_path / "streamed.mcap"), notes, summary.devices)
    out = both(tmp_path, log)
    assert streamed == out[True][:3]
    assert any("dropped" in note for note in streamed[1])
    with pytest.warns(UserWarning, match="skipping topic /status"):  # the log's flag of no IMU, as estimate said
        (device,) = scan_devices(log)[0].values()
    stream = DeviceStream(device.channels, messages=device.messages)
    for batch in McapRecordWalk(log).batches():
        fed = stream.feed(batch)
        block = stream.take()
        if fed is not None and fed > T0_NS + 2 * 3000 // 3 * 10_000_000:  # the raw topic and the field have ended
            assert block.through_ns == fed


def test_a_pose_topic_that_ends_early_holds_nothing_back(tmp_path):
    """/truth/pose for the first half of the samples only: once its last message is read, the samples
    after it need none, and every block is decided up to the last IMU message read but one (whose /mag the
    next chunk holds; before, every later sample waited for a pose that never came, to the file's end);
    the estimate is the whole read's."""
    log = crafted_log(tmp_path / "poses.mcap", n=9000, poses=4500)
    (device,) = scan_devices(log)[0].values()
    stream = DeviceStream(device.channels, pair_pose=True, messages=device.messages)
    decided = 0
    for batch in McapRecordWalk(log).batches():
        fed = stream.feed(batch)
        block = stream.take()
        if fed is not None and fed > T0_NS + 4600 * 10_000_000:  # the poses have ended
            assert block.through_ns is not None and block.through_ns >= fed - 10_000_000  # its /mag: next chunk
            decided += 1
    assert decided > 10
    out = both(tmp_path, log)
    assert out[False] == out[True]


def test_stamps_a_nanosecond_apart_are_refused_both_ways(tmp_path):
    """Two IMU stamps 1 ns apart at today's epoch are one float second (the filters' time): the whole read
    refuses the log naming the sample, and so does the streamed one (it wrote an output before, or
    failed with the filter's own error)."""
    from gyroemu.errors import LogError

    n = 500
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    seconds = stamps / 1e9  # as ns_to_stamps has them
    k = 1 + next(j for j in range(200, n) if (stamps[j] + 1) / 1e9 == seconds[j])  # not at a rounding midpoint
    stamps[k] = stamps[k - 1] + 1
    path = tmp_path / "ns.mcap"
    with open(path, "wb") as f:
        w = McapFileWriter(f, chunk_size=4096)
        accel = np.tile([0.0, 0.0, 9.8], (n, 1))
        w.add_messages(
            [(w.register_ros2_channel("/imu", IMU), stamps, IMU.encode(stamps, "imu", {"linear_acceleration": accel}))]
        )
        w.finish()
    errors = []
    for whole in (False, True):
        with pytest.raises(LogError, match=f"IMU stamps of device 'imu0' are not increasing: sample {k} at") as e:
            estimate_log(path, tmp_path / f"out{whole}.mcap", read_whole=whole, filter_name="madgwick")
        errors.append(str(e.value))
    assert errors[0] == errors[1] and not list(tmp_path.glob("out*"))


@pytest.mark.slow
@pytest.mark.parametrize("filter_name", ["mekf", "mekf-smooth"])
def test_memory_does_not_grow_with_the_log(tmp_path, filter_name):
    """Python's peak allocation (tracemalloc sees NumPy's buffers) for a log 4× longer: the same within
    the chunk and first-block buffers when streamed (the smoother: and a stretch of its windows, its
    storage on disk); read whole, it grows with the samples."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.sensors import load_device

    scenario = load_scenario("smooth_manoeuvre")
    logs = {}
    for minutes in (2, 8):
        device = load_device("consumer_mems", seed=1)
        logs[minutes] = tmp_path / f"m{minutes}.mcap"
        samples = device.measure(scenario.simulate(duration=60.0 * minutes))
        write_mcap(logs[minutes], Recording(samples=samples, device=device))
    assert_flat_when_streamed(
        lambda minutes, whole: estimate_log(
            logs[minutes], tmp_path / f"e{minutes}{whole}.mcap", read_whole=whole, filter_name=filter_name
        )
    )


def test_the_smoother_spools_beside_the_output(manoeuvre_log, tmp_path, monkeypatch):
    """``--smooth`` keeps its storage in nameless temporary files in the output's folder (a small /tmp
    could not hold hours of it), timed or not, and leaves nothing there but the output."""
    import tempfile
    import types

    from gyroemu.pipelines.estimation import mekf_smoother_spool

    folders, original = [], tempfile.TemporaryFile

    def temporary_file(dir=None):  # noqa: A002 - tempfile's own keyword
        folders.append(dir)
        return original(dir=dir)

    # the spool's own name for the module, not tempfile's attribute (numba's cache writes use it too)
    monkeypatch.setattr(mekf_smoother_spool, "tempfile", types.SimpleNamespace(TemporaryFile=temporary_file))
    out = tmp_path / "out" / "smoothed.mcap"
    out.parent.mkdir()
    estimate_log(manoeuvre_log, out, filter_name="mekf-smooth", latency_s={"gyro": 0.004})
    assert folders and all(Path(f) == out.parent for f in folders)
    assert sorted(p.name for p in out.parent.iterdir()) == ["smoothed.mcap"]
