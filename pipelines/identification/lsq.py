"""Linear least squares with parameter covariance and an observability check.

For outputs Y (n, k) and regressor X (n, p), each output column y_i = X β_i + e_i with white e_i:

    β̂_i = argmin ‖y_i − X β‖²,      Cov(β̂_i) = s_i² (XᵀX)⁻¹,      s_i² = ‖y_i − X β̂_i‖² / (n − p)

The regressor's columns scaled to unit rms give singular values whose ratio (the condition number)
says how well the data separate the parameters: a near-zero singular value is a direction of the
parameters the excitation does not reach (unobservable).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

__all__ = ["LinearFit", "linear_fit"]


@dataclass(frozen=True)
class LinearFit:
    """A linear least-squares fit of k outputs on p regressors.

    Attributes
    ----------
    coef : (p, k) β̂, one column per output.
    cov : (k, p, p) covariance of each output's β̂.
    residual_rms : (k,) s_i, rms residual with the degrees of freedom n − p.
    singular_values : (p,) of the regressor with columns scaled to unit rms, descending.
    n : rows used.
    """

    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    residual_rms: NDArray[np.float64]
    singular_values: NDArray[np.float64]
    n: int

    @property
    def sigma(self) -> NDArray[np.float64]:
        """(p, k) standard uncertainty of each coefficient."""
        return np.sqrt(np.diagonal(self.cov, axis1=1, axis2=2)).T

    @property
    def condition(self) -> float:
        """Condition number of the column-scaled regressor (∞ when rank-deficient)."""
        s = self.singular_values
        return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def linear_fit(x: NDArray[np.float64], y: NDArray[np.float64]) -> LinearFit:
    """Fit ``y`` (n, k) on ``x`` (n, p) (module notes); rows with a NaN are dropped."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
    x, y = x[ok], y[ok]
    n, p = x.shape
    if n <= p:
        raise ValueError(f"{n} usable rows for {p} parameters")
    scale = np.sqrt(np.mean(x * x, axis=0))
    scale[scale == 0] = 1.0
    sv = np.linalg.svd(x / scale, compute_uv=False) / np.sqrt(n)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    resid = y - x @ coef
    s2 = np.sum(resid**2, axis=0) / (n - p)
    xtx_inv = np.linalg.pinv(x.T @ x)
    cov = s2[:, None, None] * xtx_inv[None]
    # coef: float64, which numpy's stubs type as floating[Any] (np.linalg.lstsq)
    return LinearFit(
        coef=cast("NDArray[np.float64]", coef), cov=cov, residual_rms=np.sqrt(s2), singular_values=sv, n=int(n)
    )
