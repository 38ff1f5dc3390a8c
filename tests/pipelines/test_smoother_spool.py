"""The smoother over a log learned a block at a time, its storage on disk
(:mod:`gyroemu.pipelines.estimation.mekf_smoother_spool`): the same bytes as :func:`smooth_log` over the
whole log, however the log is cut and however short the stretches of the backward pass; and the
mistakes of a caller refused. (``gyroemu estimate --smooth`` through it, byte for byte the whole read's,
and its memory: ``test_estimate_stream.py``.)
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.estimation.latency import LatencyCompensated
from gyroemu.pipelines.estimation.mekf_smoother import MekfSmoother, smooth_log, smoother_params
from gyroemu.pipelines.estimation.mekf_smoother_spool import (
    SAMPLE_RECORD,
    SMOOTHED_RECORD,
    WINDOW_RECORD,
    SmootherSpool,
    spool_bytes,
)
from gyroemu.pipelines.estimation.setup import setup_for
from gyroemu.sensors import load_device


@pytest.fixture(scope="module")
def run():
    """20 s of the smooth manoeuvre with the consumer MEMS (its field too), stamps from 0."""
    scenario = load_scenario("smooth_manoeuvre")
    device = load_device("consumer_mems", seed=5)
    samples = device.measure(scenario.simulate(duration=20.0))
    t = np.asarray(samples.t, float) - samples.t[0]
    return setup_for(device, scenario), t, samples


def cuts(rng: np.random.Generator, n: int, first: int, count: int) -> np.ndarray:
    """Block edges ``0 … n``: a first block of ``first`` samples, then ``count`` random cuts (single
    samples among them)."""
    inner = rng.choice(np.arange(first + 1, n), count, replace=False)
    return np.unique(np.concatenate([[0, first, first + 1, n - 1, n], inner]))


@pytest.mark.parametrize("nine", [True, False], ids=["9D", "6D"])
@pytest.mark.parametrize("segment", [2, 3, 97, None], ids=["2", "3", "97", "default"])
def test_the_spool_is_smooth_log_to_the_bit(run, nine, segment):
    """Attitude, bias and covariance of every sample equal :func:`smooth_log`'s, learned in ~60 blocks
    and given out in ~80 others (cut elsewhere), with stretches of 2, 3, 97 windows and the default
    (longer than the log: one stretch)."""
    setup, t, samples = run
    setup = setup if nine else setup.__class__(**{**setup.__dict__, "use_mag": False})
    mag = samples.mag if nine else None
    whole = smooth_log(setup, t, samples.gyro, samples.accel, mag).smoothed
    rng = np.random.default_rng(11)
    n = len(t)
    first = int(np.searchsorted(t, 10.5))  # the filter starts from its first 10 s
    options = {} if segment is None else {"segment_windows": segment}
    with SmootherSpool(setup, smoother_params(setup), **options) as spool:
        edges = cuts(rng, n, first, 60)
        for a, b in zip(edges[:-1], edges[1:]):
            spool.learn(t[a:b], samples.gyro[a:b], samples.accel[a:b], None if mag is None else mag[a:b])
        edges = np.unique(np.concatenate([[0, 1, n], rng.choice(np.arange(2, n), 80, replace=False)]))
        parts = [spool.process(t[a:b], samples.gyro[a:b], samples.accel[a:b]) for a, b in zip(edges[:-1], edges[1:])]
        assert spool.samples == n and spool.windows > 2 * (segment or 0)  # several stretches where cut
    for name in ("q_wb", "gyro_bias", "q_wb_covariance"):
        assert np.array_equal(np.concatenate([getattr(p, name) for p in parts]), getattr(whole, name)), name


def test_a_timed_smoother_learns_its_field_moved(run):
    """Wrapped for the sensors' latencies, :class:`MekfSmoother` learned in blocks gives the wrapped
    whole log's estimate (the field turned back to the gyro's instant before it is learned)."""
    setup, t, samples = run
    setup = setup.__class__(**{**setup.__dict__, "gyro_latency_s": 0.004, "mag_latency_s": 0.015})
    args = (samples.gyro, samples.accel, samples.mag)
    whole = LatencyCompensated(MekfSmoother(setup), 0.004, 0.015).process(t, *args)
    timed = LatencyCompensated(MekfSmoother(setup), 0.004, 0.015)
    half = int(np.searchsorted(t, 12.0))
    timed.learn(t[:half], *(a[:half] for a in args))
    timed.learn(t[half:], *(a[half:] for a in args))
    out = [timed.process(t[s], *(a[s] for a in args)) for s in (slice(0, 7), slice(7, None))]
    timed.close()
    assert np.array_equal(np.concatenate([o.q_wb for o in out]), whole.q_wb)
    assert np.array_equal(np.concatenate([o.q_wb_covariance for o in out]), whole.q_wb_covariance)


def test_a_callers_mistakes_are_refused(run):
    setup, t, samples = run
    g, a = samples.gyro, samples.accel
    with SmootherSpool(setup, smoother_params(setup)) as spool:
        with pytest.raises(ValueError, match="learned no samples"):
            spool.process(t[:5], g[:5], a[:5])
        spool.learn(t[:3000], g[:3000], a[:3000], samples.mag[:3000])
        with pytest.raises(ValueError, match="does not follow"):
            spool.learn(t[2999:3100], g[2999:3100], a[2999:3100], samples.mag[2999:3100])
        with pytest.raises(ValueError, match="shape"):
            spool.learn(t[3000:3100], g[3000:3099], a[3000:3100], samples.mag[3000:3100])
        with pytest.raises(ValueError, match="not those learned"):
            spool.process(t[1:5], g[1:5], a[1:5])
        with pytest.raises(ValueError, match="3001 samples asked for, 3000 learned"):
            spool.process(t[:3001], g[:3001], a[:3001])
        with pytest.raises(ValueError, match="learns no more"):
            spool.learn(t[3000:3100], g[3000:3100], a[3000:3100], samples.mag[3000:3100])
    smoother = MekfSmoother(setup)
    smoother.learn(t[:3000], g[:3000], a[:3000], samples.mag[:3000])
    with pytest.raises(ValueError, match="block at a time"):
        smoother.process_increments(t[:5], g[:5] * 0.01, a[:5])
    smoother.close()


def test_spool_bytes_counts_the_files_a_log_takes(run):
    """What ``gyroemu estimate`` checks against the free disk is at least what the files hold once the
    log is learned and smoothed: a record per sample, and per window its storage and smoothed record.
    A window ends when its samples span 20 ms or count 21 (``window_due``), so at 1 kHz it holds 20 or
    21 samples (20 steps of 1 ms may round below 20 ms): between n/21 and n/20 windows, and window 0
    (the initial state); ``spool_bytes`` counts one every 20 ms."""
    setup, t, samples = run
    params = smoother_params(setup)
    with SmootherSpool(setup, params) as spool:
        spool.learn(t, samples.gyro, samples.accel, samples.mag)
        spool.process(t, samples.gyro, samples.accel)
        held = spool.disk_bytes
    n = len(t)
    counted = spool_bytes(n, n / 1000.0, params.window_s)  # the census's duration: samples over the rate
    window = WINDOW_RECORD.itemsize + SMOOTHED_RECORD.itemsize
    assert n * SAMPLE_RECORD.itemsize + (n // 21 + 1) * window <= held <= counted
    assert counted == n * SAMPLE_RECORD.itemsize + (-(-n // 20) + 1) * window
    assert MekfSmoother(setup).spool_bytes(n, n / 1000.0) == counted


def test_spool_bytes_over_the_span_bounds_a_log_with_gaps(run):
    """Windows end on elapsed time, so a log with gaps (10 samples kept of every 40) has windows over its
    span, not over its samples' count at the rate: counted over the stamps' span (what ``gyroemu
    estimate`` gives it), at least what the files hold; over samples / rate, less."""
    setup, t, samples = run
    keep = np.arange(len(t)) % 40 < 10
    params = smoother_params(setup)
    with SmootherSpool(setup, params) as spool:
        spool.learn(t[keep], samples.gyro[keep], samples.accel[keep], samples.mag[keep])
        spool.process(t[keep], samples.gyro[keep], samples.accel[keep])
        held = spool.disk_bytes
    n = int(keep.sum())
    assert spool_bytes(n, float(t[keep][-1] - t[keep][0]), params.window_s) >= held
    assert spool_bytes(n, n / 1000.0, params.window_s) < held


def test_only_a_filter_with_the_learners_methods_is_fed_in_blocks(run):
    """The job's two questions, by name before the filter is made (``registry.learns_in_blocks``) and of
    the filter made (``protocol.learns_in_blocks``), get one answer: the smoother, wrapped for latency or
    not, learns in blocks; a class that says so but lacks ``spool_in`` does not, nor does an online one."""
    from gyroemu.pipelines.estimation import protocol, registry
    from gyroemu.pipelines.estimation.mekf import Mekf

    setup = run[0]

    class Claims:
        name, offline, learns_in_blocks = "claims", True, True

        def process(self, t, gyro, accel, mag=None): ...

        def learn(self, t, gyro, accel, mag=None): ...

    assert registry.learns_in_blocks("mekf-smooth") and protocol.learns_in_blocks(MekfSmoother(setup))
    assert protocol.learns_in_blocks(LatencyCompensated(MekfSmoother(setup), 0.004, 0.015))
    assert not protocol.learns_in_blocks(Claims) and not protocol.learns_in_blocks(Claims())
    assert not registry.learns_in_blocks("mekf") and not protocol.learns_in_blocks(Mekf(setup))
    assert not protocol.learns_in_blocks(LatencyCompensated(Mekf(setup), 0.004))
