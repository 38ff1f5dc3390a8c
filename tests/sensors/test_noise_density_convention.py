"""The noise-density convention, stated once: what each white-noise key means, measured on the output.

gyroemu draws white noise of density N as per-sample σ = N/√Δt, so its Allan deviation at τ = 1 s is N
and its one-sided power spectral density is 2N² (two-sided N²). The keys ``arw_deg_per_sqrt_h``,
``noise_density_deg_per_s_per_sqrt_hz``, ``vrw_m_per_s_per_sqrt_h`` and ``noise_density_ug_per_sqrt_hz``
give N; ``psd_one_sided_deg_per_s_per_sqrt_hz`` and ``psd_one_sided_ug_per_sqrt_hz`` give the one-sided
amplitude √S₁ = √2·N. Each key is checked through the error layer at a few rates, against both readings,
with tolerances from the sample count; the checks also refuse the other reading (a factor √2 off).
"""

import math

import numpy as np
import pytest
import scipy.signal
from scipy.stats import chi2, norm

from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors import device_from_dict
from gyroemu.sensors.allan import allan_deviation
from gyroemu.sensors.errors import STANDARD_GRAVITY, AccelErrors, GyroErrors, apply_errors

DEG = math.pi / 180  # rad per degree
UG = 1e-6 * STANDARD_GRAVITY  # m/s² per µg
DURATION_S = 1000.0
ALPHA = 1e-4  # two-sided probability of a false failure, per check
Z = norm.isf(ALPHA / 2)  # ≈ 3.9 standard deviations
NPERSEG = 256

# (errors class, key, value, N in SI: rad/√s or m/s/√s)
CASES = [
    (GyroErrors, "arw_deg_per_sqrt_h", 0.6, 0.6 * DEG / 60),
    (GyroErrors, "noise_density_deg_per_s_per_sqrt_hz", 0.01, 0.01 * DEG),
    (GyroErrors, "psd_one_sided_deg_per_s_per_sqrt_hz", 0.01, 0.01 * DEG / math.sqrt(2)),
    (AccelErrors, "vrw_m_per_s_per_sqrt_h", 0.06, 0.06 / 60),
    (AccelErrors, "noise_density_ug_per_sqrt_hz", 100.0, 100.0 * UG),
    (AccelErrors, "psd_one_sided_ug_per_sqrt_hz", 100.0, 100.0 * UG / math.sqrt(2)),
]
RATES_HZ = [100.0, 400.0, 1000.0]


def white_output(errors_cls, key, value, rate_hz, seed):
    """The error layer's output for a zero input: the white noise alone, (n, 3)."""
    t = np.arange(int(DURATION_S * rate_hz)) / rate_hz
    spec = errors_cls(**{key: value})
    return apply_errors(np.zeros((t.size, 3)), t, spec, np.random.default_rng(seed))


def case_id(case):
    return f"{case[0].__name__}-{case[1]}"


@pytest.fixture(
    scope="module", params=[(c, r) for c in CASES for r in RATES_HZ], ids=lambda p: f"{case_id(p[0])}-{p[1]:g}Hz"
)
def generated(request):
    (errors_cls, key, value, density), rate_hz = request.param
    seed = 1000 + CASES.index(request.param[0]) * 10 + RATES_HZ.index(rate_hz)
    return white_output(errors_cls, key, value, rate_hz, seed), 1.0 / rate_hz, density


def test_the_key_converts_exactly():
    # The stated figure, converted: N-style keys as they were; one-sided amplitudes divided by √2.
    for errors_cls, key, value, density in CASES:
        np.testing.assert_allclose(errors_cls(**{key: value}).to_si().noise_density, density, rtol=1e-15)
    one_sided = GyroErrors(psd_one_sided_deg_per_s_per_sqrt_hz=[0.02, 0.03, 0.04]).to_si().noise_density
    np.testing.assert_allclose(one_sided * math.sqrt(2), np.array([0.02, 0.03, 0.04]) * DEG, rtol=1e-15)
    one_sided = AccelErrors(psd_one_sided_ug_per_sqrt_hz=math.sqrt(2) * 70).to_si().noise_density
    np.testing.assert_allclose(
        one_sided, AccelErrors(noise_density_ug_per_sqrt_hz=70).to_si().noise_density, rtol=1e-15
    )


def test_allan_deviation_at_one_second_is_n(generated):
    y, dt, density = generated
    for axis in range(3):
        allan = allan_deviation(y[:, axis], dt, taus=np.array([1.0]))
        assert allan.tau[0] == pytest.approx(1.0)
        # χ² interval of σ(1 s) from the independent clusters (ν = clusters − 1: conservative for the
        # overlapping estimator, whose ν is larger).
        nu = allan.edf[0]
        low, high = density * np.sqrt(chi2.ppf(ALPHA / 2, nu) / nu), density * np.sqrt(chi2.isf(ALPHA / 2, nu) / nu)
        assert low < allan.adev[0] < high, (axis, allan.adev[0] / density, low / density, high / density)
        # ... and the interval is narrow enough to tell N from the √2-off reading.
        assert high < math.sqrt(2) * low


def test_one_sided_welch_psd_is_2n_squared(generated):
    y, dt, density = generated
    n = y.shape[0]
    f, psd = scipy.signal.welch(
        y, fs=1.0 / dt, window="hann", nperseg=NPERSEG, axis=0, return_onesided=True, scaling="density"
    )
    # Leave out DC, the two bins the segment detrend and the Hann main lobe reach, and Nyquist.
    bins = slice(3, -1)
    level = psd[bins].mean(axis=0)
    expected = 2 * density**2
    # Relative std of one bin: 1/√K with K the segments averaged (counted without the 50 % overlap's
    # gain: conservative); averaged over M bins of which the Hann window makes neighbours correlated
    # (about M/2 independent ones).
    segments = n // NPERSEG
    independent_bins = psd[bins].shape[0] / 2
    rel_std = 1 / math.sqrt(segments) / math.sqrt(independent_bins)
    tolerance = Z * rel_std
    assert tolerance < 0.1
    np.testing.assert_allclose(level / expected, 1.0, atol=tolerance)
    # Flat: every bin agrees with the level (per-bin relative std 1/√K, with a Bonferroni margin).
    per_bin = norm.isf(ALPHA / 2 / psd[bins].size) / math.sqrt(segments)
    assert np.all(np.abs(psd[bins] / expected - 1) < per_bin)
    # The two-sided level N² (or a one-sided 4N²) is far outside.
    assert np.all(np.abs(level / (density**2) - 1) > 0.5)


@pytest.mark.parametrize(
    "errors_cls, data, key",
    [
        (
            GyroErrors,
            {"arw_deg_per_sqrt_h": 0.1, "psd_one_sided_deg_per_s_per_sqrt_hz": 0.01},
            "psd_one_sided_deg_per_s_per_sqrt_hz",
        ),
        (
            GyroErrors,
            {"noise_density_deg_per_s_per_sqrt_hz": 0.01, "psd_one_sided_deg_per_s_per_sqrt_hz": 0.01},
            "psd_one_sided_deg_per_s_per_sqrt_hz",
        ),
        (
            AccelErrors,
            {"vrw_m_per_s_per_sqrt_h": 0.01, "psd_one_sided_ug_per_sqrt_hz": 100},
            "psd_one_sided_ug_per_sqrt_hz",
        ),
        (
            AccelErrors,
            {"noise_density_ug_per_sqrt_hz": 100, "psd_one_sided_ug_per_sqrt_hz": 100},
            "psd_one_sided_ug_per_sqrt_hz",
        ),
    ],
)
def test_two_readings_of_one_noise_are_refused(errors_cls, data, key):
    with pytest.raises(ConfigError) as error:
        validate(errors_cls, data, file="device.toml", prefix="gyro")
    assert error.value.key == f"gyro.{key}"
    other = next(k for k in data if k != key)
    assert other in str(error.value) and key in str(error.value) and "not both" in str(error.value)


def test_one_sided_key_negative_names_the_key():
    with pytest.raises(ConfigError) as error:
        validate(GyroErrors, {"psd_one_sided_deg_per_s_per_sqrt_hz": -1}, file="device.toml", prefix="gyro")
    assert error.value.key == "gyro.psd_one_sided_deg_per_s_per_sqrt_hz"


def test_device_budget_reads_the_one_sided_key():
    # A device given a one-sided amplitude √2·N outputs the same noise as one given N.
    def device(errors):
        return device_from_dict({"description": "x", "rate_hz": 200, "gyro": {"errors": errors}}, seed=5)

    one_sided = device({"psd_one_sided_deg_per_s_per_sqrt_hz": 0.02 * math.sqrt(2)})
    allan_style = device({"noise_density_deg_per_s_per_sqrt_hz": 0.02})
    np.testing.assert_allclose(one_sided.gyro_noise_density, allan_style.gyro_noise_density, rtol=1e-15)
    np.testing.assert_allclose(one_sided.gyro_noise_density, 0.02 * DEG, rtol=1e-15)
