"""The paced publisher's waiting machinery (:class:`gyroemu.pipelines.transport.zenoh_io.Timing`), without timing
figures:
what it changes in the process and puts back, that it never sends before a deadline, and that a
schedule of batches goes out complete and in order. The figures are ``tests/benchmarks/bench_replay.py``'s.
"""

import gc
import sys
import time

import pytest

zenoh = pytest.importorskip("zenoh")

from gyroemu.pipelines.transport import zenoh_io  # noqa: E402
from gyroemu.pipelines.transport.zenoh_io import PRECISE, SLEEP_ONLY, PacedPublisher, Timing, hot_loop  # noqa: E402


def _read_slack():
    """This thread's timer slack (ns), Linux."""
    import ctypes

    return ctypes.CDLL(None).prctl(zenoh_io._PR_GET_TIMERSLACK, 0, 0, 0, 0)


def _slack():
    return _read_slack() if sys.platform.startswith("linux") else None


def test_hot_loop_sets_and_restores_the_process_settings():
    interval, enabled, slack = sys.getswitchinterval(), gc.isenabled(), _slack()
    with hot_loop(PRECISE):
        assert sys.getswitchinterval() == pytest.approx(PRECISE.switch_interval_s)
        assert not gc.isenabled() and gc.get_freeze_count() > 0
        if sys.platform.startswith("linux"):
            assert _read_slack() == PRECISE.timer_slack_ns
    assert (sys.getswitchinterval(), gc.isenabled(), _slack()) == (interval, enabled, slack)
    assert gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError):
        with hot_loop(Timing(switch_interval_s=1e-3, timer_slack_ns=1000)):
            raise RuntimeError("inside")
    assert (sys.getswitchinterval(), gc.isenabled(), _slack()) == (interval, enabled, slack)
    with hot_loop(SLEEP_ONLY):  # changes nothing
        assert (sys.getswitchinterval(), gc.isenabled(), _slack()) == (interval, enabled, slack)


def test_wait_until_never_returns_before_the_deadline():
    start = time.monotonic_ns()
    for k in range(1, 101):
        deadline = start + k * 300_000  # every 0.3 ms: some deadlines land inside the spin, some after a sleep
        for spin_ns in (0, 100_000, 1_000_000):
            now = zenoh_io._wait_until(deadline, spin_ns)
            assert now >= deadline
    assert zenoh_io._wait_until(time.monotonic_ns() + 10**9, 0, stop=lambda: True) is None


def _lone_session():
    """A peer session that neither listens nor scouts: it reaches only its own subscribers."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def test_run_schedule_sends_every_batch_in_order():
    session = _lone_session()
    try:
        sub = session.declare_subscriber("pace/**", zenoh.handlers.FifoChannel(1 << 12))
        publisher = PacedPublisher(session, ["pace/a", "pace/b"])
        batches = [
            [
                (k * 200_000, key, f"{key}:{k}".encode())
                for k in range(j * 10, j * 10 + 10)
                for key in ("pace/a", "pace/b")
            ]
            for j in range(5)
        ]
        report = publisher.run_schedule(iter(batches))
        assert report.messages == 100 and len(report.lateness_s) == 50 and report.lateness_s.min() >= 0
        assert report.elapsed_s >= 49 * 200e-6
        time.sleep(0.2)
        got = []
        while (s := sub.try_recv()) is not None:
            got.append((str(s.key_expr), s.payload.to_bytes(), zenoh_io.unpack_attachment(s.attachment.to_bytes())[0]))
        assert [g[1] for g in got] == [p for batch in batches for _, _, p in batch]
        assert [g[2] for g in got if g[0] == "pace/a"] == list(range(50))
        stopped = publisher.run_schedule(iter(batches), stop=lambda: True)
        assert stopped.messages == 0
        publisher.close()
    finally:
        session.close()


def test_run_schedule_stops_between_deadlines_never_inside_one():
    """A stop asked mid-run ends it after a whole group of messages that share a deadline (a stream's
    sample goes out with all its topics or none), at the first deadline after 64 messages."""
    session = _lone_session()
    try:
        keys = ["pace/a", "pace/b", "pace/c"]  # 3 per deadline: 64 messages end inside a group
        publisher = PacedPublisher(session, keys)
        batch = [(k, key, b"x") for k in range(100) for key in keys]  # 1 ns apart: always behind, no waits
        polls = []
        report = publisher.run_schedule(iter([batch]), stop=lambda: polls.append(1) or len(polls) > 1)  # go, then stop
        assert report.messages == 66  # the first whole group after 64 messages
        publisher.close()
    finally:
        session.close()
