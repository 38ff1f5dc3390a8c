"""How much later than the gyro the magnetometer measures, read from the log itself: no truth needed.

A field sample read ``Δ = L_m − L_g`` before the gyro's instant (:mod:`.latency`) is in the body's axes
of then, so turned into the world with the attitude the gyro integrated to it, it swings with the body's
rate: ``R_k m_k`` is off the world field by about ``Δ R_k (ω_k × m_k)``. Turned back by the right Δ the
field is the same everywhere the body turns (within the field's own variation along the path). Over
windows of ``window_s`` short enough for the world field to stay put and the raw gyro's drift to stay
small, with ``R_k`` a strapdown of the raw rates and each window's mean taken off (the world field, a
nuisance per window), Δ is the least-squares fit of

    ỹ_k(Δ) = [R_k exp(−ω_k Δ) m_k]~ ,   ỹ_k(Δ + δ) ≈ ỹ_k(Δ) − δ J̃_k ,   J_k = R_k (ω_k × exp(−ω_k Δ) m_k)

(``~``: less the window's mean), solved by Gauss–Newton, ``δ = Σ ỹ·J̃ / Σ |J̃|²``, three steps from 0. The
residuals are not white (the field varies along the path, the strapdown drifts), so the standard error
is the delete-one-group jackknife over ``groups`` contiguous stretches of the log (Efron & Tibshirani,
*An Introduction to the Bootstrap*, §11.2), which holds for residuals correlated within a stretch.

What this cannot see: a field that turns with the body (a magnet fixed to the sensor, hard iron not
calibrated out) is not the same everywhere the body turns at any Δ; there the fit is poor and its
error large, and :func:`estimate_field_lag` says the lag is not observable. So does a log whose body
hardly turns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyroemu.dynamics.rotation import quat_from_rotvec, quat_rotate

from .mekf_kernels import rotations_since_first

__all__ = ["FieldLag", "estimate_field_lag"]


@dataclass(frozen=True)
class FieldLag:
    """The magnetometer's lag behind the gyro read from a log (:func:`estimate_field_lag`).

    Attributes
    ----------
    lag_s : float
        ``Δ = L_m − L_g``, s: how much earlier than the gyro's instant each field sample was read.
    standard_error_s : float
        Its jackknife standard error, s (inf when it cannot be formed).
    observable : bool
        The fit is usable: its standard error at most ``max_standard_error_s`` and Δ within
        ``±max_lag_s`` (:func:`estimate_field_lag`).
    windows : int
        Windows in which the body turned and the field was read.
    """

    lag_s: float
    standard_error_s: float
    observable: bool
    windows: int

    def describe(self) -> str:
        """One line for a report: the lag and its error, ms, and whether it is used."""
        fit = f"{self.lag_s * 1e3:.2f} ± {self.standard_error_s * 1e3:.2f} ms over {self.windows} windows"
        if self.observable:
            return f"the field lags the gyro by {fit}, read from the log: each field sample turned back by it"
        return (
            f"the field's lag behind the gyro cannot be read from the log ({fit}: a field that turns with the "
            "body, or too little turning): not applied"
        )


def estimate_field_lag(
    t: np.ndarray,
    gyro: np.ndarray,
    mag: np.ndarray,
    *,
    window_s: float = 2.0,
    groups: int = 8,
    min_rate: float = 0.2,
    max_lag_s: float = 0.1,
    max_standard_error_s: float = 0.002,
) -> FieldLag:
    """Fit the magnetometer's lag behind the gyro, ``Δ = L_m − L_g`` (see the module's notes).

    Parameters
    ----------
    t : ndarray (N,)
        Sample times, s, increasing.
    gyro : ndarray (N, 3)
        Rates, rad/s, body axes (raw: a bias adds a slow drift within a window, which the fit tolerates).
    mag : ndarray (N, 3)
        Field, any unit, body axes; rows without a field sample are NaN.
    window_s : float
        Length of the windows whose mean field is taken off, s.
    groups : int
        Contiguous stretches of windows for the jackknife (at least 2).
    min_rate : float
        Samples turning slower than this, rad/s, carry too little of Δ and are left out.
    max_lag_s, max_standard_error_s : float
        The fit is observable when ``|Δ| ≤ max_lag_s`` and its standard error ``≤ max_standard_error_s``.

    Returns
    -------
    FieldLag
    """
    t = np.asarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    mag = np.asarray(mag, dtype=float)
    # the raw rates' strapdown, the initial state's (sample k's axes to sample 0's; a fixed turn of the
    # frame leaves the fit as it is)
    to_first = rotations_since_first(t, np.ascontiguousarray(gyro))
    usable = np.isfinite(mag).all(axis=1) & np.isfinite(gyro).all(axis=1)
    usable &= np.linalg.norm(np.where(np.isfinite(gyro), gyro, 0.0), axis=1) >= min_rate
    index = np.flatnonzero(usable)
    window = np.floor((t[index] - t[0]) / window_s).astype(np.int64)
    _, inverse, sizes = np.unique(window, return_inverse=True, return_counts=True)
    index, window = index[sizes[inverse] >= 2], window[sizes[inverse] >= 2]  # one sample has no spread
    if len(index) == 0:
        return FieldLag(0.0, float("inf"), False, 0)
    windows, window = np.unique(window, return_inverse=True)
    count = np.bincount(window).astype(float)
    r, w, m = to_first[index], gyro[index], mag[index]

    def centred(v: np.ndarray) -> np.ndarray:
        means = np.stack([np.bincount(window, v[:, i]) for i in range(3)], axis=1) / count[:, None]
        deviation: np.ndarray = v - means[window]
        return deviation

    stretches = max(groups, 2)
    group = np.minimum(window * stretches // len(windows), stretches - 1)
    lag = 0.0
    for _ in range(3):
        turned = quat_rotate(quat_from_rotvec(-w * lag), m)
        y = centred(np.einsum("kij,kj->ki", r, turned))
        jac = centred(np.einsum("kij,kj->ki", r, np.cross(w, turned)))
        num = np.bincount(group, np.einsum("ij,ij->i", y, jac), minlength=stretches)
        den = np.bincount(group, np.einsum("ij,ij->i", jac, jac), minlength=stretches)
        if not den.sum() > 0.0:
            return FieldLag(0.0, float("inf"), False, len(windows))
        lag += num.sum() / den.sum()
    # the jackknife of the last step's ratio (the earlier steps only moved the point it is taken at), over
    # the stretches that hold a window; fewer than three leave no error to speak of
    num, den = num[den > 0.0], den[den > 0.0]
    k = len(num)
    error = float("inf")
    if k >= 3:
        left_out = (num.sum() - num) / (den.sum() - den)
        error = float(np.sqrt((k - 1) / k * np.sum((left_out - np.mean(left_out)) ** 2)))
    observable = abs(lag) <= max_lag_s and error <= max_standard_error_s
    return FieldLag(float(lag), error, bool(observable), len(windows))
