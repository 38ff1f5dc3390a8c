"""The parts of ``gyroemu twin`` one at a time (:mod:`gyroemu.pipelines.twin`), on small synthetic inputs.

Tolerances. Exact where the arithmetic is (the same float operations, an index, a string); round-off
as a few machine epsilons of the magnitude where a sum is taken apart again; statistical bounds from
the sample count (five standard deviations of the estimator) for the white-noise spectra and Allan
deviations; closed forms for Student's t (1 degree of freedom: tan(0.475 pi); 2: sqrt(2 p^2 / (1 - p^2))
with p = 0.95); three significant digits (a relative half-unit of 5e-3) where the report prints them.
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest

from gyroemu.pipelines import cli
from gyroemu.pipelines.twin import (
    HANDLING_STREAM,
    TAUS_S,
    TWIN_SMOOTHING,
    Handling,
    Recording,
    SiteFileError,
    TwinReport,
    filter_errors,
    load_recording,
    longest_run,
    pool_adev,
    pooled_residuals,
    read_site,
    rest_phases,
    rest_residuals,
    run_one_twin,
    trial_result,
    twin_seed,
    welch_spectrum,
)

EPS = np.finfo(float).eps
README = Path(__file__).resolve().parents[2] / "README.md"
EPOCH_2026_NS = 1_780_272_000 * 10**9
SITE = "[site]\nmagnetic_field_enu_uT = [0.0, 14.25, -39.72]\n"


def _one_line(text: str) -> str:
    return " ".join(text.split())


# ---------------------------------------------------------------------------------------------------
# Documented defaults: the help and the README say what the constants are.


def test_the_help_and_the_readme_state_the_twins_smoothing(capsys):
    """``--smoothing``'s help names the defaults (it once said other values than the code), and so does
    the README's account of the twins' motion."""
    with pytest.raises(SystemExit) as e:
        cli.main(["twin", "--help"])
    assert e.value.code == 0
    text = _one_line(capsys.readouterr().out)
    smoothing = text[text.index("--smoothing KEY=VALUE a [smoothing] key") :]
    defaults = smoothing[smoothing.index("(repeatable; default") :]
    defaults = defaults[: defaults.index(";", len("(repeatable;"))]
    stated = {k: float(v) for k, v in re.findall(r"(\w+_cutoff_hz)=([\d.]+)", defaults)}
    assert stated == TWIN_SMOOTHING, (defaults, TWIN_SMOOTHING)
    readme = _one_line(README.read_text(encoding="utf-8"))
    m = re.search(r"smoothed to ([\d.]+) Hz; the position is smoothed to ([\d.]+) Hz \(`TWIN_SMOOTHING`", readme)
    assert m is not None
    assert (float(m[1]), float(m[2])) == (TWIN_SMOOTHING["orientation_cutoff_hz"], TWIN_SMOOTHING["position_cutoff_hz"])


def test_the_readme_and_the_report_state_the_residuals_taus():
    """The README's target and the pooled table's header name the τ range of :data:`TAUS_S`."""
    readme = _one_line(README.read_text(encoding="utf-8"))
    m = re.search(r"\[Allan deviation within [\d.]+× over τ ([\d.]+)–([\d.]+) s\]", readme)
    assert m is not None
    assert (float(m[1]), float(m[2])) == pytest.approx((TAUS_S[0], TAUS_S[-1]), rel=4 * EPS)
    md = _report([_trial("a.mcap"), _trial("b.mcap")], pooled=True).to_markdown()
    m = re.search(r"τ ([\d.]+)…([\d.]+) s \| real clusters at ([\d.]+) s", md)
    assert m is not None
    assert (float(m[1]), float(m[2]), float(m[3])) == pytest.approx((TAUS_S[0], TAUS_S[-1], TAUS_S[-1]), rel=4 * EPS)


# ---------------------------------------------------------------------------------------------------
# site.py: the [handling] table and its draws


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**63 + 7])
def test_handling_draw_is_mean_plus_sd_times_its_own_normals(seed):
    mean, sd = np.array([-0.005, 0.05, -0.006]), np.array([0.02, 0.0, 0.013])
    normals = np.random.default_rng([seed, HANDLING_STREAM]).standard_normal(3)
    drawn = Handling(mean, sd).draw(seed)
    assert drawn.shape == (3,)
    assert np.array_equal(drawn, mean + sd * normals)
    assert drawn[1] == mean[1]  # a zero sd draws the mean exactly
    assert np.array_equal(Handling(mean, np.zeros(3)).draw(seed), mean)


def test_read_site_takes_zero_sigmas_and_defaults_a_missing_key_to_zeros(tmp_path):
    path = tmp_path / "site.toml"
    path.write_text(SITE + "\n[handling]\naccel_offset_sigma_m_s2 = [0.0, 0.0, 0.0]\n")
    site, handling = read_site(path)
    assert site == {"magnetic_field_enu_uT": [0.0, 14.25, -39.72]}
    assert np.array_equal(handling.accel_offset, np.zeros(3))
    assert np.array_equal(handling.accel_offset_sigma, np.zeros(3))
    path.write_text(SITE + "\n[handling]\naccel_offset_m_s2 = [0.01, -0.02, 0.03]\n")
    _, handling = read_site(path)
    assert np.array_equal(handling.accel_offset, [0.01, -0.02, 0.03])
    assert np.array_equal(handling.accel_offset_sigma, np.zeros(3))
    path.write_text(SITE + "\n[handling]\n")
    _, handling = read_site(path)
    assert np.array_equal(handling.accel_offset, np.zeros(3)) and np.array_equal(
        handling.accel_offset_sigma, np.zeros(3)
    )
    path.write_text(SITE)
    assert read_site(path)[1] is None
    path.write_text(SITE + "\n[handling]\naccel_offset_sigma_m_s2 = [0.0, -1e-9, 0.0]\n")
    with pytest.raises(SiteFileError, match="non-negative"):
        read_site(path)


# ---------------------------------------------------------------------------------------------------
# recording.py


@pytest.mark.parametrize(
    "flags, run",
    [
        ([], None),
        ([0, 0, 0], None),
        ([1], (0, 1)),
        ([1, 1, 1, 1, 0, 1], (0, 4)),  # the longest, not the latest (a product of the ends would pick (5, 6))
        ([0, 1, 0, 1, 1, 0, 1, 1, 1], (6, 9)),
        ([0, 1, 1, 0, 1, 1], (1, 3)),  # the first of equal ones
        ([1, 1, 0, 0, 1, 1, 1, 0], (4, 7)),
    ],
)
def test_longest_run(flags, run):
    assert longest_run(np.array(flags, dtype=bool)) == run


def _write_log(path: Path, truth_shift: float, n: int = 200, dt: float = 0.01):
    """A hand-made gyroemu log at 100 Hz from 2026: the magnetometer on every other sample (NaN rows
    between), a movement mask, and truth stamped ``truth_shift`` s off the samples, missing 50…59."""
    from gyroemu.pipelines.formats.channels import ImuSeries
    from gyroemu.pipelines.formats.mcap_log import McapLogWriter
    from gyroemu.pipelines.formats.mcap_log import Recording as LogRecording
    from gyroemu.sensors.samples import ImuSamples

    rng = np.random.default_rng(7)
    t = 1.0 + np.arange(n) * dt
    mag = 1e-5 * rng.standard_normal((n, 3))
    mag[1::2] = np.nan
    samples = ImuSamples(t=t, gyro=rng.standard_normal((n, 3)), accel=rng.standard_normal((n, 3)), mag=mag)
    angle = 1e-3 * np.arange(n)  # a distinct attitude per truth row
    q = np.stack([np.cos(angle / 2), 0 * angle, 0 * angle, np.sin(angle / 2)], axis=1)
    omega, force = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    kept = np.r_[0:50, 60:n]
    truth = ImuSeries(t=t[kept] + truth_shift, q_wb=q[kept], omega_b=omega[kept], specific_force_b=force[kept])
    movement = np.zeros(n, bool)
    movement[100:150] = True
    with McapLogWriter(path, start_ns=EPOCH_2026_NS) as log:
        log.write(LogRecording(samples, truth=truth, movement=movement))
    return t, mag, q, omega, force, kept, movement


@pytest.mark.parametrize("shift", [0.0, -0.001, 0.001])
def test_load_recording_matches_each_sample_to_its_nearest_truth(tmp_path, shift):
    """Each sample takes the truth row nearest its stamp, when within a quarter sample (truth stamped
    at the samples or 0.1 sample either side; none for 50…59, whose nearest truth is ≥ 0.9 sample
    away), down to the last sample; the magnetometer keeps its NaN rows; the movement mask counts."""
    path = tmp_path / "hand.mcap"
    t, mag, q, omega, force, kept, movement = _write_log(path, shift)
    rec = load_recording(path)
    n = len(t)
    assert rec.format == "mcap" and rec.name == "hand.mcap" and len(rec.t) == n
    has = np.zeros(n, bool)
    has[kept] = True
    assert np.array_equal(np.isfinite(rec.q_true).all(axis=1), has)
    assert np.array_equal(rec.q_true[has], q[has])  # row i's truth is truth row i: bit for bit
    assert np.array_equal(rec.omega_true[has], omega[has]) and np.array_equal(rec.force_true[has], force[has])
    assert np.array_equal(rec.q_true[[0, -1]], q[[0, -1]])  # the ends too
    # the clock: the motion's, from the first truth stamp (float seconds at 2026 resolve 2**-22 s)
    assert np.allclose(rec.t, t - (t[0] + shift), rtol=0, atol=2.0**-21)
    assert rec.rate_hz == pytest.approx(100.0, rel=1e-5)
    assert rec.mag is not None
    assert np.isnan(rec.mag[1::2]).all() and np.array_equal(rec.mag[0::2], mag[0::2])
    assert rec.counted == "movement mask" and np.array_equal(rec.mask, movement)


def test_a_log_with_a_gyro_axis_never_measured_is_refused_by_name(tmp_path):
    """A gyro column NaN in every row leaves no sample to run on: refused as estimate refuses it (it ended
    in np.interp's 'array of sample points is empty')."""
    from gyroemu.pipelines.formats.channels import ImuSeries
    from gyroemu.pipelines.formats.mcap_log import McapLogWriter
    from gyroemu.pipelines.formats.mcap_log import Recording as LogRecording
    from gyroemu.pipelines.twin.recording import RecordingError
    from gyroemu.sensors.samples import ImuSamples

    n = 200
    t = 1.0 + np.arange(n) * 0.01
    gyro = np.random.default_rng(1).standard_normal((n, 3))
    gyro[:, 1] = np.nan
    samples = ImuSamples(t=t, gyro=gyro, accel=np.ones((n, 3)), mag=np.full((n, 3), np.nan))
    path = tmp_path / "blind.mcap"
    with McapLogWriter(path, start_ns=EPOCH_2026_NS) as log:
        log.write(LogRecording(samples, truth=ImuSeries(t=t, q_wb=np.tile([1.0, 0, 0, 0], (n, 1)))))
    with pytest.raises(RecordingError, match="every IMU sample of device 'imu0' holds NaN"):
        load_recording(path)


def _recording(t, gyro, accel, q_true, mask, counted="movement mask", **truth) -> Recording:
    fs = 1.0 / float(np.median(np.diff(t)))
    return Recording(
        "syn.mcap", Path("syn.mcap"), "mcap", t, gyro, accel, None, q_true, mask, fs, None, counted, **truth
    )


def test_rest_phases_are_inside_the_recording_with_a_reference_and_outside_the_mask():
    """Still 0–10 s and 20–30 s at 100 Hz, moving between; the reference starts at 3 s and has a gap at
    24.0–24.2 s; the mask covers 8.5–21.5 s. Each found phase is cut to its longest stretch with a
    reference outside the mask."""
    from gyroemu.pipelines.identification import find_rest_phases

    fs, n = 100.0, 3000
    t = np.arange(n) / fs
    rng = np.random.default_rng(2)
    gyro = 1e-3 * rng.standard_normal((n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + 1e-2 * rng.standard_normal((n, 3))
    moving = (t >= 10) & (t < 20)
    gyro[moving, 0] += np.sin(2 * np.pi * t[moving])
    accel[moving, 1] += 2 * np.sin(2 * np.pi * 0.7 * t[moving])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    q[:300] = np.nan
    q[2400:2420] = np.nan
    mask = (t >= 8.5) & (t < 21.5)
    phases = find_rest_phases(t, gyro, accel)
    assert len(phases) == 2  # the layout's premise: one phase per still stretch, each covering …
    assert phases[0].start <= 300 and phases[0].stop >= 850 and phases[1].start <= 2150 and phases[1].stop >= 2900
    rests, info = rest_phases(_recording(t, gyro, accel, q, mask))
    assert rests == [slice(300, 850), slice(2420, phases[1].stop)]  # … so cut to these
    for r in rests:
        assert 0 <= r.start and r.stop - r.start >= 64 and r.stop <= n
        assert np.isfinite(q[r]).all() and not mask[r].any()
    intervals = [(t[r.start], t[r.stop - 1]) for r in rests]
    assert info == {"source": "2 rest phase(s)", "intervals_s": intervals, "still_s": intervals}


def test_without_rest_phases_the_samples_before_the_movement_stand_in():
    """2 s (too short for a rest phase of 3 s): the samples with a reference before the first movement
    sample, with or without the log's own truth; a recording that moves from its first sample gives
    the whole recording only with its own truth rate and specific force."""
    fs, n = 100.0, 200
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    gyro, accel = 1e-3 * rng.standard_normal((n, 3)), 9.81 + 1e-2 * rng.standard_normal((n, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    q[:20] = np.nan
    mask = t >= 1.2
    truth = {"omega_true": np.zeros((n, 3)), "force_true": np.zeros((n, 3))}
    for extra in ({}, truth):
        rests, info = rest_phases(_recording(t, gyro, accel, q, mask, **extra))
        assert rests == [slice(20, 120)]
        assert info["source"] == "samples before the first movement sample" and info["still_s"] == []
        assert info["intervals_s"] == [(t[20], t[119])]
    everywhere = np.ones(n, bool)
    rests, info = rest_phases(_recording(t, gyro, accel, q, everywhere, **truth))
    assert rests == [slice(20, n)] and info["source"].startswith("the whole recording")
    rests, info = rest_phases(_recording(t, gyro, accel, q, everywhere))
    assert rests == [] and info["source"].startswith("none")


# ---------------------------------------------------------------------------------------------------
# residuals.py


def test_welch_spectrum_of_white_noise_is_its_flat_one_sided_level():
    """Variance s² at fs: scipy's one-sided density 2 s²/fs between DC and Nyquist (two-sided s²/fs).
    Averaged over K = N/nperseg independent segments (overlap only adds) and the interior bins (every
    other one counted: Hann couples neighbours) and 3 axes, the relative sd is ≤ 1/sqrt(K·M·3)."""
    fs, n = 64.0, 2**14
    sd = np.array([0.5, 1.0, 2.0])
    x = np.random.default_rng(11).standard_normal((n, 3)) * sd
    f, p = welch_spectrum([x], fs)
    nper = 2 * (len(f) - 1)
    assert np.allclose(np.diff(f), fs / nper, rtol=0, atol=4 * EPS * fs)
    inner = (f > 0) & (f < fs / 2)
    level = (p[inner] / (2 * sd**2 / fs)).mean()
    bound = 5 / math.sqrt((n // nper) * (inner.sum() // 2) * 3)
    assert abs(level - 1) < bound, (level, bound)


def test_welch_spectrum_weights_segments_by_their_lengths():
    """Two segments: (n_a P_a + n_b P_b) / (n_a + n_b), P each one's own spectrum (the same segment
    length, both longer than it), to round-off."""
    fs = 64.0
    rng = np.random.default_rng(12)
    a, b = rng.standard_normal((1000, 3)), 3.0 * rng.standard_normal((3000, 3)) + 5.0
    f, p = welch_spectrum([a, b], fs)
    fa, pa = welch_spectrum([a], fs)
    fb, pb = welch_spectrum([b], fs)
    assert np.array_equal(f, fa) and np.array_equal(f, fb)
    want = (1000 * pa + 3000 * pb) / 4000
    assert np.allclose(p, want, rtol=8 * EPS, atol=0)
    assert np.all(p[1:-1] > pa[1:-1])  # b's 9 times the variance weighs 3 of 4


@pytest.mark.parametrize("fs, length, nper", [(2.0, 1000, 8), (3.5, 1000, 8), (100.0, 1000, 128), (100.0, 40, 40)])
def test_welch_segments_hold_two_seconds_but_at_least_8_samples_and_at_most_the_shortest(fs, length, nper):
    """A power of two near 2 s of samples (the 0.5 Hz resolution the twin's band from 1 Hz needs), never
    fewer than 8, and no more than the shortest segment holds."""
    from numpy.fft import rfftfreq

    x = np.random.default_rng(13).standard_normal((length, 3))
    f, _ = welch_spectrum([x, np.vstack([x, x])], fs)
    assert np.allclose(f, rfftfreq(nper, 1 / fs), rtol=0, atol=4 * EPS * fs)


def test_rest_residuals_allan_deviation_of_white_noise_is_n_over_sqrt_tau():
    """White rate noise of density N (rad/s/√Hz) at fs has per-sample sd N·√fs and Allan deviation
    N/√τ; at τ with K independent clusters its relative sd is ≤ 1/√(2(K − 1)): 5 of it."""
    fs, n = 100.0, 20000
    density = np.array([1e-3, 2e-3, 4e-3])
    rng = np.random.default_rng(14)
    gyro = rng.standard_normal((n, 3)) * density * math.sqrt(fs)
    accel = rng.standard_normal((n, 3)) * 10 * density * math.sqrt(fs)
    out = rest_residuals([gyro[: n // 2], gyro[n // 2 :]], [accel[: n // 2], accel[n // 2 :]], fs)
    assert out["samples"] == n
    for key, scale in (("gyro", 1.0), ("accel", 10.0)):
        adev, clusters = out[f"{key}_adev"], out[f"{key}_clusters"]
        for i in (0, 5, 10):  # τ = 0.01, 0.1, 1 s
            tau = TAUS_S[i]
            assert np.all(clusters[i] == 2 * math.floor(n / 2 / round(tau * fs)))
            want = scale * density / math.sqrt(tau)
            bound = 5 / np.sqrt(2 * (clusters[i] - 1))
            assert np.all(np.abs(adev[i] / want - 1) < bound), (key, tau, adev[i] / want, bound)
    # shorter than 16 finite samples: left out
    short = rest_residuals([gyro[:15]], [accel[:15]], fs)
    assert short["samples"] == 0 and np.isnan(short["gyro_adev"]).all() and np.isnan(short["gyro_std"]).all()


def test_pool_adev_weights_the_allan_variances_by_their_clusters():
    m = len(TAUS_S)
    a1, a2 = np.full((m, 3), 2.0), np.full((m, 3), 3.0)
    n1, n2 = np.full((m, 3), 10.0), np.full((m, 3), 30.0)
    a1[-2:] = np.nan  # run 1 too short for the last two τ (its clusters there, if any, do not count)
    n1[-2:] = [[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]]
    a2[-2], n2[-2] = np.nan, 0.0  # run 2 too short for the one before the last
    runs = [
        {"residuals": {"gyro_adev": a1, "gyro_clusters": n1}},
        {"residuals": {"gyro_adev": a2, "gyro_clusters": n2}},
    ]
    pooled, clusters = pool_adev(runs, "gyro")
    both = math.sqrt((10 * 4.0 + 30 * 9.0) / 40)
    assert np.allclose(pooled[:-2], both, rtol=4 * EPS, atol=0) and np.all(clusters[:-2] == 40)
    assert np.isnan(pooled[-2]).all() and np.all(clusters[-2] == 0)
    assert np.array_equal(pooled[-1], a2[-1]) and np.all(clusters[-1] == 30)


# ---------------------------------------------------------------------------------------------------
# runs.py


def test_filter_errors_times_each_filter_within_the_call_and_reports_its_failure():
    from gyroemu.pipelines.estimation.protocol import FilterSetup

    n = 50
    t = np.arange(n) / 100.0
    gyro, accel = np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    timings = {"filter no_such_module_xyz:Nope 6d": 1.5}
    start = time.perf_counter()
    out = filter_errors(
        ["no_such_module_xyz:Nope"],
        None,
        FilterSetup(rate_hz=100.0, use_mag=False),
        t,
        gyro,
        accel,
        None,
        q,
        np.ones(n, bool),
        timings,
    )
    wall = time.perf_counter() - start
    row = out["no_such_module_xyz:Nope"]
    assert row["error"].startswith("6d: ") and all(row[m] is None for m in ("total_9d", "inclination_6d"))
    spent = timings["filter no_such_module_xyz:Nope 6d"] - 1.5  # added to what was there
    assert 0.0 <= spent <= wall, (spent, wall)
    assert "filter no_such_module_xyz:Nope 9d" not in timings  # no 9D setup: not run


@pytest.fixture(scope="module")
def twin_runs(tmp_path_factory):
    """3 s of ``smooth_manoeuvre`` logged by the ideal device at 1 kHz, cut to its first 2.5 s, with a
    movement mask from 1 s and a reference whose rows are distinct; twin 0 of it sensed by an ideal
    device at 300 Hz (its instants k/300 s fall 0, 1/3 or 2/3 of a real sample past one), without and
    with a handling offset, and without with the reference lost over 1.5–1.6 s; what each run gave the
    filters."""
    from gyroemu.pipelines.twin import runs as twin_runs_module

    folder = tmp_path_factory.mktemp("twin_parts")
    log = folder / "syn.mcap"
    code = cli.main(
        ["simulate", "--scenario", "smooth_manoeuvre", "--duration", "3", "--device", "ideal", "--out", str(log)]
    )
    assert code in (0, None)
    device = folder / "ideal_300.toml"
    device.write_text(
        'description = "ideal at 300 Hz"\nresembles = ""\nrate_hz = 300\n\n[gyro.mechanism]\nkind = "ideal"\n'
    )
    rec = load_recording(log)
    n = 2500
    angle = 1e-4 * np.arange(n)
    q = np.stack([np.cos(angle / 2), 0 * angle, 0 * angle, np.sin(angle / 2)], axis=1)
    mask = np.arange(n) >= 1000
    real = dataclasses.replace(
        rec,
        t=rec.t[:n],
        gyro=rec.gyro[:n],
        accel=rec.accel[:n],
        mag=None,
        q_true=q,
        mask=mask,
        counted="movement mask",
        omega_true=None,
        force_true=None,
    )
    handling = Handling(np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.2, 0.3]))
    seen = []

    def capture(filters, setup9, setup6, t, gyro, accel, mag, q_true, mask, timings):
        seen.append({"t": np.array(t), "accel": np.array(accel), "q_true": np.array(q_true), "mask": np.array(mask)})
        return {}

    mp = pytest.MonkeyPatch()
    mp.setattr(twin_runs_module, "filter_errors", capture)
    try:
        runs = [run_one_twin(real, {}, None, str(device), 0, [], None, None, [], handling=h) for h in (None, handling)]
        lost = real.q_true.copy()
        lost[1500:1600] = np.nan  # a reference lost inside the movement mask
        runs.append(run_one_twin(dataclasses.replace(real, q_true=lost), {}, None, str(device), 0, [], None, None, []))
    finally:
        mp.undo()
    return real, handling, runs, seen


def test_a_twin_is_scored_at_the_nearest_real_sample_over_the_real_mask_inside_the_recording(twin_runs):
    real, _, runs, seen = twin_runs
    run, given = runs[0], seen[0]
    real_time = given["t"] + run["t0"]  # the ideal device's instants are its stamps
    dt = 1.0 / real.rate_hz
    inside = (real_time >= real.t[0] - 0.5 * dt) & (real_time <= real.t[-1] + 0.5 * dt)
    assert inside.any() and not inside.all()  # the twin runs past the cut recording
    nearest = np.argmin(np.abs(real_time[:, None] - real.t[None, :]), axis=1)
    assert np.all(np.abs(real.t[nearest[inside]] - real_time[inside]) <= 0.5 * dt)
    assert np.array_equal(given["q_true"][inside], real.q_true[nearest[inside]])
    assert np.isnan(given["q_true"][~inside]).all()
    want = real.mask[nearest] & inside
    assert want.any() and not want[inside].all()  # both sides of the mask inside, and its end outside
    assert np.array_equal(given["mask"], want)
    assert run["counted"] == int(want.sum()) and run["samples"] == len(given["t"])


def test_the_handling_offset_is_added_over_the_mask_only(twin_runs):
    """The same twin seed without and with ``[handling]``: the device's draws are the same, and the
    accelerometer the filters see differs by the twin seed's draw over the mask, by nothing elsewhere."""
    real, handling, runs, seen = twin_runs
    offset = handling.draw(twin_seed(0, real.name))
    assert runs[0]["handling_offset"] is None and runs[1]["handling_offset"] == [float(x) for x in offset]
    assert np.array_equal(seen[0]["mask"], seen[1]["mask"]) and np.array_equal(seen[0]["t"], seen[1]["t"])
    mask = seen[0]["mask"]
    diff = seen[1]["accel"] - seen[0]["accel"]
    assert np.array_equal(diff[~mask], np.zeros_like(diff[~mask]))
    roundoff = 4 * EPS * np.abs(seen[1]["accel"][mask]).max()
    assert np.allclose(diff[mask], offset, rtol=0, atol=roundoff)


# ---------------------------------------------------------------------------------------------------
# report.py


def _residuals(rng, gyro_sd: float, accel_sd: float) -> dict:
    g, a = gyro_sd * rng.standard_normal((1200, 3)), accel_sd * rng.standard_normal((1200, 3))
    return rest_residuals([g], [a], 100.0)


def _errors(values: dict) -> dict:
    return {
        f: {"total_9d": v, "heading_9d": v, "inclination_9d": v, "inclination_6d": v, "error": None}
        for f, v in values.items()
    }


def _trial(name="syn.mcap", real=None, seeds=None, mode="9D", offsets=None, q_true=None):
    """trial_result of a hand-made real run and twins: ``real`` and ``seeds`` the 9D totals per filter,
    ``q_true`` the reference (default zeros: finite throughout)."""
    real = {"mekf": 1.0, "vqf": 2.0} if real is None else real
    seeds = {"mekf": [1.1, 1.2], "vqf": [2.1, 2.3]} if seeds is None else seeds
    count = len(next(iter(seeds.values())))
    offsets = [None] * count if offsets is None else offsets
    rng = np.random.default_rng(len(name))
    n = 400
    rec = Recording(
        name,
        Path(name),
        "mcap",
        np.arange(n) / 100.0,
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        None,
        np.zeros((n, 4)) if q_true is None else q_true,
        np.arange(n) >= 100,
        100.0,
        None,
        "movement mask",
    )
    real_run = {"errors": _errors(real), "residuals": _residuals(rng, 0.01, 0.02)}
    real_run["residuals"]["gyro_std"] = np.array([0.01, 0.02, 0.005])
    twins = [
        {
            "errors": _errors({f: v[i] for f, v in seeds.items()}),
            "residuals": _residuals(rng, 0.01, 0.02),
            "counted": 300,
            "t0": 0.0,
            "handling_offset": offsets[i],
        }
        for i in range(count)
    ]
    rest = {"source": "1 rest phase(s)", "intervals_s": [(0.0, 0.99)], "still_s": [(0.0, 0.99)]}
    return trial_result(rec, real_run, twins, list(real), mode, rest, count, 100.0), real_run, twins


def _report(trials, pooled=False) -> TwinReport:
    settings = {"device": "ideal", "seeds": 2, "site": "site.toml"}
    pool = None
    if pooled:
        pool = pooled_residuals([t[1] for t in trials], [[t[2][i] for t in trials] for i in range(2)])
    return TwinReport(trials=[t[0] for t in trials], settings=settings, timings={"total": 1.0}, pooled_residuals=pool)


def test_the_report_gives_the_ranking_and_the_gyro_std_in_degrees_per_second():
    tr, real_run, twins = _trial()
    assert tr.ranking["real"] == tr.ranking["twin"] == ["mekf", "vqf"] and tr.ranking["same"] is True
    md = _report([(tr, real_run, twins)]).to_markdown()
    assert "Ranking by 9D total: real mekf < vqf; twin mekf < vqf — **same**." in md.splitlines()
    for key, scale, unit in (("gyro", 180 / math.pi, "°/s"), ("accel", 1.0, "m/s²")):
        (row,) = [line for line in md.splitlines() if line.startswith(f"| {key} | ")]
        cells = row.split(" | ")
        real_std = [float(v) for v in cells[1].removesuffix(f" {unit}").split(", ")]
        twin_std = [float(v) for v in cells[2].removesuffix(f" {unit}").split(", ")]
        want_real = real_run["residuals"][f"{key}_std"] * scale
        want_twin = np.mean([t["residuals"][f"{key}_std"] for t in twins], axis=0) * scale
        assert np.allclose(real_std, want_real, rtol=5e-3, atol=0), (key, real_std, want_real)
        assert np.allclose(twin_std, want_twin, rtol=5e-3, atol=0), (key, twin_std, want_twin)


def test_the_handling_offsets_drawn_are_noted_per_seed():
    tr, *_ = _trial(offsets=[[0.01, -0.02, 0.03], None])
    assert "handling offsets over the movement, m/s² (x, y, z) per seed: (0.01, -0.02, 0.03); none" in tr.notes
    tr, *_ = _trial()
    assert not any("handling" in n for n in tr.notes)


def test_a_filter_without_a_real_9d_total_leaves_the_ranking_out():
    for real in ({"mekf": None, "vqf": 2.0}, {"mekf": 1.0, "vqf": float("nan")}):
        tr, real_run, twins = _trial(real=real)
        assert tr.ranking["why"] == "a filter without a 9D total" and tr.ranking["same"] is None
        md = _report([(tr, real_run, twins)]).to_markdown()
        assert "Ranking by 9D total: not available (a filter without a 9D total)." in md
    tr, *_ = _trial(seeds={"mekf": [1.1, None], "vqf": [None, None]})
    assert tr.ranking["why"] == "a filter without a 9D total"
    tr, *_ = _trial(mode="6D")
    assert tr.ranking["why"] == "6D only"


T_975 = {1: math.tan(0.475 * math.pi), 2: math.sqrt(2 * 0.95**2 / (1 - 0.95**2))}
"""Student's t, 97.5 % quantile, in closed form for 1 and 2 degrees of freedom."""


@pytest.mark.parametrize("count", [2, 3])
@pytest.mark.parametrize("margin, unresolved", [(1.02, False), (0.98, True)])
def test_a_pair_is_unresolved_when_its_paired_differences_are_within_the_t_bound(count, margin, unresolved):
    """Differences d = m ± s (2 seeds: sd s·√2; 3 seeds m − s, m, m + s: sd s): unresolved exactly when
    |m| < t_{0.975, n−1} · sd / √n; m put 2 % either side of the bound."""
    s = 0.01
    sd = s * math.sqrt(2) if count == 2 else s
    m = margin * T_975[count - 1] * sd / math.sqrt(count)
    d = [m - s, m + s] if count == 2 else [m - s, m, m + s]
    vqf = [2.0, 2.1, 2.3][:count]
    mekf = [v + x for v, x in zip(vqf, d)]  # mekf − vqf = d > 0: the twins put vqf first
    tr, *_ = _trial(real={"mekf": 1.0, "vqf": 2.0}, seeds={"mekf": mekf, "vqf": vqf})
    assert tr.ranking["real"] == ["mekf", "vqf"]
    assert tr.ranking["unresolved"] == ([["mekf", "vqf"]] if unresolved else [])
    assert tr.ranking["same_within_spread"] is unresolved


def test_one_seed_cannot_order_a_pair():
    tr, *_ = _trial(seeds={"mekf": [1.0], "vqf": [5.0]})
    assert tr.ranking["unresolved"] == [["mekf", "vqf"]]
    tr, *_ = _trial(seeds={"mekf": [1.0, None], "vqf": [5.0, 6.0]})
    assert tr.ranking["unresolved"] == [["mekf", "vqf"]]


def test_the_pooled_table_gives_the_fewest_real_clusters_at_the_longest_tau():
    trials = [_trial("a.mcap"), _trial("bb.mcap")]
    for _, real_run, _ in trials:  # hand-set clusters: the last τ differs from the one before
        clusters = real_run["residuals"]["gyro_clusters"]
        clusters[-2] = [50.0, 60.0, 70.0]
        clusters[-1] = [3.0, 2.0, 4.0]
        real_run["residuals"]["gyro_adev"][-2:] = 1e-3
    report = _report(trials, pooled=True)
    assert np.array_equal(report.pooled_residuals["gyro"]["real_clusters"][-1], [6.0, 4.0, 8.0])
    md = report.to_markdown()
    section = md[md.index("## Residuals at rest, pooled over the 2 recordings") :]
    (row,) = [line for line in section.splitlines() if line.startswith("| gyro | ")]
    assert row.endswith(" | 4 |"), row


@pytest.mark.parametrize("n", [1, 4])
def test_a_full_disk_leaves_the_earlier_twin_report_as_it_was(tmp_path, monkeypatch, n):
    """twin.json, twin.md and the plots are written all or none: a disk that fills at any of them leaves
    the earlier report whole and no temporary file, or no folder where there was none."""
    import errno

    from full_disk import contents, disk_full_at

    out = tmp_path / "out"
    report = _report([_trial("a.mcap"), _trial("bb.mcap")])
    paths = report.save(out)
    assert [p.name for p in paths["plots"]] == ["a.png", "bb.png"]
    before = contents(out)
    report.settings["device"] = "another"
    asked = disk_full_at(monkeypatch, n)
    with pytest.raises(OSError) as caught:
        report.save(out)
    assert caught.value.errno == errno.ENOSPC and len(asked) == n
    assert contents(out) == before
    disk_full_at(monkeypatch, n)
    with pytest.raises(OSError):
        report.save(tmp_path / "new" / "out")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _filter_module(folder: Path) -> Path:
    """A file of user filters: ``Diverging`` (identity, then NaN from sample ``len(t) // 2``: a filter
    that diverged halfway), ``LateNaN`` (NaN on the last sample only) and ``Failing`` (raises)."""
    module = folder / "user_filters.py"
    module.write_text(
        "import numpy as np\n"
        "from gyroemu.pipelines.estimation.protocol import Estimate\n\n\n"
        "class Diverging:\n"
        "    name = 'diverging'\n\n"
        "    def __init__(self, setup):\n"
        "        self.setup = setup\n\n"
        "    def process(self, t, gyro, accel, mag=None):\n"
        "        q = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))\n"
        "        q[len(t) // 2 :] = np.nan\n"
        "        return Estimate(q_wb=q)\n\n\n"
        "class LateNaN(Diverging):\n"
        "    name = 'late_nan'\n\n"
        "    def process(self, t, gyro, accel, mag=None):\n"
        "        q = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))\n"
        "        q[-1] = np.nan\n"
        "        return Estimate(q_wb=q)\n\n\n"
        "class Failing(Diverging):\n"
        "    name = 'failing'\n\n"
        "    def process(self, t, gyro, accel, mag=None):\n"
        "        raise RuntimeError('mag' if mag is not None else 'no mag')\n"
    )
    return module


def test_a_filter_whose_attitude_turns_nan_at_a_counted_sample_has_failed(tmp_path):
    """An attitude that is NaN from halfway through the counted samples: no RMSE of the half before (it
    scored better than the filters that kept going), but an error saying where, in each mode run; NaN
    only at a sample not counted (the last, outside the mask): scored as before, exactly 0 against an
    identity reference. A filter failing in both modes: both errors kept."""
    from gyroemu.pipelines.estimation.protocol import FilterSetup

    module = _filter_module(tmp_path)
    n = 100
    t = np.arange(n) / 100.0
    gyro, accel, mag = np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), np.tile([0.0, 2e-5, -4e-5], (n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    mask = np.arange(n) < n - 1  # all but the last sample
    specs = [f"{module}:{name}" for name in ("Diverging", "LateNaN", "Failing")]
    setup9, setup6 = FilterSetup(rate_hz=100.0, use_mag=True), FilterSetup(rate_hz=100.0, use_mag=False)
    out = filter_errors(specs, setup9, setup6, t, gyro, accel, mag, q, mask, {})
    diverged, late, failing = (out[s] for s in specs)
    assert all(diverged[m] is None for m in ("total_9d", "heading_9d", "inclination_9d", "inclination_6d"))
    lost = "diverged: a non-finite attitude at 49 of 99 counted samples, the first at t = 0.5 s"
    assert diverged["error"] == f"9d: {lost}; 6d: {lost}"
    assert late["error"] is None and all(late[m] == 0.0 for m in ("total_9d", "inclination_6d"))
    assert failing["error"] == "9d: RuntimeError: mag; 6d: RuntimeError: no mag"
    assert failing["total_9d"] is None and failing["inclination_6d"] is None


def test_a_broad_trial_whose_magnetometer_never_reads_has_none(tmp_path):
    """imu_mag NaN in every row: no magnetometer (the run is 6D, not a 9D run on NaN), as for a log."""
    import h5py

    n = 200
    path = tmp_path / "blind.hdf5"
    with h5py.File(path, "w") as f:
        f["imu_gyr"], f["imu_acc"] = np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1))
        f["imu_mag"] = np.full((n, 3), np.nan)
        f["opt_quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        f["movement"] = np.arange(n) >= 100
        f.attrs["sampling_rate"] = 100.0
    assert load_recording(path).mag is None


def test_the_samples_counted_are_those_with_a_reference_on_both_sides(twin_runs):
    """A reference lost inside the movement mask: neither side scores those samples, and the note counts
    what is scored (mask and a finite reference), not the mask alone."""
    real, _, runs, seen = twin_runs
    given = seen[2]
    scored = given["mask"] & np.isfinite(given["q_true"]).all(axis=1)
    assert runs[2]["counted"] == int(scored.sum()) < runs[0]["counted"]
    q = np.zeros((400, 4))
    q[150:170] = np.nan  # 20 of the 300 masked samples (100…399) without a reference
    trial, _, _ = _trial(q_true=q)
    assert trial.notes[0].startswith("real: 280 samples counted (movement mask); twins: 300, 300")
