"""The fibre-optic gyro: the Sagnac scale factor, the open loop's sine law, the closed loop's
linearity and range, the shot + RIN noise formula against a photon-level simulation of the detector
and against the gyro's own output, and the mechanism contract (chunks, seeds, config errors).

Statistical checks allow SIGMAS standard deviations of the estimate: σ/√n for a mean, 1/√(2n)
(relative) for a standard deviation from n independent values.
"""

import math
import re

import numpy as np
import pytest
from scipy.special import jv

from gyroemu.dynamics import Environment, trajectory_from_world_motion
from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors import device_from_dict
from gyroemu.sensors.allan import allan_deviation
from gyroemu.sensors.fog import ELEMENTARY_CHARGE, SPEED_OF_LIGHT, FiberOpticGyro
from gyroemu.sensors.mechanism import GyroTruth

SIGMAS = 4
DEG = math.pi / 180


def make_truth(t, omega, alpha=None):
    """A GyroTruth on the uniform grid ``t`` with rates ``omega`` (3,) or (M, 3)."""
    zero = np.zeros((len(t), 3))
    return GyroTruth(
        t=t,
        dt=float(t[1] - t[0]),
        omega=zero + np.asarray(omega, float),
        alpha=zero if alpha is None else zero + alpha,
        specific_force=zero,
        q_is=np.tile([1.0, 0, 0, 0], (len(t), 1)),
        temperature_degC=np.full(len(t), 25.0),
    )


def grid(duration, hz):
    return np.arange(int(round(duration * hz)) + 1) / hz


def mean_rate(gyro, omega, duration=20.0, hz=1000.0, seed=0):
    """The indicated mean rate (3,) over ``duration`` at constant rates ``omega``."""
    response = gyro.respond(make_truth(grid(duration, hz), omega), np.random.default_rng(seed))
    return response.angle[-1] / duration


# --------------------------------------------------------------------------------------------------
# Sagnac phase and the two readouts
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("params", [{}, {"coil_length_m": 1000.0, "coil_diameter_m": 0.12, "wavelength_nm": 1310.0}])
def test_sagnac_scale_factor_is_2pi_l_d_over_lambda_c(params):
    gyro = FiberOpticGyro(**params)
    length, diameter = gyro.coil_length_m, gyro.coil_diameter_m
    expected = 2 * math.pi * length * diameter / (gyro.wavelength_nm * 1e-9 * 299_792_458.0)
    assert gyro.scale_factor_s == pytest.approx(expected, rel=1e-15)
    omega = np.array([0.01, -0.3, 2.0])
    raw = gyro.respond(make_truth(grid(0.01, 1000), omega), np.random.default_rng(0)).raw
    np.testing.assert_allclose(raw["sagnac_phase_rad"], np.broadcast_to(expected * omega, (11, 3)), rtol=1e-15)
    assert SPEED_OF_LIGHT == 299_792_458.0
    if not params:  # the default coil: S = 0.176 s, proper frequency c/(2 n_g L) ≈ 511 kHz
        assert gyro.scale_factor_s == pytest.approx(0.1758, abs=1e-4)
        assert gyro.proper_frequency_hz == pytest.approx(SPEED_OF_LIGHT / (2 * 1.468 * 200.0), rel=1e-12)


def test_open_loop_follows_the_sine_of_the_sagnac_phase():
    gyro = FiberOpticGyro(loop="open")
    S, duration = gyro.scale_factor_s, 20.0
    phases = np.array([0.3, 0.8, 1.3])  # Sagnac phases, rad
    omega = phases / S
    read = mean_rate(gyro, omega, duration)
    # Linearised scale factor: sin(SΩ)/S, within the noise of a 20 s mean.
    noise = gyro.phase_noise(phases) / S / math.sqrt(duration)
    assert np.all(np.abs(read - np.sin(phases) / S) < SIGMAS * noise)
    # … which is far from Ω: 1.5 % low at 0.3 rad, 25 % at 1.3 rad (the textbook (SΩ)²/6 for small SΩ).
    assert np.all(np.abs(omega - np.sin(phases) / S) > 100 * SIGMAS * noise)
    np.testing.assert_allclose(read / omega, np.sin(phases) / phases, atol=1e-4)
    # The arcsin readout undoes the sine (noise amplified by 1/cos Δφ).
    corrected = mean_rate(FiberOpticGyro(loop="open", open_loop_readout="arcsin"), omega, duration)
    assert np.all(np.abs(corrected - omega) < SIGMAS * noise / np.cos(phases) + 1e-6 * omega)
    # Beyond π/2 the open loop folds over: a faster rate reads slower.
    folded = mean_rate(gyro, np.array([2.0, 2.5, 3.0]) / S, 1.0)
    assert np.all(np.diff(folded) < 0)


def test_closed_loop_is_linear_over_its_range_and_saturates_beyond():
    gyro = FiberOpticGyro()  # closed loop, range ±π
    S, duration = gyro.scale_factor_s, 20.0
    full_scale = gyro.feedback_range_rad / S  # 17.9 rad/s = 1024°/s
    sigma = gyro.intrinsic_noise_density() / math.sqrt(duration)
    for fraction in (np.array([1e-4, -0.01, 0.3]), np.array([-0.6, 0.9, 0.99])):
        omega = fraction * full_scale
        read = mean_rate(gyro, omega, duration)
        # No scale-factor error at any rate inside the range: Ω within the noise of the mean.
        assert np.all(np.abs(read - omega) < SIGMAS * sigma + 1e-12 * np.abs(omega))
    # The feedback step nulls the Sagnac phase: φ_f = −Δφ (noise apart); beyond the range it saturates.
    omega = np.array([0.5, 1.2, -1.5]) * full_scale
    response = gyro.respond(make_truth(grid(1.0, 1000), omega), np.random.default_rng(1))
    np.testing.assert_allclose(response.raw["feedback_phase_rad"][-1], [-0.5 * math.pi, -math.pi, math.pi], atol=1e-3)
    np.testing.assert_allclose(response.angle[-1], [0.5 * full_scale, full_scale, -full_scale], rtol=1e-3)
    # The light sees what the saturated ramp misses: the detector power drops from its null value.
    power = response.raw["detector_power_w"][-1]
    null = 0.5e-6 * gyro.detector_power_uw * (1 + jv(0, gyro.modulation_depth_rad))
    assert power[0] == pytest.approx(null) and power[1] < null and power[2] < null


def test_the_outputs_follow_a_varying_rate():
    # A rate swinging through ±50°/s: both loops read the mean of their law over each step.
    t = grid(2.0, 1000.0)
    amplitude, w = 50 * DEG, 2 * math.pi * 3.125  # 6¼ periods: ends at the largest angle
    omega = amplitude * np.sin(w * t)[:, None] * [1, -1, 0.5]
    alpha = amplitude * w * np.cos(w * t)[:, None] * [1, -1, 0.5]
    true_angle = amplitude / w * (1 - np.cos(w * t))[:, None] * [1, -1, 0.5]
    closed, opened = FiberOpticGyro(), FiberOpticGyro(loop="open")
    walk = SIGMAS * closed.intrinsic_noise_density() * math.sqrt(t[-1])  # the ARW over the run
    response = closed.respond(make_truth(t, omega, alpha), np.random.default_rng(2))
    assert np.all(np.abs(response.angle[-1] - true_angle[-1]) < walk + 1e-9)
    # The open loop integrates sin(SΩ)/S: 0.3 % short of the true angle at these rates (fine quadrature).
    S, fine = opened.scale_factor_s, np.linspace(0.0, t[-1], 200_001)
    law = np.sin(S * amplitude * np.sin(w * fine))[:, None] * [1, -1, 0] / S
    law[:, 2] = np.sin(S * 0.5 * amplitude * np.sin(w * fine)) / S
    expected = np.sum(0.5 * (law[1:] + law[:-1]) * np.diff(fine)[:, None], axis=0)
    response = opened.respond(make_truth(t, omega, alpha), np.random.default_rng(2))
    assert np.all(np.abs(response.angle[-1] - expected) < walk + 1e-9)
    assert np.all(np.abs(expected - true_angle[-1])[:2] > 5 * walk)  # the full-swing axes: visibly short


class ZeroDraws:
    """A Generator stand-in whose standard normal draws are all zero. The FOG's only random input is one
    standard normal per inner step and axis, scaled by σ(Δφ)/√h (module notes, "Random draws"), so this
    switches the shot noise and the excess RIN off and leaves the loop's deterministic response."""

    def standard_normal(self, size=None):
        return np.zeros(size)


def test_closed_loop_nulls_the_exact_mean_sagnac_phase_of_every_step():
    """Closed loop, noiseless: the ramp step of each inner step [t_k, t_k+1] is minus the step's mean
    Sagnac phase, φ_f,k = −(S/h) ∫ Ω dt, computed by the loop as the corrected trapezoid rule
    (h/2)(Ω_k + Ω_k+1) + (h²/12)(α_k − α_k+1): exact for cubics. For Ω = c + A sin(w t + p), exactly

        (1/h) ∫ Ω dt = c + A sin(w t_m + p) · sin(w h/2)/(w h/2),      t_m the step's midpoint,

    the indicated rate of the step is that mean, and the angle its running integral.

    Bounds: the rule's error is h⁵/720 Ω⁗(ξ) per step, so |Δ mean phase| ≤ S h⁴ A w⁴/720 = 3.1·10⁻⁹ rad
    (on axis 3, A = 2 rad/s; rounding, a few ε of S|Ω| ~ 10⁻¹⁶ rad, is far below), while the h² term is
    up to S h² A w²/12 = 7.4·10⁻⁵ rad: with (α_k − α_k+1) reversed the steps would be off by twice that,
    2·10⁴ times the bound. The rate is the phase over S; the angle accumulates the steps' errors (t h⁴
    A w⁴/720) and the running sum's rounding (M ε max|angle|).
    """
    gyro = FiberOpticGyro()  # closed loop, range ±π
    S, hz = gyro.scale_factor_s, 1000.0
    t = grid(0.4, hz)  # 3.2 periods of an 8 Hz swing
    h = t[1] - t[0]
    c, amp, p = np.array([0.3, -0.5, 0.1]), np.array([1.0, 1.5, 2.0]), np.array([0.0, 1.0, -2.0])
    w = 2 * math.pi * 8.0
    omega = c + amp * np.sin(w * t[:, None] + p)
    alpha = amp * w * np.cos(w * t[:, None] + p)
    theta = c * t[:, None] + amp / w * (np.cos(p) - np.cos(w * t[:, None] + p))  # ∫₀ᵗ Ω dt
    mid, dt = 0.5 * (t[1:] + t[:-1])[:, None], np.diff(t)[:, None]
    mean_rate = c + amp * np.sin(w * mid + p) * np.sin(0.5 * w * dt) / (0.5 * w * dt)

    response = gyro.respond(make_truth(t, omega, alpha), ZeroDraws())
    feedback = response.raw["feedback_phase_rad"]
    assert np.all(np.abs(S * omega) < 0.5 * gyro.feedback_range_rad)  # well inside the range: no clipping

    truncation = S * h**4 * amp * w**4 / 720  # (3,) rad
    rounding = 8 * np.finfo(float).eps * S * np.abs(omega).max(axis=0)
    h2_term = S * h**2 * amp * w**2 / 12
    assert np.all(h2_term > 1e4 * (truncation + rounding))  # the O(h²) term is resolved

    np.testing.assert_allclose(feedback[0], -S * omega[0], rtol=0, atol=4 * np.finfo(float).eps)  # power-up
    err = np.abs(feedback[1:] + S * mean_rate)
    assert np.all(err <= truncation + rounding), (err.max(axis=0), truncation + rounding)
    # The increments, as the IMU reports them: each is the step's rate × h, rounded with the running sum
    # (a few ε of the angle and of the increment).
    rate = np.diff(response.angle, axis=0) / h
    eps = np.finfo(float).eps
    increment_rounding = 4 * eps * (np.abs(theta).max(axis=0) / h + np.abs(omega).max(axis=0))
    err = np.abs(rate - mean_rate)
    assert np.all(err <= (truncation + rounding) / S + increment_rounding), (err.max(axis=0), truncation / S)
    angle_rounding = len(t) * eps * np.abs(theta).max(axis=0)  # the running sum: one rounding per step
    err = np.abs(response.angle - theta)
    assert np.all(err <= t[:, None] * truncation / S + angle_rounding), (err.max(axis=0), t[-1] * truncation / S)


# --------------------------------------------------------------------------------------------------
# Noise: the formula against photon counting, and the gyro's output against the formula
# --------------------------------------------------------------------------------------------------


def photon_counting(gyro, sagnac_phase, shot, rin, trials=4000, periods=20, per_period=64, seed=1):
    """Demodulated outputs (trials,), in units of sin Δφ, of a detector simulated sample by sample.

    The modulation runs at 1 Hz (the formula is scale-free), 64 samples per period. The source's power
    carries white RIN (single-sided density RIN: variance RIN/(2Δt) per sample); the detector counts
    Poisson photo-electrons of mean R P Δt/e. The lock-in sums i(t)·2cos ω_m t over whole periods.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / per_period
    t = (np.arange(periods * per_period) + 0.5) * dt
    cos_m = np.cos(2 * math.pi * t)
    p0, responsivity = gyro.detector_power_uw * 1e-6, gyro.responsivity_a_per_w
    power = 0.5 * p0 * (1 + np.cos(sagnac_phase + gyro.modulation_depth_rad * cos_m))
    current = np.broadcast_to(responsivity * power, (trials, t.size)).copy()
    if rin:
        current *= 1 + rng.standard_normal(current.shape) * math.sqrt(gyro.relative_intensity_noise_per_hz / (2 * dt))
    if shot:
        current = rng.poisson(current * dt / ELEMENTARY_CHARGE) * ELEMENTARY_CHARGE / dt
    first_harmonic = 2.0 / periods * np.sum(current * cos_m * dt, axis=1)  # −R P₀ J₁ sin Δφ
    return first_harmonic / (-responsivity * p0 * jv(1, gyro.modulation_depth_rad)), float(periods)


@pytest.mark.parametrize(
    "terms, params",
    [
        ("shot", {"detector_power_uw": 1e-3}),  # ~10⁴ photo-electrons per sample
        ("rin", {"spectral_width_nm": 1e-7}),  # RIN = 8·10⁻² /Hz
        ("total", {"detector_power_uw": 2e-4, "spectral_width_nm": 2e-3}),  # the two comparable
    ],
)
@pytest.mark.parametrize("sagnac_phase", [0.0, 0.7])
def test_demodulator_noise_formula_against_photon_counting(terms, params, sagnac_phase):
    gyro = FiberOpticGyro(**params)
    if terms == "total":
        shot, rin = gyro.phase_noise(sagnac_phase, "shot"), gyro.phase_noise(sagnac_phase, "rin")
        assert 0.3 < shot / rin < 3
    read, duration = photon_counting(gyro, sagnac_phase, shot=terms != "rin", rin=terms != "shot")
    sigma = gyro.phase_noise(sagnac_phase, terms) / math.sqrt(duration)
    assert abs(read.mean() - math.sin(sagnac_phase)) < SIGMAS * sigma / math.sqrt(read.size)
    assert abs(read.std() / sigma - 1) < SIGMAS / math.sqrt(2 * read.size)


def test_noise_formula_written_out_at_rest_and_its_dependence_on_the_bias():
    # At Δφ = 0, written out independently: shot √(e(1 + J₀ − J₂)/(R P₀))/J₁, RIN
    # √(RIN((1 + J₀ − J₂)² + Σ_{m≥1}(J_2m − J_2m+2)²))/(2J₁).
    gyro = FiberOpticGyro()
    j = jv(np.arange(60), gyro.modulation_depth_rad)
    p = gyro.detector_power_uw * 1e-6 * gyro.responsivity_a_per_w
    shot = math.sqrt(ELEMENTARY_CHARGE * (1 + j[0] - j[2]) / p) / j[1]
    harmonics = (1 + j[0] - j[2]) ** 2 + sum((j[2 * m] - j[2 * m + 2]) ** 2 for m in range(1, 25))
    rin = math.sqrt(gyro.relative_intensity_noise_per_hz * harmonics) / (2 * j[1])
    assert gyro.phase_noise(0.0, "shot") == pytest.approx(shot, rel=1e-12)
    assert gyro.phase_noise(0.0, "rin") == pytest.approx(rin, rel=1e-12)
    assert gyro.phase_noise(0.0) == pytest.approx(math.hypot(shot, rin), rel=1e-12)
    # Over-modulating (φ_b from 1.8 towards 2.6 rad) lowers both: less power is left on the detector,
    # and the shot and excess-RIN noises scale as √P and P against a signal ∝ P J₁ (Lefèvre's advice
    # for RIN-limited gyros).
    depths = (1.8, 2.2, 2.6)
    shots = [FiberOpticGyro(modulation_depth_rad=d).phase_noise(0.0, "shot") for d in depths]
    rins = [FiberOpticGyro(modulation_depth_rad=d).phase_noise(0.0, "rin") for d in depths]
    assert shots[0] > shots[1] > shots[2]
    assert rins[0] > rins[1] > rins[2]


@pytest.mark.parametrize("loop", ["closed", "open"])
def test_noise_only_run_has_the_shot_plus_rin_angle_random_walk(loop):
    gyro = FiberOpticGyro(loop=loop)
    hz, duration = 1000.0, 200.0
    response = gyro.respond(make_truth(grid(duration, hz), [0.0, 0.0, 0.0]), np.random.default_rng(7))
    rate = np.diff(response.angle, axis=0) * hz
    n = gyro.intrinsic_noise_density()
    # White rate noise of density N: per-sample σ = N/√Δt …
    assert np.all(np.abs(rate.std(axis=0) / (n * math.sqrt(hz)) - 1) < SIGMAS / math.sqrt(2 * len(rate)))
    # … and an Allan deviation N/√τ, N read at τ = 1 s.
    for axis in range(3):
        allan = allan_deviation(rate[:, axis], 1 / hz, taus=np.array([0.01, 0.1, 1.0]))
        assert np.all(np.abs(allan.adev * np.sqrt(allan.tau) / n - 1) < SIGMAS / np.sqrt(2 * allan.edf))
    # The defaults: a DSP-1760-class ARW (≤ 0.012°/√h), RIN limited.
    arw = n / DEG * 60
    assert 0.008 < arw < 0.012
    assert gyro.phase_noise(0.0, "rin") > 2 * gyro.phase_noise(0.0, "shot")


def test_noise_scales_with_power_and_source_width():
    base = FiberOpticGyro()
    # Shot noise ∝ 1/√P₀, RIN noise ∝ 1/√Δλ, both divided by S ∝ L D.
    assert FiberOpticGyro(detector_power_uw=80.0).phase_noise(0.0, "shot") == pytest.approx(
        base.phase_noise(0.0, "shot") / 2, rel=1e-12
    )
    assert FiberOpticGyro(spectral_width_nm=120.0).phase_noise(0.0, "rin") == pytest.approx(
        base.phase_noise(0.0, "rin") / 2, rel=1e-12
    )
    assert FiberOpticGyro(coil_length_m=400.0).intrinsic_noise_density() == pytest.approx(
        base.intrinsic_noise_density() / 2, rel=1e-12
    )


# --------------------------------------------------------------------------------------------------
# The mechanism contract
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("loop", ["closed", "open"])
def test_chunks_continue_one_run_and_seeds_reproduce(loop):
    gyro = FiberOpticGyro(loop=loop)
    t = grid(2.0, 500.0)
    omega = 0.4 * np.sin(3 * t)[:, None] * [1, 2, -3]
    alpha = 1.2 * np.cos(3 * t)[:, None] * [1, 2, -3]
    whole = gyro.respond(make_truth(t, omega, alpha), np.random.default_rng(3), {})
    rng, state, parts = np.random.default_rng(3), {}, []
    for first, last in ((0, 377), (377, 800), (800, len(t) - 1)):  # chunks share their end sample
        cut = slice(first, last + 1)
        parts.append(gyro.respond(make_truth(t[cut], omega[cut], alpha[cut]), rng, state))
    # Each chunk's angle restarts from 0 at its first sample: stitch them back together.
    stitched = [parts[0].angle]
    for part in parts[1:]:
        stitched.append(stitched[-1][-1] + part.angle[1:])
    np.testing.assert_allclose(np.vstack(stitched), whole.angle, rtol=0, atol=1e-13)
    for name in whole.raw:
        pieces = np.vstack([parts[0].raw[name]] + [part.raw[name][1:] for part in parts[1:]])
        np.testing.assert_allclose(pieces, whole.raw[name], rtol=1e-14, atol=0)  # SIMD round-off
        # the shared sample repeats the previous chunk's last value
        np.testing.assert_array_equal(parts[1].raw[name][0], parts[0].raw[name][-1])
    again = gyro.respond(make_truth(t, omega, alpha), np.random.default_rng(3), {})
    np.testing.assert_array_equal(again.angle, whole.angle)
    other = gyro.respond(make_truth(t, omega, alpha), np.random.default_rng(4), {})
    assert not np.array_equal(other.angle, whole.angle)


def test_inside_an_imu_the_mechanism_makes_part_of_the_specified_arw():
    t = np.arange(0, 10.0 + 1e-9, 1e-2)
    w = np.broadcast_to([0.1, -0.05, 0.3], (len(t), 3))
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    zero = np.zeros((len(t), 3))
    traj = trajectory_from_world_motion(t, q, w, zero, zero, zero, zero, Environment.inertial(9.81))
    device = device_from_dict(
        {
            "description": "fog",
            "rate_hz": 200.0,
            "gyro": {"mechanism": {"kind": "fog"}, "errors": {"arw_deg_per_sqrt_h": 0.012}},
        }
    )
    spec = 0.012 * DEG / 60
    assert device.gyro_noise_density == pytest.approx(np.full(3, spec), rel=1e-12)
    samples = device.measure(traj)
    error = samples.gyro - w[0]
    assert np.all(np.abs(error.std(axis=0) / (spec * math.sqrt(200.0)) - 1) < SIGMAS / math.sqrt(2 * len(error)))
    assert samples.raw["fog"]["sagnac_phase_rad"].shape == (len(samples), 3)
    # A mechanism noisier than its specification is refused.
    with pytest.raises(ConfigError, match="exceeds? the specified"):
        device_from_dict(
            {
                "description": "fog",
                "rate_hz": 200.0,
                "gyro": {"mechanism": {"kind": "fog"}, "errors": {"arw_deg_per_sqrt_h": 0.005}},
            }
        )


@pytest.mark.parametrize(
    "key, value",
    [
        ("coil_length_m", -200.0),
        ("coil_diameter_m", 0.0),
        ("wavelength_nm", -1550.0),
        ("spectral_width_nm", 2000.0),
        ("detector_power_uw", -20.0),
        ("detector_power_uw", 0.0),
        ("responsivity_a_per_w", 1.5),
        ("modulation_depth_rad", 3.9),
        ("feedback_range_rad", 4.0),
        ("loop", "half-open"),
    ],
)
def test_bad_parameters_name_their_key(key, value):
    with pytest.raises(ConfigError) as err:
        validate(FiberOpticGyro, {"kind": "fog", key: value}, prefix="gyro.mechanism")
    assert err.value.key == f"gyro.mechanism.{key}"
    # The same through a device file.
    with pytest.raises(ConfigError) as err:
        device_from_dict({"description": "x", "rate_hz": 100.0, "gyro": {"mechanism": {"kind": "fog", key: value}}})
    assert err.value.key == f"gyro.mechanism.{key}"


def test_defaults_are_checked_against_the_given_wavelength():
    """The default responsivity (0.9 A/W) is validated against a given wavelength too: at 1000 nm 0.9 A/W
    exceeds e λ/(h c) = 0.807 A/W. The width is checked against the wavelength (at 100 nm, the shortest
    taken, a width of 150 nm is not narrower; the default 30 nm always is). A responsivity below
    e λ/(h c) = 0.081 A/W isolates that check."""
    with pytest.raises(ConfigError) as err:
        validate(
            FiberOpticGyro,
            {"kind": "fog", "wavelength_nm": 100.0, "spectral_width_nm": 150.0, "responsivity_a_per_w": 0.05},
            prefix="m",
        )
    assert err.value.key == "m.spectral_width_nm"
    with pytest.raises(ConfigError) as err:
        validate(FiberOpticGyro, {"kind": "fog", "wavelength_nm": 1000.0}, prefix="m")
    assert err.value.key == "m.responsivity_a_per_w"
    assert FiberOpticGyro(wavelength_nm=1200.0).spectral_width_nm == 30.0


def test_max_rate_is_the_feedback_range_closed_loop_and_the_sine_extremum_open_loop():
    closed, opened = FiberOpticGyro(feedback_range_rad=2.5), FiberOpticGyro(loop="open", feedback_range_rad=2.5)
    eps = np.finfo(float).eps
    assert closed.max_rate() == pytest.approx(2.5 / closed.scale_factor_s, rel=4 * eps)
    assert opened.max_rate() == pytest.approx(0.5 * np.pi / opened.scale_factor_s, rel=4 * eps)


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("wavelength_nm", 1e300, "more than the limit of 10000: "),  # OverflowError in the RIN λ²/(c Δλ)
        ("wavelength_nm", 1e-300, "less than the limit of 100: "),  # blamed spectral_width_nm
        ("coil_length_m", 1e300, "more than the limit of 100000: "),  # blamed gyro.errors.range_deg_per_s
        ("coil_length_m", 1e-300, "less than the limit of 1: "),  # OverflowError: the noise σ/S squared
        ("coil_diameter_m", 1e300, "more than the limit of 10: "),
        ("coil_diameter_m", 1e-300, "less than the limit of 0.001: "),  # OverflowError, as the length
        ("modulation_depth_rad", 1e-300, "less than the limit of 0.1: "),  # OverflowError: σ/J₁ with J₁ → 0
    ],
)
def test_absurd_coils_sources_and_biases_are_refused_naming_the_key(key, value, words):
    with pytest.raises(ConfigError, match=re.escape(words)) as err:
        device_from_dict(
            {"description": "x", "rate_hz": 1000, "gyro": {"mechanism": {"kind": "fog", key: value}}}, name="dev.toml"
        )
    assert err.value.key == f"gyro.mechanism.{key}" and err.value.file == "dev.toml"
    assert "FOGs" in err.value.reason or "fibre" in err.value.reason  # why: what real FOGs are


def test_a_fog_at_the_limits_of_its_keys_is_finite():
    """The shortest, thinnest coil at the longest wavelength and the lightest bias: a noisy gyro, but numbers."""
    fog = FiberOpticGyro(coil_length_m=1.0, coil_diameter_m=0.001, wavelength_nm=10_000.0, modulation_depth_rad=0.1)
    assert math.isfinite(fog.intrinsic_noise_density()) and math.isfinite(fog.max_rate())
    t = np.arange(101) * 1e-3
    omega = np.tile([0.1, 0.0, -0.2], (len(t), 1))
    response = fog.respond(GyroTruth(t=t, dt=1e-3, omega=omega, alpha=np.zeros_like(omega)), np.random.default_rng(0))
    assert response.angle is not None and np.isfinite(response.angle).all()
