"""A magnet near the working volume, found in a recording: a point dipole fitted to the world field.

The world-axes field along the path, ``m_w(p_i)`` (:func:`.magnetic_environment.world_field` of the
calibrated magnetometer), is modelled as a uniform background plus one dipole fixed in the world
(:func:`gyroemu.dynamics.dipole.dipole_field`)::

    m_w(p) = B₀ + μ₀/(4π) (3 (m·r̂) r̂ − m) / |r|³,      r = p − p_d

The model is linear in ``(B₀, m)`` for a given dipole position ``p_d``: the fit (variable projection)
solves those six by linear least squares inside a nonlinear least-squares search over ``p_d``,
started from the best point of a coarse grid around the path (a magnet lies beside the path, not on
it). The parameters' standard uncertainties come from the full nine-parameter Jacobian at the optimum,
``s² (JᵀJ)⁻¹`` with ``s²`` the residual variance; samples closer than ``min_distance_m`` to the fitted
point are not in the path (the grid keeps that distance).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.dipole import dipole_field

__all__ = ["DipoleFit", "fit_dipole"]

_POINTS = 3000  # path samples used (evenly spread): the fit is over-determined by far


@dataclass(frozen=True)
class DipoleFit:
    """A fitted dipole and background (SI: m, A m², tesla), each with its standard uncertainty.

    ``rms_before`` is the RMS of ``|m_w − B₀|`` with the background alone (tesla), ``rms_after`` with the
    dipole: how much of the field's variation along the path the magnet explains.
    """

    position_m: NDArray[np.float64]
    position_sigma_m: NDArray[np.float64]
    moment_A_m2: NDArray[np.float64]
    moment_sigma_A_m2: NDArray[np.float64]
    background_T: NDArray[np.float64]
    background_sigma_T: NDArray[np.float64]
    rms_before: float
    rms_after: float
    samples: int


def _design(pos: NDArray[np.float64], p_d: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3N, 6) matrix of the model's linear part: columns B₀ (3) and m (3), rows x, y, z per sample."""
    n = len(pos)
    a = np.zeros((n, 3, 6))
    a[:, :, :3] = np.eye(3)
    for j in range(3):
        unit = np.zeros(3)
        unit[j] = 1.0
        a[:, :, 3 + j] = dipole_field(pos, p_d, unit)
    return a.reshape(3 * n, 6)


def _linear(
    pos: NDArray[np.float64], field: NDArray[np.float64], p_d: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a = _design(pos, p_d)
    coef, *_ = np.linalg.lstsq(a, field.reshape(-1), rcond=None)
    # float64, which numpy's stubs type as floating[Any] (np.linalg.lstsq)
    return cast("NDArray[np.float64]", coef), field.reshape(-1) - a @ coef


def fit_dipole(
    pos_w: NDArray[np.float64], field_w: NDArray[np.float64], min_distance_m: float = 0.05, grid_m: float = 0.05
) -> DipoleFit:
    """Fit ``B₀`` and one dipole to the field ``field_w`` (N, 3), tesla, at positions ``pos_w`` (N, 3), m
    (NaN rows skipped); see the module's notes."""
    from scipy.optimize import least_squares

    pos = np.asarray(pos_w, dtype=float)
    field = np.asarray(field_w, dtype=float)
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(field), axis=1)
    pos, field = pos[ok], field[ok]
    if len(pos) < 20:
        raise ValueError(f"only {len(pos)} samples with a position and a field: nothing to fit")
    keep = np.linspace(0, len(pos) - 1, min(_POINTS, len(pos))).astype(int)
    pos, field = pos[keep], field[keep]
    background = field.mean(axis=0)
    rms_before = float(np.sqrt(np.mean(np.sum((field - background) ** 2, axis=1))))

    # Coarse grid around the path's bounding box, 0.3 m wider on each side, away from the path.
    lo, hi = pos.min(axis=0) - 0.3, pos.max(axis=0) + 0.3
    axes = [np.arange(a, b + grid_m / 2, grid_m) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    sparse = pos[:: max(1, len(pos) // 300)]
    near = np.min(np.linalg.norm(grid[:, None, :] - sparse[None, :, :], axis=-1), axis=1)
    grid = grid[near >= min_distance_m]
    cost = np.array([np.sum(_linear(sparse, field[:: max(1, len(pos) // 300)], g)[1] ** 2) for g in grid])
    start = grid[int(np.argmin(cost))]
    result = least_squares(lambda p: _linear(pos, field, p)[1], start, x_scale=0.05, ftol=1e-12, xtol=1e-12, gtol=1e-12)
    p_d = result.x
    coef, residual = _linear(pos, field, p_d)

    def full(x: NDArray[np.float64]) -> NDArray[np.float64]:
        model = x[:3] + dipole_field(pos, x[6:9], x[3:6])
        difference: NDArray[np.float64] = (field - model).reshape(-1)
        return difference

    x = np.concatenate([coef, p_d])
    step = np.concatenate([np.full(3, 1e-9), np.maximum(np.abs(coef[3:]) * 1e-6, 1e-9), np.full(3, 1e-6)])
    jac = np.column_stack(
        [(full(x + np.eye(9)[k] * step[k]) - full(x - np.eye(9)[k] * step[k])) / (2 * step[k]) for k in range(9)]
    )
    dof = max(1, residual.size - 9)
    s2 = float(residual @ residual) / dof
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return DipoleFit(
        position_m=p_d,
        position_sigma_m=sigma[6:9],
        moment_A_m2=coef[3:],
        moment_sigma_A_m2=sigma[3:6],
        background_T=coef[:3],
        background_sigma_T=sigma[:3],
        rms_before=rms_before,
        rms_after=float(np.sqrt(np.mean(np.sum(residual.reshape(-1, 3) ** 2, axis=1)))),
        samples=len(pos),
    )
