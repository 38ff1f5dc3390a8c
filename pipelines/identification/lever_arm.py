"""Where the accelerometer sits relative to the truth's reference point: its lever arm.

A truth track (an optical marker body) gives the position and attitude of its own origin; an
accelerometer a distance r from it senses, besides that origin's specific force, the rigid body's
tangential and centripetal accelerations (sensor axes; Titterton and Weston, *Strapdown Inertial
Navigation Technology*, 2nd ed., 2004, §10.5.2):

    f_m = C R_bw (a_w + g e_z) + α × r + ω × (ω × r) + b

so the residual d = f_m − C R_bw (a_w + g e_z) is linear in r (and the bias b):
d = ([α×] + [ω×]²) r + b. ω is the gyro's (less its fitted bias: the differentiated optical attitude
is too noisy at the sample rate), α its time derivative. Both sides are averaged over non-overlapping
windows of ``window_s`` (the centripetal term is quadratic in ω: the window mean of [ω×]² is taken of
the products, not of ω), over the movement, and r and b come by least squares over the stacked axes
(:func:`gyroemu.pipelines.identification.lsq.linear_fit`). Its formal uncertainty is optimistic
(window residuals correlated by the motion); pooled over recordings, the scatter between them widens
it (:func:`gyroemu.pipelines.identification.pool_estimates`). The lever arm is returned in the
body's axes (r_b = Cᵀ r), as ``[mounting] lever_arm_m`` takes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .calibration import truth_specific_force_body, window_means
from .lsq import linear_fit

__all__ = ["LeverArmFit", "fit_lever_arm"]


@dataclass(frozen=True)
class LeverArmFit:
    """A fitted lever arm.

    Attributes
    ----------
    lever_arm_b, lever_arm_sigma : (3,) m, body axes, and the standard uncertainty.
    bias : (3,) m/s², the residual's constant (sensor axes).
    windows : windows used. residual_rms : (3,) m/s² after the fit; rms_before : (3,) before.
    """

    lever_arm_b: NDArray[np.float64]
    lever_arm_sigma: NDArray[np.float64]
    bias: NDArray[np.float64]
    windows: int
    residual_rms: NDArray[np.float64]
    rms_before: NDArray[np.float64]


def _skew(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 3, 3) [v×] of ``v`` (N, 3)."""
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], 1)


def fit_lever_arm(
    t: NDArray[np.float64],
    accel: NDArray[np.float64],
    gyro: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    pos_w: NDArray[np.float64],
    latency_s: float,
    mask: NDArray[np.bool_],
    *,
    gyro_bias: NDArray[np.float64] | None = None,
    c_sb: NDArray[np.float64] | None = None,
    gravity_m_s2: float = 9.81,
    window_s: float = 0.1,
    min_windows: int = 50,
) -> LeverArmFit:
    """The lever arm of the module notes. ``accel`` (N, 3) m/s² and ``gyro`` (N, 3) rad/s at ``t`` (N,) s;
    truth ``q_wb`` (M, 4) and ``pos_w`` (M, 3) m at ``truth_t``; ``latency_s`` the accelerometer's;
    ``mask`` (N,) bool, the samples to use (the movement); ``gyro_bias`` (3,) rad/s; ``c_sb`` (3, 3)
    body → sensor. Raises ``ValueError`` with fewer than ``min_windows`` usable windows."""
    t = np.asarray(t, dtype=float)
    c = np.eye(3) if c_sb is None else np.asarray(c_sb, dtype=float)
    force_b = truth_specific_force_body(t, truth_t, q_wb, latency_s, pos_w, gravity_m_s2)
    d = np.asarray(accel, dtype=float) - np.einsum("ij,nj->ni", c, force_b)
    omega = np.asarray(gyro, dtype=float) - (np.zeros(3) if gyro_bias is None else np.asarray(gyro_bias, dtype=float))
    alpha = np.gradient(omega, t, axis=0)
    w = _skew(omega)
    m = _skew(alpha) + w @ w  # d = M r + b
    d = np.where(np.asarray(mask, dtype=bool)[:, None], d, np.nan)
    length = max(1, int(round(window_s / float(np.median(np.diff(t))))))
    d_w = window_means(d, length)
    m_w = window_means(m.reshape(len(m), 9), length).reshape(-1, 3, 3)
    ok = np.all(np.isfinite(d_w), axis=1) & np.all(np.isfinite(m_w.reshape(-1, 9)), axis=1)
    k = int(ok.sum())
    if k < min_windows:
        raise ValueError(f"only {k} usable windows for the lever arm")
    d_w, m_w = d_w[ok], m_w[ok]
    x = np.concatenate([m_w, np.broadcast_to(np.eye(3), (k, 3, 3))], axis=2).reshape(3 * k, 6)
    fit = linear_fit(x, d_w.reshape(3 * k, 1))
    coef = fit.coef[:, 0]
    resid = (d_w.reshape(3 * k) - x @ coef).reshape(k, 3)
    r_cov = fit.cov[0][:3, :3]
    return LeverArmFit(
        lever_arm_b=c.T @ coef[:3],
        lever_arm_sigma=np.sqrt(np.diag(c.T @ r_cov @ c)),
        bias=coef[3:].copy(),
        windows=k,
        residual_rms=np.sqrt(np.mean(resid**2, axis=0)),
        rms_before=np.std(d_w, axis=0),
    )
