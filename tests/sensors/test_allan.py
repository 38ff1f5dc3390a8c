"""Allan deviation and the IEEE 952 fit: the algebra on an exact curve, and a synthetic static run."""

import allantools
import numpy as np
import pytest

from gyroemu.sensors import noise
from gyroemu.sensors.allan import TERMS, AllanDeviation, allan_deviation, fit_allan
from gyroemu.sensors.errors import GyroErrors, apply_errors

DEG = np.pi / 180


def test_allan_deviation_of_white_noise_with_its_confidence():
    dt, density, n = 0.01, 3e-3, 200_000
    x = noise.white_noise(np.random.default_rng(0), n, dt, density)
    allan = allan_deviation(x, dt)

    m = np.round(allan.tau / dt)
    np.testing.assert_array_equal(allan.clusters, np.floor(n / m))
    np.testing.assert_array_equal(allan.edf, allan.clusters - 1)
    assert np.all(allan.clusters >= 2)
    np.testing.assert_allclose(allan.tau, dt * 2.0 ** np.arange(allan.tau.size))  # octaves from Δt

    # The interval is allantools' chi-squared interval; about ±1/√(2ν) when ν is large.
    low, high = allantools.confidence_interval(allan.adev[5], allan.edf[5], ci=0.682689492137086)
    assert (allan.low[5], allan.high[5]) == (low, high)
    half_width = (allan.high - allan.low) / 2 / allan.adev
    big = allan.edf > 100
    np.testing.assert_allclose(half_width[big], 1 / np.sqrt(2 * allan.edf[big]), rtol=0.02)

    # White noise: σ(τ) = N/√τ, slope −½, within 4 standard deviations.
    assert np.all(np.abs(allan.adev / (density / np.sqrt(allan.tau)) - 1) < 4 / np.sqrt(2 * allan.edf))
    short = allan.tau <= 1.0
    assert np.polyfit(np.log(allan.tau[short]), np.log(allan.adev[short]), 1)[0] == pytest.approx(-0.5, abs=0.02)


def exact_curve(q, n, b, k, r, tau):
    """σ(τ) of the IEEE 952 model, as an AllanDeviation with plenty of degrees of freedom."""
    avar = 3 * q**2 / tau**2 + n**2 / tau + 2 * np.log(2) / np.pi * b**2 + k**2 * tau / 3 + r**2 * tau**2 / 2
    adev = np.sqrt(avar)
    edf = np.full(tau.shape, 1e6)
    return AllanDeviation(tau=tau, adev=adev, clusters=edf + 1, edf=edf, low=adev, high=adev)


def test_fit_recovers_an_exact_curve():
    tau = 0.01 * 2.0 ** np.arange(22)
    truth = dict(quantisation=2e-6, arw=1e-4, bias_instability=5e-5, rrw=2e-6, rate_ramp=1e-8)
    fit = fit_allan(exact_curve(*truth.values(), tau))
    for name, value in truth.items():
        assert getattr(fit, name).value == pytest.approx(value, rel=1e-6), name
        assert getattr(fit, name).low < value < getattr(fit, name).high
    np.testing.assert_allclose(fit.model(tau), fit.allan.adev, rtol=1e-7)
    # N is the −½ line at τ = 1 s, K the +½ line at τ = 3 s, the floor is 0.664 B.
    assert fit.arw.value / np.sqrt(1.0) == pytest.approx(1e-4)
    assert fit.rrw.value * np.sqrt(3.0 / 3) == pytest.approx(2e-6)


def test_terms_left_out_are_zero_and_absent_terms_get_an_upper_limit():
    tau = 0.01 * 2.0 ** np.arange(20)
    curve = exact_curve(0.0, 1e-4, 5e-5, 2e-6, 0.0, tau)
    fit = fit_allan(curve, terms=("arw", "bias_instability", "rrw", "rate_ramp"))
    assert fit.quantisation.value == fit.quantisation.high == 0.0  # left out
    assert fit.rate_ramp.value == 0.0 < fit.rate_ramp.high  # fitted, not found: an upper limit
    with pytest.raises(ValueError, match="unknown terms"):
        fit_allan(fit.allan, terms=("arw", "flicker"))
    assert set(TERMS) == {"quantisation", "arw", "bias_instability", "rrw", "rate_ramp"}


def test_static_run_recovers_the_noise_terms():
    """Four hours of a static gyro at 100 Hz through the error layer, fitted axis by axis.

    The terms are scaled so that each dominates its own stretch of τ in 4 h: quantisation below
    0.05 s, ARW to 0.5 s, the flicker floor to 3 s, RRW beyond (an exaggerated RRW, so that the
    record pins K to about 2.5 %; over 36 axis-fits of 12 seeds the largest errors were N 0.9 %,
    B 2.8 %, K 4.8 %, Q 0.2 %, so 10 % is about four standard deviations of K's scatter).

    The error layer's own angle quantiser gives IEEE 952's white angle error only when the angle moves
    an LSB or more between samples (a dithered ring-laser gyro, a vehicle in motion); a quiet static
    gyro does not, so the run adds the model's quantisation noise instead.
    """
    dt, hours = 0.01, 4.0
    t = np.arange(int(hours * 3600 / dt)) * dt
    spec = GyroErrors(
        arw_deg_per_sqrt_h=0.15,
        bias_instability_deg_per_h=20.0,
        rrw_deg_per_h_per_sqrt_h=800.0,
        bias_instability_tau_range_s=(0.01, 1e5),
        turn_on_bias_deg_per_h=100.0,
        bias_deg_per_h=[10.0, -20.0, 30.0],
    )
    lsb = 2.7e-5  # rad, angle per count
    rng = np.random.default_rng(0)
    rate = apply_errors(np.zeros((t.size, 3)), t, spec, rng)
    rate += noise.quantisation_noise(rng, rate.shape, dt, lsb)

    n = 0.15 * DEG / 60  # rad/√s
    b = 20.0 * DEG / 3600  # rad/s
    k = 800.0 * DEG / 3600 / 60  # rad/s/√s
    q = lsb / np.sqrt(12)  # rad
    for axis in range(3):
        allan = allan_deviation(rate[:, axis], dt)
        fit = fit_allan(allan, terms=("quantisation", "arw", "bias_instability", "rrw"))  # no ramp here
        assert fit.arw.value == pytest.approx(n, rel=0.10)
        assert fit.bias_instability.value == pytest.approx(b, rel=0.10)
        assert fit.rrw.value == pytest.approx(k, rel=0.10)
        assert fit.quantisation.value == pytest.approx(q, rel=0.10)
        # The −1 slope of quantisation at the shortest τ (ARW's −½ takes over from 0.05 s).
        assert fit.allan.slope()[0] < -0.9
        assert fit.allan.tau[0] == pytest.approx(dt)
        for term in (fit.arw, fit.bias_instability, fit.rrw, fit.quantisation):
            assert term.low < term.value < term.high


def test_a_term_too_small_to_pin_is_reported_undetermined_not_nonsense():
    # White noise with a rate random walk 10⁴ times below where a 2000 s record could see it.
    rng = np.random.default_rng(11)
    dt, n = 0.1, 20000
    rate = 1e-3 / np.sqrt(dt) * rng.standard_normal(n) + np.cumsum(1e-12 * np.sqrt(dt) * rng.standard_normal(n))
    fit = fit_allan(allan_deviation(rate, dt))
    for name in ("quantisation", "arw", "bias_instability", "rrw", "rate_ramp"):
        c = getattr(fit, name)
        assert c.low <= c.value <= c.high, (name, c)


def test_a_constant_series_has_every_term_zero_and_a_curve_zero_in_places_is_refused():
    """A constant axis (a gyro saturated by a fast spin, a noiseless device) has σ(τ) = 0 at every τ: every
    term 0 with the interval [0, 0] (it was nonsense from weights of 0: 'array must not contain infs or
    NaNs'); σ(τ) 0 at some τ only fits no model, and is refused by name."""
    constant = allan_deviation(np.full(4096, 0.25), 0.01)
    for fit in (fit_allan(constant), fit_allan(constant, band_limit=True)):
        for name in TERMS:
            c = getattr(fit, name)
            assert (c.value, c.low, c.high) == (0.0, 0.0, 0.0), name
    noisy = allan_deviation(np.random.default_rng(0).normal(0.0, 1e-3, 4096), 0.01)
    holed = AllanDeviation(
        tau=noisy.tau, adev=np.where(np.arange(len(noisy.tau)) == 3, 0.0, noisy.adev), clusters=noisy.clusters,
        edf=noisy.edf, low=noisy.low, high=noisy.high, dt=noisy.dt,
    )  # fmt: skip
    with pytest.raises(ValueError, match=r"σ\(τ\) is 0 at τ = 0.08 s but not everywhere"):
        fit_allan(holed)
