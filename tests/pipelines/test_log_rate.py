"""A log's sample rate from its integer stamps: :func:`rate_of` over the whole series and :class:`RateCounter`
a block at a time give the same float, ``1e9 / median`` of the integer steps (ns), whatever the epoch.

Float seconds since the Unix epoch resolve 2**-22 s (0.24 µs) from 2004 to 2038: a 1 kHz log's steps there
are 4194 or 4195 such units, whose median put the rate 72 ppm off (1000.0725 Hz), and with it the rate
``gyroemu estimate`` and ``gyroemu bench --log`` gave the filters. Tolerances: exact where the quotient is
a float; otherwise the correctly rounded quotient, within half a unit in the last place.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.estimation.series import median_step_ns, rate_of
from gyroemu.pipelines.formats.device_stream import RateCounter
from gyroemu.pipelines.formats.mcap_log import McapLogWriter, Recording, truth_series
from gyroemu.pipelines.jobs import bench, bench_log, estimate
from gyroemu.pipelines.jobs.bench import LogCase
from gyroemu.sensors import load_device

EPOCH_2026_NS = 1_780_272_000 * 10**9  # 2026-06-01T00:00:00Z
"""Stamps of today: float seconds resolve 2**-22 s here."""


def counted(blocks: list[np.ndarray]) -> RateCounter:
    """A :class:`RateCounter` fed ``blocks`` (integer ns) in turn."""
    counter = RateCounter()
    for block in blocks:
        counter.add(block)
    return counter


def assert_correctly_rounded(rate: float, median_ns: Fraction) -> None:
    """``rate`` is 1e9 / ``median_ns`` Hz rounded to the nearest float: within half an ulp of the exact quotient."""
    exact = Fraction(10**9) / median_ns
    assert abs(Fraction(rate) - exact) <= Fraction(math.ulp(rate)) / 2, (rate, float(exact))


@pytest.mark.parametrize("step_ns", [1_000_000, 5_000_000, 2_500_000, 3_500_000, 3_333_333, 10_000_000])
def test_clocked_stamps_at_a_2026_epoch_give_the_exact_rate(step_ns):
    """Steps of exactly ``step_ns``: the median is that step and the rate ``1e9 / step`` (1000.0 Hz for
    1 ms; exact wherever the quotient is a float), both ways; float seconds are off by up to 2**-23 s in
    each stamp (ppm of the rate), which the median used to keep."""
    stamps = EPOCH_2026_NS + np.arange(20_001, dtype=np.int64) * step_ns
    assert median_step_ns(stamps) == step_ns
    rate = rate_of(stamps)
    assert_correctly_rounded(rate, Fraction(step_ns))
    if 10**9 % step_ns == 0:
        assert rate == 10**9 // step_ns
    counter = counted(np.array_split(stamps, 7))
    assert counter.median_ns() == step_ns and counter.median() == step_ns / 1e9 and counter.rate() == rate
    assert rate_of(np.array([EPOCH_2026_NS])) == counted([stamps[:1]]).rate() == 1.0  # no interval
    old = 1.0 / float(np.median(np.diff(stamps / 1e9)))  # what float seconds gave
    assert abs(old / rate - 1) > 1e-7


def test_a_1khz_log_at_today_epoch_is_1000_hz():
    """The case the defect was found on: 1 ms steps from 2025-01-01 (``gyroemu simulate``'s epoch) and
    2026: 1000.0 Hz to the bit, where float seconds gave 1000.0725 Hz (72 ppm)."""
    for start_ns in (1_735_689_600 * 10**9 + 1_000_000, EPOCH_2026_NS):
        stamps = start_ns + np.arange(60_000, dtype=np.int64) * 1_000_000
        assert rate_of(stamps) == 1000.0 and counted([stamps]).rate() == 1000.0


def test_float_seconds_are_refused():
    """Float seconds where integer ns are due would be read as a rate 1e9 times off: a TypeError."""
    seconds = np.arange(10) * 1e-3
    for call in (rate_of, median_step_ns, RateCounter().add):
        with pytest.raises(TypeError, match="integer nanoseconds"):
            call(seconds)


def _jittered(rng: np.random.Generator, n: int, spread_ns: int) -> np.ndarray:
    """``n`` increasing integer stamps from 2026, 1 ms apart ± up to ``spread_ns`` each."""
    steps = 1_000_000 + rng.integers(-spread_ns, spread_ns + 1, n - 1)
    return EPOCH_2026_NS + np.concatenate(([0], np.cumsum(steps)))


def _cuts(stamps: np.ndarray, positions) -> list[np.ndarray]:
    """``stamps`` cut at ``positions`` (any of 0 … N, repeated: empty blocks)."""
    edges = [0, *sorted(positions), len(stamps)]
    return [stamps[a:b] for a, b in itertools.pairwise(edges)]


def _assert_same_both_ways(stamps: np.ndarray, blocks: list[np.ndarray]) -> None:
    want = float(np.median(np.diff(stamps)))  # NumPy's median of the integer steps: exact below 2**52 ns
    counter = counted(blocks)
    assert median_step_ns(stamps) == counter.median_ns() == want
    assert rate_of(stamps) == counter.rate() == 1e9 / want


def test_streamed_is_the_whole_series_for_every_cut_of_a_short_one():
    """Every way of cutting 2 … 6 stamps into blocks (empty blocks at either end or between, too)."""
    rng = np.random.default_rng(5)
    for n in range(2, 7):
        stamps = _jittered(rng, n, 3)
        for k in range(n + 2):
            for positions in itertools.combinations_with_replacement(range(n + 1), k):
                _assert_same_both_ways(stamps, _cuts(stamps, positions))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    st.integers(2, 3000).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.integers(0, 2**32 - 1),
            st.sampled_from([0, 1, 2, 50, 400_000]),
            st.lists(st.integers(0, n), max_size=12),
        )
    )
)
def test_streamed_is_the_whole_series_for_blocks_cut_anywhere(case):
    """Jittered stamps (steps of one value, a few, or every one its own) cut at arbitrary places."""
    n, seed, spread_ns, positions = case
    stamps = _jittered(np.random.default_rng(seed), n, spread_ns)
    _assert_same_both_ways(stamps, _cuts(stamps, positions))


def test_streamed_is_the_whole_series_past_the_merges():
    """More distinct intervals than the counter holds before it merges a block's in (2**16), merged many
    times over, in blocks of every size from one stamp up."""
    rng = np.random.default_rng(8)
    stamps = _jittered(rng, 400_001, 100_000)
    positions = np.cumsum(rng.integers(0, 3000, 400))
    _assert_same_both_ways(stamps, _cuts(stamps, positions[positions <= len(stamps)].tolist()))


@pytest.mark.parametrize("count", [2000, 2001])
def test_a_jittered_clock_has_the_median_of_its_steps(count):
    """A clock whose steps alternate, shuffled, between 999,999 ns and 1,000,002 ns in equal numbers (even
    count: the median is half way, 1,000,000.5 ns, rate 999.9995000002 Hz) or with one more 999,999 ns
    step (odd count: 999,999 ns, 1000.001000001 Hz); from 2026, where float seconds resolve 238 ns."""
    rng = np.random.default_rng(3)
    steps = np.where(np.arange(count) % 2 == 0, 999_999, 1_000_002)
    rng.shuffle(steps)
    stamps = EPOCH_2026_NS + np.concatenate(([0], np.cumsum(steps)))
    median = Fraction(2_000_001, 2) if count % 2 == 0 else Fraction(999_999)
    assert median_step_ns(stamps) == median  # exact: an integer or a half
    rate = rate_of(stamps)
    assert_correctly_rounded(rate, median)
    counter = counted(np.array_split(stamps, 13))
    assert counter.median_ns() == median and counter.rate() == rate


def _log_at_2026(path, seconds: float = 2.0) -> None:
    """A gyroemu log of the smooth manoeuvre on the consumer MEMS (1 kHz, with truth) from 2026."""
    scenario = load_scenario("smooth_manoeuvre")
    dev = load_device("consumer_mems", seed=4)
    traj = scenario.simulate(duration=seconds)
    samples = dev.measure(traj)
    with McapLogWriter(path, scenario=scenario, start_ns=EPOCH_2026_NS) as log:
        log.write(Recording(samples, truth=truth_series(traj, samples), device=dev))


def test_estimate_and_bench_give_a_1khz_log_1000_hz_both_ways(tmp_path, monkeypatch):
    """What the filters get: ``gyroemu estimate`` read whole and a block at a time, and ``gyroemu bench
    --log`` read whole and a block at a time, set them up at 1000.0 Hz (the bench's nominal step 1 ms)."""
    path = tmp_path / "run.mcap"
    _log_at_2026(path)
    rates, make_filter = [], estimate.make_filter

    def recording_make_filter(name, setup, **options):
        rates.append(setup.rate_hz)
        return make_filter(name, setup, **options)

    monkeypatch.setattr(estimate, "make_filter", recording_make_filter)
    for whole in (False, True):
        estimate.estimate_log(path, tmp_path / f"out{whole}.mcap", read_whole=whole, filter_name="madgwick")
    assert rates == [1000.0, 1000.0]
    case = LogCase(path)
    (streamed,) = bench_log.stream_log_devices(case)
    ((*_, setup, _, _, _),) = bench._log_runs(dataclasses.replace(case, read_whole=True))
    assert streamed.setup.rate_hz == setup.rate_hz == 1000.0 and streamed.dt_nominal == 1e-3


def test_the_filters_run_on_exact_seconds_since_the_first_stamp(tmp_path, monkeypatch):
    """``gyroemu estimate`` and ``gyroemu bench --log``, each read whole and a block at a time, give the
    filters seconds since the device's first stamp from the integer nanoseconds: the same floats
    ``(stamp_ns − first_ns) · 1e-9`` on every path, whose steps are 1 ms within round-off at the span
    (float seconds since the epoch, less the first, step by 0.99993–1.0004 ms: 2.4·10⁻⁷ s off)."""
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    path = tmp_path / "run.mcap"
    _log_at_2026(path)
    stamp_ns = read_mcap(path).device.stamp_ns
    exact = (stamp_ns - stamp_ns[0]) * 1e-9
    assert np.max(np.abs(np.diff(exact) - 1e-3)) <= 8 * np.finfo(float).eps * exact[-1]
    seen: list[np.ndarray] = []

    def recording(module):
        make_filter = module.make_filter

        def make(name, setup, **options):
            flt = make_filter(name, setup, **options)
            process = flt.process

            def spy(t, *args, **kwargs):
                seen.append(np.array(t, dtype=float))
                return process(t, *args, **kwargs)

            flt.process = spy
            return flt

        monkeypatch.setattr(module, "make_filter", make)

    for module in (estimate, bench, bench_log):
        recording(module)
    runs = {}
    for whole in (False, True):
        seen.clear()
        estimate.estimate_log(path, tmp_path / f"out{whole}.mcap", read_whole=whole, filter_name="madgwick")
        runs[f"estimate whole={whole}"] = np.concatenate(seen)
    for whole in (False, True):
        seen.clear()
        bench.run_bench([LogCase(path, read_whole=whole)], filters=["madgwick"])
        runs[f"bench whole={whole}"] = np.concatenate(seen)  # the warm-up's filters are not recorded
    for what, t in runs.items():
        assert np.array_equal(t, exact), what
