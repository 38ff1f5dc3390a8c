"""Every built-in device loads, measures, and is reproducible; presets list and Allan commands work."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import norm

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir
from gyroemu.sensors import ConfigError, load_device
from gyroemu.sensors.noise import flicker_bank

PRESETS = sorted(p.stem for p in (config_dir() / "devices").glob("*.toml"))
EPS = np.finfo(float).eps
TABLE_S = 2.0  # seconds on the constant-rate table
# The mean error of every axis of every preset is held to a z-score bound: a false alarm in 1e-3 runs of
# the whole set (Bonferroni over presets × axes).
Z = norm.isf(1e-3 / (2 * 3 * len(PRESETS)))


@pytest.fixture(scope="module")
def manoeuvre():
    return load_scenario("smooth_manoeuvre").simulate(duration=2.0)


def sample_count(device, span: float) -> int:
    """Samples a device takes over ``span`` s from 0: ``round(span / T)``, or with latencies ``K₂ − K₁ + 1``,
    ``K₁ = 1 + ceil(L_max / T)``, ``K₂ = floor((span + L_min) / T)`` (the samples whose shifted intervals
    lie in the truth, ``sensors/imu.py``)."""
    period = 1.0 / device.spec.rate_hz
    lat = device.latencies
    if not any(lat):
        return int(round(span / period))
    first = 1 + math.ceil(max(0.0, *lat) / period)
    return math.floor((span + min(0.0, *lat)) / period * (1 + 1e-12)) - first + 1


@pytest.mark.parametrize("name", PRESETS)
def test_preset_measures_reproducibly(name, manoeuvre):
    a = load_device(name, seed=5).measure(manoeuvre)
    b = load_device(name, seed=5).measure(manoeuvre)
    device = load_device(name)
    assert len(a) == (int(2.0 * device.spec.rate_hz) if not any(device.latencies) else sample_count(device, 2.0))
    assert np.all(np.isfinite(a.gyro)) and np.all(np.isfinite(a.accel))
    assert a.gyro.tobytes() == b.gyro.tobytes() and a.accel.tobytes() == b.accel.tobytes()


@pytest.fixture(scope="module")
def table():
    """10 °/s about the vertical, level, in Berlin: a constant rate plus the Earth's, whose horizontal part
    turns in body axes (|ω̇| ≤ 10 °/s · Ω_E cos φ = 8·10⁻⁶ rad/s²)."""
    return load_scenario("rate_table_constant").simulate(duration=TABLE_S)


def record_mean(traj):
    """(1/D) ∫ ω_b dt over the record, exactly for the cubic Hermite spline of ω_b the IMU samples
    (corrected trapezoid h(ω₀ + ω₁)/2 + h²(α₀ − α₁)/12 per step)."""
    h = traj.t[1] - traj.t[0]
    w, a = traj.omega_b, traj.alpha_b
    return np.sum(h * (w[1:] + w[:-1]) / 2 + h**2 * (a[:-1] - a[1:]) / 12, axis=0) / (traj.t[-1] - traj.t[0])


def mechanism_offset(device, omega, alpha, force):
    """(n, 3) rate a mechanism indicates beyond ω for constant inputs, from the closed forms of its notes."""
    m = device.mechanism
    if device.kind == "mems":  # −tan φ_e (k_q/m + α + Ω_d Ω_s)/(2ω_d) + G f_s (mems.py eqs. 2–4)
        w_d = 2 * np.pi * m.drive_frequency_hz
        w_s = 2 * np.pi * (m.drive_frequency_hz + m.mode_split_hz)
        drive, sense = [1, 2, 0], [2, 0, 1]
        quadrature = m.quadrature_stiffness_n_per_m / m.proof_mass_kg + alpha + omega[:, drive] * omega[:, sense]
        g_sensitivity = m.drive_force_sense_coupling_per_m * w_d / (2 * m.drive_quality_factor * w_s**2)
        return -math.tan(m.demodulation_phase_error_rad) * quadrature / (2 * w_d) + g_sensitivity * force[:, sense]
    if device.kind == "rate-gyro":  # the gimbal's static balance K θ = H (ω_IA cos θ − ω_SRA sin θ) of eq. (1)
        gain = m.spin_momentum / m.spring_stiffness_n_m_per_rad
        w_ia, w_sra, theta = omega, omega[:, [2, 0, 1]], np.zeros_like(omega)
        for _ in range(20):  # a contraction by H|ω|/K < 10⁻²: round-off after 10 steps
            theta = gain * (w_ia * np.cos(theta) - w_sra * np.sin(theta))
        return theta / gain - w_ia
    return np.zeros_like(omega)


def mechanism_slack(device, omega, omega_dot):
    """(3,) bound on what :func:`mechanism_offset` leaves out, rad/s, on the table."""
    m, w, w_dot = device.mechanism, np.abs(omega).max(), np.abs(omega_dot).max()
    # Lag of a unit-DC-gain mechanism behind the turning Earth rate: |mean error| ≤ τ_lag max|ω̇| (×2 for
    # the next order). Rate gyro: 2ζ/ω_n. MEMS: the Butterworth's DC group delay 1/(ω_c sin(π/2n)) plus the
    # envelope's σ/|p|² ≤ 1/|p|. Rate-integrating (a type-2 loop): no rate lag; its angle lags by
    # c ω̇/(k_t k_i), which moves the record's mean rate by at most twice that over D.
    lag = 0.0
    if device.kind == "rate-gyro":
        lag = 2 * m.damping_ratio / (2 * np.pi * m.natural_frequency_hz)
    elif device.kind == "mems":
        lag = 1 / abs(m.envelope_pole())
        if m.demodulator_bandwidth_hz is not None:
            lag += 1 / (2 * np.pi * m.demodulator_bandwidth_hz * math.sin(math.pi / (2 * m.demodulator_filter_order)))
    elif device.kind == "rate-integrating":
        k = m.torquer_scale_n_m_per_a * m.loop_integral_a_per_rad_s
        lag = 2 * m.damping_n_m_s_per_rad / k / TABLE_S
    slack = 2 * lag * w_dot
    if device.kind == "rlg":
        # The fringe count loses no angle: the record's mean rate is off by the two end counts' fractions,
        # under one fringe q in all. Lock-in pulls the scale factor by (Ω_L/Ω_d)² at most under dither.
        slack += m.fringe_angle_rad / TABLE_S + (m.lock_in_rate / m.dither_rate_amplitude) ** 2 * w
    if device.kind == "free-gyro":
        # Each rotor drifts at |T|/H ≤ (τ_i + τ_o/cos θ)/H, each bearing torque ≤ b|ω| + τ_c (eq. 4; cos θ = 1
        # on the level table to 10⁻⁸); an indicated axis sees at most both rotors' drifts.
        torque = m.inner_viscous_friction_n_m_s_per_rad * w + m.inner_coulomb_friction_n_m
        torque += m.outer_viscous_friction_n_m_s_per_rad * w + m.outer_coulomb_friction_n_m
        slack += 2 * torque / m.spin_momentum
    return slack


@pytest.mark.parametrize("name", PRESETS)
def test_preset_reads_a_constant_rate_within_its_own_error_budget(name, table):
    device = load_device(name, seed=5)
    samples = device.measure(table)
    e, period = device.gyro_errors, 1.0 / device.spec.rate_hz
    assert len(samples) == sample_count(device, TABLE_S)
    assert samples.t_true[-1] == pytest.approx(TABLE_S, abs=1e-12 + (period if any(device.latencies) else 0))
    omega, alpha, force = table.omega_b, table.alpha_b, table.specific_force_b
    # The record's mean rate is the mean indicated rate over [0, D]: the mean of the truth's Hermite spline,
    # plus the deterministic terms of errors.py applied to it and the mechanism's offset:
    # (I + S + M)(ω + m) + k (ω + m)² + b − ω (no ramp, temperature, g-sensitivity or clock error in the presets).
    truth = record_mean(table)
    # The offsets vary only with the turning Earth rate (by < 10⁻⁸ rad/s): their sample mean is their record mean.
    indicated = truth + np.mean(mechanism_offset(device, omega, alpha, force), axis=0)
    gain = np.eye(3) + np.diag(e.scale_factor) + e.cross_axis
    expected = gain @ indicated + e.nonlinearity * indicated**2 + e.bias - truth
    # Random parts of the mean over D, independent, added in variance: turn-on bias σ_on; white noise N/√D
    # (N the total density at the output: mechanism, error layer and the rate quantiser's LSB²T/12);
    # rate random walk from 0, K √(D/3); each Gauss–Markov component of the flicker bank (σ_j, τ_j),
    # 2σ_j² (τ_j/D)² (D/τ_j − 1 + e^{−D/τ_j}).
    variance = e.turn_on_bias**2 + device.gyro_noise_density**2 / TABLE_S + e.random_walk**2 * TABLE_S / 3
    if np.any(e.bias_instability):
        bank = flicker_bank(e.bias_instability, e.bias_instability_tau_range, period, n_axes=3)
        x = TABLE_S / bank.tau_c[:, None]
        variance = variance + np.sum(2 * bank.sigma**2 * (x - 1 + np.exp(-x)) / x**2, axis=0)
    # Bounded parts: the mechanism's neglected terms; a rate LSB dithered by noise of σ per sample biases
    # the mean by ≤ (LSB/π) e^{−2π²σ²/LSB²}; round-off of the inner cumulative angle, n_inner ε |ω|.
    slack = mechanism_slack(device, omega, np.diff(omega, axis=0) / np.diff(table.t)[:, None])
    if e.output_lsb:
        sigma2 = (device.gyro_noise_density**2 - e.output_lsb**2 * period / 12) / period
        slack = slack + e.output_lsb / np.pi * np.exp(-2 * np.pi**2 * sigma2 / e.output_lsb**2)
    slack = slack + device.inner_rate_hz * TABLE_S * EPS * np.abs(omega).max()
    bound = Z * np.sqrt(variance) + slack
    error = samples.gyro.mean(axis=0) - truth - expected
    assert np.all(np.abs(error) <= bound), f"{name}: mean error {error} rad/s beyond {bound}"


def test_unknown_preset_is_named():
    with pytest.raises(ConfigError, match="unknown device 'navigation_fgo'.*did you mean 'navigation_fog'"):
        load_device("navigation_fgo")


def gyroemu(*args):
    return subprocess.run([sys.executable, "-m", "gyroemu", *args], capture_output=True, text=True)


def test_presets_command_lists_every_preset():
    result = gyroemu("presets")
    assert result.returncode == 0, result.stderr
    assert {line.split()[0] for line in result.stdout.splitlines()[1:]} == set(PRESETS)


def test_allan_command_fits_a_log_and_draws_the_plot(tmp_path):
    log = tmp_path / "static.npz"
    device = tmp_path / "dev.toml"
    device.write_text('description = "x"\nrate_hz = 50\n[gyro.errors]\narw_deg_per_sqrt_h = 2.0\n')
    result = gyroemu(
        "simulate", "--scenario", "bench_static", "--device", str(device), "--duration", "600", "--out", str(log)
    )
    assert result.returncode == 0, result.stderr
    result = gyroemu("allan", str(log), "--out", str(tmp_path / "allan.png"), "--json")
    assert result.returncode == 0, result.stderr
    fitted = json.loads(result.stdout)["gyro"]["arw"]
    arw = [fitted[axis]["value"] for axis in "xyz"]
    # 30 000 samples: the ARW read off the curve is within a few percent of 2 deg/sqrt(h); allow 15 %.
    assert fitted["unit"] == "deg/sqrt(h)" and all(fitted[axis]["resolved"] for axis in "xyz")
    assert all(abs(v / 2.0 - 1) < 0.15 for v in arw) and fitted["spec"] == pytest.approx(2.0)
    assert (tmp_path / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = gyroemu("allan", str(device))
    assert bad.returncode == 2 and str(device) in bad.stderr


@pytest.mark.parametrize(
    "sensor, key", [("gyro", "bias_instability_deg_per_h"), ("accelerometer", "bias_instability_ug")]
)
def test_bias_instability_range_below_the_sample_interval_is_refused(tmp_path, sensor, key):
    """A flicker floor flat only at averaging times shorter than the 1 s sample interval cannot be
    made (the bank is fitted on [max(τ_min, T), τ_max]): refused when the device is built, naming the key,
    and the CLI exits 2 (it used to stop on a ValueError from the noise design, exit 1)."""
    device = tmp_path / "dev.toml"
    device.write_text(
        f'description = "test"\nrate_hz = 1.0\n[{sensor}.errors]\n{key} = 1.0\n'
        "bias_instability_tau_range_s = [0.01, 0.5]\n"
    )
    with pytest.raises(ConfigError) as error:
        load_device(device)
    assert error.value.key == f"{sensor}.errors.bias_instability_tau_range_s"
    if sensor == "gyro":
        log = tmp_path / "out.npz"
        args = ("--scenario", "bench_static", "--duration", "20", "--device", str(device), "--out", str(log))
        result = gyroemu("simulate", *args)
        assert result.returncode == 2 and "gyro.errors.bias_instability_tau_range_s" in result.stderr, result.stderr
