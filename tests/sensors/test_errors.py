"""The error-term layer: deterministic terms against closed forms, the filter, randomness, config errors."""

import numpy as np
import pytest
import scipy.signal
from scipy.stats import chi2

from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors import noise
from gyroemu.sensors.allan import allan_deviation
from gyroemu.sensors.errors import STANDARD_GRAVITY, AccelErrors, ErrorModel, GyroErrors, apply_errors

DEG_PER_H = np.pi / 180 / 3600  # rad/s
UG = 1e-6 * STANDARD_GRAVITY  # m/s²
SIGMAS = 4


@pytest.fixture
def motion():
    """A minute of tumbling at 100 Hz: t (N,), ω (N, 3) rad/s, f (N, 3) m/s², T (N,) °C."""
    rng = np.random.default_rng(42)
    t = np.arange(6000) * 0.01
    omega = np.column_stack([np.sin(t), 0.5 * np.cos(2 * t), 0.2 + 0 * t]) + 0.1 * rng.standard_normal((t.size, 3))
    force = np.array([0.3, -0.2, 9.81]) + rng.standard_normal((t.size, 3))
    temperature = 25 + 10 * np.sin(t / 10)
    return t, omega, force, temperature


def measure(spec, motion, seed=0, **kwargs):
    t, omega, _, _ = motion
    return apply_errors(omega, t, spec, np.random.default_rng(seed), **kwargs)


def close(actual, expected):
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------------------------------
# Deterministic terms, one at a time, exact
# --------------------------------------------------------------------------------------------------


def test_no_errors_is_the_identity(motion):
    close(measure(GyroErrors(), motion), motion[1])


def test_bias(motion):
    close(measure(GyroErrors(bias_deg_per_h=[1.0, -2.0, 3.0]), motion), motion[1] + np.array([1, -2, 3]) * DEG_PER_H)


def test_scale_factor(motion):
    close(
        measure(GyroErrors(scale_factor_ppm=[100, -200, 300]), motion),
        motion[1] * (1 + np.array([100, -200, 300]) * 1e-6),
    )


def test_misalignment_angles_and_cross_axis_matrix(motion):
    xy, xz, yx, yz, zx, zy = 0.1, -0.2, 0.3, -0.4, 0.5, -0.6  # mrad
    m = np.array([[0, xy, xz], [yx, 0, yz], [zx, zy, 0]]) * 1e-3
    expected = motion[1] @ (np.eye(3) + m).T
    close(measure(GyroErrors(misalignment_mrad=[xy, xz, yx, yz, zx, zy]), motion), expected)
    close(measure(GyroErrors(cross_axis_matrix=m.tolist()), motion), expected)


def test_quadratic_nonlinearity_in_ppm_of_full_scale(motion):
    full_scale = 300 * np.pi / 180
    spec = GyroErrors(range_deg_per_s=300, scale_factor_nonlinearity_ppm=[50, 100, 150])
    k = np.array([50, 100, 150]) * 1e-6 / full_scale  # deviation at full scale: ppm of full scale
    close(measure(spec, motion), motion[1] + k * motion[1] ** 2)
    assert k[0] * full_scale**2 == pytest.approx(50e-6 * full_scale)


def test_saturation_clips_at_the_range(motion):
    t, omega, _, _ = motion
    y = apply_errors(10 * omega, t, GyroErrors(range_deg_per_s=30), np.random.default_rng(0))
    limit = 30 * np.pi / 180
    close(y, np.clip(10 * omega, -limit, limit))
    assert np.any(np.abs(10 * omega) > limit)


@pytest.mark.parametrize(
    ("model", "bias_key", "unit", "signal"),
    [
        (GyroErrors, "bias_temperature_deg_per_h_per_degC", DEG_PER_H, 1),  # input ω, rad/s
        (AccelErrors, "bias_temperature_ug_per_degC", 1e-6 * STANDARD_GRAVITY, 2),  # input f, m/s²
    ],
)
def test_temperature_sensitivity_of_bias_and_scale_factor(motion, model, bias_key, unit, signal):
    """Bias per °C in the sensor's datasheet unit and scale factor in ppm/°C, on either sensor."""
    t, _, _, temperature = motion
    x = motion[signal]
    spec = model(
        **{bias_key: [0.5, -1.0, 2.0]},
        scale_factor_temperature_ppm_per_degC=[10, 20, -30],
        reference_temperature_degC=20,
    )
    dT = (temperature - 20)[:, None]
    expected = x + np.array([0.5, -1.0, 2.0]) * unit * dT + np.array([10, 20, -30]) * 1e-6 * dT * x
    close(apply_errors(x, t, spec, np.random.default_rng(0), temperature_degC=temperature), expected)
    # Without a temperature input the sensor sits at the reference temperature.
    close(apply_errors(x, t, spec, np.random.default_rng(0)), x)


def test_g_sensitivity(motion):
    _, omega, force, _ = motion
    g = [[1.0, 2.0, 0.0], [0.0, -1.0, 0.5], [0.3, 0.0, 4.0]]  # deg/h per g
    expected = omega + force @ (np.array(g) * DEG_PER_H / STANDARD_GRAVITY).T
    close(measure(GyroErrors(g_sensitivity_deg_per_h_per_g=g), motion, specific_force=force), expected)
    with pytest.raises(ValueError, match="specific force"):
        measure(GyroErrors(g_sensitivity_deg_per_h_per_g=g), motion)


def test_rate_ramp(motion):
    t, omega, _, _ = motion
    close(
        measure(GyroErrors(rate_ramp_deg_per_h_per_h=[1.0, 0.0, -1.0]), motion),
        omega + t[:, None] * np.array([1.0, 0.0, -1.0]) * DEG_PER_H / 3600,
    )


def test_accelerometer_terms_in_their_own_units(motion):
    t, _, force, temperature = motion
    spec = AccelErrors(bias_ug=[100, 200, -300], scale_factor_ppm=500, bias_temperature_ug_per_degC=2, range_g=2)
    y = apply_errors(force, t, spec, np.random.default_rng(0), temperature_degC=temperature)
    expected = force * (1 + 500e-6) + np.array([100, 200, -300]) * UG + 2 * UG * (temperature - 25)[:, None]
    close(y, np.clip(expected, -2 * STANDARD_GRAVITY, 2 * STANDARD_GRAVITY))


def test_noise_density_keys_agree():
    # 0.1 deg/√h and 0.1/60 deg/s/√Hz are the same density; so are 100 µg/√Hz and its VRW.
    gyro = [GyroErrors(arw_deg_per_sqrt_h=0.1), GyroErrors(noise_density_deg_per_s_per_sqrt_hz=0.1 / 60)]
    np.testing.assert_allclose(gyro[0].to_si().noise_density, gyro[1].to_si().noise_density, rtol=1e-15)
    accel = [AccelErrors(noise_density_ug_per_sqrt_hz=100), AccelErrors(vrw_m_per_s_per_sqrt_h=100 * UG * 60)]
    np.testing.assert_allclose(accel[0].to_si().noise_density, accel[1].to_si().noise_density, rtol=1e-15)


def test_rate_quantisation_outputs_whole_lsbs(motion):
    y = measure(GyroErrors(quantisation_rad_per_s=1e-3), motion)
    np.testing.assert_allclose(y / 1e-3, np.round(y / 1e-3), atol=1e-9)
    assert np.max(np.abs(y - motion[1])) <= 0.5e-3 * (1 + 1e-9)


def test_angle_quantisation_loses_no_angle(motion):
    t, omega, _, _ = motion
    y = measure(GyroErrors(quantisation_rad=1e-4), motion)
    np.testing.assert_allclose(y * 0.01 / 1e-4, np.round(y * 0.01 / 1e-4), atol=1e-6)
    assert np.max(np.abs(np.cumsum(y - omega, axis=0) * 0.01)) < 1e-4


# --------------------------------------------------------------------------------------------------
# Bandwidth
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", [1, 2])
def test_bandwidth_is_minus_3db_at_bandwidth_hz(order):
    dt, f_c = 0.001, 50.0
    t = np.arange(20_000) * dt
    omega = np.column_stack([np.sin(2 * np.pi * f_c * t), np.cos(2 * np.pi * f_c * t), np.ones_like(t)])
    y = apply_errors(omega, t, GyroErrors(bandwidth_hz=f_c, filter_order=order), np.random.default_rng(0))

    settled = t > 1.0  # 50 time constants
    basis = np.column_stack([np.sin(2 * np.pi * f_c * t), np.cos(2 * np.pi * f_c * t)])[settled]
    for axis in (0, 1):
        amplitude = np.hypot(*np.linalg.lstsq(basis, y[settled, axis], rcond=None)[0])
        assert amplitude == pytest.approx(1 / np.sqrt(2), abs=1e-6)
    close(y[:, 2], np.ones_like(t))  # unit DC gain, started in steady state: no transient

    b, a = scipy.signal.butter(order, f_c, fs=1 / dt)
    assert abs(scipy.signal.freqz(b, a, worN=[f_c], fs=1 / dt)[1][0]) == pytest.approx(1 / np.sqrt(2), abs=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_bandwidth_filter_is_scipys_lfilter_from_steady_state(motion, order):
    t, omega, _, _ = motion
    y = measure(GyroErrors(bandwidth_hz=5.0, filter_order=order), motion)
    b, a = scipy.signal.butter(order, 5.0, fs=100.0)
    expected = scipy.signal.lfilter(b, a, omega, axis=0, zi=scipy.signal.lfilter_zi(b, a)[:, None] * omega[0])[0]
    close(y, expected)


def test_bandwidth_must_be_below_nyquist(motion):
    with pytest.raises(ConfigError, match="Nyquist") as error:
        measure(GyroErrors(bandwidth_hz=60), motion)
    assert error.value.key == "bandwidth_hz"
    assert "Nyquist frequency 50 Hz of the 100 Hz sample rate" in str(error.value)


def test_bandwidth_must_not_be_narrower_than_float64_holds(motion):
    """At 1e-300 Hz the low-pass's matrices were singular (a LinAlgError); 10⁻⁴ of the rate is the limit."""
    for bandwidth in (1e-300, 0.0099):
        with pytest.raises(ConfigError, match="less than the limit of 0.0001 of the 100 Hz sample rate") as error:
            measure(GyroErrors(bandwidth_hz=bandwidth), motion)
        assert error.value.key == "bandwidth_hz"
    assert np.isfinite(measure(GyroErrors(bandwidth_hz=0.01), motion)).all()


@pytest.mark.parametrize(
    "model, key, limit", [(GyroErrors, "quantisation_rad", 0.1), (AccelErrors, "quantisation_m_per_s", 1.0)]
)
def test_an_integrating_outputs_count_is_bounded(model, key, limit):
    """A count of 1e300 was taken and every sample read 0: bounded like the rate LSB, the limit itself taken."""
    with pytest.raises(ConfigError, match=f"more than the limit of {limit:g}: over") as error:
        validate(model, {key: 1e300}, prefix="errors")
    assert error.value.key == f"errors.{key}"
    validate(model, {key: limit})


# --------------------------------------------------------------------------------------------------
# Randomness
# --------------------------------------------------------------------------------------------------


ALL_TERMS = dict(
    bias_deg_per_h=1.0,
    turn_on_bias_deg_per_h=10.0,
    bias_temperature_deg_per_h_per_degC=0.1,
    scale_factor_ppm=100,
    scale_factor_temperature_ppm_per_degC=5,
    range_deg_per_s=400,
    scale_factor_nonlinearity_ppm=50,
    misalignment_mrad=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
    g_sensitivity_deg_per_h_per_g=[[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    arw_deg_per_sqrt_h=0.5,
    bias_instability_deg_per_h=2.0,
    rrw_deg_per_h_per_sqrt_h=0.5,
    rate_ramp_deg_per_h_per_h=0.1,
    quantisation_rad=1e-7,
    bandwidth_hz=40,
)


def test_same_seed_gives_the_same_bits(motion):
    _, _, force, temperature = motion
    spec = GyroErrors(**ALL_TERMS)
    run = lambda seed: measure(spec, motion, seed, temperature_degC=temperature, specific_force=force)  # noqa: E731
    np.testing.assert_array_equal(run(1), run(1))
    assert not np.array_equal(run(1), run(2))


def test_other_seeds_give_independent_noise():
    # White noise dominates every sample (300 deg/h per sample against 2 deg/h of flicker), so the
    # samples of two seeds are n independent pairs: their correlation is within 4/√n of zero.
    # (Random walks alone would not do: two independent walks are often strongly correlated.)
    t = np.arange(100_000) * 0.01
    spec = GyroErrors(
        arw_deg_per_sqrt_h=0.5,
        bias_instability_deg_per_h=2.0,
        rrw_deg_per_h_per_sqrt_h=0.5,
        turn_on_bias_deg_per_h=10.0,
    )
    a = apply_errors(np.zeros((t.size, 3)), t, spec, np.random.default_rng(1))
    b = apply_errors(np.zeros((t.size, 3)), t, spec, np.random.default_rng(2))
    for axis in range(3):
        assert abs(np.corrcoef(a[:, axis], b[:, axis])[0, 1]) < 4 / np.sqrt(t.size)


def test_turn_on_bias_differs_per_power_up_with_the_configured_sigma():
    sigma = np.array([5.0, 10.0, 20.0])  # deg/h
    spec = GyroErrors(turn_on_bias_deg_per_h=sigma.tolist())
    t, zero = np.array([0.0, 0.01]), np.zeros((2, 3))
    powerups = 4000
    biases = np.array([apply_errors(zero, t, spec, np.random.default_rng(seed))[0] for seed in range(powerups)])

    assert len(np.unique(biases[:, 0])) == powerups  # a new bias at every power-up
    sigma_si = sigma * DEG_PER_H
    np.testing.assert_array_less(np.abs(biases.std(axis=0) / sigma_si - 1), SIGMAS / np.sqrt(2 * powerups))
    np.testing.assert_array_less(np.abs(biases.mean(axis=0)) / sigma_si, SIGMAS / np.sqrt(powerups))
    # Within one power-up the turn-on bias is constant.
    one = apply_errors(np.zeros((100, 3)), np.arange(100) * 0.01, spec, np.random.default_rng(0))
    assert np.all(one == one[0])


def test_turn_on_scale_factor_differs_per_power_up_with_the_configured_sigma():
    """The scale factor drawn per power-up (repeatability): on a constant rate ω the output is
    (1 + s + s_on) ω with s_on ~ N(0, σ²) per axis, constant within a power-up; over 4000 power-ups its
    standard deviation and mean lie within SIGMAS standard errors of σ and 0 (√(2n) and √n); with the
    turn-on bias on as well, the bias is drawn first (the same bias as without the scale term) and the
    draws that follow are the scale's."""
    sigma = np.array([500.0, 1000.0, 2000.0])  # ppm
    omega = np.array([1.0, -2.0, 0.5])  # rad/s
    spec = GyroErrors(scale_factor_ppm=[100.0, 0.0, -50.0], turn_on_scale_factor_ppm=sigma.tolist())
    t, rate = np.array([0.0, 0.01]), np.tile(omega, (2, 1))
    powerups = 4000
    out = np.array([apply_errors(rate, t, spec, np.random.default_rng(seed)) for seed in range(powerups)])
    assert np.all(out[:, 0] == out[:, 1])  # constant within a power-up
    s_on = out[:, 0] / omega - 1 - np.array([100.0, 0.0, -50.0]) * 1e-6
    np.testing.assert_array_less(np.abs(s_on.std(axis=0) / (sigma * 1e-6) - 1), SIGMAS / np.sqrt(2 * powerups))
    np.testing.assert_array_less(np.abs(s_on.mean(axis=0)) / (sigma * 1e-6), SIGMAS / np.sqrt(powerups))
    both = GyroErrors(turn_on_bias_deg_per_h=10.0, turn_on_scale_factor_ppm=sigma.tolist())
    bias_only = GyroErrors(turn_on_bias_deg_per_h=10.0)
    zero = np.zeros((2, 3))
    np.testing.assert_array_equal(
        apply_errors(zero, t, both, np.random.default_rng(3)),
        apply_errors(zero, t, bias_only, np.random.default_rng(3)),
    )
    rng = np.random.default_rng(3)
    b_on = 10.0 * DEG_PER_H * rng.standard_normal(3)  # first the bias, then the scale factor
    s_on = sigma * 1e-6 * rng.standard_normal(3)
    got = apply_errors(rate, t, both, np.random.default_rng(3))[0]
    np.testing.assert_allclose(got, (1 + s_on) * omega + b_on, rtol=0, atol=8 * np.finfo(float).eps * 2.0)


def test_error_model_is_accepted_directly(motion):
    model = GyroErrors(bias_deg_per_h=3.0).to_si()
    assert isinstance(model, ErrorModel)
    close(measure(model, motion), motion[1] + 3.0 * DEG_PER_H)


def test_sample_times_must_be_uniform(motion):
    t, omega, _, _ = motion
    t = t.copy()
    t[10] += 0.001
    with pytest.raises(ValueError, match="uniform"):
        apply_errors(omega, t, GyroErrors(), np.random.default_rng(0))


def test_bias_instability_has_the_flat_allan_floor_0664_b_and_is_absent_at_b_zero():
    """Bias instability B alone (flicker noise from the Gauss–Markov bank of ``noise.flicker_bank``): the
    output's Allan deviation is flat at σ(τ) = B √(2 ln2/π) = 0.664 B over ``bias_instability_tau_range_s``
    (IEEE 952 Annex C), per axis; an axis with B = 0 gets none, and a sensor with B = 0 on every axis
    passes the truth through untouched and draws nothing from the Generator.

    Bound at each τ = m Δt, from the sample count n. The overlapping Allan variance estimate is taken as
    σ²(τ) χ²_ν/ν with ν = ⌊n/m⌋ − 3: NIST SP 1065 (Table 5) gives edf ≥ n/m − 3 for every noise type
    from white to random-walk FM (flicker FM: ≈ 1.25 n/m), so fewer degrees of freedom than the truth,
    a wider interval. The false-alarm probability 10⁻⁶ is split over the 8 τ × 2 axes tested, each
    two-sided (Bonferroni, valid for correlated estimates). Around the statistical interval, the model's
    own documented tolerances (``sensors/noise.py``): the bank's closed-form floor is flat within ±0.5 %
    (checked here on the closed form itself: τ_min = 10 Δt, above Δt), and simulating slow components
    on a coarser grid keeps the simulated floor within 1 %. At n = 2²¹ the statistical part is ±0.8 %
    at τ = 0.1 s (ν ≈ 2·10⁵) and −8 / +8.5 % at 10 s (ν ≈ 2100).
    """
    dt, n, tau_range = 0.01, 2**21, (0.1, 10.0)
    b = np.array([5.0, 0.0, 10.0])  # deg/h; the middle axis has none
    t = np.arange(n) * dt
    spec = GyroErrors(bias_instability_deg_per_h=b.tolist(), bias_instability_tau_range_s=tau_range)
    y = apply_errors(np.zeros((n, 3)), t, spec, np.random.default_rng(2024))
    np.testing.assert_array_equal(y[:, 1], 0.0)  # B = 0 on that axis: no flicker at all

    floor = noise.FLICKER_FLOOR * b * DEG_PER_H  # 0.664 B, rad/s
    design, interpolation = 0.005, 0.01  # documented in sensors/noise.py
    bank = noise.flicker_bank(b * DEG_PER_H, tau_range, dt, n_axes=3)
    dense = np.geomspace(*tau_range, 300)
    flatness = np.sqrt(bank.avar(dense, dt)[:, [0, 2]]) / floor[[0, 2]] - 1
    assert np.abs(flatness).max() <= design, np.abs(flatness).max()

    taus = np.append(tau_range[0] * 2.0 ** np.arange(7), tau_range[1])  # 0.1 … 6.4 s in octaves, and 10 s
    alpha = 1e-6 / (taus.size * 2)  # per test, two-sided
    for axis in (0, 2):
        allan = allan_deviation(y[:, axis], dt, taus=taus)
        np.testing.assert_allclose(allan.tau, taus, rtol=1e-12)
        nu = allan.clusters - 3
        low = np.sqrt(chi2.ppf(alpha / 2, nu) / nu) * (1 - design) * (1 - interpolation)
        high = np.sqrt(chi2.isf(alpha / 2, nu) / nu) * (1 + design) * (1 + interpolation)
        ratio = allan.adev / floor[axis]
        assert np.all((ratio >= low) & (ratio <= high)), (axis, ratio, low, high)

    # B = 0 everywhere: the branch is off; the truth passes unchanged and the Generator is not touched.
    truth = np.broadcast_to([0.1, -0.2, 0.3], (1000, 3))
    rng = np.random.default_rng(5)
    before = rng.bit_generator.state
    off = GyroErrors(bias_instability_deg_per_h=0.0, bias_instability_tau_range_s=tau_range)
    np.testing.assert_array_equal(apply_errors(truth, t[:1000], off, rng), truth)
    assert rng.bit_generator.state == before


# --------------------------------------------------------------------------------------------------
# Config errors name the key
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "model, data, key, words",
    [
        (GyroErrors, {"arw_deg_per_sqrt_h": -0.1}, "gyro.arw_deg_per_sqrt_h", ">= 0"),
        (GyroErrors, {"bias_instability_deg_per_h": [1, -1, 1]}, "gyro.bias_instability_deg_per_h[1]", "0"),
        (GyroErrors, {"arw_deg_per_h": 0.1}, "gyro.arw_deg_per_h", "did you mean 'arw_deg_per_sqrt_h'"),
        (GyroErrors, {"typo_key": 1}, "gyro.typo_key", "unknown key"),
        (GyroErrors, {"bias_instability_deg_per_h": "3 deg/h"}, "gyro.bias_instability_deg_per_h", "number"),
        (GyroErrors, {"scale_factor_ppm": [1, 2]}, "gyro.scale_factor_ppm", "3"),
        (
            GyroErrors,
            {"arw_deg_per_sqrt_h": 0.1, "noise_density_deg_per_s_per_sqrt_hz": 0.01},
            "gyro.noise_density_deg_per_s_per_sqrt_hz",
            "not both",
        ),
        (GyroErrors, {"scale_factor_nonlinearity_ppm": 100}, "gyro.scale_factor_nonlinearity_ppm", "range_deg_per_s"),
        (GyroErrors, {"cross_axis_matrix": [[1, 0, 0], [0, 0, 0], [0, 0, 0]]}, "gyro.cross_axis_matrix", "diagonal"),
        (GyroErrors, {"cross_axis_matrix": [[0, 0, 0], [0, 0, 0], [0, 0, 1e-3]]}, "gyro.cross_axis_matrix", "diagonal"),
        (GyroErrors, {"bias_instability_tau_range_s": [100, 10]}, "gyro.bias_instability_tau_range_s", "min < max"),
        (GyroErrors, {"range_deg_per_s": 0}, "gyro.range_deg_per_s", "greater than 0"),
        (AccelErrors, {"bias_instability_deg_per_h": 1}, "gyro.bias_instability_deg_per_h", "bias_instability_ug"),
        (AccelErrors, {"vrw_m_per_s_per_sqrt_h": -1}, "gyro.vrw_m_per_s_per_sqrt_h", ">= 0"),
        (
            AccelErrors,
            {"g_sensitivity_deg_per_h_per_g": [[0] * 3] * 3},
            "gyro.g_sensitivity_deg_per_h_per_g",
            "unknown key",
        ),
    ],
)
def test_config_errors_name_the_key(model, data, key, words):
    with pytest.raises(ConfigError) as error:
        validate(model, data, file="device.toml", prefix="gyro")
    assert error.value.key == key
    assert error.value.file == "device.toml"
    assert words in str(error.value)


def test_gauss_markov_keys_in_datasheet_units_give_the_closed_form_allan_deviation():
    """``markov_sigma_ug`` / ``markov_sigma_deg_per_h`` with ``markov_tau_s`` (both or neither): σ in the
    key's unit, τ_c in s. The output of a sensor at rest with this term alone has the Allan deviation of
    the sampled Gauss–Markov process (``noise.gauss_markov_avar``) at every octave τ, within SIGMAS
    relative standard deviations 1/√(2(n/m − 1)) (IEEE 952 Annex C), per axis; an axis with σ = 0 gets
    none, and the gyro's key converts as deg/h."""
    dt, n = 0.005, 2**19
    sigma_ug, tau_c = np.array([300.0, 0.0, 150.0]), np.array([0.8, 0.0, 2.0])
    spec = AccelErrors(markov_sigma_ug=sigma_ug.tolist(), markov_tau_s=tau_c.tolist())
    model = spec.to_si()
    np.testing.assert_allclose(model.markov_sigma, sigma_ug * UG, rtol=1e-15)
    t = np.arange(n) * dt
    y = apply_errors(np.zeros((n, 3)), t, spec, np.random.default_rng(77))
    np.testing.assert_array_equal(y[:, 1], 0.0)
    taus = dt * 2.0 ** np.arange(0, 12)  # 0.005 … 10.24 s
    for axis in (0, 2):
        allan = allan_deviation(y[:, axis], dt, taus=taus)
        expected = np.sqrt(noise.gauss_markov_avar(allan.tau, sigma_ug[axis] * UG, tau_c[axis], dt))
        tolerance = SIGMAS / np.sqrt(2 * (n / np.round(allan.tau / dt) - 1))
        assert np.all(np.abs(allan.adev / expected - 1) < tolerance), (axis, allan.adev / expected - 1)

    gyro = GyroErrors(markov_sigma_deg_per_h=36.0, markov_tau_s=5.0).to_si()
    np.testing.assert_allclose(gyro.markov_sigma, 36.0 * DEG_PER_H, rtol=1e-15)
    np.testing.assert_array_equal(gyro.markov_tau_s, 5.0)
    assert not np.any(GyroErrors().to_si().markov_sigma)  # off by default


@pytest.mark.parametrize(
    "model, data, key, words",
    [
        (AccelErrors, {"markov_sigma_ug": 10.0}, "accelerometer.markov_tau_s", "give both"),
        (AccelErrors, {"markov_tau_s": 1.0}, "accelerometer.markov_tau_s", "give both"),
        (
            GyroErrors,
            {"markov_sigma_deg_per_h": [1, 0, 1], "markov_tau_s": [1, 1, 0]},
            "accelerometer.markov_tau_s",
            "> 0",
        ),
        (
            GyroErrors,
            {"markov_sigma_deg_per_h": -1.0, "markov_tau_s": 1.0},
            "accelerometer.markov_sigma_deg_per_h",
            ">= 0",
        ),
    ],
)
def test_gauss_markov_keys_come_in_pairs(model, data, key, words):
    with pytest.raises(ConfigError) as error:
        validate(model, data, file="device.toml", prefix="accelerometer")
    assert error.value.key == key
    assert words in str(error.value)


def test_power_up_bias_is_the_fixed_plus_the_turn_on_draw():
    """``SensorErrors.bias``: b + σ_on·z with z the generator's first three normal draws; on one sample
    and on none the output is still (n, 3); a specific force of the wrong shape is refused."""
    from gyroemu.sensors.errors import SensorErrors

    spec = GyroErrors(
        bias_deg_per_h=[1.0, 2.0, 3.0], turn_on_bias_deg_per_h=10.0, g_sensitivity_deg_per_h_per_g=np.eye(3).tolist()
    )
    errors = SensorErrors(spec, 0.01, np.random.default_rng(4))
    z = np.random.default_rng(4).standard_normal(3)
    scale = (np.array([1.0, 2.0, 3.0]) + 10.0 * np.abs(z)) * DEG_PER_H  # the sum's terms: round-off on them
    np.testing.assert_allclose(
        errors.bias,
        (np.array([1.0, 2.0, 3.0]) + 10.0 * z) * DEG_PER_H,
        rtol=0,
        atol=4 * np.finfo(float).eps * scale.max(),
    )
    assert errors.bias.shape == (3,)
    one = errors.apply(np.zeros((1, 3)), np.zeros(1), specific_force=np.zeros((1, 3)))
    assert one.shape == (1, 3) and np.all(np.isfinite(one))
    assert errors.apply(np.zeros((0, 3)), np.zeros(0), specific_force=np.zeros((0, 3))).shape == (0, 3)
    with pytest.raises(ValueError, match="specific_force"):
        errors.apply(np.zeros((2, 3)), np.array([0.0, 0.01]), specific_force=np.zeros((3, 3)))
