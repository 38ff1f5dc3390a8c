"""A low-pass whose memory reaches the first octaves (sensors/allan.py module notes, "The low-pass's
reach"): :func:`fit_band_limited` leaves those τ out, and reads the white noise where the τ⁻² form holds.

White noise N through a first-order low-pass of time constant T has the Allan variance of exponentially
correlated noise (IEEE 952 Annex C), (N²/τ)(1 − (T/2τ)(3 − 4e^(−τ/T) + e^(−2τ/T))); the τ⁻² form
N²/τ − (3/2)N²T/τ² leaves (N²/τ)(T/2τ)(4e^(−τ/T) − e^(−2τ/T)) out, which at τ ≈ T is most of the curve.
"""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from gyroemu.pipelines.jobs.allan import allan_report
from gyroemu.sensors.allan import AllanDeviation, allan_deviation, fit_allan, fit_band_limited

FS = 100.0
SECONDS = 300.0
N = 0.01


def beyond_form(tau: np.ndarray, t: float) -> np.ndarray:
    """What the τ⁻² form leaves out of a first-order low-pass's Allan variance, relative to N²/τ."""
    x = tau / t
    return (0.5 / x) * (4 * np.exp(-x) - np.exp(-2 * x))


def exact_low_pass(t: float, edf: float) -> AllanDeviation:
    """The exact curve at octaves from τ = T/4, every point with ``edf`` degrees of freedom."""
    tau = 0.25 * t * 2.0 ** np.arange(16)
    avar = (N**2 / tau) * (1 - (t / (2 * tau)) * (3 - 4 * np.exp(-tau / t) + np.exp(-2 * tau / t)))
    adev = np.sqrt(avar)
    edfs = np.full(tau.shape, edf)
    return AllanDeviation(tau=tau, adev=adev, clusters=edfs + 1, edf=edfs, low=adev, high=adev)


def smoothed_white_noise(seed: int, cutoff_hz: float | None) -> np.ndarray:
    """``SECONDS`` of white noise of density N sampled at ``FS``, through the sampled first-order low-pass
    of cut-off ``cutoff_hz`` (y_k = a y_(k−1) + (1 − a) x_k, a = e^(−Δt/T)), settled for 50 s first."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(int((SECONDS + 50) * FS)) * N * math.sqrt(FS)
    if cutoff_hz is not None:
        a = math.exp(-2 * math.pi * cutoff_hz / FS)
        x = lfilter([1 - a], [1, -a], x)
    return x[int(50 * FS) :]


def test_an_exact_curve_is_fitted_where_the_form_holds():
    """On the exact curve (ν = 10⁶ a point: a relative sd √(2/ν) of 1.4·10⁻³) every point kept lies
    where the τ⁻² form misses by at most half a standard deviation (of the T the fit finds; the true T's
    within one sd), so N comes back to within half a standard deviation; fitted over all of the curve,
    the form's misfit at τ ≈ T pulls N off by many."""
    t, edf = 0.1, 1e6
    curve = exact_low_pass(t, edf)
    sd = math.sqrt(2 / edf)
    fit = fit_band_limited(curve, terms=("quantisation", "arw"))
    kept = curve.tau[fit.skipped :]
    assert fit.skipped > 0
    assert np.all(beyond_form(kept, t) <= sd)
    assert beyond_form(curve.tau[fit.skipped - 1 : fit.skipped], t)[0] > 0.25 * sd  # not more than needed
    assert fit.arw.value == pytest.approx(N, rel=0.5 * sd)
    assert fit.allan is curve  # the whole curve, for the plot
    whole = fit_allan(curve, terms=("quantisation", "arw"), band_limit=True)
    assert abs(whole.arw.value / N - 1) > 10 * sd


@pytest.mark.parametrize("cutoff_hz", [FS / 10, FS / 40])
def test_smoothed_white_noise_reads_its_density(cutoff_hz):
    """Eight runs of 300 s: the mean of N̂/N − 1 within three standard errors of 0, the standard error
    taken from the fits' own 68 % half-widths (their mean over √8). Over all the octaves (a first-order
    low-pass at a tenth of the rate: 26 % low; at a fortieth N is not found) it is not."""
    errors, half_widths, plain = [], [], []
    for seed in range(8):
        allan = allan_deviation(smoothed_white_noise(seed, cutoff_hz), 1 / FS)
        fit = fit_band_limited(allan)
        assert fit.skipped > 0
        errors.append(fit.arw.value / N - 1)
        half_widths.append((fit.arw.high - fit.arw.low) / 2 / N)
        plain.append(fit_allan(allan, band_limit=True).arw.value / N - 1)
    bound = 3 * np.mean(half_widths) / math.sqrt(len(errors))
    assert abs(np.mean(errors)) <= bound
    assert abs(np.mean(plain)) > bound


def test_white_noise_without_a_low_pass_is_fitted_whole():
    """No octave is left out where nothing smooths the noise: the fit is fit_allan's of the whole curve."""
    for seed in range(8):
        allan = allan_deviation(smoothed_white_noise(seed, None), 1 / FS)
        fit = fit_band_limited(allan)
        assert fit.skipped == 0
        assert fit == fit_allan(allan, band_limit=True)


def test_a_random_walk_rises_without_falling_and_is_fitted_whole():
    """A curve that rises from its first point and never falls (a rate random walk) is no smoothed white
    noise: nothing is left out, though no white noise is resolved."""
    tau = 0.01 * 2.0 ** np.arange(12)
    adev = np.sqrt(1e-6 * tau / 3)
    edf = np.full(tau.shape, 1e4)
    curve = AllanDeviation(tau=tau, adev=adev, clusters=edf + 1, edf=edf, low=adev, high=adev)
    fit = fit_band_limited(curve)
    assert fit.skipped == 0 and not fit.arw.resolved


def test_gyroemu_allan_reports_where_its_fit_starts():
    """``gyroemu allan``'s report (text and JSON) gives the shortest τ fitted: Δt without a low-pass, a
    longer one (the same on the three axes here) behind one at a tenth of the rate."""
    x = np.column_stack([smoothed_white_noise(seed, FS / 10) for seed in (1, 2, 3)])
    report = allan_report(x, 1 / FS)
    starts = [report.to_dict()["gyro"]["fitted_from"][axis]["value"] for axis in "xyz"]
    assert all(s > 1 / FS for s in starts)
    row = next(line for line in report.table().splitlines() if line.startswith("fitted from"))
    assert row.split()[4:7] == [f"{s * 1e3:.3g}" for s in starts]
    white = np.column_stack([smoothed_white_noise(seed, None) for seed in (1, 2, 3)])
    plain = allan_report(white, 1 / FS).to_dict()["gyro"]["fitted_from"]
    assert [plain[axis]["value"] for axis in "xyz"] == [1 / FS] * 3
