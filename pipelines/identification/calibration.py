"""Deterministic errors of a gyro, accelerometer and magnetometer against a truth attitude track.

All three are linear least squares (:func:`gyroemu.pipelines.identification.lsq.linear_fit`) over
non-overlapping windows of ``window_s`` (the mean of each window on both sides: the relation stays
exact, the differentiated optical truth loses most of its noise, and the windows' residuals are
nearly independent, as the covariance s²(XᵀX)⁻¹ assumes). The truth is read at t − latency.

- **Gyro**: ω_m = M ω + b, ω the truth's body rate (plus Earth's rate R_bw Ω_w when given). M holds
  the mounting rotation C (sensor ← body), the scale factors and the non-orthogonality; its polar
  decomposition M = P C (P symmetric positive) splits them: P = I + S + N with S = diag(P) − 1 and
  N = P − diag(P) symmetric (an antisymmetric misalignment is a rotation, so it goes into C).
  Observable when every direction is turned: the rms rates along the principal axes of the windows'
  ω (the singular values of the regressor / √windows) all exceed ``min_rate_rad_s`` and the
  column-scaled condition number stays below ``max_condition``; otherwise only the bias is fitted
  (with M = I) and the report says why.
- **Accelerometer**: f_m = A R_bw (a_w + g e_z) + b, with a_w from the truth position when there is one;
  only slow windows (|ω| < ``max_rate_rad_s``: no lever-arm forces) are used, and without a position
  only those with ‖f_m‖ ≈ g. A = (I + S + N) C with the
  gyro's C; observable when gravity takes several directions in the sensor (tilts), else the bias only.
- **Magnetometer**: m_m = K R_bw m_w + h with K = soft iron × C. Linear in W = K ⊗ m_wᵀ (3 × 9) and
  h: regressing m_m on vec R_bw gives W, whose rearrangement Z_(ij),k = K_ij m_w,k is rank one; its
  leading singular pair gives K and m_w up to a common scale, fixed by det K = 1 (the field is then
  as strong as the sensor measures it on average). Observable when the rotations span all nine
  entries of R_bw (condition number below ``max_condition``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .lsq import linear_fit
from .truth import interpolate_attitude, interpolate_vectors, rotation_bw, truth_angular_velocity

__all__ = [
    "GyroCalibration",
    "AccelCalibration",
    "MagCalibration",
    "fit_gyro",
    "fit_accel",
    "fit_mag",
    "polar_decomposition",
    "window_means",
    "paired_windows",
    "truth_specific_force_world",
    "truth_specific_force_body",
]


def window_means(x: ArrayLike, length: int) -> NDArray[np.float64]:
    """(N // length, ...) means of ``x`` (N, ...) over non-overlapping windows of ``length`` samples;
    NaN for a window holding a NaN."""
    x = np.asarray(x, dtype=float)
    k = len(x) // length
    means: NDArray[np.float64] = x[: k * length].reshape((k, length) + x.shape[1:]).mean(axis=1)
    return means


def paired_windows(
    t: NDArray[np.float64],
    truth: NDArray[np.float64],
    measured: NDArray[np.float64],
    mask: NDArray[np.bool_] | None,
    window_s: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Window means of a truth and a measurement at the samples ``t`` (N,): the measurement is NaN
    outside ``mask`` (N,) bool, the windows last ``window_s`` (at least one sample); returns both
    windowed arrays and the window's length in samples."""
    meas = np.asarray(measured, dtype=float).copy()
    if mask is not None:
        meas[~np.asarray(mask, dtype=bool)] = np.nan
    length = max(1, int(round(window_s / float(np.median(np.diff(t))))))
    return window_means(truth, length), window_means(meas, length), length


def polar_decomposition(m: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(P, C) with ``m`` (3, 3) = P C, P symmetric positive definite, C a rotation (det +1)."""
    u, s, vt = np.linalg.svd(m)
    c = u @ vt
    if np.linalg.det(c) < 0:  # a reflection: push the sign onto the smallest singular value
        u[:, -1] *= -1
        s[-1] *= -1
        c = u @ vt
    return u @ np.diag(s) @ u.T, c


def truth_specific_force_world(
    truth_t: NDArray[np.float64], pos_w: NDArray[np.float64] | None, gravity_m_s2: float = 9.81, step_s: float = 0.02
) -> NDArray[np.float64]:
    """(M, 3) a_w + g e_z, m/s², world axes: a_w from the second difference of ``pos_w`` (M, 3) m over
    ±``step_s`` (a_k ≈ (p_{k+h} − 2p_k + p_{k−h}) / (hΔt)²), or 0 without a position track."""
    n = len(truth_t)
    force = np.zeros((n, 3))
    force[:, 2] = gravity_m_s2
    if pos_w is None:
        return force
    p = np.asarray(pos_w, dtype=float)
    dt = float(np.median(np.diff(truth_t)))
    h = max(1, int(round(step_s / dt)))
    acc = np.full((n, 3), np.nan)
    acc[h:-h] = (p[2 * h :] - 2 * p[h:-h] + p[: -2 * h]) / (h * dt) ** 2
    total: NDArray[np.float64] = force + acc
    return total


def truth_specific_force_body(
    t: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float = 0.0,
    pos_w: NDArray[np.float64] | None = None,
    gravity_m_s2: float = 9.81,
) -> NDArray[np.float64]:
    """(N, 3) the truth's specific force R_bw (a_w + g e_z) in body axes, m/s², at the instants
    ``t`` (N,) s less ``latency_s`` (what an accelerometer with that delay senses at its origin), from
    ``q_wb`` (M, 4) and ``pos_w`` (M, 3) m at ``truth_t`` (:func:`truth_specific_force_world`)."""
    times = np.asarray(t, dtype=float) - latency_s
    q = interpolate_attitude(truth_t, q_wb, times)
    force_w = interpolate_vectors(truth_t, truth_specific_force_world(truth_t, pos_w, gravity_m_s2), times)
    force_b: NDArray[np.float64] = np.einsum("nij,nj->ni", rotation_bw(q), force_w)
    return force_b


def _row_cov(cov: NDArray[np.float64], c: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3, 3) standard uncertainties of P = M Cᵀ from the (3, p, p) covariances of M's rows (C fixed)."""
    sig = np.empty((3, 3))
    for i in range(3):
        ci = c @ cov[i, :3, :3] @ c.T  # P_i,: = M_i,: Cᵀ
        sig[i] = np.sqrt(np.diag(ci))
    return sig


@dataclass(frozen=True)
class GyroCalibration:
    """A gyro's fitted deterministic errors (rad/s; dimensionless), with standard uncertainties.

    Attributes
    ----------
    bias, bias_sigma : (3,) rad/s.
    matrix, matrix_sigma : (3, 3) M (I when not observable).
    scale, scale_sigma : (3,) S (0 when not observable).
    misalignment, misalignment_sigma : (3, 3) N, symmetric, zero diagonal.
    c_sb : (3, 3) rotation body → sensor (R(q_bs)ᵀ).
    observable : scale, misalignment and mounting fitted.
    excitation_rad_s : (3,) rms rates along the principal axes of the motion.
    condition : condition number of the column-scaled regressor.
    windows : windows used.
    residual_rms : (3,) rad/s, per window.
    note : why not observable, or "".
    """

    bias: NDArray[np.float64]
    bias_sigma: NDArray[np.float64]
    matrix: NDArray[np.float64]
    matrix_sigma: NDArray[np.float64]
    scale: NDArray[np.float64]
    scale_sigma: NDArray[np.float64]
    misalignment: NDArray[np.float64]
    misalignment_sigma: NDArray[np.float64]
    c_sb: NDArray[np.float64]
    observable: bool
    excitation_rad_s: NDArray[np.float64]
    condition: float
    windows: int
    residual_rms: NDArray[np.float64]
    note: str


def fit_gyro(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float = 0.0,
    *,
    window_s: float = 0.1,
    earth_rate_w: NDArray[np.float64] | None = None,
    min_rate_rad_s: float = 0.2,
    max_condition: float = 50.0,
    mask: NDArray[np.bool_] | None = None,
) -> GyroCalibration:
    """Fit ω_m = M ω + b (module notes). ``gyro`` (N, 3) rad/s at ``t`` (N,) s; truth ``q_wb`` (M, 4)
    at ``truth_t``; ``earth_rate_w`` (3,) rad/s world axes; ``mask`` (N,) bool: samples to use."""
    times = np.asarray(t, dtype=float) - latency_s
    omega = interpolate_vectors(truth_t, truth_angular_velocity(truth_t, q_wb), times)
    if earth_rate_w is not None:
        r_bw = rotation_bw(interpolate_attitude(truth_t, q_wb, times))
        omega = omega + r_bw @ np.asarray(earth_rate_w, dtype=float)
    w_true, w_meas, _ = paired_windows(t, omega, gyro, mask, window_s)
    ok = np.all(np.isfinite(w_true), axis=1) & np.all(np.isfinite(w_meas), axis=1)
    w_true, w_meas = w_true[ok], w_meas[ok]
    k = len(w_true)
    if k < 8:
        raise ValueError(f"only {k} windows with both truth and gyro: nothing to fit")
    excitation = np.linalg.svd(w_true, compute_uv=False) / np.sqrt(k)
    fit = linear_fit(np.column_stack([w_true, np.ones(k)]), w_meas)
    reasons = []
    if excitation[-1] < min_rate_rad_s:
        reasons.append(
            f"the motion's weakest principal axis turns at {excitation[-1]:.3g} rad/s rms "
            f"(< {min_rate_rad_s:g}): scale factor and misalignment are not observable"
        )
    if fit.condition > max_condition:
        reasons.append(f"condition number {fit.condition:.3g} > {max_condition:g}")
    eye = np.eye(3)
    if reasons:
        d = w_meas - w_true
        bias = d.mean(axis=0)
        return GyroCalibration(
            bias=bias,
            bias_sigma=d.std(axis=0, ddof=1) / np.sqrt(k),
            matrix=eye,
            matrix_sigma=np.zeros((3, 3)),
            scale=np.zeros(3),
            scale_sigma=np.zeros(3),
            misalignment=np.zeros((3, 3)),
            misalignment_sigma=np.zeros((3, 3)),
            c_sb=eye,
            observable=False,
            excitation_rad_s=excitation,
            condition=fit.condition,
            windows=k,
            residual_rms=d.std(axis=0, ddof=1),
            note="; ".join(reasons) + "; fitted the bias only (M = I)",
        )
    m = fit.coef[:3].T  # row i: output axis i
    p, c = polar_decomposition(m)
    p_sigma = _row_cov(fit.cov, c)
    return GyroCalibration(
        bias=fit.coef[3].copy(),
        bias_sigma=fit.sigma[3].copy(),
        matrix=m,
        matrix_sigma=fit.sigma[:3].T.copy(),
        scale=np.diag(p) - 1.0,
        scale_sigma=np.diag(p_sigma).copy(),
        misalignment=p - np.diag(np.diag(p)),
        misalignment_sigma=p_sigma - np.diag(np.diag(p_sigma)),
        c_sb=c,
        observable=True,
        excitation_rad_s=excitation,
        condition=fit.condition,
        windows=k,
        residual_rms=fit.residual_rms,
        note="",
    )


@dataclass(frozen=True)
class AccelCalibration:
    """An accelerometer's fitted errors (m/s²; dimensionless) with standard uncertainties.

    Attributes
    ----------
    bias, bias_sigma : (3,) m/s².
    scale, scale_sigma : (3,) S (0 when not observable).
    cross_axis, cross_axis_sigma : (3, 3) N, zero diagonal (relative to the gyro's mounting).
    observable : scale and cross-axis fitted.
    tilt_excitation : (3,) singular values of the unit gravity directions seen, / √windows.
    condition : of the column-scaled regressor.
    windows : windows used.
    residual_rms : (3,) m/s².
    used_position : a_w from the truth's position track.
    note : why not observable, or "".
    """

    bias: NDArray[np.float64]
    bias_sigma: NDArray[np.float64]
    scale: NDArray[np.float64]
    scale_sigma: NDArray[np.float64]
    cross_axis: NDArray[np.float64]
    cross_axis_sigma: NDArray[np.float64]
    observable: bool
    tilt_excitation: NDArray[np.float64]
    condition: float
    windows: int
    residual_rms: NDArray[np.float64]
    used_position: bool
    note: str


def fit_accel(
    t: NDArray[np.float64],
    accel: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float = 0.0,
    *,
    pos_w: NDArray[np.float64] | None = None,
    gravity_m_s2: float = 9.81,
    c_sb: NDArray[np.float64] | None = None,
    window_s: float = 0.1,
    max_rate_rad_s: float = 0.3,
    max_force_error_m_s2: float = 0.1,
    min_tilt: float = 0.1,
    max_condition: float = 50.0,
    mask: NDArray[np.bool_] | None = None,
) -> AccelCalibration:
    """Fit f_m = A R_bw (a_w + g e_z) + b (module notes). ``accel`` (N, 3) m/s² at ``t`` (N,) s; truth
    ``q_wb`` (M, 4) and optional ``pos_w`` (M, 3) m at ``truth_t``; ``c_sb`` (3, 3) the gyro's mounting
    (body → sensor; None: identity); ``mask`` (N,) bool: samples to use."""
    times = np.asarray(t, dtype=float) - latency_s
    force_b = truth_specific_force_body(t, truth_t, q_wb, latency_s, pos_w, gravity_m_s2)
    w_true, w_meas, length = paired_windows(t, force_b, accel, mask, window_s)
    ok = np.all(np.isfinite(w_true), axis=1) & np.all(np.isfinite(w_meas), axis=1)
    # Slow windows only: turning makes centripetal and tangential forces at the sensor's lever arm from
    # the truth's reference point, which neither model holds. Without a_w also |f| ≈ g.
    omega = window_means(interpolate_vectors(truth_t, truth_angular_velocity(truth_t, q_wb), times), length)
    ok &= np.linalg.norm(np.nan_to_num(omega, nan=np.inf), axis=1) < max_rate_rad_s
    if pos_w is None:
        ok &= np.abs(np.linalg.norm(w_meas, axis=1) - gravity_m_s2) < max_force_error_m_s2
    w_true, w_meas = w_true[ok], w_meas[ok]
    k = len(w_true)
    if k < 8:
        raise ValueError(f"only {k} usable accelerometer windows")
    c = np.eye(3) if c_sb is None else np.asarray(c_sb, dtype=float)
    tilt = np.linalg.svd(w_true / gravity_m_s2, compute_uv=False) / np.sqrt(k)
    fit = linear_fit(np.column_stack([w_true, np.ones(k)]), w_meas)
    reasons = []
    if tilt[-1] < min_tilt:
        reasons.append(
            f"gravity took too few directions in the sensor (weakest singular value {tilt[-1]:.3g} < {min_tilt:g})"
        )
    if fit.condition > max_condition:
        reasons.append(f"condition number {fit.condition:.3g} > {max_condition:g}")
    if reasons:
        d = w_meas - w_true @ c.T
        return AccelCalibration(
            bias=d.mean(axis=0),
            bias_sigma=d.std(axis=0, ddof=1) / np.sqrt(k),
            scale=np.zeros(3),
            scale_sigma=np.zeros(3),
            cross_axis=np.zeros((3, 3)),
            cross_axis_sigma=np.zeros((3, 3)),
            observable=False,
            tilt_excitation=tilt,
            condition=fit.condition,
            windows=k,
            residual_rms=d.std(axis=0, ddof=1),
            used_position=pos_w is not None,
            note="; ".join(reasons) + "; fitted the bias only (scale and cross-axis 0, mounting from the gyro)",
        )
    a = fit.coef[:3].T
    p = a @ c.T  # I + S + N in the gyro's sensor axes
    p_sigma = _row_cov(fit.cov, c)
    return AccelCalibration(
        bias=fit.coef[3].copy(),
        bias_sigma=fit.sigma[3].copy(),
        scale=np.diag(p) - 1.0,
        scale_sigma=np.diag(p_sigma).copy(),
        cross_axis=p - np.diag(np.diag(p)),
        cross_axis_sigma=p_sigma - np.diag(np.diag(p_sigma)),
        observable=True,
        tilt_excitation=tilt,
        condition=fit.condition,
        windows=k,
        residual_rms=fit.residual_rms,
        used_position=pos_w is not None,
        note="",
    )


@dataclass(frozen=True)
class MagCalibration:
    """A magnetometer's hard and soft iron against the truth attitude.

    Attributes
    ----------
    hard_iron, hard_iron_sigma : (3,) tesla.
    k_matrix : (3, 3) K = soft iron × C (sensor ← body), det 1.
    soft_iron, soft_iron_sigma : (3, 3) K C_sbᵀ (with the gyro's C_sb), and its uncertainty.
    field_w : (3,) the uniform world field m_w, tesla (ENU, heading as the truth's).
    observable : fitted; otherwise identity and zeros with ``note``.
    condition : of the column-scaled regressor.
    windows : windows used.
    residual_rms : (3,) tesla.
    note : why not observable, or "".
    """

    hard_iron: NDArray[np.float64]
    hard_iron_sigma: NDArray[np.float64]
    k_matrix: NDArray[np.float64]
    soft_iron: NDArray[np.float64]
    soft_iron_sigma: NDArray[np.float64]
    field_w: NDArray[np.float64]
    observable: bool
    condition: float
    windows: int
    residual_rms: NDArray[np.float64]
    note: str

    def calibrated_body(self, mag: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) R_bw m_w recovered from measurements ``mag`` (N, 3) tesla: K⁻¹ (m − h)."""
        # float64, which numpy's stubs type as floating[Any] (np.linalg.solve)
        return cast(
            "NDArray[np.float64]", np.linalg.solve(self.k_matrix, (np.asarray(mag, dtype=float) - self.hard_iron).T).T
        )


def fit_mag(
    t: NDArray[np.float64],
    mag: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float = 0.0,
    *,
    c_sb: NDArray[np.float64] | None = None,
    window_s: float = 0.1,
    max_condition: float = 200.0,
    mask: NDArray[np.bool_] | None = None,
) -> MagCalibration:
    """Fit m_m = K R_bw m_w + h (module notes). ``mag`` (N, 3) tesla at ``t`` (N,) s; truth ``q_wb``
    (M, 4) at ``truth_t``; ``c_sb`` (3, 3) the gyro's mounting (None: C from K's polar decomposition)."""
    times = np.asarray(t, dtype=float) - latency_s
    r_bw = rotation_bw(interpolate_attitude(truth_t, q_wb, times)).reshape(len(times), 9)
    w_true, w_meas, _ = paired_windows(t, r_bw, mag, mask, window_s)
    ok = np.all(np.isfinite(w_true), axis=1) & np.all(np.isfinite(w_meas), axis=1)
    w_true, w_meas = w_true[ok], w_meas[ok]
    k = len(w_true)
    if k < 20:
        raise ValueError(f"only {k} windows with both truth and magnetometer: nothing to fit")
    fit = linear_fit(np.column_stack([w_true, np.ones(k)]), w_meas)
    if fit.condition > max_condition:
        h = w_meas.mean(axis=0)
        return MagCalibration(
            hard_iron=np.zeros(3),
            hard_iron_sigma=np.full(3, np.nan),
            k_matrix=np.eye(3),
            soft_iron=np.eye(3),
            soft_iron_sigma=np.zeros((3, 3)),
            field_w=np.full(3, np.nan),
            observable=False,
            condition=fit.condition,
            windows=k,
            residual_rms=w_meas.std(axis=0) if np.all(np.isfinite(h)) else np.full(3, np.nan),
            note=f"the attitudes do not span the rotations (condition number {fit.condition:.3g} > "
            f"{max_condition:g}): hard and soft iron are not separable from the field",
        )
    w = fit.coef[:9].T  # (3, 9): W_i,(3j+k) = K_ij m_w,k
    z = w.reshape(9, 3)  # rows (i, j), columns k
    u, s, vt = np.linalg.svd(z)
    kmat = u[:, 0].reshape(3, 3) * s[0]
    field = vt[0].copy()
    det = np.linalg.det(kmat)
    alpha = np.sign(det) * abs(det) ** (1.0 / 3.0)  # K/α has det 1; m_w·α keeps K m_w
    kmat, field = kmat / alpha, field * alpha
    c = polar_decomposition(kmat)[1] if c_sb is None else np.asarray(c_sb, dtype=float)
    # σ(K_ij): K_ij = Σ_k W_i,(3j+k) m_k / |m|² with m fixed; then soft iron = K Cᵀ row by row.
    mhat = field / np.dot(field, field)
    k_sigma_rows = []
    for i in range(3):
        cov_k = np.array(
            [[mhat @ fit.cov[i, 3 * a : 3 * a + 3, 3 * b : 3 * b + 3] @ mhat for b in range(3)] for a in range(3)]
        )
        k_sigma_rows.append(np.sqrt(np.diag(c @ cov_k @ c.T)))
    return MagCalibration(
        hard_iron=fit.coef[9].copy(),
        hard_iron_sigma=fit.sigma[9].copy(),
        k_matrix=kmat,
        soft_iron=kmat @ c.T,
        soft_iron_sigma=np.array(k_sigma_rows),
        field_w=field,
        observable=True,
        condition=fit.condition,
        windows=k,
        residual_rms=fit.residual_rms,
        note="",
    )
