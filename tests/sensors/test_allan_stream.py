"""The streamed overlapping Allan deviation (``gyroemu.sensors.allan_stream``) against allantools' and theory.

Round-off bound used below (derived in the module notes of ``allan_stream``). A second difference
D = x_{k+2m} − 2x_{k+m} + x_k of a phase x computed by running sums has an error of at most

    δ ≤ ε·[P·(m + 2r + 3.5) + m·Δt·Y]

with ε = 2⁻⁵², P the largest phase magnitude that is rounded, m the sums inside the term's span (ε/2 of
P each, over 2m steps), r re-basings of each of its three points (ε/2 of P each, weights 1, 2, 1:
2rεP; r = 0 for allantools, which does not re-base), 3.5εP for the subtractions forming D (and for
allantools 2εP more for its multiplication by Δt, folded into the 3.5 + 2 below), and Y the largest
|y − offset| (the rounding of each sample's offset removal, ε/2·Y·Δt, over 2m samples). Then
|δΣD²|/ΣD² ≤ 2δ/rms(D) + (δ/rms(D))² (Cauchy–Schwarz: Σ|D| ≤ √(n ΣD²)), and σ = √(σ²) halves it.
The sums of squares (pairwise, and compensated across chunks) and the final scaling add a few ε·log₂n.
"""

from __future__ import annotations

import allantools
import numpy as np
import pytest
from scipy.stats import chi2

from gyroemu.sensors import OverlappingAllanAccumulator
from gyroemu.sensors.allan import allan_deviation

EPS = np.finfo(float).eps


def relative_bound(m, P, Y, dt, rms, rebases, extra=0.0):
    """Bound on the relative error of σ(τ) (see the module notes): ½(2δ/rms + (δ/rms)²)."""
    delta = EPS * (P * (m + 2 * rebases + 3.5 + extra) + m * dt * Y)
    q = delta / rms
    return 0.5 * (2 * q + q * q)


def gyro_like(n, rng, dt):
    """(n, 3) rad/s: white noise, a random walk of the rate and a bias (an earth-rate-sized 7e-5 rad/s)."""
    white = rng.normal(0.0, 1e-3, (n, 3))
    walk = np.cumsum(rng.normal(0.0, 1e-6, (n, 3)), axis=0)
    return white + walk + np.array([7e-5, -1e-5, 3e-5])


def feed(y, cuts, **kw):
    acc = OverlappingAllanAccumulator(kw.pop("dt", 0.01), n_axes=y.shape[1], **kw)
    for chunk in np.split(y, cuts):
        acc.update(chunk)
    return acc


def our_phase_scale(y, offset, dt):
    """(P, Y) for the accumulator: its phases are differences of two sums of (y − offset), so at most
    twice the largest running sum, in phase units (×Δt); Y the largest |y − offset|."""
    s = np.cumsum(y - offset, axis=0) * dt
    return 2 * np.abs(s).max(axis=0), np.abs(y - offset).max(axis=0)


def test_exact_octaves_equal_allantools_oadev_to_round_off():
    rng = np.random.default_rng(7)
    dt, n = 0.01, 1 << 17
    y = gyro_like(n, rng, dt)
    cuts = np.sort(rng.choice(np.arange(1, n), size=6, replace=False))
    acc = feed(y, cuts, dt=dt)
    streamed = acc.deviations()
    P_ours, Y_ours = our_phase_scale(y, acc.offset, dt)
    for axis in range(3):
        tau, adev, _, _ = allantools.oadev(y[:, axis], rate=1 / dt, data_type="freq", taus="octave")
        ours = streamed[axis]
        assert len(ours.tau) == len(tau) == 16  # m = 1 … 2^15: 2m ≤ N − 1
        assert np.all(acc.strides[: len(tau)] == 1), "every octave of this run is exact"
        np.testing.assert_allclose(ours.tau, tau, rtol=4 * EPS, atol=0)
        # allantools' phase: x = Δt·cumsum(y − ȳ), and the second differences it sums.
        x = np.concatenate([[0.0], np.cumsum(y[:, axis] - y[:, axis].mean()) * dt])
        P_ref, Y_ref = np.abs(x).max(), np.abs(y[:, axis] - y[:, axis].mean()).max()
        for i, m in enumerate(np.round(tau / dt).astype(int)):
            d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
            rms = np.sqrt(np.mean(d * d))
            rebases = min(2 * m, len(cuts))
            bound = (
                relative_bound(m, P_ref, Y_ref, dt, rms, 0, extra=2.0)
                + relative_bound(m, P_ours[axis], Y_ours[axis], dt, rms, rebases)
                + 8 * EPS * np.log2(n)
            )
            assert abs(ours.adev[i] / adev[i] - 1) <= bound, (axis, m, ours.adev[i] / adev[i] - 1, bound)


def test_the_allan_deviation_fields_are_those_of_allan_deviation():
    rng = np.random.default_rng(3)
    dt, n = 0.005, 5000
    y = gyro_like(n, rng, dt)
    acc = feed(y, [1234, 1235, 4000], dt=dt)
    for axis, ours in enumerate(acc.deviations()):
        ref = allan_deviation(y[:, axis], dt)
        np.testing.assert_array_equal(ours.clusters, ref.clusters)
        np.testing.assert_array_equal(ours.edf, ref.edf)
        # Same formulas on σ equal to round-off (the test above): the interval scales with σ.
        scale = ours.adev / ref.adev
        np.testing.assert_allclose(ours.low, ref.low * scale, rtol=8 * EPS)
        np.testing.assert_allclose(ours.high, ref.high * scale, rtol=8 * EPS)
        assert np.all(np.abs(scale - 1) < 1e-9)  # far inside the bound of the test above for this run


@pytest.mark.parametrize("n", [4, 5, 6, 7, 8, 9, 63, 64, 65, 127, 128, 129, 1000])
def test_octaves_are_those_allan_deviation_keeps(n):
    y = np.random.default_rng(n).normal(size=(n, 1))
    acc = feed(y, [n // 3], dt=0.1, max_exact_m=2)
    np.testing.assert_allclose(acc.deviations()[0].tau, allan_deviation(y[:, 0], 0.1).tau, rtol=4 * EPS)


def test_fewer_than_four_samples_and_bad_chunks_are_refused():
    acc = OverlappingAllanAccumulator(0.01, n_axes=3)
    acc.update(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="at least 4 samples"):
        acc.deviations()
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        acc.update(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="NaN"):
        acc.update(np.full((5, 3), np.nan))
    assert acc.n_samples == 3
    with pytest.raises(ValueError, match="power of two"):
        OverlappingAllanAccumulator(0.01, max_exact_m=100)


def white_noise_edf(n, m, s):
    """Equivalent degrees of freedom of Σ_k D_k² over k = 0, s, 2s, … ≤ N − 2m for white noise.

    D_k = S_{k+2m} − 2S_{k+m} + S_k of unit white samples has the autocovariance r(h) = 2m − 3|h| for
    |h| ≤ m, |h| − 2m for m ≤ |h| ≤ 2m, 0 beyond; for Gaussian terms Var(ΣD²) = 2 Σ_{k,l} r(l − k)²,
    E ΣD² = K·2m with K terms, and ν = 2(EΣD²)²/Var(ΣD²) (Satterthwaite: the chi-squared of the same mean
    and variance).
    """
    terms = (n - 2 * m) // s + 1
    lags = np.arange(-(terms - 1), terms) * s
    h = np.abs(lags)
    r = np.where(h <= m, 2 * m - 3 * h, np.where(h <= 2 * m, h - 2 * m, 0)).astype(float)
    variance = 2 * np.sum((terms - np.abs(lags // s)) * r**2)
    return 2 * (terms * 2.0 * m) ** 2 / variance


def test_decimated_octaves_are_unbiased_on_white_noise_within_their_chi_squared_interval():
    """White noise of density N: σ²(τ) = N²/τ, here per sample variance 1 and Δt = 1, so σ²(m) = 1/m.
    Each octave's estimate is within its two-sided 1e-4 chi-squared interval of ν degrees of freedom
    (``white_noise_edf``); 13 octaves, so a false failure has probability ≤ 1.3e-3 (seeded anyway)."""
    rng = np.random.default_rng(11)
    n = 1 << 18
    y = rng.normal(size=(n, 2))
    acc = feed(y, np.arange(5000, n, 5000), dt=1.0, max_exact_m=16)
    reported = acc.reported()
    m, s, terms = acc.octaves[reported], acc.strides[reported], acc.terms[reported]
    assert list(m) == [1 << k for k in range(17)]
    assert np.all(s[m <= 16] == 1) and np.all(s[m > 16] == m[m > 16] // 16)
    np.testing.assert_array_equal(terms, (n - 2 * m) // s + 1)
    variance = acc.variances()
    alpha = 1e-4
    for i in np.flatnonzero(m > 16):
        nu = white_noise_edf(n, int(m[i]), int(s[i]))
        low, high = chi2.ppf(alpha / 2, nu) / nu, chi2.ppf(1 - alpha / 2, nu) / nu
        for axis in range(2):
            ratio = variance[i, axis] * m[i]  # estimate / (1/m)
            assert low <= ratio <= high, (int(m[i]), axis, ratio, low, high, nu)


def test_the_result_does_not_depend_on_how_the_data_were_cut():
    """The same samples in one chunk and in pieces cut at random (single samples among them): only the
    order of the roundings differs, so each σ differs by at most the sum of the two runs' bounds."""
    rng = np.random.default_rng(5)
    dt, n = 0.01, 1 << 16
    y = gyro_like(n, rng, dt)
    whole = feed(y, [], dt=dt, max_exact_m=64)
    cuts = np.unique(np.concatenate([rng.integers(1, n, 200), [1, 2, 3, 70000 % n]]))
    cut = feed(y, cuts, dt=dt, max_exact_m=64)
    assert np.any(cut.strides[cut.reported()] > 1), "decimated octaves are exercised too"
    a, b = whole.deviations(), cut.deviations()
    m = whole.octaves[whole.reported()]
    for axis in range(3):
        P1, Y1 = our_phase_scale(y[:, axis], whole.offset[axis], dt)
        P2, Y2 = our_phase_scale(y[:, axis], cut.offset[axis], dt)
        rms = np.sqrt(2.0) * m * dt * a[axis].adev  # rms of the terms: σ² = ⟨D²⟩/(2τ²)
        for i, mi in enumerate(m):
            rebases = min(2 * int(mi), len(cuts))
            bound = (
                relative_bound(mi, P1, Y1, dt, rms[i], 0)
                + relative_bound(mi, P2, Y2, dt, rms[i], rebases)
                + 8 * EPS * np.log2(n)
            )
            assert abs(b[axis].adev[i] / a[axis].adev[i] - 1) <= bound, (axis, mi, bound)
        np.testing.assert_array_equal(a[axis].tau, b[axis].tau)


def run_state_sizes(n_first, chunk, **kw):
    """State size of an accumulator fed ``n_first`` samples, then 4·n_first: (at N, at 4N)."""
    rng = np.random.default_rng(0)
    acc = OverlappingAllanAccumulator(1e-3, n_axes=3, **kw)
    sizes = []
    for target in (n_first, 4 * n_first):
        while acc.n_samples < target:
            acc.update(rng.normal(size=(chunk, 3)))
        sizes.append(acc.state_nbytes())
    return acc, sizes


def test_state_size_does_not_grow_with_the_length():
    acc, (at_n, at_4n) = run_state_sizes(1 << 16, 4096, max_exact_m=64, coarse_overlap=16)
    assert at_n == at_4n
    # Exact buffer (2M₀ + 1)·3, one (2R + 1)·3 buffer per decimated octave 2^7 … 2^61, sums and counts.
    floats = (2 * 64 + 1) * 3 + (61 - 6) * (2 * 16 + 1) * 3 + 2 * 62 * 3 + 3
    assert at_n <= 8 * (floats + 4 * 62 + 2 * 62 + 62)
    assert acc.n_samples == 1 << 18


@pytest.mark.slow
def test_state_size_is_fixed_over_tens_of_millions_of_samples():
    """2^24 then 2^26 samples (the length of a 12-hour run at 1.5 kHz) with the default buffers."""
    acc, (at_n, at_4n) = run_state_sizes(1 << 24, 1 << 16)
    assert at_n == at_4n < 3_000_000
    assert acc.n_samples == 1 << 26
