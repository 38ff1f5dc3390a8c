"""Each sensor's time offset against the truth, by least squares over trial delays.

For a trial delay d, the truth is read at t − d and the sensor's output regressed on a model linear in
its parameters (with an intercept, the bias):

    gyro           ω_m(t) = M ω(t − d) + b                       ω from the differentiated truth
    accelerometer  f_m(t) = A R_bw(t − d) (a_w(t − d) + g e_z) + b   (a_w = 0 without a position track)
    magnetometer   m_m(t) = W vec R_bw(t − d) + h                  (W absorbs soft iron, mounting and m_w)

Both sides are averaged over ``smooth_s`` first (the same linear filter on both keeps the model
exact and tames the noise of a differentiated optical track), and only every window-th row is kept
so the residuals are nearly independent. The residual sum of squares S(d) is evaluated on the truth's
sample grid (steps of Δt) over the rows valid at every trial delay, then on steps h = Δt/8 around its
minimum (the truth interpolated linearly), and the minimum is refined by a parabola through the best
point and its neighbours:

    d* = d₀ + h (S₋ − S₊) / (2 (S₋ − 2S₀ + S₊))

Near the minimum S(d) ≈ S₀ + a (d − d*)², and the least-squares standard uncertainty of d is
s / √a with s² = S₀ / (rows − parameters): formal, assuming white residuals (coloured residuals
make it optimistic). Positive d: the sensor lags the truth (its sample stamped t measures t − d).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from .truth import interpolate_attitude, interpolate_vectors, moving_average, rotation_bw, truth_angular_velocity

__all__ = ["LatencyEstimate", "estimate_latency", "gyro_latency", "accel_latency", "mag_latency"]


@dataclass(frozen=True)
class LatencyEstimate:
    """A sensor's latency against the truth.

    Attributes
    ----------
    latency_s : delay d*, s (positive: the sensor lags the truth).
    sigma_s : formal standard uncertainty, s.
    delays_s, cost : (K,) the trial delays and S(d) / S₀ there.
    rows : independent rows used.
    at_edge : the minimum lies at the edge of the search (widen it: the estimate is a bound).
    """

    latency_s: float
    sigma_s: float
    delays_s: NDArray[np.float64]
    cost: NDArray[np.float64]
    rows: int
    at_edge: bool


def estimate_latency(
    t: NDArray[np.float64],
    y: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    features: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    *,
    search_s: float = 0.06,
    smooth_s: float = 0.05,
    mask: NDArray[np.bool_] | None = None,
) -> LatencyEstimate:
    """Latency of the output ``y`` (N, k) stamped ``t`` (N,) s against a truth sampled at ``truth_t``.

    ``features(times)`` gives the model's regressors (M, p) of the truth at ``times`` (NaN where
    unknown); an intercept is added. Trial delays run over ±``search_s`` in steps of the truth's
    sample interval, then over an eighth of it around the best. ``mask`` (N,) bool selects the samples
    that may be used.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    step = float(np.median(np.diff(truth_t)))
    dt = float(np.median(np.diff(t)))
    length = max(1, int(round(smooth_s / dt)))
    # float64, which numpy's stubs type as floating[Any] (a float times an int array)
    delays = cast(
        "NDArray[np.float64]", step * np.arange(-int(np.ceil(search_s / step)), int(np.ceil(search_s / step)) + 1)
    )
    ys = moving_average(y, length)
    if mask is not None:
        ys[~np.asarray(mask, dtype=bool)] = np.nan
    rows = np.arange(length // 2, len(t), length)
    ys = ys[rows]
    # Rows valid at every delay, the extremes of the search included (the truth's NaN rows move with d).
    ok = np.all(np.isfinite(ys), axis=1)
    for d in (delays[0], 0.0, delays[-1]):
        ok &= np.all(np.isfinite(moving_average(features(t - d), length)[rows]), axis=1)
    n = int(ok.sum())
    p = len(features(t[:2])[0]) + 1
    if n <= 2 * p:
        raise ValueError(f"only {n} rows valid at every trial delay: too little overlap with the truth")

    def cost_at(d: float) -> float:
        f = moving_average(features(t - d), length)[rows][ok]
        if not np.all(np.isfinite(f)):
            return float("inf")
        x = np.column_stack([f, np.ones(n)])
        coef, *_ = np.linalg.lstsq(x, ys[ok], rcond=None)
        return float(np.sum((ys[ok] - x @ coef) ** 2))

    cost = np.array([cost_at(d) for d in delays])
    j = int(np.argmin(cost))
    if j == 0 or j == len(delays) - 1:
        return LatencyEstimate(float(delays[j]), float("inf"), delays, cost / cost[j], n, True)
    # Refine on a grid of an eighth of a step around the coarse minimum (the parabola through three
    # points a whole step apart is biased by the cost's departure from a quadratic), then the parabola.
    h = step / 8
    fine = delays[j] + h * np.arange(-8, 9)
    fine_cost = np.array([cost_at(d) for d in fine])
    i = int(np.clip(np.argmin(fine_cost), 1, len(fine) - 2))
    s_minus, s0, s_plus = fine_cost[i - 1], fine_cost[i], fine_cost[i + 1]
    curvature = s_minus - 2 * s0 + s_plus  # = 2 a h²
    shift = 0.5 * (s_minus - s_plus) / curvature if curvature > 0 else 0.0
    a = curvature / (2 * h**2)
    s2 = s0 / (n * y.shape[1] - p * y.shape[1])
    sigma = float(np.sqrt(s2 / a)) if a > 0 else float("inf")
    all_d = np.concatenate([delays, fine])
    order = np.argsort(all_d)
    all_cost = np.concatenate([cost, fine_cost])[order]
    return LatencyEstimate(float(fine[i] + shift * h), sigma, all_d[order], all_cost / s0, n, False)


def gyro_latency(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    **kwargs: Any,
) -> LatencyEstimate:
    """Latency of a gyro ``gyro`` (N, 3) rad/s against the truth attitude ``q_wb`` (M, 4) at ``truth_t``."""
    omega = truth_angular_velocity(truth_t, q_wb)
    return estimate_latency(t, gyro, truth_t, lambda times: interpolate_vectors(truth_t, omega, times), **kwargs)


def accel_latency(
    t: NDArray[np.float64],
    accel: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    pos_w: NDArray[np.float64] | None = None,
    gravity_m_s2: float = 9.81,
    **kwargs: Any,
) -> LatencyEstimate:
    """Latency of an accelerometer ``accel`` (N, 3) m/s² against the truth attitude (and position
    ``pos_w`` (M, 3) m, when known: its second difference gives a_w)."""
    from .calibration import truth_specific_force_world

    force_w = truth_specific_force_world(truth_t, pos_w, gravity_m_s2)

    def features(times: NDArray[np.float64]) -> NDArray[np.float64]:
        r_bw = rotation_bw(interpolate_attitude(truth_t, q_wb, times))
        force_b: NDArray[np.float64] = np.einsum("nij,nj->ni", r_bw, interpolate_vectors(truth_t, force_w, times))
        return force_b

    return estimate_latency(t, accel, truth_t, features, **kwargs)


def mag_latency(
    t: NDArray[np.float64],
    mag: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    **kwargs: Any,
) -> LatencyEstimate:
    """Latency of a magnetometer ``mag`` (N, 3) against the truth attitude (field assumed uniform)."""

    def features(times: NDArray[np.float64]) -> NDArray[np.float64]:
        return rotation_bw(interpolate_attitude(truth_t, q_wb, times)).reshape(len(times), 9)

    return estimate_latency(t, mag, truth_t, features, **kwargs)
