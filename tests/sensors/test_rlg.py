"""The ring laser gyro: Adler's equation against its closed forms and a brute-force integration, the
dither against the dead band, fringe quantisation, the dither random walk against its formula, and
the mechanism contract (chunks, seeds, config errors).

Statistical checks allow SIGMAS standard deviations of the estimate (1/√(2n) for a standard deviation
from n independent values); the deterministic ones are bounded by the physics (one fringe, one slip).
"""

import math

import numba
import numpy as np
import pytest
from scipy.special import jv

from gyroemu.dynamics import Environment, trajectory_from_world_motion
from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors import device_from_dict
from gyroemu.sensors.allan import allan_deviation
from gyroemu.sensors.mechanism import GyroTruth
from gyroemu.sensors.rlg import RingLaserGyro

SIGMAS = 4
ARCSEC = math.pi / (180 * 3600)
NO_DITHER = {"dither_amplitude_arcsec": 0.0}


def make_truth(t, omega):
    """A GyroTruth on the uniform grid ``t`` at a constant rate ``omega`` (3,)."""
    zero = np.zeros((len(t), 3))
    return GyroTruth(
        t=t,
        dt=float(t[1] - t[0]),
        omega=zero + np.asarray(omega, float),
        alpha=zero,
        specific_force=zero,
        q_is=np.tile([1.0, 0, 0, 0], (len(t), 1)),
        temperature_degC=np.full(len(t), 25.0),
    )


def run(gyro, duration, omega, seed=0, chunk=400_000, every=1):
    """Run ``gyro`` for ``duration`` s at constant rates ``omega`` (3,) on its own inner grid, in chunks
    (as the IMU does). Returns t, the indicated angle and the raw arrays, at every ``every``-th node."""
    h = 1.0 / gyro.simulation_rate_hz
    n = int(round(duration / h))
    state, rng = {}, np.random.default_rng(seed)
    keep: dict = {"t": [], "angle": []}
    offset = np.zeros(3)
    for first in range(0, n, chunk):
        j = np.arange(first, min(first + chunk, n) + 1)
        response = gyro.respond(make_truth(j * h, omega), rng, state)
        pick = (j % every == 0) & ((j > first) | (first == 0))  # the shared first node only once
        keep["t"].append(j[pick] * h)
        keep["angle"].append(response.angle[pick] + offset)
        offset = offset + response.angle[-1]
        for name, values in response.raw.items():
            keep.setdefault(name, []).append(values[pick])
    return {name: np.concatenate(parts) for name, parts in keep.items()}


def lock_in_deviation(gyro, out, omega):
    """χ = ψ − K(θ + θ_d): what lock-in did to the beat phase, rad (no fringe quantisation)."""
    ideal = out["t"][:, None] * np.asarray(omega, float) + out["dither_angle_rad"]
    return out["beat_phase_rad"] - gyro.beat_phase_per_rad * ideal


# --------------------------------------------------------------------------------------------------
# Geometry: beat phase per radian and the fringe quantum
# --------------------------------------------------------------------------------------------------


def test_beat_scale_factor_and_fringe_quantum_from_the_cavity():
    gyro = RingLaserGyro()
    side = 0.10  # the default cavity: an equilateral triangle
    area, perimeter, wavelength = math.sqrt(3) / 4 * side**2, 3 * side, 632.8e-9
    assert gyro.beat_phase_per_rad == pytest.approx(2 * math.pi * 4 * area / (wavelength * perimeter), rel=1e-14)
    assert gyro.fringe_angle_rad == pytest.approx(wavelength * perimeter / (4 * area), rel=1e-14)
    assert gyro.fringe_angle_rad / ARCSEC == pytest.approx(2.26, abs=0.01)  # 1–3″ per pulse

    # Output = q × (fringe count) − dither pick-off, counts are whole numbers of fringes of ψ.
    out = run(gyro, 0.05, [0.01, -0.2, 3.0])
    count = out["fringe_count"]
    assert count.dtype == np.int64
    np.testing.assert_array_equal(count, np.floor(out["beat_phase_rad"] / (2 * math.pi)))
    expected = gyro.fringe_angle_rad * (count - count[0]) - (out["dither_angle_rad"] - out["dither_angle_rad"][0])
    np.testing.assert_allclose(out["angle"], expected, rtol=0, atol=1e-15)


# --------------------------------------------------------------------------------------------------
# Lock-in without dither: the dead band and Adler's law
# --------------------------------------------------------------------------------------------------


def test_dead_band_without_dither():
    gyro = RingLaserGyro(**NO_DITHER)
    lock = gyro.lock_in_rate
    omega = np.array([0.3, -0.6, 0.95]) * lock
    out = run(gyro, 2.0, omega)
    # The beat phase settles on the stable fixed point of Adler's equation, sin ψ* = Ω/Ω_L, cos ψ* > 0
    # (relaxing at K Ω_L cos ψ* ≥ 170 s⁻¹: long settled after 2 s), to the O((kh)²) of the two-term
    # Picard step (kh = K Ω_L h = 0.017; measured 4·10⁻⁵) …
    psi = out["beat_phase_rad"][-1]
    kh = gyro.beat_phase_per_rad * lock / gyro.simulation_rate_hz
    np.testing.assert_allclose(np.sin(psi), omega / lock, rtol=0, atol=kh**2)
    assert np.all(np.cos(psi) > 0)
    # … so the fringe count stops: no output over the second half, though the true angle grew by
    # 26 to 84 fringes.
    half = len(out["t"]) // 2
    assert np.all(out["fringe_count"][half:] == out["fringe_count"][-1])
    assert np.all(np.abs(omega) * 1.0 > 25 * gyro.fringe_angle_rad)


def crossing_times(t, psi):
    """Times at which ψ (increasing) passes each multiple of 2π, by linear interpolation."""
    levels = np.arange(np.ceil(psi[0] / (2 * math.pi)), np.floor(psi[-1] / (2 * math.pi)) + 1) * 2 * math.pi
    return np.interp(levels, psi, t)


@pytest.mark.parametrize("ratio", [1.02, 1.2, 2.0, 5.0, 20.0])
def test_mean_beat_follows_adlers_law_above_lock_in(ratio):
    gyro = RingLaserGyro(**NO_DITHER)
    K, lock = gyro.beat_phase_per_rad, gyro.lock_in_rate
    out = run(gyro, 2.0, [ratio * lock, -ratio * lock, 0.0])
    # The two-term Picard step drops the (kh)³/6 term of each step (kh = KΩ_L h = 0.017): it acts as a
    # lock-in rate off by at most (kh)²/6 relatively, and the beat K√(Ω² − Ω_L²) moves by that times
    # |d ln beat / d ln Ω_L| = 1/(r² − 1). Whole slip periods, between the first and the last 2π
    # crossing, leave no partial-period error.
    kh = K * lock / gyro.simulation_rate_hz
    tolerance = kh**2 / 6 / (ratio**2 - 1)
    adler = K * lock * math.sqrt(ratio**2 - 1)
    for axis, sign in ((0, 1), (1, -1)):  # negative rates: the same law with the sign of Ω
        crossings = crossing_times(out["t"], sign * out["beat_phase_rad"][:, axis])
        mean_beat = 2 * math.pi * (len(crossings) - 1) / (crossings[-1] - crossings[0])
        assert mean_beat == pytest.approx(adler, rel=tolerance)
    # Against the ideal Sagnac beat: pulled down by about Ω_L²/(2Ω²).
    assert mean_beat / (K * ratio * lock) < 1 - 0.4 / ratio**2


# --------------------------------------------------------------------------------------------------
# Integrating Adler's equation through the dither: against a brute-force RK4
# --------------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _brute_force_lock_in(K, k_lock, omega, amplitudes, f_d, h, every, chi0, nodes):
    """χ' = −k sin(K(Ωt + θ_d(t)) + χ) by classic RK4 at step h (every ``every`` steps a node), with the
    dither θ_d = A(u) sin 2πu, u = f_d t, A linear from A_n to A_{n+1} over cycle n."""

    def f(t, chi):
        u = f_d * t
        n = int(math.floor(u))
        amplitude = amplitudes[n] + (amplitudes[n + 1] - amplitudes[n]) * (u - n)
        return -k_lock * math.sin(K * (omega * t + amplitude * math.sin(2 * math.pi * u)) + chi)

    out = np.empty(nodes)
    chi = chi0
    for i in range(nodes):
        out[i] = chi
        for s in range(every):
            t = (i * every + s) * h
            f1 = f(t, chi)
            f2 = f(t + h / 2, chi + h / 2 * f1)
            f3 = f(t + h / 2, chi + h / 2 * f2)
            f4 = f(t + h, chi + h * f3)
            chi += h / 6 * (f1 + 2 * f2 + 2 * f3 + f4)
    return out


@pytest.mark.parametrize("rate, spread", [(0.0, 0.0), (0.0, 0.05), (3e-3, 0.05)])
def test_lock_in_through_the_dither_agrees_with_brute_force_rk4(rate, spread):
    gyro = RingLaserGyro(dither_amplitude_noise_fraction=spread)
    K, k = gyro.beat_phase_per_rad, gyro.beat_phase_per_rad * gyro.lock_in_rate
    duration, seed = 0.05, 3
    out = run(gyro, duration, [rate, 0.0, 0.0], seed=seed)
    chi = lock_in_deviation(gyro, out, [rate, 0.0, 0.0])[:, 0]
    # The same dither amplitudes: the Generator's draws after the three initial phases.
    rng = np.random.default_rng(seed)
    rng.random(3)
    amplitudes = gyro._cycle_amplitudes(rng, int(duration * gyro.dither_frequency_hz) + 3)[:, 0]
    # RK4 at ≤ 0.02 rad of beat phase per step at the peak dither rate (~10⁸ steps per second).
    h = 1.0 / gyro.simulation_rate_hz
    every = math.ceil(h * K * gyro.dither_rate_amplitude * 1.2 / 0.02)
    reference = _brute_force_lock_in(
        K, k, rate, amplitudes, gyro.dither_frequency_hz, h / every, every, chi[0], len(chi)
    )
    # Each turn-around kicks χ by ~KΩ_L √(2π/a) = 0.022 rad (a = K Ω_d ω_d); 44 of them here. Agree to
    # 2 % of one kick all along (4·10⁻⁴ rad of beat phase, 8·10⁻¹⁰ rad of angle); measured ~10⁻⁴.
    kick = k * math.sqrt(2 * math.pi / (K * gyro.dither_rate_amplitude * 2 * math.pi * gyro.dither_frequency_hz))
    assert np.max(np.abs(chi - reference)) < 0.02 * kick
    assert np.ptp(reference) > 2 * kick  # the lock-in did act


# --------------------------------------------------------------------------------------------------
# Dither: no dead band, a random walk instead
# --------------------------------------------------------------------------------------------------


def test_dither_removes_the_dead_band():
    dithered, plain = RingLaserGyro(), RingLaserGyro(**NO_DITHER)
    lock, duration = dithered.lock_in_rate, 10.0
    omega = np.array([0.2, -0.5, 0.8]) * lock  # all inside the dead band
    locked = run(plain, duration, omega, every=320)["angle"][-1]
    read = run(dithered, duration, omega, every=320)["angle"][-1]
    true = omega * duration
    # Without dither: nothing beyond the initial pull-in (a fraction of a fringe to a few fringes).
    assert np.all(np.abs(locked) < 0.02 * np.abs(true))
    # With dither: the true angle, within the dither random walk N√T and a fringe at each end.
    bound = SIGMAS * dithered.dither_random_walk() * math.sqrt(duration) + 2 * dithered.fringe_angle_rad
    assert np.all(np.abs(read - true) < bound)
    # Scale factor error within that bound: below 2 % at 0.2 Ω_L (= 40°/h), 0.5 % at 0.8 Ω_L.
    assert np.all(np.abs(read / true - 1) < bound / np.abs(true))
    assert np.all(bound / np.abs(true) < [0.02, 0.008, 0.005])


def test_fixed_dither_leaves_the_bessel_residual_dead_band():
    # Without the random amplitude, averaging ψ' = KΩ − KΩ_L sin(ψ̄ + Kθ₀ sin ω_d t) over the dither
    # keeps only the J₀ term: a dead band of Ω_L |J₀(Kθ₀)| (1.8 % of Ω_L here; Aronowitz 1971), with
    # Adler's law around it. First-order averaging in K Ω_L/ω_d = 0.2: the tests bracket ±20 %.
    gyro = RingLaserGyro(dither_amplitude_noise_fraction=0.0)
    K, duration = gyro.beat_phase_per_rad, 8.0
    residual = gyro.lock_in_rate * abs(jv(0, K * gyro.dither_amplitude))
    assert residual / gyro.lock_in_rate == pytest.approx(0.0184, abs=1e-4)
    omega = np.array([0.8, -0.8, 2.0]) * residual
    out = run(gyro, duration, omega, seed=1)
    cycle_starts = np.searchsorted(
        out["t"], np.arange(1, duration * gyro.dither_frequency_hz) / gyro.dither_frequency_hz
    )
    slow = (out["beat_phase_rad"] - K * out["dither_angle_rad"])[cycle_starts]  # ψ̄, once per dither cycle
    t = out["t"][cycle_starts]
    # Inside: locked, the slow phase stands still (after the pull-in) …
    assert np.all(np.abs(slow[-1, :2] - slow[len(t) // 2, :2]) < 0.1)
    # … outside: it slips at the averaged Adler rate K √(Ω² − Ω_r²), over whole slip periods.
    crossings = crossing_times(t, slow[:, 2])
    beat = 2 * math.pi * (len(crossings) - 1) / (crossings[-1] - crossings[0])
    assert len(crossings) > 10
    assert beat == pytest.approx(K * residual * math.sqrt(2.0**2 - 1), rel=0.05)  # measured 10⁻⁴


def test_dither_random_walk_matches_killpatricks_formula():
    # Lock-in 5× the default so that the walk is clear of the fringe quantisation within a minute;
    # the step must then be finer for the lock-in time (k h ≤ 0.05).
    base = dict(lock_in_rate_deg_per_h=1000.0, simulation_rate_hz=64_000.0)
    duration, tau = 40.0, 0.1
    ratios = []
    for changes in ({}, {"lock_in_rate_deg_per_h": 500.0}, {"dither_amplitude_arcsec": 400.0}):
        gyro = RingLaserGyro(**(base | changes))
        out = run(gyro, duration, [0.0, 0.0, 0.0], seed=11, every=round(tau * gyro.simulation_rate_hz))
        error = lock_in_deviation(gyro, out, [0.0, 0.0, 0.0]) / gyro.beat_phase_per_rad  # angle error, rad
        steps = np.diff(error, axis=0).ravel()  # independent increments over τ, 3 axes
        measured = np.sqrt(np.mean(steps**2) / tau)
        formula = gyro.dither_random_walk()  # Ω_L / √(K Ω_d)
        assert gyro.intrinsic_noise_density() == formula
        # Statistical bound, plus 5 % for the stationary-phase approximation behind the formula (each
        # kick is ~0.1 rad here: second-order terms of that relative size); measured within 3 %.
        assert abs(measured / formula - 1) < SIGMAS / math.sqrt(2 * steps.size) + 0.05
        ratios.append(measured / formula)
    # The formula's dependences: ∝ Ω_L, ∝ 1/√Ω_d (the three ratios agree).
    assert np.ptp(ratios) < 2 * SIGMAS / math.sqrt(2 * steps.size)


def test_default_random_walk_is_a_navigation_grade_arw():
    gyro = RingLaserGyro()
    arw_deg_per_sqrt_h = gyro.intrinsic_noise_density() * 180 / math.pi * 60
    assert 0.0025 < arw_deg_per_sqrt_h < 0.0035  # GG1320AN class: ≤ 0.0035°/√h
    assert RingLaserGyro(**NO_DITHER).intrinsic_noise_density() == 0.0


def test_fringe_quantisation_has_the_allan_minus_one_slope():
    gyro = RingLaserGyro()
    duration, output_hz = 20.0, 1000.0
    every = round(gyro.simulation_rate_hz / output_hz)
    out = run(gyro, duration, [0.0, 0.0, 0.0], seed=5, every=every)
    rate = np.diff(out["angle"], axis=0) * output_hz  # 1 kHz output, rad/s
    q = gyro.fringe_angle_rad / math.sqrt(12)  # IEEE 952's Q for a counter of one fringe per pulse
    n = gyro.dither_random_walk()
    taus = np.array([1e-3, 4e-3, 16e-3, 64e-3])
    for axis in range(3):
        allan = allan_deviation(rate[:, axis], 1 / output_hz, taus=taus)
        model = np.sqrt(3 * q**2 / allan.tau**2 + n**2 / allan.tau)
        assert np.all(np.abs(allan.adev / model - 1) < SIGMAS / np.sqrt(2 * allan.edf))
        # Quantisation dominates there (below τ = 3Q²/N² ≈ 40 s): slope −1.
        slope = np.polyfit(np.log(allan.tau), np.log(allan.adev), 1)[0]
        assert slope == pytest.approx(-1.0, abs=0.03)


# --------------------------------------------------------------------------------------------------
# The mechanism contract
# --------------------------------------------------------------------------------------------------


def test_chunks_continue_one_run_and_seeds_reproduce():
    gyro = RingLaserGyro()
    whole = run(gyro, 0.3, [0.02, -0.001, 0.5], seed=4, chunk=10**9)
    pieces = run(gyro, 0.3, [0.02, -0.001, 0.5], seed=4, chunk=1_237)  # chunks cut mid dither cycle
    np.testing.assert_array_equal(pieces["fringe_count"], whole["fringe_count"])
    np.testing.assert_array_equal(pieces["dither_angle_rad"], whole["dither_angle_rad"])
    # ψ (up to 10⁵ rad here) is summed step by step, and a chunk restarts e^{iψ} from ψ: at most one
    # rounding of ψ per step apart.
    psi = whole["beat_phase_rad"]
    np.testing.assert_allclose(pieces["beat_phase_rad"], psi, rtol=0, atol=len(psi) * np.spacing(np.abs(psi).max()))
    np.testing.assert_allclose(pieces["angle"], whole["angle"], rtol=0, atol=1e-12)
    again = run(gyro, 0.3, [0.02, -0.001, 0.5], seed=4, chunk=10**9)
    for name in whole:
        np.testing.assert_array_equal(again[name], whole[name])
    other = run(gyro, 0.3, [0.02, -0.001, 0.5], seed=5, chunk=10**9)
    assert not np.array_equal(other["beat_phase_rad"], whole["beat_phase_rad"])


def test_inside_an_imu():
    t = np.arange(0, 0.5 + 1e-9, 1e-3)
    w = np.broadcast_to([0.1, -0.05, 0.3], (len(t), 3))
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    zero = np.zeros((len(t), 3))
    traj = trajectory_from_world_motion(t, q, w, zero, zero, zero, zero, Environment.inertial(9.81))
    device = device_from_dict(
        {
            "description": "rlg",
            "rate_hz": 1000.0,
            "gyro": {"mechanism": {"kind": "rlg"}, "errors": {"arw_deg_per_sqrt_h": 0.0035}},
        }
    )
    assert device.inner_rate_hz == RingLaserGyro().simulation_rate_hz
    samples = device.measure(traj)
    # The body rate, to within a fringe per sample at worst, and to the ARW over the whole run.
    assert np.all(np.abs(samples.gyro - w[1:]) < 2 * RingLaserGyro().fringe_angle_rad * 1000 + 1e-3)
    mean_error = samples.gyro.mean(axis=0) - w[0]
    assert np.all(np.abs(mean_error) < (2 * RingLaserGyro().fringe_angle_rad + 1e-5) / 0.5)
    assert samples.raw["rlg"]["fringe_count"].shape == (len(samples), 3)


@pytest.mark.parametrize(
    "key, value",
    [
        ("perimeter_m", -0.3),
        ("area_m2", -1e-3),
        ("area_m2", 0.01),
        ("wavelength_nm", 0.0),
        ("lock_in_rate_deg_per_h", -10.0),
        ("dither_frequency_hz", -400.0),
        ("dither_amplitude_arcsec", -1.0),
        ("dither_amplitude_noise_fraction", 0.8),
        ("simulation_rate_hz", 10_000.0),
        ("simulation_rate_hz", -1.0),
    ],
)
def test_bad_parameters_name_their_key(key, value):
    with pytest.raises(ConfigError) as err:
        validate(RingLaserGyro, {"kind": "rlg", key: value}, prefix="gyro.mechanism")
    assert err.value.key == f"gyro.mechanism.{key}"


@pytest.mark.parametrize(
    "key, value, limit",
    [
        ("perimeter_m", 1e300, "1000"),  # P² overflowed in the area check (OverflowError)
        ("perimeter_m", 1e200, "1000"),
        ("dither_amplitude_arcsec", 1e300, "3600"),  # all-NaN beat_phase_rad, INT64_MIN fringe counts
        ("wavelength_nm", 1e300, "10000"),  # K vanished: the error blamed gyro.errors.arw_deg_per_sqrt_h
    ],
)
def test_absurd_sizes_are_refused_naming_their_key_and_why(key, value, limit):
    with pytest.raises(ConfigError, match=f"more than the limit of {limit}: ") as err:
        device_from_dict(
            {"description": "x", "rate_hz": 1000, "gyro": {"mechanism": {"kind": "rlg", key: value}}}, name="dev.toml"
        )
    assert err.value.key == f"gyro.mechanism.{key}" and err.value.file == "dev.toml"


def test_a_wavelength_too_short_is_refused_naming_it():
    """10⁻³⁰⁰ nm made K overflow, and simulation_rate_hz was asked for "at least inf Hz"."""
    with pytest.raises(ConfigError, match="less than the limit of 100: ") as err:
        device_from_dict(
            {"description": "x", "rate_hz": 1000, "gyro": {"mechanism": {"kind": "rlg", "wavelength_nm": 1e-300}}},
            name="dev.toml",
        )
    assert err.value.key == "gyro.mechanism.wavelength_nm" and "inf" not in str(err.value)


def test_the_largest_dither_still_gives_a_finite_beat():
    """At the limits (1°, 10 kHz) the beat phase and the fringe counts are finite numbers."""
    rlg = RingLaserGyro(dither_amplitude_arcsec=3600.0, dither_frequency_hz=10_000.0, simulation_rate_hz=1e6)
    t = np.arange(2001) * 1e-6
    response = rlg.respond(make_truth(t, [0.1, 0.0, -0.2]), np.random.default_rng(0))
    assert np.isfinite(response.raw["beat_phase_rad"]).all() and np.isfinite(response.angle).all()
    assert response.raw["fringe_count"].min() > np.iinfo(np.int64).min


def test_the_step_must_resolve_the_lock_in_time_and_the_dither():
    # Too slow for the lock-in time 1/(K Ω_L) without dither (k h ≤ 0.05) …
    with pytest.raises(ConfigError, match="lock-in time") as err:
        validate(RingLaserGyro, {"lock_in_rate_deg_per_h": 2000.0, **NO_DITHER})
    assert err.value.key == "simulation_rate_hz"
    # … too slow for the dither (≥ 50 steps per cycle) …
    with pytest.raises(ConfigError, match="does not resolve the 800 Hz dither"):
        validate(RingLaserGyro, {"dither_frequency_hz": 800.0})
    # … and a truth grid coarser than the configured rate.
    with pytest.raises(ValueError, match="simulation_rate_hz"):
        RingLaserGyro().respond(make_truth(np.arange(100) * 1e-3, [0, 0, 0]), np.random.default_rng(0))


def test_kernel_sine_and_cosine_are_accurate_to_round_off():
    """The kernels' own sin/cos (Cody–Waite reduction and Taylor series to r¹⁵/r¹⁶): within the
    documented 2.2·10⁻¹⁶ of the true values for |x| < 10⁶, against numpy's (themselves within one ulp,
    ≤ 2.2·10⁻¹⁶ for values ≤ 1), over every quadrant and the whole reduced range |r| ≤ π/4, where the
    series' last terms matter most."""
    from gyroemu.sensors.rlg import _sincos

    x = np.concatenate([np.linspace(-8.0, 8.0, 4001), np.linspace(1e5, 1e5 + 8.0, 401), [math.pi / 4, -math.pi / 4]])
    got = np.array([_sincos(v) for v in x])
    bound = 2.2e-16 + 2.2e-16
    assert np.abs(got[:, 0] - np.sin(x)).max() <= bound
    assert np.abs(got[:, 1] - np.cos(x)).max() <= bound


def test_filon_weight_series_matches_the_closed_form_within_its_truncation():
    """Below |x| = 0.05 f = (e^{ix} − 1)/(ix) comes from its Taylor series; written stably, the closed
    form is Re f = sin x / x, Im f = 2 sin²(x/2)/x, and the series must agree within 10⁻⁹."""
    from gyroemu.sensors.rlg import _filon_weights

    for x in (0.049, -0.045, 0.03, 0.01):
        f, _, _ = _filon_weights(complex(math.cos(x), math.sin(x)), x)
        assert abs(f.real - math.sin(x) / x) < 1e-9
        assert abs(f.imag - 2 * math.sin(0.5 * x) ** 2 / x) < 1e-9
