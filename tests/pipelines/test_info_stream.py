"""``gyroemu info`` reads a log in one pass in bounded memory, and finds what ``read_mcap`` finds."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from gyroemu.pipelines.formats import mcap_log
from gyroemu.pipelines.formats.mcap_log import read_mcap
from gyroemu.pipelines.jobs.info import log_info
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate

from ..foreign_bags import N, write_foreign_bag


def simulated(folder, seconds: float, device: str = "consumer_mems"):
    out = folder / f"{device}_{seconds:g}s.mcap"
    run_simulate(SimulateOptions(scenario="bench_static", out=out, device=device, duration=seconds, progress=False))
    return out


def read_mcap_devices(path):
    """(name, samples, span, rate, topics, metadata) per device, as read_mcap gives them."""
    out = []
    for name, dev in read_mcap(path).devices.items():
        t = dev.samples.t
        span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
        out.append(
            (name, len(t), span, (len(t) - 1) / span if span > 0 else float("nan"), dict(dev.topics), dev.metadata)
        )
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("info")
    return {
        "short": simulated(folder, 5.0),
        "long": simulated(folder, 20.0),
        "foreign": write_foreign_bag(folder / "bag"),
    }


@pytest.mark.parametrize("which", ["short", "foreign"])
def test_info_finds_the_devices_read_mcap_finds_without_decoding(logs, which, monkeypatch):
    """The same devices, counts, spans (of the header stamps: the foreign bag's log times are 1 ms
    later, so a span from log times would differ at its ends only, and a rate from them alike), topics
    and metadata; and read_mcap is not called."""
    expected = read_mcap_devices(logs[which])
    monkeypatch.setattr(mcap_log, "read_mcap", lambda *a, **k: pytest.fail("info decoded the log"))
    got = [(d.name, d.samples, d.span_s, d.rate_hz, d.topics, d.metadata) for d in log_info(logs[which]).devices]
    assert [g[0] for g in got] == [e[0] for e in expected]
    for g, e in zip(got, expected):
        assert g[1] == e[1] and g[2] == e[2] and g[4] == e[4] and g[5] == e[5]
        assert g[3] == e[3] or (np.isnan(g[3]) and np.isnan(e[3]))
    if which == "foreign":
        assert [d.samples for d in log_info(logs[which]).devices] == [N, N]


def test_info_memory_does_not_grow_with_the_log(logs):
    """Four times the messages, the same peak: one chunk at a time and fixed-size summaries (read_mcap
    holds every message; its peak grows with the log)."""

    def peak(path) -> int:
        tracemalloc.start()
        try:
            log_info(path)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    short, long = peak(logs["short"]), peak(logs["long"])
    size_ratio = logs["long"].stat().st_size / logs["short"].stat().st_size
    assert size_ratio > 3.5
    # Bounded: the longer log's peak within 25 % of the shorter's (a peak in proportion to the data
    # would be 3.5 times it or more).
    assert long < 1.25 * short, (short, long)


def test_replay_and_view_validate_a_log_in_bounded_memory(logs):
    """``check_mcap_noting`` (replay's and view's validation) decodes every message a chunk at a time:
    four times the messages, the same peak, and the channels and metadata read_mcap finds."""
    from gyroemu.pipelines.formats.mcap_log import check_mcap_noting

    def peak(path) -> int:
        tracemalloc.start()
        try:
            check_mcap_noting(path, print)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    short, long = peak(logs["short"]), peak(logs["long"])
    assert long < 1.25 * short, (short, long)  # in proportion to the data it would be 3.5 times or more
    for which in ("short", "foreign"):
        checked, read = check_mcap_noting(logs[which], print), read_mcap(logs[which])
        assert checked.channels == read.channels and checked.metadata == read.metadata
        assert checked.message_count == read.message_count


def test_a_corrupt_message_fails_validation_as_read_mcap_fails(tmp_path):
    """A message its type cannot decode (a frame id running past the payload) is refused by name before
    anything is served, as read_mcap refuses it; so is a log without IMU messages."""
    from gyroemu.errors import LogError
    from gyroemu.pipelines.formats.mcap_log import check_mcap_noting
    from gyroemu.pipelines.formats.mcap_records import McapFileWriter
    from gyroemu.pipelines.formats.messages import IMU, MAGNETIC_FIELD

    rows = IMU.encode(np.arange(1, 6) * 10**7, "imu")
    rows[3, 12] = 200  # frame_id length far past the message's end
    path = tmp_path / "corrupt.mcap"
    with open(path, "wb") as f:
        writer = McapFileWriter(f)
        writer.add_messages([(writer.register_ros2_channel("/imu", IMU), np.arange(1, 6) * 10**7, rows)])
        writer.finish()
    with pytest.raises(LogError, match="corrupt sensor_msgs/msg/Imu message") as checked:
        check_mcap_noting(path, print)
    with pytest.raises(LogError) as read:
        read_mcap(path)
    assert str(checked.value) == str(read.value)
    empty = tmp_path / "mag_only.mcap"
    with open(empty, "wb") as f:
        writer = McapFileWriter(f)
        mag = writer.register_ros2_channel("/mag", MAGNETIC_FIELD)
        writer.add_messages([(mag, [1], MAGNETIC_FIELD.encode([1], "imu"))])
        writer.finish()
    with pytest.raises(LogError, match="holds no sensor_msgs/msg/Imu messages"):
        check_mcap_noting(empty, print)


def test_info_says_whether_the_file_has_a_summary_and_indexes(tmp_path):
    """A writer's options decide what a reader can seek by: info says what the file has, not what
    gyroemu's writer would have written (it said "summary and indexes" of every complete file)."""
    from mcap.writer import IndexType
    from plain_mcap import write_plain_imu

    from gyroemu.pipelines.formats.messages import IMU

    rows = IMU.encode(np.arange(1, 101) * 10**7, "imu", {"linear_acceleration": np.tile([0.0, 0.0, 9.8], (100, 1))})
    bare = {
        "index_types": IndexType.NONE,
        "repeat_channels": False,
        "repeat_schemas": False,
        "use_statistics": False,
        "use_summary_offsets": False,
    }
    cases = {
        "indexed": ({}, "complete (summary and indexes)", True, True),
        "bare": (bare, "complete, without a summary or indexes", False, False),
        "unchunked": ({"use_chunking": False}, "complete (summary, no chunk indexes)", True, False),
    }
    for name, (options, state, summary, indexed) in cases.items():
        path = write_plain_imu(tmp_path / f"{name}.mcap", rows, **options)
        info = log_info(path)
        assert (info.summary, info.indexed) == (summary, indexed), name
        assert info.text().splitlines()[0].endswith(state), name
        assert (info.to_dict()["summary"], info.to_dict()["indexed"]) == (summary, indexed)
