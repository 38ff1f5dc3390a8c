"""Our own overlapping Allan deviation and chi-squared interval against allantools' (a test-only dependency).

``allan_deviation`` computes octave τ with the streamed accumulator (one chunk, every octave exact) and
explicit τ in numpy from the phase x = Δt·cumsum(y − ȳ), the same phase allantools builds. Round-off
bound as in ``test_allan_stream``: a second difference D = x_{k+2m} − 2x_{k+m} + x_k has an error of at
most δ ≤ ε·[P·(m + 2r + 3.5 + extra) + m·Δt·Y] (P the largest phase magnitude rounded, r re-basings, Y
the largest |y − offset|), and σ(τ) a relative error of at most ½(2δ/rms(D) + (δ/rms(D))²); the sums of
squares and the final scaling add a few ε·log₂n. Each side's bound is added.

The interval: ``chi2_interval`` evaluates the formula ``allantools.confidence_interval`` does
(dev·√(ν/χ²_ppf(1 − α/2, ν)), dev·√(ν/χ²_ppf(α/2, ν))), with scipy's χ² quantiles, so the two agree to
a few ε (a product, a quotient and a square root).
"""

from __future__ import annotations

import subprocess
import sys

import allantools
import numpy as np
import pytest

from gyroemu.sensors.allan import allan_confidence, allan_deviation, chi2_interval, fit_allan

EPS = np.finfo(float).eps
ONE_SIGMA = 0.682689492137086


def relative_bound(m: int, P: float, Y: float, dt: float, rms: float, rebases: int, extra: float = 0.0) -> float:
    """Bound on the relative error of σ(τ) (module notes): ½(2δ/rms + (δ/rms)²)."""
    delta = EPS * (P * (m + 2 * rebases + 3.5 + extra) + m * dt * Y)
    q = delta / rms
    return 0.5 * (2 * q + q * q)


def gyro_like(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) rad/s: white noise, a random walk of the rate and an earth-rate-sized bias."""
    return rng.normal(0.0, 1e-3, n) + np.cumsum(rng.normal(0.0, 1e-6, n)) + 7e-5


def round_off_bound(y: np.ndarray, dt: float, m: int, rebases: int) -> float:
    """Both sides' bound on |σ_ours/σ_allantools − 1| at τ = mΔt (both carry the phase of y − ȳ)."""
    x = np.concatenate([[0.0], np.cumsum(y - y.mean()) * dt])
    P, Y = np.abs(x).max(), np.abs(y - y.mean()).max()
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    rms = np.sqrt(np.mean(d * d))
    ours = relative_bound(m, 2 * P, Y, dt, rms, rebases)  # the accumulator: differences of two sums
    return relative_bound(m, P, Y, dt, rms, 0, extra=2.0) + ours + 8 * EPS * np.log2(len(y))


@pytest.mark.parametrize("n", [4, 5, 7, 8, 100, 1001, 1 << 17])
def test_octave_allan_deviation_equals_allantools_oadev(n: int) -> None:
    rng = np.random.default_rng(n)
    dt = 0.01
    y = gyro_like(n, rng)
    ours = allan_deviation(y, dt)
    tau, adev, _, _ = allantools.oadev(y, rate=1 / dt, data_type="freq", taus="octave")
    assert len(ours.tau) == len(tau)
    np.testing.assert_allclose(ours.tau, tau, rtol=4 * EPS, atol=0)
    for i, m in enumerate(np.round(tau / dt).astype(int)):
        bound = round_off_bound(y, dt, m, rebases=0)
        assert abs(ours.adev[i] / adev[i] - 1) <= bound, (m, ours.adev[i] / adev[i] - 1, bound)
    np.testing.assert_array_equal(ours.clusters, np.floor(n / np.round(tau / dt)))
    np.testing.assert_array_equal(ours.edf, ours.clusters - 1)


@pytest.mark.parametrize(
    "taus",
    [
        np.array([0.01, 0.03, 0.03, 0.02, 1.0, 5.0, 1e9]),  # repeats, unsorted, one beyond the series
        np.array([0.015, 0.07, 0.333]),  # rounded to multiples of Δt
        np.geomspace(0.01, 100.0, 25),
    ],
)
def test_explicit_taus_equal_allantools_oadev(taus: np.ndarray) -> None:
    rng = np.random.default_rng(11)
    dt, n = 0.01, 20000
    y = gyro_like(n, rng)
    ours = allan_deviation(y, dt, taus=taus)
    tau, adev, _, _ = allantools.oadev(y, rate=1 / dt, data_type="freq", taus=taus)
    np.testing.assert_allclose(ours.tau, tau, rtol=4 * EPS, atol=0)
    for i, m in enumerate(np.round(tau / dt).astype(int)):
        bound = round_off_bound(y, dt, m, rebases=0)
        assert abs(ours.adev[i] / adev[i] - 1) <= bound, (m, ours.adev[i] / adev[i] - 1, bound)


@pytest.mark.parametrize("keyword", ["all", "decade", "log10"])
def test_allantools_tau_keywords_give_its_taus(keyword: str) -> None:
    rng = np.random.default_rng(5)
    dt, n = 0.02, 3000
    y = gyro_like(n, rng)
    ours = allan_deviation(y, dt, taus=keyword)
    tau, adev, _, _ = allantools.oadev(y, rate=1 / dt, data_type="freq", taus=keyword)
    np.testing.assert_allclose(ours.tau, tau, rtol=4 * EPS, atol=0)
    np.testing.assert_allclose(ours.adev, adev, rtol=1e-12)  # far inside the bound above for this run


def test_explicit_taus_none_of_which_fit_give_an_empty_result() -> None:
    allan = allan_deviation(np.arange(10.0), 0.1, taus=np.array([0.5, 2.0]))  # 2m > n − 1 for both
    assert allan.tau.size == allan.adev.size == allan.low.size == 0


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 4 samples"):
        allan_deviation(np.zeros(3), 0.1)
    with pytest.raises(ValueError, match="NaN or infinite"):
        allan_deviation(np.array([0.0, 1.0, np.nan, 2.0, 3.0]), 0.1)
    with pytest.raises(ValueError, match="dt must be"):
        allan_deviation(np.zeros(10), 0.0)
    with pytest.raises(ValueError, match="unknown taus"):
        allan_deviation(np.zeros(10), 0.1, taus="weekly")


@pytest.mark.parametrize("ci", [ONE_SIGMA, 0.9, 0.95, 0.3])
def test_chi2_interval_equals_allantools_confidence_interval(ci: float) -> None:
    dev = np.geomspace(1e-9, 1e3, 13)
    edf = np.array([0.3, 1, 1.5, 2, 3, 7, 10, 31, 100, 1e3, 1e4, 1e5, 1e6])
    low, high = chi2_interval(dev, edf, ci=ci)
    for i in range(len(dev)):
        ref_low, ref_high = allantools.confidence_interval(dev[i], edf[i], ci=ci)
        assert low[i] == pytest.approx(ref_low, rel=4 * EPS, abs=0)
        assert high[i] == pytest.approx(ref_high, rel=4 * EPS, abs=0)
    assert np.all(low < dev) and np.all(dev < high)
    scalar = chi2_interval(2.0, 5.0, ci=ci)
    assert float(scalar[0]) == pytest.approx(allantools.confidence_interval(2.0, 5.0, ci=ci)[0], rel=4 * EPS)


def test_allan_confidence_and_fit_use_the_same_interval() -> None:
    rng = np.random.default_rng(2)
    y = gyro_like(50000, rng)
    allan = allan_deviation(y, 0.01)
    again = allan_confidence(allan.tau, allan.adev, allan.clusters)
    np.testing.assert_array_equal(again.low, allan.low)
    np.testing.assert_array_equal(again.high, allan.high)
    for s, nu, lo, hi in zip(allan.adev, allan.edf, allan.low, allan.high):
        ref = allantools.confidence_interval(s, nu, ci=ONE_SIGMA)
        assert lo == pytest.approx(ref[0], rel=4 * EPS) and hi == pytest.approx(ref[1], rel=4 * EPS)
    arw = fit_allan(allan).arw
    assert arw.resolved and arw.low < arw.value < arw.high


def test_runtime_modules_do_not_import_allantools() -> None:
    """allantools is a test dependency: the CLI, the Allan job and the Allan module run without it."""
    code = (
        "import sys; import gyroemu, gyroemu.pipelines.cli, gyroemu.pipelines.jobs.allan, gyroemu.sensors.allan; "
        "assert 'allantools' not in sys.modules, 'allantools imported'"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
