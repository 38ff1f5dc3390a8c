"""The magnetometer's lag behind the gyro read from a log (pipelines/estimation/field_lag.py), and
``--latency mag=auto`` on the command line."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest
from broad_trials import BROAD_DIR, needs_trial

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir, read_toml
from gyroemu.dynamics.rotation import quat_angle, quat_from_matrix, quat_from_rotvec, quat_multiply
from gyroemu.pipelines.estimation import (
    FilterSetup,
    estimate_field_lag,
    latencies_for_log,
)
from gyroemu.pipelines.estimation.mekf_kernels import rotations_since_first
from gyroemu.pipelines.formats.importers import read_broad
from gyroemu.pipelines.formats.mcap_log import Recording, truth_series, write_mcap
from gyroemu.pipelines.jobs.bench import LogCase, run_bench
from gyroemu.sensors import device_from_dict, load_device

EPS = np.finfo(float).eps
TRIAL_02 = BROAD_DIR / "02_undisturbed_slow_rotation_B.hdf5"
TRIAL_33 = BROAD_DIR / "33_disturbed_attached_magnet_2cm.hdf5"


def test_the_fits_strapdown_is_the_ordered_product_of_the_sample_turns():
    """The strapdown the fit turns the field with (``mekf_kernels.rotations_since_first``, the MEKF's
    start-up one) is ``exp(ω₁ dt) ⊗ exp(ω₂ dt) ⊗ …`` in that order from sample 0's axes: against the
    product taken one sample after another, and for a constant rate against ``exp(ω t)``, to round-off
    (N products of a few ε each); the product in the other order differs at first order (the rates do
    not commute)."""
    rng = np.random.default_rng(3)
    n = 1000
    t = np.arange(n) * 0.01
    gyro = rng.normal(scale=2.0, size=(n, 3))
    gyro[17] = np.nan  # a missing sample turns nothing
    got = quat_from_matrix(rotations_since_first(t, gyro))
    steps = quat_from_rotvec(np.where(np.isfinite(gyro), gyro, 0.0) * 0.01)
    steps[0] = [1.0, 0.0, 0.0, 0.0]  # sample 0's axes are the frame
    one_by_one = np.empty_like(steps)
    one_by_one[0] = steps[0]
    for k in range(1, n):
        one_by_one[k] = quat_multiply(one_by_one[k - 1], steps[k])
    assert quat_angle(got, one_by_one).max() < 8 * n * EPS
    reversed_order = np.empty_like(steps)
    reversed_order[0] = steps[0]
    for k in range(1, n):
        reversed_order[k] = quat_multiply(steps[k], reversed_order[k - 1])
    assert quat_angle(reversed_order, one_by_one).max() > 1e-3

    omega = np.array([0.3, -1.1, 0.7])
    constant = quat_from_matrix(rotations_since_first(t, np.tile(omega, (n, 1))))
    exact = quat_from_rotvec(np.outer(t, omega))
    assert quat_angle(constant, exact).max() < 8 * n * EPS * (1 + np.linalg.norm(omega) * t[-1])


def _lagging_ideal_imu(gyro_latency_s: float, mag_latency_s: float):
    spec = copy.deepcopy(read_toml(config_dir() / "devices" / "ideal.toml"))
    spec["gyro"]["latency_s"] = gyro_latency_s
    spec["magnetometer"]["latency_s"] = mag_latency_s
    return device_from_dict(spec, name="imu0")


def _lag_bound(truth, samples, delta: float) -> float:
    """What turning back by the sample's rate leaves, ω̇ (|Δ| + T) |Δ| / 2, as a lag against the turn
    ω |Δ| it corrects: RMS ω̇ / RMS ω · (|Δ| + T) |Δ| / 2, s."""
    spin_up = np.gradient(truth.omega_b, truth.t, axis=0)
    ratio = np.sqrt(np.mean(np.sum(spin_up**2, axis=1)) / np.mean(np.sum(truth.omega_b**2, axis=1)))
    T = float(np.median(np.diff(samples.t)))
    return float(ratio * (abs(delta) + T) * abs(delta) / 2)


@pytest.mark.parametrize(("gyro_l", "mag_l"), [(0.0, 0.02), (0.005, 0.02), (0.01, 0.004)])
def test_the_fit_finds_the_fields_lag_behind_the_gyro(gyro_l, mag_l):
    """An ideal IMU on the smooth manoeuvre (60 s), its gyro and magnetometer lagging the motion: the fit
    is Δ = L_m − L_g (negative when the field is read first) within four of its standard errors plus
    what the turn back leaves, ω̇ (|Δ| + T) |Δ| / 2 against a turn of ω |Δ| (the rule's residue of
    :mod:`latency`, as a lag: RMS ω̇ / RMS ω · (|Δ| + T) |Δ| / 2); a guard that the bound tells Δ from 0."""
    scenario = load_scenario("smooth_manoeuvre")
    traj = scenario.simulate(duration=60.0)
    samples = _lagging_ideal_imu(gyro_l, mag_l).measure(traj)
    t = samples.t - samples.t[0]
    fit = estimate_field_lag(t, samples.gyro, samples.mag)
    delta = mag_l - gyro_l
    bound = 4 * fit.standard_error_s + _lag_bound(truth_series(traj, samples), samples, delta)
    assert fit.observable, fit
    assert abs(fit.lag_s - delta) <= bound, (fit, delta, bound)
    assert bound < abs(delta) / 4


@pytest.fixture(scope="module")
def noisy_lagging_field():
    """An ideal IMU on the smooth manoeuvre (60 s), its magnetometer 20 ms late and 0.2 µT noisy."""
    traj = load_scenario("smooth_manoeuvre").simulate(duration=60.0)
    samples = _lagging_ideal_imu(0.0, 0.02).measure(traj)
    mag = samples.mag + 2e-7 * np.random.default_rng(1).normal(size=samples.mag.shape)
    return samples.t - samples.t[0], samples.gyro, mag


def _used_windows(t, gyro, mag, window_s=2.0, min_rate=0.2):
    """The fit's windows (indices of 2-s windows from t[0] holding two usable samples or more) and each
    sample's window index."""
    usable = np.isfinite(mag).all(axis=1) & (np.linalg.norm(gyro, axis=1) >= min_rate)
    window = np.floor(t / window_s).astype(int)
    used, counts = np.unique(window[usable], return_counts=True)
    return used[counts >= 2], window


def test_the_standard_error_is_the_jackknife_over_eight_stretches(noisy_lagging_field):
    """The standard error is the delete-one-group jackknife over eight contiguous stretches of the fit's
    windows: refitting with each stretch's field left out gives Δ_g, and √((k−1)/k Σ (Δ_g − Δ̄)²) is the
    fit's standard error. The fit takes each Δ_g as one Gauss–Newton step, which is the refit to first
    order in the step; the residual's nonlinearity over a lag Δ is of relative size ω Δ (the turn back,
    ``exp(−ω Δ) m``), so the two agree within RMS ω · Δ of each other."""
    t, gyro, mag = noisy_lagging_field
    fit = estimate_field_lag(t, gyro, mag)
    used, window = _used_windows(t, gyro, mag)
    stretch = np.arange(len(used)) * 8 // len(used)
    lags = []
    for g in range(8):
        left_out = mag.copy()
        left_out[np.isin(window, used[stretch == g])] = np.nan
        lags.append(estimate_field_lag(t, gyro, left_out).lag_s)
    jackknife = np.sqrt(7 / 8 * np.sum((np.array(lags) - np.mean(lags)) ** 2))
    nonlinearity = np.sqrt(np.mean(np.sum(gyro**2, axis=1))) * abs(fit.lag_s)
    assert fit.windows == len(used)
    assert abs(fit.standard_error_s / jackknife - 1) <= nonlinearity, (fit.standard_error_s, jackknife)


def test_a_window_with_one_usable_sample_is_left_out(noisy_lagging_field):
    """A window's mean is taken off its samples, so a window with a single usable sample carries nothing
    of Δ: the fit is the same, to the bit, as with that sample's field missing too."""
    t, gyro, mag = noisy_lagging_field
    used, window = _used_windows(t, gyro, mag)
    usable = np.linalg.norm(gyro, axis=1) >= 0.2
    in_window = np.flatnonzero(window == used[5])
    kept = in_window[usable[in_window]][0]
    lone = mag.copy()
    lone[in_window[in_window != kept]] = np.nan  # window 5 keeps one usable sample
    none = lone.copy()
    none[kept] = np.nan
    assert estimate_field_lag(t, gyro, lone) == estimate_field_lag(t, gyro, none)
    assert estimate_field_lag(t, gyro, none).windows == len(used) - 1


def test_no_turning_no_lag():
    """At rest the field carries nothing of Δ: not observable, and a setup keeps its latency."""
    traj = load_scenario("bench_static").simulate(duration=20.0)
    samples = _lagging_ideal_imu(0.0, 0.02).measure(traj)
    t = samples.t - samples.t[0]
    fit = estimate_field_lag(t, samples.gyro, samples.mag)
    assert not fit.observable and fit.windows == 0
    setup, lag = latencies_for_log(FilterSetup(rate_hz=1000.0), {"mag": "auto"}, t, samples.gyro, samples.mag)
    assert lag == fit and setup.mag_latency_s == 0.0


def test_latencies_for_log_adds_the_fit_to_the_gyros_latency():
    """``mag: auto`` is the gyro's latency plus the fit; a 6D setup, or no field, fits nothing; "auto" for
    the gyro is refused naming it."""
    traj = load_scenario("smooth_manoeuvre").simulate(duration=30.0)
    samples = _lagging_ideal_imu(0.005, 0.02).measure(traj)
    t = samples.t - samples.t[0]
    base = FilterSetup(rate_hz=1000.0)
    setup, lag = latencies_for_log(base, {"gyro": 0.005, "mag": "auto"}, t, samples.gyro, samples.mag)
    assert lag is not None and lag.observable
    assert setup.gyro_latency_s == 0.005 and setup.mag_latency_s == 0.005 + lag.lag_s
    six_d = FilterSetup(rate_hz=1000.0, use_mag=False)
    assert latencies_for_log(six_d, {"mag": "auto"}, t, samples.gyro, samples.mag) == (six_d, None)
    assert latencies_for_log(base, {"mag": "auto"}, t, samples.gyro, None) == (base, None)
    with pytest.raises(ValueError, match="gyro=auto"):
        latencies_for_log(base, {"gyro": "auto"}, t, samples.gyro, samples.mag)


@needs_trial(TRIAL_33.name)
def test_broad_a_magnet_on_the_sensor_is_not_read_as_a_lag():
    """BROAD's trial 33 has a magnet fixed 2 cm from the sensor: the field turns with the body and no lag
    makes it steady, so the fit says it cannot tell."""
    trial = read_broad(TRIAL_33)
    fit = estimate_field_lag(np.arange(len(trial)) / trial.rate_hz, trial.gyro, trial.mag_ut)
    assert not fit.observable, fit


@needs_trial(TRIAL_02.name)
def test_broad_the_lag_lies_within_what_the_latencies_allow():
    """BROAD's trial 02 (undisturbed): the field lags the gyro by less than its own latency behind the
    optical stamps (``aktos_t_broad``'s ``latency_s``, 15.38 ms; the gyro's is positive) and by more than 0."""
    trial = read_broad(TRIAL_02)
    fit = estimate_field_lag(np.arange(len(trial)) / trial.rate_hz, trial.gyro, trial.mag_ut)
    assert fit.observable, fit
    assert 0.0 < fit.lag_s < load_device("aktos_t_broad").latencies[2], fit


def _lagging_log(tmp_path, gyro_l: float, mag_l: float):
    """A gyroemu log of 30 s of the smooth manoeuvre through :func:`_lagging_ideal_imu`: its path, the
    samples and their truth."""
    scenario = load_scenario("smooth_manoeuvre")
    traj = scenario.simulate(duration=30.0)
    device = _lagging_ideal_imu(gyro_l, mag_l)
    samples = device.measure(traj)
    truth = truth_series(traj, samples)
    log = write_mcap(tmp_path / "late.mcap", Recording(samples, truth=truth, device=device), scenario=scenario)
    return log, samples, truth


def test_estimate_latency_mag_auto_on_the_command_line(tmp_path):
    """``gyroemu estimate --latency mag=auto --json`` on a log of a lagging ideal IMU reports the fit (the
    bound of ``test_the_fit_finds_the_fields_lag_behind_the_gyro``) and the magnetometer latency it used:
    the gyro's, from the log's device, plus the fit; in 6D it says nothing was read. (A bad ``--latency``
    exits 2: ``test_cli_robust``.)"""
    log, samples, truth = _lagging_log(tmp_path, 0.002, 0.02)
    out = tmp_path / "est.mcap"
    argv = ["estimate", str(log), "--out", str(out), "--latency", "mag=auto", "--json"]
    result = subprocess.run([sys.executable, "-m", "gyroemu", *argv], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    (lag,) = json.loads(result.stdout)["field_lags"]
    assert lag["applied"] and lag["mag_latency_ms"] == pytest.approx(2.0 + lag["lag_ms"], rel=4 * EPS)
    bound = _lag_bound(truth, samples, 0.018) * 1e3 + 4 * lag["standard_error_ms"]
    assert abs(lag["lag_ms"] - 18.0) <= bound < 18.0 / 4, lag
    six_d = subprocess.run(
        [sys.executable, "-m", "gyroemu", *argv[:-1], "--force", "--6d"], capture_output=True, text=True
    )
    assert six_d.returncode == 0, six_d.stderr
    assert "imu0: --latency mag=auto: 6D, no field used: nothing read" in six_d.stdout, six_d.stdout


def test_bench_reads_the_lag_for_every_filter(tmp_path):
    """``gyroemu bench --log LOG --latency mag=auto`` (``LogCase.latency_s``) on a log of an ideal IMU whose
    magnetometer lags its gyro by 20 ms: the report notes the fit, and the magnetometer's latency every
    filter is timed by is the fit (the gyro's is 0)."""
    log, samples, truth = _lagging_log(tmp_path, 0.0, 0.02)
    fit = estimate_field_lag(samples.t - samples.t[0], samples.gyro, samples.mag)
    assert fit.observable
    report = run_bench([LogCase(log, latency_s={"mag": "auto"})], filters=["mekf", "madgwick"], progress=False)
    (case,) = report.cases
    assert fit.describe() in case.notes
    assert any(f"magnetometer {fit.lag_s * 1e3:g} ms" in note for note in case.notes), case.notes
    assert [f.filter for f in case.filters] == ["mekf", "madgwick"]
