"""The cubic smoothing spline: Reinsch's solution against scipy's, the chosen λ against exact GCV, and the
closed-form noise gain of its derivatives against white noise."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import make_smoothing_spline

from gyroemu.dynamics.smoothing_spline import (
    choose_lambda,
    contiguous_runs,
    cutoff_hz,
    derivative_noise_std,
    lambda_for_cutoff,
    smoothing_spline,
    spline_gain,
)

EPS = np.finfo(float).eps


@pytest.mark.parametrize("lam", [0.0, 1e-8, 1e-5, 1e-2])
def test_same_spline_as_scipy(lam):
    rng = np.random.default_rng(3)
    n = 400
    t = np.cumsum(rng.uniform(0.5, 1.5, n)) / 100.0  # uneven stamps, about 100 Hz
    y = np.column_stack([np.sin(3 * t), np.cos(7 * t) + 0.01 * rng.standard_normal(n)])
    w = rng.uniform(0.5, 2.0, n)
    ours = smoothing_spline(t, y, lam, w)
    tt = np.linspace(t[0], t[-1], 3001)
    for j in range(2):
        ref = make_smoothing_spline(t, y[:, j], w=w, lam=lam)
        for nu in (0, 1, 2):
            scale = np.abs(ref(tt, nu)).max()
            # Both solve a banded system of condition ≲ 1e6 here: agreement to 1e6 ε of the magnitude.
            assert np.abs(ours(tt, nu)[:, j] - ref(tt, nu)).max() <= 1e6 * EPS * scale


def test_interpolates_at_lambda_zero_and_is_linear_in_y():
    rng = np.random.default_rng(4)
    t = np.sort(rng.uniform(0, 10, 50))
    y = rng.standard_normal((50, 2))
    s = smoothing_spline(t, y, 0.0)
    assert np.abs(s(t) - y).max() <= 1e3 * EPS * np.abs(y).max()
    assert np.abs(s(t[[0, -1]], 2)).max() <= 1e3 * EPS * np.abs(s(t, 2)).max()  # natural ends
    a, b = smoothing_spline(t, y[:, 0], 0.3), smoothing_spline(t, y[:, 1], 0.3)
    both = smoothing_spline(t, 2 * y[:, 0] - y[:, 1], 0.3)
    assert np.allclose(both(t), 2 * a(t) - b(t), rtol=0, atol=1e3 * EPS * np.abs(y).max())


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="strictly increasing"):
        smoothing_spline([0, 1, 1, 2], [0, 1, 2, 3], 1.0)
    with pytest.raises(ValueError, match="at least 3"):
        smoothing_spline([0, 1], [0, 1], 1.0)
    with pytest.raises(ValueError, match="≥ 0"):
        smoothing_spline([0, 1, 2], [0, 1, 2], -1.0)


def exact_gcv(t, y, lam):
    """GCV with the smoother matrix built column by column (n × n)."""
    n = len(t)
    s = smoothing_spline(t, np.eye(n), lam)(t)
    r = y - s @ y
    return n * np.sum(r**2) / (n - np.trace(s)) ** 2


@pytest.mark.parametrize("sigma", [1e-3, 1e-5])
def test_chosen_lambda_minimises_exact_gcv(sigma):
    rng = np.random.default_rng(1)
    n, h = 600, 1 / 120
    t = np.arange(n) * h
    y = np.sin(1.3 * t) + 0.3 * np.cos(4 * t) + sigma * rng.standard_normal(n)
    lam = choose_lambda(t, y)
    grid = np.logspace(np.log10(lam) - 3, np.log10(lam) + 3, 61)
    best = min(exact_gcv(t, y, g) for g in grid)
    # The spectral trace is within about one of the exact (module notes); with n − tr S ≳ 300 that
    # moves the score by ≲ 2/300: the chosen λ scores within 1 % of the exact minimum.
    assert exact_gcv(t, y, lam) <= best * 1.01


def test_gaps_split_runs():
    t = np.r_[np.arange(100), 150 + np.arange(50)] * 0.01
    runs = contiguous_runs(t)
    assert [(r.start, r.stop) for r in runs] == [(0, 100), (100, 150)]


@pytest.mark.parametrize("order", [0, 1, 2])
def test_noise_gain_of_derivatives(order):
    """The k-th derivative of the spline of white noise has the closed-form standard deviation."""
    rng = np.random.default_rng(10 + order)
    n, h, lam = 20000, 1 / 120, 2e-4
    t = np.arange(n) * h
    noise = rng.standard_normal((n, 4))
    inner = (t > 3) & (t < t[-1] - 3)
    d = smoothing_spline(t, noise, lam)(t[inner], order)
    measured = np.sqrt(np.mean(d**2))
    predicted = derivative_noise_std(lam, h, order)
    # The derivative is correlated over about 1/f_c: n_eff ≈ 4 columns × span × 2 f_c independent
    # values, and the relative standard error of an RMS is 1/sqrt(2 n_eff); 5 standard errors.
    n_eff = 4 * (t[inner][-1] - t[inner][0]) * 2 * cutoff_hz(lam, h)
    assert abs(measured / predicted - 1) <= 5 / np.sqrt(2 * n_eff)


def test_gain_and_cutoff():
    h, lam = 0.01, 1e-4
    fc = cutoff_hz(lam, h)
    assert spline_gain(lam, h, 2 * np.pi * fc) == pytest.approx(0.5, abs=1e-9)
    assert fc == pytest.approx((lam * h) ** -0.25 / (2 * np.pi), rel=0.02)  # μ ≈ ω⁴ h well below Nyquist
    assert spline_gain(lam, h, 0.0) == 1.0
    assert cutoff_hz(0.0, h) == pytest.approx(50.0)


@pytest.mark.parametrize("f_hz", [0.3, 5.0, 40.0])
def test_lambda_for_cutoff_inverts_cutoff(f_hz):
    h = 1 / 120
    lam = lambda_for_cutoff(f_hz, h)
    assert cutoff_hz(lam, h) == pytest.approx(f_hz, rel=1e-9)
    assert spline_gain(lam, h, 2 * np.pi * f_hz) == pytest.approx(0.5, rel=1e-12)
    with pytest.raises(ValueError, match="Nyquist"):
        lambda_for_cutoff(60.0, h)
