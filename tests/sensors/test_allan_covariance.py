"""The IEEE 952 fit's band limit and the covariance it gives its coefficients (sensors/allan.py module
notes): a low-pass's sag recovered from its exact curve, the white-noise correlation of octave points
against its exact sampled sums, the white-noise degrees of freedom against NIST SP 1065's, and the whole
fit's variance of N against the scatter of N over many draws of white noise."""

import allantools
import numpy as np
import pytest

from gyroemu.sensors.allan import (
    AllanDeviation,
    _basis,
    allan_deviation,
    fit_allan,
    fit_covariance,
    weighted_fit,
    white_correlation,
    white_edf,
)


def test_band_limit_of_white_noise_through_a_first_order_low_pass():
    """White noise N through a first-order low-pass of time constant T has the Allan variance of
    exponentially correlated noise (IEEE 952 Annex C), (N²/τ)(1 − (T/2τ)(3 − 4e^(−τ/T) + e^(−2τ/T))):
    from τ = 20T on, N²/τ − (3/2) N² T/τ² but for terms below e⁻²⁰. Fitted with the τ⁻² term of
    either sign, N and the band limit (3/2) N² T come back to the solver's round-off; held ≥ 0, the
    quantisation term is 0 and N reads low."""
    n, t = 1e-3, 1e-3
    tau = 20 * t * 2.0 ** np.arange(14)
    avar = (n**2 / tau) * (1 - (t / (2 * tau)) * (3 - 4 * np.exp(-tau / t) + np.exp(-2 * tau / t)))
    edf = np.full(tau.shape, 1e6)
    adev = np.sqrt(avar)
    allan = AllanDeviation(tau=tau, adev=adev, clusters=edf + 1, edf=edf, low=adev, high=adev)
    fit = fit_allan(allan, terms=("quantisation", "arw"), band_limit=True)
    assert fit.arw.value == pytest.approx(n, rel=1e-9)
    assert fit.band_limit == pytest.approx(1.5 * n**2 * t, rel=1e-6)
    assert fit.quantisation.value == 0.0
    np.testing.assert_allclose(fit.model(tau), adev, rtol=1e-9)
    held = fit_allan(allan, terms=("quantisation", "arw"))
    assert held.quantisation.value == 0.0 and held.band_limit == 0.0
    assert held.arw.value < n * (1 - 1e-4)


def _sampled_correlation(m_a: int, m_b: int) -> float:
    """Correlation of the overlapping Allan variance estimates at m_a, m_b samples of white noise, from
    the second differences' kernels h_m = (−1 × m, +1 × m): for Gaussian data cov(d_a², d_b²) = 2 cov(d_a,
    d_b)², so over a long record cov ∝ Σ_s g_ab(s)² with g_ab the kernels' cross-correlation."""

    def kernel(m: int) -> np.ndarray:
        return np.concatenate([-np.ones(m), np.ones(m)])

    def power(a: int, b: int) -> float:
        g = np.correlate(kernel(a), kernel(b), "full")
        return float(np.sum(g * g))

    return power(m_a, m_b) / np.sqrt(power(m_a, m_a) * power(m_b, m_b))


def test_white_correlation_is_the_large_sample_limit_of_the_sampled_sums():
    """ρ(τ_a, τ_b) (closed form, continuous time) against the exact sums at m_a = 64: the sums differ
    from their limit by O(1/m²), 10⁻³ here; the closed form (3/2)(τ_a/τ_b)^(3/2) holds from τ_b = 2τ_a."""
    m = 64
    for ratio in (1.0, 1.25, 1.5, 1.75, 2.0, 3.0, 4.0, 8.0):
        tau = np.array([1.0, ratio])
        rho = white_correlation(tau)
        assert rho[0, 1] == rho[1, 0]
        assert rho[0, 0] == rho[1, 1] == pytest.approx(1.0, rel=1e-15)
        assert rho[0, 1] == pytest.approx(_sampled_correlation(m, round(m * ratio)), abs=1e-3), ratio
        if ratio >= 2.0:
            assert rho[0, 1] == pytest.approx(1.5 * ratio**-1.5, rel=1e-12)
    # Neighbouring octaves of the sampled estimator at τ = Δt, 2Δt: 0.46 against the limit's 0.53.
    assert _sampled_correlation(1, 2) == pytest.approx(0.4629, abs=1e-4)
    octaves = white_correlation(2.0 ** np.arange(12))
    assert np.all(np.linalg.eigvalsh(octaves) > 0)  # a correlation matrix: positive definite


def test_white_edf_is_nist_sp_1065s_for_white_noise():
    """ν_w for one record of n samples (n + 1 phase points N) against allantools' NIST SP 1065 Table 5
    formula (3(N − 1)/(2m) − 2(N − 2)/N)·4m²/(4m² + 5): ours takes n/m as the count ⌊n/m⌋ − 1 + 1, so
    they differ by (3/2)(n/m − ⌊n/m⌋) − 3/2 + 2(N − 2)/N times the factor ≤ 1, less than 1 in absolute."""
    n, dt = 5000, 0.01
    allan = allan_deviation(np.random.default_rng(0).standard_normal(n), dt)
    m = np.round(allan.tau / dt)
    nist = np.array([allantools.edf_simple(n + 1, mi, 0) for mi in m])
    assert np.all(np.abs(white_edf(allan) - nist) < 1.0)
    unknown = allan.__class__(**{**allan.__dict__, "dt": float("nan")})
    np.testing.assert_array_equal(white_edf(unknown), allan.edf)  # without Δt: the count


def test_fit_covariance_of_white_noise_meets_the_scatter_of_the_fitted_density():
    """400 records of white noise (n = 20 000), each fitted with the τ⁻² term of either sign beside N:
    the variance of c_N = N² over the records against the median of the fit's covariance of it. A
    sample variance of K draws has a relative standard deviation √(2/(K − 1)) (7 % here): the two agree
    within three of those. (Counted as independent octaves of the count's ν, the plain (XᵀX)⁻¹ of the
    weighted least squares, it was three quarters of the scatter.)"""
    dt, n, draws = 0.01, 20_000, 400
    rng = np.random.default_rng(3)
    values, predicted = [], []
    for _ in range(draws):
        allan = allan_deviation(rng.standard_normal(n) * 0.1, dt)
        basis = _basis(allan.tau)[:, :2]
        free = np.array([True, False])
        c, model, _ = weighted_fit(allan, basis, free)
        values.append(c[1])
        predicted.append(fit_covariance(allan, basis, c, model, free)[1, 1])
    empirical = np.var(values, ddof=1)
    tolerance = 3 * np.sqrt(2 / (draws - 1))
    assert np.median(predicted) == pytest.approx(empirical, rel=tolerance)
    fit = fit_allan(allan, terms=("quantisation", "arw"), band_limit=True)
    assert fit.arw.value == pytest.approx(np.sqrt(values[-1]), rel=1e-12)


def test_a_band_limit_needs_the_tau_minus_2_term():
    """``band_limit=True`` frees the τ⁻² column; without it in ``terms`` there is nothing to free, and the
    fit says so rather than fitting non-negatively in silence."""
    from gyroemu.sensors.allan import allan_deviation, fit_allan

    allan = allan_deviation(np.random.default_rng(3).standard_normal(4096), 0.01)
    with pytest.raises(ValueError, match="quantisation"):
        fit_allan(allan, terms=("arw", "bias_instability"), band_limit=True)


def test_the_fit_residual_counts_a_point_the_signed_fit_takes_below_zero():
    """With the τ⁻² term free, the model can go ≤ 0 at the first τ; that point then weighs by the data
    (its model is no standard deviation), but its misfit still counts in the residual χ² that identify's
    Gauss–Markov F-test compares (it counted 0: the χ² fell from 2608 to 679)."""
    tau = 0.01 * 2.0 ** np.arange(10)
    avar = 1e-4 / tau
    avar[1] = 1e-9  # a second point far below the white line: the fit bends down through it
    adev, edf = np.sqrt(avar), np.full(10, 1e3)
    allan = AllanDeviation(tau=tau, adev=adev, clusters=edf + 1, edf=edf, low=adev, high=adev)
    basis = _basis(tau)[:, :2]
    c, model, chi2 = weighted_fit(allan, basis, free=[True, False])
    fitted, avar = basis @ c, allan.adev**2  # the variance the fit sees
    assert fitted[0] < 0 and model[0] == avar[0]
    expected = np.sum(((avar - fitted) / (model * np.sqrt(2 / edf))) ** 2)
    assert chi2 == pytest.approx(expected, rel=1e-12)
    assert chi2 > 2 * np.sum(((avar - model) / (model * np.sqrt(2 / edf))) ** 2)
