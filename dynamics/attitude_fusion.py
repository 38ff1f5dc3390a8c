"""A recorded attitude refined by a gyro that sensed the same motion: the reference below a crossover
frequency, the integrated body rate above it.

An optical reference is accurate at low frequencies and noisy at high ones (on BROAD, its rate above
5 Hz differs from the gyro's by 4.6 °/s RMS in 5–15 Hz and exceeds it threefold above 15 Hz, where the
gyro sees 2.2 °/s of motion); a gyro is the reverse (its bias makes the integrated angle drift). The
complementary estimate keeps each where it is good. With ``q_g`` the body rate integrated from the
reference's first valid attitude (midpoint rule per step, ``q_{k+1} = q_k ⊗ exp((ω_k + ω_{k+1}) Δt_k / 4)``
as a quaternion, i.e. the rotation vector ``(ω_k + ω_{k+1}) Δt_k / 2``), the difference in world axes

    δ(t) = log(q_g ⊗ q_ref⁻¹)

is what the gyro's drift and the reference's noise make of the same motion. A gyro's bias or scale error
integrates into δ slowly (in world axes, the integral of a bounded rate), the reference's noise enters
it fast; so δ is low-passed (zero-phase, second-order Butterworth forwards and backwards, at the
crossover) and taken back out of the integrated attitude:

    q = exp(−δ_lp) ⊗ q_g

Below the crossover ``q`` follows the reference, above it the gyro. Points without a reference are
bridged by linear interpolation of δ.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .jit import njit
from .rotation import quat_conjugate, quat_from_rotvec, quat_multiply, quat_to_rotvec, rotate_body

__all__ = ["complementary_attitude"]


def complementary_attitude(
    t: ArrayLike, q_ref: ArrayLike, omega_b: ArrayLike, crossover_hz: float
) -> NDArray[np.float64]:
    """The reference attitude below ``crossover_hz`` and the integrated body rate above it.

    Parameters
    ----------
    t : array_like (N,)
        Uniform sample instants, s.
    q_ref : array_like (N, 4)
        Reference attitude (w, x, y, z), body to world; NaN rows where it is missing.
    omega_b : array_like (N, 3)
        Body angular velocity at the same instants (the gyro's, aligned in time and turned into body
        axes by the caller), rad/s.
    crossover_hz : float
        Where the two meet (the low-pass's −3 dB point), Hz; below half the sample rate.

    Returns
    -------
    ndarray (N, 4)
        Unit quaternions; from the first reference sample on (rows before it are NaN).
    """
    from scipy.signal import butter, filtfilt  # scipy where used: the CLI's listings skip it

    t = np.asarray(t, dtype=float)
    q_ref = np.asarray(q_ref, dtype=float)
    omega = np.ascontiguousarray(omega_b, dtype=float)
    n = len(t)
    if q_ref.shape != (n, 4) or omega.shape != (n, 3):
        raise ValueError(
            f"t (N,), q_ref (N, 4) and omega_b (N, 3) are needed, got {t.shape}, {q_ref.shape}, {omega.shape}"
        )
    valid = np.isfinite(q_ref).all(axis=1)
    if valid.sum() < 2:
        raise ValueError("the reference needs at least two valid samples")
    step = float(np.median(np.diff(t)))
    if not 0.0 < crossover_hz < 0.5 / step:
        raise ValueError(
            f"crossover_hz must lie between 0 and half the sample rate ({0.5 / step:g} Hz), got {crossover_hz}"
        )
    first = int(np.flatnonzero(valid)[0])
    q = np.full((n, 4), np.nan)
    q[first] = q_ref[first] / np.linalg.norm(q_ref[first])
    _integrate(t, omega, first, q)
    delta = np.full((n, 3), np.nan)
    reference = q_ref[valid] / np.linalg.norm(q_ref[valid], axis=1, keepdims=True)
    delta[valid] = quat_to_rotvec(quat_multiply(q[valid], quat_conjugate(reference)))  # δ = log(q_g ⊗ q_ref⁻¹)
    rows = np.arange(first, n)
    known = valid[first:]
    for axis in range(3):  # bridge the reference's gaps (and its end) linearly in δ
        delta[first:, axis] = np.interp(rows, rows[known], delta[first:, axis][known])
    b, a = butter(2, crossover_hz * 2.0 * step)
    slow = filtfilt(b, a, delta[first:], axis=0)
    q[first:] = quat_multiply(quat_from_rotvec(-slow), q[first:])  # q = exp(−δ_lp) ⊗ q_g
    return q


@njit
def _integrate(t: NDArray[np.float64], omega: NDArray[np.float64], first: int, q: NDArray[np.float64]) -> None:
    """q_{k+1} = q_k ⊗ exp(φ_k / 2) with φ_k = (ω_k + ω_{k+1}) (t_{k+1} − t_k) / 2, from row ``first``."""
    for k in range(first, len(t) - 1):
        h = t[k + 1] - t[k]
        q[k + 1, :] = q[k, :]
        rotate_body(
            q[k + 1],
            0.5 * (omega[k, 0] + omega[k + 1, 0]) * h,
            0.5 * (omega[k, 1] + omega[k + 1, 1]) * h,
            0.5 * (omega[k, 2] + omega[k + 1, 2]) * h,
        )
