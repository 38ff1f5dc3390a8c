"""The compiled cubic splines give scipy's bits (``gyroemu.dynamics.cubic``).

Bit for bit, not within a tolerance: the module replicates scipy's order of operations (the
coefficients of ``CubicHermiteSpline``, the sum of ``PPoly``'s evaluation, LAPACK's ``dgtsv`` for the
not-a-knot slopes), so any difference is a wrong line. Grids are uniform (as a truth window's) and
random (so that ``dgtsv`` pivots), values of several magnitudes, points inside, on the knots, at the
ends and beyond them.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline, CubicSpline

from gyroemu.dynamics.cubic import HermiteCubic, not_a_knot, not_a_knot_slopes


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _case(seed: int, uniform: bool):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(4, 300))
    if uniform:
        x = 3.7 + np.arange(m) * 10.0 ** rng.uniform(-4, 0)
    else:
        x = np.cumsum(rng.uniform(0.01, 2.0, m) * rng.choice([1e-3, 1.0], m)) - 5.0
    scale = 10.0 ** rng.uniform(-6, 4)
    y = scale * rng.standard_normal((m, int(rng.integers(1, 5))))
    dydx = scale * rng.standard_normal(y.shape)
    lo, hi = x[0], x[-1]
    t = np.concatenate(
        [
            rng.uniform(lo, hi, 500),
            x,  # the knots themselves
            [lo, hi, lo - 0.3 * (hi - lo), hi + 0.2 * (hi - lo), np.nextafter(hi, lo)],
            np.sort(rng.uniform(lo, hi, 200)),  # ascending, as a block's instants
        ]
    )
    return x, y, dydx, t


@pytest.mark.parametrize("uniform", [True, False])
@pytest.mark.parametrize("seed", range(25))
def test_hermite_cubic_and_its_derivative_are_scipys_bits(seed, uniform):
    x, y, dydx, t = _case(seed, uniform)
    ours, theirs = HermiteCubic(x, y, dydx), CubicHermiteSpline(x, y, dydx, axis=0)
    assert _same_bits(ours(t), theirs(t))
    assert _same_bits(ours.derivative()(t), theirs.derivative()(t))


@pytest.mark.parametrize("uniform", [True, False])
@pytest.mark.parametrize("seed", range(25))
def test_not_a_knot_spline_is_scipys_cubic_spline_bits(seed, uniform):
    x, y, _, t = _case(seed, uniform)
    theirs = CubicSpline(x, y, axis=0)
    # scipy's own slopes at the knots: c[2] of each interval, and the last knot's from its derivative
    slopes = np.vstack([theirs.c[2], theirs(x[-1:], 1)])
    assert _same_bits(not_a_knot_slopes(x, y)[:-1], slopes[:-1])
    assert _same_bits(not_a_knot(x, y)(t), theirs(t))


def test_nan_points_give_nan_and_short_grids_use_scipys_special_cases():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    y = np.arange(10.0).reshape(5, 2) ** 2
    out = HermiteCubic(x, y, y)(np.array([0.5, np.nan, 2.5]))
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()
    for m in (2, 3):
        t = np.linspace(-0.5, m - 0.5, 17)
        assert _same_bits(not_a_knot(x[:m], y[:m])(t), CubicSpline(x[:m], y[:m], axis=0)(t))


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="knots"):
        HermiteCubic([0.0], [[1.0]], [[1.0]])
    with pytest.raises(ValueError, match="slopes"):
        HermiteCubic([0.0, 1.0], [[1.0], [2.0]], [[1.0]])
    with pytest.raises(ValueError, match="nu"):
        HermiteCubic([0.0, 1.0], [[1.0], [2.0]], [[1.0], [1.0]])([0.5], nu=2)
    with pytest.raises(ValueError, match="4 knots"):
        not_a_knot_slopes([0.0, 1.0, 2.0], [[0.0], [1.0], [2.0]])
