"""Attitude error metrics, as the BROAD benchmark defines them.

With ``q_est`` and ``q_ref`` scalar first, the error quaternion in the world frame is
``q_err = q_est ⊗ conj(q_ref)``; then (Laidig et al., "BROAD - A Benchmark for Robust Inertial
Orientation Estimation", Data 6(7), 2021):

- total error        ``2 acos |w|``
- heading error      ``2 atan |z / w|``
- inclination error  ``2 acos sqrt(w² + z²)``

Each is summarised as the RMSE in degrees over the evaluated samples, ignoring NaN rows (a reference
that lost tracking). A 6D filter has no defined heading, so only its inclination error is compared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyroemu.dynamics.rotation import quat_conjugate, quat_multiply, quat_to_rotvec

__all__ = [
    "AttitudeErrors",
    "attitude_error_vector",
    "attitude_errors",
    "attitude_nees",
    "convergence_time",
    "rmse_deg",
]


@dataclass(frozen=True, eq=False)
class AttitudeErrors:
    """Per-sample errors, rad (NaN where either quaternion is NaN)."""

    total: np.ndarray
    heading: np.ndarray
    inclination: np.ndarray


def attitude_errors(q_est: np.ndarray, q_ref: np.ndarray) -> AttitudeErrors:
    """BROAD's total, heading and inclination errors of ``q_est`` against ``q_ref``, both (N, 4)."""
    q_err = quat_multiply(np.asarray(q_est, dtype=float), quat_conjugate(np.asarray(q_ref, dtype=float)))
    q_err = q_err / np.linalg.norm(q_err, axis=-1, keepdims=True)
    w = np.abs(q_err[..., 0])
    z = q_err[..., 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        total = 2.0 * np.arccos(np.clip(w, 0.0, 1.0))
        heading = 2.0 * np.arctan(np.abs(z) / w)  # w = 0 gives π, as atan(inf) should
        inclination = 2.0 * np.arccos(np.clip(np.sqrt(w**2 + z**2), 0.0, 1.0))
    return AttitudeErrors(total=total, heading=heading, inclination=inclination)


def rmse_deg(error_rad: np.ndarray, mask: np.ndarray | None = None) -> float:
    """RMSE in degrees over ``mask`` (default: all samples), ignoring NaN; NaN if nothing is left."""
    e = np.asarray(error_rad, dtype=float)
    if mask is not None:
        e = e[np.asarray(mask, dtype=bool)]
    e = e[~np.isnan(e)]
    return float(np.degrees(np.sqrt(np.mean(e**2)))) if len(e) else float("nan")


def convergence_time(t: np.ndarray, error_rad: np.ndarray, threshold_rad: float) -> float:
    """Time from the first sample after which the error never again exceeds ``threshold_rad``, s.

    NaN errors (no reference) neither break nor establish convergence. Returns ``inf`` when the last
    valid error is above the threshold, and 0 when it never was.
    """
    t = np.asarray(t, dtype=float)
    e = np.asarray(error_rad, dtype=float)
    above = np.flatnonzero(~np.isnan(e) & (e > threshold_rad))
    if not len(above):
        return 0.0
    last = above[-1]
    valid_after = np.flatnonzero(~np.isnan(e[last + 1 :]))
    if not len(valid_after):
        return float("inf")
    return float(t[last + 1 + valid_after[0]] - t[0])


def attitude_error_vector(q_ref: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """The attitude error as a rotation vector in world axes, (N, 3) rad: ``q_ref ⊗ q_est*``, the error
    that the filters' ``q_wb_covariance`` describes. ``q_ref``, ``q_est`` (N, 4), scalar first."""
    return quat_to_rotvec(quat_multiply(q_ref, quat_conjugate(q_est)))


def attitude_nees(q_ref: np.ndarray, q_est: np.ndarray, covariance: np.ndarray, dof: int = 3) -> np.ndarray:
    """Normalised estimation error squared eᵀ P⁻¹ e of attitudes, (N,).

    ``e`` is the rotation vector of ``q_ref ⊗ q_est*`` (world axes, rad), the error that the filters'
    ``q_wb_covariance`` (N, 3, 3) describes; its first ``dof`` components are used (2: the tilt alone,
    for a 6D filter whose heading is not observed). ``q_ref``, ``q_est`` (N, 4). A consistent filter's
    NEES is χ²(dof)-distributed.
    """
    e = attitude_error_vector(q_ref, q_est)[:, :dof]
    cov = np.asarray(covariance, dtype=float)[:, :dof, :dof]
    nees: np.ndarray = np.einsum("ki,ki->k", e, np.linalg.solve(cov, e[:, :, None])[:, :, 0])
    return nees
