"""``gyroemu estimate --plot`` and ``gyroemu info --plot`` (pipelines/jobs/plots.py).

The angles are checked on rotations built from known angles (exact to a few ε of the angle); the
pictures by what the CLI writes: a PNG (its signature) of the size matplotlib gives the figure.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from cli_runs import run_cli

from gyroemu.pipelines.jobs.plots import attitude_error_deg, euler_zyx_deg


def _q(axis, angle):
    axis = np.asarray(axis, dtype=float)
    return np.array([np.cos(angle / 2), *(np.sin(angle / 2) * axis / np.linalg.norm(axis))])


def _mul(a, b):
    w1, v1, w2, v2 = a[0], a[1:], b[0], b[1:]
    return np.array([w1 * w2 - v1 @ v2, *(w1 * v2 + w2 * v1 + np.cross(v1, v2))])


def test_euler_angles_and_error_of_known_rotations():
    rng = np.random.default_rng(1)
    angles = np.column_stack([rng.uniform(-170, 170, 50), rng.uniform(-80, 80, 50), rng.uniform(-170, 170, 50)])
    q = np.array(
        [
            _mul(_mul(_q([0, 0, 1], np.radians(y)), _q([0, 1, 0], np.radians(p))), _q([1, 0, 0], np.radians(r)))
            for r, p, y in angles
        ]
    )
    assert np.allclose(euler_zyx_deg(q), angles, rtol=0, atol=1e-10)
    assert np.all(np.isnan(euler_zyx_deg(np.full((1, 4), np.nan))))
    small = np.array([_mul(qk, _q([1, 2, 3], 1e-9)) for qk in q])  # 1e-9 rad about a body axis
    assert np.allclose(attitude_error_deg(q, small), np.degrees(1e-9), rtol=1e-6, atol=0)
    assert np.allclose(attitude_error_deg(q, -q), 0.0, atol=1e-12)  # q and -q: the same attitude


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


@pytest.mark.slow  # matplotlib's import and two figures: 2.4 s, over the fast tier's share
@pytest.mark.filterwarnings("ignore")
def test_estimate_and_info_draw_their_pictures(tmp_path, capsys):
    from gyroemu.pipelines.cli import main

    log, out = tmp_path / "run.mcap", tmp_path / "est.mcap"
    common = ["--device", "tactical_mems", "--duration", "2", "--seed", "3"]
    assert main(["simulate", "--scenario", "smooth_manoeuvre", *common, "--out", str(log)]) == 0
    assert main(["estimate", str(log), "--out", str(out), "--plot"]) == 0
    assert "drew" in capsys.readouterr().out
    assert _png_size(tmp_path / "est.estimate.png") == (770, 1320)  # 7 x 12 in at 110 dpi
    assert main(["info", str(log), "--plot"]) == 0
    assert _png_size(tmp_path / "run.info.png") == (770, 990)  # 7 x 9 in


def _direct_columns(t, values, t0, width, buckets):
    """Each column's least, greatest and mean value computed from all the samples at once."""
    index = np.maximum(np.floor((t - t0) / width), 0).astype(int)
    assert index.max() < buckets
    rows = []
    for j in np.unique(index):
        v = values[index == j]
        with np.errstate(all="ignore"):
            rows.append((t0 + (j + 0.5) * width, np.nanmin(v, axis=0), np.nanmax(v, axis=0), np.nanmean(v, axis=0)))
    return [np.array(c) for c in zip(*rows)]


@pytest.mark.parametrize("n", [15, 16, 17, 5000])
def test_an_envelope_holds_each_columns_extremes_however_the_series_is_cut(n):
    """Up to 2 · buckets samples (16 here): the samples themselves. Beyond: per column, the least and the
    greatest of its samples exactly and their mean to round-off, NaN ignored (a channel NaN in a whole
    column gives NaN), the same for two different cuts of the series into blocks."""
    from gyroemu.pipelines.jobs.plot_envelope import Envelope

    rng = np.random.default_rng(n)
    t = 100.0 + np.cumsum(rng.uniform(0.001, 0.01, n))
    values = rng.standard_normal((n, 2)) * [1.0, 1e6]
    values[rng.random(n) < 0.1, 0] = np.nan
    values[n // 2 : n // 2 + n // 8, 1] = np.nan  # a stretch where channel 1 has nothing
    results = []
    for seed in (1, 2):
        envelope = Envelope(2, buckets=8)
        cuts = np.unique(np.concatenate([[0, n], np.random.default_rng(seed).integers(0, n, 10)]))
        for a, b in zip(cuts[:-1], cuts[1:]):
            envelope.add(t[a:b], values[a:b])
        results.append(envelope)
        assert len(envelope) == n
    for envelope in results:
        middle, lo, hi, mean = envelope.columns()
        if n <= 16:
            assert not envelope.decimated
            assert np.array_equal(middle, t) and np.array_equal(lo, values, equal_nan=True)
            continue
        assert envelope.decimated and len(middle) <= 8
        want = _direct_columns(t, values, envelope.t0, envelope.width, 8)
        assert np.array_equal(middle, want[0])
        assert np.array_equal(lo, want[1], equal_nan=True) and np.array_equal(hi, want[2], equal_nan=True)
        scale = np.nanmax(np.abs(values), axis=0)
        assert np.allclose(mean, want[3], rtol=0, atol=n * np.finfo(float).eps * scale, equal_nan=True)
    assert results[0].width == results[1].width  # the columns do not depend on the cut


@pytest.fixture(scope="module")
def estimated_log(tmp_path_factory):
    """8 s of the smooth manoeuvre with the consumer MEMS (a magnetometer), its truth, estimated (9D), in
    small chunks."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.mcap_log import Recording, write_mcap
    from gyroemu.pipelines.jobs.estimate import estimate_log
    from gyroemu.sensors import load_device

    folder = tmp_path_factory.mktemp("plot")
    scenario = load_scenario("smooth_manoeuvre")
    device = load_device("consumer_mems", seed=3)
    traj = scenario.simulate(duration=8.0)
    from gyroemu.pipelines.formats.mcap_log import truth_series

    samples = device.measure(traj)
    log = write_mcap(
        folder / "run.mcap", Recording(samples, truth=truth_series(traj, samples), device=device), chunk_size=1 << 14
    )
    out = folder / "est.mcap"
    estimate_log(log, out)
    return log, out


@pytest.mark.parametrize("buckets", [16, 100_000], ids=["columns", "samples"])
def test_the_curves_read_a_chunk_at_a_time_are_the_whole_reads(estimated_log, buckets, monkeypatch):
    """What the plots draw, read a chunk at a time, equals what the log read whole gives (its extremes
    exactly; means and the error's RMS to round-off): angles, truth, error and bias of the estimate;
    rate, force and field of the measurements. The chunked read must not fall back on the whole read
    (``read_mcap`` made to fail while it runs)."""
    from gyroemu.pipelines.formats import mcap_log
    from gyroemu.pipelines.jobs import plots

    log, out = estimated_log
    eps = np.finfo(float).eps

    def chunked(curves, path):
        with monkeypatch.context() as m:
            m.setattr(mcap_log, "read_mcap", lambda *a, **k: pytest.fail("the chunked read read the log whole"))
            return curves(path, buckets)

    (a,), (b,) = chunked(plots.estimate_curves, out), plots.estimate_curves(out, buckets, read_whole=True)
    assert a.t0 == b.t0 and a.final == b.final and abs(a.rms - b.rms) <= 1e4 * eps * b.rms
    for name in ("angles", "true_angles", "error", "bias"):
        x, y = getattr(a, name).columns(), getattr(b, name).columns()
        assert len(getattr(a, name)) == len(getattr(b, name)) > 0
        assert all(np.array_equal(u, v, equal_nan=True) for u, v in zip(x[:3], y[:3])), name
        assert np.allclose(x[3], y[3], rtol=1e-12, atol=1e-9, equal_nan=True), name
    (a,), (b,) = chunked(plots.info_curves, log), plots.info_curves(log, buckets, read_whole=True)
    for name in ("rate", "force", "field"):
        x, y = getattr(a, name).columns(), getattr(b, name).columns()
        assert len(getattr(a, name)) == len(getattr(b, name)) > 0
        assert all(np.array_equal(u, v, equal_nan=True) for u, v in zip(x[:3], y[:3])), name


@pytest.mark.slow
def test_the_curves_memory_does_not_grow_with_the_log(tmp_path):
    """Python's peak allocation (tracemalloc sees NumPy's buffers) while reading the curves of a log 4×
    longer: the same within the chunks in flight and the columns when read a chunk at a time; read
    whole, it grows with the samples."""
    import tracemalloc

    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.mcap_log import Recording, truth_series, write_mcap
    from gyroemu.pipelines.jobs import plots
    from gyroemu.pipelines.jobs.estimate import estimate_log
    from gyroemu.sensors import load_device

    scenario = load_scenario("smooth_manoeuvre")
    peaks = {}
    for minutes in (1, 4):  # 1 kHz: 60,000 samples and more, past the 4,000 a plot keeps whole
        device = load_device("consumer_mems", seed=1)
        traj = scenario.simulate(duration=60.0 * minutes)
        samples = device.measure(traj)
        log = write_mcap(
            tmp_path / f"m{minutes}.mcap", Recording(samples, truth=truth_series(traj, samples), device=device)
        )
        est = tmp_path / f"e{minutes}.mcap"
        estimate_log(log, est)
        for whole in (False, True):
            tracemalloc.start()
            plots.estimate_curves(est, read_whole=whole)
            plots.info_curves(log, read_whole=whole)
            peaks[minutes, whole] = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
    assert peaks[4, True] > 3.0 * peaks[1, True]  # the whole read holds every sample
    assert peaks[4, False] < 1.15 * peaks[1, False]  # a chunk at a time: nothing of the extra three minutes
    assert peaks[4, False] < peaks[4, True] / 3


def test_stamps_are_matched_as_the_log_goes_by_and_the_unmatched_dropped():
    """Rows of two topics meet at equal stamps whatever the blocks; a row the other side has gone past
    is dropped, also when the other side shows only stamps (messages without the quantity), so nothing
    waits without end (an estimate without a rate beside an /imu of hours)."""
    from gyroemu.pipelines.jobs.plots import StampMatch

    match = StampMatch()
    a = np.arange(0, 100, 2, dtype=np.int64)  # every even stamp
    b = np.arange(0, 100, 3, dtype=np.int64)  # every third
    got = []
    for (lo, hi), (lo_b, hi_b) in zip(((0, 10), (10, 37), (37, 100)), ((0, 15), (15, 42), (42, 100))):
        sa, sb = a[(a >= lo) & (a < hi)], b[(b >= lo_b) & (b < hi_b)]  # b runs a little ahead
        match.add(0, sa, sa[:, None] * 1.0)
        match.add(1, sb, -sb[:, None] * 1.0)
        stamps, va, vb = match.take()
        assert np.array_equal(va[:, 0], stamps) and np.array_equal(vb[:, 0], -stamps)
        got.append(stamps)
    both = np.concatenate(got)
    assert np.array_equal(both, np.intersect1d(a, b))
    waiting = [len(w[0]) for w in match.waiting if w is not None]
    assert max(waiting) <= 3  # only rows past the other side's last stamp wait

    only_stamps = StampMatch()
    for k in range(100):
        block = np.arange(k * 10, k * 10 + 10, dtype=np.int64)
        only_stamps.add(1, block, np.zeros((10, 3)))
        only_stamps.add(0, block, None)  # the estimate has no rate
        assert len(only_stamps.take()[0]) == 0
        assert only_stamps.waiting[1] is not None and len(only_stamps.waiting[1][0]) == 0


def test_a_log_without_truth_draws_its_estimate_and_bias(tmp_path):
    """A recording with no /truth/imu (a real sensor's): the estimate's angles and bias, no error, the
    same read a chunk at a time as whole."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.formats.mcap_log import Recording, write_mcap
    from gyroemu.pipelines.jobs import plots
    from gyroemu.pipelines.jobs.estimate import estimate_log
    from gyroemu.sensors import load_device

    device = load_device("consumer_mems", seed=2)
    samples = device.measure(load_scenario("smooth_manoeuvre").simulate(duration=3.0))
    log = write_mcap(tmp_path / "real.mcap", Recording(samples, device=device), chunk_size=1 << 13)
    estimate_log(log, tmp_path / "est.mcap")
    for whole in (False, True):
        (c,) = plots.estimate_curves(tmp_path / "est.mcap", 16, read_whole=whole)
        assert len(c.angles) == len(c.bias) == len(samples.t) and len(c.error) == 0 and c.rms is None


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    """Half a second of the consumer MEMS (a gyroemu log)."""
    log = tmp_path_factory.mktemp("short") / "run.mcap"
    argv = ["--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "0.5", "--out", str(log)]
    code, _, stderr = run_cli(["simulate", *argv])
    assert code == 0, stderr
    return log


@pytest.mark.parametrize("command", ["estimate", "info"])
def test_a_picture_there_is_overwritten_only_with_force(tmp_path, short_log, command):
    """``--plot`` draws beside --out (estimate) or the log (info): a file there is someone's, refused
    before any work (nothing printed, nothing written), naming --plot; --force is what overwrites it."""
    log = tmp_path / "run.mcap"
    log.write_bytes(short_log.read_bytes())
    if command == "estimate":
        argv, picture = ["estimate", str(log), "--out", str(tmp_path / "e.mcap"), "--plot"], tmp_path / "e.estimate.png"
    else:
        argv, picture = ["info", str(log), "--plot"], tmp_path / "run.info.png"
    picture.write_bytes(b"someone's picture")
    code, stdout, stderr = run_cli(argv)
    assert code == 2 and f"argument --plot: {picture} exists (use --force to overwrite it)" in stderr, stderr
    assert stdout == ""
    assert picture.read_bytes() == b"someone's picture"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run.mcap", picture.name])
    code, stdout, _ = run_cli([command, "--help"])
    assert code == 0 and "--force" in stdout


def test_info_plot_in_a_read_only_folder_is_refused_before_work(monkeypatch, short_log):
    """The log's folder cannot take LOG.info.png (a read-only mount refuses even root, which a test cannot
    make: folder_problem is told so): refused naming --plot before the summary, not an OSError after."""
    import gyroemu.pipelines.formats.atomic as atomic

    real = atomic.folder_problem
    monkeypatch.setattr(
        atomic, "folder_problem", lambda f: "read-only file system" if f == short_log.parent else real(f)
    )
    code, stdout, stderr = run_cli(["info", str(short_log), "--plot"])
    assert code == 2 and f"argument --plot: {short_log.parent}: read-only file system" in stderr, stderr
    assert stdout == ""
    assert not short_log.with_suffix(".info.png").exists()
