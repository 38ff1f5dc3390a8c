"""Cubic splines through samples, compiled: scipy's arithmetic, bit for bit, without its temporaries.

:class:`HermiteCubic` is ``scipy.interpolate.CubicHermiteSpline(x, y, dydx)`` and its first derivative;
:func:`not_a_knot` is ``scipy.interpolate.CubicSpline(x, y)`` (its default, not-a-knot ends). Both give
the same bits as scipy (held by ``tests/dynamics/test_cubic.py`` on random grids, values and points):

* the cubic on interval ``i`` (``x_i ≤ t < x_{i+1}``, the last interval up to and including its end, and
  the end intervals beyond the ends) has scipy's local power-basis coefficients, from
  ``h = x_{i+1} − x_i``, the secant ``m = (y_{i+1} − y_i)/h`` and ``τ = (ẏ_i + ẏ_{i+1} − 2m)/h``::

      c₀ = τ/h,   c₁ = (m − ẏ_i)/h − τ,   c₂ = ẏ_i,   c₃ = y_i

  evaluated at ``s = t − x_i`` as scipy's ``PPoly`` sums them, ``((c₃ + c₂ s) + c₁ s²) + c₀ s³`` with
  ``s² = s·s`` and ``s³ = s²·s``; its derivative has the coefficients ``(3c₀, 2c₁, c₂)``;
* the not-a-knot slopes solve scipy's tridiagonal system (the continuity of the second derivative
  inside, the third's across the second and the last-but-one knots) by LAPACK's ``dgtsv`` (Gaussian
  elimination with partial pivoting), written out here in its order of operations.

What scipy spends on a block of 16 k samples and 3 axes (3.4 ms to build a ``CubicSpline``, most of it
the coefficient array's four copies and new memory) becomes one pass over the samples asked for:
the coefficients are formed per point from the samples, never stored.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .jit import njit

__all__ = ["HermiteCubic", "not_a_knot", "not_a_knot_slopes"]


class HermiteCubic:
    """The cubic Hermite spline through ``y`` with slopes ``dydx`` at the knots ``x``.

    Parameters
    ----------
    x : array_like (M,)
        Strictly increasing knots, M ≥ 2.
    y, dydx : array_like (M, D)
        Values and their derivatives at the knots.

    Calling it at ``t`` (N,) gives the (N, D) values, ``nu=1`` the first derivative; points beyond
    the ends extend the end cubics (scipy's ``extrapolate=True``); NaN gives NaN.
    """

    def __init__(self, x: ArrayLike, y: ArrayLike, dydx: ArrayLike) -> None:
        self.x = np.ascontiguousarray(x, dtype=float)
        self.y = np.ascontiguousarray(y, dtype=float)
        self.dydx = np.ascontiguousarray(dydx, dtype=float)
        if self.x.ndim != 1 or len(self.x) < 2 or self.y.shape != (len(self.x),) + self.y.shape[1:] or self.y.ndim != 2:
            raise ValueError(f"knots (M,) with M ≥ 2 and values (M, D) are needed, got {self.x.shape}, {self.y.shape}")
        if self.dydx.shape != self.y.shape:
            raise ValueError(f"slopes {self.dydx.shape} do not match values {self.y.shape}")

    def __call__(self, t: ArrayLike, nu: int = 0) -> NDArray[np.float64]:
        if nu not in (0, 1):
            raise ValueError(f"nu must be 0 or 1, got {nu!r}")
        points = np.ascontiguousarray(t, dtype=float).reshape(-1)
        out = np.empty((len(points), self.y.shape[1]))
        _hermite_evaluate(self.x, self.y, self.dydx, points, nu, out)
        return out

    def derivative(self) -> Callable[[ArrayLike], NDArray[np.float64]]:
        """The first derivative, as a callable of ``t``."""
        return lambda t: self(t, nu=1)


def not_a_knot_slopes(x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """The slopes (M, D) of ``scipy.interpolate.CubicSpline(x, y)`` at its knots ``x`` (M,), M ≥ 4."""
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    if len(x) < 4:
        raise ValueError(f"the not-a-knot system is tridiagonal from 4 knots on, got {len(x)}")
    slopes = np.empty(y.shape)
    _not_a_knot_slopes(x, y, slopes)
    return slopes


def not_a_knot(x: ArrayLike, y: ArrayLike) -> Callable[[ArrayLike], NDArray[np.float64]]:
    """``CubicSpline(x, y)`` as a callable of ``t``: a :class:`HermiteCubic` through the not-a-knot
    slopes from 4 knots on, scipy's own spline below (its special cases for 2 and 3 knots)."""
    x = np.ascontiguousarray(x, dtype=float)
    if len(x) < 4:
        from scipy.interpolate import CubicSpline

        spline: Callable[[ArrayLike], NDArray[np.float64]] = CubicSpline(x, y, axis=0)
        return spline
    return HermiteCubic(x, y, not_a_knot_slopes(x, y))


@njit
def _interval(x: NDArray[np.float64], value: float, hint: int) -> int:
    """scipy's ``find_interval`` with extrapolation: ``i`` with ``x_i ≤ value < x_{i+1}`` (``len(x) − 2``
    at and beyond the end, 0 before the start), −1 for NaN; ``hint`` the previous answer."""
    n = len(x)
    if not (x[0] <= value <= x[n - 1]):
        if value < x[0]:
            return 0
        if value > x[n - 1]:
            return n - 2
        return -1
    if value == x[n - 1]:
        return n - 2
    low, high = 0, n - 2
    if 0 <= hint <= n - 2:
        if value >= x[hint]:
            low = hint
            if value < x[hint + 1]:
                return hint
        else:
            high = hint
    while low < high:  # x[low] <= value < x[high + 1]
        mid = (low + high) // 2
        if value < x[mid]:
            high = mid - 1
        elif value >= x[mid + 1]:
            low = mid + 1
        else:
            return mid
    return low


@njit
def _hermite_evaluate(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    dydx: NDArray[np.float64],
    points: NDArray[np.float64],
    nu: int,
    out: NDArray[np.float64],
) -> None:
    """The Hermite cubics (``nu`` 0) or their derivatives (``nu`` 1) at ``points`` into ``out`` (N, D):
    the coefficients of CubicHermiteSpline.__init__ and the sum of PPoly's evaluate_poly1."""
    n_axes = y.shape[1]
    i = 0
    for j in range(len(points)):
        value = points[j]
        i = _interval(x, value, i)
        if i < 0:
            for a in range(n_axes):
                out[j, a] = np.nan
            i = 0
            continue
        s = value - x[i]
        h = x[i + 1] - x[i]
        for a in range(n_axes):
            slope = (y[i + 1, a] - y[i, a]) / h
            t = (dydx[i, a] + dydx[i + 1, a] - 2 * slope) / h
            c0 = t / h
            c1 = (slope - dydx[i, a]) / h - t
            c2 = dydx[i, a]
            # PPoly's sum from the constant term up, z the power of s (its prefactor 1.0 is exact)
            res = 0.0
            z = 1.0
            if nu == 0:
                res = res + y[i, a] * z
                z = z * s
                res = res + c2 * z
                z = z * s
                res = res + c1 * z
                z = z * s
                res = res + c0 * z
            else:  # PPoly.derivative(): coefficients times (3, 2, 1)
                res = res + c2 * 1.0 * z
                z = z * s
                res = res + c1 * 2.0 * z
                z = z * s
                res = res + c0 * 3.0 * z
            out[j, a] = res


@njit
def _not_a_knot_slopes(x: NDArray[np.float64], y: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """CubicSpline.__init__'s tridiagonal system (not-a-knot ends, M ≥ 4 knots) solved as LAPACK's
    dgtsv does for several right-hand sides, into ``out`` (M, D)."""
    m, n_axes = y.shape
    dx = np.empty(m - 1)
    for k in range(m - 1):
        dx[k] = x[k + 1] - x[k]
    # The bands: du (upper), d (diagonal), dl (lower), and the right-hand sides b.
    du = np.empty(m - 1)
    d = np.empty(m)
    dl = np.empty(m - 1)
    b = out
    for k in range(1, m - 1):
        d[k] = 2 * (dx[k - 1] + dx[k])
        du[k] = dx[k - 1]
        dl[k - 1] = dx[k]
        for a in range(n_axes):
            slope_lo = (y[k, a] - y[k - 1, a]) / dx[k - 1]
            slope_hi = (y[k + 1, a] - y[k, a]) / dx[k]
            b[k, a] = 3 * (dx[k] * slope_lo + dx[k - 1] * slope_hi)
    d[0] = dx[1]
    du[0] = x[2] - x[0]
    span = x[2] - x[0]
    for a in range(n_axes):
        s0 = (y[1, a] - y[0, a]) / dx[0]
        s1 = (y[2, a] - y[1, a]) / dx[1]
        b[0, a] = ((dx[0] + 2 * span) * dx[1] * s0 + dx[0] * dx[0] * s1) / span
    d[m - 1] = dx[m - 3]
    dl[m - 2] = x[m - 1] - x[m - 3]
    span = x[m - 1] - x[m - 3]
    for a in range(n_axes):
        s2 = (y[m - 2, a] - y[m - 3, a]) / dx[m - 3]
        s1 = (y[m - 1, a] - y[m - 2, a]) / dx[m - 2]
        b[m - 1, a] = (dx[m - 2] * dx[m - 2] * s2 + (2 * span + dx[m - 2]) * dx[m - 3] * s1) / span
    # dgtsv: elimination with partial pivoting (du2 the fill-in of an interchange) ...
    du2 = np.zeros(m - 2)
    for i in range(m - 2):
        if abs(d[i]) >= abs(dl[i]):
            fact = dl[i] / d[i]
            d[i + 1] = d[i + 1] - fact * du[i]
            for a in range(n_axes):
                b[i + 1, a] = b[i + 1, a] - fact * b[i, a]
            dl[i] = 0.0
        else:
            fact = d[i] / dl[i]
            d[i] = dl[i]
            temp = d[i + 1]
            d[i + 1] = du[i] - fact * temp
            dl[i] = du[i + 1]
            du[i + 1] = -fact * dl[i]
            du[i] = temp
            for a in range(n_axes):
                temp = b[i, a]
                b[i, a] = b[i + 1, a]
                b[i + 1, a] = temp - fact * b[i + 1, a]
        du2[i] = dl[i]
    i = m - 2
    if abs(d[i]) >= abs(dl[i]):
        fact = dl[i] / d[i]
        d[i + 1] = d[i + 1] - fact * du[i]
        for a in range(n_axes):
            b[i + 1, a] = b[i + 1, a] - fact * b[i, a]
    else:
        fact = d[i] / dl[i]
        d[i] = dl[i]
        temp = d[i + 1]
        d[i + 1] = du[i] - fact * temp
        du[i] = temp
        for a in range(n_axes):
            temp = b[i, a]
            b[i, a] = b[i + 1, a]
            b[i + 1, a] = temp - fact * b[i + 1, a]
    # ... and the back substitution with U (diagonal d, superdiagonals du and du2).
    for a in range(n_axes):
        b[m - 1, a] = b[m - 1, a] / d[m - 1]
        b[m - 2, a] = (b[m - 2, a] - du[m - 2] * b[m - 1, a]) / d[m - 2]
        for k in range(m - 3, -1, -1):
            b[k, a] = (b[k, a] - du[k] * b[k + 1, a] - du2[k] * b[k + 2, a]) / d[k]
