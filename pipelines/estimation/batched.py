"""The MEKF over many runs at once: Monte Carlo in one compiled call, runs spread over the cores.

The per-sample strapdown and the measurement models are the very functions :class:`~.mekf.Mekf`
calls (:mod:`.mekf_kernels`); only the Kalman algebra, which ``Mekf`` takes from filterpy, is written
here (:func:`kalman_predict`, :func:`kalman_update`: the same equations, Joseph form), so that a whole
run stays in compiled code. ``tests/pipelines/test_mekf.py`` checks that both give the same attitude.

numba's on-disk cache is keyed on this file's content only: a change to :mod:`.mekf_kernels` reaches
the cached ``_run`` only when this file changes too (kernel layout as of ``P_SIZE = 35``, ``X_SIZE = 17``,
``S_SIZE = 110``, ``P_BIAS_RW_VERTICAL`` the last; the gravity update ``mekf_kernels.gravity_update`` after
``mekf_kernels.gravity_adapt``, no gate;
``mekf_kernels.body_vertical`` shared by the transition and the heading gain; ``P_ACC_GM_PROCESS``).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.jit import njit

from . import mekf_kernels as kern
from .latency import attitude_at_stamps, field_at_gyro_instant
from .mekf import MekfParams, earth_rate_enu, initial_state
from .protocol import Estimate, FilterSetup

__all__ = ["mekf_batch"]


@njit
def kalman_predict(P: NDArray[np.float64], F: NDArray[np.float64], Q: NDArray[np.float64]) -> None:
    """P ← F P Fᵀ + Q (the error state is zero between windows, so x stays zero)."""
    P[:, :] = F @ P @ F.T + Q


@njit
def kalman_update(
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    z: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
) -> None:
    """y = z − H x, S = H P Hᵀ + R, K = P Hᵀ S⁻¹, x ← x + K y, P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ."""
    PHT = P @ H.T
    S = H @ PHT + R
    K = PHT @ np.linalg.inv(S)
    x += K @ (z - H @ x)
    A = np.eye(len(x)) - K @ H
    P[:, :] = A @ P @ A.T + K @ R @ K.T


@njit
def _window(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
    P: NDArray[np.float64],
    x: NDArray[np.float64],
    earth: NDArray[np.float64],
    params: NDArray[np.float64],
    use_mag: bool,
) -> None:
    """One window's prediction and updates, then the injection: :meth:`Mekf._window`, compiled."""
    F = np.empty((kern.X_SIZE, kern.X_SIZE))
    Q = np.empty((kern.X_SIZE, kern.X_SIZE))
    kern.transition(win, phi, q, earth, params, F, Q)
    kalman_predict(P, F, Q)
    z, H, R = np.empty(2), np.empty((2, kern.X_SIZE)), np.empty((2, 2))
    if kern.gravity_measurement(win, slow, params, z, H, R):
        kern.gravity_adapt(P, z, H, R, slow, params)
        kern.gravity_update(x, P, z, H, R)
    if kern.rest_due(win, slow, params):
        z3, H3, R3 = np.empty(3), np.empty((3, kern.X_SIZE)), np.empty((3, 3))
        kern.rest_measurement(win, q, b, earth, params, z3, H3, R3, P)
        if kern.rest_gate(win, slow, params):
            kalman_update(x, P, z3, H3, R3)
    if use_mag:
        kern.heading_update(x, P, q, win, slow, params)
    kern.inject(x, q, b, slow, win, phi)


@njit(parallel=True)
def _run(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    P: NDArray[np.float64],
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    delta: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64],
    earth: NDArray[np.float64],
    params: NDArray[np.float64],
    use_mag: bool,
    q_out: NDArray[np.float64],
    b_out: NDArray[np.float64],
) -> None:
    runs, n = gyro.shape[0], len(t)
    for r in numba.prange(runs):
        win = np.zeros(kern.W_SIZE)
        phi = np.zeros((3, kern.N_DRIFT))
        x = np.zeros(kern.X_SIZE)
        k = 0
        d = delta[r] if delta.shape[0] > 0 else delta[0:0, 0]
        while k < n:
            end = kern.strapdown(
                q[r], b[r], slow[r], win, phi, t, gyro[r], d, accel[r], mag[r], earth, params, k, q_out[r]
            )
            for j in range(k, end):
                b_out[r, j, :] = b[r]
            if kern.window_due(win, params):
                _window(q[r], b[r], slow[r], win, phi, P[r], x, earth, params, use_mag)
                q_out[r, end - 1, :] = q[r]
                b_out[r, end - 1, :] = b[r]
            k = end


def mekf_batch(
    setup: FilterSetup,
    t: ArrayLike,
    gyro: ArrayLike | None,
    accel: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    delta_angle: ArrayLike | None = None,
    params: MekfParams | None = None,
) -> Estimate:
    """Run the MEKF over R runs that share their stamps.

    Parameters
    ----------
    setup : FilterSetup
    t : ndarray (N,)
        Stamps, s, common to every run.
    gyro, accel : ndarray (R, N, 3)
        rad/s and m/s²; ``mag`` (R, N, 3) T or None.
    delta_angle : ndarray (R, N, 3), optional
        Angle increments, rad, instead of ``gyro``.
    params : MekfParams, optional
        Default: :meth:`MekfParams.for_setup`.

    Returns
    -------
    Estimate
        ``q_wb`` (R, N, 4), ``gyro_bias`` (R, N, 3); no covariance.
    """
    params = params if params is not None else MekfParams.for_setup(setup)
    t = np.ascontiguousarray(t, dtype=float)
    accel = np.ascontiguousarray(accel, dtype=float)
    if delta_angle is not None:
        delta = np.ascontiguousarray(delta_angle, dtype=float)
        gyro = delta / np.diff(t, prepend=t[0] - 1.0 / setup.rate_hz)[None, :, None]
    else:
        gyro = np.ascontiguousarray(gyro, dtype=float)
        delta = np.empty((0, len(t), 3))
    runs, n = gyro.shape[:2]
    if gyro.shape != (runs, len(t), 3) or accel.shape != gyro.shape:
        raise ValueError(f"gyro and accel must have shape (runs, {len(t)}, 3), got {gyro.shape} and {accel.shape}")
    if n > 1 and not np.all(np.diff(t) > 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1
        raise ValueError(f"sample {bad}: stamp {t[bad]!r} s does not increase")
    use_mag = bool(setup.use_mag and mag is not None)
    mag = np.ascontiguousarray(mag, dtype=float) if use_mag else np.full((runs, n, 3), np.nan)
    if use_mag:  # timed as make_filter's LatencyCompensated times every filter
        mag = np.ascontiguousarray(field_at_gyro_instant(mag, gyro, setup.gyro_latency_s, setup.mag_latency_s))
    q = np.empty((runs, 4))
    b = np.empty((runs, 3))
    slow = np.empty((runs, kern.S_SIZE))
    P = np.empty((runs, kern.X_SIZE, kern.X_SIZE))
    for r in range(runs):
        init = initial_state(t, gyro[r], accel[r], mag[r] if use_mag else None, setup, params)
        q[r], b[r], slow[r], P[r] = init.q, init.b, init.slow, init.P
    q_out = np.empty((runs, n, 4))
    b_out = np.empty((runs, n, 3))
    _run(q, b, slow, P, t, gyro, delta, accel, mag, earth_rate_enu(setup), params.vector(setup), use_mag, q_out, b_out)
    return Estimate(q_wb=attitude_at_stamps(q_out, gyro, b_out, setup.gyro_latency_s), gyro_bias=b_out)
